"""Compiled route geometry of the matcher: what :class:`~estimator.route.Route` computes from
its vertices, its arc-length lookups and projections, and the local route pieces a window is
fitted to (a stretch of the route, shifted sideways, maybe reversed).

Each kernel computes bit for bit what the numpy code of :class:`~estimator.route.Route` does
(the same operations in the same order), so a run's results do not depend on which is called;
``tests/estimator/matching/test_route_kernels.py`` holds them equal.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MIN_VERTEX_GAP_M = 1e-6
"""Route drops a vertex closer than this to its predecessor (see Route.__post_init__)."""
MIN_SHIFT_SEGMENT_M = 1e-9
"""shifted_route ignores segments shorter than this when building miters."""


@njit(cache=True)
def polyline_arrays(xy: F64) -> tuple[F64, F64, F64, F64]:
    """What :class:`~estimator.route.Route` computes from its vertices: the kept vertices (a
    vertex within 1e-6 m of its predecessor in the input is dropped), segment lengths, unit
    directions and cumulative arc length."""
    n = xy.shape[0]
    keep = np.ones(n, np.bool_)
    m = min(n, 1)
    for i in range(1, n):
        keep[i] = np.hypot(xy[i, 0] - xy[i - 1, 0], xy[i, 1] - xy[i - 1, 1]) > MIN_VERTEX_GAP_M
        if keep[i]:
            m += 1
    out = np.empty((m, 2))
    j = 0
    for i in range(n):
        if keep[i]:
            out[j, 0] = xy[i, 0]
            out[j, 1] = xy[i, 1]
            j += 1
    nseg = max(m - 1, 0)
    seglen = np.empty(nseg)
    unit = np.empty((nseg, 2))
    s = np.empty(nseg + 1)
    s[0] = 0.0
    for i in range(nseg):
        dx = out[i + 1, 0] - out[i, 0]
        dy = out[i + 1, 1] - out[i, 1]
        seglen[i] = np.hypot(dx, dy)
        unit[i, 0] = dx / seglen[i]
        unit[i, 1] = dy / seglen[i]
        s[i + 1] = s[i] + seglen[i]
    return out, seglen, unit, s


@njit(cache=True)
def offset_polyline(pts: F64, lateral_m: float) -> F64:
    """The polyline moved sideways by ``lateral_m`` (left positive) along its vertex miters,
    with the vertices of folded (looped) stretches dropped; (0, 2) when it has no length.
    The body of :func:`estimator.matching.geometry.shifted_route`."""
    n = pts.shape[0]
    # vertices after dropping segments shorter than MIN_SHIFT_SEGMENT_M (the first always kept)
    idx = np.empty(n, np.int64)
    m = 0
    for i in range(n):
        if i == 0:
            idx[m] = 0
            m += 1
            continue
        d = np.hypot(pts[i, 0] - pts[i - 1, 0], pts[i, 1] - pts[i - 1, 1])
        if d > MIN_SHIFT_SEGMENT_M:
            idx[m] = i
            m += 1
    if m < 2:
        return np.empty((0, 2))
    p = np.empty((m, 2))
    for i in range(m):
        p[i, 0] = pts[idx[i], 0]
        p[i, 1] = pts[idx[i], 1]
    nrm = np.empty((m - 1, 2))
    for i in range(m - 1):
        ux = p[i + 1, 0] - p[i, 0]
        uy = p[i + 1, 1] - p[i, 1]
        h = np.hypot(ux, uy)
        ux /= h
        uy /= h
        nrm[i, 0] = -uy
        nrm[i, 1] = ux
    out = np.empty((m, 2))
    for c in range(2):
        out[0, c] = p[0, c] + lateral_m * nrm[0, c]
        out[m - 1, c] = p[m - 1, c] + lateral_m * nrm[m - 2, c]
    for i in range(1, m - 1):
        cos = nrm[i - 1, 0] * nrm[i, 0] + nrm[i - 1, 1] * nrm[i, 1]
        den = max(1.0 + cos, 0.5)
        for c in range(2):
            out[i, c] = p[i, c] + lateral_m * ((nrm[i - 1, c] + nrm[i, c]) / den)
    keep = np.arange(m)
    while keep.shape[0] > 2:
        k = keep.shape[0]
        drop = np.zeros(k, np.bool_)
        any_folded = False
        for i in range(k - 1):
            a, b = keep[i], keep[i + 1]
            chord_x = p[b, 0] - p[a, 0]
            chord_y = p[b, 1] - p[a, 1]
            moved_x = out[b, 0] - out[a, 0]
            moved_y = out[b, 1] - out[a, 1]
            if chord_x * moved_x + chord_y * moved_y <= 0.0:
                any_folded = True
                drop[i] = True
                drop[i + 1] = True
        if not any_folded:
            break
        drop[0] = False
        drop[k - 1] = False
        if not drop.any():
            break
        keep = keep[~drop]
    res = np.empty((keep.shape[0], 2))
    for i in range(keep.shape[0]):
        res[i, 0] = out[keep[i], 0]
        res[i, 1] = out[keep[i], 1]
    return res


@njit(cache=True)
def segment_index(rs: F64, s: float) -> int:
    """``Route._segment_index``: the segment an arc length falls in (searchsorted right - 1,
    clipped to the segments)."""
    nseg = rs.shape[0] - 1
    lo, hi = 0, rs.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if rs[mid] <= s:
            lo = mid + 1
        else:
            hi = mid
    return int(min(max(lo - 1, 0), nseg - 1))


@njit(cache=True)
def segment_points(xy: F64, rs: F64, unit: F64, s0: float, s1: float) -> F64:
    """``Route.segment(s0, s1)``: the polyline between two arc lengths with the vertices
    strictly inside, bit for bit."""
    n = rs.shape[0]
    # vertices with s0 < rs < s1
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if rs[mid] <= s0:
            lo = mid + 1
        else:
            hi = mid
    first = lo
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if rs[mid] < s1:
            lo = mid + 1
        else:
            hi = mid
    inner = max(lo - first, 0)
    out = np.empty((inner + 2, 2))
    i = segment_index(rs, s0)
    out[0, 0] = xy[i, 0] + (s0 - rs[i]) * unit[i, 0]
    out[0, 1] = xy[i, 1] + (s0 - rs[i]) * unit[i, 1]
    for k in range(inner):
        out[k + 1, 0] = xy[first + k, 0]
        out[k + 1, 1] = xy[first + k, 1]
    i = segment_index(rs, s1)
    out[inner + 1, 0] = xy[i, 0] + (s1 - rs[i]) * unit[i, 0]
    out[inner + 1, 1] = xy[i, 1] + (s1 - rs[i]) * unit[i, 1]
    return out


@njit(cache=True)
def project_window(
    xy: F64,
    rs: F64,
    unit: F64,
    seglen: F64,
    pts: F64,
    s_guess: F64,
    search_m: float,
    s_out: F64,
    lat_out: F64,
) -> None:
    """``Route.project(pts, s_guess, search_m)`` (``search_m`` >= 0): arc length and signed
    lateral offset of the nearest foot point on the stretch [guess - search, guess + search]
    (clipped inside long segments too), bit for bit; the first of equal distances wins, as
    numpy's argmin."""
    for p in range(pts.shape[0]):
        x, y = pts[p, 0], pts[p, 1]
        s_lo = s_guess[p] - search_m
        s_hi = s_guess[p] + search_m
        best = np.inf
        best_s = 0.0
        fx = fy = 0.0
        for j in range(segment_index(rs, s_lo), segment_index(rs, s_hi) + 1):
            along = (x - xy[j, 0]) * unit[j, 0] + (y - xy[j, 1]) * unit[j, 1]
            lo_a = max(0.0, s_lo - rs[j])
            hi_a = max(lo_a, min(seglen[j], s_hi - rs[j]))
            along = min(max(along, lo_a), hi_a)
            footx = xy[j, 0] + along * unit[j, 0]
            footy = xy[j, 1] + along * unit[j, 1]
            ex = x - footx
            ey = y - footy
            d2 = ex * ex + ey * ey
            if d2 < best:
                best = d2
                best_s = rs[j] + along
                fx, fy = footx, footy
        s_out[p] = best_s
        rx, ry = x - fx, y - fy
        t = segment_index(rs, best_s)
        lat = unit[t, 0] * ry - unit[t, 1] * rx
        dist = np.hypot(rx, ry)
        if abs(lat) < dist - 1e-9:
            lat = np.sign(lat) * dist
        lat_out[p] = lat


