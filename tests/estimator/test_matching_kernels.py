"""The compiled matcher kernels against the numpy code they replaced (kept here verbatim as the
reference), piece by piece and end to end: a whole run with the reference pieces swapped back
in gives the same epochs and match records.

Tolerance: 1e-9, relative for values above 1 (the rivals' costs reach 1e8). Registration
residuals are compared as mean squares: the numpy version computed them as
sum|a|^2 + sum|b|^2 - 2 tr(R C), whose cancellation leaves ~1e-12 m^2, i.e. 1e-9 m on a
millimetre residual; the kernel sums the point residuals directly.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numba import njit

from estimator.errors import RouteError
from estimator.matching import match as matching
from estimator.matching.kernels import offset_polyline, polyline_arrays, unit_interval
from estimator.params import Params
from estimator.pipeline.runner import run
from estimator.route import Route
from estimator.sim import simulate

RESIDUALS = ("residual_m", "residual_left_m", "residual_right_m", "residual_reversed_m")

# ---------------------------------------------------------------------------------------------
# the numpy originals (estimator/matching.py before the kernels)


def ref_shifted_route(
    route: Route, lateral_m: float, *, s0: float = 0.0, s1: float | None = None
) -> Route:
    end = route.length if s1 is None else s1
    pts = route.segment(s0, end)
    seglen = np.hypot(*np.diff(pts, axis=0).T)
    if not np.any(seglen > 1e-9):
        raise RouteError(route.source or None, "route piece to shift has no length")
    pts = np.vstack([pts[:1], pts[1:][seglen > 1e-9]])
    u = np.diff(pts, axis=0)
    u /= np.hypot(u[:, 0], u[:, 1])[:, None]
    nrm = np.column_stack([-u[:, 1], u[:, 0]])
    miter = np.empty_like(pts)
    miter[0], miter[-1] = nrm[0], nrm[-1]
    if len(nrm) > 1:
        cos = np.einsum("ij,ij->i", nrm[:-1], nrm[1:])
        miter[1:-1] = (nrm[:-1] + nrm[1:]) / np.maximum(1.0 + cos, 0.5)[:, None]
    out = pts + lateral_m * miter
    keep = np.arange(len(pts))
    while len(keep) > 2:
        chord = np.diff(pts[keep], axis=0)
        moved = np.diff(out[keep], axis=0)
        folded = np.flatnonzero(np.einsum("ij,ij->i", chord, moved) <= 0.0)
        if not len(folded):
            break
        drop = np.zeros(len(keep), bool)
        drop[folded] = drop[folded + 1] = True
        drop[[0, -1]] = False
        if not drop.any():
            break
        keep = keep[~drop]
    out = out[keep]
    return Route(out, name=route.name, source=route.source)


def ref_local_route(xy, like: Route) -> Route:
    return Route(xy, name=like.name, source=like.source)


def ref_pairs(win, route: Route, s_first: float, spacing: float, *, exact: bool = True):
    s = s_first + spacing * np.arange(len(win))
    valid = (s >= -1e-6) & (s <= route.length + 1e-6)
    q = route.point_at(s)
    rot, trans, ms = matching._kabsch(win[None], q[None], valid[None].astype(np.float64))
    return s, valid, q, rot[0], trans[0], float(np.sqrt(ms[0]))


def ref_unit_interval(x, chi, k):
    ends = []
    for direction in (-1, 1):
        i = k
        while True:
            j = i + direction
            if j < 0 or j >= len(x) or not np.isfinite(chi[j]):
                return None
            if chi[j] > 1.0:
                f = (1.0 - chi[i]) / (chi[j] - chi[i])
                ends.append(float(x[i] + f * (x[j] - x[i])))
                break
            i = j
    return ends[0], ends[1]


def ref_mahalanobis2(nu, cov) -> float:
    try:
        return float(nu @ np.linalg.solve(cov, nu))
    except np.linalg.LinAlgError:
        return float("inf")


@njit(cache=True)
def _ref_scan_kernel(win, rxy, rs, s_anchor, deltas, spacing, ms, m):
    """matching_kernels.scan_offsets with its original segment walk from the route's start."""
    n = win.shape[0]
    nseg = rxy.shape[0] - 1
    length = rs[nseg]
    ox, oy = win[0, 0], win[0, 1]
    for k in range(deltas.shape[0]):
        sw = 0.0
        sax = say = sbx = sby = 0.0
        saa = sbb = c00 = c01 = c10 = c11 = 0.0
        j = 0
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
        if sw < 3:
            ms[k] = np.inf
            continue
        ax, ay, bx, by = sax / sw, say / sw, sbx / sw, sby / sw
        saa -= sw * (ax * ax + ay * ay)
        sbb -= sw * (bx * bx + by * by)
        c00 -= sw * ax * bx
        c01 -= sw * ax * by
        c10 -= sw * ay * bx
        c11 -= sw * ay * by
        tr = np.hypot(c00 + c11, c01 - c10)
        ms[k] = max(saa + sbb - 2.0 * tr, 0.0) / sw


