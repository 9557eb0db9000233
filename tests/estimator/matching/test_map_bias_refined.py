"""A map bias carried from the previous outage and refined by the short GNSS-good stretch
since (``offset.map_bias_refine``), and a shift explained by a small rotation
(``offset.map_bias_turned_rescue``) (:mod:`estimator.matching.map_bias`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.matching.map_bias import MapBias, learn_map_bias, refined_bias
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.route import Route
from estimator.sim.stress import moved_route
from tests.estimator._map_biases import map_bias

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
P = Params()
GNSS_COV = np.eye(2) * 0.25


def bend() -> Route:
    """A road turning 30 deg over 300 m between straights."""
    s = np.arange(0.0, 2000.0, 2.0)
    heading = np.radians(30.0) * np.clip((s - 1000.0) / 300.0, 0.0, 1.0)
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * 2.0
    return Route(np.vstack([[0.0, 0.0], np.cumsum(step, axis=0)]))


def carried(offset: np.ndarray, pivot: np.ndarray, sigma: float) -> MapBias:
    """A significant bias as :func:`estimator.matching.map_bias.carried_bias` hands it on."""
    cov = np.zeros((3, 3))
    cov[1:, 1:] = sigma**2 * np.eye(2)
    return map_bias(
        offset,
        pivot=pivot,
        lane=0.0,
        cov=cov,
        measured_cov=cov[1:, 1:],
        chi2=99.0,
        along_observed=True,
    )


def refine(road: Route, shift: np.ndarray, previous: MapBias, s_end: float) -> MapBias:
    route = Route(road.xy + shift)
    xy = road.point_at(np.arange(s_end - 250.0, s_end + 1e-9, 1.0))
    s_guess = float(route.project(xy[-1:]).s[0])
    return refined_bias(xy, GNSS_COV, route, carried=previous, s_guess=s_guess, params=P)


def test_a_stretch_that_turns_corrects_the_along_track_error_of_a_carried_bias() -> None:
    road = bend()
    s_end = 1250.0
    tangent = road.tangent_at(s_end)[0]
    truth = 10.0 * tangent + np.array([0.0, 3.0])
    previous = carried(truth + 2.0 * tangent, np.zeros(2), sigma=1.5)
    out = refine(road, truth, previous, s_end)
    before = abs(float(tangent @ (previous.offset - truth)))
    after = abs(float(tangent @ (out.offset - truth)))
    assert after < before
    sigma_before = math.sqrt(float(tangent @ previous.measured_cov @ tangent))
    assert math.sqrt(float(tangent @ out.measured_cov @ tangent)) < sigma_before
    assert out.significant


def test_a_stretch_on_another_road_leaves_the_carried_bias_as_it_was() -> None:
    road = bend()
    previous = carried(np.array([5.0, 0.0]), np.zeros(2), sigma=1.5)
    out = refine(road, np.array([0.0, 40.0]), previous, 1250.0)
    assert out is previous


def test_an_insignificant_bias_is_not_refined() -> None:
    previous = dataclasses.replace(carried(np.zeros(2), np.zeros(2), 1.0))
    assert refine(bend(), np.array([3.0, 0.0]), previous, 1250.0) is previous


def turned_map(rotation_deg: float, pivot_x: float) -> tuple[Route, Route]:
    """A straight road and the map drawn turned by ``rotation_deg`` about a point on it."""
    road = Route(np.array([[-1000.0, 0.0], [12000.0, 0.0]]))
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    pivot = np.array([pivot_x, 0.0])
    return road, Route((road.xy - pivot) @ rot.T + pivot)


@pytest.mark.parametrize("rescue", [True, False])
def test_a_shift_at_the_portal_from_a_map_turned_far_ahead_is_learned_with_the_rotation(
    rescue: bool,
) -> None:
    road, route = turned_map(-0.3, 4000.0)
    xy = road.point_at(np.arange(200.0, 1000.0 + 1e-9, 1.0))
    params = with_values(P, {"offset.map_bias_turned_rescue": rescue})
    bias = learn_map_bias(
        xy,
        GNSS_COV,
        route,
        s_guess=float(route.project(xy[-1:]).s[0]),
        lane_offset=0.0,
        params=params,
    )
    shift = math.radians(0.3) * 3000.0  # the route lies this far to the left at the end
    assert bias.measured[1] > 0.8 * shift
    if rescue:
        assert bias.significant
        assert math.degrees(bias.rotation) == pytest.approx(-0.3, abs=0.2)
        assert bias.rotation_sigma > 0.0
    else:
        assert not bias.significant


@pytest.mark.slow
def test_the_multi_tunnel_on_a_biased_map_refines_the_bias_between_tunnels() -> None:
    inp = open_inputs(SAMPLES / "multi_tunnel.mcap", SAMPLES / "multi_tunnel.route.geojson")
    assert inp.route is not None
    moved = dataclasses.replace(inp, route=moved_route(inp.route))
    rmse = {}
    for refine_on in (True, False):
        p = with_values(Params(), {"offset.map_bias_refine": refine_on})
        run = run_methods(moved, p, methods=("proposed",))["proposed"]
        firsts = []
        for a, b in run.degraded_intervals:
            recs = [m for m in run.matches if a <= m.t <= b and m.map_bias is not None]
            firsts.append(recs[0].map_bias.chi2)  # type: ignore[union-attr]
        refined = len(set(firsts)) == len(firsts)
        assert refined == refine_on
        truth = method_metrics(run, moved.route, moved.log).truth  # type: ignore[arg-type]
        assert truth is not None and truth.rmse_h_err_m is not None
        rmse[refine_on] = truth.rmse_h_err_m
    assert rmse[True] < rmse[False]
    assert rmse[True] <= 1.5
