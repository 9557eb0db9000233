"""``routefuse bench``: load, estimator, re-run, inspector and export speed and memory on
simulated 10- and 60-minute 200 Hz drives, as a table or JSON."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

NAME = "bench"
HELP = (
    "measure load, estimator runs, live re-runs after a parameter change, inspector frame steps "
    "and export on simulated 10- and 60-minute 200 Hz drives (each item in its own process, "
    "with its peak memory); the drives are simulated once into the bench folder"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from benchmarks.harness import ITEM_NAMES

    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument(
        "--quick", action="store_true", help="only the 10-minute log's items (a smoke test)"
    )
    parser.add_argument(
        "--only",
        nargs="+",
        default=[],
        metavar="NAME",
        help=f"only these items (or name prefixes such as 'load', 'rerun'): "
        f"{', '.join(ITEM_NAMES)}",
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
    from benchmarks.harness import format_table, run_benchmarks, select_items
    from estimator.errors import ConfigError

    if args.repeat < 1:
        raise ConfigError("--repeat", f"must be at least 1, not {args.repeat}")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(
            "--duration", f"must be a positive number of seconds, not {args.duration}"
        )
    select_items(args.only)  # unknown names fail before anything is simulated

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    doc = run_benchmarks(
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
        print(format_table(doc))
    return 1 if any(r["error"] for r in doc["items"]) else 0