REFERENCE = {
    "shifted_route": ref_shifted_route,
    "_local_route": ref_local_route,
    "_pairs": ref_pairs,
    "_unit_interval": ref_unit_interval,
    "_mahalanobis2": ref_mahalanobis2,
    "scan_offsets": _ref_scan_kernel,
}


@pytest.fixture
def reference_matcher(monkeypatch):
    """Swap the numpy originals back into estimator.matching.match."""
    for name, fn in REFERENCE.items():
        assert hasattr(matching, name), f"estimator.matching.match.{name} is gone: update the test"
        monkeypatch.setattr(matching, name, fn)


# ---------------------------------------------------------------------------------------------
# comparison


def _close(a, b, path: str, squared: bool = False) -> None:
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            sq = f.name in RESIDUALS or (f.name == "value" and getattr(a, "name", "") == "residual")
            _close(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}", sq)
        return
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _close(a[k], b[k], f"{path}[{k}]", k in RESIDUALS)
        return
    if isinstance(a, (tuple, list)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}[{i}]")
        return
    if isinstance(a, (str, bool)) or a is None:
        assert a == b, path
        return
    x, y = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if squared:
        x, y = x * x, y * y
    assert x.shape == y.shape, path
    np.testing.assert_array_equal(np.isfinite(x), np.isfinite(y), err_msg=path)
    f = np.isfinite(x)
    err = np.abs(x[f] - y[f]) / np.maximum(1.0, np.abs(y[f]))
    assert err.size == 0 or err.max() <= 1e-9, f"{path}: {err.max():.3g}"


