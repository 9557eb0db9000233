"""How good a run is: the paper's route-relative deviations, and errors against ground truth.

The paper's logs have no ground truth, so it reports the deviation of the estimate from the
mission route (position: distance to the route; heading: against the route tangent). We report
the same table, and where a log carries truth also the horizontal, along-track and cross-track
errors and the heading error, since a solution can sit on the route and still be metres ahead of
the vehicle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from estimator.evaluation.exits import exit_notes
from estimator.log import Log
from estimator.matching import learn_lane_offset, track_on_route
from estimator.nav.frames import LocalFrame
from estimator.params import Params
from estimator.results import MapBiasRefusal, Run
from estimator.route import Route

F64 = NDArray[np.float64]

Intervals = Sequence[tuple[float, float]] | Literal["degraded", "all"] | None

_MIN_SPEED = 0.5
"""m/s below which the truth track has no direction of travel"""
_MAX_TRUTH_GAP = 1.0
"""s: truth is not interpolated across longer gaps"""


@dataclass(frozen=True)
class RouteDeviation:
    """The paper's five columns. None when no epoch falls in the evaluated intervals."""

    max_pos_dev_m: float | None
    mean_pos_dev_m: float | None
    rmse_pos_dev_m: float | None
    mean_heading_dev_deg: float | None
    rmse_heading_dev_deg: float | None


@dataclass(frozen=True)
class TruthErrors:
    """Errors against ground truth; along/cross decomposed by the truth direction of travel."""

    max_h_err_m: float | None
    mean_h_err_m: float | None
    rmse_h_err_m: float | None
    rmse_along_m: float | None
    rmse_cross_m: float | None
    rmse_heading_err_deg: float | None


@dataclass(frozen=True)
class MethodMetrics:
    route: RouteDeviation
    truth: TruthErrors | None
    """None when the log has no ground truth"""
    n_epochs: int
    """epochs evaluated"""

    def to_dict(self) -> dict[str, dict[str, float | None] | None]:
        return {
            "route": dict(vars(self.route)),
            "truth": None if self.truth is None else dict(vars(self.truth)),
        }


@dataclass(frozen=True)
class TruthSeries:
    """Errors against truth at the epochs truth covers (``index`` into the run's epochs)."""

    index: NDArray[np.intp]
    t: F64
    h_err_m: F64
    along_err_m: F64
    """positive = estimate ahead of the vehicle"""
    cross_err_m: F64
    """positive = estimate left of the vehicle"""
    heading_err_deg: F64
    """estimate minus truth, wrapped to [-180, 180); 0 where truth has no heading (standstill)"""
    heading_known: NDArray[np.bool_]


@dataclass(frozen=True)
class DeviationSeries:
    """Per-epoch deviations for plots (absolute times; subtract ``run.t0`` for display)."""

    t: F64
    degraded: NDArray[np.bool_]
    lateral_m: F64
    """signed offset of the estimate from the route, positive = left (lane offset removed if
    asked)"""
    pos_dev_m: F64
    """|lateral_m|: the paper's position deviation"""
    heading_dev_deg: F64
    """estimate yaw minus route heading, wrapped to [-180, 180)"""
    route_s: F64
    """arc length of the foot point"""
    truth: TruthSeries | None


def _wrap_deg(a: F64) -> F64:
    return (np.degrees(a) + 180.0) % 360.0 - 180.0


def interval_mask(t: F64, intervals: Sequence[tuple[float, float]]) -> NDArray[np.bool_]:
    """Epochs inside any of the closed intervals."""
    m = np.zeros(len(t), bool)
    for a, b in intervals:
        m |= (t >= a) & (t <= b)
    return m


def outage_errors(run: Run, log: Log, frame: LocalFrame) -> tuple[F64, F64]:
    """The horizontal error against truth ((N, 2) E, N, m) and its NEES (``(N,)``, 2 dof:
    e' P^-1 e with the filter's own horizontal covariance) at the run's epochs inside its
    GNSS-degraded intervals and the truth's span; empty without truth. Is the covariance
    honest? The NEES averages 2, and 5 % of epochs exceed 5.99, when it is. The E-N
    covariance counts: in an outage the ellipse is long along the road, and the E and N
    sigmas alone would spread its length over any error across a diagonal road."""
    if log.truth is None:
        return np.zeros((0, 2)), np.zeros(0)
    e = run.epochs
    sel = interval_mask(e.t, run.degraded_intervals) & (e.t <= log.truth.t[-1])
    truth = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
    err: F64 = e.position[sel, :2] - np.column_stack(
        [np.interp(e.t[sel], log.truth.t, truth[:, i]) for i in range(2)]
    )
    return err, horizontal_nees(err, e.position_sigma[sel, :2] ** 2, e.position_cov_en[sel])


