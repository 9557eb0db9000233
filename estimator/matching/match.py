"""The route match of one window: the paper's shape registration plus routefuse's validation.

The last ``window.length_m`` of dead-reckoned travel is resampled at a fixed spacing, paired by
arc length with the route segment that starts where the window's first point projects, and
registered to it with a rigid 2-D transform (Kabsch). The current DR position mapped by that
transform, shifted by the learned lane offset, is the pseudo-position the filter is updated with.

Beyond the paper (each switchable in :class:`~estimator.params.ExtensionParams`): the route
segment's arc-length offset is searched, so route shape can correct along-track drift where the
road bends; the observation covariance follows the route geometry, so a straight road says
"along-track unknown" instead of pretending; and a candidate is validated against the filter's
own covariance, the lane the vehicle was in, and laterally shifted and reversed rivals, because a
parallel carriageway has the same shape and would pass every shape gate.

Every intermediate and every gate goes into a :class:`~estimator.results.MatchRecord`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from estimator.errors import RouteError, RoutefuseError
from estimator.matching.kernels import (
    nearest_arc,
    offset_polyline,
    pair_points,
    polyline_arrays,
    project_window,
    rigid_fit,
    rival_score,
    rotation_sigma,
    scan_offsets,
    segment_index,
    segment_points,
    track_chunks,
    unit_interval,
)
from estimator.params import Params
from estimator.results import Comparison, GateDecision, MatchRecord
from estimator.route import Route

F64 = NDArray[np.float64]

GATE_NAMES = (
    "min_pairs",
    "heading",
    "residual",
    "rotation",
    "mahalanobis",
    "lane_continuity",
    "alternative_left",
    "alternative_right",
    "alternative_reversed",
    "correction_cap",
)
"""Every gate a match record can hold, in the order they are evaluated."""


def resample_polyline(
    xy: ArrayLike, spacing: float, *, anchor: Literal["start", "end"] = "end"
) -> F64:
    """Points every ``spacing`` metres of arc length along a polyline, in its order.

    Removes the effect of speed and sampling rate on the window's shape. With ``anchor="end"``
    the last point is the polyline's last point (the current position), so the terminal pair
    and ``p_ref`` refer to where the vehicle is now; the first point is up to one spacing after
    the polyline's start.
    """
    p = np.asarray(xy, np.float64)[:, :2]
    d = p[1:] - p[:-1]
    c = np.empty(len(p))
    c[0] = 0.0
    np.cumsum(np.hypot(d[:, 0], d[:, 1]), out=c[1:])
    total = float(c[-1])
    n = int(np.floor(total / spacing + 1e-9)) + 1
    steps = spacing * np.arange(n)
    at = total - steps[::-1] if anchor == "end" else steps
    out = np.empty((n, 2))
    out[:, 0] = np.interp(at, c, p[:, 0])
    out[:, 1] = np.interp(at, c, p[:, 1])
    return out


def kabsch_2d(src: ArrayLike, dst: ArrayLike, weights: ArrayLike | None = None) -> tuple[F64, F64]:
    """The proper rotation R and translation t minimising sum w_i |R src_i + t - dst_i|^2.

    SVD of the cross-covariance C = U S V^T, R = V diag(1, det(V U^T)) U^T: the diagonal guard
    refuses reflections, so a mirrored shape is fitted by the best rotation, with its residual.
    Accepts (n, 2) arrays or stacks (k, n, 2); returns R (…, 2, 2) and t (…, 2).
    """
    s = np.asarray(src, np.float64)
    d = np.asarray(dst, np.float64)
    single = s.ndim == 2 and d.ndim == 2
    d3 = d[None] if d.ndim == 2 else d
    s3 = np.broadcast_to(s[None] if s.ndim == 2 else s, d3.shape)
    w = (
        np.ones(d3.shape[:2])
        if weights is None
        else np.broadcast_to(np.asarray(weights, np.float64), d3.shape[:2])
    )
    rot, trans, _ = _kabsch(s3, d3, w)
    return (rot[0], trans[0]) if single else (rot, trans)


def _kabsch(src: F64, dst: F64, w: F64) -> tuple[F64, F64, F64]:
    """Batched weighted Kabsch: R (k, 2, 2), t (k, 2) and the weighted mean squared residual."""
    wsum = np.maximum(w.sum(axis=1), 1e-300)
    w3 = w[:, :, None]
    cs = (w3 * src).sum(axis=1) / wsum[:, None]
    ct = (w3 * dst).sum(axis=1) / wsum[:, None]
    a = src - cs[:, None]
    b = dst - ct[:, None]
    aw = w3 * a
    cov = np.swapaxes(aw, 1, 2) @ b
    u, _, vt = np.linalg.svd(cov)
    v = np.swapaxes(vt, 1, 2).copy()
    ut = np.swapaxes(u, 1, 2)
    sign = np.sign(np.linalg.det(v @ ut))
    sign[sign == 0] = 1.0
    v[:, :, 1] *= sign[:, None]
    rot = v @ ut
    trans = ct - (rot @ cs[:, :, None])[:, :, 0]
    # sum w |R a - b|^2 = sum w |a|^2 + sum w |b|^2 - 2 tr(R C)
    sq = (aw * a).sum(axis=(1, 2)) + (w3 * b * b).sum(axis=(1, 2))
    tr = np.einsum("kij,kji->k", rot, cov)
    ms = np.maximum(sq - 2.0 * tr, 0.0) / wsum
    return rot, trans, ms


def _kabsch_one(src: F64, dst: F64, w: F64) -> tuple[F64, F64, float]:
    """:func:`_kabsch` of one (n, 2) pair of point sets: the same numpy operations in the same
    order, so the same values bit for bit, without the batch axis's overhead (the matcher fits
    once per attempt and the run's results were made with these roundings)."""
    wsum = max(float(w.sum()), 1e-300)
    w2 = w[:, None]
    cs = (w2 * src).sum(axis=0) / wsum
    ct = (w2 * dst).sum(axis=0) / wsum
    a = src - cs
    b = dst - ct
    aw = w2 * a
    cov = aw.T @ b
    u, _, vt = np.linalg.svd(cov)
    v = vt.T.copy()
    r = v @ u.T
    if r[0, 0] * r[1, 1] - r[0, 1] * r[1, 0] < 0.0:
        v[:, 1] *= -1.0
        r = v @ u.T
    trans = ct - r @ cs
    sq = float((aw * a).sum() + (w2 * b * b).sum())
    tr = float(np.einsum("ij,ji->", r, cov))
    return r, trans, max(sq - 2.0 * tr, 0.0) / wsum