def _random_polyline(rng: np.random.Generator, n: int) -> np.ndarray:
    heading = np.cumsum(rng.normal(0.0, 0.6, n))
    step = rng.uniform(0.5, 40.0, n)
    xy = 5e4 + np.cumsum(np.column_stack([np.cos(heading), np.sin(heading)]) * step[:, None], 0)
    # some repeated and nearly repeated vertices
    for i in rng.choice(np.arange(1, n - 1), size=max(1, n // 8), replace=False):
        xy[i] = xy[i - 1] + rng.choice([0.0, 1e-10, 5e-7, 2e-6]) * rng.normal(size=2)
    return xy


# ---------------------------------------------------------------------------------------------
# the kernels one by one


@pytest.mark.parametrize("seed", range(20))
def test_polyline_arrays_are_what_route_computes(seed):
    xy = _random_polyline(np.random.default_rng(seed), 30)
    route = Route(xy, name="n", source="src")
    fast = matching._local_route(xy, route)
    for name in ("xy", "s", "_seglen", "_unit"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(route, name), err_msg=name)
    assert (fast.name, fast.source, fast.warnings) == (route.name, route.source, route.warnings)
    np.testing.assert_array_equal(polyline_arrays(xy)[0], route.xy)


def test_local_route_refuses_what_route_refuses():
    like = Route(np.array([[0.0, 0.0], [1.0, 0.0]]))
    with pytest.raises(RouteError):
        matching._local_route(np.array([[1.0, 1.0], [1.0, 1.0 + 1e-8]]), like)


@pytest.mark.parametrize("seed", range(30))
@pytest.mark.parametrize("lateral", [-60.0, -25.0, -3.2, 0.7, 25.0, 200.0])
def test_offset_polyline_is_the_numpy_shift(seed, lateral):
    route = Route(_random_polyline(np.random.default_rng(seed), 40))
    s0, s1 = 0.1 * route.length, 0.8 * route.length
    fast = matching.shifted_route(route, lateral, s0=s0, s1=s1)
    ref = ref_shifted_route(route, lateral, s0=s0, s1=s1)
    np.testing.assert_array_equal(fast.xy, ref.xy)
    np.testing.assert_array_equal(fast.s, ref.s)


def test_offset_polyline_of_a_point_has_no_length():
    assert offset_polyline(np.array([[2.0, 3.0], [2.0, 3.0 + 1e-12]]), 5.0).shape == (0, 2)
    route = Route(np.array([[0.0, 0.0], [10.0, 0.0]]))
    with pytest.raises(RouteError, match="no length"):
        matching.shifted_route(route, 3.0, s0=4.0, s1=4.0)


@pytest.mark.parametrize("seed", range(30))
def test_pairs_are_the_numpy_pairs(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 25))
    n = int(rng.integers(2, 80))
    spacing = float(rng.uniform(1.0, 8.0))
    s_first = float(rng.uniform(-0.3, 0.9) * route.length)
    q = route.point_at(s_first + spacing * np.arange(n))
    angle = rng.uniform(-0.3, 0.3)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    noise = rng.normal(0, rng.choice([1e-3, 0.3, 3.0]), q.shape)
    win = (q - q.mean(0)) @ rot.T + q.mean(0) + noise
    ref = ref_pairs(win, route, s_first, spacing)
    # the fit the filter is updated with: bit for bit
    for got, want in zip(matching._pairs(win, route, s_first, spacing), ref, strict=True):
        np.testing.assert_array_equal(got, want)
    # the rivals' closed-form fit: to rounding
    s, valid, qq, r, t, res = matching._pairs(win, route, s_first, spacing, exact=False)
    for got, want in zip((s, valid, qq), ref[:3], strict=True):
        np.testing.assert_array_equal(got, want)
    if valid.sum() >= 2:
        _close(r, ref[3], "rotation")
        _close(t, ref[4], "translation")
        _close(res, ref[5], "residual", squared=True)


def test_closed_form_fit_refuses_a_mirror_image():
    route = Route(np.array([[0.0, 0.0], [50.0, 0.0], [50.0, 40.0]]))
    q = route.point_at(np.arange(0.0, 90.0, 5.0))
    mirrored = q * np.array([1.0, -1.0])
    r, res = matching._pairs(mirrored, route, 0.0, 5.0, exact=False)[3::2]
    assert np.isclose(np.linalg.det(r), 1.0) and res > 1.0
    _close(res, ref_pairs(mirrored, route, 0.0, 5.0)[5], "residual", squared=True)


@pytest.mark.parametrize("seed", range(30))
def test_unit_interval_is_the_python_loop(seed):
    rng = np.random.default_rng(seed)
    x = np.arange(-30.0, 31.0)
    chi = rng.uniform(0.0, 2.0) * (x - rng.uniform(-25, 25)) ** 2 / rng.uniform(5, 400)
    if seed % 5 == 0:
        chi[rng.integers(0, len(x))] = np.inf
    k = int(np.argmin(chi))
    assert matching._unit_interval(x, chi, k) == ref_unit_interval(x, chi, k)
    assert unit_interval(x, chi, k)[0] == (ref_unit_interval(x, chi, k) is not None)


@pytest.mark.parametrize("seed", range(10))
def test_scan_from_a_binary_search_is_the_walk_from_the_start(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 300))
    win = route.point_at(rng.uniform(0, route.length) + 5.0 * np.arange(50))
    deltas = np.arange(-30.0, 31.0)
    for s_anchor in (-80.0, 0.0, float(rng.uniform(0, route.length)), route.length - 20.0):
        a = (np.empty(len(deltas)), np.empty(len(deltas)))
        b = (np.empty(len(deltas)), np.empty(len(deltas)))
        matching.scan_offsets(win, route.xy, route.s, s_anchor, deltas, 5.0, *a)
        _ref_scan_kernel(win, route.xy, route.s, s_anchor, deltas, 5.0, *b)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])


@pytest.mark.parametrize("seed", range(20))
def test_mahalanobis_is_the_solve(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(2, 2)) * rng.choice([1e-3, 1.0, 30.0])
    cov = a @ a.T + np.eye(2) * rng.choice([0.0, 1e-6, 1.0])
    nu = rng.normal(size=2) * rng.choice([0.1, 10.0, 1e4])
    _close(matching._mahalanobis2(nu, cov), ref_mahalanobis2(nu, cov), "d2")
    assert matching._mahalanobis2(nu, np.zeros((2, 2))) == float("inf")


