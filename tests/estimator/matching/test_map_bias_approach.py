"""A longer map-bias approach (``offset.map_bias_track_m``) without a right map's noise taken
for a rotation: the GNSS wander along the approach (``offset.map_bias_wander_rows``) and the
rotation considered for a fit not applied (``offset.map_turn_lower_sigmas``)."""

from __future__ import annotations

import math

import numpy as np

from estimator.matching import map_bias as mb
from estimator.params import Params, with_values
from estimator.route import Route
from estimator.sim.sensors import gauss_markov
from tests._session11_fit import MOMENTS_PRIOR

LANE = -1.75
SPEED = 16.0
WANDER_M = 0.8
"""the simulated receiver's wander (estimator/sim/sensors.py), 60 s as the filter assumes"""


def bend() -> Route:
    """1800 m east, a quarter circle of radius 300 m to the left, then north."""
    a = np.radians(np.arange(0.0, 90.1, 2.0))
    arc = np.column_stack([300.0 * np.sin(a), 300.0 * (1.0 - np.cos(a))])
    return Route(np.vstack([[[-1800.0, 0.0]], arc, [[300.0, 1500.0]]]))


def approach(seed: int, length: float) -> tuple[np.ndarray, np.ndarray, Route, float]:
    """``length`` m of GNSS-good driving up to 100 m past the bend, at ``SPEED``, its estimate
    off by a Gauss-Markov wander; the points, their times, the road and the end's arc length."""
    road = bend()
    s_end = float(road.project(np.array([300.0, 400.0])).s[0])
    t = np.arange(0.0, length / SPEED + 1e-9, 1.0)
    s = s_end - length + SPEED * t
    err = gauss_markov(np.random.default_rng(seed), len(t), 1.0, WANDER_M, 60.0, dims=2)
    return road.point_at(s) + LANE * road.normal_at(s) + err, t, road, s_end


def rotation_z(params: Params, seed: int, *, length: float = 1600.0, times: bool) -> float:
    """The rotation fitted on a right map against its sigma (the fit's and the shared error's)."""
    xy, t, road, s_end = approach(seed, length)
    cov = np.eye(2) * WANDER_M**2
    rows = mb._turned_rows(xy, road, s_end, None, cov, params, t if times else None)
    assert rows is not None
    op = params.offset
    P0 = np.zeros((4, 4))
    P0[0, 0] = op.map_bias_lane_sigma_m**2
    P0[1:3, 1:3] = mb._prior_cov(params, road.normal_at(np.array([s_end]))[0])
    P0[3, 3] = math.radians(op.map_bias_rotation_sigma_deg) ** 2
    mean = np.array([op.map_bias_lane_prior_m, 0.0, 0.0, 0.0])
    fit = mb._fit_with_shape(*rows, P0, mean, xy, cov, road, s_end, params)
    assert fit is not None
    u, C, G, _ = fit
    total = C + G @ cov @ G.T
    return float(u[3] / math.sqrt(total[3, 3]))


def test_the_wander_weighs_the_far_approach_less_and_shares_less_of_the_end_error() -> None:
    params = with_values(Params(), {"offset.map_bias_wander_rows": True})
    xy, t, road, s_end = approach(0, 1600.0)
    cov = np.eye(2) * WANDER_M**2
    plain = mb._lateral_rows(xy, road, s_end, None, cov, params)
    wander = mb._lateral_rows(xy, road, s_end, None, cov, params, t)
    assert plain is not None and wander is not None
    assert plain.weights.ndim == 1 and np.all(plain.common == 1.0)
    assert wander.weights.shape == (len(wander.d), len(wander.d))
    # the end shares all of its own error, the start, 100 s back, exp(-100 / 60) of it
    assert wander.common[-1] == 1.0
    assert 0.15 < wander.common[0] < 0.22
    # the far points' own variance beyond the shared error makes them weigh less
    var = np.diag(np.linalg.inv(wander.weights))
    assert var[0] > var[-1] + 0.5 * WANDER_M**2


def test_a_right_map_s_fitted_rotation_sits_within_its_sigma_on_a_long_approach() -> None:
    # the receiver's wander the filter models, on a right map: were the rotation's sigma too
    # small for it, z^2 would average well over one
    for on in (False, True):
        params = with_values(Params(), {"offset.map_bias_wander_rows": on})
        z = np.array([rotation_z(params, seed, times=True) for seed in range(40)])
        assert float(np.mean(z**2)) < 1.2, on


def test_a_rotation_within_its_noise_is_not_considered_beyond_the_lower_bound() -> None:
    sigma = math.radians(0.06)
    moments = with_values(Params(), {"offset.map_turn_lower_sigmas": 0.0})
    lower = with_values(Params(), {"offset.map_turn_lower_sigmas": 2.0})
    # a 1.3-sigma draw on a right map: the method of moments considers a rotation, the
    # 2-sigma lower bound none
    draw = 1.3 * sigma
    assert mb._unapplied_turn_var(draw, sigma**2, moments) > (0.5 * sigma) ** 2
    assert mb._unapplied_turn_var(-draw, sigma**2, lower) == 0.0
    # a draw just short of the significance test keeps what lies beyond two sigmas
    near = -2.9 * sigma
    assert math.isclose(mb._unapplied_turn_var(near, sigma**2, lower), (0.9 * sigma) ** 2)


def test_the_learned_bias_of_a_right_map_considers_no_rotation_within_two_sigmas() -> None:
    base = {"extensions.map_bias": True, "offset.map_bias_track_m": 1600.0, **MOMENTS_PRIOR}
    moments = with_values(Params(), {**base, "offset.map_turn_lower_sigmas": 0.0})
    lower = with_values(Params(), {**base, "offset.map_turn_lower_sigmas": 2.0})
    considered = {"moments": 0, "lower": 0}
    for seed in range(30):
        xy, t, road, s_end = approach(seed, 1600.0)
        turn_var = {}
        for label, params in (("moments", moments), ("lower", lower)):
            turn_var[label] = mb.learn_map_bias(
                xy,
                np.eye(2) * WANDER_M**2,
                road,
                s_guess=s_end,
                lane_offset=LANE,
                params=params,
                track_t=t,
            ).turn_var
            considered[label] += turn_var[label] > 0.0
        assert turn_var["lower"] <= turn_var["moments"]
    # the right map's draws beyond one sigma turn it for the method of moments only
    assert considered["moments"] >= 2
    assert considered["lower"] == 0
