"""The inspector's session state, without any UI: which files are offered, what is loaded, the
current runs, and the one worker thread that (re)runs the estimator.

Every browser tab shares one :class:`Controller`. Tabs only read its immutable
:class:`Session`; they change it through requests (open files, set parameters) that the worker
serves with the latest request winning, so a slider dragged across ten values costs at most two
runs, and a tab never sees a half-built session.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from estimator.errors import RoutefuseError, WhereToChoose
from estimator.io.topics import AUTO_TOPICS, TopicChoice
from estimator.params import Params
from estimator.results import Run
from inspector.browser_values import (
    PROPOSED_METHODS,
    ProposedMethod,
    checked_method,
    with_param,
)
from inspector.folders import DataFolders, Kind, Listing, UploadFolder
from inspector.scene_data import SceneData
from inspector.timeline import (
    Outages,
    Playhead,
    Timeline,
    format_outages,
    normalise_outages,
    parse_outages,
)

if TYPE_CHECKING:
    from estimator.params import Method
    from estimator.pipeline import Inputs, MethodRuns
    from estimator.pipeline import MethodRunner as RunFn
    from inspector.offroute import OffRoute
    from inspector.plots import DeviationPlot


__all__ = [
    "PROPOSED_METHODS",
    "Controller",
    "DataFolders",
    "Kind",
    "Listing",
    "Outages",
    "Playhead",
    "ProposedMethod",
    "Session",
    "Superseded",
    "Timeline",
    "UploadFolder",
    "checked_method",
    "format_outages",
    "normalise_outages",
    "parse_outages",
    "with_param",
]


RouteFeature = str | int | None
"""which line of a route file holding several: an index, or text as ``--route-feature`` reads
it (a name, else an index); None for a file's only line"""


@dataclass(frozen=True)
class Session:
    """Everything loaded and computed, immutable: tabs draw from it without locks."""

    version: int
    log_path: Path
    route_path: Path
    log_name: str
    route_name: str
    inputs: Inputs
    """log, route and frame (tests hand in a stand-in with the same fields)"""
    params: Params
    method: ProposedMethod
    outages: Outages
    """the GNSS outages injected into both runs"""
    baseline: Run
    proposed: Run
    timeline: Timeline
    scene: SceneData
    metrics: tuple[tuple[str, str, str], ...]
    """rows (quantity, baseline, proposed) of the ``routefuse run`` table"""
    deviation: DeviationPlot
    """the deviation plots of both runs"""
    timings: dict[str, float] = field(default_factory=dict)
    off_route: OffRoute | None = None
    """the proposed run against the route (None for hand-built sessions)"""
    route_feature: RouteFeature = None
    """the line of a route file holding several (its index, or as ``--route-feature`` reads
    text); None: the file's only line"""
    topics: TopicChoice = AUTO_TOPICS
    """the log's topics chosen by ``routefuse serve --imu-topic`` ... (``--no-wheel``)"""


@dataclass(frozen=True)
class _Request:
    version: int
    log_path: Path
    route_path: Path
    log_name: str
    route_name: str
    params: Params
    method: ProposedMethod
    outages: Outages
    route_feature: RouteFeature
    topics: TopicChoice

    @classmethod
    def of(
        cls,
        version: int,
        base: _Request | Session | None,
        initial: dict[str, Any],
        changes: dict[str, Any],
    ) -> _Request:
        """``base`` (or, before the first load, the ``initial`` choices) with ``changes``."""
        fields_ = (
            dict(initial)
            if base is None
            else {k: getattr(base, k) for k in _REQUEST_FIELDS if k != "version"}
        )
        fields_.update(changes)
        return cls(version=version, **fields_)

    def same_target(self, other: _Request | Session | None) -> bool:
        """Would ``other`` show the same runs? (everything a run depends on)"""
        if other is None:
            return False
        return (
            self.log_path,
            self.route_path,
            self.route_feature,
            self.topics,
            self.params,
            self.method,
            self.outages,
        ) == (
            other.log_path,
            other.route_path,
            other.route_feature,
            other.topics,
            other.params,
            other.method,
            other.outages,
        )


_REQUEST_FIELDS = tuple(f.name for f in fields(_Request))


class Superseded(Exception):
    """Raised inside a run's progress callback when a newer request has arrived."""


ProgressListener = Callable[[float, str], None]
SessionListener = Callable[[Session], None]
ErrorListener = Callable[[RoutefuseError], None]