@pytest.mark.parametrize("seed", range(20))
def test_segment_tangent_and_projection_are_the_route_methods(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 60))
    for _ in range(20):
        s0, s1 = np.sort(rng.uniform(-0.1, 1.1, 2) * route.length)
        if rng.uniform() < 0.2:
            s0 = s1 = float(route.s[rng.integers(0, len(route.s))])  # on a vertex
        if rng.uniform() < 0.1:
            s0, s1 = s1, s0
        np.testing.assert_array_equal(matching._segment_of(route, s0, s1), route.segment(s0, s1))
        np.testing.assert_array_equal(matching._tangent(route, s0), route.tangent_at(s0)[0])
    pts = route.point_at(rng.uniform(-50, route.length + 50, 30)) + rng.normal(0, 20, (30, 2))
    guess = rng.uniform(0, route.length, 30)
    for search in (0.0, 5.0, 60.0, 2.0 * route.length):
        s, lat = matching._project_near(route, pts, guess, search)
        ref = route.project(pts, guess, search)
        np.testing.assert_array_equal(s, ref.s)
        np.testing.assert_array_equal(lat, ref.lateral)
    one = matching._project_near(route, pts[0], 10.0, 60.0)
    np.testing.assert_array_equal(one[0], route.project(pts[0], 10.0, 60.0).s)


def ref_track_on_route(route, xy, *, search_m=50.0, chunk=64):
    p = np.atleast_2d(np.asarray(xy, np.float64))[:, :2]
    n = len(p)
    s, lat = np.empty(n), np.empty(n)
    s_prev = float(matching.project_on_route(route, p[:1])[0][0])
    step = np.r_[0.0, np.hypot(*np.diff(p, axis=0).T)]
    for i in range(0, n, chunk):
        j = min(i + chunk, n)
        reach = search_m + float(np.sum(step[i:j]))
        proj = route.project(p[i:j], np.full(j - i, s_prev), reach)
        s[i:j], lat[i:j] = proj.s, proj.lateral
        s_prev = float(proj.s[-1])
    return s, lat


@pytest.mark.parametrize("seed", range(8))
def test_track_on_route_is_the_chunked_route_projection(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 200))
    s_true = np.sort(rng.uniform(0, route.length, 3000))
    xy = route.point_at(s_true) + rng.normal(0, 3.0, (3000, 2))
    for chunk in (1, 7, 64):
        got = matching.track_on_route(route, xy, chunk=chunk)
        want = ref_track_on_route(route, xy, chunk=chunk)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    xy[100] = np.nan  # the numpy path
    got = matching.track_on_route(route, xy)
    want = ref_track_on_route(route, xy)
    np.testing.assert_array_equal(got[0], want[0])


def ref_rival_scores(win, p_dr, cov, route, s_anchor, lane, lane_path, params):
    """The rivals as the Python matcher computes them: _piece, _anchor, _fit, _rival_cost."""
    z_lane = 0.0 if lane_path else lane
    out = []
    pieces = matching._rival_pieces(win, route, s_anchor, lane, lane_path, params)
    for name, lateral, lo, hi, reverse in pieces:
        piece = matching._piece(route, lateral, lo, hi, reverse=reverse)
        if piece is None:
            continue
        anchor = matching._anchor(piece, win[0])
        fit = matching._fit(win, p_dr, piece, anchor, z_lane, params, exact=False)
        if fit is None:
            continue
        cost = matching._rival_cost(fit, p_dr, cov, params)
        out.append((name, matching._shape_values(fit), cost, fit.residual))
    return tuple(out)


