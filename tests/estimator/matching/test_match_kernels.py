"""The compiled matcher kernels against numpy oracles (the numpy code they replaced, kept here):
route geometry bit for bit as :class:`~estimator.route.Route` computes it, the along-track
search bit for bit as the Python matcher computed it, the rest to rounding (1e-9, relative
for values above 1). The whole run is held bit for bit by ``tests/test_golden_runs.py``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numba import njit

from estimator.errors import RouteError
from estimator.matching import FitSettings, Polyline, fit_window, resample_polyline, shifted_route
from estimator.matching import track_on_route as fast_track_on_route
from estimator.matching.fit import mahalanobis2
from estimator.matching.geometry import local_piece, project_near, project_on_route
from estimator.matching.kernels import (
    along_track_pairs,
    pair_points,
    rotation_sigma,
    scan_offsets,
    search_right,
    unit_interval,
)
from estimator.matching.route_kernels import offset_polyline, polyline_arrays
from estimator.params import Params, with_values
from estimator.route import Route

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


# ---------------------------------------------------------------------------------------------
# comparison


def _close(a, b, path: str, squared: bool = False) -> None:
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            _close(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
        return
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _close(a[k], b[k], f"{path}[{k}]")
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
    kept, seglen, unit, s = polyline_arrays(xy)
    for name, got in (("xy", kept), ("s", s), ("seglen", seglen), ("unit", unit)):
        np.testing.assert_array_equal(got, getattr(route, name), err_msg=name)


def ref_piece(route: Route, lateral_m: float, lo: float, hi: float, reverse: bool):
    """The old matcher's local candidate road: Route objects all the way."""
    lo, hi = max(lo, 0.0), min(hi, route.length)
    if hi - lo <= 1e-3:
        return None
    try:
        piece = (
            ref_shifted_route(route, lateral_m, s0=lo, s1=hi)
            if lateral_m
            else Route(route.segment(lo, hi))
        )
        return Route(piece.xy[::-1]) if reverse else piece
    except RouteError:
        return None


@pytest.mark.parametrize("seed", range(20))
def test_local_piece_is_the_route_of_the_piece(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 60))
    road = Polyline.of(route)
    for _ in range(10):
        lo, hi = np.sort(rng.uniform(-0.2, 1.2, 2) * route.length)
        lateral = float(rng.choice([0.0, -3.5, 1.8, 25.0]))
        reverse = bool(rng.integers(0, 2))
        got = local_piece(road, lateral, lo, hi, reverse=reverse)
        want = ref_piece(route, lateral, lo, hi, reverse)
        assert (got is None) == (want is None)
        if got is not None and want is not None:
            for name in ("xy", "s", "unit", "seglen"):
                np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert local_piece(road, 0.0, 5.0, 5.0 + 1e-4) is None


@pytest.mark.parametrize("seed", range(30))
@pytest.mark.parametrize("lateral", [-60.0, -25.0, -3.2, 0.7, 25.0, 200.0])
def test_offset_polyline_is_the_numpy_shift(seed, lateral):
    route = Route(_random_polyline(np.random.default_rng(seed), 40))
    s0, s1 = 0.1 * route.length, 0.8 * route.length
    fast = shifted_route(route, lateral, s0=s0, s1=s1)
    ref = ref_shifted_route(route, lateral, s0=s0, s1=s1)
    np.testing.assert_array_equal(fast.xy, ref.xy)
    np.testing.assert_array_equal(fast.s, ref.s)


def test_offset_polyline_of_a_point_has_no_length():
    assert offset_polyline(np.array([[2.0, 3.0], [2.0, 3.0 + 1e-12]]), 5.0).shape == (0, 2)
    route = Route(np.array([[0.0, 0.0], [10.0, 0.0]]))
    with pytest.raises(RouteError, match="no length"):
        shifted_route(route, 3.0, s0=4.0, s1=4.0)


@pytest.mark.parametrize("seed", range(30))
def test_pairs_are_the_route_points(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 25))
    n = int(rng.integers(2, 80))
    spacing = float(rng.uniform(1.0, 8.0))
    s_first = float(rng.uniform(-0.3, 0.9) * route.length)
    win = route.point_at(s_first + spacing * np.arange(n)) + rng.normal(0, 0.3, (n, 2))
    s, valid, q = np.empty(n), np.empty(n, np.bool_), np.empty((n, 2))
    pair_points(win, route.xy, route.s, route.unit, s_first, spacing, s, valid, q)
    want_s = s_first + spacing * np.arange(n)
    np.testing.assert_array_equal(s, want_s)
    np.testing.assert_array_equal(valid, (want_s >= -1e-6) & (want_s <= route.length + 1e-6))
    np.testing.assert_array_equal(q, route.point_at(want_s))