class _Listeners:
    """Who is told of progress (kind 0), new sessions (1) and failures (2), on the worker
    thread; a listener that raises does not keep the others from hearing."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._entries: list[
            tuple[ProgressListener | None, SessionListener | None, ErrorListener | None]
        ] = []

    def add(
        self,
        entry: tuple[ProgressListener | None, SessionListener | None, ErrorListener | None],
    ) -> Callable[[], None]:
        with self._lock:
            self._entries.append(entry)

        def remove() -> None:
            with self._lock:
                if entry in self._entries:
                    self._entries.remove(entry)

        return remove

    def emit(self, kind: int, *args: Any) -> None:
        with self._lock:
            listeners = [entry[kind] for entry in self._entries]
        for fn in listeners:
            if fn is None:
                continue
            try:
                fn(*args)
            except Exception:
                traceback.print_exc()


class StageProgress(Protocol):
    """One stage's share of the progress bar: how far it is, and optionally what it does."""

    def __call__(self, fraction: float = 0.0, message: str = "", /, *_: Any) -> None: ...


ROUTE_LINE_FIELD = "route line"
"""the Files tab's control that chooses the line of a route file holding several"""
IN_THE_INSPECTOR = WhereToChoose(
    route_line=f"under '{ROUTE_LINE_FIELD}' in the Files tab, then press 'open'",
    topic="by restarting 'routefuse serve' with --{kind}-topic TOPIC",
)
"""where a browser user chooses a route file's line (the Files tab) and a log's topic (the
topics are chosen for the whole server, on its command line)"""
MAX_FEATURE_CHARS = 200
"""a line name longer than this is not a line name (a browser may send anything)"""

Opener = Callable[[Path, Path, Callable[[float], None], RouteFeature, TopicChoice], "Inputs"]


def _default_open(
    log_path: Path,
    route_path: Path,
    progress: Callable[[float], None],
    route_feature: RouteFeature,
    topics: TopicChoice = AUTO_TOPICS,
) -> Inputs:
    from estimator.pipeline.inputs import open_inputs

    return open_inputs(
        log_path,
        route_path,
        topics=topics,
        route_feature=route_feature,
        where_to_choose=IN_THE_INSPECTOR,
        progress=progress,
    )


def checked_route_feature(value: object) -> RouteFeature:
    """``value`` as a route line choice (None, an index, or a name up to
    :data:`MAX_FEATURE_CHARS`); anything else a one-line :class:`RoutefuseError`."""
    if value is None or (isinstance(value, int) and not isinstance(value, bool)):
        return value
    if isinstance(value, str) and len(value) <= MAX_FEATURE_CHARS:
        return value
    shown = str(value)[:60]
    raise RoutefuseError(ROUTE_LINE_FIELD, f"{shown!r} is not a line's name or index")


def _default_run(
    inputs: Inputs,
    params: Params,
    method: Method,
    progress: Callable[[float], None],
    reuse: Run | None,
    *,
    outages: Outages,
) -> Run:
    """How the worker runs one method (tests substitute a fake :data:`RunFn`)."""
    from estimator.pipeline import run_method

    return run_method(inputs, params, method, progress, reuse, outages=outages)


