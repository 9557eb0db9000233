"""A gyro or accelerometer that reads exactly zero throughout (estimator.io.plausibility.
_imu_alive): a ROS driver that does not fill ``angular_velocity`` publishes zeros, and the run
then dead-reckoned every outage straight on (monaco: 952 m RMS) while its warnings spoke of few
fixes used and refused matches, never of the gyro. No accelerations at all is refused."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError
from estimator.io import load_log
from estimator.io.plausibility import checked
from estimator.log import Log

REPO = Path(__file__).resolve().parents[3]
MONACO = REPO / "sample_logs" / "monaco_tunnel.mcap"


@functools.cache
def _monaco() -> Log:
    return dataclasses.replace(load_log(MONACO), warnings=())


def _with(gyro_scale: tuple[float, float, float], accel_scale: float = 1.0) -> Log:
    log = _monaco()
    imu = dataclasses.replace(
        log.imu, gyro=log.imu.gyro * np.array(gyro_scale), accel=log.imu.accel * accel_scale
    )
    return dataclasses.replace(log, imu=imu)


def test_a_gyro_that_reads_zero_is_named() -> None:
    (line,) = checked(MONACO, _with((0.0, 0.0, 0.0))).warnings
    assert line.startswith(
        "monaco_tunnel.mcap: IMU /imu/data: every angular_velocity sample is zero"
    )
    assert "dead-reckoned straight on" in line


def test_one_dead_axis_is_named() -> None:
    (line,) = checked(MONACO, _with((1.0, 1.0, 0.0))).warnings
    assert "every sample of its gyro z axis is zero" in line


def test_no_accelerations_is_refused_in_one_line() -> None:
    with pytest.raises(LogError) as err:
        checked(MONACO, _with((1.0, 1.0, 1.0), accel_scale=0.0))
    message = str(err.value)
    assert "\n" not in message and message.startswith(str(MONACO))
    assert "every linear_acceleration sample is zero" in message


def test_a_live_imu_says_nothing() -> None:
    assert not checked(MONACO, _monaco()).warnings
