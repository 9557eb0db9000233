"""Deviation plots (the paper's figures: position and heading deviation against time, baseline
vs proposed, GNSS outages shaded, the current time marked) and the metrics table, as data for
viser's uPlot element. Pure numpy: the series are computed once per run on the worker thread;
moving the time marker only rebuilds the x array around it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimator.results import Run
from estimator.route import Route

F64 = NDArray[np.float64]

MAX_PLOT_POINTS = 1500
"""Samples per series sent to the browser: about one per pixel of the panel."""

BASELINE_COLOR = "#e8710a"
PROPOSED_COLOR = "#1a73e8"
OUTAGE_FILL = "rgba(220, 50, 50, 0.15)"
NOW_COLOR = "#d62728"


def wrap_deg(a: F64) -> F64:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def route_deviation(run: Run, route: Route) -> tuple[F64, F64]:
    """Cross-track position deviation (m, positive = left of the route) and heading deviation
    (deg, vehicle yaw minus route direction) of each epoch, as in the paper's figures.

    Projection is windowed along the drive so a looping route cannot capture a point on its
    other branch."""
    xy = run.epochs.position[:, :2]
    n = len(xy)
    s = np.empty(n)
    lat = np.empty(n)
    guess: float | None = None
    chunk = 512
    for a in range(0, n, chunk):
        block = xy[a : a + chunk]
        if guess is None:
            proj = route.project(block)
        else:
            proj = route.project(block, np.full(len(block), guess), 2000.0)
        s[a : a + chunk] = proj.s
        lat[a : a + chunk] = proj.lateral
        guess = float(proj.s[-1])
    heading = np.degrees(route.heading_at(s))
    yaw = np.degrees(run.epochs.attitude[:, 2])
    return lat, wrap_deg(yaw - heading)


@dataclass(frozen=True)
class DeviationPlot:
    """Both runs' deviations on one time grid (s after the log start), thinned for display."""

    t: F64
    position: tuple[F64, F64]
    """(baseline, proposed) |cross-track deviation|, m"""
    heading: tuple[F64, F64]
    """(baseline, proposed) heading deviation, deg"""
    outages: tuple[tuple[float, float], ...]
    """GNSS-degraded intervals, s after start"""

    @classmethod
    def build(cls, inputs: Any, baseline: Run, proposed: Run) -> DeviationPlot:
        route: Route = inputs.route
        t0 = proposed.t0
        tp = proposed.epochs.t - t0
        grid = tp if len(tp) <= MAX_PLOT_POINTS else np.linspace(tp[0], tp[-1], MAX_PLOT_POINTS)
        outages = tuple((a - t0, b - t0) for a, b in proposed.degraded_intervals)
        grid = (
            np.unique(np.concatenate([grid, *[np.array(iv) for iv in outages]]))
            if outages
            else grid
        )
        pos, hdg = [], []
        for run in (baseline, proposed):
            lat, dh = route_deviation(run, route)
            tr = run.epochs.t - t0
            pos.append(_resample(tr, np.abs(lat), grid))
            hdg.append(_resample(tr, dh, grid, angle=True))
        return cls(t=grid, position=(pos[0], pos[1]), heading=(hdg[0], hdg[1]), outages=outages)

    def outage_mask(self, t: F64) -> F64:
        m = np.zeros(len(t))
        for a, b in self.outages:
            m[(t >= a) & (t <= b)] = 1.0
        return m

    def uplot(self, which: str, t_now: float) -> dict[str, Any]:
        """Keyword arguments for ``gui.add_uplot`` / the handle's props: data with the time
        marker inserted at ``t_now`` (three samples: down, up, down on a fixed 0..1 scale, so it
        spans the plot height whatever the data range)."""
        y_base, y_prop = self.position if which == "position" else self.heading
        t = self.t
        k = int(np.searchsorted(t, t_now))
        xs = np.insert(t, k, [t_now] * 3)
        yb = np.insert(y_base, k, [np.interp(t_now, t, y_base)] * 3)
        yp = np.insert(y_prop, k, [np.interp(t_now, t, y_prop)] * 3)
        shade = self.outage_mask(xs)
        now = np.full(len(xs), -1.0)
        now[k + 1] = 2.0
        unit = "m" if which == "position" else "deg"
        title = (
            "position deviation from the route"
            if which == "position"
            else "heading deviation from the route"
        )
        return {
            "data": (xs, yb, yp, shade, now),
            "series": (
                {"label": "t [s]"},
                {"label": f"baseline [{unit}]", "stroke": BASELINE_COLOR, "width": 1.5},
                {"label": f"proposed [{unit}]", "stroke": PROPOSED_COLOR, "width": 1.5},
                {
                    "label": "GNSS outage",
                    "scale": "band",
                    "stroke": "rgba(0,0,0,0)",
                    "fill": OUTAGE_FILL,
                    "width": 0,
                    "points": {"show": False},
                },
                {
                    "label": "now",
                    "scale": "band",
                    "stroke": NOW_COLOR,
                    "width": 1.5,
                    "points": {"show": False},
                },
            ),
            "scales": {"x": {"time": False}, "band": {"auto": False, "range": (0.0, 1.0)}},
            "title": title,
        }


