"""Compiled inner loops of the route matcher (:mod:`estimator.matching.match`).

A match attempt fits the window to four short route pieces (the candidate and the left, right
and reversed rivals); in numpy each fit and each piece cost some fifty small-array calls, which
made the matcher the run's bottleneck (profiles in ``docs/performance.md``).

Everything the filter is updated with is computed bit for bit as the numpy code these kernels
replaced (the same operations in the same order: arc lengths, offsets, point interpolation), so
a run's results do not change. :func:`rigid_fit` is the exception: a closed-form 2-D Kabsch fit,
equal to the SVD fit to rounding, used only for the rivals, which are scored but never fed to
the filter. ``tests/estimator/test_matching_kernels.py`` compares each kernel, and a whole run,
with the numpy originals.
"""

from __future__ import annotations

import math

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
    The body of :func:`estimator.matching.match.shifted_route`."""
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
def pair_points(
    win: F64,
    rxy: F64,
    rs: F64,
    runit: F64,
    s_first: float,
    spacing: float,
    s_out: F64,
    valid_out: NDArray[np.bool_],
    q_out: F64,
) -> None:
    """Pair window point i with the route point at ``s_first + i * spacing`` (as
    ``Route.point_at``, bit for bit: end segments extended); pairs off the route are
    invalid."""
    n = win.shape[0]
    nseg = rxy.shape[0] - 1
    length = rs[nseg]
    # the segment of the first point: searchsorted(rs, s, 'right') - 1, clipped
    lo, hi = 0, nseg + 1
    while lo < hi:
        mid = (lo + hi) // 2
        if rs[mid] <= s_first:
            lo = mid + 1
        else:
            hi = mid
    j = min(max(lo - 1, 0), nseg - 1)
    for i in range(n):
        s = s_first + spacing * float(i)
        while j < nseg - 1 and rs[j + 1] <= s:
            j += 1
        s_out[i] = s
        valid_out[i] = s >= -1e-6 and s <= length + 1e-6
        d = s - rs[j]
        q_out[i, 0] = rxy[j, 0] + d * runit[j, 0]
        q_out[i, 1] = rxy[j, 1] + d * runit[j, 1]


@njit(cache=True)
def rigid_fit(win: F64, q: F64, valid: NDArray[np.bool_], rot_out: F64, trans_out: F64) -> float:
    """The proper rotation and translation minimising sum |R win_i + t - q_i|^2 over the valid
    pairs, in closed form; fills the outputs and returns the RMS residual. Agrees with the SVD
    fit (``matching._kabsch``) to rounding, not bit for bit."""
    n = win.shape[0]
    wsum = 0.0
    csx = csy = ctx = cty = 0.0
    for i in range(n):
        if valid[i]:
            wsum += 1.0
            csx += win[i, 0]
            csy += win[i, 1]
            ctx += q[i, 0]
            cty += q[i, 1]
    wsum = max(wsum, 1e-300)
    csx /= wsum
    csy /= wsum
    ctx /= wsum
    cty /= wsum
    c00 = c01 = c10 = c11 = 0.0
    for i in range(n):
        if valid[i]:
            ax = win[i, 0] - csx
            ay = win[i, 1] - csy
            bx = q[i, 0] - ctx
            by = q[i, 1] - cty
            c00 += ax * bx
            c01 += ax * by
            c10 += ay * bx
            c11 += ay * by
    # the rotation maximising tr(R C) = cos (c00 + c11) + sin (c01 - c10)
    h = np.hypot(c00 + c11, c01 - c10)
    if h > 0.0:
        c = (c00 + c11) / h
        s_ = (c01 - c10) / h
    else:
        c, s_ = 1.0, 0.0
    rot_out[0, 0] = c
    rot_out[0, 1] = -s_
    rot_out[1, 0] = s_
    rot_out[1, 1] = c
    tx = ctx - (c * csx - s_ * csy)
    ty = cty - (s_ * csx + c * csy)
    trans_out[0] = tx
    trans_out[1] = ty
    # the residual summed point by point (the numpy version's |a|^2 + |b|^2 - 2 tr(R C) loses
    # ~1e-12 m^2 to cancellation, which is 1e-9 m on a millimetre residual)
    sq = 0.0
    for i in range(n):
        if valid[i]:
            # R (w - cs) + ct - q, centred: the terms are window-sized, not map-sized
            ax = win[i, 0] - csx
            ay = win[i, 1] - csy
            ex = c * ax - s_ * ay - (q[i, 0] - ctx)
            ey = s_ * ax + c * ay - (q[i, 1] - cty)
            sq += ex * ex + ey * ey
    return math.sqrt(sq / wsum)


@njit(cache=True)
def unit_interval(x: F64, chi: F64, k: int) -> tuple[bool, float, float]:
    """Where ``chi`` first rises above 1 on each side of its minimum at ``k`` (linearly
    interpolated): (found, low end, high end); not found when it never does inside the grid."""
    ends = np.empty(2)
    for side in range(2):
        direction = -1 if side == 0 else 1
        i = k
        while True:
            j = i + direction
            if j < 0 or j >= x.shape[0] or not np.isfinite(chi[j]):
                return False, 0.0, 0.0
            if chi[j] > 1.0:
                f = (1.0 - chi[i]) / (chi[j] - chi[i])
                ends[side] = x[i] + f * (x[j] - x[i])
                break
            i = j
    return True, ends[0], ends[1]


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
    return min(max(lo - 1, 0), nseg - 1)


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
    """The loop of :func:`estimator.matching.match.track_on_route`: chunk ``c`` of ``chunk`` points is
    projected within ``reach[c]`` of where the previous chunk ended (:func:`project_window`)."""
    n = pts.shape[0]
    s_prev = s_first
    for c in range(reach.shape[0]):
        i = c * chunk
        j = min(i + chunk, n)
        guess = np.full(j - i, s_prev)
        project_window(xy, rs, unit, seglen, pts[i:j], guess, reach[c], s_out[i:j], lat_out[i:j])
        s_prev = s_out[j - 1]


# ---------------------------------------------------------------------------------------------
# the rivals: scored only, computed to rounding in one compiled call


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


@njit(cache=True)
def _scan_grid(
    win: F64,
    rxy: F64,
    rs: F64,
    runit: F64,
    s0: float,
    step: float,
    k_n: int,
    ratio: int,
    ms: F64,
    m: F64,
) -> None:
    """The along-track scan (:func:`scan_offsets`) when the window spacing is ``ratio`` grid
    steps: every pair lies on the grid s0 + step * g, so each route point is interpolated once
    instead of once per offset. Equal to the direct scan to rounding."""
    n = win.shape[0]
    nseg = rxy.shape[0] - 1
    length = rs[nseg]
    n_grid = k_n + ratio * (n - 1)
    gx = np.empty(n_grid)
    gy = np.empty(n_grid)
    ok = np.empty(n_grid, np.bool_)
    ox, oy = win[0, 0], win[0, 1]
    j = segment_index(rs, s0)
    for g in range(n_grid):
        s = s0 + step * g
        ok[g] = s >= -1e-6 and s <= length + 1e-6
        while j < nseg - 1 and rs[j + 1] <= s:
            j += 1
        f = (s - rs[j]) / (rs[j + 1] - rs[j])
        gx[g] = rxy[j, 0] + f * (rxy[j + 1, 0] - rxy[j, 0]) - ox
        gy[g] = rxy[j, 1] + f * (rxy[j + 1, 1] - rxy[j, 1]) - oy
    for k in range(k_n):
        sw = 0.0
        sax = say = sbx = sby = 0.0
        saa = sbb = c00 = c01 = c10 = c11 = 0.0
        for i in range(n):
            g = k + ratio * i
            if not ok[g]:
                continue
            qx, qy = gx[g], gy[g]
            px = win[i, 0] - ox
            py = win[i, 1] - oy
            sw += 1.0
            sax += px
            say += py
            sbx += qx
            sby += qy
            saa += px * px + py * py
            sbb += qx * qx + qy * qy
            c00 += px * qx
            c01 += px * qy
            c10 += py * qx
            c11 += py * qy
        m[k] = sw
        ms[k] = (
            np.inf if sw < 3 else _rigid_msr(sw, sax, say, sbx, sby, saa, sbb, c00, c01, c10, c11)
        )


@njit(cache=True)
def rival_score(
    win: F64,
    p_dr: F64,
    cov: F64,
    xy: F64,
    rs: F64,
    unit: F64,
    lateral: float,
    lo: float,
    hi: float,
    reverse: bool,
    lane_offset: float,
    deltas: F64,
    k_center: int,
    cfg: F64,
    out: F64,
) -> bool:
    """One rival of a match attempt, as matching._piece, _fit and _rival_cost compute it (to
    rounding): the route between ``lo`` and ``hi``, shifted ``lateral`` (maybe reversed),
    registered to the window. False when no rival can be built or fitted (matching: None);
    else ``out`` = (n_pairs, heading cosine, residual, |rotation| in degrees, cost).

    ``cfg`` = (spacing, along step, along_track_search, geometry_covariance, shape_noise,
    along_sigma_max, along_sigma_min, cross_sigma, sigma_m, cross_residual_factor);
    ``k_center``: the offset index used without the along-track search."""
    h, step = cfg[0], cfg[1]
    along_search = cfg[2] > 0.0
    geometry_cov = cfg[3] > 0.0
    shape_noise, sig_max, sig_min, cross_sigma, sigma_m = cfg[4], cfg[5], cfg[6], cfg[7], cfg[8]
    cross_factor = cfg[9]
    # --- the piece (matching._piece)
    length = rs[rs.shape[0] - 1]
    lo = max(lo, 0.0)
    hi = min(hi, length)
    if hi - lo <= 1e-3:
        return False
    seg = segment_points(xy, rs, unit, lo, hi)
    if lateral != 0.0:
        seg = offset_polyline(seg, lateral)
        if seg.shape[0] == 0:
            return False
    pxy, _, punit, ps = polyline_arrays(seg)
    if pxy.shape[0] < 2:
        return False
    if reverse:
        pxy, _, punit, ps = polyline_arrays(pxy[::-1].copy())
        if pxy.shape[0] < 2:
            return False
    for i in range(pxy.shape[0]):
        if not (np.isfinite(pxy[i, 0]) and np.isfinite(pxy[i, 1])):
            return False
    s_anchor = nearest_arc(pxy, ps, win[0, 0], win[0, 1])
    # --- the along-track scan and its interval (matching._fit)
    nd = deltas.shape[0]
    ms = np.empty(nd)
    m = np.empty(nd)
    ratio = int(np.rint(h / step))
    grid = (
        along_search
        and nd > 1
        and ratio >= 1
        and abs(ratio * step - h) <= 1e-12 * h
        and abs(deltas[1] - deltas[0] - step) <= 1e-12 * step
    )
    if grid:
        _scan_grid(win, pxy, ps, punit, s_anchor + deltas[0], step, nd, ratio, ms, m)
    else:
        scan_offsets(win, pxy, ps, s_anchor, deltas, h, ms, m)
    offset, curvature, sigma = 0.0, 0.0, np.inf
    k = k_center
    if along_search:
        k = 0
        for i in range(1, nd):
            if ms[i] < ms[k]:
                k = i
    if 0 < k < nd - 1 and np.isfinite(ms[k - 1]) and np.isfinite(ms[k]) and np.isfinite(ms[k + 1]):
        jm, j0, jp = ms[k - 1], ms[k], ms[k + 1]
        curvature = (jm - 2.0 * j0 + jp) / step**2
        noise2 = max(j0 / 2.0, shape_noise**2)
        if along_search:
            chi = np.empty(nd)
            w = max(m[k], 1.0)
            for i in range(nd):
                chi[i] = w * (ms[i] - j0) / noise2
            found, b0, b1 = unit_interval(deltas, chi, k)
            if found:
                sigma = 0.5 * (b1 - b0)
                if curvature > 0:
                    offset = deltas[k] + 0.5 * step * (jm - jp) / (jm - 2.0 * j0 + jp)
                offset = min(max(offset if curvature > 0 else deltas[k], b0), b1)
        elif curvature > 0:
            sigma = np.sqrt(2.0 * noise2 / (max(m[k], 1.0) * curvature))
    observed = sigma < sig_max
    if not observed:
        offset = 0.0
    sigma = max(sigma, sig_min) if observed else sig_max
    # --- the pairs and the fit
    n = win.shape[0]
    s = np.empty(n)
    valid = np.empty(n, np.bool_)
    q = np.empty((n, 2))
    pair_points(win, pxy, ps, punit, s_anchor + offset, h, s, valid, q)
    rot = np.empty((2, 2))
    trans = np.empty(2)
    residual = rigid_fit(win, q, valid, rot, trans)
    n_pairs = 0
    i1 = i0 = -1
    for i in range(n):
        if valid[i]:
            n_pairs += 1
            i0, i1 = i1, i
    if n_pairs < 2:
        return False
    dsx, dsy = win[i1, 0] - win[i0, 0], win[i1, 1] - win[i0, 1]
    dtx, dty = q[i1, 0] - q[i0, 0], q[i1, 1] - q[i0, 1]
    norm = np.hypot(dsx, dsy) * np.hypot(dtx, dty)
    heading_cos = (dsx * dtx + dsy * dty) / norm if norm > 0 else -1.0
    prx = rot[0, 0] * p_dr[0] + rot[0, 1] * p_dr[1] + trans[0]
    pry = rot[1, 0] * p_dr[0] + rot[1, 1] * p_dr[1] + trans[1]
    s_end = s[i1]
    t_end = punit[segment_index(ps, s_end)]
    s_ref = s_end + (prx - q[i1, 0]) * t_end[0] + (pry - q[i1, 1]) * t_end[1]
    t = punit[segment_index(ps, s_ref)]
    nx, ny = -t[1], t[0]
    zx = prx + lane_offset * nx
    zy = pry + lane_offset * ny
    if geometry_cov:
        cross = max(cross_sigma, cross_factor * residual)
        a, b = sigma**2, cross**2
        r00 = t[0] * t[0] * a + nx * nx * b
        r01 = t[0] * t[1] * a + nx * ny * b
        r11 = t[1] * t[1] * a + ny * ny * b
    else:
        r00 = r11 = sigma_m**2
        r01 = 0.0
    # --- its cost (matching._rival_cost)
    s00 = cov[0, 0] + r00
    s01 = cov[0, 1] + r01
    s10 = cov[1, 0] + r01
    s11 = cov[1, 1] + r11
    det = s00 * s11 - s01 * s10
    nux, nuy = zx - p_dr[0], zy - p_dr[1]
    d2 = (
        np.inf
        if det == 0.0
        else (nux * (s11 * nux - s01 * nuy) + nuy * (s00 * nuy - s10 * nux)) / det
    )
    out[0] = n_pairs
    out[1] = heading_cos
    out[2] = residual
    out[3] = np.degrees(abs(np.arctan2(rot[1, 0], rot[0, 0])))
    out[4] = d2 + (residual / shape_noise) ** 2
    return True


@njit(cache=True)
def _rigid_msr(
    sw: float,
    sax: float,
    say: float,
    sbx: float,
    sby: float,
    saa: float,
    sbb: float,
    c00: float,
    c01: float,
    c10: float,
    c11: float,
) -> float:
    """Mean squared residual of the best 2-D rigid fit of point set a onto b, from their sums
    (count, coordinate sums, sums of squared norms, cross products C = sum a b^T).

    The optimum over SO(2) has tr(R C) = |(C00 + C11, C01 - C10)| for the centred C, the same
    value the SVD solution with the reflection guard reaches, so no rotation is formed."""
    ax, ay, bx, by = sax / sw, say / sw, sbx / sw, sby / sw
    saa -= sw * (ax * ax + ay * ay)
    sbb -= sw * (bx * bx + by * by)
    c00 -= sw * ax * bx
    c01 -= sw * ax * by
    c10 -= sw * ay * bx
    c11 -= sw * ay * by
    tr = np.hypot(c00 + c11, c01 - c10)
    return max(saa + sbb - 2.0 * tr, 0.0) / sw


@njit(cache=True)
def scan_offsets(
    win: F64, rxy: F64, rs: F64, s_anchor: float, deltas: F64, spacing: float, ms: F64, m: F64
) -> None:
    """Mean squared rigid-fit residual ``ms`` of the window against the route, and the number
    of pairs ``m``, at each arc-length offset of the route window's start from ``s_anchor``."""
    n = win.shape[0]
    nseg = rxy.shape[0] - 1
    length = rs[nseg]
    ox, oy = win[0, 0], win[0, 1]
    for k in range(deltas.shape[0]):
        sw = 0.0
        sax = say = sbx = sby = 0.0
        saa = sbb = c00 = c01 = c10 = c11 = 0.0
        j = segment_index(rs, s_anchor + deltas[k])
        for i in range(n):
            s = s_anchor + deltas[k] + spacing * i
            if s < -1e-6 or s > length + 1e-6:
                continue
            while j < nseg - 1 and rs[j + 1] <= s:
                j += 1
            f = (s - rs[j]) / (rs[j + 1] - rs[j])
            qx = rxy[j, 0] + f * (rxy[j + 1, 0] - rxy[j, 0]) - ox
            qy = rxy[j, 1] + f * (rxy[j + 1, 1] - rxy[j, 1]) - oy
            px = win[i, 0] - ox
            py = win[i, 1] - oy
            sw += 1.0
            sax += px
            say += py
            sbx += qx
            sby += qy
            saa += px * px + py * py
            sbb += qx * qx + qy * qy
            c00 += px * qx
            c01 += px * qy
            c10 += py * qx
            c11 += py * qy
        m[k] = sw
        ms[k] = (
            np.inf if sw < 3 else _rigid_msr(sw, sax, say, sbx, sby, saa, sbb, c00, c01, c10, c11)
        )


