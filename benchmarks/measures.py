"""The measuring of ``routefuse bench``, inside a worker process (``python -m
benchmarks.measures ITEM BAG ROUTE REPEAT``, started by :mod:`benchmarks.harness`): one item,
its figures as one JSON line on stdout."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.items import (
    EARLY_CHANGE,
    MATCHING_CHANGE,
    NOISE_CHANGE,
    WINDOW_CHANGE,
    BenchLog,
    Figures,
)
from estimator.params import Method


def _peak_rss_mb() -> float:
    """This process's peak resident set (VmHWM). Not ``ru_maxrss``: after a vfork + exec (how
    ``subprocess`` starts the worker) Linux carries the parent's peak into the child's."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1024.0 if sys.platform != "darwin" else kb / 2**20


@dataclass
class _Clock:
    wall: list[float]
    cpu: list[float]

    @classmethod
    def new(cls) -> _Clock:
        return cls([], [])

    @contextlib.contextmanager
    def lap(self) -> Any:
        w, c = time.perf_counter(), time.process_time()
        yield
        self.cpu.append(time.process_time() - c)
        self.wall.append(time.perf_counter() - w)

    def figures(self, prefix: str = "") -> Figures:
        return {f"{prefix}wall_s": min(self.wall), f"{prefix}cpu_s": min(self.cpu)}


def _open(paths: BenchLog) -> Any:
    from estimator.pipeline.inputs import open_inputs

    return open_inputs(paths.bag, paths.route)


def _messages(log: Any) -> int:
    n = len(log.imu.t) + len(log.gnss.t)
    n += len(log.wheel.t) if log.wheel is not None else 0
    n += len(log.truth.t) if log.truth is not None else 0
    return n


def measure_load_first(paths: BenchLog, repeat: int) -> Figures:
    from estimator.io import load_log

    clock = _Clock.new()
    for _ in range(max(1, min(repeat, 2))):
        with tempfile.TemporaryDirectory() as cache, clock.lap():
            log = load_log(paths.bag, cache_dir=Path(cache))
    n = _messages(log)
    figs = clock.figures()
    figs.update(
        messages=float(n),
        messages_per_s=n / figs["wall_s"],
        messages_per_cpu_s=n / figs["cpu_s"],
        log_s=log.duration_s,
    )
    return figs


def measure_load_cached(paths: BenchLog, repeat: int) -> Figures:
    from estimator.io import load_log

    clock = _Clock.new()
    for _ in range(repeat):
        with clock.lap():
            log = load_log(paths.bag)
    return {**clock.figures(), "log_s": log.duration_s}


def _measure_run(paths: BenchLog, repeat: int, method: Method) -> Figures:
    from estimator.params import Params
    from estimator.pipeline import run

    inputs = _open(paths)
    clock = _Clock.new()
    for _ in range(repeat + 1):  # the first one loads the compiled kernels: not counted
        with clock.lap():
            result = run(
                inputs.log,
                inputs.route,
                Params(),
                method=method,
                frame=inputs.frame,
            )
    clock.wall.pop(0)
    clock.cpu.pop(0)
    figs = clock.figures()
    dur = inputs.log.duration_s
    figs.update(
        log_s=dur,
        x_realtime=dur / figs["cpu_s"],
        x_realtime_wall=dur / figs["wall_s"],
        attempts=float(len(result.matches)),
        accepted=float(sum(m.accepted for m in result.matches)),
    )
    return figs


def measure_baseline(paths: BenchLog, repeat: int) -> Figures:
    return _measure_run(paths, repeat, "baseline")


def measure_proposed(paths: BenchLog, repeat: int) -> Figures:
    return _measure_run(paths, repeat, "proposed")


class _SessionWaiter:
    """Times requests to a :class:`Controller` until the new session is published."""

    def __init__(self, controller: Any) -> None:
        self.controller = controller
        self._done = threading.Event()
        self._errors: list[Exception] = []
        controller.subscribe(on_session=lambda s: self._done.set(), on_error=self._errors.append)

    def __call__(self, request: Callable[[], None], timeout: float = 900.0) -> Any:
        self._done.clear()
        request()
        if not self._done.wait(timeout):
            raise RuntimeError("the inspector did not publish a session in time")
        if self._errors:
            raise self._errors[-1]
        return self.controller.session


def _controller(paths: BenchLog) -> tuple[Any, _SessionWaiter]:
    from inspector.controller import Controller
    from inspector.folders import DataFolders

    controller = Controller(DataFolders.of(paths.bag.parent))
    waiter = _SessionWaiter(controller)
    waiter(lambda: controller.open(paths.bag, paths.route))
    return controller, waiter


