"""The inspector's session state, without any UI: which files are offered, what is loaded, the
current runs, and the one worker thread that (re)runs the estimator.

Every browser tab shares one :class:`Controller`. Tabs only read its immutable
:class:`Session`; they change it through requests (open files, set parameters) that the worker
serves with the latest request winning, so a slider dragged across ten values costs at most two
runs, and a tab never sees a half-built session.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from estimator.errors import ConfigError, RoutefuseError
from estimator.params import Params, with_values
from estimator.results import Run
from inspector.cli.options import parse_outage
from inspector.scene_data import SceneData

F64 = NDArray[np.float64]

ProposedMethod = Literal["proposed", "paper"]
Kind = Literal["log", "route"]
Outages = tuple[tuple[float, float], ...]
"""injected GNSS outages: (start, end) seconds after the log start, as ``--outage START:END``"""

LOG_SUFFIXES = (".mcap", ".bag", ".db3")
ROUTE_SUFFIXES = (".geojson", ".gpx", ".kml", ".csv")
DEFAULT_UPLOAD_LIMIT = 100 * 1024 * 1024


# ---------------------------------------------------------------------------------------------
# Files the user may open


def _is_route(path: Path) -> bool:
    return path.name.lower().endswith(ROUTE_SUFFIXES) or path.name.lower().endswith(".route.json")


def _is_log_file(path: Path) -> bool:
    return path.suffix.lower() in LOG_SUFFIXES


@dataclass(frozen=True)
class Listing:
    """Display name -> path of every log and route under the data folders."""

    logs: dict[str, Path]
    routes: dict[str, Path]


@dataclass(frozen=True)
class DataFolders:
    """The folders the server may read from. Only what :meth:`listing` found can be opened, so a
    name can never reach outside them (no ``..``, no symlink leading out)."""

    roots: tuple[Path, ...]
    max_depth: int = 4
    max_entries: int = 5000

    @classmethod
    def of(cls, *roots: str | Path) -> DataFolders:
        seen: list[Path] = []
        for r in roots:
            p = Path(r).expanduser().resolve()
            if p.is_dir() and p not in seen:
                seen.append(p)
        return cls(tuple(seen))

    def with_root(self, root: Path) -> DataFolders:
        root = root.resolve()
        return self if root in self.roots else replace(self, roots=(*self.roots, root))

    def _labels(self) -> list[str]:
        labels: list[str] = []
        for root in self.roots:
            label = root.name or "data"
            n = 2
            base = label
            while label in labels:
                label = f"{base}#{n}"
                n += 1
            labels.append(label)
        return labels

    def listing(self) -> Listing:
        logs: dict[str, Path] = {}
        routes: dict[str, Path] = {}
        count = 0
        for label, root in zip(self._labels(), self.roots, strict=True):
            for path in self._walk(root):
                count += 1
                if count > self.max_entries:
                    break
                name = f"{label}/{path.relative_to(root).as_posix()}"
                if path.is_dir() or _is_log_file(path):
                    logs[name] = path
                elif _is_route(path):
                    routes[name] = path
        return Listing(dict(sorted(logs.items())), dict(sorted(routes.items())))

    def _walk(self, root: Path) -> Iterable[Path]:
        """Candidate files and ROS 2 bag folders under ``root`` whose real path stays inside it."""
        root_depth = len(root.parts)
        for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
            here = Path(dirpath)
            dirnames.sort()
            if len(here.parts) - root_depth >= self.max_depth:
                dirnames.clear()
            if "metadata.yaml" in filenames and here != root:
                dirnames.clear()
                if _inside(here, root):
                    yield here
                continue
            dirnames[:] = [d for d in dirnames if not d.startswith(".")]
            for name in sorted(filenames):
                p = here / name
                if (_is_log_file(p) or _is_route(p)) and _inside(p, root):
                    yield p

    def resolve(self, name: str, kind: Kind) -> Path:
        """The path behind a display name from :meth:`listing`."""
        listing = self.listing()
        table = listing.logs if kind == "log" else listing.routes
        path = table.get(name)
        if path is None:
            raise RoutefuseError(name, f"no such {kind} under the data folders")
        return path

    def default_route(self, log_name: str) -> str | None:
        """The route that belongs to a log: ``<stem>.route.*`` or ``<stem>.<route suffix>``
        beside it."""
        listing = self.listing()
        log = listing.logs.get(log_name)
        if log is None:
            return None
        stem = log.name.split(".")[0]
        for name, path in listing.routes.items():
            if path.parent == log.parent and path.name.split(".")[0] == stem:
                return name
        return None


def _inside(path: Path, root: Path) -> bool:
    try:
        real = path.resolve(strict=True)
    except OSError:
        return False
    return real == root or root in real.parents


class UploadFolder:
    """A private temporary folder for uploaded files (mode 0700, removed on :meth:`close`),
    with a size limit per file."""

    def __init__(self, *, max_bytes: int = DEFAULT_UPLOAD_LIMIT) -> None:
        self.max_bytes = max_bytes
        self.path = Path(tempfile.mkdtemp(prefix="routefuse-uploads-")).resolve()
        self._lock = threading.Lock()
        self._count = 0

    def check_size(self, filename: str, size: int) -> None:
        if size > self.max_bytes:
            raise RoutefuseError(
                filename,
                f"upload of {size / 1e6:.1f} MB exceeds the limit of "
                f"{self.max_bytes / 1e6:.0f} MB (put large logs in a --data-dir instead)",
            )

    def save(self, filename: str, content: bytes) -> Path:
        """Write an upload under a sanitised name; the client's name never picks a folder."""
        self.check_size(filename, len(content))
        if not content:
            raise RoutefuseError(filename, "the uploaded file is empty")
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(filename.replace("\\", "/")).name)
        base = base.lstrip(".") or "upload"
        if not (_is_log_file(Path(base)) or _is_route(Path(base))):
            raise RoutefuseError(
                filename, "not a log (.mcap, .bag, .db3) or route (.geojson, .gpx, .kml, .csv)"
            )
        with self._lock:
            self._count += 1
            target = self.path / f"{self._count:03d}-{base}"
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(content)
        return target

    def close(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)


