from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.errors import RoutefuseError
from estimator.matching import (
    learn_lane_offset,
    match_window,
    resample_polyline,
    route_arc_length,
    shifted_route,
)
from estimator.params import Params, for_method, with_values
from estimator.route import Route

DATA = Path(__file__).resolve().parents[3] / ".." / "shared" / "data"
LANE = -1.8  # vehicle 1.8 m right of the route centreline


def s_bend() -> Route:
    """500 m straight, then a 600 m-wavelength sine of amplitude 60 m: changing curvature."""
    x = np.arange(-500.0, 1501.0, 2.0)
    return Route(np.column_stack([x, 60.0 * np.sin(2 * np.pi * x / 600.0) * (x > 0)]))


def straight() -> Route:
    return Route(np.array([[-500.0, 0.0], [2000.0, 0.0]]))


def driven(route: Route, s_end: float, *, lane: float = LANE, length: float = 260.0) -> np.ndarray:
    """The path of a vehicle keeping its lane, sampled every 0.5 m, ending at ``s_end``."""
    s = np.arange(s_end - length, s_end + 1e-9, 0.5)
    return route.point_at(s) + lane * route.normal_at(s)


def rot(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def match(window, route, *, params=None, cov=4.0, lane=LANE, s_guess="track"):
    window = np.asarray(window)
    if s_guess == "track":
        s_guess = route.project(window[-1]).s[0]
    return match_window(
        window,
        window[-1],
        np.eye(2) * cov,
        route,
        s_guess=s_guess,
        lane_offset=lane,
        params=params or Params(),
        index=3,
        t=12.5,
        epoch=7,
    )


def gate(rec, name):
    found = [g for g in rec.gates if g.name == name]
    assert found, f"gate {name} not recorded: {[g.name for g in rec.gates]}"
    return found[0]


def along_cross(route: Route, s: float, err: np.ndarray) -> tuple[float, float]:
    t = route.tangent_at(s)[0]
    return float(err @ t), float(err @ np.array([-t[1], t[0]]))


# ---------------------------------------------------------------- resampling and Kabsch


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=30),
    st.floats(0.5, 10.0),
)
def test_resample_keeps_spacing_and_ends_at_last_point(pts, spacing):
    xy = np.cumsum(np.asarray(pts), axis=0)
    out = resample_polyline(xy, spacing)
    np.testing.assert_allclose(out[-1], xy[-1], atol=1e-9)
    total = np.sum(np.hypot(*np.diff(xy, axis=0).T))
    assert len(out) == int(np.floor(total / spacing + 1e-9)) + 1
    # every resampled point lies on the polyline at the right arc length
    c = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    at = total - spacing * np.arange(len(out))[::-1]
    ref = np.column_stack([np.interp(at, c, xy[:, 0]), np.interp(at, c, xy[:, 1])])
    np.testing.assert_allclose(out, ref, atol=1e-9)


def test_resample_removes_speed_and_rate():
    line_fast = np.column_stack([np.linspace(0, 100, 11), np.zeros(11)])
    line_slow = np.column_stack(
        [np.r_[np.linspace(0, 50, 501), np.linspace(50.2, 100, 250)], np.zeros(751)]
    )
    np.testing.assert_allclose(
        resample_polyline(line_fast, 5.0), resample_polyline(line_slow, 5.0), atol=1e-9
    )


# ---------------------------------------------------------------- one match, every gate


def test_correct_route_is_accepted_and_keeps_the_lane():
    route = s_bend()
    path = driven(route, 800.0)
    dr = path + np.array([1.5, -2.0])  # a DR error
    rec = match(dr, route)
    assert rec.accepted, rec.verdict
    assert rec.n_pairs == len(rec.window_dr) == len(rec.route_points) >= 50
    err = rec.pseudo_position - path[-1]
    assert np.hypot(*err) < 0.2
    np.testing.assert_allclose(rec.innovation, rec.pseudo_position - rec.p_dr)
    np.testing.assert_array_equal(rec.correction, np.zeros(2))
    # p_ref on the centreline, z in the lane
    assert abs(route.project(rec.p_ref).lateral[0]) < 0.1
    assert route.project(rec.pseudo_position).lateral[0] == pytest.approx(LANE, abs=0.1)
    assert (rec.index, rec.t, rec.epoch) == (3, 12.5, 7)
    for g in rec.gates:
        assert g.passed == (
            g.value <= g.threshold if g.comparison == "<=" else g.value >= g.threshold
        )
    assert np.all(np.isfinite(rec.obs_cov))


