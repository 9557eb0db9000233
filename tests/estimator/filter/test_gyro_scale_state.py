"""The z gyro's scale factor as an estimated state (``extensions.gyro_scale_state``): turns seen
by GNSS calibrate it, and the mechanisation applies it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from estimator.filter import layout, updates
from estimator.filter.engine import Filter
from estimator.filter.setup import prepare_inputs
from estimator.params import Params, with_values
from estimator.sim import simulate
from estimator.sim.scenarios import long_drive
from tests.estimator.filter._turning import quiet_cfg, turned

PRIOR = 1500e-6


def _final_state(seed: int, values: dict[str, bool]) -> tuple[float, float, float]:
    """(true z scale error, estimate, its sigma) after 300 s of a random road with a large
    scale error drawn (3000 ppm, twice the filter's prior)."""
    sc = long_drive(10.0)
    sc = replace(sc, imu=replace(sc.imu, gyro_scale_ppm=3000.0))
    sim = simulate(sc, seed=seed, duration_s=300.0)
    log = sim.log()
    p = with_values(Params(), values)
    inp = prepare_inputs(log, p, sim.frame, ())
    f = Filter(inp, source=log.path, t_start=log.t_start)
    f.alloc(4000)
    f.write_row()
    f.aux[layout.A_NEXT_OUT] = f.aux[layout.A_TIME] + inp.cfg[layout.C_OUT_DT]
    f.advance(math.inf)
    sigma = math.sqrt(max(f.P[layout.E_GSF, layout.E_GSF], 0.0))
    return float(sim.imu_errors.gyro_scale[2]), float(f.x[layout.X_GSF]), sigma


@pytest.mark.parametrize("seed", [1, 2])
def test_turns_under_gnss_calibrate_the_scale_factor(seed: int) -> None:
    true, est, sigma = _final_state(seed, {"extensions.gyro_scale_state": True})
    assert abs(true) > 1.5 * PRIOR, "the drawn error is large enough to tell calibration from prior"
    assert sigma < 0.5 * PRIOR
    assert abs(est - true) < 3 * sigma
    assert abs(est - true) < 0.5 * abs(true)


def test_considered_the_scale_factor_is_never_estimated() -> None:
    _, est, sigma = _final_state(1, {"extensions.gyro_scale_consider": True})
    assert est == 0.0
    assert sigma == pytest.approx(PRIOR)


def test_a_heading_update_after_a_turn_corrects_the_scale_factor() -> None:
    """The yaw error a turn left correlates with the scale error: with C_GSF_EST the update
    gives the scale factor a gain, shrinks its variance and moves the nominal state."""
    cfg = quiet_cfg()
    cfg[layout.C_GSF_EST] = 1.0
    P = np.zeros((layout.NE, layout.NE))
    P[layout.E_GSF, layout.E_GSF] = PRIOR**2
    P[layout.E_ATT + 2, layout.E_ATT + 2] = 1e-8
    aux = turned(P, 2 * math.pi, cfg=cfg)
    before = P[layout.E_GSF, layout.E_GSF]
    x = np.zeros(layout.NX)
    x[layout.X_QUAT] = 1.0
    x[layout.X_SCALE] = 1.0
    dyaw = -2 * math.pi * 1e-3  # the heading a 1000 ppm scale error leaves after one turn
    updates.heading_update(x, P, aux, cfg, dyaw, 1e-8)
    assert P[layout.E_GSF, layout.E_GSF] < 0.2 * before
    assert x[layout.X_GSF] == pytest.approx(1e-3, rel=0.2)
