"""``routefuse info LOG [--route ROUTE]``: what a log holds, before running anything on it."""

from __future__ import annotations

import argparse
from pathlib import Path

from estimator.io import LOG_FORMATS_TEXT, ROUTE_FORMATS_TEXT, route_format
from inspector.cli.checks import check_log, check_route
from inspector.cli.options import add_route_feature_option, add_topic_options

NAME = "info"
HELP = (
    "Show what a log holds: topics, message types, counts, rates, time span, GNSS outages and "
    "distance travelled; with --route, the route and how far the log is from it."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "log",
        metavar="LOG",
        help=f"{LOG_FORMATS_TEXT} (or a route file, to list its lines)",
    )
    parser.add_argument(
        "--route",
        metavar="ROUTE",
        help=f"route file ({ROUTE_FORMATS_TEXT}) to compare with the log",
    )
    add_route_feature_option(parser)
    add_topic_options(parser)


def execute(args: argparse.Namespace) -> int:
    from estimator.errors import LogError
    from estimator.io import TopicChoice, load_log
    from estimator.pipeline.inputs import Inputs, frame_of, open_inputs
    from inspector.cli.summary import format_route_file, format_summary, summarize

    if route_format(args.log) is not None and args.route is None:
        print(format_route_file(Path(args.log)))
        return 0
    topics = TopicChoice.from_args(args)
    if args.route is None:
        log = load_log(Path(args.log), topics=topics)
        try:
            frame = frame_of(log)
        except LogError:
            print(format_summary(summarize(log)))
            return 0
        print(format_summary(summarize(Inputs(log, None, frame))))
        return 0
    # the log's own problem first, then a folder or missing file given as the route
    log_path = check_log(args.log)
    inputs = open_inputs(
        log_path,
        check_route(args.route),
        topics=topics,
        route_feature=args.route_feature,
    )
    print(format_summary(summarize(inputs)))
    return 0