def _measure_rerun(paths: BenchLog, repeat: int, change: tuple[str, float]) -> Figures:
    from estimator.params import get_param

    controller, waiter = _controller(paths)
    name, changed = change
    values = (changed, get_param(controller.params, name))
    if values[0] == values[1]:
        raise ValueError(f"{name}: the changed value {changed} is the current value")
    clock = _Clock.new()
    stages: dict[str, list[float]] = {}
    first_changed = []
    before = controller.session
    # the first change warms up what a first re-run compiles or caches: not counted
    for i in range(repeat + 1):
        value = values[i % len(values)]
        with clock.lap():
            session = waiter(functools.partial(controller.set_param, name, value))
        first_changed.append(_first_changed(before.proposed.matches, session.proposed.matches))
        before = session
        if i == 0:
            clock.wall.pop(0)
            clock.cpu.pop(0)
            continue
        for k, v in session.timings.items():
            stages.setdefault(k, []).append(v)
    controller.close()
    figs = clock.figures()
    figs.update({k: min(v) for k, v in stages.items()})
    n = len(session.proposed.matches)
    figs["attempts"] = float(n)
    figs["first_changed"] = float(min(first_changed))
    figs["first_changed_fraction"] = min(first_changed) / max(n, 1)
    return figs


def _first_changed(old: Sequence[Any], new: Sequence[Any]) -> int:
    """Index of the first attempt whose outcome differs (verdict, or the pseudo-position an
    accepted match applied); the length of the shorter list when none does."""
    for i, (a, b) in enumerate(zip(old, new, strict=False)):
        if a.accepted != b.accepted or a.t != b.t:
            return i
        if a.accepted and not np.array_equal(a.pseudo_position, b.pseudo_position):
            return i
    return min(len(old), len(new))


def measure_rerun_matching(paths: BenchLog, repeat: int) -> Figures:
    return _measure_rerun(paths, repeat, MATCHING_CHANGE)


def measure_rerun_early(paths: BenchLog, repeat: int) -> Figures:
    return _measure_rerun(paths, repeat, EARLY_CHANGE)


def measure_rerun_window(paths: BenchLog, repeat: int) -> Figures:
    return _measure_rerun(paths, repeat, WINDOW_CHANGE)


def measure_rerun_noise(paths: BenchLog, repeat: int) -> Figures:
    return _measure_rerun(paths, repeat, NOISE_CHANGE)


class _StubCamera:
    """What a tab's view reads of the browser's camera before the browser reports one."""

    update_timestamp = 0.0
    aspect = 1.5
    image_width = 1400
    fov = 1.0
    position = (0.0, 0.0, 100.0)
    look_at = (0.0, 0.0, 0.0)

    def on_update(self, fn: Callable[[Any], None]) -> None:
        pass


class HeadlessTab:
    """Stands in for a connected browser tab: the tab's GUI and scene calls go to the server's
    (shared) GUI and scene, so a frame step runs the same server-side code and serialises the
    same messages, without a browser."""

    client_id = 0

    def __init__(self, server: Any) -> None:
        self.gui = server.gui
        self.scene = server.scene
        self.atomic = server.atomic
        self.camera = _StubCamera()

    def add_notification(self, *args: Any, **kwargs: Any) -> None:
        pass


def _percentiles(ms: list[float], prefix: str) -> Figures:
    a = np.asarray(ms)
    return {
        f"{prefix}_median_ms": float(np.median(a)),
        f"{prefix}_p95_ms": float(np.percentile(a, 95)),
        f"{prefix}_max_ms": float(a.max()),
    }


