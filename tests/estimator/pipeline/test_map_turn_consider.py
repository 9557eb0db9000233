"""``extensions.map_turn_consider`` (issue 17, item 2): the map's rotation error is carried as
one considered quantity shared by an outage's matches, so a map turned a little, whose error
grows along a long tunnel while the filter follows it, stays inside the filter's covariance."""

from __future__ import annotations

import numpy as np

from estimator.evaluation.metrics import outage_errors
from estimator.filter.layout import A_MAP_AT, E_MAP, E_ROT, NA, NE, X_POS
from estimator.filter.updates import clone_map_turn, turn_map_bias
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.sim.stress import build, drive_spec
from tests._session11_fit import SESSION_11_FIT

CHI2_2DOF_95 = 5.991


def test_turning_the_map_error_is_t_p_t_transposed() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(NE, NE))
    P = a @ a.T
    aux = np.zeros(NA)
    x = np.zeros(20)
    x[X_POS : X_POS + 2] = [100.0, -50.0]
    clone_map_turn(P, aux, x, 1e-6, False)
    assert P[E_ROT, E_ROT] == 1e-6 and not np.any(P[E_ROT, :E_ROT])
    want = P.copy()
    x[X_POS : X_POS + 2] = [400.0, 350.0]
    turn_map_bias(P, aux, x)
    T = np.eye(NE)
    T[E_MAP, E_ROT], T[E_MAP + 1, E_ROT] = -400.0, 300.0  # J d, d = (300, 400)
    np.testing.assert_allclose(P, T @ want @ T.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(aux[A_MAP_AT : A_MAP_AT + 2], [400.0, 350.0])
    # the map error 500 m on: 500 m times the rotation's sigma more, on top of its own
    assert P[E_MAP + 1, E_MAP + 1] > want[E_MAP + 1, E_MAP + 1]


def _truth_figures(index: int, values: dict[str, object]) -> tuple[float, float]:
    """(truth RMSE, mean horizontal NEES) of the proposed run over the GNSS outages of corpus
    drive ``index``."""
    inputs = build(drive_spec(index)).inputs
    log, frame = inputs.log, inputs.frame
    assert log.truth is not None
    run = run_methods(inputs, with_values(Params(), values), methods=("proposed",))["proposed"]
    err, nees = outage_errors(run, log, frame)
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), float(nees.mean())


def test_a_map_turned_along_a_long_tunnel_stays_in_the_covariance() -> None:
    """Corpus drive 4: the long tunnel, the map shifted 9.8 m and turned 0.17 deg, which the
    straight approach does not tell from zero. With the random-walk growth alone every match
    was accepted while the cross-track error grew along the tunnel far beyond its sigma. With
    session 11's approach (800 m): the 1600 m one applies the bias with its rotation."""
    key = "extensions.map_turn_consider"
    rmse, nees = _truth_figures(4, {**SESSION_11_FIT, key: True})
    off_rmse, off_nees = _truth_figures(4, {**SESSION_11_FIT, key: False})
    assert nees <= CHI2_2DOF_95 < off_nees
    assert rmse < off_rmse
