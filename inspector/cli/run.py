"""``routefuse run LOG --route ROUTE``: run the methods over a log and print the paper's table."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from estimator.errors import RoutefuseError
from estimator.io import LOG_FORMATS_TEXT, ROUTE_FORMATS_TEXT, TopicChoice
from estimator.params import Method
from inspector.cli.checks import check_log, check_output_file, route_for
from inspector.cli.exit_codes import ExitCode
from inspector.cli.options import (
    add_outage_option,
    add_param_options,
    add_route_feature_option,
    add_topic_options,
    params_from_args,
    parse_outage,
)
from inspector.cli.terminal import one_line

if TYPE_CHECKING:
    from estimator.results import Run

NAME = "run"
HELP = (
    "Run the estimator over a log (baseline and proposed by default) and print the paper's "
    "table of route deviations in the GNSS-degraded intervals, plus truth errors when the log "
    "has ground truth."
)

METHODS: tuple[Method, ...] = ("baseline", "proposed", "paper")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", metavar="LOG", help=LOG_FORMATS_TEXT)
    parser.add_argument(
        "--route",
        metavar="ROUTE",
        default=None,
        help=f"route file ({ROUTE_FORMATS_TEXT}; default: LOG's <name>.route.* beside it)",
    )
    add_route_feature_option(parser)
    add_outage_option(parser)
    parser.add_argument(
        "--method",
        nargs="+",
        choices=METHODS,
        default=None,
        help="methods to run (default: baseline proposed)",
    )
    parser.add_argument("--json", metavar="OUT", type=Path, help="write the results as JSON")
    parser.add_argument(
        "--csv", metavar="OUT", type=Path, help="write every method's output epochs as CSV"
    )
    parser.add_argument(
        "--subtract-lane-offset",
        action="store_true",
        help="measure route deviations from the learned lane instead of the route line",
    )
    parser.add_argument(
        "--check-exits",
        action="store_true",
        help="exit with status 5 when routefuse's estimate (--method proposed) ended an outage "
        "farther from the fixes after it than its sigmas allow: a gate for CI over logs "
        "without ground truth (docs/integrity.md, 'The exit check')",
    )
    parser.add_argument(
        "--quiet", action="store_true", help="no progress on stderr (errors still print)"
    )
    add_topic_options(parser)
    add_param_options(parser)


class _Progress:
    """One status line on stderr, rewritten in place on a terminal; silent for quick runs."""

    def __init__(self, *, enabled: bool) -> None:
        self.enabled = enabled
        self.tty = sys.stderr.isatty()
        self.started = time.perf_counter()
        self.shown = False
        self.last_print = 0.0
        self.stage = ""
        self.finished = False

    def __call__(self, stage: str, fraction: float) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.started < 1.0 and fraction < 1.0:
            return
        new_stage = stage != self.stage
        if new_stage:
            self.stage, self.finished = stage, False
        elif self.finished or (
            fraction < 1.0 and now - self.last_print < (0.2 if self.tty else 5.0)
        ):
            return
        self.finished = fraction >= 1.0
        self.last_print, self.shown = now, True
        line = f"routefuse run: {stage} {100 * min(fraction, 1.0):3.0f}%"
        if self.tty:
            print("\r" + line.ljust(50), end="", file=sys.stderr, flush=True)
        else:
            print(line, file=sys.stderr, flush=True)

    def done(self) -> None:
        if self.enabled and self.tty and self.shown:
            print(file=sys.stderr, flush=True)


def _epoch_rows(r: Run) -> list[list[Any]]:
    import numpy as np

    e = r.epochs
    geo = r.frame.to_geodetic(e.position)
    att = np.degrees(e.attitude)
    rows = []
    for i in range(len(e)):
        rows.append(
            [
                r.method,
                f"{e.t[i] - r.t0:.3f}",
                f"{geo[i, 0]:.9f}",
                f"{geo[i, 1]:.9f}",
                f"{geo[i, 2]:.3f}",
                *(f"{v:.3f}" for v in e.position[i]),
                *(f"{v:.3f}" for v in e.velocity[i]),
                *(f"{v:.3f}" for v in att[i]),
                *(f"{v:.3f}" for v in e.position_sigma[i]),
                f"{np.degrees(e.yaw_sigma[i]):.4f}",
                int(e.gnss_used[i]),
                int(e.degraded[i]),
                f"{e.position_cov_en[i]:.6g}",
            ]
        )
    return rows


_CSV_HEADER = [
    "method", "t_s", "lat_deg", "lon_deg", "height_m", "east_m", "north_m", "up_m",
    "v_east_m_s", "v_north_m_s", "v_up_m_s", "roll_deg", "pitch_deg", "yaw_deg",
    "sigma_east_m", "sigma_north_m", "sigma_up_m", "sigma_yaw_deg", "gnss_used", "degraded",
    "cov_east_north_m2",
]  # fmt: skip


def execute(args: argparse.Namespace) -> int:
    # imported here, not above: building the parser (``routefuse --help``) stays light
    from estimator.evaluation import format_table, match_summary, method_metrics
    from estimator.evaluation.document import results_document
    from estimator.pipeline import open_inputs, run_methods

    params = params_from_args(args)
    outages = [parse_outage(o) for o in args.outage]
    methods: list[Method] = list(dict.fromkeys(args.method or ("baseline", "proposed")))
    if args.check_exits and "proposed" not in methods:
        raise RoutefuseError("--check-exits", "checks routefuse's run: add proposed to --method")
    # the inputs' and outputs' problems before any work: the log's own first, then the route's
    # (given or beside the log), then the output files' folders
    route_path = route_for(check_log(args.log), args.route)
    for out in (args.json, args.csv):
        if out is not None:
            check_output_file(out)
    progress = _Progress(enabled=not args.quiet)
    inputs = open_inputs(
        Path(args.log),
        route_path,
        topics=TopicChoice.from_args(args),
        route_feature=args.route_feature,
        progress=lambda f: progress("loading", f),
    )
    log, route = inputs.log, inputs.route
    assert route is not None
    runs = run_methods(inputs, params, methods=methods, outages=outages, progress=progress).runs
    progress.done()

    named: dict[str, Run] = {method: r for method, r in runs.items()}
    metrics = {
        method: method_metrics(
            r, route, log, subtract_lane_offset=args.subtract_lane_offset, params=r.params
        )
        for method, r in named.items()
    }
    print(format_table([(Path(args.log).name, method, m) for method, m in metrics.items()]))
    _print_notes(named, {m: match_summary(r) for m, r in named.items() if m != "baseline"})
    if all(m.truth is None for m in metrics.values()):
        print(NO_TRUTH)
    if args.json is not None:
        doc = results_document(
            args.log,
            str(route_path),
            log,
            named,
            metrics,
            outages=outages,
            lane_offset_subtracted=args.subtract_lane_offset,
        )
        try:
            args.json.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
        except OSError as exc:
            raise RoutefuseError(args.json, f"cannot write: {exc.strerror or exc}") from None
    if args.csv is not None:
        _write_csv(args.csv, named.values())
    if args.check_exits and any(x.overconfident for x in named["proposed"].exits):
        return ExitCode.EXIT_CHECK_FAILED
    return ExitCode.OK


NO_TRUTH = (
    "no ground truth in this log: the table gives the deviation from the route only, which "
    "rewards following a wrong map (the accuracy needs a truth topic, *truth*)"
)


def _print_notes(runs: dict[str, Run], summaries: dict[str, dict[str, Any]]) -> None:
    """The degraded intervals, each matching method's match counts, the fixes its portal
    re-runs left out and its map biases, the runs' warnings."""
    from estimator.evaluation import run_notes

    first = next(iter(runs.values()))
    intervals = [[a - first.t0, b - first.t0] for a, b in first.degraded_intervals]
    if intervals:
        spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in intervals)
        print(f"\nGNSS-degraded: {spans} (metrics over these intervals)")
    else:
        print("\nno GNSS-degraded interval in this log: every metric is empty (use --outage)")
    for method, s in summaries.items():
        rejected = ", ".join(f"{k} {v}" for k, v in s["rejected"].items()) or "none"
        print(
            f"{method}: {s['accepted']} of {s['attempted']} matches accepted; "
            f"rejected by {rejected}"
        )
    for method, r in runs.items():
        for note in run_notes(r):
            print(f"{method}: {note}")
    for warning in dict.fromkeys(w for r in runs.values() for w in r.warnings):
        print(f"routefuse run: warning: {one_line(warning)}", file=sys.stderr)


def _write_csv(path: Path, runs: Iterable[Run]) -> None:
    try:
        with path.open("w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f)
            writer.writerow(_CSV_HEADER)
            for r in runs:
                writer.writerows(_epoch_rows(r))
    except OSError as exc:
        raise RoutefuseError(path, f"cannot write: {exc.strerror or exc}") from None