@njit(cache=True)
def track_chunks(
    xy: F64,
    rs: F64,
    unit: F64,
    seglen: F64,
    pts: F64,
    s_first: float,
    reach: F64,
    chunk: int,
    s_out: F64,
    lat_out: F64,
) -> None:
    """The loop of :func:`estimator.matching.geometry.track_on_route`: chunk ``c`` of
    ``chunk`` points is projected within ``reach[c]`` of where the previous chunk ended
    (:func:`project_window`)."""
    n = pts.shape[0]
    s_prev = s_first
    for c in range(reach.shape[0]):
        i = c * chunk
        j = min(i + chunk, n)
        guess = np.full(j - i, s_prev)
        project_window(xy, rs, unit, seglen, pts[i:j], guess, reach[c], s_out[i:j], lat_out[i:j])
        s_prev = s_out[j - 1]


@njit(cache=True)
def nearest_arc(rxy: F64, rs: F64, x: float, y: float) -> float:
    """Arc length of the point of a polyline nearest to (x, y) (small local pieces)."""
    best, best_s = np.inf, 0.0
    for j in range(rxy.shape[0] - 1):
        dx = rxy[j + 1, 0] - rxy[j, 0]
        dy = rxy[j + 1, 1] - rxy[j, 1]
        seg = rs[j + 1] - rs[j]
        f = ((x - rxy[j, 0]) * dx + (y - rxy[j, 1]) * dy) / (seg * seg)
        f = min(max(f, 0.0), 1.0)
        ex = rxy[j, 0] + f * dx - x
        ey = rxy[j, 1] + f * dy - y
        d = ex * ex + ey * ey
        if d < best:
            best, best_s = d, rs[j] + f * seg
    return best_s


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
def nearest_all(rxy: F64, rs: F64, pts: F64, s_out: F64, lat_out: F64) -> None:
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