def ref_along_track(win, road: Polyline, s_anchor: float, settings: FitSettings):
    """The along-track search as the Python matcher computed it around the scan kernel."""
    deltas, step = settings.deltas, settings.step_m
    ms, m = np.empty(len(deltas)), np.empty(len(deltas))
    scan_offsets(win, road.xy, road.s, float(s_anchor), deltas, settings.spacing_m, ms, m)
    offset, curvature, sigma = 0.0, 0.0, float("inf")
    k = int(np.argmin(ms)) if settings.along_search else len(deltas) // 2
    if 0 < k < len(deltas) - 1 and np.isfinite(ms[k - 1 : k + 2]).all():
        jm, j0, jp = ms[k - 1], ms[k], ms[k + 1]
        curvature = float((jm - 2.0 * j0 + jp) / step**2)
        noise2 = max(float(j0) / 2.0, settings.shape_noise_m**2)
        if settings.along_search:
            chi = max(m[k], 1.0) * (ms - j0) / noise2
            bounds = ref_unit_interval(deltas, chi, k)
            if bounds is not None:
                sigma = 0.5 * (bounds[1] - bounds[0])
                if curvature > 0:
                    offset = float(deltas[k] + 0.5 * step * (jm - jp) / (jm - 2.0 * j0 + jp))
                lo, hi = bounds
                offset = min(max(float(offset if curvature > 0 else deltas[k]), lo), hi)
        elif curvature > 0:
            sigma = float(np.sqrt(2.0 * noise2 / (max(m[k], 1.0) * curvature)))
    observed = sigma < settings.along_sigma_max_m
    if not observed:
        offset = 0.0
    floor, unobserved = settings.along_sigma_min_m, settings.along_sigma_max_m
    sigma = float(max(sigma, floor)) if observed else unobserved
    return offset, curvature, sigma, observed


ALONG_PARAMS = [
    {},
    {"extensions.along_track_search": False},
    {"extensions.along_track_search": False, "extensions.geometry_covariance": False},
    {"window.spacing_m": 3.5, "window.along_search_step_m": 0.7},
]


@pytest.mark.parametrize("seed", range(15))
@pytest.mark.parametrize("change", ALONG_PARAMS)
def test_along_track_search_is_the_python_search_bit_for_bit(seed, change):
    rng = np.random.default_rng(seed)
    settings = FitSettings.of(with_values(Params(), change))
    route = Route(_random_polyline(rng, 200))
    road = Polyline.of(route)
    h = settings.spacing_m
    for _ in range(5):
        s0 = float(rng.uniform(-30.0, route.length - 50.0))
        n = int(rng.integers(2, 80))
        win = route.point_at(s0 + h * np.arange(n)) + rng.normal(0, rng.choice([0.01, 1.0]), (n, 2))
        s, valid, q = np.empty(n), np.empty(n, np.bool_), np.empty((n, 2))
        got = along_track_pairs(
            win, road.xy, road.s, road.unit, s0, settings.deltas, settings.along_search,
            settings.step_m, h, settings.shape_noise_m, settings.along_sigma_max_m,
            settings.along_sigma_min_m, 0, s, valid, q,
        )  # fmt: skip
        want = ref_along_track(win, road, s0, settings)
        assert got == want
        s2, valid2, q2 = np.empty(n), np.empty(n, np.bool_), np.empty((n, 2))
        pair_points(win, road.xy, road.s, road.unit, s0 + want[0], h, s2, valid2, q2)
        np.testing.assert_array_equal(q, q2)
        np.testing.assert_array_equal(valid, valid2)


