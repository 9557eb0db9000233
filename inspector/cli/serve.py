"""``routefuse serve``: the inspector in the browser."""

from __future__ import annotations

import argparse
import errno
import ipaddress
import math
import socket
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from estimator.errors import LogError, RoutefuseError, TopicError
from estimator.io import AUTO_TOPICS, TopicChoice, route_beside
from estimator.io.registry import check_log_exists
from inspector.cli.checks import check_log, route_for
from inspector.cli.options import (
    add_outage_option,
    add_param_options,
    add_route_feature_option,
    add_topic_options,
    params_from_args,
    parse_outage,
)
from inspector.cli.samples import (
    DEFAULT_SAMPLE,
    DEFAULT_TRAP_ROUTE,
    find_sample_logs,
    sample_log_candidates,
)
from inspector.cli.terminal import one_line

if TYPE_CHECKING:
    import viser

    from estimator.params import Params
    from inspector.app import InspectorApp
    from inspector.controller import Controller, RouteFeature, Session

MatchingMethod = Literal["proposed", "paper"]

NAME = "serve"
HELP = (
    "open a log and its route in the browser inspector: step the estimator, scrub, debug "
    "every match attempt, tune parameters live; --outage (or the GNSS outages field) removes "
    "GNSS from an open-sky log to make it a tunnel test"
)

