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

from estimator.evaluation.metrics import deviation_series, match_summary, method_metrics
from estimator.results import Run
from estimator.route import Route

F64 = NDArray[np.float64]

MAX_PLOT_POINTS = 1500
"""Samples per series sent to the browser: about one per pixel of the panel."""

BASELINE_COLOR = "#e8710a"
PROPOSED_COLOR = "#1a73e8"
PINNED_COLOR = "#963cc8"
"""run A of a comparison (the Compare tab), as its trajectory on the map"""
OUTAGE_FILL = "rgba(220, 50, 50, 0.15)"
NOW_COLOR = "#d62728"


def wrap_deg(a: F64) -> F64:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class DeviationPlot:
    """Both runs' deviations from the route (``estimator.evaluation.metrics.deviation_series``, the
    quantities of the metrics table) on one time grid (s after the log start), thinned for
    display; and the horizontal error against truth when the log has truth."""

    t: F64
    position: tuple[F64, F64]
    """(baseline, proposed) |cross-track deviation|, m"""
    heading: tuple[F64, F64]
    """(baseline, proposed) heading deviation, deg"""
    outages: tuple[tuple[float, float], ...]
    """GNSS-degraded intervals, s after start"""
    truth: tuple[F64, F64] | None = None
    """(baseline, proposed) horizontal error against truth, m (NaN where truth is missing)"""
    sigma: F64 | None = None
    """the proposed run's horizontal 1-sigma, m, drawn beside its error against truth: an
    error far above it is a filter that claims to know more than it does"""

    @classmethod
    def build(cls, inputs: Any, baseline: Run, proposed: Run) -> DeviationPlot:
        route: Route = inputs.route
        log = getattr(inputs, "log", None)
        t0 = proposed.t0
        tp = proposed.epochs.t - t0
        grid = tp if len(tp) <= MAX_PLOT_POINTS else np.linspace(tp[0], tp[-1], MAX_PLOT_POINTS)
        outages = tuple((a - t0, b - t0) for a, b in proposed.degraded_intervals)
        if outages:
            grid = np.unique(np.concatenate([grid, np.ravel(outages)]))
        pos, hdg, err = [], [], []
        for run in (baseline, proposed):
            series = deviation_series(run, route, log)
            tr = run.epochs.t - t0
            pos.append(_resample(tr, series.pos_dev_m, grid))
            hdg.append(_resample(tr, series.heading_dev_deg, grid, angle=True))
            if series.truth is not None and len(series.truth.t) > 1:
                err.append(_resample(series.truth.t - t0, series.truth.h_err_m, grid, gaps=True))
        truth = (err[0], err[1]) if len(err) == 2 else None
        sigma = np.hypot(proposed.epochs.position_sigma[:, 0], proposed.epochs.position_sigma[:, 1])
        return cls(
            t=grid,
            position=(pos[0], pos[1]),
            heading=(hdg[0], hdg[1]),
            outages=outages,
            truth=truth,
            sigma=None if truth is None else _resample(tp, sigma, grid),
        )

    @property
    def kinds(self) -> tuple[str, ...]:
        return ("position", "heading") + (("truth",) if self.truth is not None else ())

    def outage_mask(self, t: F64) -> F64:
        m = np.zeros(len(t))
        for a, b in self.outages:
            m[(t >= a) & (t <= b)] = 1.0
        return m

    def uplot(self, which: str, t_now: float) -> dict[str, Any]:
        """Keyword arguments for ``gui.add_uplot`` / the handle's props: data with the time
        marker inserted at ``t_now`` (three samples: down, up, down on a fixed 0..1 scale, so it
        spans the plot height whatever the data range)."""
        y_base, y_prop = {"position": self.position, "heading": self.heading, "truth": self.truth}[
            which
        ] or (self.t * 0, self.t * 0)
        t = self.t
        k = int(np.searchsorted(t, t_now))
        xs = np.insert(t, k, [t_now] * 3)
        yb = np.insert(y_base, k, [np.interp(t_now, t, np.nan_to_num(y_base))] * 3)
        yp = np.insert(y_prop, k, [np.interp(t_now, t, np.nan_to_num(y_prop))] * 3)
        shade = self.outage_mask(xs)
        now = np.full(len(xs), -1.0)
        now[k + 1] = 2.0
        unit = "deg" if which == "heading" else "m"
        title = {
            "position": "position deviation from the route",
            "heading": "heading deviation from the route",
            "truth": "horizontal error against ground truth",
        }[which]
        data: tuple[F64, ...] = (xs, yb, yp, shade, now)
        extra: tuple[dict[str, Any], ...] = ()
        if which == "truth" and self.sigma is not None:
            ys = np.insert(self.sigma, k, [np.interp(t_now, t, self.sigma)] * 3)
            data += (ys,)
            extra = (
                {
                    "label": "proposed 1-sigma [m]",
                    "stroke": PROPOSED_COLOR,
                    "width": 1,
                    "dash": [4, 4],
                    "points": {"show": False},
                },
            )
        return {
            "data": data,
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
                *extra,
            ),
            "scales": {"x": {"time": False}, "band": {"auto": False, "range": (0.0, 1.0)}},
            "title": title,
        }


