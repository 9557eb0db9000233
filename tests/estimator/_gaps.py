"""Logs with the IMU cut out for a while (an IMU gap), for the tests of what bridges it."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.evaluation.metrics import deviation_series
from estimator.pipeline.inputs import Inputs
from estimator.results import Run

F64 = NDArray[np.float64]

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def without_imu(inputs: Inputs, a: float, b: float) -> Inputs:
    """``inputs`` with no IMU sample from ``a`` to ``b`` s after the log start."""
    imu, t0 = inputs.log.imu, inputs.log.t_start
    keep = ~((imu.t >= t0 + a) & (imu.t < t0 + b))
    cut = dataclasses.replace(imu, t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep])
    return dataclasses.replace(inputs, log=dataclasses.replace(inputs.log, imu=cut))


def truth_turn_deg(inputs: Inputs, a: float, b: float) -> float:
    """How far the truth's heading turned from ``a`` to ``b`` s after the log start, deg."""
    truth, t0 = inputs.log.truth, inputs.log.t_start
    assert truth is not None
    yaw = np.unwrap(truth.heading)
    return math.degrees(float(np.interp(t0 + b, truth.t, yaw) - np.interp(t0 + a, truth.t, yaw)))


def errors_after(run: Run, inputs: Inputs, gap_end: float, since: float) -> tuple[F64, F64]:
    """``run``'s error against truth (m) and yaw error (deg) from ``since`` (s after the log
    start) to the end of the outage the gap ending at ``gap_end`` is in."""
    truth = inputs.log.truth
    assert inputs.route is not None and truth is not None
    series = deviation_series(run, inputs.route, inputs.log).truth
    assert series is not None
    t0 = inputs.log.t_start
    t = run.epochs.t[series.index] - t0
    (end,) = [b - t0 for a, b in run.degraded_intervals if a - t0 < gap_end < b - t0]
    after = (t > since) & (t < end)
    assert after.sum() > 50
    yaw = run.epochs.attitude[series.index, 2][after]
    true_yaw = np.interp(run.epochs.t[series.index][after], truth.t, np.unwrap(truth.heading))
    return series.h_err_m[after], np.degrees(np.angle(np.exp(1j * (yaw - true_yaw))))