RIVAL_PARAMS = [
    {},
    {"extensions.along_track_search": False},
    {"extensions.along_track_search": False, "extensions.geometry_covariance": False},
    {"window.spacing_m": 3.5, "window.along_search_step_m": 0.7},  # the direct scan
    {"window.spacing_m": 4.0, "window.along_search_step_m": 1.5},
    {"gates.alternative_shift_m": 4.0, "pseudo.shape_noise_m": 0.3},
]


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("change", RIVAL_PARAMS)
def test_compiled_rivals_are_the_python_rivals(seed, change):
    from estimator.params import with_values

    rng = np.random.default_rng(seed)
    params = with_values(Params(), change)
    route = Route(_random_polyline(rng, 120))
    h = params.window.spacing_m
    s0 = float(rng.uniform(-20.0, route.length - 100.0))
    n = int(rng.integers(3, 60))
    q = route.point_at(s0 + h * np.arange(n))
    angle = rng.uniform(-0.05, 0.05)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    win = (q - q.mean(0)) @ rot.T + q.mean(0) + rng.normal(0, rng.choice([0.01, 0.5]), q.shape)
    p_dr = win[-1] + rng.normal(0, 2.0, 2)
    a = rng.normal(size=(2, 2))
    cov = a @ a.T + np.eye(2)
    s_anchor = float(matching.project_on_route(route, win[0])[0][0])
    lane = float(rng.choice([0.0, 1.8, -3.1]))
    for lane_path in (False, True):
        got = matching._rival_scores(win, p_dr, cov, route, s_anchor, lane, lane_path, params)
        want = ref_rival_scores(win, p_dr, cov, route, s_anchor, lane, lane_path, params)
        assert [r[0] for r in got] == [r[0] for r in want]
        for g, w in zip(got, want, strict=True):
            assert g[1][0] == w[1][0]  # pairs
            _close(g[1][1], w[1][1], "heading cos")
            _close(g[1][2], w[1][2], "residual", squared=True)
            _close(g[1][3], w[1][3], "rotation")
            _close(g[2], w[2], "cost")


def ref_max_turn_deg(xy, stretch_m, spacing_m):
    """runner._max_turn_deg in numpy (before the kernel)."""
    pts = matching.resample_polyline(xy, spacing_m, anchor="end")
    if len(pts) < 3:
        return 0.0
    d = np.diff(pts, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    n = max(round(stretch_m / spacing_m), 1)
    if len(heading) <= n:
        return float(np.degrees(np.ptp(heading)))
    win = np.lib.stride_tricks.sliding_window_view(heading, n + 1)
    return float(np.degrees(np.max(win.max(axis=1) - win.min(axis=1))))


@pytest.mark.parametrize("seed", range(40))
def test_max_turn_is_the_numpy_max_turn(seed):
    from estimator.pipeline.runner import _max_turn_deg

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 1500))
    head = np.cumsum(rng.normal(0, rng.choice([0.01, 0.3, 2.0]), n))
    step = rng.uniform(0.01, 3.0, n)
    xy = 1e4 + np.cumsum(np.column_stack([np.cos(head), np.sin(head)]) * step[:, None], 0)
    for stretch, spacing in ((250.0, 5.0), (100.0, 3.0), (50.0, 7.5)):
        _close(_max_turn_deg(xy, stretch, spacing), ref_max_turn_deg(xy, stretch, spacing), "turn")


def ref_rotation_sigma(win, fit, pos_cov2, params):
    """matching._rotation_sigma in numpy (before the kernel)."""
    a = win[fit.valid] - win[fit.valid].mean(axis=0)
    spread = float(np.sum(a * a))
    noise2 = max(fit.residual**2 / 2.0, params.pseudo.shape_noise_m**2)
    q = fit.route_points[fit.valid]
    d0, d1 = q[1] - q[0], q[-1] - q[-2]
    turn = abs(float(np.arctan2(d0[0] * d1[1] - d0[1] * d1[0], d0 @ d1)))
    length = max(float(np.sum(np.hypot(*np.diff(q, axis=0).T))), 1e-9)
    along2 = min(fit.along_sigma**2, float(fit.tangent @ pos_cov2 @ fit.tangent))
    return float(np.sqrt(noise2 / max(spread, 1e-9) + (turn / length) ** 2 * along2))


@pytest.mark.parametrize("seed", range(30))
def test_rotation_sigma_is_the_numpy_one(seed):
    rng = np.random.default_rng(seed)
    params = Params()
    route = Route(_random_polyline(rng, 60))
    q = route.point_at(
        rng.uniform(-30.0, route.length / 2) + 5.0 * np.arange(int(rng.integers(2, 50)))
    )
    win = q + rng.normal(0, 0.5, q.shape)
    a = rng.normal(size=(2, 2))
    cov = a @ a.T + np.eye(2) * rng.choice([1e-3, 10.0])
    fit = matching._fit(win, win[-1], route, float(matching._anchor(route, win[0])), 0.0, params)
    if fit is None:
        return
    got = matching._rotation_sigma(win, fit, cov, params)
    _close(got, ref_rotation_sigma(win, fit, cov, params), "heading sigma")


