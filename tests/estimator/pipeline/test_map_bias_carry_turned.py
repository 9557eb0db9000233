"""``extensions.map_bias_carry_turned`` (issue 17): a map bias applied in one outage is carried
to the next when the bias learned afresh there is refused as too large for a map's error but
is what the carried bias, turned by its rotation over the kilometres between, predicts."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.matching.map_bias import MapBias, carried_explains
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.sim.stress import build, drive_spec
from tests.estimator._map_biases import applied_per_outage, map_bias

CARRY = "extensions.map_bias_carry_turned"
TURN = math.radians(-1.2)
"""the carried map's rotation: 2 km east of its pivot it lies 42 m further south"""


def _carried() -> MapBias:
    cov = np.zeros((3, 3))
    cov[1:, 1:] = np.eye(2) * 4.0
    return map_bias((0.0, 17.0), rotation=TURN, cov=cov)


def _fresh(measured: tuple[float, float], refused: str | None = "too large") -> MapBias:
    return map_bias(
        (0.0, 0.0),
        pivot=np.array([2000.0, 0.0]),
        measured=np.array(measured),
        measured_cov=np.eye(2) * 4.0,
        chi2=100.0,
        refused=refused,
    )


def test_a_refused_bias_the_carried_rotation_predicts_is_explained() -> None:
    predicted = (0.0, 17.0 + TURN * 2000.0)  # -24.9 m: too large for the generic prior
    assert carried_explains(_carried(), _fresh(predicted), Params())
    near = (predicted[0] + 5.0, predicted[1] - 5.0)  # chi-square 6.25 of the two covariances
    assert carried_explains(_carried(), _fresh(near), Params())


def test_a_bias_the_carried_one_does_not_predict_stands_refused() -> None:
    # a parallel road 25 m off on the other side, or the carried shift not turned
    assert not carried_explains(_carried(), _fresh((0.0, 25.0)), Params())
    assert not carried_explains(_carried(), _fresh((0.0, 17.0)), Params())
    strict = with_values(Params(), {"offset.map_bias_max_prior_sigmas": 1.0})
    predicted = (0.0, 17.0 + TURN * 2000.0)
    assert not carried_explains(_carried(), _fresh((predicted[0] + 5.0, predicted[1])), strict)


def test_only_a_refusal_as_too_large_after_an_applied_bias_is_weighed() -> None:
    predicted = (0.0, 17.0 + TURN * 2000.0)
    assert not carried_explains(_carried(), _fresh(predicted, refused=None), Params())
    assert not carried_explains(_carried(), _fresh(predicted, refused="lane too far"), Params())
    unapplied = dataclasses.replace(_carried(), offset=np.zeros(2), rotation=0.0)
    assert not carried_explains(unapplied, _fresh(predicted), Params())
    unmeasured = dataclasses.replace(_fresh(predicted), measured=np.full(2, np.nan))
    assert not carried_explains(_carried(), unmeasured, Params())


def _run(values: dict[str, object]) -> tuple[list[bool], int, float, tuple[str, ...]]:
    """Held-out corpus 3, drive 30: per outage whether its map bias was applied, the matches
    accepted, the truth RMSE and the warnings."""
    inputs = build(drive_spec(30, corpus=3)).inputs
    run = run_methods(inputs, with_values(Params(), values), methods=("proposed",))["proposed"]
    applied = applied_per_outage(run)
    truth = method_metrics(run, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return applied, sum(m.accepted for m in run.matches), truth.rmse_h_err_m, run.warnings


@pytest.mark.slow
def test_a_map_turned_a_degree_is_followed_through_three_tunnels() -> None:
    """Held-out corpus 3, drive 30 (multi tunnel, the map turned -1.25 deg about its middle):
    the first approach learns the turn (-1.22 deg) and applies it; the stretches before the
    second and third tunnels see the map 20 and 19 m off, which the generic prior calls another
    road, so those tunnels ran on the map as drawn and refused every match, 64 m from the
    vehicle at the third. Carried, the learned map is applied in all three and the run is
    within dead reckoning's + 0.2 m."""
    carried, accepted, rmse, warnings = _run({CARRY: True})
    refused, refused_accepted, refused_rmse, refused_warnings = _run({CARRY: False})
    assert carried == [True, True, True] and refused == [True, False, False]
    assert accepted > refused_accepted
    assert any(w.startswith("the route is ") for w in refused_warnings)
    assert not any(w.startswith("the route is ") for w in warnings)
    inputs = build(drive_spec(30, corpus=3)).inputs
    base = run_methods(inputs, Params(), methods=("baseline",))["baseline"]
    truth = method_metrics(base, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    assert rmse <= truth.rmse_h_err_m + 0.2 < refused_rmse