NEES_95_2DOF = 5.991
"""the chi-square of 2 degrees of freedom at 95 %: a horizontal NEES exceeds it on 5 % of epochs
when the covariance is honest (and the ellipse it bounds holds 95 % of the errors)"""


def horizontal_nees(err: F64, var_en: F64, cov_en: F64) -> F64:
    """e' P^-1 e per row for the errors ``err`` ((N, 2) E, N) under P = [[var_e, cov], [cov,
    var_n]]; a row whose P is not positive definite (rounding) is taken without its cov."""
    var_e, var_n = var_en[:, 0], var_en[:, 1]
    det = var_e * var_n - cov_en**2
    ok = det > 1e-12 * var_e * var_n
    cov = np.where(ok, cov_en, 0.0)
    det = np.where(ok, det, var_e * var_n)
    e, n = err[:, 0], err[:, 1]
    # P^-1 = [[var_n, -cov], [-cov, var_e]] / det
    nees: F64 = (var_n * e * e - 2.0 * cov * e * n + var_e * n * n) / det
    return nees


def _lane_offsets(run: Run, route: Route, s: F64, lat: F64, params: Params) -> F64:
    """Per-epoch learned lane offset: inside each degraded interval the offset learned from the
    good-GNSS epochs before it; elsewhere the same exponential average, run causally."""
    ep = run.epochs
    tau = params.offset.time_constant_s
    inside = (s > 1e-6) & (s < route.length - 1e-6)
    use = ep.gnss_used & inside
    out = np.zeros(len(ep.t))
    acc = w_acc = 0.0
    t_prev = float(ep.t[0]) if len(ep.t) else 0.0
    for k in range(len(ep.t)):
        decay = np.exp(-(float(ep.t[k]) - t_prev) / tau)
        acc *= decay
        w_acc *= decay
        t_prev = float(ep.t[k])
        if use[k]:
            acc += float(lat[k])
            w_acc += 1.0
        mean = acc / w_acc if w_acc > 0 else 0.0
        out[k] = mean if abs(mean) <= params.offset.max_offset_m else 0.0
    pos = ep.position[:, :2]
    for a, b in run.degraded_intervals:
        m = (ep.t >= a) & (ep.t <= b)
        if m.any():
            out[m] = learn_lane_offset(ep.t, pos, ep.gnss_used, route, t_end=a, params=params)
    return out


def _bracketed(t_src: F64, t: F64) -> NDArray[np.bool_]:
    """Query times that lie between two samples at most ``_MAX_TRUTH_GAP`` apart."""
    if len(t_src) < 2:
        return np.zeros(len(t), bool)
    j = np.clip(np.searchsorted(t_src, t), 1, len(t_src) - 1)
    inside = (t >= t_src[0]) & (t <= t_src[-1])
    bracketed: NDArray[np.bool_] = inside & ((t_src[j] - t_src[j - 1]) <= _MAX_TRUTH_GAP)
    return bracketed


def _truth_series(run: Run, log: Log) -> TruthSeries | None:
    truth = log.truth
    if truth is None or len(truth.t) < 2:
        return None
    enu = run.frame.to_enu(truth.lat, truth.lon, truth.alt)
    ok = np.isfinite(truth.t) & np.all(np.isfinite(enu[:, :2]), axis=1)
    shift = run.params.sensors.truth_time_offset_s
    tt, xy, hd = truth.t[ok] + shift, enu[ok, :2], truth.heading[ok]
    order = np.argsort(tt, kind="stable")
    tt, xy, hd = tt[order], xy[order], hd[order]
    keep = np.r_[True, np.diff(tt) > 0]
    tt, xy, hd = tt[keep], xy[keep], hd[keep]
    if len(tt) < 2:
        return None
    idx = np.flatnonzero(_bracketed(tt, run.epochs.t))
    if not len(idx):
        return None
    t_e = run.epochs.t[idx]
    p_true = np.column_stack([np.interp(t_e, tt, xy[:, 0]), np.interp(t_e, tt, xy[:, 1])])
    vel = np.gradient(xy, tt, axis=0)
    v_e = np.column_stack([np.interp(t_e, tt, vel[:, 0]), np.interp(t_e, tt, vel[:, 1])])
    speed = np.hypot(v_e[:, 0], v_e[:, 1])
    moving = speed > _MIN_SPEED
    # the truth heading where given, else the direction of travel
    heading = np.arctan2(v_e[:, 1], v_e[:, 0])
    known = moving.copy()
    hd_ok = np.isfinite(hd)
    if hd_ok.sum() >= 2:
        near = _bracketed(tt[hd_ok], t_e)
        h_e = np.interp(t_e, tt[hd_ok], np.unwrap(hd[hd_ok]))
        heading = np.where(near, h_e, heading)
        known |= near
    err = run.epochs.position[idx, :2] - p_true
    fwd = np.where(
        moving[:, None],
        v_e / np.maximum(speed, 1e-12)[:, None],
        np.column_stack([np.cos(heading), np.sin(heading)]),
    )
    along = np.einsum("ij,ij->i", err, fwd)
    cross = fwd[:, 0] * err[:, 1] - fwd[:, 1] * err[:, 0]
    dh = _wrap_deg(run.epochs.attitude[idx, 2] - heading)
    return TruthSeries(
        index=idx,
        t=t_e,
        h_err_m=np.hypot(err[:, 0], err[:, 1]),
        along_err_m=np.where(known, along, 0.0),
        cross_err_m=np.where(known, cross, 0.0),
        heading_err_deg=np.where(known, dh, 0.0),
        heading_known=known,
    )