@pytest.mark.parametrize("seed", range(15))
@pytest.mark.parametrize(
    "change", [{}, {"window.spacing_m": 3.5, "window.along_search_step_m": 0.7}]
)
def test_grid_scan_is_the_direct_scan_to_rounding(seed, change):
    """The rivals' along-track search on the shared grid finds the direct scan's offset."""
    rng = np.random.default_rng(seed)
    settings = FitSettings.of(with_values(Params(), change))
    assert settings.grid_ratio == round(settings.spacing_m / settings.step_m)
    route = Route(_random_polyline(rng, 200))
    road = Polyline.of(route)
    h = settings.spacing_m
    for _ in range(5):
        s0 = float(rng.uniform(-30.0, route.length - 50.0))
        n = int(rng.integers(2, 80))
        win = route.point_at(s0 + h * np.arange(n)) + rng.normal(0, rng.choice([0.01, 1.0]), (n, 2))
        got = []
        for ratio in (settings.grid_ratio, 0):
            s, valid, q = np.empty(n), np.empty(n, np.bool_), np.empty((n, 2))
            found = along_track_pairs(
                win, road.xy, road.s, road.unit, s0, settings.deltas, settings.along_search,
                settings.step_m, h, settings.shape_noise_m, settings.along_sigma_max_m,
                settings.along_sigma_min_m, ratio, s, valid, q,
            )  # fmt: skip
            got.append((found, valid, q))
        (grid, valid_g, q_g), (direct, valid_d, q_d) = got
        assert grid[3] == direct[3]
        np.testing.assert_allclose(grid[:3], direct[:3], rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(valid_g, valid_d)
        np.testing.assert_allclose(q_g, q_d, rtol=0, atol=1e-6)


def test_grid_scan_needs_a_shared_grid():
    no_search = {"extensions.along_track_search": False}
    assert FitSettings.of(with_values(Params(), no_search)).grid_ratio == 0
    off_grid = {"window.spacing_m": 5.0, "window.along_search_step_m": 0.3}
    assert FitSettings.of(with_values(Params(), off_grid)).grid_ratio == 0


@pytest.mark.parametrize("seed", range(30))
def test_unit_interval_is_the_python_loop(seed):
    rng = np.random.default_rng(seed)
    x = np.arange(-30.0, 31.0)
    chi = rng.uniform(0.0, 2.0) * (x - rng.uniform(-25, 25)) ** 2 / rng.uniform(5, 400)
    if seed % 5 == 0:
        chi[rng.integers(0, len(x))] = np.inf
    k = int(np.argmin(chi))
    found, lo, hi = unit_interval(x, chi, k)
    want = ref_unit_interval(x, chi, k)
    assert found == (want is not None)
    if want is not None:
        assert (lo, hi) == want


@pytest.mark.parametrize("seed", range(10))
def test_scan_from_a_binary_search_is_the_walk_from_the_start(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 300))
    win = route.point_at(rng.uniform(0, route.length) + 5.0 * np.arange(50))
    deltas = np.arange(-30.0, 31.0)
    for s_anchor in (-80.0, 0.0, float(rng.uniform(0, route.length)), route.length - 20.0):
        a = (np.empty(len(deltas)), np.empty(len(deltas)))
        b = (np.empty(len(deltas)), np.empty(len(deltas)))
        scan_offsets(win, route.xy, route.s, s_anchor, deltas, 5.0, *a)
        _ref_scan_kernel(win, route.xy, route.s, s_anchor, deltas, 5.0, *b)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])


@pytest.mark.parametrize("seed", range(20))
def test_mahalanobis_is_the_solve(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(2, 2)) * rng.choice([1e-3, 1.0, 30.0])
    cov = a @ a.T + np.eye(2) * rng.choice([0.0, 1e-6, 1.0])
    nu = rng.normal(size=2) * rng.choice([0.1, 10.0, 1e4])
    _close(mahalanobis2(nu, cov), ref_mahalanobis2(nu, cov), "d2")
    assert mahalanobis2(nu, np.zeros((2, 2))) == float("inf")


@pytest.mark.parametrize("seed", range(20))
def test_segment_tangent_and_projection_are_the_route_methods(seed):
    rng = np.random.default_rng(seed)
    route = Route(_random_polyline(rng, 60))
    road = Polyline.of(route)
    for _ in range(20):
        s0, s1 = np.sort(rng.uniform(-0.1, 1.1, 2) * route.length)
        if rng.uniform() < 0.2:
            s0 = s1 = float(route.s[rng.integers(0, len(route.s))])  # on a vertex
        if rng.uniform() < 0.1:
            s0, s1 = s1, s0
        np.testing.assert_array_equal(road.segment(s0, s1), route.segment(s0, s1))
        np.testing.assert_array_equal(road.tangent(s0), route.tangent_at(s0)[0])
    pts = route.point_at(rng.uniform(-50, route.length + 50, 30)) + rng.normal(0, 20, (30, 2))
    guess = rng.uniform(0, route.length, 30)
    for search in (0.0, 5.0, 60.0, 2.0 * route.length):
        s, lat = project_near(road, pts, guess, search)
        ref = route.project(pts, guess, search)
        np.testing.assert_array_equal(s, ref.s)
        np.testing.assert_array_equal(lat, ref.lateral)
    one = project_near(road, pts[0], 10.0, 60.0)
    np.testing.assert_array_equal(one[0], route.project(pts[0], 10.0, 60.0).s)


