"""``noise.nhc_mount_sigma_deg``: the non-holonomic constraint's variance grows with the speed
as (speed x angle)^2, the body velocity an IMU turned by that unknown angle from the vehicle's
axes sees where the constraint says zero. At 0 (the default) the update is the one before."""

from __future__ import annotations

import math

import numpy as np

from estimator.filter import layout
from estimator.filter.quaternion import euler_to_quat
from estimator.filter.setup import kernel_config
from estimator.filter.updates import body_velocity_update
from estimator.nav.frames import LocalFrame
from estimator.params import Params, with_values


def _state(speed: float) -> tuple[np.ndarray, np.ndarray]:
    x = np.zeros(layout.NX)
    x[layout.X_QUAT : layout.X_QUAT + 4] = euler_to_quat(0.01, -0.06, 0.7)
    # a velocity off the body axes: the constraint has something to correct
    x[layout.X_VEL : layout.X_VEL + 3] = speed * np.array([math.cos(0.72), math.sin(0.72), 0.02])
    x[layout.X_SCALE] = 1.0
    rng = np.random.default_rng(3)
    a = rng.standard_normal((layout.NE, layout.NE)) * 0.05
    P = a @ a.T + 0.01 * np.eye(layout.NE)
    P[layout.E_LANE :, :] = 0.0
    P[:, layout.E_LANE :] = 0.0
    return x, P


def _nhc(x: np.ndarray, P: np.ndarray, nhc_var: float, tilt2: float):
    x, P = x.copy(), P.copy()
    cfg = np.zeros(layout.NC)
    cfg[layout.C_NHC_VAR] = nhc_var
    cfg[layout.C_NHC_TILT2] = tilt2
    C, H, y, R = np.empty((3, 3)), np.zeros((3, layout.NE)), np.zeros(3), np.zeros((3, 3))
    PHt, S, Si = np.zeros((layout.NE, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    body_velocity_update(x, P, cfg, 0.0, False, C, H, y, R, PHt, S, Si)
    return x, P


def test_the_constraint_is_widened_by_the_speed_times_the_mount_angle():
    """R = sigma^2 + |v|^2 sigma_mount^2: the same update as a fixed sigma of that size."""
    speed, sigma, mount = 25.0, 0.1, math.radians(2.0)
    x, P = _state(speed)
    widened = _nhc(x, P, sigma**2, mount**2)
    v2 = float(np.sum(x[layout.X_VEL : layout.X_VEL + 3] ** 2))
    fixed = _nhc(x, P, sigma**2 + v2 * mount**2, 0.0)
    np.testing.assert_allclose(widened[0], fixed[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(widened[1], fixed[1], rtol=0, atol=1e-12)
    tight = _nhc(x, P, sigma**2, 0.0)
    # the constraint trusted less: the attitude keeps more of its variance
    att = slice(layout.E_ATT, layout.E_ATT + 3)
    assert np.trace(widened[1][att, att]) > np.trace(tight[1][att, att])
    # standing still there is no speed to turn: the term vanishes
    x0, P0 = _state(0.0)
    np.testing.assert_array_equal(
        _nhc(x0, P0, sigma**2, mount**2)[1], _nhc(x0, P0, sigma**2, 0.0)[1]
    )


def test_off_by_default_and_the_update_is_the_old_one_bit_for_bit():
    frame = LocalFrame(37.0, -122.0, 0.0)
    cfg = kernel_config(Params(), frame, np.zeros(0))
    assert cfg[layout.C_NHC_TILT2] == 0.0
    on = kernel_config(
        with_values(Params(), {"noise.nhc_mount_sigma_deg": 2.0}), frame, np.zeros(0)
    )
    assert on[layout.C_NHC_TILT2] == math.radians(2.0) ** 2
    x, P = _state(30.0)
    a = _nhc(x, P, 0.01, 0.0)
    b = _nhc(x, P, 0.01, cfg[layout.C_NHC_TILT2])
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