def shifted_route(
    route: Route, lateral_m: float, *, s0: float = 0.0, s1: float | None = None
) -> Route:
    """The part of ``route`` between two arc lengths, offset sideways (positive = to the left).

    Vertices move along their miter direction, so each segment stays parallel to the original
    at exactly ``lateral_m`` (a parallel carriageway). Where the offset exceeds the radius of a
    bend, the offset segments fold back into a loop; their vertices are dropped, since a real
    parallel road does not loop either.
    """
    end = route.length if s1 is None else s1
    out = offset_polyline(_segment_of(route, s0, end), float(lateral_m))
    if len(out) == 0:
        raise RouteError(route.source or None, "route piece to shift has no length")
    return _local_route(out, route)


def _segment_of(route: Route, s0: float, s1: float) -> F64:
    """``route.segment(s0, s1)``, compiled (bit for bit)."""
    return segment_points(route.xy, route.s, route._unit, float(s0), float(s1))


def _tangent(route: Route, s: float) -> F64:
    """``route.tangent_at(s)[0]``, compiled (bit for bit)."""
    return route._unit[segment_index(route.s, float(s))].copy()


def _project_near(
    route: Route, xy: ArrayLike, s_guess: ArrayLike, search_m: float
) -> tuple[F64, F64]:
    """``route.project(xy, s_guess, search_m)``'s arc lengths and lateral offsets, compiled
    (bit for bit) for the matcher's few points per attempt."""
    p = np.ascontiguousarray(np.asarray(xy, np.float64).reshape(-1, np.shape(xy)[-1])[:, :2])
    g = np.empty(len(p))
    g[:] = s_guess
    s = np.empty(len(p))
    lat = np.empty(len(p))
    project_window(route.xy, route.s, route._unit, route._seglen, p, g, float(search_m), s, lat)
    return s, lat


def _local_route(xy: F64, like: Route) -> Route:
    """``Route(xy, name=like.name, source=like.source)`` for the matcher's short local pieces,
    with the arrays computed by a compiled kernel (the same values, bit for bit) instead of
    the constructor's dozen small numpy calls."""
    kept, seglen, unit, s = polyline_arrays(np.ascontiguousarray(xy, np.float64))
    if len(kept) < 2 or not np.isfinite(kept).all():
        return Route(xy, name=like.name, source=like.source)  # raises its own error
    removed = len(xy) - len(kept)
    route = object.__new__(Route)
    kept.setflags(write=False)
    for name, value in (
        ("xy", kept),
        ("name", like.name),
        ("source", like.source),
        ("s", s),
        ("_seglen", seglen),
        ("_unit", unit),
        (
            "warnings",
            (
                f"route {like.source or like.name}: removed {removed} repeated vertices "
                "(zero-length segments)",
            )
            if removed
            else (),
        ),
    ):
        object.__setattr__(route, name, value)
    return route


_BLOCK = 32
"""route segments per bounding circle in the nearest-point search"""


@njit(cache=True)
def _segment_d2(rxy: F64, j: int, x: float, y: float) -> tuple[float, float]:
    dx = rxy[j + 1, 0] - rxy[j, 0]
    dy = rxy[j + 1, 1] - rxy[j, 1]
    f = ((x - rxy[j, 0]) * dx + (y - rxy[j, 1]) * dy) / (dx * dx + dy * dy)
    f = min(max(f, 0.0), 1.0)
    ex = x - rxy[j, 0] - f * dx
    ey = y - rxy[j, 1] - f * dy
    return ex * ex + ey * ey, f