def deviation_series(
    run: Run,
    route: Route,
    log: Log | None = None,
    *,
    subtract_lane_offset: bool = False,
    params: Params | None = None,
) -> DeviationSeries:
    """Position and heading deviation from the route at every epoch, and the errors against
    truth where the log has it. ``subtract_lane_offset``: measure from the lane the vehicle
    kept under good GNSS (learned as the estimator learns it, with ``params.offset``) rather
    than from the route centreline.

    The inspector asks for the same run's series twice per session (plot and table) and for
    the unchanged baseline after every parameter change, so the last few results are kept,
    by the identity of the (immutable) epochs, route and log they were computed from."""
    key = (
        id(run.epochs),
        id(route),
        id(log),
        run.degraded_intervals,
        run.frame,
        run.params.sensors,
        subtract_lane_offset,
        (params or run.params) if subtract_lane_offset else None,
    )
    for entry_key, owners, series in _SERIES_CACHE:
        if entry_key == key and owners[0] is run.epochs:
            return series
    series = _deviation_series(run, route, log, subtract_lane_offset, params)
    _SERIES_CACHE.insert(0, (key, (run.epochs, route, log), series))
    del _SERIES_CACHE[_SERIES_CACHE_SIZE:]
    return series


_SERIES_CACHE_SIZE = 6
_SERIES_CACHE: list[tuple[tuple[object, ...], tuple[object, ...], DeviationSeries]] = []
"""(key, the objects whose ids are in it, kept alive so an id is not reused, series)"""


def _deviation_series(
    run: Run,
    route: Route,
    log: Log | None,
    subtract_lane_offset: bool,
    params: Params | None,
) -> DeviationSeries:
    ep = run.epochs
    xy = ep.position[:, :2]
    s, lat = track_on_route(route, xy)
    if subtract_lane_offset and len(xy):
        lat = lat - _lane_offsets(run, route, s, lat, params or run.params)
    dh = _wrap_deg(ep.attitude[:, 2] - route.smooth_heading_at(s)) if len(xy) else np.empty(0)
    return DeviationSeries(
        t=ep.t,
        degraded=ep.degraded | interval_mask(ep.t, run.degraded_intervals),
        lateral_m=lat,
        pos_dev_m=np.abs(lat),
        heading_dev_deg=dh,
        route_s=s,
        truth=None if log is None else _truth_series(run, log),
    )


def _rmse(x: F64) -> float | None:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else None


def _mean(x: F64) -> float | None:
    return float(np.mean(x)) if len(x) else None


def _max(x: F64) -> float | None:
    return float(np.max(x)) if len(x) else None


def _selection(run: Run, intervals: Intervals) -> NDArray[np.bool_]:
    t = run.epochs.t
    if intervals == "all":
        return np.ones(len(t), bool)
    if intervals is None or intervals == "degraded":
        return interval_mask(t, run.degraded_intervals)
    return interval_mask(t, intervals)


