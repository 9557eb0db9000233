"""``routefuse sweep LOGS... --out DIR``: parameter sets over many logs, as Dask tasks, into one
table (``results.parquet``, ``results.csv``) and ``report.html`` (:mod:`inspector.fleet`)."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from estimator.errors import ConfigError
from estimator.io import LOG_FORMATS_TEXT
from inspector.cli.checks import check_log_specs
from inspector.cli.exit_codes import ExitCode
from inspector.cli.options import add_outage_option, add_topic_options, parse_outage

NAME = "sweep"
MAX_FAILURES_LISTED = 20
"""failed tasks named one per line after the summary (the rest are in the table)"""
HELP = (
    "run parameter sets (--config, --grid, --method) over many logs as Dask tasks, on this "
    "machine or a cluster, into one table (results.parquet, results.csv) and report.html with "
    "each log's change against the first set; a second run resumes"
)


class _SetAction(argparse.Action):
    """``--config``, ``--grid`` and ``--method`` append to one ordered list: the first set
    named on the command line is the reference, whichever option named it."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        sets = list(getattr(namespace, "sets", None) or [])
        sets.append((self.const, str(values)))
        namespace.sets = sets


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "logs",
        nargs="+",
        metavar="LOGS",
        help=f"folders, quoted globs, logs ({LOG_FORMATS_TEXT}) or a manifest CSV with columns "
        "log, route, outages, tags; a log's route is <stem>.route.* beside it unless the "
        "manifest names one",
    )
    parser.add_argument("--out", metavar="DIR", required=True, help="output folder")
    g = parser.add_argument_group(
        "parameter sets",
        "in the order given; the first set is the reference (default: one "
        "set, the default parameters with the proposed method)",
    )
    g.set_defaults(sets=[])
    g.add_argument(
        "--config",
        metavar="FILE.toml",
        action=_SetAction,
        const="config",
        help="a set from a parameter file (repeatable)",
    )
    g.add_argument(
        "--grid",
        metavar="GRID.toml",
        action=_SetAction,
        const="grid",
        help="a set per combination of the file's lists, e.g. [gates] max_residual_m = [1, 2.5]",
    )
    g.add_argument(
        "--method",
        choices=("proposed", "paper", "baseline"),
        action=_SetAction,
        const="method",
        help="a set running this method with the default parameters (repeatable)",
    )
    g.add_argument(
        "--set",
        metavar="NAME=VALUE",
        action="append",
        default=[],
        help="a value under every set (the sets' files and grids override it)",
    )
    e = parser.add_argument_group("execution")
    where = e.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        metavar="N",
        default=None,
        help="worker processes of a local Dask cluster (default: one per core)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDR",
        default=None,
        help="a running Dask scheduler, e.g. tcp://head:8786 (start it with `dask scheduler`, "
        "workers with `dask worker ADDR`)",
    )
    e.add_argument(
        "--cache-dir",
        metavar="DIR",
        default=None,
        help="the decoded-log cache the workers share (default: this user's routefuse cache; "
        "on a cluster, a folder every node sees)",
    )
    e.add_argument(
        "--export",
        action="store_true",
        help="also write each task's replay export (exports/<set>/<log>/replay.html)",
    )
    e.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_outage_option(parser)
    add_topic_options(parser)


def execute(args: argparse.Namespace) -> int:
    from estimator.io import TopicChoice
    from estimator.params import Params, parse_assignments, with_values
    from inspector.fleet import SweepPlan, build_sets, collect_logs
    from inspector.fleet.engine import QuietProgress, TerminalProgress, run_sweep

    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", f"{args.workers}: at least one worker")
    check_log_specs(args.logs)  # a missing path is named as missing, not as "no logs found"
    base = with_values(Params(), parse_assignments(args.set), "--set")
    outages = tuple(parse_outage(o) for o in args.outage)
    plan = SweepPlan(
        collect_logs(args.logs, outages=outages),
        build_sets(args.sets, base=base),
        TopicChoice.from_args(args),
    )
    export = None
    if args.export:
        from inspector.export.replay import ReplayOptions

        export = ReplayOptions()
    failures: list[str] = []

    def keep_failure(row: Mapping[str, Any]) -> None:
        if row.get("status") != "ok" and len(failures) <= MAX_FAILURES_LISTED:
            failures.append(f"failed: {Path(str(row['log'])).name} {row['set']}: {row['error']}")

    result = run_sweep(
        plan,
        Path(args.out),
        workers=args.workers,
        scheduler=args.scheduler,
        export=export,
        cache_dir=args.cache_dir,
        progress=QuietProgress() if args.quiet else TerminalProgress(),
        on_row=keep_failure,
    )
    print(
        f"{result.total} tasks ({len(plan.logs)} logs x {len(plan.sets)} sets): "
        f"{result.ran} run, {result.skipped} finished before, {result.failed} failed, "
        f"in {result.seconds:.1f} s"
    )
    print(f"table: {result.parquet} and {result.csv.name}")
    if result.report is not None:
        print(f"report: {result.report}")
    # the failed tasks are named here too, --quiet or not: a CI log shows what exit 4 means
    for line in failures[:MAX_FAILURES_LISTED]:
        print(line)
    if result.failed > MAX_FAILURES_LISTED:
        print(
            f"... and {result.failed - MAX_FAILURES_LISTED} more failed tasks ({result.csv.name})"
        )
    return ExitCode.SOME_FAILED if result.failed else ExitCode.OK
