"""Logs with the IMU cut out for a while (an IMU gap), for the tests of what bridges it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from estimator.pipeline.inputs import Inputs

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def without_imu(inputs: Inputs, a: float, b: float) -> Inputs:
    """``inputs`` with no IMU sample from ``a`` to ``b`` s after the log start."""
    imu, t0 = inputs.log.imu, inputs.log.t_start
    keep = ~((imu.t >= t0 + a) & (imu.t < t0 + b))
    cut = dataclasses.replace(imu, t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep])
    return dataclasses.replace(inputs, log=dataclasses.replace(inputs.log, imu=cut))
