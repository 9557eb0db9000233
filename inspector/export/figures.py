"""The paper's figures as files: deviation from the route against time (baseline vs the compared
method, GNSS outages shaded) and the trajectories over the route with the outage stretch
zoomed. Drawn with matplotlib's object API on the Agg canvas, so no display and no global
pyplot state are involved.

The curves come from the same objects the live inspector draws: :class:`DeviationPlot` (its
deviation panel) and :class:`SceneData` (its map), so a figure and the UI never disagree.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from numpy.typing import NDArray

from estimator.results import Run
from inspector.plots import BASELINE_COLOR, PROPOSED_COLOR, DeviationPlot
from inspector.scene_data import SceneData

F64 = NDArray[np.float64]

ROUTE_COLOR = "#787878"
TRUTH_COLOR = "#1e963c"
OUTAGE_COLOR = "#dc3232"
ACCEPTED_COLOR = "#1eaa3c"
REJECTED_COLOR = "#dc2828"
DPI = 150
ZOOM_MIN_HALF_M = 60.0
"""the zoom panel shows at least 120 m: the lane, the route and a stretch of both tracks"""
_SVG_META = {"Date": None}
"""no timestamp in the SVG, so an unchanged export gives an identical file"""


def write_figures(
    out: Path, plot: DeviationPlot, scene: SceneData, compared: Run
) -> tuple[Path, ...]:
    """``deviation.png``, ``deviation.svg`` and ``trajectory.png``."""
    dev = deviation_figure(plot, compared.method)
    paths = (out / "deviation.png", out / "deviation.svg", out / "trajectory.png")
    dev.savefig(paths[0], dpi=DPI)
    dev.savefig(paths[1], metadata=_SVG_META)
    trajectory_figure(scene, compared.degraded_intervals, compared.method).savefig(
        paths[2], dpi=DPI
    )
    return paths


def _shade(ax: Any, outages: Sequence[tuple[float, float]]) -> None:
    for i, (a, b) in enumerate(outages):
        ax.axvspan(
            a, b, color=OUTAGE_COLOR, alpha=0.12, lw=0, label="GNSS outage" if i == 0 else None
        )


def _time_span(t: NDArray[np.float64]) -> tuple[float, float]:
    """The time axis' limits: the first and last epoch, or a second from the first where they
    coincide (a log of one epoch: matplotlib warned of a singular transformation and widened
    the axis itself), or 0-1 s with no epoch."""
    if not len(t):
        return 0.0, 1.0
    lo, hi = float(t[0]), float(t[-1])
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def deviation_figure(plot: DeviationPlot, method: str = "proposed") -> Figure:
    """Position (|cross-track|, m) and heading (deg) deviation from the route against time
    since the log start."""
    fig = Figure(figsize=(10, 6), layout="constrained")
    ax_pos, ax_hdg = fig.subplots(2, 1, sharex=True)
    for ax, (base, comp), label in (
        (ax_pos, plot.position, "position deviation [m]"),
        (ax_hdg, plot.heading, "heading deviation [deg]"),
    ):
        _shade(ax, plot.outages)
        ax.plot(plot.t, base, color=BASELINE_COLOR, lw=1.2, label="baseline")
        ax.plot(plot.t, comp, color=PROPOSED_COLOR, lw=1.2, label=method)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    ax_hdg.axhline(0.0, color="k", lw=0.5)
    ax_hdg.set_xlabel("time since log start [s]")
    ax_hdg.set_xlim(*_time_span(plot.t))
    ax_pos.set_ylim(bottom=0.0)
    ax_pos.legend(loc="upper left", fontsize="small")
    ax_pos.set_title("Deviation from the route: baseline vs " + method)
    return fig


@dataclass(frozen=True)
class TimeStrip:
    """A small plot against log time as a PNG, with where its time axis lies in the image, so a
    page can draw a cursor over it and turn a click into a time."""

    png: bytes
    width_px: int
    height_px: int
    x_left_px: float
    """image column of ``t_lo`` (the axes' left edge)"""
    x_right_px: float
    """image column of ``t_hi``"""
    t_lo: float
    t_hi: float


def replay_strip(
    plot: DeviationPlot, refused_t: F64, method: str = "proposed", *, width_in: float = 4.6
) -> TimeStrip:
    """The error against truth (when the log has it) and the route deviation of both runs
    against time since the log start, outages shaded, refused attempts ticked, and the compared
    run's own horizontal 1-sigma dashed beside its error: the replay page's deviation plot. The
    route deviation is never shown alone where truth exists (it rewards following a wrong
    map)."""
    panels: list[tuple[str, tuple[F64, F64], F64 | None]] = [
        ("route deviation [m]", plot.position, None)
    ]
    if plot.truth is not None:
        panels.insert(0, ("error vs truth [m]", plot.truth, plot.sigma))
    fig = Figure(figsize=(width_in, 1.0 + 1.15 * len(panels)), dpi=100, layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, (base, comp), sigma) in zip(axes, panels, strict=True):
        _shade(ax, plot.outages)
        ax.plot(plot.t, base, color=BASELINE_COLOR, lw=1.0, label="baseline")
        ax.plot(plot.t, comp, color=PROPOSED_COLOR, lw=1.0, label=method)
        if sigma is not None:
            ax.plot(plot.t, sigma, color=PROPOSED_COLOR, lw=0.8, ls="--", label="1-sigma")
        ax.set_ylabel(label, fontsize="small")
        ax.set_ylim(bottom=0.0)
        ax.tick_params(labelsize="x-small")
        ax.grid(alpha=0.3)
        ax.vlines(
            refused_t,
            0.0,
            1.0,
            transform=ax.get_xaxis_transform(),
            color=REJECTED_COLOR,
            lw=0.6,
            alpha=0.6,
        )
    axes[0].legend(loc="upper left", fontsize="x-small", ncols=3)
    axes[-1].set_xlabel("log time [s]", fontsize="small")
    t_lo, t_hi = _time_span(plot.t)
    axes[-1].set_xlim(t_lo, t_hi)
    fig.draw_without_rendering()
    box = axes[-1].get_window_extent()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    width, height = round(fig.bbox.width), round(fig.bbox.height)
    return TimeStrip(
        png=buf.getvalue(),
        width_px=int(width),
        height_px=int(height),
        x_left_px=float(box.x0),
        x_right_px=float(box.x1),
        t_lo=t_lo,
        t_hi=t_hi,
    )


def _zoom_box(
    scene: SceneData, intervals: Sequence[tuple[float, float]]
) -> tuple[F64, F64, float] | None:
    """A square (lo, hi) around where the baseline is farthest from the compared run during the
    longest outage, large enough to show both tracks and the route there, and that distance;
    None when the run has no outage."""
    if not intervals:
        return None
    a, b = max(intervals, key=lambda iv: iv[1] - iv[0])
    prop, base = scene.proposed, scene.baseline
    m = (prop.t >= a) & (prop.t <= b)
    if m.sum() < 2 or len(base.t) < 2:
        return None
    t = prop.t[m]
    p = prop.xy[m]
    q = np.column_stack([np.interp(t, base.t, base.xy[:, 0]), np.interp(t, base.t, base.xy[:, 1])])
    gap = np.hypot(*(q - p).T)
    ok = np.isfinite(gap)
    if not ok.any():
        return None
    k = int(np.argmax(np.where(ok, gap, -1.0)))
    mid = (p[k] + q[k]) / 2
    half = max(0.75 * float(gap[k]) + 20.0, ZOOM_MIN_HALF_M)
    return mid - half, mid + half, float(gap[k])


def _draw_map(ax: Any, scene: SceneData, method: str, *, adjustable: str = "datalim") -> None:
    seg = scene.degraded_segments
    for k, s in enumerate(seg):
        ax.plot(s[:, 0], s[:, 1], color=OUTAGE_COLOR, lw=7, alpha=0.25, solid_capstyle="butt",
                label="GNSS outage" if k == 0 else None)  # fmt: skip
    ax.plot(*scene.route_line.T, color=ROUTE_COLOR, lw=2.5, label="route")
    if scene.truth is not None:
        ax.plot(*scene.truth.line.T, color=TRUTH_COLOR, lw=1.2, ls="--", label="truth")
    ax.plot(*scene.baseline.line.T, color=BASELINE_COLOR, lw=1.3, label="baseline")
    ax.plot(*scene.proposed.line.T, color=PROPOSED_COLOR, lw=1.3, label=method)
    if len(scene.match_xy):
        ok = scene.match_accepted
        ax.scatter(*scene.match_xy[ok].T, s=6, color=ACCEPTED_COLOR, zorder=1.5, label="accepted")
        ax.scatter(*scene.match_xy[~ok].T, s=6, color=REJECTED_COLOR, zorder=1.5, label="rejected")
    ax.set_aspect("equal", adjustable=adjustable)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.grid(alpha=0.3)


def trajectory_figure(
    scene: SceneData, intervals: Sequence[tuple[float, float]], method: str = "proposed"
) -> Figure:
    """The trajectories over the route (local ENU metres); with an outage, a second panel
    zoomed where the baseline drifted farthest in the longest one, its extent marked on the
    overview."""
    box = _zoom_box(scene, intervals)
    fig = Figure(figsize=(13, 6) if box is not None else (8, 7), layout="constrained")
    axes = fig.subplots(1, 2) if box is not None else [fig.subplots()]
    _draw_map(axes[0], scene, method)
    axes[0].set_title("Trajectories over the route")
    axes[0].legend(loc="best", fontsize="small")
    if box is not None:
        lo, hi, gap = box
        zoom = axes[1]
        _draw_map(zoom, scene, method, adjustable="box")
        zoom.set_xlim(lo[0], hi[0])
        zoom.set_ylim(lo[1], hi[1])
        a, b = max(intervals, key=lambda iv: iv[1] - iv[0])
        zoom.set_title(f"Largest baseline drift in the longest outage ({b - a:.0f} s): {gap:.1f} m")
        axes[0].add_patch(
            Rectangle(tuple(lo), *(hi - lo), fill=False, ec="k", lw=0.8, ls=":", zorder=6)
        )
    return fig
