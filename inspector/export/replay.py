"""Headless export: everything a person needs to look at one run without the inspector open.

:func:`export_log` runs the baseline and the compared method over one log and writes, into one
folder, a replay of the 3D scene (drawn by the inspector's own scene layers into viser's scene
serializer, so it shows exactly what the live UI shows), the paper's figures, the metrics, every
match attempt, and the trajectories as CSV, GeoJSON and TUM (for many logs:
:mod:`inspector.export.batch`).

Nothing here needs a display or a network: viser's server only binds the loopback interface to
host the scene API the layers draw into; no browser ever connects to it.
"""

from __future__ import annotations

import base64
import contextlib
import dataclasses
import io
import math
import os
import shutil
import socket
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimator.errors import ConfigError, RoutefuseError
from estimator.io import AUTO_TOPICS, TopicChoice
from estimator.params import Method, Params
from estimator.results import Run
from inspector.export import figures as export_figures
from inspector.export import tables as export_tables
from inspector.plots import DeviationPlot
from inspector.scene_data import SceneData

F64 = NDArray[np.float64]
Progress = Callable[[str, float], None]
"""called with the stage being worked on and the fraction of the whole export done"""

DEFAULT_MAX_FRAMES = 300
"""Frames of the replay when ``fps`` is not given: enough to follow every match attempt of a
few-minute log, small enough that the page stays a few MB and opens in seconds."""
DEFAULT_MAX_FPS = 2.0
"""frames per second of log time when the log is short enough to afford them"""
DEFAULT_REPLAY_S = 60.0
"""Length the replay aims at when ``time_lapse`` is not given (never slower than real time)."""
POSE_MARKER_FRACTION = 0.05
"""vehicle marker length in the replay, as a fraction of the drive's extent (never smaller
than the live UI's)"""
MAX_FRAMES = 20_000
"""refuse an explicit ``fps`` that would make a replay page of hundreds of MB"""


@dataclass(frozen=True)
class ReplayOptions:
    """How the log's time becomes the replay's frames."""

    fps: float | None = None
    """frames per second of log time; None: at most ``DEFAULT_MAX_FPS``, fewer for long logs
    so the replay keeps about ``max_frames`` frames"""
    time_lapse: float | None = None
    """log seconds per replay second; None: real time, or faster so the replay lasts
    ``DEFAULT_REPLAY_S``"""
    max_frames: int = DEFAULT_MAX_FRAMES
    """frame budget used when ``fps`` is None"""


@dataclass(frozen=True)
class ExportResult:
    """What one export wrote and measured."""

    log: Path
    route: Path
    out_dir: Path
    files: tuple[Path, ...]
    metrics: dict[str, Any]
    """the ``routefuse run --json`` document"""
    frames: int
    """frames in the replay"""
    timings: dict[str, float] = field(default_factory=dict)
    """seconds per stage"""


# ---------------------------------------------------------------------------------------------
# one log