def pinned_uplot(a: DeviationPlot, b: DeviationPlot, which: str, t_now: float) -> dict[str, Any]:
    """The proposed run of A (pinned) against B's, on B's time grid, in the form of
    :meth:`DeviationPlot.uplot`: the same plot with A in place of the baseline."""
    kw = b.uplot(which, t_now)
    xs = kw["data"][0]
    y_a = {"position": a.position, "heading": a.heading, "truth": a.truth}[which]
    assert y_a is not None
    ya = np.interp(xs, a.t, np.nan_to_num(y_a[1]), left=np.nan, right=np.nan)
    series = list(kw["series"])
    unit = series[2]["label"].split("[")[1]
    series[1] = {"label": f"A (pinned) [{unit}", "stroke": PINNED_COLOR, "width": 1.5}
    series[2] = {**series[2], "label": f"B (on screen) [{unit}"}
    return {
        **kw,
        "data": (xs, ya, *kw["data"][2:]),
        "series": tuple(series),
        "title": f"A against B: {kw['title']}",
    }


def _resample(t: F64, y: F64, grid: F64, *, angle: bool = False, gaps: bool = False) -> F64:
    """``y(t)`` on ``grid``; with ``gaps`` the grid points farther than a second from any
    sample are NaN (truth that stops is not drawn as a straight line)."""
    ok = np.isfinite(y)
    if ok.sum() < 2:
        return np.full(len(grid), np.nan if gaps else 0.0)
    if angle:
        out = wrap_deg(np.degrees(np.interp(grid, t[ok], np.unwrap(np.radians(y[ok])))))
    else:
        out = np.interp(grid, t[ok], y[ok])
    if gaps:
        i = np.clip(np.searchsorted(t[ok], grid), 1, ok.sum() - 1)
        near = np.minimum(np.abs(grid - t[ok][i - 1]), np.abs(t[ok][i] - grid))
        out[near > 1.0] = np.nan
    return out


def _fmt(v: float | None, digits: int = 3) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


_ROW_LABELS = (
    ("route", "max_pos_dev_m", "max position deviation [m]", 1),
    ("route", "mean_pos_dev_m", "mean position deviation [m]", 3),
    ("route", "rmse_pos_dev_m", "position deviation RMSE [m]", 3),
    ("route", "mean_heading_dev_deg", "mean heading deviation [deg]", 3),
    ("route", "rmse_heading_dev_deg", "heading deviation RMSE [deg]", 3),
    ("truth", "max_h_err_m", "max error vs truth [m]", 1),
    ("truth", "mean_h_err_m", "mean error vs truth [m]", 3),
    ("truth", "rmse_h_err_m", "error vs truth RMSE [m]", 3),
    ("truth", "rmse_along_m", "along-track RMSE [m]", 3),
    ("truth", "rmse_cross_m", "cross-track RMSE [m]", 3),
    ("truth", "rmse_heading_err_deg", "heading error RMSE [deg]", 3),
)


def metrics_rows(inputs: Any, baseline: Run, proposed: Run) -> tuple[tuple[str, str, str], ...]:
    """Rows (quantity, baseline, proposed) of the ``routefuse run`` table
    (:func:`estimator.evaluation.metrics.method_metrics` over the GNSS-degraded intervals), then
    the match summary."""
    route: Route = inputs.route
    log = getattr(inputs, "log", None)
    per_run = [method_metrics(run, route, log) for run in (baseline, proposed)]
    rows: list[tuple[str, str, str]] = []
    for part, key, label, digits in _ROW_LABELS:
        values = [
            getattr(getattr(m, part), key) if getattr(m, part) is not None else None
            for m in per_run
        ]
        if part == "truth" and all(v is None for v in values):
            continue
        base_value, proposed_value = (_fmt(v, digits) for v in values)
        rows.append((label, base_value, proposed_value))
    base_flagged, flagged = (sum(x.overconfident for x in r.exits) for r in (baseline, proposed))
    rows.append(("outages ended beyond their sigmas (exit check)", str(base_flagged), str(flagged)))
    summary = match_summary(proposed)
    rejected = summary["rejected"]
    assert isinstance(rejected, dict)
    n_rej = sum(rejected.values())
    rows.append(
        (
            "match attempts (accepted / rejected)",
            "–",
            f"{summary['attempted']} ({summary['accepted']} / {n_rej})",
        )
    )
    for gate, n in sorted(rejected.items(), key=lambda kv: -kv[1]):
        rows.append((f"rejected first by {gate}", "–", str(n)))
    return tuple(rows)


def metrics_markdown(rows: tuple[tuple[str, str, str], ...], method: str = "proposed") -> str:
    lines = [f"| | baseline | {method} |", "|---|---:|---:|"]
    lines += [f"| {q} | {b} | {p} |" for q, b, p in rows]
    return "\n".join(lines)
