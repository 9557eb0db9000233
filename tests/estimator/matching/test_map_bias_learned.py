"""The map bias learned from the GNSS-good approach (issue 17, item 1): a known route offset is
learned, with its lane, rotation and uncertainty; a right route learns a bias consistent with
zero; the outage's matches correct it where the road turns."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.matching.map_bias import carried_bias, learn_map_bias
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.pipeline.inputs import Inputs
from estimator.route import Route
from estimator.sim import simulate
from estimator.sim.road import straight, turn
from estimator.sim.scenario import Scenario
from tests._session11_fit import MOMENTS_PRIOR

ON = with_values(Params(), {"extensions.map_bias": True})
OFF = with_values(Params(), {"extensions.map_bias": False})
GNSS_COV = np.eye(2) * 0.25
LANE = -1.75
THRESHOLD = ON.offset.map_bias_min_sigmas**2


def corner() -> Route:
    """600 m east, a quarter circle of radius 150 m to the left, then 1350 m north."""
    a = np.radians(np.arange(0.0, 90.1, 2.0))
    arc = np.column_stack([150.0 * np.sin(a), 150.0 * (1.0 - np.cos(a))])
    return Route(np.vstack([[[-600.0, 0.0]], arc, [[150.0, 1500.0]]]))


def portal(road: Route) -> float:
    """Arc length 300 m past the corner: the approach's last 800 m turn through 90 deg."""
    return float(road.project(np.array([150.0, 450.0])).s[0])


def lane_track(road: Route, s_end: float, length: float = 800.0) -> np.ndarray:
    """GNSS-good driving ``LANE`` m left of ``road``'s centreline, every metre, to ``s_end``."""
    s = np.arange(s_end - length, s_end + 1e-9, 1.0)
    return road.point_at(s) + LANE * road.normal_at(s)


def learn(road: Route, route: Route, s_end: float, params: Params = ON):
    xy = lane_track(road, s_end)
    s_guess = float(route.project(xy[-1]).s[0])
    lane_seen = float(route.project(xy[-1]).lateral[0])
    return learn_map_bias(
        xy, GNSS_COV, route, s_guess=s_guess, lane_offset=lane_seen, params=params
    )


def test_a_shifted_route_is_learned_along_and_across_with_the_lane_on_a_bend() -> None:
    road = corner()
    shift = np.array([6.0, -4.0])
    bias = learn(road, Route(road.xy + shift), portal(road))
    assert bias.significant and bias.chi2 > THRESHOLD
    np.testing.assert_allclose(bias.offset, shift, atol=1.0)
    assert bias.lane == pytest.approx(LANE, abs=1.0)
    sigmas = np.sqrt(np.diag(bias.measured_cov))
    assert np.all(sigmas < 2.0)
    assert np.all(np.abs(bias.offset - shift) < 3.0 * sigmas)


def test_a_right_route_learns_a_bias_consistent_with_zero() -> None:
    road = corner()
    bias = learn(road, road, portal(road))
    assert bias.chi2 < THRESHOLD
    assert not bias.significant
    np.testing.assert_array_equal(bias.offset, 0.0)
    assert bias.lane == pytest.approx(LANE, abs=0.05)  # the lane learned near the portal kept


def test_a_straight_approach_cannot_tell_a_sideways_map_from_a_lane() -> None:
    road = Route(np.array([[-500.0, 0.0], [3000.0, 0.0]]))
    bias = learn(road, Route(road.xy + np.array([10.0, 4.0])), 1500.0)
    assert not bias.along_observed
    along_sigma = math.sqrt(bias.measured_cov[0, 0])
    assert along_sigma > 0.9 * ON.offset.map_bias_prior_sigma_m
    cross_sigma = math.sqrt(bias.measured_cov[1, 1])
    assert cross_sigma > 1.0  # the split of the 4 m between lane and map stays uncertain


def test_a_rotated_route_is_learned_as_a_rotation_on_a_straight_approach() -> None:
    road = Route(np.array([[-1000.0, 0.0], [3000.0, 0.0]]))
    angle = math.radians(1.0)
    pivot = np.array([1500.0, 0.0])  # the map is right at the portal, turned about it
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    route = Route((road.xy - pivot) @ rot.T + pivot)
    bias = learn(road, route, 2500.0)
    assert bias.significant
    assert math.degrees(bias.rotation) == pytest.approx(1.0, abs=0.15)
    assert bias.rotation_sigma < math.radians(0.2)
    np.testing.assert_allclose(bias.offset, 0.0, atol=1.0)
    # moved back, the route is the road again 1 km into the tunnel (17 m off before)
    ahead = road.point_at(np.array([3500.0]))
    back = bias.moved_back(route.xy, bias.offset)
    assert float(Route(back).project(ahead).distance[0]) < 1.0