def export_log(
    log_path: str | Path,
    route_path: str | Path,
    out_dir: str | Path,
    *,
    params: Params | None = None,
    method: Method = "proposed",
    outages: Sequence[tuple[float, float]] = (),
    topics: TopicChoice = AUTO_TOPICS,
    route_feature: str | int | None = None,
    replay: ReplayOptions = ReplayOptions(),
    progress: Progress | None = None,
    cache_dir: Path | None = None,
    subtract_lane_offset: bool = False,
) -> ExportResult:
    """Run the baseline and ``method`` over one log and write every export file into
    ``out_dir`` (created if missing; files of an earlier export are overwritten).

    ``outages``: (start, end) seconds after the log start where GNSS is removed, as
    ``routefuse run --outage``. ``route_feature``: which line of a route file holding several
    (name or index). ``cache_dir``: the decoded-log cache (default: the user's).
    ``subtract_lane_offset``: route deviations from the learned lane, not the route line."""
    from estimator.pipeline import open_inputs, run_methods

    log_path, route_path, out = Path(log_path), Path(route_path), Path(out_dir)
    params = params or Params()
    _check_replay_options(replay)
    created = not out.exists()
    make_dir(out)  # before the runs: a bad --out fails at once
    try:
        steps = _Stages(progress or (lambda stage, fraction: None))
        stage, lap = steps.stage, steps.lap
        inputs = open_inputs(
            log_path,
            route_path,
            topics=topics,
            route_feature=route_feature,
            cache_dir=cache_dir,
            progress=stage("loading", 0, 0.2),
        )
        lap("load_s")
        stages = {
            "baseline": stage("baseline run", 0.2, 0.35),
            method: stage(f"{method} run", 0.35, 0.55),
        }
        session = run_methods(
            inputs,
            params,
            methods=("baseline", method),
            outages=outages,
            progress=lambda m, f: stages[m](f),
        )
        baseline, compared = session["baseline"], session[method]
        lap("run_s")
        doc = export_tables.metrics_document(
            inputs,
            baseline,
            compared,
            log_path,
            route_path,
            outages=outages,
            subtract_lane_offset=subtract_lane_offset,
        )
        # written into a hidden folder of ``out`` and moved into place once every file is there:
        # stopped midway (Ctrl-C, an error), ``out`` keeps the earlier export whole, or nothing,
        # never this export's first files beside that one's replay and report
        staging = out / f".partial-{uuid.uuid4().hex[:12]}"
        try:
            make_dir(staging)
            files, n_frames = _write_files(staging, inputs, baseline, compared, doc, replay, steps)
            files = _publish(files, out)
        except OSError as exc:
            where = exc.filename or out
            raise RoutefuseError(where, f"cannot write: {exc.strerror or exc}") from None
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        steps.report("done", 1.0)
        return ExportResult(
            log=log_path,
            route=route_path,
            out_dir=out,
            files=files,
            metrics=doc,
            frames=n_frames,
            timings=steps.timings,
        )
    except BaseException:
        if created:  # a log that failed leaves no empty folder that looks like its export
            with contextlib.suppress(OSError):
                out.rmdir()
        raise


@dataclass
class _Stages:
    """The stages of one export on one progress bar, and the seconds each took."""

    report: Progress
    timings: dict[str, float] = field(default_factory=dict)
    clock: float = field(default_factory=time.perf_counter)

    def stage(self, name: str, lo: float, hi: float) -> Callable[[float], None]:
        return lambda f: self.report(name, lo + (hi - lo) * float(np.clip(f, 0.0, 1.0)))

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.timings[name] = now - self.clock
        self.clock = now


def _write_files(
    out: Path,
    inputs: Any,
    baseline: Run,
    compared: Run,
    doc: dict[str, Any],
    replay: ReplayOptions,
    steps: _Stages,
) -> tuple[tuple[Path, ...], int]:
    """Tables, figures, the replay and the report of two runs; the files and replay frames."""
    steps.report("tables", 0.55)
    files = export_tables.write_tables(out, inputs, baseline, compared, doc)
    steps.lap("tables_s")
    steps.report("figures", 0.65)
    scene = SceneData.build(
        baseline=baseline, proposed=compared, route=inputs.route, log=inputs.log
    )
    plot = DeviationPlot.build(inputs, baseline, compared)
    files += export_figures.write_figures(out, plot, scene, compared)
    steps.lap("figures_s")
    frames = replay_times(scene, replay)
    files += write_replay(
        out,
        scene,
        frames,
        plot=plot,
        degraded=compared.degraded_intervals,
        time_lapse=_time_lapse(frames, replay),
        title=f"{Path(doc['log']).name} on {Path(doc['route']).name}",
        method=compared.method,
        progress=steps.stage("replay", 0.75, 0.98),
    )
    steps.lap("replay_s")
    files += (export_tables.write_report(out, doc, files, steps.timings),)
    return files, len(frames)


