"""THE rigid fit (:mod:`estimator.matching.fit`): Kabsch, the along-track scan's closed-form
residual against it, the fit against a numpy oracle, and the rivals going through the same fit
as the candidate."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.matching import FitSettings, Polyline, fit_rivals, fit_window, kabsch_2d
from estimator.matching.fit import _weaker_than_filter, fit_cost
from estimator.matching.gates import ShapeValues
from estimator.matching.geometry import local_piece
from estimator.matching.kernels import scan_offsets
from estimator.matching.rivals import rival_pieces
from estimator.params import Params, with_values
from estimator.route import Route


def rot(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def s_bend() -> Route:
    x = np.arange(-500.0, 1501.0, 2.0)
    return Route(np.column_stack([x, 60.0 * np.sin(2 * np.pi * x / 600.0) * (x > 0)]))


def random_polyline(rng: np.random.Generator, n: int) -> np.ndarray:
    heading = np.cumsum(rng.normal(0.0, 0.4, n))
    step = rng.uniform(2.0, 40.0, n)
    return 5e4 + np.cumsum(np.column_stack([np.cos(heading), np.sin(heading)]) * step[:, None], 0)


def drive(rng: np.random.Generator, route: Route, params: Params):
    """A noisy, slightly rotated window along ``route``, its DR position and covariance."""
    h = params.window.spacing_m
    s0 = float(rng.uniform(-20.0, route.length - 100.0))
    q = route.point_at(s0 + h * np.arange(int(rng.integers(3, 60))))
    angle = rng.uniform(-0.05, 0.05)
    win = (q - q.mean(0)) @ rot(np.degrees(angle)).T + q.mean(0)
    win = win + rng.normal(0, rng.choice([0.01, 0.5]), q.shape)
    a = rng.normal(size=(2, 2))
    return win, win[-1] + rng.normal(0, 2.0, 2), a @ a.T + np.eye(2), s0


PARAMS = [
    {},
    {"extensions.along_track_search": False},
    {"extensions.along_track_search": False, "extensions.geometry_covariance": False},
    {"window.spacing_m": 3.5, "window.along_search_step_m": 0.7},
    {"gates.alternative_shift_m": 4.0, "pseudo.shape_noise_m": 0.3},
]


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-np.pi, np.pi), st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.integers(0, 2**31 - 1)
)
def test_kabsch_recovers_rotation_and_translation(angle, tx, ty, seed):
    rng = np.random.default_rng(seed)
    src = rng.normal(scale=50.0, size=(20, 2))
    r_true = rot(np.degrees(angle))
    dst = src @ r_true.T + np.array([tx, ty])
    r, t = kabsch_2d(src, dst)
    np.testing.assert_allclose(r, r_true, atol=1e-9)
    np.testing.assert_allclose(t, [tx, ty], atol=1e-6)


def test_kabsch_refuses_a_reflection():
    src = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 3.0], [25.0, 8.0], [30.0, -4.0]])
    mirrored = src * np.array([1.0, -1.0])
    r, t = kabsch_2d(src, mirrored)
    assert np.linalg.det(r) == pytest.approx(1.0)
    residual = np.sqrt(np.mean(np.sum((src @ r.T + t - mirrored) ** 2, axis=1)))
    assert residual > 1.0  # the mirror image cannot be reached by a rotation


def test_kabsch_weights_ignore_unpaired_points():
    src = np.column_stack([np.arange(10.0), np.arange(10.0) ** 1.5])
    dst = src @ rot(20).T + 3.0
    dst[0] += 100.0
    w = np.ones(10)
    w[0] = 0.0
    r, _ = kabsch_2d(src, dst, w)
    np.testing.assert_allclose(r, rot(20), atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.floats(-30, 30), st.floats(0, 300), st.integers(0, 2**31 - 1))
def test_scan_kernel_equals_svd_fit(delta, s0, seed):
    """The numba scan's closed-form residual is the SVD Kabsch residual."""
    route = s_bend()
    rng = np.random.default_rng(seed)
    win = route.point_at(s0 + 5.0 * np.arange(40)) @ rot(3).T + rng.normal(scale=0.5, size=(40, 2))
    ms, m = np.empty(1), np.empty(1)
    scan_offsets(win, route.xy, route.s, s0, np.array([delta]), 5.0, ms, m)
    q = route.point_at(s0 + delta + 5.0 * np.arange(40))
    s = s0 + delta + 5.0 * np.arange(40)
    valid = (s >= -1e-6) & (s <= route.length + 1e-6)
    r, t = kabsch_2d(win, q, valid.astype(float))
    res = np.sum(((win @ r.T + t - q) ** 2).sum(axis=1) * valid) / valid.sum()
    assert m[0] == valid.sum()
    assert ms[0] == pytest.approx(res, rel=1e-6, abs=1e-8)


