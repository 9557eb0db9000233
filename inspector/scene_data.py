"""What the scene layers draw, computed once per run: decimated polylines, per-epoch poses and
per-attempt markers. Pure numpy (no viser), so the controller builds it on its worker thread and
the headless export can build the same thing.

Scrubbing and stepping then only index into these arrays; nothing here is recomputed per frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from estimator.evaluation.metrics import NEES_95_2DOF
from estimator.log import Log
from estimator.nav.frames import LocalFrame
from estimator.results import MatchRecord, OutageExit, Run
from estimator.route import Route

F64 = NDArray[np.float64]

DISPLAY_TOLERANCE_M = 0.05
"""Largest deviation of a displayed polyline from the computed one. Well below a pixel at any
zoom a person uses to look at a lane-level match, yet it keeps a 60-minute track to a few
thousand vertices (straight stretches collapse to their ends)."""

MAX_FIX_POINTS = 20_000


def decimate_polyline(xy: F64, tolerance_m: float = DISPLAY_TOLERANCE_M) -> NDArray[np.intp]:
    """Indices of the vertices to keep so no dropped vertex is further than ``tolerance_m`` from
    the kept polyline (Ramer-Douglas-Peucker). NaN rows are dropped first."""
    pts = np.asarray(xy, np.float64)[:, :2]
    finite = np.flatnonzero(np.all(np.isfinite(pts), axis=1))
    if len(finite) <= 2:
        return finite
    return finite[_rdp_keep(np.ascontiguousarray(pts[finite]), float(tolerance_m))]


@numba.njit(cache=True)
def _rdp_keep(p: F64, tol: float) -> NDArray[np.bool_]:
    """Iterative RDP (an explicit stack of spans); compiled: a 60-minute track in ~10 ms."""
    n = len(p)
    keep = np.zeros(n, np.bool_)
    keep[0] = True
    keep[n - 1] = True
    stack = np.empty((n, 2), np.int64)
    stack[0, 0] = 0
    stack[0, 1] = n - 1
    top = 1
    while top > 0:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        if b - a < 2:
            continue
        dx = p[b, 0] - p[a, 0]
        dy = p[b, 1] - p[a, 1]
        length = np.hypot(dx, dy)
        worst = -1.0
        m = a
        for i in range(a + 1, b):
            rx = p[i, 0] - p[a, 0]
            ry = p[i, 1] - p[a, 1]
            d = np.hypot(rx, ry) if length < 1e-12 else abs(dx * ry - dy * rx) / length
            if d > worst:
                worst = d
                m = i
        if worst > tol:
            keep[m] = True
            stack[top, 0] = a
            stack[top, 1] = m
            stack[top + 1, 0] = m
            stack[top + 1, 1] = b
            top += 2
    return keep


def polyline_segments(xy: F64, z: float = 0.0) -> NDArray[np.float32]:
    """(N-1, 2, 3) line segments joining consecutive points (the form viser draws fast)."""
    pts = np.asarray(xy, np.float64)
    if len(pts) < 2:
        return np.zeros((0, 2, 3), np.float32)
    p3 = np.column_stack([pts[:, 0], pts[:, 1], np.full(len(pts), z)])
    return np.stack([p3[:-1], p3[1:]], axis=1).astype(np.float32)


def display_polyline(xy: F64, tolerance_m: float = DISPLAY_TOLERANCE_M) -> F64:
    """The polyline with the vertices the screen needs; NaN rows split nothing, they are
    dropped."""
    pts = np.asarray(xy, np.float64)[:, :2]
    return pts[decimate_polyline(pts, tolerance_m)]


def interval_mask(t: F64, intervals: tuple[tuple[float, float], ...]) -> NDArray[np.bool_]:
    """Which times fall inside any of the closed intervals."""
    mask = np.zeros(len(t), bool)
    for a, b in intervals:
        mask |= (t >= a) & (t <= b)
    return mask


def masked_segments(xy: F64, mask: NDArray[np.bool_], z: float = 0.0) -> NDArray[np.float32]:
    """Line segments of the runs of ``xy`` where ``mask`` holds, each run decimated."""
    out = []
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        run_xy = display_polyline(xy[a:b])
        out.append(polyline_segments(run_xy, z))
    return np.concatenate(out) if out else np.zeros((0, 2, 3), np.float32)


def ellipse_axes(cov: F64, chi2: float) -> tuple[float, float, float] | None:
    """Semi-axes (the larger first) and the larger's angle from East of the ellipse
    e' P^-1 e = ``chi2`` for P = [[cov[0], cov[2]], [cov[2], cov[1]]]; None unless P is finite
    and positive definite."""
    var_e, var_n, c = (float(v) for v in cov)
    if not (np.isfinite(var_e) and np.isfinite(var_n) and np.isfinite(c)):
        return None
    mid, half = 0.5 * (var_e + var_n), float(np.hypot(0.5 * (var_e - var_n), c))
    big, small = mid + half, mid - half
    if small <= 0.0:
        return None
    angle = 0.5 * float(np.arctan2(2.0 * c, var_e - var_n))
    return float(np.sqrt(chi2 * big)), float(np.sqrt(chi2 * small)), angle


@dataclass(frozen=True)
class Track:
    """One run's trajectory: the full-rate poses for the vehicle marker, and the decimated
    polyline for the line."""

    t: F64
    """(N,) absolute epoch times"""
    xy: F64
    """(N, 2) EN positions"""
    yaw: F64
    """(N,) ENU yaw, rad"""
    line: F64
    """(M, 2) decimated polyline for display"""
    cov: F64 | None = None
    """(N, 3) the filter's E and N variances and their covariance (m^2), None for the truth"""

    @classmethod
    def of_run(cls, run: Run) -> Track:
        ep = run.epochs
        xy = np.ascontiguousarray(ep.position[:, :2], np.float64)
        cov = np.column_stack([ep.position_sigma[:, :2] ** 2, ep.position_cov_en])
        return cls(t=ep.t, xy=xy, yaw=ep.attitude[:, 2], line=display_polyline(xy), cov=cov)

    def index_at(self, t: float) -> int:
        return int(np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 1))

    def pose_at(self, t: float) -> tuple[F64, float]:
        """Position (2,) and yaw at the last epoch at or before ``t``."""
        i = self.index_at(t)
        return self.xy[i], float(self.yaw[i])

    def ring_at(self, t: float) -> tuple[float, float, float] | None:
        """The semi-axes (m) and the first axis's ENU angle (rad) of the ellipse holding 95 %
        of where the filter says the vehicle is, at the last epoch at or before ``t``; None
        without a covariance (the truth) or where it is not a proper one."""
        if self.cov is None:
            return None
        return ellipse_axes(self.cov[self.index_at(t)], NEES_95_2DOF)