def test_min_pairs_gate_rejects_a_short_window():
    route = s_bend()
    rec = match(driven(route, 600.0, length=62.0), route)
    assert not rec.accepted
    assert rec.verdict == "rejected: min_pairs"
    assert gate(rec, "min_pairs").value == 13  # 62 m of lane at 5 m spacing


def test_min_pairs_gate_when_the_route_ends():
    route = Route(s_bend().xy[:300])  # ends at x = 98
    path = driven(s_bend(), 800.0)  # drives beyond the route's end
    rec = match(path, route, s_guess=route.length)
    assert not rec.accepted
    assert not gate(rec, "min_pairs").passed


def test_heading_gate_rejects_a_turn_the_route_does_not_make():
    route = straight()
    path = driven(route, 600.0, lane=0.0)
    kink = path.copy()
    tail = kink[:, 0] > path[-1, 0] - 6.0
    kink[tail] = kink[tail][0] + (kink[tail] - kink[tail][0]) @ rot(25).T
    rec = match(kink, route, lane=0.0)
    g = gate(rec, "heading")
    assert not g.passed
    assert g.value == pytest.approx(np.cos(np.radians(25)), abs=0.02)
    assert not rec.accepted


def test_residual_gate_rejects_a_shape_the_route_lacks():
    route = straight()
    path = driven(route, 600.0, lane=0.0)
    wavy = path + np.column_stack([np.zeros(len(path)), 6.0 * np.sin(path[:, 0] / 15.0)])
    wavy[-12:] = path[-12:] + np.array([0.0, wavy[-13, 1]])  # straight end: heading passes
    rec = match(wavy, route, lane=0.0, params=for_method(Params(), "paper"))
    assert gate(rec, "heading").passed
    assert not gate(rec, "residual").passed
    assert rec.verdict == "rejected: residual"


def test_rotation_gate_rejects_a_large_fitted_rotation():
    route = straight()
    path = driven(route, 600.0, lane=0.0)
    turned = path[0] + (path - path[0]) @ rot(20).T  # heading drifted 20 degrees
    params = with_values(Params(), {"gates.max_heading_diff_deg": 60})
    rec = match(turned, route, params=params, lane=0.0, s_guess=None)
    assert gate(rec, "heading").passed
    g = gate(rec, "rotation")
    assert g.value == pytest.approx(20.0, abs=0.01)
    assert rec.verdict == "rejected: rotation"


def test_fitted_rotation_is_the_heading_correction():
    route = straight()
    path = driven(route, 600.0, lane=0.0)
    drifted = path[0] + (path - path[0]) @ rot(0.5).T  # DR heading 0.5 deg left of truth
    rec = match(drifted, route, lane=0.0, s_guess=None)
    assert rec.accepted
    assert np.degrees(rec.rotation_rad) == pytest.approx(-0.5, abs=1e-9)
    # shape noise 1 m over a 250 m window: about 0.1 deg
    assert rec.fit is not None
    assert 0.05 < np.degrees(rec.fit.heading_sigma_rad) < 0.2


def test_correction_cap_rejects_a_large_jump():
    route = straight()
    path = driven(route, 600.0, lane=0.0)
    rec = match(path + np.array([0.0, 40.0]), route, lane=0.0, params=for_method(Params(), "paper"))
    g = gate(rec, "correction_cap")
    assert g.value == pytest.approx(40.0, abs=0.01)
    assert rec.verdict == "rejected: correction_cap"
    assert [x.name for x in rec.gates] == [
        "min_pairs",
        "heading",
        "residual",
        "rotation",
        "correction_cap",
    ]


