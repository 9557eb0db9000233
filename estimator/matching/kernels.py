"""Compiled inner loops of the rigid fit (:mod:`estimator.matching.fit`) and of the pipeline's
match window.

A match attempt fits the window to four short route pieces (the candidate and the left, right
and reversed rivals); in numpy the along-track search and the pairing cost some fifty
small-array calls per fit, which made the matcher the run's bottleneck (profiles in
``docs/performance.md``). Each kernel computes bit for bit what the numpy code it replaced
did (the same operations in the same order), so a run's results do not change;
``tests/estimator/matching/test_match_kernels.py`` compares each with a numpy oracle (the
rivals' grid scan, :func:`_scan_grid`, equals the direct scan to rounding only).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimator.matching.route_kernels import segment_index

F64 = NDArray[np.float64]


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
    return float(max(saa + sbb - 2.0 * tr, 0.0) / sw)


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
    """The along-track scan (:func:`scan_offsets`) of ``k_n`` offsets ``step`` apart from
    ``s0`` when the window spacing is ``ratio`` grid steps: every pair lies on the grid
    s0 + step * g, so each route point is interpolated once instead of once per offset. Equal
    to the direct scan to rounding (the arc lengths are summed in another order), so only the
    rivals, which are scored and never applied, use it."""
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
def along_track_pairs(
    win: F64,
    rxy: F64,
    rs: F64,
    runit: F64,
    s_anchor: float,
    deltas: F64,
    search: bool,
    step: float,
    spacing: float,
    shape_noise: float,
    sigma_max: float,
    sigma_min: float,
    grid_ratio: int,
    s_out: F64,
    valid_out: NDArray[np.bool_],
    q_out: F64,
    plausible: bool = False,
) -> tuple[float, float, float, bool]:
    """Where along the route the window's pairs start, and how well route shape says so:
    the mean squared rigid-fit residual at each arc-length offset ``deltas`` from
    ``s_anchor`` (:func:`scan_offsets`); with ``search``, the offset of its minimum (a
    parabola through the three grid points around it, kept inside the likelihood interval
    where the chi-square rise stays within 1: robust to the ripples a vertexed map leaves on a
    residual that is flat on a constant bend); without, the centre offset and the curvature
    there. Fills the pairs at the chosen offset (:func:`pair_points`) and returns (offset,
    curvature, 1-sigma, observed): an along-track sigma of ``sigma_max`` or more is
    unobserved (offset 0, sigma ``sigma_max``), a smaller one is floored at ``sigma_min``.
    ``grid_ratio`` > 0: the deltas are a grid ``step`` apart and the spacing is that many
    steps, scanned by :func:`_scan_grid`; 0: the direct scan.

    ``plausible``: where along-track stays unobserved but the shape rules the dead-reckoned
    place out (its chi-square over the best offset's is above 1, as when the window has
    entered a bend on one side of a plateau), the pairs are placed at the offset nearest to it
    that the shape allows, not at the place it rules out (offset still reported 0)."""
    nd = deltas.shape[0]
    ms = np.empty(nd)
    m = np.empty(nd)
    if grid_ratio > 0:
        _scan_grid(win, rxy, rs, runit, s_anchor + deltas[0], step, nd, grid_ratio, ms, m)
    else:
        scan_offsets(win, rxy, rs, s_anchor, deltas, spacing, ms, m)
    offset, curvature, sigma = 0.0, 0.0, np.inf
    k = nd // 2
    if search:
        k = 0
        for i in range(1, nd):
            if ms[i] < ms[k]:
                k = i
    if 0 < k < nd - 1 and np.isfinite(ms[k - 1]) and np.isfinite(ms[k]) and np.isfinite(ms[k + 1]):
        jm, j0, jp = ms[k - 1], ms[k], ms[k + 1]
        curvature = (jm - 2.0 * j0 + jp) / step**2
        noise2 = max(j0 / 2.0, shape_noise**2)
        if search:
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
    observed = sigma < sigma_max
    place = 0.0
    if not observed:
        offset = 0.0
        if plausible and search and np.isfinite(ms[k]):
            place = _nearest_allowed(deltas, ms, m, k, shape_noise)
    sigma = max(sigma, sigma_min) if observed else sigma_max
    at = s_anchor + (offset if observed else place)
    pair_points(win, rxy, rs, runit, at, spacing, s_out, valid_out, q_out)
    return offset, curvature, sigma, observed


@njit(cache=True)
def _nearest_allowed(deltas: F64, ms: F64, m: F64, k: int, shape_noise: float) -> float:
    """The offset nearest to 0 whose residual's chi-square over the minimum at ``k`` is at
    most 1 (0 itself when it is allowed)."""
    j0 = ms[k]
    noise2 = max(j0 / 2.0, shape_noise**2)
    w = max(m[k], 1.0)
    best = -1
    for i in range(deltas.shape[0]):
        if not np.isfinite(ms[i]) or w * (ms[i] - j0) / noise2 > 1.0:
            continue
        if best < 0 or abs(deltas[i]) < abs(deltas[best]):
            best = i
    return 0.0 if best < 0 else float(deltas[best])


@njit(cache=True)
def rms_residual(win: F64, q: F64, valid: NDArray[np.bool_], rot: F64) -> float:
    """RMS of |R w_i + t - q_i| over the valid pairs of a rigid fit with rotation ``rot`` (t
    maps the centroids onto each other), summed point by point on centred coordinates: the
    terms are window-sized, not map-sized, and nothing cancels (the Kabsch sums' |a|^2 + |b|^2
    - 2 tr(R C) lose ~1e-12 m^2, 1e-8 m on a millimetre residual)."""
    n = win.shape[0]
    count = 0.0
    csx = csy = ctx = cty = 0.0
    for i in range(n):
        if valid[i]:
            count += 1.0
            csx += win[i, 0]
            csy += win[i, 1]
            ctx += q[i, 0]
            cty += q[i, 1]
    count = max(count, 1e-300)
    csx /= count
    csy /= count
    ctx /= count
    cty /= count
    sq = 0.0
    for i in range(n):
        if valid[i]:
            ax = win[i, 0] - csx
            ay = win[i, 1] - csy
            ex = rot[0, 0] * ax + rot[0, 1] * ay - (q[i, 0] - ctx)
            ey = rot[1, 0] * ax + rot[1, 1] * ay - (q[i, 1] - cty)
            sq += ex * ex + ey * ey
    return float(np.sqrt(sq / count))


@njit(cache=True)
def max_turn_deg(xy: F64, stretch_m: float, spacing_m: float) -> float:
    """The largest heading change over any ``stretch_m`` of a polyline, in degrees: the
    polyline resampled every ``spacing_m`` from its end (as
    :func:`~estimator.matching.resample_polyline`), the unwrapped headings of its steps, the
    largest max - min over ``stretch_m / spacing_m`` + 1 consecutive headings (the pipeline's
    numpy code before the kernel, to rounding)."""
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
        return float(np.degrees(heading.max() - heading.min()))
    best = 0.0
    for k in range(m - w):
        lo = hi = heading[k]
        for i in range(k + 1, k + w + 1):
            lo = min(lo, heading[i])
            hi = max(hi, heading[i])
        best = max(best, hi - lo)
    return float(np.degrees(best))


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
    """The fitted rotation's 1-sigma read as a heading correction (``FitSummary``), to
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
    return float(np.sqrt(noise2 / max(spread, 1e-9) + (turn / length) ** 2 * along2))


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
    """The pipeline's DR window: rows ``i0:`` of the DR track ``dr`` and the current point
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