def method_metrics(
    run: Run,
    route: Route,
    log: Log | None,
    *,
    intervals: Intervals = None,
    subtract_lane_offset: bool = False,
    params: Params | None = None,
) -> MethodMetrics:
    """The paper's table row for one run, plus truth errors when ``log`` has truth.

    ``intervals``: None or "degraded" = the run's GNSS-degraded intervals (the paper's
    setting), "all" = the whole log, or explicit (t0, t1) pairs on the log's clock.
    """
    series = deviation_series(
        run, route, log, subtract_lane_offset=subtract_lane_offset, params=params
    )
    sel = _selection(run, intervals)
    pos = series.pos_dev_m[sel]
    dh = series.heading_dev_deg[sel]
    route_dev = RouteDeviation(
        max_pos_dev_m=_max(pos),
        mean_pos_dev_m=_mean(pos),
        rmse_pos_dev_m=_rmse(pos),
        mean_heading_dev_deg=_mean(dh),
        rmse_heading_dev_deg=_rmse(dh),
    )
    truth = None
    ts = series.truth
    if ts is not None:
        in_sel = sel[ts.index]
        known = in_sel & ts.heading_known
        h = ts.h_err_m[in_sel]
        truth = TruthErrors(
            max_h_err_m=_max(h),
            mean_h_err_m=_mean(h),
            rmse_h_err_m=_rmse(h),
            rmse_along_m=_rmse(ts.along_err_m[known]),
            rmse_cross_m=_rmse(ts.cross_err_m[known]),
            rmse_heading_err_deg=_rmse(ts.heading_err_deg[known]),
        )
    elif log is not None and log.truth is not None:
        truth = TruthErrors(None, None, None, None, None, None)
    return MethodMetrics(route=route_dev, truth=truth, n_epochs=int(sel.sum()))


def match_summary(run: Run) -> dict[str, object]:
    """Attempts, acceptances and, per gate, the rejections it was the first to cause."""
    rejected: dict[str, int] = {}
    accepted = 0
    for rec in run.matches:
        if rec.accepted:
            accepted += 1
            continue
        failed = rec.failed_gates
        name = failed[0].name if failed else "other"
        rejected[name] = rejected.get(name, 0) + 1
    return {"attempted": len(run.matches), "accepted": accepted, "rejected": rejected}


_REFUSALS: dict[MapBiasRefusal, str] = {
    "too large": "too large for a map's error",
    "lane too far": "the lane it implies too far from the route",
}


def map_bias_notes(run: Run) -> list[str]:
    """One line per GNSS-degraded interval that was matched with a map bias
    (``extensions.map_bias``): what the approach measured, along and across the road, and
    whether it was applied, taken for another road, or found not significant (the route taken
    as right). A map the run corrected must say so: the route deviation alone would call the
    corrected run "off the route"; and a bias refused as another road is not a right map."""
    notes = []
    for a, b in run.degraded_intervals:
        rec = next(
            (m for m in run.matches if a <= m.t <= b and m.map_bias is not None and m.fit), None
        )
        if rec is None or rec.map_bias is None or rec.fit is None:
            continue
        bias, n, t = rec.map_bias, rec.normal, rec.tangent
        if not bias.applied and not np.all(np.isfinite(bias.learned)):
            notes.append(
                f"map bias for the outage at {a - run.t0:.1f} s: nothing measured (too little "
                "GNSS-good driving before it, or its GNSS track does not follow the route); "
                "the route taken as right"
            )
            continue
        learned = bias.learned if np.all(np.isfinite(bias.learned)) else bias.offset
        along, across = float(t @ learned), float(n @ learned)
        measured = (
            f"{abs(along):.1f} m {'ahead' if along >= 0 else 'behind'} and {abs(across):.1f} m "
            f"{'left' if across >= 0 else 'right'} of the road driven at the approach's end"
        )
        if bias.rotation_rad:
            measured += f", turned {math.degrees(bias.rotation_rad):+.2f} deg about there"
        if bias.applied:
            verdict = (
                f"applied (sigma {math.sqrt(float(t @ bias.cov @ t)):.1f} m along, "
                f"{math.sqrt(float(n @ bias.cov @ n)):.1f} m across)"
            )
        elif bias.refused is not None:
            verdict = f"not applied: {_REFUSALS[bias.refused]} (another road?)"
        else:
            verdict = "not significant: the route taken as right"
        notes.append(
            f"map bias for the outage at {a - run.t0:.1f} s: the route is drawn {measured}; "
            f"{verdict}"
        )
    return notes


