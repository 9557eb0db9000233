"""``routefuse bench``: speed and memory of loading, the estimator, live re-runs, the inspector
and the export, on simulated 10- and 60-minute drives with a 200 Hz IMU.

Every item runs in a fresh Python process (``python -m benchmarks.harness --worker ...``), so its
peak memory (the process's maximum resident set size) and its numba/cache state do not leak
into the next item. Times are the minimum over ``repeat`` runs, wall clock and CPU time of the
process (on a machine shared with other jobs, CPU time is the stable figure; on an idle machine
the two agree for this single-threaded code).

The logs are simulated once (``long_drive_10min`` / ``long_drive_60min``, seed 0, 200 Hz) into
the bench folder (default ``<routefuse cache>/bench``), and decoded once into the bench's own
decoded-log cache there; later benchmarks reuse both.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
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

IMU_RATE_HZ = 200.0
SEED = 0
LOGS: dict[str, str] = {"10min": "long_drive_10min", "60min": "long_drive_60min"}
"""bench log key -> simulator scenario"""

MATCHING_CHANGE = ("gates.max_residual_m", 0.1)
"""a gate slider moved (then back to the default: each request is a change); on the bench logs
it rejects attempts from late in the drive on (the figures say where: first_changed)"""
EARLY_CHANGE = ("gates.max_correction_m", 2.0)
"""a gate change that rejects attempts from the first tunnel on: nearly a whole re-run"""
WINDOW_CHANGE = ("window.length_m", 300.0)
"""a window-length change: every match attempt's inputs change"""
NOISE_CHANGE = ("noise.gyro_arw_deg_sqrt_h", 0.2)
"""a filter-noise change: the whole log is re-run"""

Figures = dict[str, float]


@dataclass(frozen=True)
class Target:
    """A figure's goal (from issue 7): ``figure <op> value``."""

    figure: str
    op: str
    value: float
    text: str

    def met(self, figures: Figures) -> bool | None:
        v = figures.get(self.figure)
        if v is None or not math.isfinite(v):
            return None
        return v <= self.value if self.op == "<=" else v >= self.value


@dataclass(frozen=True)
class Item:
    name: str
    what: str
    logs: tuple[str, ...]
    targets: dict[str, tuple[Target, ...]]
    """per log key"""


def _t(figure: str, op: str, value: float, text: str) -> tuple[Target, ...]:
    return (Target(figure, op, value, text),)


ITEMS: tuple[Item, ...] = (
    Item("load_first", "bag -> arrays, first load (empty cache)", ("10min", "60min"), {}),
    Item(
        "load_cached",
        "bag -> arrays, cached reload",
        ("10min", "60min"),
        {"60min": _t("wall_s", "<=", 0.5, "<= 0.5 s")},
    ),
    Item("baseline", "baseline run (IMU + wheel + GNSS)", ("10min", "60min"), {}),
    Item(
        "proposed",
        "proposed run (with route matching)",
        ("10min", "60min"),
        {
            "10min": _t("x_realtime", ">=", 1000.0, ">= 1000x real time"),
            "60min": _t("x_realtime", ">=", 1000.0, ">= 1000x real time"),
        },
    ),
    Item(
        "rerun_matching",
        f"inspector: {MATCHING_CHANGE[0]} changed -> new session (both runs, views)",
        ("10min", "60min"),
        {"10min": _t("cpu_s", "<=", 0.5, "<= 0.5 s"), "60min": _t("cpu_s", "<=", 2.0, "<= 2 s")},
    ),
    Item(
        "rerun_early",
        f"inspector: {EARLY_CHANGE[0]} changed -> new session (changes the first tunnel)",
        ("10min", "60min"),
        {},
    ),
    Item(
        "rerun_window",
        f"inspector: {WINDOW_CHANGE[0]} changed -> new session",
        ("10min", "60min"),
        {},
    ),
    Item(
        "rerun_noise",
        f"inspector: {NOISE_CHANGE[0]} changed -> new session",
        ("10min", "60min"),
        {},
    ),
    Item(
        "inspector",
        "inspector server side: one frame step, one scrub jump; serve peak memory",
        ("10min", "60min"),
        {
            "60min": (
                Target("step_p95_ms", "<=", 30.0, "<= 30 ms"),
                Target("peak_rss_mb", "<=", 1024.0, "<= 1 GB"),
            )
        },
    ),
    Item("export", "routefuse export (all files)", ("10min",), {}),
)
ITEM_NAMES = tuple(i.name for i in ITEMS)


# ---------------------------------------------------------------------------------------------
# the logs


def default_bench_dir() -> Path:
    from estimator.io.rosbag import default_cache_dir

    return default_cache_dir() / "bench"


@dataclass(frozen=True)
class BenchLog:
    key: str
    bag: Path
    route: Path


def bench_log_paths(folder: Path, key: str, duration_s: float | None = None) -> BenchLog:
    scenario = LOGS[key]
    stem = scenario if duration_s is None else f"{scenario}-{duration_s:g}s"
    sub = folder / "logs" / stem
    return BenchLog(key, sub / f"{scenario}.mcap", sub / f"{scenario}.route.geojson")