def test_a_route_on_another_road_is_not_taken_for_a_biased_map() -> None:
    road = corner()
    bias = learn(road, Route(road.xy + np.array([-25.0, 0.0])), portal(road))
    assert bias.chi2 > THRESHOLD
    assert not bias.significant


def test_the_previous_outage_s_bias_is_carried_to_the_next_with_a_grown_uncertainty() -> None:
    """The walk alone: the unapplied rotation's prior is the method of moments' here (its
    honest second moment, the default, grows the carried bias with the distance from the
    pivot as well: tests/estimator/matching/test_map_turn_honest.py)."""
    on = with_values(ON, MOMENTS_PRIOR)
    road = corner()
    shift = np.array([6.0, -4.0])
    route = Route(road.xy + shift)
    bias = learn(road, route, portal(road), on)
    assert bias.significant
    s_next = portal(road) + 600.0
    normal = road.normal_at(np.array([s_next]))[0]
    position = road.point_at(np.array([s_next]))[0] + LANE * normal
    lane_seen = float(route.project(position).lateral[0])  # lane and map's shift together
    carried = carried_bias(
        bias,
        bias.offset,
        position=position,
        lane_seen=lane_seen,
        normal=normal,
        metres=600.0,
        params=on,
    )
    np.testing.assert_array_equal(carried.offset, bias.offset)
    assert carried.lane == pytest.approx(LANE, abs=1.0)
    # no longer the position error's: carried independent, and grown by the walk
    np.testing.assert_array_equal(carried.gain[1:], 0.0)
    walk = ON.offset.map_bias_walk_m_per_sqrt_km**2 * 0.6
    np.testing.assert_allclose(
        np.diag(carried.cov[1:, 1:]), np.diag(bias.measured_cov) + walk, rtol=1e-9
    )


def _scenario(bias_enu_m: tuple[float, float]) -> Scenario:
    """Open sky with a right-angle bend, then a 900 m tunnel with a bend: about 150 s."""
    pieces = (
        straight(500, speed_m_s=15.0)
        + turn(90, 250)
        + straight(300)
        + straight(300, tunnel=True)
        + turn(-60, 200, tunnel=True)
        + straight(400, tunnel=True)
        + straight(200)
    )
    sc = Scenario(
        name="map_bias_test",
        description="a bend before a straight tunnel",
        pieces=pieces,
        origin=(45.0, 7.0, 300.0),
    )
    return dataclasses.replace(sc, route=dataclasses.replace(sc.route, bias_enu_m=bias_enu_m))


def _drive(bias_enu_m: tuple[float, float]) -> tuple[Inputs, dict[str, float], list]:
    sim = simulate(_scenario(bias_enu_m), seed=11)
    inputs = Inputs(sim.log(), sim.route(), sim.frame)
    out = {}
    matches = []
    for label, params, method in (
        ("baseline", OFF, "baseline"),
        ("off", OFF, "proposed"),
        ("on", ON, "proposed"),
    ):
        run = run_methods(inputs, params, methods=(method,))[method]
        truth = method_metrics(run, inputs.route, inputs.log).truth
        assert truth is not None and truth.rmse_h_err_m is not None
        out[label] = truth.rmse_h_err_m
        if label == "on":
            matches = run.matches
    return inputs, out, matches


def test_a_simulated_drive_learns_its_known_route_offset() -> None:
    shift = np.array([3.0, 8.0])
    _, rmse, matches = _drive((float(shift[0]), float(shift[1])))
    assert matches and all(m.map_bias is not None for m in matches)
    first = matches[0].map_bias
    assert first.chi2 > THRESHOLD
    # the simplified map's chords across the bend and the receiver's wander limit it to metres
    np.testing.assert_allclose(first.learned, shift, atol=2.5)
    np.testing.assert_allclose(first.offset, first.learned)  # applied as learned at the start
    sigmas = np.sqrt(np.diag(first.cov))  # the bias error's at the first attempt
    assert np.all(np.abs(first.learned - shift) < 3.0 * sigmas)
    assert rmse["off"] > rmse["on"] + 0.5  # the bias dragged the estimate; learned, it does not
    assert rmse["on"] <= rmse["baseline"]


def test_a_simulated_drive_on_a_right_route_learns_no_bias() -> None:
    _, rmse, matches = _drive((0.0, 0.0))
    assert matches
    first = matches[0].map_bias
    assert first is not None
    assert first.chi2 < THRESHOLD
    for m in matches:
        assert m.map_bias is not None
        np.testing.assert_array_equal(m.map_bias.offset, 0.0)
    assert rmse["on"] == pytest.approx(rmse["off"], abs=0.05)