@njit(cache=True)
def max_turn_deg(xy: F64, stretch_m: float, spacing_m: float) -> float:
    """The largest heading change over any ``stretch_m`` of a polyline, in degrees: the
    polyline resampled every ``spacing_m`` from its end (as matching.resample_polyline), the
    unwrapped headings of its steps, the largest max - min over ``stretch_m / spacing_m`` + 1
    consecutive headings (runner._max_turn_deg's numpy code, to rounding)."""
    n_in = xy.shape[0]
    c = np.empty(n_in)
    c[0] = 0.0
    for i in range(1, n_in):
        c[i] = c[i - 1] + np.hypot(xy[i, 0] - xy[i - 1, 0], xy[i, 1] - xy[i - 1, 1])
    total = c[n_in - 1]
    n = int(np.floor(total / spacing_m + 1e-9)) + 1
    if n < 3:
        return 0.0
    px = np.empty(n)
    py = np.empty(n)
    j = 0
    for k in range(n):
        at = total - spacing_m * (n - 1 - k)
        if at <= c[0]:
            px[k], py[k] = xy[0, 0], xy[0, 1]
            continue
        if at >= total:
            px[k], py[k] = xy[n_in - 1, 0], xy[n_in - 1, 1]
            continue
        while j < n_in - 2 and c[j + 1] <= at:
            j += 1
        d = c[j + 1] - c[j]
        f = (at - c[j]) / d if d > 0 else 0.0
        px[k] = xy[j, 0] + f * (xy[j + 1, 0] - xy[j, 0])
        py[k] = xy[j, 1] + f * (xy[j + 1, 1] - xy[j, 1])
    m = n - 1
    heading = np.empty(m)
    for k in range(m):
        heading[k] = np.arctan2(py[k + 1] - py[k], px[k + 1] - px[k])
    # unwrap
    corr = 0.0
    prev = heading[0]
    for k in range(1, m):
        raw = heading[k]
        dd = raw - prev
        prev = raw
        ddmod = (dd + np.pi) % (2.0 * np.pi) - np.pi
        if ddmod == -np.pi and dd > 0:
            ddmod = np.pi
        if abs(dd) >= np.pi:
            corr += ddmod - dd
        heading[k] = raw + corr
    w = max(int(np.rint(stretch_m / spacing_m)), 1)
    if m <= w:
        return np.degrees(heading.max() - heading.min())
    best = 0.0
    for k in range(m - w):
        lo = hi = heading[k]
        for i in range(k + 1, k + w + 1):
            lo = min(lo, heading[i])
            hi = max(hi, heading[i])
        best = max(best, hi - lo)
    return np.degrees(best)


