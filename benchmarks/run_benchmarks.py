"""Run the routefuse benchmarks (the same code as ``routefuse bench``; same options).

python3 benchmarks/run_benchmarks.py                 # table, both logs
python3 benchmarks/run_benchmarks.py --json > bench.json
python3 benchmarks/run_benchmarks.py --quick --only load proposed
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from inspector.cli.main import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
