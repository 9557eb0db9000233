"""The z gyro's scale-factor error as a considered state (``extensions.gyro_scale_consider``):
the heading error it makes grows with the angle turned, and no update estimates it."""

from __future__ import annotations

import math

import numpy as np

from estimator.filter import layout, updates
from tests.estimator.filter._turning import quiet_cfg, turned


def test_the_heading_variance_grows_with_the_square_of_the_angleturned() -> None:
    sigma = 1500e-6
    for turns in (1.0, 3.0):
        P = np.zeros((layout.NE, layout.NE))
        P[layout.E_GSF, layout.E_GSF] = sigma**2
        angle = 2 * math.pi * turns
        turned(P, angle)
        yaw = layout.E_ATT + 2
        np.testing.assert_allclose(P[yaw, yaw], (sigma * angle) ** 2, rtol=1e-2)
        np.testing.assert_allclose(P[yaw, layout.E_GSF], -(sigma**2) * angle, rtol=1e-2)


def test_without_the_state_a_turn_adds_no_heading_variance() -> None:
    P = np.zeros((layout.NE, layout.NE))
    turned(P, 2 * math.pi)
    assert P[layout.E_ATT + 2, layout.E_ATT + 2] == 0.0


def test_a_heading_update_reduces_the_heading_variance_but_leaves_the_scale_error() -> None:
    """Schmidt: the scale-factor error's gain is zero, its variance stays, its covariance with
    the heading shrinks as the heading's does."""
    P = np.zeros((layout.NE, layout.NE))
    P[layout.E_GSF, layout.E_GSF] = (1500e-6) ** 2
    P[layout.E_ATT + 2, layout.E_ATT + 2] = 1e-6
    turned(P, 2 * math.pi)
    before = P.copy()
    x = np.zeros(layout.NX)
    x[layout.X_QUAT] = 1.0
    x[layout.X_SCALE] = 1.0
    updates.heading_update(x, P, np.zeros(layout.NA), quiet_cfg(), 0.01, 1e-8)
    yaw = layout.E_ATT + 2
    assert P[yaw, yaw] < 0.1 * before[yaw, yaw]
    assert P[layout.E_GSF, layout.E_GSF] == before[layout.E_GSF, layout.E_GSF]
    assert abs(P[yaw, layout.E_GSF]) < 0.1 * abs(before[yaw, layout.E_GSF])
