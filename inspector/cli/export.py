"""``routefuse export``: the replay, figures, metrics and trajectories of one log, or of many,
written to files with no browser and no display."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from estimator.errors import ConfigError
from estimator.io import LOG_FORMATS_TEXT, ROUTE_FORMATS_TEXT, TopicChoice
from inspector.cli.checks import check_log, check_log_specs, route_for
from inspector.cli.exit_codes import ExitCode
from inspector.cli.options import (
    add_outage_option,
    add_param_options,
    add_route_feature_option,
    add_topic_options,
    params_from_args,
    parse_outage,
)
from inspector.library_warnings import library_warnings_as_lines
from inspector.numbers import signed

NAME = "export"
HELP = (
    "write a self-contained 3D replay (replay.html), the deviation and trajectory figures, "
    "metrics, every match attempt and the trajectories (CSV, GeoJSON, TUM) of a log, or of "
    "every log of a folder with --batch"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", nargs="?", metavar="LOG", help=LOG_FORMATS_TEXT)
    parser.add_argument(
        "--route",
        metavar="ROUTE",
        help=f"route file ({ROUTE_FORMATS_TEXT}; default: LOG's <name>.route.* beside it)",
    )
    parser.add_argument(
        "--batch",
        metavar="DIR_OR_GLOB",
        help="export every log of a folder (or matching a quoted glob); each log's route is "
        "<stem>.route.* beside it (GeoJSON, GPX, KML or CSV); the logs run as Dask tasks "
        "(routefuse sweep's engine) and a second run skips the logs exported before",
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        metavar="N",
        default=None,
        help="with --batch: worker processes of a local Dask cluster (default: one per core)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDR",
        default=None,
        help="with --batch: a running Dask scheduler, e.g. tcp://head:8786",
    )
    add_route_feature_option(parser)
    parser.add_argument("--out", metavar="DIR", required=True, help="output folder")
    parser.add_argument(
        "--compare",
        nargs=2,
        metavar=("A.toml", "B.toml"),
        default=None,
        help="run the method with two parameter sets and write their comparison (metrics of A, "
        "B and B - A; every attempt whose verdict changed, with both gate tables) instead of a "
        "replay",
    )
    parser.add_argument(
        "--subtract-lane-offset",
        action="store_true",
        help="measure route deviations from the learned lane instead of the route line (as the "
        "README's table); every table says which",
    )
    parser.add_argument(
        "--method",
        choices=("proposed", "paper"),
        default="proposed",
        help="method compared against the baseline (default proposed)",
    )
    add_outage_option(parser)
    parser.add_argument(
        "--fps",
        type=float,
        default=None,
        metavar="N",
        help="replay frames per second of log time (default: up to 2, fewer for long logs so "
        "the replay keeps about 300 frames)",
    )
    parser.add_argument(
        "--time-lapse",
        type=float,
        default=None,
        metavar="X",
        help="log seconds per replay second (default: real time, or faster so the replay "
        "lasts about a minute)",
    )
    add_param_options(parser)
    add_topic_options(parser)


class _Progress:
    """One line per log on stderr, rewritten in place on a terminal."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.last = ""
        self.stage = ""

    def __call__(self, i: int, n: int, log: Path, stage: str, fraction: float) -> None:
        prefix = f"[{i + 1}/{n}] " if n > 1 else ""
        line = f"{prefix}{log.name}: {stage} {100 * fraction:3.0f}%"
        if self.tty:
            if line != self.last:
                end = "\n" if stage in ("done", "failed") else ""
                print("\r\033[K" + line, end=end, file=sys.stderr, flush=True)
        elif stage != self.stage:
            print(line, file=sys.stderr, flush=True)
        self.last, self.stage = line, stage