class Controller:
    """Shared session state and the single re-run worker.

    Requests (:meth:`open`, :meth:`set_params`, ...) return at once; the worker serves the
    latest one. A run in progress is abandoned at its next progress report when a newer request
    arrives. A request that fails leaves the previous session in place and is reported to the
    error listeners. ``topics`` (``routefuse serve --imu-topic`` ... ``--no-wheel``) apply to
    every log opened, unless :meth:`open` is given others.
    """

    def __init__(
        self,
        folders: DataFolders,
        *,
        uploads: UploadFolder | None = None,
        params: Params | None = None,
        method: ProposedMethod = "proposed",
        topics: TopicChoice = AUTO_TOPICS,
        opener: Opener = _default_open,
        runner: RunFn = _default_run,
    ) -> None:
        self.uploads = uploads
        self._folders = folders.with_root(uploads.path) if uploads else folders
        self._opener = opener
        self._runner = runner
        self._initial_params = params or Params()
        self._initial_method: ProposedMethod = method
        self._initial_outages: Outages = ()
        self._topics = topics
        self._cond = threading.Condition()
        self._wanted: _Request | None = None
        self._done_version = 0
        self._busy = False
        self._version = 0
        self._session: Session | None = None
        self._inputs_cache: tuple[tuple[Path, Path, RouteFeature, TopicChoice], Inputs] | None = (
            None
        )
        self._lines_cache: dict[tuple[Path, int, int], tuple[str, ...]] = {}
        self._closed = False
        self._listeners = _Listeners()
        self._thread = threading.Thread(target=self._work, name="routefuse-runner", daemon=True)
        self._thread.start()

    # -- reading --------------------------------------------------------------------------

    @property
    def folders(self) -> DataFolders:
        return self._folders

    @property
    def session(self) -> Session | None:
        return self._session

    def _latest(self) -> _Request | Session | None:
        with self._cond:
            return self._wanted or self._session

    @property
    def params(self) -> Params:
        """The parameters of the latest request (what the panel should show)."""
        latest = self._latest()
        return latest.params if latest else self._initial_params

    @property
    def method(self) -> ProposedMethod:
        latest = self._latest()
        return latest.method if latest else self._initial_method

    @property
    def outages(self) -> Outages:
        """The injected GNSS outages of the latest request (what the outage field shows)."""
        latest = self._latest()
        return latest.outages if latest else self._initial_outages

    @property
    def busy(self) -> bool:
        with self._cond:
            return self._pending()

    def _pending(self) -> bool:
        return self._busy or (
            self._wanted is not None and self._wanted.version > self._done_version
        )

    def subscribe(
        self,
        *,
        on_progress: ProgressListener | None = None,
        on_session: SessionListener | None = None,
        on_error: ErrorListener | None = None,
    ) -> Callable[[], None]:
        """Register listeners (called on the worker thread); returns the unsubscribe call."""
        return self._listeners.add((on_progress, on_session, on_error))

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until every request so far has been served (tests, the CLI)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    # -- requests -------------------------------------------------------------------------

    def open_named(
        self,
        log_name: str,
        route_name: str,
        *,
        route_feature: RouteFeature = None,
        topics: TopicChoice | None = None,
    ) -> None:
        """Open a log and a route by their names in :meth:`DataFolders.listing`
        (``route_feature``: the line of a route file holding several; ``topics``: the log's
        topics, by default the server's)."""
        log_path = self._folders.resolve(log_name, "log")
        route_path = self._folders.resolve(route_name, "route")
        self.open(
            log_path,
            route_path,
            log_name=log_name,
            route_name=route_name,
            route_feature=route_feature,
            topics=topics,
        )

    @property
    def topics(self) -> TopicChoice:
        """The topics of the latest request (the server's before anything is loaded)."""
        latest = self._latest()
        return latest.topics if latest else self._topics

    @property
    def route_feature(self) -> RouteFeature:
        """The route line of the latest request."""
        latest = self._latest()
        return latest.route_feature if latest else None

    def route_lines(self, route_name: str) -> tuple[str, ...]:
        """The names of the lines of a listed route file, in order (what the Files tab offers
        to choose among); () when it cannot be read (opening it says why). Read again only
        when the file changed."""
        from estimator.io.routefile import route_line_names

        try:
            path = self._folders.resolve(route_name, "route")
            info = path.stat()
        except (RoutefuseError, OSError):
            return ()
        key = (path, info.st_mtime_ns, info.st_size)
        with self._cond:
            cached = self._lines_cache.get(key)
        if cached is not None:
            return cached
        try:
            names = route_line_names(path)
        except RoutefuseError:
            names = ()
        with self._cond:
            if len(self._lines_cache) > 64:
                self._lines_cache.clear()
            self._lines_cache[key] = names
        return names

    def open(
        self,
        log_path: Path,
        route_path: Path,
        *,
        log_name: str | None = None,
        route_name: str | None = None,
        outages: Iterable[tuple[float, float]] | None = None,
        route_feature: RouteFeature = None,
        topics: TopicChoice | None = None,
    ) -> None:
        """Open files by path (the CLI's arguments; the UI goes through :meth:`open_named`).
        ``route_feature`` picks the line of a route file holding several (checked by the
        worker, which reads the file: a file with several lines and none chosen, or no such
        line, is reported and the session before is kept). ``topics`` choose the log's topics
        (None: the server's, ``routefuse serve --imu-topic`` ...; a topic the log lacks, or
        several of a kind and none chosen, is reported likewise).

        Outages are times in one log, so another log starts with none unless ``outages`` says
        otherwise; the same log with another route keeps them (the tunnel test goes on)."""
        route_feature = checked_route_feature(route_feature)
        log_path = Path(log_path).resolve()
        if outages is not None:
            kept = normalise_outages(outages)
        else:
            with self._cond:
                current = self._wanted or self._session
                if current is None:  # typed before anything was loaded: for this log
                    kept = self._initial_outages
                else:
                    kept = current.outages if current.log_path == log_path else ()
        self._request(
            log_path=log_path,
            route_path=Path(route_path).resolve(),
            log_name=log_name or log_path.name,
            route_name=route_name or Path(route_path).name,
            outages=kept,
            route_feature=route_feature,
            topics=self._topics if topics is None else topics,
        )

    def save_upload(self, filename: str, content: bytes) -> str:
        """Store an uploaded file; returns its name in the listing."""
        if self.uploads is None:
            raise RoutefuseError(filename, "uploads are disabled on this server")
        path = self.uploads.save(filename, content)
        listing = self._folders.listing()
        for name, p in (*listing.logs.items(), *listing.routes.items()):
            if p == path:
                return name
        raise RoutefuseError(filename, "the upload could not be listed")

    def set_params(self, params: Params) -> None:
        self._request(params=params)

    def set_param(self, name: str, value: Any) -> None:
        """Change one parameter by dotted name (checked at once by :func:`with_param`: a bad
        value raises :class:`ConfigError` here, not on the worker)."""
        self.set_params(with_param(self.params, name, value))

    def reset_params(self) -> None:
        self.set_params(Params())

    def set_method(self, method: ProposedMethod) -> None:
        """Compare another method with the baseline (anything else is refused here)."""
        self._request(method=checked_method(method))

    def check_choice(self, name: str, kind: Kind) -> None:
        """Refuse a file name that is not in the listing (what a file dropdown may show)."""
        self._folders.resolve(name, kind)

    def set_outages(self, outages: Iterable[tuple[float, float]]) -> None:
        """Inject GNSS outages into the loaded log (checked at once; a start after the end of
        the log is reported by the worker, which knows the log's length)."""
        self._request(outages=normalise_outages(outages))

    def _request(self, **changes: Any) -> None:
        with self._cond:
            base = self._wanted or self._session
            if base is None and "log_path" not in changes:
                # Nothing loaded yet: remember the choice for the first load.
                if "params" in changes:
                    self._initial_params = changes["params"]
                if "method" in changes:
                    self._initial_method = changes["method"]
                if "outages" in changes:
                    self._initial_outages = changes["outages"]
                return
            initial = {
                "params": self._initial_params,
                "method": self._initial_method,
                "outages": self._initial_outages,
                "route_feature": None,
                "topics": self._topics,
            }
            self._version += 1
            req = _Request.of(self._version, base, initial, changes)
            if req.same_target(self._wanted) or (
                self._wanted is None and not self._busy and req.same_target(self._session)
            ):
                self._version -= 1
                return
            self._wanted = req
            self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout=5)
        if self.uploads is not None:
            self.uploads.close()

    # -- the worker -----------------------------------------------------------------------

    def _emit(self, kind: int, *args: Any) -> None:
        self._listeners.emit(kind, *args)

    def _superseded(self, req: _Request) -> bool:
        with self._cond:
            return self._closed or (
                self._wanted is not None
                and self._wanted.version > req.version
                and not self._wanted.same_target(req)
            )

    def _work(self) -> None:
        while True:
            with self._cond:
                while not self._closed and (
                    self._wanted is None or self._wanted.version <= self._done_version
                ):
                    self._cond.wait()
                if self._closed:
                    return
                req = self._wanted
                assert req is not None
                self._busy = True
            try:
                session = self._serve(req)
            except Superseded:
                session = None
            except RoutefuseError as exc:
                session = None
                self._fail(req, exc)
            except Exception as exc:  # a bug must not kill the worker or the server
                traceback.print_exc()
                session = None
                self._fail(
                    req,
                    RoutefuseError(req.log_name, f"internal error: {type(exc).__name__}: {exc}"),
                )
            with self._cond:
                self._busy = False
                if session is not None:
                    self._session = session
                self._done_version = max(self._done_version, req.version)
                if self._wanted is not None and self._wanted.version <= self._done_version:
                    self._wanted = None
                self._cond.notify_all()
            if session is not None:
                self._emit(1, session)

    def _fail(self, req: _Request, exc: RoutefuseError) -> None:
        """Forget a failed request (unless a newer one waits) and report it."""
        with self._cond:
            if self._wanted is not None and self._wanted.version == req.version:
                self._wanted = None
                self._done_version = max(self._done_version, req.version)
        self._emit(2, exc)

    def _serve(self, req: _Request) -> Session:
        timings: dict[str, float] = {}
        prev = self._session

        def stage(lo: float, hi: float, what: str) -> StageProgress:
            def report(fraction: float = 0.0, message: str = "", *_: Any) -> None:
                if self._superseded(req):
                    raise Superseded
                f = float(np.clip(fraction, 0.0, 1.0)) if np.isfinite(fraction) else 0.0
                self._emit(0, lo + (hi - lo) * f, message or what)

            return report

        key = (req.log_path, req.route_path, req.route_feature, req.topics)
        t_start = time.perf_counter()
        prev_key = (
            None
            if prev is None
            else (prev.log_path, prev.route_path, prev.route_feature, prev.topics)
        )
        if prev is not None and prev_key == key:
            inputs = prev.inputs
        elif self._inputs_cache is not None and self._inputs_cache[0] == key:
            inputs = self._inputs_cache[1]
        else:
            loading = stage(0.0, 0.5, f"loading {req.log_name}")
            loading(0.0)
            inputs = self._opener(
                req.log_path, req.route_path, loading, req.route_feature, req.topics
            )
            self._inputs_cache = (key, inputs)
        timings["open_s"] = time.perf_counter() - t_start
        if self._superseded(req):
            raise Superseded
        from estimator.pipeline import run_methods

        # the previous session's runs count only on the same inputs and outages (run_methods)
        previous = None if prev is None else _runs_of(prev)
        stages = {
            "baseline": stage(0.5, 0.7, "baseline run"),
            req.method: stage(0.7, 0.95, f"{req.method} run"),
        }
        session = run_methods(
            inputs,
            req.params,
            methods=("baseline", req.method),
            outages=req.outages,
            progress=lambda m, f: stages[m](f, ""),
            reuse=previous,
            outage_option="GNSS outages",
            run_one=self._runner,
        )
        baseline, proposed = session["baseline"], session[req.method]
        timings["baseline_s"] = session.seconds["baseline"]
        timings["proposed_s"] = session.seconds[req.method]
        if self._superseded(req):
            raise Superseded
        served = _session_of(req, inputs, baseline, proposed, timings)
        self._emit(0, 1.0, "done")
        return served