@njit(cache=True)
def route_piece(
    xy: F64, rs: F64, unit: F64, lateral_m: float, lo: float, hi: float, reverse: bool
) -> tuple[bool, F64, F64, F64, F64]:
    """The route between arc lengths ``lo`` and ``hi`` (clipped to the route), moved sideways
    by ``lateral_m`` (:func:`offset_polyline`), maybe reversed: (ok, vertices, segment
    lengths, unit directions, arc lengths) as a :class:`~estimator.route.Route` of it would
    hold them; not ok when the piece is shorter than 1 mm or has fewer than 2 vertices."""
    empty = np.empty((0, 2))
    none = (False, empty, np.empty(0), empty, np.empty(0))
    lo = max(lo, 0.0)
    hi = min(hi, rs[rs.shape[0] - 1])
    if hi - lo <= 1e-3:
        return none
    seg = segment_points(xy, rs, unit, lo, hi)
    if lateral_m != 0.0:
        seg = offset_polyline(seg, lateral_m)
        if seg.shape[0] == 0:
            return none
    pxy, pseglen, punit, ps = polyline_arrays(seg)
    if pxy.shape[0] < 2:
        return none
    if reverse:
        pxy, pseglen, punit, ps = polyline_arrays(pxy[::-1].copy())
        if pxy.shape[0] < 2:
            return none
    for i in range(pxy.shape[0]):
        if not (np.isfinite(pxy[i, 0]) and np.isfinite(pxy[i, 1])):
            return none
    return True, pxy, pseglen, punit, ps