def ensure_log(
    folder: Path,
    key: str,
    *,
    duration_s: float | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> BenchLog:
    """Simulate the log (once) and fill the bench's decoded-log cache with it."""
    from estimator.io.rosbag import load_log
    from estimator.sim import simulate

    paths = bench_log_paths(folder, key, duration_s)
    if not (paths.bag.exists() and paths.route.exists()):
        say(f"simulating {LOGS[key]} at {IMU_RATE_HZ:g} Hz into {paths.bag.parent} (once)")
        last = [""]

        def progress(stage: str, fraction: float) -> None:
            line = f"  {stage} {100 * fraction:3.0f} %"
            if line != last[0] and (fraction >= 1.0 or int(100 * fraction) % 25 == 0):
                last[0] = line
                say(line)

        sim = simulate(
            LOGS[key], seed=SEED, imu_rate_hz=IMU_RATE_HZ, duration_s=duration_s, progress=progress
        )
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            bag, route = sim.write(tmp)
            paths.bag.parent.mkdir(parents=True, exist_ok=True)
            os.replace(route, paths.route)
            os.replace(bag, paths.bag)
    cache = folder / "cache"
    say(f"decoding {paths.bag.name} into the bench cache (once)")
    load_log(paths.bag, cache_dir=cache)
    return paths


# ---------------------------------------------------------------------------------------------
# measuring (inside a worker process)


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
    from estimator.io.rosbag import load_log

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
    from estimator.io.rosbag import load_log

    clock = _Clock.new()
    for _ in range(repeat):
        with clock.lap():
            log = load_log(paths.bag)
    return {**clock.figures(), "log_s": log.duration_s}


def _measure_run(paths: BenchLog, repeat: int, method: str) -> Figures:
    from estimator.params import Params
    from estimator.pipeline.runner import run

    inputs = _open(paths)
    clock = _Clock.new()
    for _ in range(repeat + 1):  # the first one loads the compiled kernels: not counted
        with clock.lap():
            result = run(
                inputs.log,
                inputs.route,
                Params(),
                method=method,
                frame=inputs.frame,  # type: ignore[arg-type]
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
    from inspector.controller import Controller, DataFolders

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
            session = waiter(lambda v=value: controller.set_param(name, v))
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


class _HeadlessTab:
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
        view = ClientView(app, _HeadlessTab(server))  # type: ignore[arg-type]
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
}


def _worker(argv: Sequence[str]) -> int:
    """``python -m benchmarks.harness --worker ITEM BAG ROUTE REPEAT``: one item, JSON on stdout."""
    name, bag, route, repeat = argv
    paths = BenchLog("", Path(bag), Path(route))
    figures = MEASURES[name](paths, int(repeat))
    figures["peak_rss_mb"] = _peak_rss_mb()
    print(json.dumps(figures))
    return 0


# ---------------------------------------------------------------------------------------------
# the driver


@dataclass(frozen=True)
class Result:
    item: str
    log: str
    figures: Figures
    targets: tuple[dict[str, Any], ...]
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.item,
            "log": self.log,
            "figures": self.figures,
            "peak_rss_mb": self.figures.get("peak_rss_mb"),
            "targets": list(self.targets),
            "error": self.error,
        }


def select_items(only: Sequence[str] = ()) -> tuple[Item, ...]:
    """Items named in ``only`` (a name, or a prefix such as ``load`` or ``rerun``); all if
    empty."""
    if not only:
        return ITEMS
    chosen = [i for i in ITEMS if any(i.name == o or i.name.startswith(o) for o in only)]
    unknown = [o for o in only if not any(i.name.startswith(o) for i in ITEMS)]
    if unknown:
        from estimator.errors import ConfigError

        raise ConfigError(
            "--only", f"unknown item {', '.join(unknown)} (items: {', '.join(ITEM_NAMES)})"
        )
    return tuple(chosen)


def run_item(
    item: Item, paths: BenchLog, *, repeat: int, cache: Path, timeout_s: float = 3600.0
) -> Result:
    env = dict(os.environ, ROUTEFUSE_CACHE_DIR=str(cache))
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.harness",
        "--worker",
        item.name,
        str(paths.bag),
        str(paths.route),
        str(repeat),
    ]
    root = Path(__file__).resolve().parents[1]
    env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    try:
        proc = subprocess.run(
            cmd, env=env, capture_output=True, text=True, timeout=timeout_s, check=False
        )
    except subprocess.TimeoutExpired:
        return Result(item.name, paths.key, {}, (), f"timed out after {timeout_s:g} s")
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return Result(item.name, paths.key, {}, (), f"exit {proc.returncode}: {tail}")
    figures = {k: float(v) for k, v in json.loads(lines[-1]).items()}
    targets = tuple(
        {"figure": t.figure, "target": t.text, "met": t.met(figures)}
        for t in item.targets.get(paths.key, ())
    )
    return Result(item.name, paths.key, figures, targets)