def _publish(files: Sequence[Path], out: Path) -> tuple[Path, ...]:
    """Move the written ``files`` into ``out`` (each replacing its earlier version), the report
    page, which links the rest, last."""
    ordered = sorted(files, key=lambda f: f.name == "report.html")
    for f in ordered:
        os.replace(f, out / f.name)
    return tuple(out / f.name for f in files)


def make_dir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RoutefuseError(path, f"cannot create the output folder: {exc.strerror}") from None


def _check_replay_options(o: ReplayOptions) -> None:
    if o.fps is not None and not (math.isfinite(o.fps) and o.fps > 0):
        raise ConfigError("--fps", f"must be a positive number of frames per second, not {o.fps}")
    if o.time_lapse is not None and not (math.isfinite(o.time_lapse) and o.time_lapse > 0):
        raise ConfigError("--time-lapse", f"must be a positive factor, not {o.time_lapse}")
    if o.max_frames < 2:
        raise ConfigError("max_frames", f"must be at least 2, not {o.max_frames}")


# ---------------------------------------------------------------------------------------------
# the replay


def replay_times(scene: SceneData, options: ReplayOptions = ReplayOptions()) -> F64:
    """Absolute log times of the replay's frames: an even grid over the run plus the time of
    every match attempt (so each attempt is drawn once, however the grid falls), thinned
    evenly to fit the frame budget when ``fps`` is not given."""
    t = scene.proposed.t
    if len(t) == 0:
        return np.zeros(0)
    t_start, t_end = float(t[0]), float(t[-1])
    span = t_end - t_start
    attempts = scene.match_t[(scene.match_t >= t_start) & (scene.match_t <= t_end)]
    if options.fps is None:
        keep = min(len(attempts), options.max_frames // 2)
        if keep < len(attempts):
            attempts = attempts[np.linspace(0, len(attempts) - 1, keep).round().astype(int)]
        budget = options.max_frames - len(attempts) - 1
        fps = DEFAULT_MAX_FPS if span <= 0 else min(DEFAULT_MAX_FPS, budget / span)
    else:
        fps = options.fps
        if span * fps > MAX_FRAMES:
            raise ConfigError(
                "--fps",
                f"{fps:g} frames per second over {span:.0f} s of log makes "
                f"{span * fps:.0f} frames (at most {MAX_FRAMES})",
            )
    n = max(math.floor(span * fps), 1)
    grid = t_start + np.arange(n) * (span / n)
    return np.unique(np.concatenate([grid, attempts, [t_end]]))


def _time_lapse(frames: F64, options: ReplayOptions) -> float:
    if options.time_lapse is not None:
        return options.time_lapse
    span = float(frames[-1] - frames[0]) if len(frames) > 1 else 0.0
    return max(1.0, span / DEFAULT_REPLAY_S)


@contextlib.contextmanager
def headless_server() -> Iterator[Any]:
    """A viser server on a free loopback port, its console banner silenced; stopped on exit.
    No browser is meant to connect to it, and none of another origin can
    (:mod:`inspector.origin_guard`): while it records, it holds the whole replay."""
    import viser

    from inspector import origin_guard

    origin_guard.install()
    try:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        with contextlib.redirect_stdout(io.StringIO()):
            server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    except OSError as exc:
        raise RoutefuseError(
            "127.0.0.1", f"cannot open a loopback port to record the replay: {exc.strerror or exc}"
        ) from None
    try:
        yield server
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()


def write_replay(
    out_dir: Path,
    scene: SceneData,
    frames: F64,
    *,
    plot: DeviationPlot,
    degraded: Sequence[tuple[float, float]] = (),
    time_lapse: float = 1.0,
    title: str = "routefuse replay",
    method: str = "proposed",
    progress: Callable[[float], None] | None = None,
) -> tuple[Path, ...]:
    """Draw ``scene`` at each frame time with the inspector's layers under viser's scene
    serializer; write ``replay.html`` (self-contained, plays from file://: the scene beside a
    panel with the clock, the deviation plot, the gate table of the attempt on screen and the
    legend, all in log time) and ``replay.viser`` (the scene alone, for viser's own player).

    The recording's time is the log's time since its start, so every clock (the panel's,
    viser's and the scene's label) reads the same; ``time_lapse`` is the page's initial
    playback speed. The verdict markers appear as their attempts happen. ``degraded``:
    absolute (start, end) times where GNSS is out."""
    from inspector.layers import SceneLayers, TrackLayer

    html_path, viser_path = out_dir / "replay.html", out_dir / "replay.viser"
    with headless_server() as server:
        # Two recordings of the same messages: as_html() consumes the serializer it is
        # called on, and the page and the .viser file are both wanted.
        recorders = (server.get_scene_serializer(), server.get_scene_serializer())
        _place_camera(server, scene)
        layers = SceneLayers(server.scene)
        layers.set_data(scene)
        marker_scale = max(1.0, POSE_MARKER_FRACTION * scene.extent_m / TrackLayer.length_m)
        for layer in layers.layers.values():
            if isinstance(layer, TrackLayer):
                layer.set_pose_scale(marker_scale)
        verdicts = layers.layers["verdicts"]
        clock = server.scene.add_label(
            "/routefuse/export/clock",
            "",
            position=_clock_anchor(scene),
            anchor="top-center",
            font_screen_scale=1.2,
        )
        recorded_until = scene.t0
        shown = -1
        for i, t in enumerate(frames):
            for rec in recorders:
                rec.insert_sleep(max(float(t) - recorded_until, 0.0))
            recorded_until = float(t)
            n_done = int(np.searchsorted(scene.match_t, t + 1e-9, side="right"))
            if n_done != shown:
                verdicts.set_data(_first_attempts(scene, n_done))
                shown = n_done
            layers.draw(float(t))
            state = "GNSS outage" if any(a <= t <= b for a, b in degraded) else "GNSS"
            clock.text = f"log time {t - scene.t0:6.1f} s   {state}   attempts {n_done}"
            if progress is not None and i % 20 == 0:
                progress(i / len(frames))
        for rec in recorders:
            rec.insert_sleep(1.0)  # hold the last frame a moment before the player loops
        html = recorders[0].as_html()
        data = recorders[1].serialize()
    panel = replay_panel(
        scene,
        plot,
        degraded=degraded,
        duration=recorded_until - scene.t0,
        speed=time_lapse,
        title=title,
        method=method,
    )
    html = _with_title(html, f"routefuse replay: {title}")
    body_end = html.rindex("</body>")
    html_path.write_text(html[:body_end] + panel + html[body_end:], encoding="utf-8")
    viser_path.write_bytes(data)
    if progress is not None:
        progress(1.0)
    return html_path, viser_path


def _with_title(page: str, title: str) -> str:
    """viser's page with ``title`` (escaped) instead of its own "Viser", so that a browser tab,
    its history and a bookmark name the log replayed."""
    import html as html_text

    start, end = page.find("<title>"), page.find("</title>")
    if start < 0 or end < start:
        return page
    return page[: start + len("<title>")] + html_text.escape(title) + page[end:]


PLAYBACK_SPEEDS = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0)
"""log seconds per second the replay page offers (with the export's own time lapse)"""