@njit(cache=True)
def _nearest_all(rxy: F64, rs: F64, pts: F64, s_out: F64, lat_out: F64) -> None:
    """Global nearest foot point of every point: arc length and signed lateral offset (left
    positive), as :meth:`Route.project` computes them. Blocks of segments inside bounding
    circles are skipped when they cannot beat the best so far, and the search starts from the
    previous point's segment, so a drive costs little more than one pass over the blocks."""
    nseg = rxy.shape[0] - 1
    nblk = (nseg + _BLOCK - 1) // _BLOCK
    cx = np.empty(nblk)
    cy = np.empty(nblk)
    rad = np.empty(nblk)
    for b in range(nblk):
        j0, j1 = b * _BLOCK, min((b + 1) * _BLOCK, nseg) + 1
        cx[b] = 0.5 * (rxy[j0:j1, 0].min() + rxy[j0:j1, 0].max())
        cy[b] = 0.5 * (rxy[j0:j1, 1].min() + rxy[j0:j1, 1].max())
        r = 0.0
        for j in range(j0, j1):
            r = max(r, np.hypot(rxy[j, 0] - cx[b], rxy[j, 1] - cy[b]))
        rad[b] = r
    bj = 0
    for i in range(pts.shape[0]):
        x, y = pts[i, 0], pts[i, 1]
        best, bf = _segment_d2(rxy, bj, x, y)
        for b in range(nblk):
            lb = np.hypot(x - cx[b], y - cy[b]) - rad[b]
            if lb > 0.0 and lb * lb > best:
                continue
            for j in range(b * _BLOCK, min((b + 1) * _BLOCK, nseg)):
                d, f = _segment_d2(rxy, j, x, y)
                if d < best:
                    best, bj, bf = d, j, f
        seg = rs[bj + 1] - rs[bj]
        fx = rxy[bj, 0] + bf * (rxy[bj + 1, 0] - rxy[bj, 0])
        fy = rxy[bj, 1] + bf * (rxy[bj + 1, 1] - rxy[bj, 1])
        # the side is taken from the segment the foot's arc length starts, as Route does
        jt = bj + 1 if bf >= 1.0 and bj + 1 < nseg else bj
        dx = (rxy[jt + 1, 0] - rxy[jt, 0]) / (rs[jt + 1] - rs[jt])
        dy = (rxy[jt + 1, 1] - rxy[jt, 1]) / (rs[jt + 1] - rs[jt])
        cross = dx * (y - fy) - dy * (x - fx)
        dist = np.sqrt(best)
        s_out[i] = rs[bj] + bf * seg
        lat_out[i] = cross if abs(cross) >= dist - 1e-9 else np.copysign(dist, cross)


def project_on_route(route: Route, xy: ArrayLike) -> tuple[F64, F64]:
    """Arc length and signed lateral offset (positive = left) of every point, nearest over
    the whole route; as :meth:`Route.project` without a search window, but fast and lean on
    memory for long logs and long routes."""
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(xy, np.float64))[:, :2])
    s = np.empty(len(p))
    lat = np.empty(len(p))
    _nearest_all(route.xy, route.s, p, s, lat)
    return s, lat


def track_on_route(
    route: Route, xy: ArrayLike, *, search_m: float = 50.0, chunk: int = 64
) -> tuple[F64, F64]:
    """Arc length and signed lateral offset of a trajectory, followed along the route: each
    chunk of points is projected within ``search_m`` (plus the distance the chunk covers) of
    where the previous chunk ended. A route that passes over or near itself (a climbing spiral,
    a loop, a return carriageway) then keeps the vehicle on the stretch it is driving, where a
    nearest-point search would jump to the other level."""
    p = np.atleast_2d(np.asarray(xy, np.float64))[:, :2]
    n = len(p)
    s = np.empty(n)
    lat = np.empty(n)
    if n == 0:
        return s, lat
    s_prev = float(project_on_route(route, p[:1])[0][0])
    step = np.r_[0.0, np.hypot(*np.diff(p, axis=0).T)]
    reach = np.array([search_m + float(np.sum(step[i : i + chunk])) for i in range(0, n, chunk)])
    if np.all(np.isfinite(p)) and np.all(np.isfinite(reach)) and search_m >= 0:
        # compiled: the same projections bit for bit (project_window is Route.project)
        track_chunks(
            route.xy,
            route.s,
            route._unit,
            route._seglen,
            np.ascontiguousarray(p),
            s_prev,
            reach,
            int(chunk),
            s,
            lat,
        )
        return s, lat
    for c, i in enumerate(range(0, n, chunk)):
        j = min(i + chunk, n)
        proj = route.project(p[i:j], np.full(j - i, s_prev), float(reach[c]))
        s[i:j], lat[i:j] = proj.s, proj.lateral
        s_prev = float(proj.s[-1])
    return s, lat


def route_arc_length(
    route: Route, xy: ArrayLike, *, s_guess: float | None = None, params: Params
) -> float:
    """Route arc length of a position, searched within ``window.route_search_m`` of ``s_guess``
    (globally when None), so the runner can track where on the route the vehicle is."""
    p = np.asarray(xy, np.float64).reshape(-1)[:2]
    if not np.all(np.isfinite(p)):
        raise RoutefuseError(None, "route match: position to project is not finite")
    if s_guess is None:
        return float(project_on_route(route, p)[0][0])
    return float(_project_near(route, p, s_guess, params.window.route_search_m)[0][0])