def test_mahalanobis_gate_uses_the_filter_covariance():
    route = straight()
    path = driven(route, 600.0, lane=0.0)
    dr = path + np.array([0.0, 4.5])  # within the lane-continuity limit
    tight = match(dr, route, lane=0.0, cov=0.25)
    loose = match(dr, route, lane=0.0, cov=25.0)
    g = gate(tight, "mahalanobis")
    # S = 0.25 + cross_sigma^2 across the road (the fit is exact: the floor applies)
    cross2 = Params().pseudo.cross_sigma_m ** 2
    assert g.value == pytest.approx(4.5**2 / (0.25 + cross2), rel=1e-3)
    assert tight.verdict == "rejected: mahalanobis"
    assert gate(loose, "mahalanobis").passed
    assert loose.accepted, loose.verdict


def test_lane_continuity_rejects_a_jump_across_the_road():
    route = straight()
    path = driven(route, 600.0)
    rec = match(path + np.array([0.0, 8.0]), route, cov=400.0)
    assert gate(rec, "mahalanobis").passed
    g = gate(rec, "lane_continuity")
    assert g.value == pytest.approx(8.0, abs=0.01)
    assert not g.passed and not rec.accepted


@pytest.mark.parametrize("side", [25.0, -25.0])
@pytest.mark.parametrize("make", [s_bend, straight])
def test_parallel_route_is_never_accepted(make, side):
    """The route is a parallel road 25 m away; even with the cap at 100 m and a filter so
    uncertain that the Mahalanobis test passes, no window is accepted."""
    road = make()
    wrong = shifted_route(road, side)
    params = with_values(Params(), {"gates.max_correction_m": 100})
    accepted = 0
    for s_end in np.arange(300.0, 1400.0, 50.0):
        path = driven(road, s_end)
        rec = match(path + np.array([1.0, -1.0]), wrong, params=params, cov=900.0, lane=0.0)
        accepted += rec.accepted
    assert accepted == 0


def test_rival_test_alone_rejects_the_parallel_route():
    road = s_bend()
    wrong = shifted_route(road, 25.0)
    params = with_values(
        Params(),
        {
            "gates.max_correction_m": 100,
            "gates.max_lateral_jump_m": 100,
            "gates.mahalanobis_chi2": 1000,
        },
    )
    for s_end in (400.0, 700.0, 1000.0, 1300.0):
        rec = match(driven(road, s_end), wrong, params=params, cov=100.0, lane=0.0)
        assert rec.verdict == "rejected: alternative_right"
        assert rec.extra["cost_right"] < rec.extra["cost"]
        ok = match(driven(road, s_end), road, params=params, cov=100.0)
        assert ok.accepted, ok.verdict


def test_paper_method_accepts_the_parallel_route():
    """What the validation is for: the paper's gates alone let the wrong road through."""
    road = straight()
    rec = match(
        driven(road, 600.0),
        shifted_route(road, 25.0),
        lane=0.0,
        params=with_values(for_method(Params(), "paper"), {"gates.max_correction_m": 100}),
    )
    assert rec.accepted


@pytest.mark.parametrize("method", ["proposed", "paper"])
def test_reversed_route_is_rejected(method):
    road = s_bend()
    reversed_route = Route(road.xy[::-1])
    params = with_values(for_method(Params(), method), {"gates.max_correction_m": 100})
    for s_end in np.arange(300.0, 1400.0, 100.0):
        rec = match(driven(road, s_end), reversed_route, params=params, cov=900.0, lane=0.0)
        assert not rec.accepted
        assert not gate(rec, "heading").passed


def test_reversed_rival_is_compared():
    road = s_bend()
    rec = match(driven(road, 900.0), Route(road.xy[::-1]), lane=0.0, cov=100.0, s_guess=None)
    g = gate(rec, "alternative_reversed")
    assert "reversed" in g.note
    assert not g.passed  # the route driven backwards explains the window better