def speed_options(speed: float) -> list[tuple[str, str]]:
    """The page's speeds as (value, label): the export's own time lapse (the log's length over
    the replay's) is labelled to three figures, '4.45x', not '4.44833x'."""
    return [(f"{s:g}", f"{float(f'{s:.3g}'):g}") for s in sorted({*PLAYBACK_SPEEDS, speed})]


def replay_panel(
    scene: SceneData,
    plot: DeviationPlot,
    *,
    degraded: Sequence[tuple[float, float]],
    duration: float,
    speed: float,
    title: str,
    method: str,
) -> str:
    """The replay page's panel as HTML to append to viser's page: rendered by Jinja2 with
    autoescaping, its data as JSON in a script element (Jinja2's ``tojson``, safe inside HTML),
    its behaviour in ``templates/replay_panel.js``."""
    import jinja2
    from markupsafe import Markup

    from inspector.layers import MATCH_MAX_AGE_S, legend_entries

    refused_t = np.array([m.t - scene.t0 for m in scene.matches if not m.accepted])
    strip = export_figures.replay_strip(plot, refused_t, method)
    data = {
        "duration": round(duration, 4),
        "speed": speed,
        "autoplay": True,
        "max_age_s": MATCH_MAX_AGE_S,
        "outages": [[a - scene.t0, b - scene.t0] for a, b in degraded],
        "attempts": [_attempt_json(scene, m) for m in scene.matches],
        "strip": {
            "width_px": strip.width_px,
            "x_left_px": strip.x_left_px,
            "x_right_px": strip.x_right_px,
            "t_lo": strip.t_lo,
            "t_hi": strip.t_hi,
        },
    }
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("inspector.export", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
    )
    script = (resources.files("inspector.export") / "templates" / "replay_panel.js").read_text()
    return env.get_template("replay_panel.html").render(
        title=title,
        speeds=speed_options(speed),
        speed=f"{speed:g}",
        duration=f"{duration:.1f}",
        strip_png=base64.b64encode(strip.png).decode("ascii"),
        strip_width=strip.width_px,
        strip_height=strip.height_px,
        legend=legend_entries(),
        measure=_measure_note(plot),
        data=data,
        script=Markup(script),
    )


