"""The map's rotation learned from two places (``extensions.map_turn_two_places``): a bias
carried from one GNSS-good stretch to another kilometres further, where the shift has moved
across by the map's turn (:func:`estimator.matching.map_bias.refined_bias`)."""

from __future__ import annotations

import math

import numpy as np

from estimator.matching.map_bias import MapBias, carried_bias, refined_bias
from estimator.params import Params, with_values
from estimator.route import Route
from tests.estimator._map_biases import map_bias

P = with_values(Params(), {"extensions.map_turn_two_places": True})
GNSS_COV = np.eye(2) * 0.25
S_PIVOT, S_END = 500.0, 2850.0


def road() -> Route:
    """Straight for 2.5 km, then turning 30 deg over 300 m."""
    s = np.arange(0.0, 4000.0, 2.0)
    heading = np.radians(30.0) * np.clip((s - 2500.0) / 300.0, 0.0, 1.0)
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * 2.0
    return Route(np.vstack([[0.0, 0.0], np.cumsum(step, axis=0)]))


def drawn(road: Route, shift: np.ndarray, rotation_deg: float, pivot: np.ndarray) -> Route:
    """The map of ``road``: turned by ``rotation_deg`` about ``pivot``, then shifted."""
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return Route((road.xy - pivot) @ rot.T + pivot + shift)


def first_place(shift: np.ndarray, pivot: np.ndarray, params: Params) -> MapBias:
    """The bias learned at ``pivot``: the shift right to 1.5 m, the rotation not told from zero
    (0.15 +- 0.14 deg fitted, so its honest second moment), carried 2.35 km on."""
    cov = 1.5**2 * np.eye(2)
    learned = map_bias(
        shift,
        pivot=pivot,
        lane=0.0,
        measured_cov=cov,
        chi2=99.0,
        along_observed=True,
        turn_second_moment=math.radians(0.15) ** 2 + math.radians(0.14) ** 2,
    )
    position = road().point_at(np.array([S_END + 20.0]))[0]
    return carried_bias(
        learned,
        shift,
        position=position,
        lane_seen=0.0,
        normal=np.array([0.0, 1.0]),
        metres=S_END - S_PIVOT,
        params=params,
    )


def refined_at_end(truth: Route, route: Route, carried: MapBias, params: Params) -> MapBias:
    """``carried`` refined by the GNSS track of the last 300 m before ``S_END``."""
    xy = truth.point_at(np.arange(S_END - 300.0, S_END + 1e-9, 1.0))
    return refined_bias(
        xy,
        GNSS_COV,
        route,
        carried=carried,
        s_guess=float(route.project(xy[-1:]).s[0]),
        params=params,
        metres=S_END - S_PIVOT,
    )


def refine(rotation_deg: float, params: Params = P) -> tuple[MapBias, MapBias, Route]:
    truth = road()
    pivot = truth.point_at(np.array([S_PIVOT]))[0]
    shift = np.array([4.0, 2.0])
    route = drawn(truth, shift, rotation_deg, pivot)
    carried = first_place(shift, pivot, params)
    out = refined_at_end(truth, route, carried, params)
    return carried, out, route


def test_a_turned_map_is_learned_from_two_places_within_its_sigma() -> None:
    carried, out, route = refine(-0.3)
    assert out.pivot is not carried.pivot
    assert out.rotation_sigma > 0.0
    assert abs(out.rotation - math.radians(-0.3)) <= out.rotation_sigma
    # the map moved back by the learned bias is the road, 1 km further on too
    truth = road()
    s = np.arange(S_END, S_END + 1000.0, 10.0)
    moved = out.moved_back(route.point_at(route.project(truth.point_at(s)).s), out.offset)
    gap = moved - truth.point_at(s)
    normal = truth.normal_at(s)
    across = np.abs(np.sum(gap * normal, axis=1))
    assert float(np.max(across)) < 1.0
    assert float(np.max(across)) < 3.0 * math.sqrt(
        float(normal[-1] @ out.measured_cov @ normal[-1])
    )


def test_a_map_only_shifted_learns_no_rotation() -> None:
    carried, out, _ = refine(0.0)
    assert out.rotation == 0.0
    assert out.pivot is carried.pivot


def test_switched_off_the_rotation_is_not_learned() -> None:
    off = with_values(Params(), {"extensions.map_turn_two_places": False})
    carried, out, _ = refine(-0.3, off)
    assert out.rotation == 0.0
    assert out.pivot is carried.pivot


def applied_place(rotation_deg: float, params: Params) -> tuple[MapBias, MapBias]:
    """A bias that applies a rotation of ``rotation_deg`` +- 0.14 deg (the map is turned by
    -0.3 deg), carried 2.35 km on and refined there (:func:`refine`'s map and stretch)."""
    truth = road()
    pivot = truth.point_at(np.array([S_PIVOT]))[0]
    shift = np.array([4.0, 2.0])
    route = drawn(truth, shift, -0.3, pivot)
    sigma = math.radians(0.14)
    learned = map_bias(
        shift,
        rotation=math.radians(rotation_deg),
        rotation_sigma=sigma,
        pivot=pivot,
        lane=0.0,
        measured_cov=1.5**2 * np.eye(2),
        chi2=99.0,
        along_observed=True,
        turn_var=sigma**2,
        turn_second_moment=sigma**2,
    )
    carried = carried_bias(
        learned,
        shift,
        position=truth.point_at(np.array([S_END + 20.0]))[0],
        lane_seen=0.0,
        normal=np.array([0.0, 1.0]),
        metres=S_END - S_PIVOT,
        params=params,
    )
    out = refined_at_end(truth, route, carried, params)
    return carried, out


def test_an_applied_rotation_is_corrected_below_the_test() -> None:
    # 0.08 deg off: under two of the applied rotation's sigmas, which the test would refuse
    on = with_values(P, {"extensions.map_turn_two_places_applied": True})
    carried, out = applied_place(-0.22, on)
    assert out.pivot is not carried.pivot
    assert abs(out.rotation - math.radians(-0.3)) < 0.5 * math.radians(0.08)
    assert out.rotation_sigma < carried.rotation_sigma
    off = with_values(P, {"extensions.map_turn_two_places_applied": False})
    carried, out = applied_place(-0.22, off)
    assert out.pivot is carried.pivot
    assert out.rotation == carried.rotation
