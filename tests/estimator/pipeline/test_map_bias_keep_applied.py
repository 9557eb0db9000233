"""``extensions.map_bias_keep_applied`` (issue 17): a map bias applied in one outage is carried
to the next unless the bias learned afresh from the driving in between is significant itself,
so the applied-or-not decision does not flip on a small change of that short stretch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.matching.map_bias import MapBias
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.pipeline.driver import keeps_carried
from estimator.sim.stress import build, drive_spec
from tests._session11_fit import SESSION_11_FIT
from tests.estimator._map_biases import applied_per_outage, map_bias

GSF = "extensions.gyro_scale_state"
KEEP = "extensions.map_bias_keep_applied"
TURN_PRIOR = "offset.map_bias_turn_prior"


def _bias(offset: tuple[float, float], *, chi2: float) -> MapBias:
    return map_bias(offset, measured=np.array([4.0, -3.0]), measured_cov=np.eye(2) * 9.0, chi2=chi2)


def test_an_applied_bias_is_kept_against_an_insignificant_fresh_one() -> None:
    applied = _bias((-8.0, -9.0), chi2=30.0)
    assert keeps_carried(applied, _bias((0.0, 0.0), chi2=2.3))


def test_a_significant_fresh_bias_or_another_road_replaces_it() -> None:
    applied = _bias((-8.0, -9.0), chi2=30.0)
    assert not keeps_carried(applied, _bias((4.0, -3.0), chi2=20.0))
    refused = dataclasses.replace(_bias((0.0, 0.0), chi2=40.0), refused="too large")
    assert not keeps_carried(applied, refused)


def test_an_unapplied_bias_is_not_kept() -> None:
    assert not keeps_carried(_bias((0.0, 0.0), chi2=2.0), _bias((0.0, 0.0), chi2=2.3))


def _outages(values: dict[str, object]) -> tuple[list[bool], float]:
    """Per outage of corpus drive 2, whether its map bias was applied; and the truth RMSE."""
    inputs = build(drive_spec(2)).inputs
    run = run_methods(inputs, with_values(Params(), values), methods=("proposed",))["proposed"]
    applied = applied_per_outage(run)
    truth = method_metrics(run, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return applied, truth.rmse_h_err_m


@pytest.mark.slow
def test_drive_2_keeps_its_bias_through_the_short_stretches() -> None:
    """Corpus drive 2 (multi tunnel, no odometer, the map 8.9 m off along the road and turned
    0.44 deg), with the gyro's scale factor estimated: the 23 s of GNSS between the first and
    second tunnel learn a bias of their own that no test tells from zero, which replaced the
    bias the first approach established (chi-square 50); the last two tunnels then ran on the
    map as drawn, and the last one refused every match. Kept and refined, the bias is applied
    in every tunnel and the run is no worse than dead reckoning. With ``offset.map_bias_turn_prior``
    on (the default) the first outage ends elsewhere and the stretch's own bias is significant,
    so both runs apply one in every tunnel (6.38 m); the case is kept with it off, and with
    session 11's approach (800 m)."""
    kept, rmse = _outages({**SESSION_11_FIT, GSF: True, KEEP: True, TURN_PRIOR: False})
    assert kept == [True, True, True]
    replaced, replaced_rmse = _outages(
        {**SESSION_11_FIT, GSF: True, KEEP: False, TURN_PRIOR: False}
    )
    assert replaced[0] and not replaced[1]
    inputs = build(drive_spec(2)).inputs
    base = run_methods(inputs, with_values(Params(), {GSF: True}), methods=("baseline",))
    truth = method_metrics(base["baseline"], inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    assert rmse <= truth.rmse_h_err_m + 0.2 < replaced_rmse