# ---------------------------------------------------------------------------------------------
# Time


@dataclass(frozen=True)
class Timeline:
    """Frames and match attempts of a session on the relative clock (seconds after the log
    start), with the navigation a person uses: step, next/previous attempt, next rejection."""

    t: F64
    """(N,) frame times, s after start"""
    match_t: F64
    """(A,) attempt times, s after start"""
    match_accepted: NDArray[np.bool_]

    @classmethod
    def of_run(cls, run: Run) -> Timeline:
        return cls(
            t=np.asarray(run.epochs.t, np.float64) - run.t0,
            match_t=np.array([m.t - run.t0 for m in run.matches], np.float64),
            match_accepted=np.array([m.accepted for m in run.matches], bool),
        )

    @property
    def n_frames(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    def clamp(self, t: float) -> float:
        return float(np.clip(t, self.t[0], self.t[-1])) if len(self.t) else 0.0

    def frame_at(self, t: float) -> int:
        """The last frame at or before ``t`` (clamped)."""
        i = np.searchsorted(self.t, t + 1e-9, side="right") - 1
        return int(np.clip(i, 0, len(self.t) - 1))

    def step(self, t: float, frames: int) -> float:
        """The time ``frames`` frames away from the frame shown at ``t``."""
        return float(self.t[int(np.clip(self.frame_at(t) + frames, 0, len(self.t) - 1))])

    def match_at(self, t: float) -> int | None:
        """The last attempt at or before ``t``."""
        i = int(np.searchsorted(self.match_t, t + 1e-9, side="right")) - 1
        return i if i >= 0 else None

    def next_match(self, t: float, *, rejected_only: bool = False) -> int | None:
        """The first attempt strictly after ``t``."""
        idx = np.flatnonzero(self.match_t > t + 1e-9)
        if rejected_only:
            idx = idx[~self.match_accepted[idx]]
        return int(idx[0]) if len(idx) else None

    def previous_match(self, t: float, *, rejected_only: bool = False) -> int | None:
        """The last attempt strictly before ``t``."""
        idx = np.flatnonzero(self.match_t < t - 1e-9)
        if rejected_only:
            idx = idx[~self.match_accepted[idx]]
        return int(idx[-1]) if len(idx) else None


@dataclass
class Playhead:
    """One tab's position in time and playback state (kept per browser tab)."""

    t: float = 0.0
    playing: bool = False
    speed: float = 1.0

    def advance(self, timeline: Timeline, wall_dt: float) -> None:
        """Move by ``wall_dt`` seconds of wall time at the chosen speed; stop at the end."""
        if not self.playing:
            return
        t = self.t + wall_dt * self.speed
        if t >= timeline.duration:
            t, self.playing = timeline.duration, False
        self.t = timeline.clamp(t)


# ---------------------------------------------------------------------------------------------
# Injected GNSS outages


def parse_outages(text: str) -> Outages:
    """Outages typed as ``30:60, 90:120`` (each part read by the ``--outage`` parser, so the
    command line and the UI accept the same values); empty text means none."""
    parts = [p.strip() for p in text.split(",")]
    try:
        return normalise_outages(parse_outage(p) for p in parts if p)
    except ConfigError as exc:
        raise ConfigError("GNSS outages", exc.problem) from None


def normalise_outages(outages: Iterable[tuple[float, float]]) -> Outages:
    """Sorted float pairs, checked: the same outages typed in another order are the same
    request, so they do not re-run."""
    out = []
    for a, b in outages:
        a, b = float(a), float(b)
        if not (np.isfinite(a) and np.isfinite(b)) or not b > a:
            raise ConfigError("GNSS outages", f"{a:g}:{b:g}: END must be after START")
        out.append((a, b))
    return tuple(sorted(set(out)))


def format_outages(outages: Outages) -> str:
    """The text :func:`parse_outages` reads back (``30:60, 90:120``)."""
    return ", ".join(f"{a:g}:{b:g}" for a, b in outages)


# ---------------------------------------------------------------------------------------------
# The session and the worker


@dataclass(frozen=True)
class Session:
    """Everything loaded and computed, immutable: tabs draw from it without locks."""

    version: int
    log_path: Path
    route_path: Path
    log_name: str
    route_name: str
    inputs: Any
    """:class:`estimator.pipeline.inputs.Inputs` (log, route, frame)"""
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
    deviation: Any
    """:class:`inspector.plots.DeviationPlot` of both runs"""
    timings: dict[str, float] = field(default_factory=dict)
    off_route: Any = None
    """:class:`inspector.offroute.OffRoute` of the proposed run (None for hand-built sessions)"""


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

    def same_target(self, other: _Request | Session | None) -> bool:
        """Would ``other`` show the same runs? (everything a run depends on)"""
        if other is None:
            return False
        return (self.log_path, self.route_path, self.params, self.method, self.outages) == (
            other.log_path,
            other.route_path,
            other.params,
            other.method,
            other.outages,
        )


class Superseded(Exception):
    """Raised inside a run's progress callback when a newer request has arrived."""


ProgressListener = Callable[[float, str], None]
SessionListener = Callable[[Session], None]
ErrorListener = Callable[[RoutefuseError], None]


def _default_open(log_path: Path, route_path: Path, progress: ProgressListener) -> Any:
    from estimator.pipeline.inputs import open_inputs

    return open_inputs(log_path, route_path, progress=progress)


class RunFn(Protocol):
    """How the worker runs one method (:func:`estimator.pipeline.runner.run` unless a test fakes it)."""

    def __call__(
        self,
        inputs: Any,
        params: Params,
        method: str,
        progress: ProgressListener,
        reuse: Run | None,
        *,
        outages: Outages,
    ) -> Run: ...


def _default_run(
    inputs: Any,
    params: Params,
    method: str,
    progress: ProgressListener,
    reuse: Run | None,
    *,
    outages: Outages,
) -> Run:
    from estimator.pipeline.runner import run

    return run(
        inputs.log,
        inputs.route,
        params,
        method=method,  # type: ignore[arg-type]
        frame=inputs.frame,
        outages=outages,
        progress=progress,
        reuse=reuse,
    )


class Controller:
    """Shared session state and the single re-run worker.

    Requests (:meth:`open`, :meth:`set_params`, ...) return at once; the worker serves the
    latest one. A run in progress is abandoned at its next progress report when a newer request
    arrives. A request that fails leaves the previous session in place and is reported to the
    error listeners.
    """

    def __init__(
        self,
        folders: DataFolders,
        *,
        uploads: UploadFolder | None = None,
        params: Params | None = None,
        method: ProposedMethod = "proposed",
        opener: Callable[[Path, Path, ProgressListener], Any] = _default_open,
        runner: RunFn = _default_run,
    ) -> None:
        self.uploads = uploads
        self._folders = folders.with_root(uploads.path) if uploads else folders
        self._opener = opener
        self._runner = runner
        self._initial_params = params or Params()
        self._initial_method: ProposedMethod = method
        self._initial_outages: Outages = ()
        self._cond = threading.Condition()
        self._wanted: _Request | None = None
        self._done_version = 0
        self._busy = False
        self._version = 0
        self._session: Session | None = None
        self._inputs_cache: tuple[tuple[Path, Path], Any] | None = None
        self._closed = False
        self._listeners: list[
            tuple[ProgressListener | None, SessionListener | None, ErrorListener | None]
        ] = []
        self._thread = threading.Thread(target=self._work, name="routefuse-runner", daemon=True)
        self._thread.start()

    # -- reading --------------------------------------------------------------------------

    @property
    def folders(self) -> DataFolders:
        return self._folders

    @property
    def session(self) -> Session | None:
        return self._session

    @property
    def params(self) -> Params:
        """The parameters of the latest request (what the panel should show)."""
        with self._cond:
            if self._wanted is not None:
                return self._wanted.params
        return self._session.params if self._session else self._initial_params

    @property
    def method(self) -> ProposedMethod:
        with self._cond:
            if self._wanted is not None:
                return self._wanted.method
        return self._session.method if self._session else self._initial_method

    @property
    def outages(self) -> Outages:
        """The injected GNSS outages of the latest request (what the outage field shows)."""
        with self._cond:
            if self._wanted is not None:
                return self._wanted.outages
        return self._session.outages if self._session else self._initial_outages

    @property
    def busy(self) -> bool:
        with self._cond:
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
        entry = (on_progress, on_session, on_error)
        with self._cond:
            self._listeners.append(entry)

        def unsubscribe() -> None:
            with self._cond:
                if entry in self._listeners:
                    self._listeners.remove(entry)

        return unsubscribe

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until every request so far has been served (tests, the CLI)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._busy or (
                self._wanted is not None and self._wanted.version > self._done_version
            ):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    # -- requests -------------------------------------------------------------------------

    def open_named(self, log_name: str, route_name: str) -> None:
        """Open a log and a route by their names in :meth:`DataFolders.listing`."""
        log_path = self._folders.resolve(log_name, "log")
        route_path = self._folders.resolve(route_name, "route")
        self.open(log_path, route_path, log_name=log_name, route_name=route_name)

    def open(
        self,
        log_path: Path,
        route_path: Path,
        *,
        log_name: str | None = None,
        route_name: str | None = None,
        outages: Iterable[tuple[float, float]] | None = None,
    ) -> None:
        """Open files by path (the CLI's arguments; the UI goes through :meth:`open_named`).

        Outages are times in one log, so another log starts with none unless ``outages`` says
        otherwise; the same log with another route keeps them (the tunnel test goes on)."""
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
        """Change one parameter by dotted name (checked at once: a bad value raises
        :class:`ConfigError` here, not on the worker)."""
        self.set_params(with_values(self.params, {name: value}, "parameter panel"))

    def reset_params(self) -> None:
        self.set_params(Params())

    def set_method(self, method: ProposedMethod) -> None:
        self._request(method=method)

    def set_outages(self, outages: Iterable[tuple[float, float]]) -> None:
        """Inject GNSS outages into the loaded log (checked at once; a start after the end of
        the log is reported by the worker, which knows the log's length)."""
        self._request(outages=normalise_outages(outages))

    def _request(self, **changes: Any) -> None:
        with self._cond:
            base = self._wanted or self._session
            if base is None:
                if "log_path" not in changes:
                    # Nothing loaded yet: remember the choice for the first load.
                    if "params" in changes:
                        self._initial_params = changes["params"]
                    if "method" in changes:
                        self._initial_method = changes["method"]
                    if "outages" in changes:
                        self._initial_outages = changes["outages"]
                    return
                fields_ = {
                    "params": self._initial_params,
                    "method": self._initial_method,
                    "outages": self._initial_outages,
                }
            else:
                fields_ = {
                    k: getattr(base, k)
                    for k in (
                        "log_path",
                        "route_path",
                        "log_name",
                        "route_name",
                        "params",
                        "method",
                        "outages",
                    )
                }
            fields_.update(changes)
            self._version += 1
            req = _Request(version=self._version, **fields_)
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
        with self._cond:
            listeners = [entry[kind] for entry in self._listeners]
        for fn in listeners:
            if fn is None:
                continue
            try:
                fn(*args)
            except Exception:
                traceback.print_exc()

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

        def stage(lo: float, hi: float, what: str) -> ProgressListener:
            def report(fraction: float = 0.0, message: str = "", *_: Any) -> None:
                if self._superseded(req):
                    raise Superseded
                f = float(np.clip(fraction, 0.0, 1.0)) if np.isfinite(fraction) else 0.0
                self._emit(0, lo + (hi - lo) * f, message or what)

            return report

        key = (req.log_path, req.route_path)
        t_start = time.perf_counter()
        if prev is not None and (prev.log_path, prev.route_path) == key:
            inputs = prev.inputs
        elif self._inputs_cache is not None and self._inputs_cache[0] == key:
            inputs = self._inputs_cache[1]
        else:
            loading = stage(0.0, 0.5, f"loading {req.log_name}")
            loading(0.0)
            inputs = self._opener(req.log_path, req.route_path, loading)
            self._inputs_cache = (key, inputs)
        timings["open_s"] = time.perf_counter() - t_start
        if self._superseded(req):
            raise Superseded
        for a, b in req.outages:
            if a >= inputs.log.duration_s:
                raise ConfigError(
                    "GNSS outages",
                    f"{a:g}:{b:g} starts after the log ends ({inputs.log.duration_s:.1f} s)",
                )

        # a previous run is reused only on the same log and outages (the runner re-checks)
        same_inputs = (
            prev is not None
            and (prev.log_path, prev.route_path) == key
            and prev.outages == req.outages
        )
        t1 = time.perf_counter()
        base_reuse = prev.baseline if same_inputs and prev else None
        if base_reuse is not None and base_reuse.params == req.params:
            baseline = base_reuse
        else:
            report = stage(0.5, 0.7, "baseline run")
            report(0.0)
            baseline = self._runner(
                inputs, req.params, "baseline", report, base_reuse, outages=req.outages
            )
        timings["baseline_s"] = time.perf_counter() - t1
        t2 = time.perf_counter()
        prop_reuse = prev.proposed if same_inputs and prev and prev.method == req.method else None
        report = stage(0.7, 0.95, f"{req.method} run")
        report(0.0)
        proposed = self._runner(
            inputs, req.params, req.method, report, prop_reuse, outages=req.outages
        )
        timings["proposed_s"] = time.perf_counter() - t2
        if self._superseded(req):
            raise Superseded
        t3 = time.perf_counter()
        from inspector.plots import DeviationPlot, metrics_rows

        scene = SceneData.build(
            baseline=baseline, proposed=proposed, route=inputs.route, log=inputs.log
        )
        deviation = DeviationPlot.build(inputs, baseline, proposed)
        from inspector.offroute import OffRoute

        off_route = OffRoute.build(scene, inputs.route, req.params)
        metrics = metrics_rows(inputs, baseline, proposed)
        timings["views_s"] = time.perf_counter() - t3
        self._emit(0, 1.0, "done")
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
        )