def _measure_note(plot: DeviationPlot) -> str:
    if plot.truth is None:
        return "This log has no ground truth: the plot shows the deviation from the route only."
    return "The error against truth is the measure; the route deviation rewards following a map."


def _finite(x: float) -> float | None:
    """JSON has no NaN: a gate that never computed its value is null."""
    return float(x) if math.isfinite(x) else None


def _attempt_json(scene: SceneData, m: Any) -> dict[str, Any]:
    """One attempt as the replay page shows it: its time (log seconds), verdict, gate table and
    fit values."""
    return {
        "index": int(m.index),
        "t": round(float(m.t - scene.t0), 4),
        "accepted": bool(m.accepted),
        "verdict": str(m.verdict),
        "gates": [
            {
                "name": g.name,
                "value": _finite(g.value),
                "comparison": g.comparison,
                "threshold": _finite(g.threshold),
                "passed": bool(g.passed),
                "no_rival": bool(g.no_rival),
            }
            for g in m.gates
        ],
        "fit": (
            f"rotation {np.degrees(m.rotation_rad):.2f} deg, residual {m.residual_m:.2f} m, "
            f"pairs {m.n_pairs}, |z - p_dr| {float(np.hypot(*m.innovation)):.2f} m"
        ),
    }


def _first_attempts(scene: SceneData, n: int) -> SceneData:
    """The scene with only its first ``n`` match attempts (what the verdict layer shows at a
    time after them)."""
    return dataclasses.replace(
        scene,
        matches=scene.matches[:n],
        match_t=scene.match_t[:n],
        match_xy=scene.match_xy[:n],
        match_accepted=scene.match_accepted[:n],
    )


def _clock_anchor(scene: SceneData) -> tuple[float, float, float]:
    """Top middle of the overview (clear of the corner where the browser shows notices)."""
    return (float(scene.center[0]), float(scene.center[1] + 0.55 * scene.extent_m), 1.0)


def _place_camera(server: Any, scene: SceneData) -> None:
    """Top-down over the whole drive, north up (the live UI's overview, without its panel)."""
    cam = server.initial_camera
    fov = float(cam.fov)
    height = 0.6 * scene.extent_m / math.tan(fov / 2)
    cx, cy = float(scene.center[0]), float(scene.center[1])
    cam.far = max(10 * height, 1000.0)
    cam.near = max(height / 2000, 0.05)
    cam.up = (0.0, 0.0, 1.0)
    cam.position = (cx, cy - 0.001 * height, height)
    cam.look_at = (cx, cy, 0.0)