def ref_track_on_route(route, xy, *, search_m=50.0, chunk=64):
    p = np.atleast_2d(np.asarray(xy, np.float64))[:, :2]
    n = len(p)
    s, lat = np.empty(n), np.empty(n)
    s_prev = float(project_on_route(route, p[:1])[0][0])
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
        got = fast_track_on_route(route, xy, chunk=chunk)
        want = ref_track_on_route(route, xy, chunk=chunk)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    xy[100] = np.nan  # the numpy path
    got = fast_track_on_route(route, xy)
    want = ref_track_on_route(route, xy)
    np.testing.assert_array_equal(got[0], want[0])


def ref_max_turn_deg(xy, stretch_m, spacing_m):
    """runner._max_turn_deg in numpy (before the kernel)."""
    pts = resample_polyline(xy, spacing_m, anchor="end")
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
    from estimator.pipeline.driver import max_turn as _max_turn_deg

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 1500))
    head = np.cumsum(rng.normal(0, rng.choice([0.01, 0.3, 2.0]), n))
    step = rng.uniform(0.01, 3.0, n)
    xy = 1e4 + np.cumsum(np.column_stack([np.cos(head), np.sin(head)]) * step[:, None], 0)
    for stretch, spacing in ((250.0, 5.0), (100.0, 3.0), (50.0, 7.5)):
        _close(_max_turn_deg(xy, stretch, spacing), ref_max_turn_deg(xy, stretch, spacing), "turn")


def ref_rotation_sigma(win, fit, pos_cov2, params):
    """The fitted rotation's 1-sigma in numpy (before the kernel)."""
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
    road = Polyline.of(route)
    fit = fit_window(win, win[-1], road, road.arc_of(win[0]), 0.0, FitSettings.of(params))
    if fit is None:
        return
    got = rotation_sigma(
        win, fit.valid, fit.route_points, fit.residual, params.pseudo.shape_noise_m,
        fit.along_sigma, fit.tangent, cov,
    )  # fmt: skip
    _close(got, ref_rotation_sigma(win, fit, cov, params), "heading sigma")


def test_column_search_is_searchsorted():
    rows = np.zeros((500, 26))
    rows[:, 17] = np.cumsum(np.random.default_rng(0).choice([0.0, 0.5, 1.3], 500))
    col = rows[:, 17]
    for v in (-1.0, 0.0, 3.0, float(col[250]), float(col[-1]), 1e9):
        assert search_right(col, v) == np.searchsorted(col, v, side="right")


def ref_window(out, n_out, x, aux, length_m):
    """runner._Driver._window in numpy (before the kernel)."""
    from estimator.filter import layout as ekf

    dist = out[:n_out, ekf.O_DIST]
    d_now = float(aux[ekf.A_DIST])
    i0 = max(int(np.searchsorted(dist, d_now - length_m, side="right")) - 1, 0)
    dr = np.vstack([out[i0:n_out, ekf.O_DR : ekf.O_DR + 2], aux[ekf.A_DR : ekf.A_DR + 2]])
    d = np.r_[dist[i0:], d_now]
    keep = np.r_[np.diff(d) > 1e-6, True]
    return dr[keep] + (x[:2] - aux[ekf.A_DR : ekf.A_DR + 2])


@pytest.mark.parametrize("seed", range(10))
def test_window_is_the_numpy_window(seed):
    from estimator.filter import layout as ekf
    from estimator.pipeline.driver import dr_window

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    out = rng.normal(size=(n + 50, ekf.NO)) * 1e3
    out[:n, ekf.O_DIST] = np.cumsum(rng.choice([0.0, 1e-7, 0.5, 1.5], n))
    aux = rng.normal(size=ekf.NA) * 1e3
    aux[ekf.A_DIST] = out[n - 1, ekf.O_DIST] + rng.choice([0.0, 1e-7, 0.7])
    x = rng.normal(size=ekf.NX) * 1e3
    for length in (5.0, 250.0, 1e6):
        got = dr_window(out, n, x, aux, length)
        np.testing.assert_array_equal(got, ref_window(out, n, x, aux, length))