def portal_notes(run: Run) -> list[str]:
    """One line per GNSS-degraded interval before which the portal's fixed-lag re-run left
    fixes out (``extensions.portal_rerun``): a filter that enters an outage from a place its
    last fixes do not show must say which fixes it did not believe."""
    if not run.dropped_fix_times:
        return []
    dropped = np.asarray(run.dropped_fix_times, np.float64)
    lag = run.params.noise.gnss_rerun_lag_s
    notes = []
    for a, _ in run.degraded_intervals:
        here = dropped[(dropped >= a - lag - 1.0) & (dropped <= a)]
        if len(here) == 0:
            continue
        fixes = "1 fix" if len(here) == 1 else f"{len(here)} fixes"
        notes.append(
            f"portal re-run before the outage at {a - run.t0:.1f} s: {fixes} of "
            f"{here.min() - run.t0:.1f}-{here.max() - run.t0:.1f} s left out (they disagreed "
            "with dead reckoning)"
        )
    return notes


def unattempted_notes(run: Run) -> list[str]:
    """One line per GNSS-degraded interval of a matching run in which no match was attempted
    because the outage was too short or too little was driven in it
    (``trigger.min_outage_s``, ``trigger.min_outage_distance_m``): "0 of 0" says nothing of
    why. The distance is the dead-reckoned speed integrated over the interval."""
    if run.method == "baseline" or not run.degraded_intervals:
        return []
    tr = run.params.trigger
    e = run.epochs
    notes = []
    for a, b in run.degraded_intervals:
        if any(a <= m.t <= b for m in run.matches):
            continue
        sel = (e.t >= a) & (e.t <= b)
        driven = float(np.trapezoid(np.hypot(e.velocity[sel, 0], e.velocity[sel, 1]), e.t[sel]))
        if b - a < tr.min_outage_s:
            why = f"it lasted {b - a:.1f} s, under trigger.min_outage_s {tr.min_outage_s:g} s"
        elif driven < tr.min_outage_distance_m:
            why = (
                f"{driven:.1f} m were driven in it by dead reckoning, under "
                f"trigger.min_outage_distance_m {tr.min_outage_distance_m:g} m"
            )
        else:
            continue
        notes.append(f"no match attempted in the outage at {a - run.t0:.1f} s: {why}")
    return notes


def run_notes(run: Run) -> list[str]:
    """What a run did at its outages, outage kind by kind, as ``routefuse run`` prints it and
    the inspector shows it under its status line: the fixes its portal re-runs left out
    (:func:`portal_notes`), the outages too short for any attempt
    (:func:`unattempted_notes`), the map biases measured (:func:`map_bias_notes`) and how far
    each outage ended from the fixes after it (:func:`~estimator.evaluation.exits.exit_notes`)."""
    return [*portal_notes(run), *unattempted_notes(run), *map_bias_notes(run), *exit_notes(run)]


_ROUTE_COLUMNS = (
    ("max_pos_dev_m", "Max pos. dev. [m]"),
    ("mean_pos_dev_m", "Mean pos. dev. [m]"),
    ("rmse_pos_dev_m", "Pos. dev. RMSE [m]"),
    ("mean_heading_dev_deg", "Mean heading dev. [deg]"),
    ("rmse_heading_dev_deg", "Heading dev. RMSE [deg]"),
)
_TRUTH_COLUMNS = (
    ("max_h_err_m", "Max h. err [m]"),
    ("mean_h_err_m", "Mean h. err [m]"),
    ("rmse_h_err_m", "H. err RMSE [m]"),
    ("rmse_along_m", "Along RMSE [m]"),
    ("rmse_cross_m", "Cross RMSE [m]"),
    ("rmse_heading_err_deg", "Heading err RMSE [deg]"),
)


def format_table(
    rows: Sequence[tuple[str, str, MethodMetrics]],
    *,
    style: Literal["text", "markdown"] = "text",
) -> str:
    """The paper's table layout (scenario, method, five route columns), with the truth columns
    appended when any row has truth. ``rows``: (scenario, method, metrics)."""
    with_truth = any(m.truth is not None for _, _, m in rows)
    columns = _ROUTE_COLUMNS + (_TRUTH_COLUMNS if with_truth else ())
    header = ["Scenario", "Method", *[title for _, title in columns]]

    def cell(v: float | None, key: str) -> str:
        if v is None:
            return "-"
        return f"{v:.3f}" if "heading" in key or "mean" in key or "rmse" in key else f"{v:.1f}"

    body = []
    for scenario, method, m in rows:
        values = {**vars(m.route), **(vars(m.truth) if m.truth is not None else {})}
        body.append([scenario, method, *[cell(values.get(k), k) for k, _ in columns]])
    if style == "markdown":
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(r) + " |" for r in body]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in [header, *body]) for i in range(len(header))]

    def line(r: list[str]) -> str:
        return "  ".join(
            c.ljust(w) if i < 2 else c.rjust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        ).rstrip()

    return "\n".join([line(header), line(["-" * w for w in widths]), *[line(r) for r in body]])