@njit(cache=True)
def rotation_sigma(
    win: F64,
    valid: NDArray[np.bool_],
    q: F64,
    residual: float,
    shape_noise: float,
    along_sigma: float,
    tangent: F64,
    cov: F64,
) -> float:
    """matching._rotation_sigma (the fitted rotation's 1-sigma as a heading correction), to
    rounding; recorded only, never applied."""
    n = win.shape[0]
    m = 0
    mx = my = 0.0
    for i in range(n):
        if valid[i]:
            m += 1
            mx += win[i, 0]
            my += win[i, 1]
    mx /= m
    my /= m
    spread = 0.0
    for i in range(n):
        if valid[i]:
            ax = win[i, 0] - mx
            ay = win[i, 1] - my
            spread += ax * ax + ay * ay
    noise2 = max(residual**2 / 2.0, shape_noise**2)
    first = last = -1
    second = before_last = -1
    length = 0.0
    prev = -1
    for i in range(n):
        if valid[i]:
            if first < 0:
                first = i
            elif second < 0:
                second = i
            if prev >= 0:
                length += np.hypot(q[i, 0] - q[prev, 0], q[i, 1] - q[prev, 1])
            before_last, last = last, i
            prev = i
    d0x, d0y = q[second, 0] - q[first, 0], q[second, 1] - q[first, 1]
    d1x, d1y = q[last, 0] - q[before_last, 0], q[last, 1] - q[before_last, 1]
    turn = abs(np.arctan2(d0x * d1y - d0y * d1x, d0x * d1x + d0y * d1y))
    length = max(length, 1e-9)
    t0, t1 = tangent[0], tangent[1]
    tct = t0 * (cov[0, 0] * t0 + cov[0, 1] * t1) + t1 * (cov[1, 0] * t0 + cov[1, 1] * t1)
    along2 = min(along_sigma**2, tct)
    return np.sqrt(noise2 / max(spread, 1e-9) + (turn / length) ** 2 * along2)


