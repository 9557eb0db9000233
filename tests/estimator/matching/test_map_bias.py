"""The map bias learned before an outage (:mod:`estimator.matching.map_bias`) and what a run
does with it (``extensions.map_bias``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.matching.map_bias import learn_map_bias, unbiased
from estimator.params import Params, for_method, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.pipeline.inputs import Inputs
from estimator.route import Route

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
ON = with_values(Params(), {"extensions.map_bias": True})
GNSS_COV = np.eye(2) * 0.25


def s_bend() -> Route:
    """500 m straight, then a 600 m-wavelength sine of amplitude 60 m."""
    x = np.arange(-500.0, 1501.0, 2.0)
    return Route(np.column_stack([x, 60.0 * np.sin(2 * np.pi * x / 600.0) * (x > 0)]))


def straight() -> Route:
    return Route(np.array([[-500.0, 0.0], [3000.0, 0.0]]))


def track(road: Route, s_end: float, length: float = 800.0) -> np.ndarray:
    """GNSS-good driving on ``road``'s centreline, every metre, ending at ``s_end``."""
    return road.point_at(np.arange(s_end - length, s_end + 1e-9, 1.0))


def learn(road: Route, shift: np.ndarray, s_end: float):
    route = Route(road.xy + shift)
    xy = track(road, s_end)
    return learn_map_bias(
        xy, GNSS_COV, route, s_guess=route.project(xy[-1]).s[0], lane_offset=0.0, params=ON
    )


def test_a_route_drawn_ahead_of_the_road_on_a_bend_is_measured_along_the_road() -> None:
    road = s_bend()
    s_end = float(road.project(np.array([1200.0, 0.0])).s[0])
    tangent = road.tangent_at(s_end)[0]
    bias = learn(road, 10.0 * tangent, s_end)
    assert bias.along_observed
    assert float(tangent @ bias.offset) == pytest.approx(10.0, abs=1.5)
    assert np.sqrt(tangent @ bias.measured_cov @ tangent) < 3.0


def test_a_straight_approach_leaves_the_along_track_bias_at_its_prior() -> None:
    road = straight()
    bias = learn(road, np.array([10.0, 0.0]), 1500.0)
    assert not bias.along_observed
    assert np.allclose(bias.offset, 0.0)
    along_sigma = float(np.sqrt(bias.measured_cov[0, 0]))
    assert along_sigma > 0.9 * ON.offset.map_bias_prior_sigma_m


def test_an_unbiased_map_learns_no_bias() -> None:
    road = s_bend()
    s_end = float(road.project(np.array([1200.0, 0.0])).s[0])
    bias = learn(road, np.zeros(2), s_end)
    assert np.hypot(*bias.offset) < 1.0


def test_a_bias_too_large_for_a_map_is_refused_as_another_road_and_says_so() -> None:
    """A route 25 m to the side of the road driven (5 of the cross-track prior's sigmas): a
    significant fit, but a parallel road rather than a map's error. It is not applied, and
    the reason is kept (for the note), also when the next outage carries the finding; a
    right map is not refused, only not significant."""
    road = s_bend()
    s_end = float(road.project(np.array([1200.0, 0.0])).s[0])
    normal = road.normal_at(np.array([s_end]))[0]
    far = learn(road, 25.0 * normal, s_end)
    assert far.refused == "too large"
    assert not far.significant and np.allclose(far.offset, 0.0)
    assert far.chi2 > ON.offset.map_bias_min_sigmas**2  # refused, not insignificant
    assert unbiased(ON, lane=0.0, normal=normal, learned=far).refused == "too large"
    right = learn(road, np.zeros(2), s_end)
    assert right.refused is None and not right.significant


def test_a_track_on_another_road_teaches_nothing() -> None:
    road = s_bend()
    s_end = float(road.project(np.array([1200.0, 0.0])).s[0])
    other = Route(np.column_stack([road.xy[:, 0], -road.xy[:, 1]]))
    xy = track(other, s_end)
    bias = learn_map_bias(xy, GNSS_COV, road, s_guess=s_end, lane_offset=0.0, params=ON)
    assert np.allclose(bias.offset, 0.0)
    assert np.isnan(bias.measured).all()


def _shifted(route: Route, along: float, across: float) -> Route:
    d = route.xy[-1] - route.xy[0]
    u = d / np.hypot(*d)
    return Route(route.xy + along * u + across * np.array([-u[1], u[0]]))


@pytest.mark.parametrize("sample", ["multi_tunnel", "monaco_tunnel"])
def test_a_biased_map_no_longer_drags_the_estimate_off_the_road(sample: str) -> None:
    """The route moved 10 m along the road and 3.5 m across: without the bias the matches
    drag the estimate along the map, worse than dead reckoning; with it, better than both."""
    opened = open_inputs(SAMPLES / f"{sample}.mcap", SAMPLES / f"{sample}.route.geojson")
    assert opened.route is not None
    inputs = Inputs(opened.log, _shifted(opened.route, 10.0, 3.5), opened.frame)
    without_bias = with_values(Params(), {"extensions.map_bias": False})
    off = run_methods(inputs, without_bias, methods=("baseline", "proposed"))
    on = run_methods(inputs, ON, methods=("proposed",))

    def rmse(run) -> float:
        truth = method_metrics(run, inputs.route, inputs.log).truth
        assert truth is not None and truth.rmse_h_err_m is not None
        return truth.rmse_h_err_m

    base, without, with_bias = rmse(off["baseline"]), rmse(off["proposed"]), rmse(on["proposed"])
    assert without > base  # the failure the bias fixes
    assert with_bias < base
    assert with_bias < 0.5 * without
    used = [m.map_bias for m in on["proposed"].matches]
    assert all(u is not None for u in used)
    diagnostics = on["proposed"].matches[0].diagnostics()
    assert diagnostics["map_bias_along_m"] > 5.0
    assert diagnostics["map_bias_along_sigma_m"] > 0.0


def test_the_bias_is_learned_by_default() -> None:
    assert Params().extensions.map_bias


def test_the_paper_method_learns_no_bias() -> None:
    assert not for_method(ON, "paper").extensions.map_bias