# ---------------------------------------------------------------- along-track and R_k


@pytest.mark.parametrize("offset", [8.0, -5.0, 0.0])
def test_along_track_search_recovers_an_offset_on_a_curved_route(offset):
    route = s_bend()
    for s_end in (700.0, 900.0):
        path = driven(route, s_end)
        dr = path + offset * route.tangent_at(s_end)[0]
        rec = match(dr, route, cov=100.0)
        assert rec.accepted, rec.verdict
        along, cross = along_cross(route, s_end, rec.pseudo_position - path[-1])
        assert abs(along) < 0.1
        assert abs(cross) < 0.1
        assert rec.fit is not None and rec.along_observed
        assert rec.fit.along_sigma_m < 2.0
        # without the search the DR along-track error passes straight through
        plain = match(
            dr,
            route,
            cov=100.0,
            params=with_values(Params(), {"extensions.along_track_search": False}),
        )
        assert abs(along_cross(route, s_end, plain.pseudo_position - path[-1])[0]) > 0.5 * abs(
            offset
        )


def test_along_track_is_unobserved_on_a_straight_road():
    route = straight()
    path = driven(route, 600.0)
    rec = match(path + np.array([7.0, 0.0]), route)
    assert rec.accepted
    p = Params().pseudo
    assert rec.fit is not None and not rec.along_observed
    assert rec.fit.along_sigma_m == p.along_sigma_max_m
    assert rec.fit.along_offset_m == 0.0
    # R_k: along-track (East here) unobserved, cross-track tight
    np.testing.assert_allclose(
        rec.obs_cov, np.diag([p.along_sigma_max_m**2, p.cross_sigma_m**2]), atol=1e-6
    )
    # the innovation is across the road only
    assert rec.innovation[0] == pytest.approx(0.0, abs=1e-6)


def test_along_track_is_unobserved_on_a_constant_bend():
    """Sliding along a circle is a rotation, which the rigid fit absorbs: a steady curve tells
    no more about along-track position than a straight road."""
    a = np.radians(np.arange(0.0, 240.0, 2.0))
    route = Route(330.0 * np.column_stack([np.sin(a), 1.0 - np.cos(a)]))
    path = driven(route, 900.0)
    rec = match(path + 10.0 * route.tangent_at(900.0)[0], route, cov=100.0)
    assert rec.accepted
    assert rec.fit is not None and not rec.along_observed
    assert rec.fit.along_offset_m == 0.0
    assert rec.fit.along_sigma_m == Params().pseudo.along_sigma_max_m


@pytest.mark.parametrize("wiggle", [0.02, 0.5])
def test_cross_track_sigma_follows_the_registration_residual(wiggle):
    """A window the route fits to centimetres is trusted to the floor; a loose fit (here the
    DR wiggles across the road) only to cross_residual_factor residuals."""
    route = straight()
    path = driven(route, 600.0)
    path = path + np.column_stack(
        [np.zeros(len(path)), wiggle * np.sin(np.arange(len(path)) * np.pi / 60.0)]
    )
    rec = match(path, route)
    assert rec.accepted, rec.verdict
    p = Params().pseudo
    cross2 = np.linalg.eigvalsh(rec.obs_cov)[0]
    expected = max(p.cross_sigma_m, p.cross_residual_factor * rec.residual_m)
    assert np.sqrt(cross2) == pytest.approx(expected, rel=1e-9)
    assert (expected > p.cross_sigma_m) == (wiggle > 0.1)


def test_geometry_covariance_rotates_with_the_road():
    route = Route(straight().xy @ rot(30).T)
    path = driven(route, 600.0)
    rec = match(path, route)
    vals, vecs = np.linalg.eigh(rec.obs_cov)
    assert vals[0] == pytest.approx(Params().pseudo.cross_sigma_m ** 2)
    assert abs(vecs[:, 1] @ route.tangent_at(600.0)[0]) == pytest.approx(1.0)