@njit(cache=True)
def search_right(x: F64, value: float) -> int:
    """``np.searchsorted(x, value, side="right")`` on a sorted 1-D array of any stride (a column
    of the run's output rows), without numpy's contiguous copy of it."""
    lo, hi = 0, x.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if x[mid] <= value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def track_window(dr: F64, dist: F64, dr_now: F64, d_now: float, i0: int, shift: F64) -> F64:
    """The runner's DR window: rows ``i0:`` of the DR track ``dr`` and the current point
    ``dr_now`` (``dist``: distance travelled at each), without the rows at which the vehicle
    had not moved on by 1e-6 m before the next, all moved by ``shift`` (bit for bit what the
    numpy code computed)."""
    m = dr.shape[0] - i0
    keep = np.empty(m + 1, np.bool_)
    count = 1
    for k in range(m):
        d_next = dist[i0 + k + 1] if k + 1 < m else d_now
        keep[k] = (d_next - dist[i0 + k]) > 1e-6
        if keep[k]:
            count += 1
    keep[m] = True
    out = np.empty((count, 2))
    r = 0
    for k in range(m):
        if keep[k]:
            out[r, 0] = dr[i0 + k, 0] + shift[0]
            out[r, 1] = dr[i0 + k, 1] + shift[1]
            r += 1
    out[r, 0] = dr_now[0] + shift[0]
    out[r, 1] = dr_now[1] + shift[1]
    return out
