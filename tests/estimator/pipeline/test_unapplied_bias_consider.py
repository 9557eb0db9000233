"""``extensions.unapplied_bias_consider`` (issue 17, item 2): a map bias seen before an outage
but not applied stays in the pseudo-positions' covariance, so the filter's covariance covers
the real error and a map drawn turned does not make the run worse than dead reckoning."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator.evaluation.metrics import outage_errors
from estimator.matching.map_bias import MapBias
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.pipeline.driver import unapplied_considered
from estimator.sim.stress import build, drive_spec
from tests._session11_fit import SESSION_11_FIT
from tests.estimator._map_biases import map_bias

CHI2_2DOF_95 = 5.991


def _bias(offset: tuple[float, float], measured: tuple[float, float]) -> MapBias:
    return map_bias(offset, cov=np.diag([0.1, 0.0, 0.0]), measured=np.array(measured), chi2=6.0)


def test_an_unapplied_bias_is_carried_as_map_error() -> None:
    out = unapplied_considered(_bias((0.0, 0.0), (3.0, -4.0)))
    # m m^T less the measurement's own covariance (I): 25 - 1 along m, nothing across it
    np.testing.assert_allclose(out.cov[1:, 1:], 24.0 / 25.0 * np.outer([3.0, -4.0], [3.0, -4.0]))
    assert out.cov[0, 0] == pytest.approx(0.1)
    np.testing.assert_array_equal(out.offset, [0.0, 0.0])


def test_a_bias_within_its_own_noise_adds_nothing() -> None:
    out = unapplied_considered(_bias((0.0, 0.0), (0.6, -0.8)))
    np.testing.assert_allclose(out.cov[1:, 1:], np.zeros((2, 2)), atol=1e-12)


def test_an_applied_or_unlearned_bias_is_left_alone() -> None:
    applied = _bias((3.0, -4.0), (3.0, -4.0))
    assert unapplied_considered(applied) is applied
    unlearned = _bias((0.0, 0.0), (np.nan, np.nan))
    assert unapplied_considered(unlearned) is unlearned


def _truth_figures(index: int, method: str, values: dict[str, object]) -> tuple[float, float]:
    """(truth RMSE, mean horizontal NEES) over the GNSS outages of corpus drive ``index``."""
    inputs = build(drive_spec(index)).inputs
    log, frame = inputs.log, inputs.frame
    assert log.truth is not None
    run = run_methods(inputs, with_values(Params(), values), methods=(method,))[method]  # type: ignore[arg-type]
    err, nees = outage_errors(run, log, frame)
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), float(nees.mean())


def test_a_map_turned_in_a_long_tunnel_is_no_worse_than_dead_reckoning() -> None:
    """Corpus drive 0: the long tunnel, the map turned 0.27 deg, gyro bias 527 deg/h. The
    bias seen on the approach (15 m) is not applied; taken as an exact map, matches 12 m off
    the road were accepted and set the heading to the map's (NEES 35, 22 m against the
    baseline's 9 m). Carried as map error, the run is no worse than dead reckoning and its
    NEES honest. (Since ``offset.map_bias_turned_rescue`` is on the bias is applied with its
    rotation; the test takes it off to keep the bias unapplied, and checks the default too.
    With session 11's approach, 800 m: the 1600 m one fits the rotation well enough for the
    matches not to pull away without the consideration.)"""
    key = "extensions.unapplied_bias_consider"
    unapplied = {**SESSION_11_FIT, "offset.map_bias_turned_rescue": False}
    base_rmse, _ = _truth_figures(0, "baseline", {})
    rmse, nees = _truth_figures(0, "proposed", {**unapplied, key: True})
    assert rmse <= base_rmse + 0.2
    assert nees <= CHI2_2DOF_95
    off_rmse, _ = _truth_figures(0, "proposed", {**unapplied, key: False})
    assert off_rmse > base_rmse + 0.2
    # the turn the approach showed, considered alone (extensions.map_turn_consider), keeps the
    # NEES honest but not the error; without either the NEES blows up too
    _, neither_nees = _truth_figures(
        0, "proposed", {**unapplied, key: False, "extensions.map_turn_consider": False}
    )
    assert neither_nees > CHI2_2DOF_95
    # applied with the rotation that explains it (the default), it beats dead reckoning
    rescued, rescued_nees = _truth_figures(0, "proposed", {})
    assert rescued < base_rmse - 1.0
    assert rescued_nees <= CHI2_2DOF_95


def test_a_tied_lane_cancels_the_map_shift_across_the_portal_alone() -> None:
    """``extensions.unapplied_bias_lane_tie``: the lane kept with a bias not applied is the
    offset seen near the portal, lane and map together, so the pseudo-position's error
    ``d_map - n d_lane`` has no variance across the portal's normal and grows across a normal
    the road has turned to."""
    normal = np.array([0.0, 1.0])
    gain = np.zeros((3, 2))
    gain[0] = normal
    bias = map_bias(
        (0.0, 0.0), cov=np.diag([0.1, 0.0, 0.0]), gain=gain, measured=np.array([3.0, -4.0])
    )
    untied = unapplied_considered(bias)
    tied = unapplied_considered(bias, tied=True)
    assert tied.tied and not untied.tied
    np.testing.assert_allclose(tied.cov[1:, 1:], untied.cov[1:, 1:])

    def across(b: MapBias, n: np.ndarray) -> float:
        h = np.concatenate([[-n @ n], n])  # n . (d_map - n d_lane)
        return float(h @ b.cov @ h)

    seen = untied.cov[1:, 1:]
    assert across(tied, normal) == pytest.approx(0.1)  # only the lane's own error
    assert across(untied, normal) == pytest.approx(0.1 + normal @ seen @ normal)
    turned = np.array([1.0, 0.0])  # the road turned a quarter: the map's shift the lane held
    # (turned - normal) . d_map: the shift's change across between the two normals
    assert across(tied, turned) == pytest.approx(0.1 + seen[0, 0] + seen[1, 1] - 2 * seen[0, 1])
    assert np.all(np.linalg.eigvalsh(tied.cov) >= -1e-9)
    refused = unapplied_considered(dataclasses.replace(bias, refused="too large"), tied=True)
    assert not refused.tied


def test_a_shift_held_as_a_lane_through_a_spiral_is_no_longer_followed() -> None:
    """Corpus drive 5: the spiral tunnel, its map 4.7 m along and 5.0 m across the road, a
    shift the approach tests as insignificant (chi-square 6.6). Untied, the lane seen at the
    portal (+4.3 m) is held through the spiral, where the map's shift turns across the road:
    the matches pull away and are undone (dead reckoning's 7.6 m). Tied, the pseudo-positions
    say how far the turned road leaves them off, and the run beats dead reckoning. With session
    11's approach (800 m; the 1600 m one's matches do not pull away untied), and with the
    defaults."""
    base_rmse, _ = _truth_figures(5, "baseline", {})
    key = "extensions.unapplied_bias_lane_tie"
    tied, nees = _truth_figures(5, "proposed", {**SESSION_11_FIT, key: True})
    untied, _ = _truth_figures(5, "proposed", {**SESSION_11_FIT, key: False})
    assert tied < 0.75 * base_rmse
    assert untied > base_rmse - 0.2
    assert nees <= CHI2_2DOF_95
    defaults, defaults_nees = _truth_figures(5, "proposed", {})
    assert defaults < 0.75 * base_rmse and defaults_nees <= CHI2_2DOF_95
