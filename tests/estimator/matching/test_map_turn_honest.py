"""The honest rotation prior of an applied map bias whose fitted rotation is not applied
(``extensions.map_turn_honest_consider``, issue 17, stress drive 10): a fit within its noise
does not show the map unturned, so the outage considers, and the next outage carries, the
rotation's second moment rather than the method of moments' (often zero) estimate."""

from __future__ import annotations

import math

import numpy as np

from estimator.matching.map_bias import MapBias, carried_bias, learn_map_bias
from estimator.params import Params, with_values
from estimator.pipeline.driver import honest_turn_consider
from estimator.route import Route
from tests._session11_fit import MOMENTS_PRIOR

HONEST = with_values(
    Params(),
    {"extensions.map_bias": True, "extensions.map_turn_honest_consider": True, **MOMENTS_PRIOR},
)
MOMENTS = with_values(
    Params(),
    {"extensions.map_bias": True, "extensions.map_turn_honest_consider": False, **MOMENTS_PRIOR},
)
"""both with the outage's prior for an unapplied rotation as it was before session 13 (the
method of moments): the honest consider is what these tests compare with it"""
LANE = -1.75


def corner() -> Route:
    """600 m east, a quarter circle of radius 150 m to the left, then 1350 m north."""
    a = np.radians(np.arange(0.0, 90.1, 2.0))
    arc = np.column_stack([150.0 * np.sin(a), 150.0 * (1.0 - np.cos(a))])
    return Route(np.vstack([[[-600.0, 0.0]], arc, [[150.0, 1500.0]]]))


def shifted_and_turned(road: Route, *, shift: np.ndarray, degrees: float) -> Route:
    a = math.radians(degrees)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    pivot = np.array([150.0, 800.0])
    return Route((road.xy - pivot) @ rot.T + pivot + shift)


def learned(route: Route, road: Route, params: Params) -> tuple[MapBias, float]:
    s_end = float(road.project(np.array([150.0, 450.0])).s[0])
    s = np.arange(s_end - 800.0, s_end + 1e-9, 1.0)
    xy = road.point_at(s) + LANE * road.normal_at(s)
    hit = route.project(xy[-1])
    bias = learn_map_bias(
        xy,
        np.eye(2) * 0.25,
        route,
        s_guess=float(hit.s[0]),
        lane_offset=float(hit.lateral[0]),
        params=params,
    )
    return bias, s_end


def test_an_unapplied_rotation_keeps_its_second_moment_beside_the_method_of_moments() -> None:
    road = corner()
    route = shifted_and_turned(road, shift=np.array([6.0, -4.0]), degrees=0.05)
    bias, _ = learned(route, road, HONEST)
    assert bias.significant and bias.rotation == 0.0
    # the fit cannot show a twentieth of a degree: the method of moments leaves (almost)
    # nothing, the second moment at least the fit's own variance
    assert bias.turn_second_moment > bias.turn_var
    assert bias.turn_second_moment > math.radians(0.01) ** 2
    assert honest_turn_consider(bias, bias.turn_var) == bias.turn_second_moment
    assert honest_turn_consider(bias, 1.0) == 1.0


def test_a_map_found_right_keeps_its_rotation_variance() -> None:
    road = corner()
    bias, _ = learned(road, road, HONEST)
    assert not bias.significant
    assert honest_turn_consider(bias, bias.turn_var) == bias.turn_var


def test_the_carried_bias_grows_with_the_honest_rotation_far_from_its_pivot() -> None:
    road = corner()
    route = shifted_and_turned(road, shift=np.array([6.0, -4.0]), degrees=0.05)
    grown = {}
    for label, params in (("honest", HONEST), ("moments", MOMENTS)):
        bias, s_end = learned(route, road, params)
        s_next = s_end + 900.0
        normal = road.normal_at(np.array([s_next]))[0]
        position = road.point_at(np.array([s_next]))[0] + LANE * normal
        carried = carried_bias(
            bias,
            bias.offset,
            position=position,
            lane_seen=float(route.project(position).lateral[0]),
            normal=normal,
            metres=900.0,
            params=params,
        )
        grown[label] = np.diag(carried.cov[1:, 1:]) - np.diag(bias.measured_cov)
        d2 = float(np.sum((position - bias.pivot) ** 2))
        walk = params.offset.map_bias_walk_m_per_sqrt_km**2 * 0.9
        turn = max(bias.rotation_sigma**2, bias.turn_var)
        if label == "honest":
            turn = max(turn, bias.turn_second_moment)
        np.testing.assert_allclose(grown[label], walk + turn * d2, rtol=1e-9)
    assert np.all(grown["honest"] > grown["moments"])
