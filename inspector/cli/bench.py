"""``routefuse bench``: start-up, load, estimator, re-run, inspector and export speed and memory
on simulated 5-, 10- and 60-minute 200 Hz drives, as a table or JSON. A thin command over the
bench harness (:mod:`benchmarks.harness`), which lives in the source checkout, not in the
installed package."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import ModuleType

from estimator.errors import ConfigError, RoutefuseError
from inspector.cli.exit_codes import ExitCode

NAME = "bench"
HELP = (
    "measure start-up (routefuse --help, routefuse run on a 5-minute drive), load, estimator "
    "runs, live re-runs after a parameter change, inspector frame steps and export on simulated "
    "200 Hz drives (each item in its own process, with its peak memory); the drives are "
    "simulated once into the bench folder; needs a source checkout of routefuse"
)


def _harness() -> ModuleType:
    """:mod:`benchmarks.harness`, from the source checkout this package runs from (whatever
    the working directory)."""
    import importlib

    root = Path(__file__).resolve().parents[2]
    if not (root / "benchmarks" / "harness.py").is_file():
        raise RoutefuseError(
            "routefuse bench",
            "the bench harness is not installed with the package; run it from a source "
            "checkout: git clone the repository, pip install -e . there, then routefuse bench",
        )
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return importlib.import_module("benchmarks.harness")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument(
        "--quick", action="store_true", help="only the 5- and 10-minute logs' items (a smoke test)"
    )
    parser.add_argument(
        "--only",
        nargs="+",
        default=[],
        metavar="NAME",
        help="only these items, or name prefixes such as 'startup', 'load', 'rerun' (an unknown "
        "name lists them all)",
    )
    parser.add_argument(
        "--repeat",
        type=int,
        default=3,
        metavar="N",
        help="runs per timed item; the minimum is reported (default 3)",
    )
    parser.add_argument(
        "--dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="bench folder for the simulated logs and their decoded cache "
        "(default: <routefuse cache>/bench)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="simulate only the first S seconds of each drive (smoke tests: the figures are "
        "then not comparable)",
    )


def execute(args: argparse.Namespace) -> int:
    if args.repeat < 1:
        raise ConfigError("--repeat", f"must be at least 1, not {args.repeat}")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(
            "--duration", f"must be a positive number of seconds, not {args.duration}"
        )
    harness = _harness()
    harness.select_items(args.only)  # unknown names fail before anything is simulated

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    doc = harness.run_benchmarks(
        only=args.only,
        quick=args.quick,
        repeat=args.repeat,
        folder=args.dir,
        duration_s=args.duration,
        say=say,
    )
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(harness.format_table(doc))
    return ExitCode.SOME_FAILED if any(r["error"] for r in doc["items"]) else ExitCode.OK