def machine() -> dict[str, Any]:
    cpu = platform.processor() or ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    commit = ""
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).resolve().parents[1],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        ).stdout.strip()
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "commit": commit,
    }


def run_benchmarks(
    *,
    only: Sequence[str] = (),
    quick: bool = False,
    repeat: int = 3,
    folder: Path | None = None,
    duration_s: float | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> dict[str, Any]:
    """Run the chosen items on the chosen logs; the JSON-ready document."""
    folder = Path(folder) if folder is not None else default_bench_dir()
    folder.mkdir(parents=True, exist_ok=True)
    items = select_items(only)
    keys = ("10min",) if quick else tuple(LOGS)
    todo = [(i, k) for k in keys for i in items if k in i.logs]
    started = time.perf_counter()
    doc: dict[str, Any] = {
        "machine": machine(),
        "settings": {
            "quick": quick,
            "repeat": repeat,
            "imu_rate_hz": IMU_RATE_HZ,
            "seed": SEED,
            "duration_s": duration_s,
            "folder": str(folder),
        },
        "items": [],
    }
    logs: dict[str, BenchLog] = {}
    for n, (item, key) in enumerate(todo, 1):
        if key not in logs:
            logs[key] = ensure_log(folder, key, duration_s=duration_s, say=say)
        say(f"[{n}/{len(todo)}] {item.name} on the {key} log")
        res = run_item(item, logs[key], repeat=repeat, cache=folder / "cache")
        if res.error:
            say(f"  failed: {res.error}")
        doc["items"].append(res.as_dict())
    doc["machine"]["load_average_end"] = (
        list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    )
    doc["total_s"] = time.perf_counter() - started
    return doc


# ---------------------------------------------------------------------------------------------
# the table

_SHOWN: dict[str, tuple[tuple[str, str, str], ...]] = {
    # item -> (figure, label, format)
    "load_first": (
        ("messages_per_s", "msg/s", "{:,.0f}"),
        ("wall_s", "wall s", "{:.2f}"),
        ("cpu_s", "cpu s", "{:.2f}"),
    ),
    "load_cached": (("wall_s", "wall s", "{:.3f}"), ("cpu_s", "cpu s", "{:.3f}")),
    "baseline": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("x_realtime", "x real time (cpu)", "{:,.0f}"),
    ),
    "proposed": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("x_realtime", "x real time (cpu)", "{:,.0f}"),
        ("attempts", "attempts", "{:.0f}"),
    ),
    "rerun_matching": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
        ("views_s", "views s", "{:.3f}"),
        ("first_changed_fraction", "first changed at", "{:.0%}"),
    ),
    "rerun_early": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
        ("first_changed_fraction", "first changed at", "{:.0%}"),
    ),
    "rerun_window": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
        ("first_changed_fraction", "first changed at", "{:.0%}"),
    ),
    "rerun_noise": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("baseline_s", "baseline s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
    ),
    "inspector": (
        ("step_median_ms", "step median ms", "{:.1f}"),
        ("step_p95_ms", "step p95 ms", "{:.1f}"),
        ("scrub_median_ms", "scrub median ms", "{:.1f}"),
        ("scrub_p95_ms", "scrub p95 ms", "{:.1f}"),
    ),
    "export": (("wall_s", "wall s", "{:.1f}"), ("cpu_s", "cpu s", "{:.1f}")),
}


def format_table(doc: dict[str, Any]) -> str:
    """A plain-text table: one row per item and log."""
    rows = [("item", "log", "figures", "peak MB", "target")]
    for r in doc["items"]:
        if r["error"]:
            rows.append((r["name"], r["log"], f"FAILED: {r['error']}", "", ""))
            continue
        f = r["figures"]
        shown = ", ".join(
            f"{label} {fmt.format(f[key])}"
            for key, label, fmt in _SHOWN.get(r["name"], ())
            if key in f and math.isfinite(f[key])
        )
        verdicts = "; ".join(
            f"{t['target']}: {'met' if t['met'] else 'MISSED' if t['met'] is False else '?'}"
            for t in r["targets"]
        )
        peak = r["peak_rss_mb"]
        rows.append((r["name"], r["log"], shown, f"{peak:.0f}" if peak else "", verdicts))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    m = doc["machine"]
    load = m.get("load_average")
    lines.append("")
    lines.append(
        f"{m['cpu']}, {m['cores']} cores, Python {m['python']}, commit {m['commit'] or '?'}; "
        + (f"load average at start {load[0]:.1f}" if load else "")
    )
    lines.append(
        "times: minimum over repeats; cpu = CPU time of the benchmark process (stable on a "
        "shared machine); peak MB = maximum resident set of the item's process"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        sys.exit(_worker(sys.argv[2:]))
    parser = argparse.ArgumentParser(prog="python -m benchmarks.harness")
    parser.print_help()
    sys.exit(2)