def _truth_track(log: Log | None, frame: LocalFrame) -> Track | None:
    truth = None if log is None else log.truth
    if truth is None or len(truth.t) < 2:
        return None
    enu = frame.to_enu(truth.lat, truth.lon, truth.alt)
    xy = enu[:, :2]
    heading = np.asarray(truth.heading, np.float64)
    if not np.any(np.isfinite(heading)):
        d = np.gradient(xy, axis=0)
        heading = np.arctan2(d[:, 1], d[:, 0])
    return Track(t=np.asarray(truth.t, np.float64), xy=xy, yaw=heading, line=display_polyline(xy))


def _gnss_points(log: Log | None, frame: LocalFrame) -> F64:
    if log is None or len(log.gnss.t) == 0:
        return np.zeros((0, 2))
    ok = log.gnss.valid
    enu = frame.to_enu(log.gnss.lat[ok], log.gnss.lon[ok], log.gnss.alt[ok])[:, :2]
    enu = enu[np.all(np.isfinite(enu), axis=1)]
    if len(enu) > MAX_FIX_POINTS:
        enu = enu[np.linspace(0, len(enu) - 1, MAX_FIX_POINTS).astype(np.intp)]
    return enu


def match_anchor(m: MatchRecord) -> F64:
    """Where an attempt is marked on the map: its DR position (always computed)."""
    p = np.asarray(m.p_dr, np.float64)
    if p.shape == (2,) and np.all(np.isfinite(p)):
        return p
    if len(m.window_dr):
        return np.asarray(m.window_dr[-1], np.float64)
    return np.full(2, np.nan)


@dataclass(frozen=True)
class SceneData:
    """Everything the layers draw for one session, independent of time."""

    t0: float
    route_line: F64
    """(M, 2) the route, decimated"""
    baseline: Track
    proposed: Track
    truth: Track | None
    gnss_fixes: F64
    """(K, 2) valid GNSS fixes (thinned to at most MAX_FIX_POINTS)"""
    degraded_segments: NDArray[np.float32]
    """(S, 2, 3) the proposed track inside GNSS-degraded intervals"""
    matches: tuple[MatchRecord, ...]
    match_t: F64
    """(A,) absolute attempt times"""
    match_xy: F64
    """(A, 2) marker positions"""
    match_accepted: NDArray[np.bool_]
    exits: tuple[OutageExit, ...]
    """the proposed run's exit checks: where each outage's estimate ended against the fixes"""
    center: F64
    """(2,) middle of the drawn extent"""
    extent_m: float
    """largest side of the drawn extent"""

    @classmethod
    def build(cls, *, baseline: Run, proposed: Run, route: Route, log: Log | None) -> SceneData:
        base_track = Track.of_run(baseline)
        prop_track = Track.of_run(proposed)
        truth = _truth_track(log, proposed.frame)
        mask = interval_mask(prop_track.t, proposed.degraded_intervals)
        matches = proposed.matches
        match_xy = np.array([match_anchor(m) for m in matches]) if matches else np.zeros((0, 2))
        everything = [route.xy[:, :2], prop_track.line, base_track.line]
        allpts = np.vstack(everything)
        allpts = allpts[np.all(np.isfinite(allpts), axis=1)]
        lo, hi = allpts.min(axis=0), allpts.max(axis=0)
        return cls(
            t0=proposed.t0,
            route_line=display_polyline(route.xy),
            baseline=base_track,
            proposed=prop_track,
            truth=truth,
            gnss_fixes=_gnss_points(log, proposed.frame),
            degraded_segments=masked_segments(prop_track.xy, mask),
            matches=matches,
            match_t=np.array([m.t for m in matches], np.float64),
            match_xy=match_xy,
            match_accepted=np.array([m.accepted for m in matches], bool),
            exits=proposed.exits,
            center=(lo + hi) / 2,
            extent_m=float(max(np.max(hi - lo), 50.0)),
        )

    def match_index_at(self, t: float, *, max_age_s: float = np.inf) -> int | None:
        """The last attempt at or before ``t`` (within ``max_age_s``), or None."""
        i = int(np.searchsorted(self.match_t, t + 1e-9, side="right")) - 1
        if i < 0 or t - self.match_t[i] > max_age_s:
            return None
        return i