SAMPLE_LOGS = find_sample_logs()
"""The bundled samples (None when this install has none): always listed in the file picker."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "log",
        nargs="?",
        metavar="LOG",
        help=f"log to open (default: the bundled {DEFAULT_SAMPLE} sample, with a trap route)",
    )
    parser.add_argument(
        "--route", metavar="ROUTE", help="route file (default: LOG's <name>.route.* beside it)"
    )
    add_route_feature_option(parser)
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)"
    )
    parser.add_argument("--port", type=int, default=8080, help="port (default 8080)")
    parser.add_argument(
        "--allow-origin",
        metavar="URL",
        action="append",
        default=[],
        help="also accept browser connections from pages of this origin (http://HOST:PORT; "
        "repeatable). By default only the inspector's own page may connect: a page of any "
        "other site cannot drive the inspector",
    )
    parser.add_argument(
        "--data-dir",
        metavar="DIR",
        action="append",
        default=[],
        help="also list logs and routes under DIR in the file picker "
        "(repeatable; the bundled sample_logs are always listed)",
    )
    parser.add_argument(
        "--max-upload-mb",
        type=float,
        default=100.0,
        help="largest file a browser may upload (default 100 MB)",
    )
    parser.add_argument(
        "--method",
        choices=("proposed", "paper"),
        default="proposed",
        help="method compared against the baseline (default proposed)",
    )
    add_topic_options(parser)
    add_outage_option(parser)
    add_param_options(parser)


def resolve_inputs(log: str | None, route: str | None) -> tuple[Path, Path]:
    """The log and route to open first (the bundled sample when no log is given)."""
    if log is None:
        if SAMPLE_LOGS is None:
            looked = ", ".join(str(p) for p in sample_log_candidates())
            raise RoutefuseError(
                f"{DEFAULT_SAMPLE}.mcap",
                f"the bundled sample log is not installed (looked in {looked}); give a LOG",
            )
        log_path = SAMPLE_LOGS / f"{DEFAULT_SAMPLE}.mcap"
        trap = SAMPLE_LOGS / DEFAULT_TRAP_ROUTE
        if route is None and trap.is_file():
            return log_path, trap
    else:
        log_path = Path(log).expanduser()
        check_log_exists(log_path)
    if route is None and route_beside(log_path) is None:
        # the log's own problem first (a bad log with its route beside it is the inspector's to
        # report, and the server stays up for another one)
        check_log(log_path)
    route_path = route_for(log_path, route)
    return log_path.resolve(), route_path.resolve()


def resolve_route_line(route: Path, feature: str | None) -> int | str | None:
    """The line of the first route to open, checked before the server starts as ``run`` checks
    it: a file holding several lines given without --route-feature, or with one naming none of
    them, is a one-line error saying to give --route-feature. Returns the chosen line's index
    (None for a file's only line, when none was given). A route file that cannot be read is
    left to the inspector, which reports it with the server up (``feature`` returned as is)."""
    from estimator.errors import RouteError
    from estimator.io.routefile import choose_line, route_line_names

    try:
        names = route_line_names(route)
    except RouteError:
        return feature
    if not names:
        return feature
    index = choose_line(route, names, feature)
    return None if feature is None else index


def check_topics(log: Path, topics: TopicChoice) -> None:
    """The topics chosen, checked against the first log before the server starts, as ``run``
    checks them: several topics of a kind and none chosen is a one-line error saying to give
    --imu-topic (or whichever kind), and so is a topic given that the log lacks (or of another
    type), or --wheel-topic with --no-wheel; no server starts. A log whose topics cannot be
    read, or that lacks an IMU or GNSS topic when no topic was given, is left to the
    inspector, which reports it with the server up."""
    from estimator.io import describe_topics
    from estimator.io.topics import topic_roles

    try:
        types = {topic: msgtype for topic, (msgtype, _) in describe_topics(log).items()}
    except LogError:
        return
    try:
        topic_roles(log, types, topics)
    except TopicError:
        raise
    except LogError:
        if any((topics.imu, topics.gnss, topics.wheel, topics.truth)):
            raise


def topics_text(topics: TopicChoice) -> str:
    """The topic options given, as on the command line ('' for none)."""
    given = [
        f"--{kind}-topic {name}"
        for kind in ("imu", "gnss", "wheel", "truth")
        if (name := getattr(topics, kind)) is not None
    ]
    return ", ".join([*given, *(["--no-wheel"] if topics.no_wheel else [])])


MAX_UPLOAD_MB = 100_000.0
"""--max-upload-mb beyond this (100 GB) is a typo."""


def check_listen_address(host: str, port: int) -> None:
    """A one-line error for an address the server cannot listen on: viser printed a traceback
    for a port out of range and then waited forever, and retried an invalid address forever.
    A port in use is left to viser, which moves to the next free one."""
    if not 0 <= port <= 65535:
        raise RoutefuseError("--port", f"{port} is outside [0, 65535]")
    if host and all(c.isdigit() or c == "." for c in host):
        try:
            ipaddress.ip_address(host)
        except ValueError:
            raise RoutefuseError("--host", f"{host[:60]!r} is not an IP address") from None
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (OSError, UnicodeError) as exc:
        raise RoutefuseError("--host", f"cannot resolve {host[:60]!r} ({exc})") from None
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                raise RoutefuseError(
                    "--host", f"cannot listen on {host[:60]}:{port} ({exc.strerror or exc})"
                ) from None


class TerminalProgress:
    """Loading progress on the terminal: a line per stage (decoding, baseline, proposed,
    views) and per quarter of it, not one per callback."""

    def __init__(self) -> None:
        self._last: tuple[str, int] = ("", -1)

    def __call__(self, fraction: float, message: str) -> None:
        quarter = min(int(fraction * 4), 4)
        if (message, quarter) == self._last or fraction >= 1.0:
            return
        self._last = (message, quarter)
        print(f"  {message} ({100 * fraction:.0f} %)", flush=True)


def kernels_cached() -> bool:
    """Whether numba's cache of the filter kernels is on disk beside them (else the first run
    compiles them)."""
    from importlib.util import find_spec

    spec = find_spec("estimator.filter")
    if spec is None or spec.origin is None:
        return False
    return any((Path(spec.origin).parent / "__pycache__").glob("*.nbi"))


def start(
    *,
    host: str,
    port: int,
    data_dirs: list[str | Path],
    log: Path | None = None,
    route: Path | None = None,
    route_feature: RouteFeature = None,
    params: Params | None = None,
    method: MatchingMethod = "proposed",
    topics: TopicChoice = AUTO_TOPICS,
    outages: Sequence[tuple[float, float]] = (),
    max_upload_bytes: int = 100 * 1024 * 1024,
    allow_origins: Sequence[str] = (),
    verbose: bool = False,
) -> tuple[viser.ViserServer, Controller, InspectorApp]:
    """Start the server and the controller (returns ``(server, controller, app)``; used by the
    command and by the tests). ``outages`` are injected into the first log only: they are
    times in that log; ``route_feature`` is the line of its route file; ``topics`` (--imu-topic
    ... --no-wheel) apply to every log opened, this one and those of the Files tab. Websocket
    connections are accepted only from the server's own origin and ``allow_origins``
    (:mod:`inspector.origin_guard`)."""
    import viser

    from inspector import origin_guard
    from inspector.app import InspectorApp
    from inspector.controller import Controller
    from inspector.folders import DataFolders, UploadFolder

    roots = [*([SAMPLE_LOGS] if SAMPLE_LOGS is not None else []), *data_dirs]
    for d in data_dirs:
        if not Path(d).is_dir():
            raise RoutefuseError(d, "--data-dir is not a folder")
    controller = Controller(
        DataFolders.of(*roots),
        uploads=UploadFolder(max_bytes=max_upload_bytes),
        params=params,
        method=method,
        topics=topics,
    )
    try:
        origin_guard.install(allow_origins)
    except ValueError as exc:
        raise RoutefuseError("--allow-origin", str(exc)) from None
    server = viser.ViserServer(host=host, port=port, verbose=verbose)
    app = InspectorApp(server, controller)
    if log is not None and route is not None:
        open_first(controller, log, route, outages, route_feature=route_feature)
    return server, controller, app


def open_first(
    controller: Controller,
    log: Path,
    route: Path,
    outages: Sequence[tuple[float, float]] = (),
    *,
    route_feature: RouteFeature = None,
) -> None:
    """Start loading the log given on the command line (with the outages injected into it, and
    the line ``route_feature`` of its route file)."""
    controller.open(
        log,
        route,
        log_name=_listed_name(controller, log, "log"),
        route_name=_listed_name(controller, route, "route"),
        outages=outages,
        route_feature=route_feature,
    )


def _listed_name(controller: Controller, path: Path, kind: str) -> str:
    listing = controller.folders.listing()
    table = listing.logs if kind == "log" else listing.routes
    for name, p in table.items():
        if p == path:
            return name
    return path.name


def execute(args: argparse.Namespace) -> int:
    from inspector.folders import exit_on_termination_signals
    from inspector.timeline import format_outages, normalise_outages

    if not (math.isfinite(args.max_upload_mb) and 0 < args.max_upload_mb <= MAX_UPLOAD_MB):
        raise RoutefuseError(
            "--max-upload-mb", f"{args.max_upload_mb} is not in (0, {MAX_UPLOAD_MB}]"
        )
    check_listen_address(args.host, args.port)
    params = params_from_args(args)
    outages = tuple(parse_outage(o) for o in args.outage)
    log, route = resolve_inputs(args.log, args.route)
    route_feature = resolve_route_line(route, args.route_feature)
    topics = TopicChoice.from_args(args)
    check_topics(log, topics)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(
            f"routefuse: warning: binding {args.host}: anyone who can reach this address can "
            "open the logs under the data folders and upload files",
            file=sys.stderr,
        )
    exit_on_termination_signals()  # SIGTERM / SIGHUP still remove the upload folder
    server, controller, app = start(
        host=args.host,
        port=args.port,
        data_dirs=args.data_dir,
        params=params,
        method=args.method,
        topics=topics,
        outages=outages,
        max_upload_bytes=int(args.max_upload_mb * 1e6),
        allow_origins=args.allow_origin,
    )
    shown = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
    print(f"routefuse inspector: http://{shown}:{server.get_port()}  (Ctrl+C to stop)", flush=True)
    injected = (
        f" and GNSS outages {format_outages(normalise_outages(outages))} s" if outages else ""
    )
    line = "" if route_feature is None else f" (line {route_feature})"
    chosen = f" ({topics_text(topics)})" if topics != AUTO_TOPICS else ""
    print(f"loading {log.name}{chosen} with route {route.name}{line}{injected} ...", flush=True)
    if not kernels_cached():
        print(
            "(the first run on this machine compiles the filter kernels: about half a minute, "
            "then they are cached)",
            flush=True,
        )

    def loaded(session: Session) -> None:
        tl = session.timeline
        rejected = int((~tl.match_accepted).sum())
        print(
            f"loaded {session.log_name}: {tl.duration:.0f} s, {tl.n_frames} frames, "
            f"{len(tl.match_t)} match attempts ({rejected} rejected)",
            flush=True,
        )

    # Ctrl+C from here on, during the first load too, closes the server as at any later time
    try:
        controller.subscribe(
            on_progress=TerminalProgress(),
            on_session=loaded,
            on_error=lambda exc: print(
                f"routefuse: error: {one_line(str(exc))}", file=sys.stderr, flush=True
            ),
        )
        # after subscribing: an early failure prints
        open_first(controller, log, route, outages, route_feature=route_feature)
        for warning in controller.folders.listing().warnings:
            print(
                f"routefuse serve: warning: {one_line(warning[:300])}", file=sys.stderr, flush=True
            )
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        app.close()
        controller.close()
        server.stop()
    return 0