def _runs_of(session: Session) -> MethodRuns:
    """A session's runs, as :func:`estimator.pipeline.run_methods` may resume from them."""
    from estimator.pipeline import MethodRuns

    return MethodRuns(
        inputs=session.inputs,
        outages=session.outages,
        runs={"baseline": session.baseline, session.method: session.proposed},
        seconds={},
    )


def _session_of(
    req: _Request, inputs: Inputs, baseline: Run, proposed: Run, timings: dict[str, float]
) -> Session:
    """The session of a served request: its runs and the views drawn from them."""
    from inspector.offroute import OffRoute
    from inspector.plots import DeviationPlot, metrics_rows

    route = inputs.route
    if route is None:  # the inspector always opens a route file with the log
        raise RoutefuseError(req.route_name, "no route was read")
    t3 = time.perf_counter()
    scene = SceneData.build(baseline=baseline, proposed=proposed, route=route, log=inputs.log)
    deviation = DeviationPlot.build(inputs, baseline, proposed)
    off_route = OffRoute.build(scene, route, req.params)
    metrics = metrics_rows(inputs, baseline, proposed)
    timings["views_s"] = time.perf_counter() - t3
    return Session(
        version=req.version,
        log_path=req.log_path,
        route_path=req.route_path,
        log_name=req.log_name,
        route_name=req.route_name,
        inputs=inputs,
        params=req.params,
        method=req.method,
        outages=req.outages,
        baseline=baseline,
        proposed=proposed,
        timeline=Timeline.of_run(proposed),
        scene=scene,
        metrics=metrics,
        deviation=deviation,
        timings=timings,
        off_route=off_route,
        route_feature=req.route_feature,
        topics=req.topics,
    )