def ref_fit(win, p_dr, route: Route, s_anchor: float, lane: float, params: Params):
    """The fit in plain numpy on a :class:`Route`: every offset registered with Kabsch, the
    likelihood interval walked in Python. (z, obs_cov, residual, n_pairs) or None."""
    w, po, ext = params.window, params.pseudo, params.extensions
    h, step = w.spacing_m, w.along_search_step_m
    deltas = FitSettings.of(params).deltas

    def pairs(s_first):
        s = s_first + h * np.arange(len(win))
        return s, (s >= -1e-6) & (s <= route.length + 1e-6), route.point_at(s)

    ms, m = [], []
    for d in deltas:
        _, valid, q = pairs(s_anchor + d)
        if valid.sum() < 3:
            ms.append(np.inf)
            m.append(valid.sum())
            continue
        r, t = kabsch_2d(win, q, valid.astype(float))
        ms.append(np.sum(((win @ r.T + t - q) ** 2).sum(axis=1) * valid) / valid.sum())
        m.append(valid.sum())
    ms, m = np.array(ms), np.array(m, float)
    offset, sigma = 0.0, np.inf
    k = int(np.argmin(ms)) if ext.along_track_search else len(deltas) // 2
    if 0 < k < len(deltas) - 1 and np.isfinite(ms[k - 1 : k + 2]).all():
        jm, j0, jp = ms[k - 1 : k + 2]
        curvature = (jm - 2 * j0 + jp) / step**2
        noise2 = max(j0 / 2, po.shape_noise_m**2)
        if ext.along_track_search:
            chi = max(m[k], 1.0) * (ms - j0) / noise2
            ends = []
            for direction in (-1, 1):
                i = k
                while 0 <= i + direction < len(deltas) and np.isfinite(chi[i + direction]):
                    j = i + direction
                    if chi[j] > 1.0:
                        f = (1.0 - chi[i]) / (chi[j] - chi[i])
                        ends.append(deltas[i] + f * (deltas[j] - deltas[i]))
                        break
                    i = j
            if len(ends) == 2:
                sigma = 0.5 * (ends[1] - ends[0])
                parabola = deltas[k] + 0.5 * step * (jm - jp) / (jm - 2 * j0 + jp)
                offset = min(max(parabola if curvature > 0 else deltas[k], ends[0]), ends[1])
        elif curvature > 0:
            sigma = np.sqrt(2 * noise2 / (max(m[k], 1.0) * curvature))
    observed = sigma < po.along_sigma_max_m
    sigma = max(sigma, po.along_sigma_min_m) if observed else po.along_sigma_max_m
    s, valid, q = pairs(s_anchor + (offset if observed else 0.0))
    if valid.sum() < 2:
        return None
    r, t = kabsch_2d(win, q, valid.astype(float))
    residual = np.sqrt(np.sum(((win @ r.T + t - q) ** 2).sum(axis=1) * valid) / valid.sum())
    p_ref = r @ p_dr + t
    i1 = np.flatnonzero(valid)[-1]
    s_ref = s[i1] + (p_ref - q[i1]) @ route.tangent_at(s[i1])[0]
    tangent = route.tangent_at(s_ref)[0]
    normal = np.array([-tangent[1], tangent[0]])
    if ext.geometry_covariance:
        cross = max(po.cross_sigma_m, po.cross_residual_factor * residual)
        basis = np.column_stack([tangent, normal])
        cov = basis @ np.diag([sigma**2, cross**2]) @ basis.T
    else:
        cov = po.sigma_m**2 * np.eye(2)
    return p_ref + lane * normal, cov, residual, int(valid.sum())


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("change", PARAMS)
def test_fit_is_the_numpy_fit(seed, change):
    rng = np.random.default_rng(seed)
    params = with_values(Params(), change)
    route = Route(random_polyline(rng, 120))
    win, p_dr, _, s0 = drive(rng, route, params)
    lane = float(rng.choice([0.0, 1.8]))
    got = fit_window(win, p_dr, Polyline.of(route), s0, lane, FitSettings.of(params))
    want = ref_fit(win, p_dr, route, s0, lane, params)
    assert (got is None) == (want is None)
    if got is not None and want is not None:
        np.testing.assert_allclose(got.z, want[0], rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(got.obs_cov, want[1], rtol=1e-6, atol=1e-6)
        assert got.residual == pytest.approx(want[2], rel=1e-4, abs=1e-6)
        assert got.n_pairs == want[3]


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("change", PARAMS)
def test_rivals_are_the_fit_on_their_pieces(seed, change):
    """One fit: each rival is :func:`fit_window` on its route piece, scored by its cost."""
    rng = np.random.default_rng(seed)
    params = with_values(Params(), change)
    settings_ = FitSettings.of(params)
    route = Route(random_polyline(rng, 120))
    road = Polyline.of(route)
    win, p_dr, cov, s0 = drive(rng, route, params)
    lane = float(rng.choice([0.0, 1.8, -3.1]))
    for lane_path in (False, True):
        got = fit_rivals(win, p_dr, cov, road, s0, lane, lane_path, params, settings_)
        want = []
        for piece_at in rival_pieces(len(win), s0, lane, lane_path, params):
            piece = local_piece(road, *piece_at[1:4], reverse=piece_at.reverse)
            if piece is None:
                continue
            fit = fit_window(
                win,
                p_dr,
                piece,
                piece.arc_of(win[0]),
                0.0 if lane_path else lane,
                settings_,
                pointwise_residual=True,
                grid_scan=True,
                pos_cov2=cov,
            )
            if fit is not None:
                want.append((piece_at.rival, fit))
        assert [r.rival for r in got] == [r for r, _ in want]
        for r, (_, fit) in zip(got, want, strict=True):
            assert r.shape == ShapeValues.of(fit)
            assert r.cost == fit_cost(fit, p_dr, cov, settings_)
            assert r.residual_m == fit.residual


def test_pointwise_residual_is_the_kabsch_residual_to_rounding():
    rng = np.random.default_rng(3)
    route = s_bend()
    settings_ = FitSettings.of(Params())
    for s0 in (100.0, 600.0, 900.0):
        win = route.point_at(s0 + 5.0 * np.arange(50)) + rng.normal(0, 0.3, (50, 2))
        a = fit_window(win, win[-1], Polyline.of(route), s0, 0.0, settings_)
        b = fit_window(
            win, win[-1], Polyline.of(route), s0, 0.0, settings_, pointwise_residual=True
        )
        assert a is not None and b is not None
        assert a.residual == pytest.approx(b.residual, rel=1e-9)
        np.testing.assert_array_equal(a.rotation, b.rotation)


@pytest.mark.parametrize(
    ("along_m", "fit_sigma_m", "applied_across_only"),
    [
        (12.0, 7.0, True),  # the drift bend's fits: weak, and within their own sigma
        (0.5, 7.0, False),  # within 5 of the filter's sigmas: used whole
        (25.0, 3.2, False),  # the Husky lot's other stretch: off by its own sigma too, wrong
        (12.0, 0.5, False),  # stronger than the filter: used whole
    ],
)
def test_weak_along_track_only_takes_a_weak_fit_that_its_own_sigma_allows(
    along_m: float, fit_sigma_m: float, applied_across_only: bool
) -> None:
    """``pseudo.weak_along_max_chi2``: a fit off along the road by more than its own and the
    filter's sigmas together allow is not weak but wrong; applied across the road it would pass
    the innovation gate that refuses it whole."""
    tangent = np.array([1.0, 0.0])
    filter_cov = np.diag([0.6**2, 0.6**2])
    p = Params().pseudo
    got = _weaker_than_filter(
        fit_sigma_m,
        along_m,
        tangent,
        filter_cov,
        p.weak_along_disagreement,
        p.weak_along_max_chi2,
    )
    assert got is applied_across_only
    assert _weaker_than_filter(fit_sigma_m, along_m, tangent, None, 5.0, 13.8) is False