def learn_lane_offset(
    t: ArrayLike,
    xy: ArrayLike,
    gnss_used: ArrayLike,
    route: Route,
    *,
    t_end: float,
    params: Params,
    s_guess: float | None = None,
) -> float:
    """The vehicle's lateral offset from the route (m, positive = vehicle LEFT of the route),
    exponentially weighted with ``offset.time_constant_s`` over the good-GNSS epochs up to
    ``t_end``: a lane is not the road centreline, and the pseudo-position should keep the lane.

    0 when offset compensation is off, when no epoch is usable (no GNSS, off the route's ends),
    or when the offset is larger than ``offset.max_offset_m`` (the vehicle is not on this road).
    """
    op = params.offset
    if not op.enabled:
        return 0.0
    t_a = np.asarray(t, np.float64).reshape(-1)
    p = np.asarray(xy, np.float64).reshape(len(t_a), -1)[:, :2]
    used = np.asarray(gnss_used, bool).reshape(-1)
    horizon = 5.0 * op.time_constant_s
    sel = (
        used
        & (t_a <= t_end)
        & (t_a >= t_end - horizon)
        & np.isfinite(t_a)
        & np.all(np.isfinite(p), axis=1)
    )
    if not sel.any():
        return 0.0
    pts, ts = p[sel], t_a[sel]
    if s_guess is None:
        s, lateral = project_on_route(route, pts)
    else:
        travel = float(np.sum(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0
        proj = route.project(pts, s_guess, travel + params.window.route_search_m)
        s, lateral = proj.s, proj.lateral
    inside = (s > 1e-6) & (s < route.length - 1e-6)
    if not inside.any():
        return 0.0
    w = np.exp(-(t_end - ts[inside]) / op.time_constant_s)
    offset = float(np.sum(w * lateral[inside]) / np.sum(w))
    if not np.isfinite(offset) or abs(offset) > op.max_offset_m:
        return 0.0
    return offset


@dataclass(frozen=True)
class _Fit:
    """One route candidate registered to the window."""

    s_first: float
    """arc length (on the candidate's route) of the first pair"""
    valid: NDArray[np.bool_]
    route_points: F64
    rotation: F64
    translation: F64
    residual: float
    n_pairs: int
    heading_cos: float
    along_offset: float
    along_curvature: float
    along_sigma: float
    along_observed: bool
    p_ref: F64
    s_ref: float
    tangent: F64
    normal: F64
    z: F64
    obs_cov: F64

    @property
    def angle(self) -> float:
        return float(np.arctan2(self.rotation[1, 0], self.rotation[0, 0]))


def _anchor(piece: Route, point: F64) -> float:
    return float(nearest_arc(piece.xy, piece.s, float(point[0]), float(point[1])))


def _scan(win: F64, route: Route, s_anchor: float, deltas: F64, spacing: float) -> tuple[F64, F64]:
    """Mean squared residual and number of valid pairs at each arc-length offset."""
    ms = np.empty(len(deltas))
    m = np.empty(len(deltas))
    scan_offsets(
        np.ascontiguousarray(win),
        route.xy,
        route.s,
        float(s_anchor),
        np.ascontiguousarray(deltas, np.float64),
        float(spacing),
        ms,
        m,
    )
    return ms, m


def _pairs(
    win: F64, route: Route, s_first: float, spacing: float, *, exact: bool = True
) -> tuple[F64, NDArray[np.bool_], F64, F64, F64, float]:
    """The pairs at one offset (compiled), registered with the rigid fit.

    ``exact``: the numpy SVD fit, whose rounding the filter's results were made with (a match
    the filter is updated with feeds later windows, and the along-track search amplifies a
    1e-16 change into 1e-8 m over an outage); otherwise the closed-form compiled fit, equal to
    rounding, for the rivals, which are only scored."""
    n = len(win)
    w = np.ascontiguousarray(win, np.float64)
    s = np.empty(n)
    valid = np.empty(n, np.bool_)
    q = np.empty((n, 2))
    pair_points(w, route.xy, route.s, route._unit, float(s_first), float(spacing), s, valid, q)
    if exact:
        rot, trans, ms = _kabsch_one(w, q, valid.astype(np.float64))
        return s, valid, q, rot, trans, float(np.sqrt(ms))
    rot = np.empty((2, 2))
    trans = np.empty(2)
    residual = rigid_fit(w, q, valid, rot, trans)
    return s, valid, q, rot, trans, float(residual)


def _unit_interval(x: F64, chi: F64, k: int) -> tuple[float, float] | None:
    """Where ``chi`` first rises above 1 on each side of its minimum at ``k`` (linearly
    interpolated); None when it never does inside the grid."""
    found, lo, hi = unit_interval(
        np.ascontiguousarray(x, np.float64), np.ascontiguousarray(chi, np.float64), int(k)
    )
    return (float(lo), float(hi)) if found else None


def _fit(
    win: F64,
    p_dr: F64,
    route: Route,
    s_anchor: float,
    lane_offset: float,
    params: Params,
    *,
    exact: bool = True,
) -> _Fit | None:
    """Register the window to one route candidate; None when fewer than 2 pairs exist.
    ``exact``: see :func:`_pairs` (False for rivals)."""
    ext = params.extensions
    h = params.window.spacing_m
    po = params.pseudo
    step = params.window.along_search_step_m
    half = params.window.along_search_m
    deltas = _deltas(ext.along_track_search, ext.geometry_covariance, half, step)
    ms, m = _scan(win, route, s_anchor, deltas, h)

    offset, curvature, sigma = 0.0, 0.0, float("inf")
    k = int(np.argmin(ms)) if ext.along_track_search else len(deltas) // 2
    if 0 < k < len(deltas) - 1 and np.isfinite(ms[k - 1 : k + 2]).all():
        jm, j0, jp = ms[k - 1], ms[k], ms[k + 1]
        curvature = float((jm - 2.0 * j0 + jp) / step**2)
        noise2 = max(float(j0) / 2.0, po.shape_noise_m**2)
        if ext.along_track_search:
            # likelihood interval: offsets whose chi-square rise stays within 1; robust to the
            # ripples a vertexed map leaves on a residual that is flat on a constant bend
            chi = max(m[k], 1.0) * (ms - j0) / noise2
            bounds = _unit_interval(deltas, chi, k)
            if bounds is not None:
                sigma = 0.5 * (bounds[1] - bounds[0])
                if curvature > 0:
                    offset = float(deltas[k] + 0.5 * step * (jm - jp) / (jm - 2.0 * j0 + jp))
                lo, hi = bounds
                offset = min(max(float(offset if curvature > 0 else deltas[k]), lo), hi)
        elif curvature > 0:
            sigma = float(np.sqrt(2.0 * noise2 / (max(m[k], 1.0) * curvature)))
    observed = sigma < po.along_sigma_max_m
    if not observed:
        offset = 0.0
    sigma = float(max(sigma, po.along_sigma_min_m)) if observed else po.along_sigma_max_m

    s, valid, q, rot, trans, residual = _pairs(win, route, s_anchor + offset, h, exact=exact)
    idx = np.flatnonzero(valid)
    n_pairs = len(idx)
    if n_pairs < 2:
        return None
    i1, i0 = idx[-1], idx[-2]
    d_s = win[i1] - win[i0]
    d_t = q[i1] - q[i0]
    norm = float(np.hypot(*d_s) * np.hypot(*d_t))
    heading_cos = float(np.dot(d_s, d_t) / norm) if norm > 0 else -1.0

    p_ref = rot @ p_dr + trans
    s_end = float(s[i1])
    s_ref = s_end + float((p_ref - q[i1]) @ _tangent(route, s_end))
    tangent = _tangent(route, s_ref)
    normal = np.array([-tangent[1], tangent[0]])
    z = p_ref + lane_offset * normal
    if ext.geometry_covariance:
        cross = max(po.cross_sigma_m, po.cross_residual_factor * residual)
        basis = np.column_stack([tangent, normal])
        obs_cov = basis @ np.diag([sigma**2, cross**2]) @ basis.T
    else:
        obs_cov = po.sigma_m**2 * np.eye(2)
    return _Fit(
        s_first=float(s[idx[0]]),
        valid=valid,
        route_points=q,
        rotation=rot,
        translation=trans,
        residual=residual,
        n_pairs=n_pairs,
        heading_cos=heading_cos,
        along_offset=offset,
        along_curvature=curvature,
        along_sigma=sigma,
        along_observed=observed,
        p_ref=p_ref,
        s_ref=s_ref,
        tangent=tangent,
        normal=normal,
        z=z,
        obs_cov=obs_cov,
    )


def _rotation_sigma(win: F64, fit: _Fit, pos_cov2: F64, params: Params) -> float:
    """1-sigma of the fitted rotation read as a heading correction (yaw + rotation_rad): the
    shape noise over the window's spread, plus what an along-track error the fit could not
    see turns into on a bend (sliding along a curve of curvature k is a rotation of k ds)."""
    return float(
        rotation_sigma(
            np.ascontiguousarray(win, np.float64),
            fit.valid,
            fit.route_points,
            float(fit.residual),
            float(params.pseudo.shape_noise_m),
            float(fit.along_sigma),
            np.ascontiguousarray(fit.tangent, np.float64),
            np.ascontiguousarray(pos_cov2, np.float64),
        )
    )


def _gate(
    name: str, value: float, threshold: float, comparison: Comparison, note: str = ""
) -> GateDecision:
    passed = bool(value <= threshold) if comparison == "<=" else bool(value >= threshold)
    return GateDecision(name, float(value), float(threshold), comparison, passed, note)


def _shape_gates(fit: _Fit, params: Params) -> list[GateDecision]:
    return _shape_gates_of(_shape_values(fit), params)


def _shape_passes(values: tuple[float, float, float, float], params: Params) -> bool:
    """Whether every shape gate passes (what :func:`_shape_gates_of` would decide, without
    building the decisions)."""
    g = params.gates
    n_pairs, heading_cos, residual, rotation_deg = values
    return bool(
        n_pairs >= float(g.min_pairs)
        and heading_cos >= _cos_deg(g.max_heading_diff_deg)
        and residual <= float(g.max_residual_m)
        and rotation_deg <= float(g.max_rotation_deg)
    )


@functools.lru_cache(maxsize=64)
def _cos_deg(angle_deg: float) -> float:
    return float(np.cos(np.radians(angle_deg)))


def _shape_values(fit: _Fit) -> tuple[float, float, float, float]:
    """What the shape gates test: pairs, heading cosine, residual, |rotation| in degrees."""
    return (fit.n_pairs, fit.heading_cos, fit.residual, float(np.degrees(abs(fit.angle))))


def _shape_gates_of(
    values: tuple[float, float, float, float], params: Params
) -> list[GateDecision]:
    g = params.gates
    n_pairs, heading_cos, residual, rotation_deg = values
    return [
        _gate("min_pairs", n_pairs, g.min_pairs, ">=", "valid window/route point pairs"),
        _gate(
            "heading",
            heading_cos,
            _cos_deg(g.max_heading_diff_deg),
            ">=",
            "signed cosine between DR and route end directions",
        ),
        _gate("residual", residual, g.max_residual_m, "<=", "RMS of the rigid fit, m"),
        _gate("rotation", rotation_deg, g.max_rotation_deg, "<=", "fitted rotation, deg"),
    ]


def _mahalanobis2(nu: F64, cov: F64) -> float:
    """nu^T cov^-1 nu of a 2-vector (inf when cov is singular); the 2x2 inverse written out,
    which is np.linalg.solve's result to rounding at a fraction of its call overhead."""
    a, b = float(cov[0, 0]), float(cov[0, 1])
    c, d = float(cov[1, 0]), float(cov[1, 1])
    det = a * d - b * c
    if det == 0.0:
        return float("inf")
    n0, n1 = float(nu[0]), float(nu[1])
    return (n0 * (d * n0 - b * n1) + n1 * (a * n1 - c * n0)) / det


def _rival_cost(fit: _Fit, p_dr: F64, pos_cov2: F64, params: Params) -> float:
    """How badly a candidate explains the window: innovation chi-square plus fit quality."""
    nu = fit.z - p_dr
    return (
        _mahalanobis2(nu, pos_cov2 + fit.obs_cov)
        + (fit.residual / params.pseudo.shape_noise_m) ** 2
    )


def _piece(
    route: Route, lateral_m: float, lo: float, hi: float, *, reverse: bool = False
) -> Route | None:
    """A local candidate road: the route between two arc lengths, shifted, maybe reversed."""
    lo, hi = max(lo, 0.0), min(hi, route.length)
    if hi - lo <= 1e-3:
        return None
    try:
        piece = (
            shifted_route(route, lateral_m, s0=lo, s1=hi)
            if lateral_m
            else _local_route(_segment_of(route, lo, hi), route)
        )
        if reverse:
            piece = _local_route(piece.xy[::-1], route)
    except RouteError:
        return None
    return piece


RIVALS = ("left", "right", "reversed")


def _rival_pieces(
    win: F64, route: Route, s_anchor: float, lane: float, lane_path: bool, params: Params
) -> tuple[tuple[str, float, float, float, bool], ...]:
    """(name, lateral shift, lo, hi, reversed) of the route pieces the rivals are fitted to:
    the route shifted left and right, and driven backwards."""
    h = params.window.spacing_m
    span = (len(win) - 1) * h
    pad = params.window.along_search_m + 2.0 * h
    shift = params.gates.alternative_shift_m
    base = lane if lane_path else 0.0
    return (
        ("left", base + shift, s_anchor - pad, s_anchor + span + pad, False),
        ("right", base - shift, s_anchor - pad, s_anchor + span + pad, False),
        # driven the other way, the lane lies on the other side of the centreline
        ("reversed", -base, s_anchor - span - pad, s_anchor + pad, True),
    )


@functools.lru_cache(maxsize=64)
def _deltas(along_track_search: bool, geometry_covariance: bool, half: float, step: float) -> F64:
    """The along-track offsets :func:`_fit` scans."""
    if along_track_search:
        k_half = max(int(np.ceil(half / step)), 1)
        out = step * np.arange(-k_half, k_half + 1, dtype=np.float64)
    elif geometry_covariance:
        out = np.array([-step, 0.0, step])
    else:
        out = np.zeros(1)
    out.setflags(write=False)
    return out


def _rival_scores(
    win: F64,
    p_dr: F64,
    cov: F64,
    route: Route,
    s_anchor: float,
    lane: float,
    lane_path: bool,
    params: Params,
) -> tuple[tuple[str, tuple[float, float, float, float], float, float], ...]:
    """(name, shape-gate values, cost, residual) of each rival that can be fitted: what
    :func:`_fit` (``exact=False``) and :func:`_rival_cost` give on each :func:`_rival_pieces`
    piece, to rounding, in one compiled call per rival (they are scored, never applied)."""
    ext, w, po = params.extensions, params.window, params.pseudo
    deltas = _deltas(
        ext.along_track_search, ext.geometry_covariance, w.along_search_m, w.along_search_step_m
    )
    cfg = np.array(
        [
            w.spacing_m,
            w.along_search_step_m,
            float(ext.along_track_search),
            float(ext.geometry_covariance),
            po.shape_noise_m,
            po.along_sigma_max_m,
            po.along_sigma_min_m,
            po.cross_sigma_m,
            po.sigma_m,
            po.cross_residual_factor,
        ]
    )
    z_lane = 0.0 if lane_path else lane
    w_c = np.ascontiguousarray(win, np.float64)
    out = np.empty(5)
    scores = []
    for name, lateral, lo, hi, reverse in _rival_pieces(
        win, route, s_anchor, lane, lane_path, params
    ):
        if rival_score(
            w_c,
            p_dr,
            cov,
            route.xy,
            route.s,
            route._unit,
            float(lateral),
            float(lo),
            float(hi),
            reverse,
            float(z_lane),
            deltas,
            len(deltas) // 2,
            cfg,
            out,
        ):
            shape = (int(out[0]), float(out[1]), float(out[2]), float(out[3]))
            scores.append((name, shape, float(out[4]), float(out[2])))
    return tuple(scores)


def _check_inputs(
    window_xy: ArrayLike, p_dr: ArrayLike, pos_cov2: ArrayLike
) -> tuple[F64, F64, F64]:
    w = np.asarray(window_xy, np.float64)
    if w.ndim != 2 or w.shape[1] < 2 or len(w) < 1:
        raise RoutefuseError(None, f"route match: window must be (N, 2) positions, got {w.shape}")
    w = w[:, :2]
    p = np.asarray(p_dr, np.float64).reshape(-1)[:2]
    cov = np.asarray(pos_cov2, np.float64)
    if cov.shape != (2, 2):
        raise RoutefuseError(None, f"route match: position covariance must be 2x2, got {cov.shape}")
    if not (np.isfinite(w).all() and np.isfinite(p).all() and np.isfinite(cov).all()):
        raise RoutefuseError(None, "route match: window, position or covariance is not finite")
    return w, p, 0.5 * (cov + cov.T)


@dataclass(frozen=True)
class MatchGeometry:
    """What a match attempt computes before any quality gate: the resampled window, where it
    anchors on the route, the candidate's fit and the rivals' fits.

    It depends on the attempt's inputs and on :func:`geometry_params` only, not on the gate
    thresholds, so after a gate change the runner re-judges the attempts it shares with the
    previous run (:func:`judge_match`) instead of fitting them again."""

    win: F64
    p_dr: F64
    cov: F64
    lane: float
    lane_path: bool
    s_anchor: float
    span: float
    fit: _Fit | None
    route_s: tuple[float, float]
    route_segment: F64
    validated: bool
    """``extensions.candidate_validation``: the rivals were scored"""
    scores: _Scores | None = None
    """the values the gates test (None without a fit)"""


@dataclass(frozen=True)
class _Scores:
    """The gate values of a fitted attempt and the record's extras; they depend on the geometry
    and the pseudo-observation parameters, not on the thresholds."""

    nu: F64
    p_ref: F64
    shape: tuple[float, float, float, float]
    extra: dict[str, float]
    d2: float
    jump: float
    cost: float
    rivals: tuple[tuple[str, tuple[float, float, float, float], float], ...]
    """(name, shape values, cost) of each rival that could be fitted"""
    correction: float


def geometry_params(params: Params) -> tuple:
    """The parameters a :class:`MatchGeometry` depends on: all matching parameters except the
    gate thresholds (the rivals' lateral shift is geometry)."""
    return (
        params.window,
        params.pseudo,
        params.offset,
        params.extensions,
        params.gates.alternative_shift_m,
    )


def match_window(
    window_xy: ArrayLike,
    p_dr: ArrayLike,
    pos_cov2: ArrayLike,
    route: Route,
    *,
    s_guess: float | None,
    lane_offset: float,
    params: Params,
    index: int,
    t: float,
    epoch: int,
) -> MatchRecord:
    """Match the DR window ending at ``p_dr`` to the route; every gate is recorded.

    ``window_xy``: (N, 2) DR positions in time order covering the last ``window.length_m`` of
    travel, free of correction jumps. ``pos_cov2``: the filter's E/N covariance before the
    update. ``s_guess``: the vehicle's previous route arc length (None: search the whole route).
    ``lane_offset``: learned lateral offset, positive = vehicle left of the route. The record's
    ``innovation`` is z - p_dr and ``correction`` is zero: the caller fills in what it applied.
    """
    geometry = match_geometry(
        window_xy, p_dr, pos_cov2, route, s_guess=s_guess, lane_offset=lane_offset, params=params
    )
    return judge_match(geometry, params, index=index, t=t, epoch=epoch)


def match_geometry(
    window_xy: ArrayLike,
    p_dr: ArrayLike,
    pos_cov2: ArrayLike,
    route: Route,
    *,
    s_guess: float | None,
    lane_offset: float,
    params: Params,
) -> MatchGeometry:
    """The fits of :func:`match_window` (same arguments), before its gates."""
    win_raw, p, cov = _check_inputs(window_xy, p_dr, pos_cov2)
    enabled = params.offset.enabled and np.isfinite(lane_offset)
    lane = float(lane_offset) if enabled else 0.0
    h = params.window.spacing_m
    win = resample_polyline(win_raw, h, anchor="end")
    span = (len(win) - 1) * h
    if s_guess is None or not np.isfinite(s_guess):
        s_anchor = float(project_on_route(route, win[0])[0][0])
    else:
        s_anchor = float(
            _project_near(route, win[0], s_guess - span, params.window.route_search_m)[0][0]
        )
    ext = params.extensions
    lane_path = ext.lane_path_matching and abs(lane) > 1e-3
    pad = params.window.along_search_m + 2.0 * h
    cand = _piece(route, lane, s_anchor - pad, s_anchor + span + pad) if lane_path else route
    fit = None
    if cand is not None and len(win) >= 2:
        if lane_path:
            fit = _fit(win, p, cand, _anchor(cand, win[0]), 0.0, params)
        else:
            fit = _fit(win, p, cand, s_anchor, lane, params)
    if fit is None:
        return MatchGeometry(
            win=win,
            p_dr=p,
            cov=cov,
            lane=lane,
            lane_path=lane_path,
            s_anchor=s_anchor,
            span=span,
            fit=None,
            route_s=(s_anchor, s_anchor),
            route_segment=np.empty((0, 2)),
            validated=False,
        )
    if lane_path:
        ends = fit.route_points[np.flatnonzero(fit.valid)[[0, -1]]] - lane * fit.normal
        route_s = _project_near(
            route, ends, s_anchor + fit.along_offset + np.array([0.0, span]), pad + 10.0
        )[0]
        s0, s1 = float(route_s[0]), float(route_s[1])
    else:
        s0, s1 = fit.s_first, fit.s_first + (fit.n_pairs - 1) * h
    nu = fit.z - p
    extra: dict[str, float] = {
        "anchor_s": s_anchor,
        "window_length_m": span,
        "along_offset_m": fit.along_offset,
        "along_curvature": fit.along_curvature,
        "along_sigma_m": fit.along_sigma,
        "along_observed": float(fit.along_observed),
        "cross_sigma_m": float(np.sqrt(fit.normal @ fit.obs_cov @ fit.normal)),
        "lane_path": float(lane_path),
        "innovation_along_m": float(nu @ fit.tangent),
        "innovation_cross_m": float(nu @ fit.normal),
        "normal_e": float(fit.normal[0]),
        "normal_n": float(fit.normal[1]),
        "heading_sigma_rad": _rotation_sigma(win, fit, cov, params),
    }
    d2 = jump = cost = float("nan")
    rival_scores: list[tuple[str, tuple[float, float, float, float], float]] = []
    if ext.candidate_validation:
        d2 = _mahalanobis2(nu, cov + fit.obs_cov)
        extra["mahalanobis_d2"] = d2
        jump = abs(float(nu @ fit.normal))
        cost = _rival_cost(fit, p, cov, params)
        extra["cost"] = cost
        for name, shape, rival_cost, rival_residual in _rival_scores(
            win, p, cov, route, s_anchor, lane, lane_path, params
        ):
            extra[f"cost_{name}"] = rival_cost
            extra[f"residual_{name}_m"] = rival_residual
            rival_scores.append((name, shape, rival_cost))
    scores = _Scores(
        nu=nu,
        p_ref=fit.z - lane * fit.normal,
        shape=_shape_values(fit),
        extra=extra,
        d2=d2,
        jump=jump,
        cost=cost,
        rivals=tuple(rival_scores),
        correction=float(np.hypot(*nu)),
    )
    return MatchGeometry(
        win=win,
        p_dr=p,
        cov=cov,
        lane=lane,
        lane_path=lane_path,
        s_anchor=s_anchor,
        span=span,
        fit=fit,
        route_s=(s0, s1),
        route_segment=_segment_of(route, s0, s1),
        validated=ext.candidate_validation,
        scores=scores,
    )


def judge_match(
    geometry: MatchGeometry, params: Params, *, index: int, t: float, epoch: int
) -> MatchRecord:
    """The gates of one attempt on its geometry (computed with the same
    :func:`geometry_params`): the record :func:`match_window` returns."""
    win, p, lane, span = geometry.win, geometry.p_dr, geometry.lane, geometry.span
    s_anchor, fit = geometry.s_anchor, geometry.fit
    nan2 = np.full(2, np.nan)
    if fit is None:
        gates = (
            _gate(
                "min_pairs",
                0 if len(win) < 2 else 1,
                params.gates.min_pairs,
                ">=",
                "window or route too short to pair",
            ),
        )
        return MatchRecord(
            index=index,
            t=t,
            epoch=epoch,
            accepted=False,
            gates=gates,
            window_dr=win,
            route_points=np.empty((0, 2)),
            route_segment=np.empty((0, 2)),
            route_s=(s_anchor, s_anchor),
            n_pairs=0,
            rotation_rad=float("nan"),
            translation=nan2,
            residual_m=float("nan"),
            heading_cos=float("nan"),
            p_dr=p,
            p_ref=nan2.copy(),
            lane_offset_m=lane,
            pseudo_position=nan2.copy(),
            obs_cov=np.full((2, 2), np.nan),
            innovation=nan2.copy(),
            correction=np.zeros(2),
            extra={"anchor_s": s_anchor, "window_length_m": span},
        )

    sc = geometry.scores
    assert sc is not None
    gates = _shape_gates_of(sc.shape, params)
    nu, p_ref = sc.nu, sc.p_ref
    s0, s1 = geometry.route_s
    extra = dict(sc.extra)
    if geometry.validated:
        g = params.gates
        gates.append(
            _gate(
                "mahalanobis",
                sc.d2,
                g.mahalanobis_chi2,
                "<=",
                "innovation chi-square, S = P_EN + R_k",
            )
        )
        gates.append(
            _gate(
                "lane_continuity",
                sc.jump,
                g.max_lateral_jump_m,
                "<=",
                "move across the route away from the learned lane, m",
            )
        )
        for name, shape, rival_cost in sc.rivals:
            plausible = _shape_passes(shape, params)
            margin = rival_cost - sc.cost if plausible else float("inf")
            note = (
                f"rival cost minus candidate cost ({name} "
                + (f"shift {g.alternative_shift_m:g} m)" if name != "reversed" else "direction)")
                + ("" if plausible else "; rival fails the shape gates")
            )
            gates.append(
                _gate(f"alternative_{name}", min(margin, 1e9), g.alternative_margin, ">=", note)
            )
    gates.append(
        _gate("correction_cap", sc.correction, params.gates.max_correction_m, "<=", "|z - p_dr|, m")
    )
    accepted = all(d.passed for d in gates)
    return MatchRecord(
        index=index,
        t=t,
        epoch=epoch,
        accepted=accepted,
        gates=tuple(gates),
        window_dr=win[fit.valid],
        route_points=fit.route_points[fit.valid],
        route_segment=geometry.route_segment,
        route_s=(s0, s1),
        n_pairs=fit.n_pairs,
        rotation_rad=fit.angle,
        translation=fit.translation,
        residual_m=fit.residual,
        heading_cos=fit.heading_cos,
        p_dr=p,
        p_ref=p_ref,
        lane_offset_m=lane,
        pseudo_position=fit.z,
        obs_cov=fit.obs_cov,
        innovation=nu,
        correction=np.zeros(2),
        extra=extra,
    )
