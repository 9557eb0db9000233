"""Quaternions are scalar-first (w, x, y, z) in routefuse; a ROS message's (x, y, z, w) is
reordered by :func:`quaternion_from_ros` where it is read."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.nav import (
    dcm_from_euler,
    dcm_from_quaternion,
    quaternion_from_ros,
    yaw_from_quaternion,
)


def test_ros_order_is_reordered_scalar_first() -> None:
    assert quaternion_from_ros(0.1, 0.2, 0.3, 0.9) == (0.9, 0.1, 0.2, 0.3)


@pytest.mark.parametrize("yaw", [0.0, 0.3, -2.0, math.pi])
def test_a_yaw_quaternion_is_the_euler_rotation(yaw: float) -> None:
    w, z = math.cos(yaw / 2), math.sin(yaw / 2)
    c = dcm_from_quaternion(w, 0.0, 0.0, z)
    assert c is not None
    np.testing.assert_allclose(c, dcm_from_euler(0.0, 0.0, yaw)[0], atol=1e-15)
    got = yaw_from_quaternion(np.array([w]), np.zeros(1), np.zeros(1), np.array([z]))
    assert math.isclose(math.remainder(float(got[0]) - yaw, math.tau), 0.0, abs_tol=1e-12)


def test_unnormalised_quaternions_are_normalised_and_empty_ones_refused() -> None:
    c = dcm_from_quaternion(2.0, 0.0, 0.0, 0.0)
    assert c is not None
    np.testing.assert_array_equal(c, np.eye(3))
    assert dcm_from_quaternion(0.0, 0.0, 0.0, 0.0) is None
    assert dcm_from_quaternion(math.nan, 0.0, 0.0, 1.0) is None
    assert dcm_from_quaternion(math.inf, 0.0, 0.0, 1.0) is None