def _compare(
    args: argparse.Namespace,
    log: Path,
    route: Path,
    out: Path,
    outages: tuple[tuple[float, float], ...],
    topics: TopicChoice,
) -> int:
    from inspector.export.compare import export_comparison

    set_a, set_b = (Path(p).expanduser() for p in args.compare)
    comparison, files = export_comparison(
        log,
        route,
        out,
        set_a,
        set_b,
        method=args.method,
        outages=outages,
        topics=topics,
        route_feature=args.route_feature,
    )
    for label, va, vb in comparison.metrics:
        if va is not None and vb is not None:
            print(f"{label}: A {va:.3f}, B {vb:.3f} (B - A {signed(vb - va)})")
    truth = [(va, vb) for label, va, vb in comparison.metrics if label.startswith("truth")]
    if truth and all(va is None and vb is None for va, vb in truth):
        print(
            "no ground truth in this log: only the route deviation is compared, and it rewards "
            "following the map"
        )
    print(
        f"accepted A {comparison.accepted[0]} / {comparison.attempts[0]}, "
        f"B {comparison.accepted[1]} / {comparison.attempts[1]}; "
        f"{len(comparison.changed)} attempts changed verdict"
    )
    print(f"wrote {len(files)} files to {out} (open compare.html)")
    return 0


def execute(args: argparse.Namespace) -> int:
    with library_warnings_as_lines(NAME):
        return _export(args)


def _export(args: argparse.Namespace) -> int:
    from inspector.export import (
        ReplayOptions,
        export_batch,
        export_log,
        find_logs,
        format_summary,
    )

    params = params_from_args(args)
    outages = tuple(parse_outage(o) for o in args.outage)
    topics = TopicChoice.from_args(args)
    replay = ReplayOptions(fps=args.fps, time_lapse=args.time_lapse)
    progress = _Progress()
    out = Path(args.out).expanduser()
    if args.batch is not None:
        if args.log is not None or args.route is not None:
            raise ConfigError("--batch", "give either LOG --route ROUTE or --batch, not both")
        if args.workers is not None and args.workers < 1:
            raise ConfigError("--workers", f"{args.workers}: at least one worker")
        if args.compare is not None:
            raise ConfigError("--compare", "compares two sets on one log, not a batch")
        if args.subtract_lane_offset:
            raise ConfigError(
                "--subtract-lane-offset",
                "applies to a single export; a batch's tables measure from the route line",
            )
        from inspector.fleet.engine import TerminalProgress

        check_log_specs([args.batch])

        batch = export_batch(
            find_logs(args.batch),
            out,
            params=params,
            method=args.method,
            outages=outages,
            topics=topics,
            replay=replay,
            progress=TerminalProgress(),
            workers=args.workers,
            scheduler=args.scheduler,
        )
        print(format_summary(batch.items))
        print(f"summary: {batch.summary_csv}")
        return ExitCode.SOME_FAILED if batch.failed else ExitCode.OK
    if args.log is None:
        raise ConfigError(None, "give a LOG (with --route ROUTE) or --batch DIR_OR_GLOB")
    # the log's own problem first, then the route's (given, or the one beside the log as
    # ``run`` and ``serve`` find it)
    log = check_log(args.log)
    route = route_for(log, args.route)
    if args.compare is not None:
        return _compare(args, log, route, out, outages, topics)

    def report(stage: str, fraction: float) -> None:
        progress(0, 1, log, stage, fraction)

    result = export_log(
        log,
        route,
        out,
        params=params,
        method=args.method,
        outages=outages,
        topics=topics,
        route_feature=args.route_feature,
        replay=replay,
        progress=report,
        subtract_lane_offset=args.subtract_lane_offset,
    )
    m = result.metrics
    if not m["degraded_intervals"]:
        print("no GNSS-degraded interval in this log: the metrics are empty (use --outage)")
    for name, row in m["methods"].items():
        r, truth = row["route"], row["truth"]
        rmse = "-" if r["rmse_pos_dev_m"] is None else f"{r['rmse_pos_dev_m']:.2f} m"
        error = (
            "no ground truth in this log"
            if truth is None or truth.get("rmse_h_err_m") is None
            else f"error against truth RMSE {truth['rmse_h_err_m']:.2f} m"
        )
        print(
            f"{name:<9} over the outages: {error}; position deviation RMSE (from the "
            f"{m['route_deviation_from']}) {rmse}"
        )
    print(
        f"match attempts {m['matches']['attempted']}, accepted {m['matches']['accepted']}; "
        f"replay {result.frames} frames"
    )
    print(f"wrote {len(result.files)} files to {result.out_dir} (open report.html)")
    return 0