def test_paper_covariance_is_isotropic():
    params = for_method(Params(), "paper")
    rec = match(driven(s_bend(), 800.0), s_bend(), params=params)
    np.testing.assert_allclose(rec.obs_cov, params.pseudo.sigma_m**2 * np.eye(2))
    assert not any(g.gate.rival is not None for g in rec.gates)


def test_lane_path_matching_removes_the_curve_stretch():
    """The lane is an offset curve: its arc length differs from the centreline's on bends."""
    route = s_bend()
    path = driven(route, 800.0, lane=-3.5)
    on = match(path, route, lane=-3.5)
    off = match(
        path,
        route,
        lane=-3.5,
        params=with_values(Params(), {"extensions.lane_path_matching": False}),
    )
    err_on = np.hypot(*(on.pseudo_position - path[-1]))
    err_off = np.hypot(*(off.pseudo_position - path[-1]))
    assert err_on < 0.1 < err_off


def test_realistic_dr_error_on_real_tunnel_geometry():
    """Tunnel de Monaco (OSM, raw vertices up to 513 m apart) against a smoothed drive."""
    path = DATA / "osm_monaco" / "monaco_tunnels.geojson"
    if not path.exists():
        pytest.skip(f"real data not found at {path}")
    from scipy.ndimage import gaussian_filter1d

    from estimator.io.routefile import load_route
    from estimator.nav.frames import LocalFrame

    c0 = json.loads(path.read_text())["features"][0]["geometry"]["coordinates"][0]
    frame = LocalFrame(c0[1], c0[0])
    route = load_route(path, frame, feature=0)
    other_way = load_route(path, frame, feature=1)
    dense = route.resample(1.0)
    road = Route(gaussian_filter1d(dense, 15, axis=0, mode="nearest"))
    lane_path = Route(road.point_at(road.s) + LANE * road.normal_at(road.s))
    params = with_values(Params(), {"gates.max_correction_m": 100})
    accepted, wrong_accepted, z_err = 0, 0, []
    ends = np.arange(300.0, lane_path.length - 50.0, 50.0)
    for s_end in ends:
        truth = driven(lane_path, s_end, lane=0.0)
        dr = truth + 6.0 * lane_path.tangent_at(s_end)[0] + 1.5 * lane_path.normal_at(s_end)[0]
        rec = match(dr, route, cov=9.0)
        accepted += rec.accepted
        if rec.accepted:
            z_err.append(rec.pseudo_position - truth[-1])
        wrong_accepted += match(dr, other_way, cov=900.0, lane=0.0, params=params).accepted
    assert accepted >= 0.9 * len(ends)
    assert np.sqrt(np.mean(np.sum(np.square(z_err), axis=1))) < 6.0  # DR error was 6.2 m
    assert wrong_accepted == 0


# ---------------------------------------------------------------- inputs, lane offset, speed


def test_bad_inputs_give_a_routefuse_error():
    route = straight()
    path = driven(route, 600.0)
    bad = path.copy()
    bad[10, 0] = np.nan
    with pytest.raises(RoutefuseError, match="not finite"):
        match(bad, route)
    with pytest.raises(RoutefuseError, match="2x2"):
        match_window(
            path,
            path[-1],
            np.eye(3),
            route,
            s_guess=None,
            lane_offset=0.0,
            params=Params(),
            index=0,
            t=0.0,
            epoch=0,
        )


def test_single_point_window_is_rejected_without_nan_gates():
    rec = match(np.array([[0.0, 0.0]]), straight())
    assert not rec.accepted and rec.verdict == "rejected: min_pairs"
    assert all(np.isfinite(g.value) for g in rec.gates)


def test_route_arc_length_tracks_within_the_search_window():
    loop = Route(np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 1.0], [0.0, 1.0]]))
    params = Params()
    assert route_arc_length(loop, [50.0, 0.9], params=params) == pytest.approx(551.0)
    assert route_arc_length(loop, [50.0, 0.9], s_guess=50.0, params=params) == pytest.approx(50.0)