def test_column_search_is_searchsorted():
    from estimator.matching.kernels import search_right

    rows = np.zeros((500, 26))
    rows[:, 17] = np.cumsum(np.random.default_rng(0).choice([0.0, 0.5, 1.3], 500))
    col = rows[:, 17]
    for v in (-1.0, 0.0, 3.0, float(col[250]), float(col[-1]), 1e9):
        assert search_right(col, v) == np.searchsorted(col, v, side="right")


def ref_window(out, n_out, x, aux, length_m):
    """runner._Driver._window in numpy (before the kernel)."""
    from estimator.filter import ekf

    dist = out[:n_out, ekf.O_DIST]
    d_now = float(aux[ekf.A_DIST])
    i0 = max(int(np.searchsorted(dist, d_now - length_m, side="right")) - 1, 0)
    dr = np.vstack([out[i0:n_out, ekf.O_DR : ekf.O_DR + 2], aux[ekf.A_DR : ekf.A_DR + 2]])
    d = np.r_[dist[i0:], d_now]
    keep = np.r_[np.diff(d) > 1e-6, True]
    return dr[keep] + (x[:2] - aux[ekf.A_DR : ekf.A_DR + 2])


@pytest.mark.parametrize("seed", range(10))
def test_window_is_the_numpy_window(seed):
    from estimator.filter import ekf
    from estimator.pipeline.runner import _Driver

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    out = rng.normal(size=(n + 50, ekf.NO)) * 1e3
    out[:n, ekf.O_DIST] = np.cumsum(rng.choice([0.0, 1e-7, 0.5, 1.5], n))
    aux = rng.normal(size=ekf.NA) * 1e3
    aux[ekf.A_DIST] = out[n - 1, ekf.O_DIST] + rng.choice([0.0, 1e-7, 0.7])
    x = rng.normal(size=ekf.NX) * 1e3
    for length in (5.0, 250.0, 1e6):
        got = _Driver._window(None, out, n, x, aux, length)  # type: ignore[arg-type]
        np.testing.assert_array_equal(got, ref_window(out, n, x, aux, length))


def test_shape_passes_is_every_shape_gate_passing():
    rng = np.random.default_rng(0)
    params = Params()
    g = params.gates
    edge = (g.min_pairs, float(np.cos(np.radians(g.max_heading_diff_deg))), g.max_residual_m)
    for _ in range(2000):
        values = (
            int(rng.choice([0, g.min_pairs - 1, g.min_pairs, 80])),
            float(rng.choice([edge[1], 1.0, 0.5, np.nan, np.nextafter(edge[1], 0)])),
            float(rng.choice([edge[2], 0.1, 7.0, np.nan])),
            float(rng.choice([g.max_rotation_deg, 0.2, 30.0])),
        )
        want = all(d.passed for d in matching._shape_gates_of(values, params))
        assert matching._shape_passes(values, params) == want


# ---------------------------------------------------------------------------------------------
# end to end


@pytest.fixture(scope="module")
def drive():
    sim = simulate("multi_tunnel", seed=2, duration_s=260.0)
    return sim.log(), sim.route(), sim.frame


@pytest.fixture(scope="module")
def optimised_run(drive):
    log, route, frame = drive
    return run(log, route, Params(), method="proposed", frame=frame)


def test_a_run_is_the_run_of_the_numpy_matcher(drive, optimised_run, reference_matcher):
    log, route, frame = drive
    ref = run(log, route, Params(), method="proposed", frame=frame)
    fast = optimised_run
    assert len(fast.matches) == len(ref.matches) >= 20
    assert sum(m.accepted for m in fast.matches) >= 5
    # what the filter computed: bit for bit (rounding differences grow through the along-track
    # search over an outage, so the filter's inputs are computed exactly as before)
    for f in dataclasses.fields(fast.epochs):
        np.testing.assert_array_equal(
            getattr(fast.epochs, f.name), getattr(ref.epochs, f.name), err_msg=f.name
        )
    for a, b in zip(fast.matches, ref.matches, strict=True):
        for name in ("pseudo_position", "obs_cov", "innovation", "correction", "window_dr"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        # the rivals' scores and the Mahalanobis gate: to rounding
        _close(a, b, f"match {a.index}")