def _resample(t: F64, y: F64, grid: F64, *, angle: bool = False) -> F64:
    ok = np.isfinite(y)
    if ok.sum() < 2:
        return np.zeros(len(grid))
    if angle:
        return wrap_deg(np.degrees(np.interp(grid, t[ok], np.unwrap(np.radians(y[ok])))))
    return np.interp(grid, t[ok], y[ok])


def _fmt(v: float, digits: int = 3) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def deviation_stats(pos: F64, hdg: F64) -> dict[str, float]:
    """The paper's table columns for one method over the given samples."""
    if len(pos) == 0:
        return {k: np.nan for k in ("max", "mean", "rmse", "hmean", "hrmse")}
    return {
        "max": float(np.max(pos)),
        "mean": float(np.mean(pos)),
        "rmse": float(np.sqrt(np.mean(pos**2))),
        "hmean": float(np.mean(hdg)),
        "hrmse": float(np.sqrt(np.mean(hdg**2))),
    }


def metrics_rows(inputs: Any, baseline: Run, proposed: Run) -> tuple[tuple[str, str, str], ...]:
    """Rows (quantity, baseline, proposed): the paper's route-relative deviations inside the
    GNSS-degraded intervals, then the match counts."""
    route: Route = inputs.route
    stats = []
    for run in (baseline, proposed):
        lat, dh = route_deviation(run, route)
        mask = np.zeros(len(run.epochs.t), bool)
        for a, b in run.degraded_intervals:
            mask |= (run.epochs.t >= a) & (run.epochs.t <= b)
        if not mask.any():
            mask[:] = True
        stats.append(deviation_stats(np.abs(lat[mask]), dh[mask]))
    labels = [
        ("max", "max position deviation [m]"),
        ("mean", "mean position deviation [m]"),
        ("rmse", "position deviation RMSE [m]"),
        ("hmean", "mean heading deviation [deg]"),
        ("hrmse", "heading deviation RMSE [deg]"),
    ]
    rows = [(label, _fmt(stats[0][k]), _fmt(stats[1][k])) for k, label in labels]
    n = len(proposed.matches)
    acc = sum(m.accepted for m in proposed.matches)
    rows.append(("match attempts (accepted / rejected)", "–", f"{n} ({acc} / {n - acc})"))
    return tuple(rows)


def metrics_markdown(rows: tuple[tuple[str, str, str], ...], method: str = "proposed") -> str:
    lines = [f"| | baseline | {method} |", "|---|---:|---:|"]
    lines += [f"| {q} | {b} | {p} |" for q, b, p in rows]
    return "\n".join(lines)