def _gnss_track(lateral, t_end=200.0, rate=10.0):
    route = straight()
    t = np.arange(0.0, t_end + 1e-9, 1.0 / rate)
    s = 10.0 * t
    xy = route.point_at(s) + np.asarray(lateral)[..., None] * route.normal_at(s)
    return route, t, xy


def test_learn_lane_offset_constant():
    route, t, xy = _gnss_track(np.full(2001, LANE))
    off = learn_lane_offset(t, xy, np.ones(len(t), bool), route, t_end=200.0, params=Params())
    assert off == pytest.approx(LANE)


def test_learn_lane_offset_is_exponentially_weighted():
    tau = Params().offset.time_constant_s
    t = np.arange(0.0, 200.0 + 1e-9, 0.1)
    lateral = np.where(t > 200.0 - tau, 2.0, 0.0)
    route, t, xy = _gnss_track(lateral)
    off = learn_lane_offset(
        t, xy, np.ones(len(t), bool), route, t_end=200.0, params=Params(), s_guess=2000.0
    )
    # continuous limit over the last 5 tau: 2 (1 - e^-1) / (1 - e^-5)
    assert off == pytest.approx(2.0 * (1 - np.exp(-1)) / (1 - np.exp(-5)), rel=0.01)


def test_learn_lane_offset_uses_only_good_gnss_before_t_end():
    route, t, xy = _gnss_track(np.where(np.arange(2001) < 1000, 1.0, -3.0))
    used = np.ones(len(t), bool)
    used[1000:] = False
    off = learn_lane_offset(t, xy, used, route, t_end=199.0, params=Params())
    assert off == pytest.approx(1.0)
    off = learn_lane_offset(t, xy, np.ones(len(t), bool), route, t_end=99.0, params=Params())
    assert off == pytest.approx(1.0)


def test_learn_lane_offset_gives_zero_when_unusable():
    params = Params()
    route, t, xy = _gnss_track(np.full(2001, 25.0))
    assert (
        learn_lane_offset(t, xy, np.ones(len(t), bool), route, t_end=200.0, params=params) == 0.0
    )  # a parallel road, not a lane
    route, t, xy = _gnss_track(np.full(2001, LANE))
    assert (
        learn_lane_offset(t, xy, np.zeros(len(t), bool), route, t_end=200.0, params=params) == 0.0
    )
    xy[:] = np.nan
    assert learn_lane_offset(t, xy, np.ones(len(t), bool), route, t_end=200.0, params=params) == 0.0
    route, t, xy = _gnss_track(np.full(2001, LANE))
    off = replace(params, offset=replace(params.offset, enabled=False))
    assert learn_lane_offset(t, xy, np.ones(len(t), bool), route, t_end=200.0, params=off) == 0.0


def test_match_window_is_fast():
    route = s_bend()
    path = driven(route, 800.0)
    match(path, route)  # compile
    times = []
    for _ in range(20):
        t0 = time.process_time()  # CPU time: other processes share the cores
        match(path, route)
        times.append(time.process_time() - t0)
    assert np.median(times) < 0.010


def test_track_on_route_keeps_to_the_driven_stretch() -> None:
    """Out and back 5 m apart: a vehicle 3 m left of the outbound stretch is nearer to the
    return stretch once beside it. Nearest-point projection jumps there; tracking along the
    route does not."""
    from estimator.matching import project_on_route, track_on_route

    theta = np.linspace(-np.pi / 2, np.pi / 2, 30)
    turn = np.column_stack([300 + 2.5 * np.cos(theta), 2.5 + 2.5 * np.sin(theta)])
    route = Route(np.vstack([[-100.0, 0.0], turn, [0.0, 5.0]]))
    drive = np.column_stack([np.arange(-50.0, 200.0, 2.0), np.full(125, 3.0)])
    s_track, lat_track = track_on_route(route, drive)
    s_near, _ = project_on_route(route, drive)
    assert np.allclose(s_track, drive[:, 0] + 100) and np.allclose(lat_track, 3.0)
    assert np.all(s_near[drive[:, 0] > 10] > 400)
