"""The considered z gyro scale factor kept out of every gain (``extensions.gyro_scale_blind_gain``):
the estimate is the one of the filter without the scale, the covariance that of its error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.evaluation.metrics import outage_errors
from estimator.filter import layout, updates
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.sim.stress import build, drive_spec
from tests.estimator.filter._turning import quiet_cfg

SS = (1500e-6) ** 2


def _covariance(seed: int) -> np.ndarray:
    """A random covariance whose every state correlates with the scale-factor error."""
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(layout.NE, layout.NE)) * 0.3
    P = L @ L.T + np.eye(layout.NE) * 0.1
    d = np.sqrt(np.diag(P))
    corr = P / np.outer(d, d)
    sig = np.full(layout.NE, 1.0)
    sig[layout.E_GSF] = math.sqrt(SS)
    out: np.ndarray = corr * np.outer(sig, sig)
    return out


def _position_update(
    x: np.ndarray, P: np.ndarray, y: np.ndarray, cfg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    H = np.zeros((3, layout.NE))
    H[0, layout.E_POS] = H[1, layout.E_POS + 1] = 1.0
    R = np.diag([0.5, 0.7, 1.0])
    PHt, S, Si = np.empty((layout.NE, 3)), np.empty((3, 3)), np.empty((3, 3))
    updates.innovation_cov(P, H, R, 2, PHt, S, Si)
    updates.apply_update(x, P, y, 2, PHt, Si, cfg)
    return H[:2], R[:2, :2]


def _nominal() -> np.ndarray:
    x = np.zeros(layout.NX)
    x[layout.X_QUAT] = 1.0
    x[layout.X_SCALE] = 1.0
    return x


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_gain_is_the_one_of_the_filter_without_the_scale(seed: int) -> None:
    P = _covariance(seed)
    c = P[:, layout.E_GSF].copy()
    P0 = P - np.outer(c, c) / SS  # the filter that does not know the scale
    P0_before = P0.copy()
    assert abs(P0[layout.E_GSF, layout.E_GSF]) < 1e-15
    y = np.array([1.3, -0.8, 0.0])
    x_blind, x_plain = _nominal(), _nominal()
    cfg = quiet_cfg()
    cfg[layout.C_GSF_BLIND] = 1.0
    H, R = _position_update(x_blind, P, y, cfg)
    _position_update(x_plain, P0, y, quiet_cfg())
    np.testing.assert_allclose(x_blind, x_plain, atol=1e-12)
    assert np.abs(x_plain[layout.X_POS : layout.X_POS + 2]).max() > 0.1

    # the scale's column goes through (I - K H) with that gain, its variance stays, and what
    # the scale does not explain is the plain filter's updated covariance
    pos = slice(layout.E_POS, layout.E_POS + 2)
    K = P0_before[:, pos] @ np.linalg.inv(P0_before[pos, pos] + R)
    K[layout.E_LANE :] = 0.0  # considered in a plain update
    expected_c = c - K @ (H @ c)
    expected_c[layout.E_GSF] = c[layout.E_GSF]
    np.testing.assert_allclose(P[:, layout.E_GSF], expected_c, atol=1e-12)
    assert P[layout.E_GSF, layout.E_GSF] == SS
    c1 = P[:, layout.E_GSF]
    np.testing.assert_allclose(P - np.outer(c1, c1) / SS, P0, atol=1e-10)


def test_the_covariance_is_that_of_the_error_made_with_that_gain() -> None:
    """Monte Carlo: errors drawn from P, updated with the gain the blind filter applies, have
    the covariance the blind update leaves (not the smaller one the optimal gain would)."""
    P = _covariance(4)
    rng = np.random.default_rng(5)
    n = 40000
    e = rng.multivariate_normal(np.zeros(layout.NE), P, size=n, method="eigh")
    R = np.diag([0.5, 0.7])
    v = rng.multivariate_normal(np.zeros(2), R, size=n)
    gains = np.empty((layout.NE, 2))
    for a in range(2):
        x = _nominal()
        y = np.zeros(3)
        y[a] = 1.0
        _position_update(x, P.copy(), y, _blind_cfg())
        gains[layout.E_POS : layout.E_POS + 3, a] = x[layout.X_POS : layout.X_POS + 3]
    z = e[:, layout.E_POS : layout.E_POS + 2] + v
    after = e[:, layout.E_POS : layout.E_POS + 3] - z @ gains[layout.E_POS : layout.E_POS + 3].T
    P_after = P.copy()
    _position_update(_nominal(), P_after, np.zeros(3), _blind_cfg())
    pos = slice(layout.E_POS, layout.E_POS + 3)
    np.testing.assert_allclose(np.cov(after.T), P_after[pos, pos], rtol=0.05, atol=0.01)
    optimal = P.copy()
    _position_update(_nominal(), optimal, np.zeros(3), quiet_cfg())
    assert np.trace(P_after[pos, pos]) > np.trace(optimal[pos, pos]) + 1e-3


def _blind_cfg() -> np.ndarray:
    cfg = quiet_cfg()
    cfg[layout.C_GSF_BLIND] = 1.0
    return cfg


def test_dead_reckoning_through_a_spiral_keeps_its_estimate_and_gets_an_honest_sigma() -> None:
    """Corpus drive 33 (spiral tunnel, the baseline's NEES 21.6 without the scale factor): the
    blind gain leaves the dead-reckoned error as it is, the sigma covers most of it (NEES
    21.6 -> 4.7 when written)."""
    inputs = build(drive_spec(33)).inputs
    log = inputs.log
    out = {}
    for label, values in (
        ("plain", {"extensions.gyro_scale_consider": False}),
        (
            "blind",
            {"extensions.gyro_scale_consider": True, "extensions.gyro_scale_blind_gain": True},
        ),
    ):
        run = run_methods(inputs, with_values(Params(), values), methods=("baseline",))["baseline"]
        err, nees = outage_errors(run, log, inputs.frame)
        out[label] = (float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), float(np.mean(nees)))
    (rmse0, nees0), (rmse1, nees1) = out["plain"], out["blind"]
    assert rmse1 == pytest.approx(rmse0, rel=0.02)
    assert nees0 > 10.0
    assert nees1 < 0.25 * nees0