def measure_inspector(paths: BenchLog, repeat: int) -> Figures:
    from inspector.app import ClientView, InspectorApp
    from inspector.export.replay import headless_server

    controller, _ = _controller(paths)
    session = controller.session
    steps = max(50, 100 * repeat)
    jumps = max(20, 40 * repeat)
    with headless_server() as server:
        app = InspectorApp(server, controller)
        view = ClientView(app, HeadlessTab(server))  # type: ignore[arg-type]  # a stand-in for viser.ClientHandle
        view.set_session(session)
        tl = session.timeline
        # start a little before the middle attempt, so the steps cross attempts (overlays)
        mid = tl.match_t[len(tl.match_t) // 2] - 2.0 if len(tl.match_t) else tl.duration / 2
        view.seek(float(mid))
        step_ms: list[float] = []
        for _ in range(steps):
            w = time.perf_counter()
            view.step(1)
            step_ms.append(1e3 * (time.perf_counter() - w))
        rng = np.random.default_rng(0)
        jump_ms: list[float] = []
        for t in rng.uniform(0.0, tl.duration, jumps):
            w = time.perf_counter()
            view.seek(float(t))
            jump_ms.append(1e3 * (time.perf_counter() - w))
        app.close()
    controller.close()
    figs = _percentiles(step_ms, "step")
    figs.update(_percentiles(jump_ms, "scrub"))
    figs.update(frames=float(tl.n_frames), attempts=float(len(tl.match_t)))
    figs.update({f"load_{k}": v for k, v in session.timings.items()})
    return figs


def measure_export(paths: BenchLog, repeat: int) -> Figures:
    from inspector.export.replay import export_log

    clock = _Clock.new()
    for _ in range(max(1, min(repeat, 2))):
        with tempfile.TemporaryDirectory() as out, clock.lap():
            result = export_log(paths.bag, paths.route, out)
    figs = clock.figures()
    figs.update({k: v for k, v in result.timings.items()})
    return figs


def _command_env() -> dict[str, str]:
    """The timed commands' environment: this process's, with Python's byte-code cache on.

    An installed routefuse has its modules' byte code (pip compiles it), so a warm start reads
    it; with ``PYTHONDONTWRITEBYTECODE`` set (as in some shells and CI images) a source checkout
    has none, and every command compiled routefuse's 70 modules from source again: 0.12-0.15 s
    of CPU of each ``routefuse run`` measured (Intel Xeon, 2 cores, at 203162e), a cost of the
    environment, not of routefuse. Then the warm-up run writes the byte code into the bench's
    cache folder (``PYTHONPYCACHEPREFIX``; the checkout is left untouched) and the timed runs
    read it. Without that variable nothing changes: Python's own ``__pycache__`` is used."""
    env = dict(os.environ)
    if env.pop("PYTHONDONTWRITEBYTECODE", None) is not None and "PYTHONPYCACHEPREFIX" not in env:
        from estimator.io import default_cache_dir

        env["PYTHONPYCACHEPREFIX"] = str(default_cache_dir() / "pycache")
    return env


def _command_wall_s(argv: Sequence[str], repeat: int) -> Figures:
    """Wall time of a command run ``repeat`` times after one warm-up run (minimum and median,
    as hyperfine reports them), with Python's byte-code cache on (:func:`_command_env`)."""
    cmd = [sys.executable, "-m", "inspector", *argv]
    env = _command_env()
    times: list[float] = []
    for i in range(repeat + 1):
        w = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
        if i > 0:
            times.append(time.perf_counter() - w)
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"{' '.join(argv[:1])} failed: {tail}")
    child_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return {
        "wall_s": min(times),
        "wall_median_s": float(np.median(times)),
        "runs": len(times),
        "command_peak_rss_mb": child_kb / 1024.0,
    }


def measure_startup_help(paths: BenchLog, repeat: int) -> Figures:
    return _command_wall_s(["--help"], repeat)


def measure_startup_run(paths: BenchLog, repeat: int) -> Figures:
    """The warm-up run fills the decoded-log cache and loads the compiled kernels' cache."""
    from estimator.io import load_log

    figs = _command_wall_s(["run", str(paths.bag), "--route", str(paths.route), "--quiet"], repeat)
    figs["log_s"] = load_log(paths.bag).duration_s
    return figs


def measure_route_parse(paths: BenchLog, repeat: int) -> Figures:
    """Route files at the caps, each read in a fresh process (once: a peak, not a time)."""
    from benchmarks.route_parse_memory import default_dir, run_cases, summary

    return summary(run_cases(default_dir()))


MEASURES: dict[str, Callable[[BenchLog, int], Figures]] = {
    "load_first": measure_load_first,
    "load_cached": measure_load_cached,
    "baseline": measure_baseline,
    "proposed": measure_proposed,
    "rerun_matching": measure_rerun_matching,
    "rerun_early": measure_rerun_early,
    "rerun_window": measure_rerun_window,
    "rerun_noise": measure_rerun_noise,
    "inspector": measure_inspector,
    "export": measure_export,
    "startup_help": measure_startup_help,
    "startup_run": measure_startup_run,
    "route_parse": measure_route_parse,
}


def worker(argv: Sequence[str]) -> int:
    """``python -m benchmarks.measures ITEM BAG ROUTE REPEAT``: one item, JSON on stdout."""
    name, bag, route, repeat = argv
    paths = BenchLog("", Path(bag), Path(route))
    figures = MEASURES[name](paths, int(repeat))
    figures["peak_rss_mb"] = _peak_rss_mb()
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(worker(sys.argv[1:]))
