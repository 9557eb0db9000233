"""IMU-only drives (issue 17, item 4): simulated tunnel drives without wheel speed whose MEMS
IMU has what a real one has before calibration and the simulator's nominal unit has not: a
gyro turn-on bias of hundreds of deg/h, accelerometer scale errors of about 1 %, a mounting
a few degrees off the car's axes and a clock tens of milliseconds off the receiver's. None of
these is told to the filter, as none is known to a user who runs a log as recorded.

As in :mod:`estimator.sim.stress`, a drive is a pure function of its index
(:func:`imu_only_spec`, then :func:`build_imu_only`); the route is the road (the map is right),
so a proposed run worse than dead reckoning is the matcher's or the covariance's fault.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from estimator.nav.rotation import dcm_from_euler
from estimator.pipeline.inputs import Inputs
from estimator.sim.scenarios import get_scenario
from estimator.sim.simulation import simulate
from estimator.sim.stress import BASES, Drive, DriveSpec


@dataclass(frozen=True)
class ImuOnlySpec:
    """One IMU-only drive: its base scenario, seed and the IMU faults drawn for it."""

    index: int
    base: str
    seed: int
    gyro_bias_deg_h: float
    """1-sigma of the gyro turn-on bias (drawn per axis by the simulator)"""
    accel_scale_ppm: float
    """1-sigma of the accelerometer scale errors (drawn per axis)"""
    mount_roll_deg: float
    mount_pitch_deg: float
    mount_yaw_deg: float
    """the IMU's mounting, IMU-to-body as ``sensors.imu_*_deg`` (the filter is told zero)"""
    imu_time_offset_s: float
    """added to every IMU stamp: the IMU clock against the receiver's (the filter is told zero)"""

    @property
    def label(self) -> str:
        return f"sim {self.index} {self.base}"


def imu_only_spec(index: int) -> ImuOnlySpec:
    """The faults of IMU-only drive ``index`` (drawn from its own generator)."""
    rng = np.random.default_rng([20261124, index])

    def signed(lo: float, hi: float) -> float:
        return float(rng.uniform(lo, hi)) * float(rng.choice([-1.0, 1.0]))

    return ImuOnlySpec(
        index=index,
        base=BASES[index % len(BASES)],
        seed=2000 + index,
        gyro_bias_deg_h=float(rng.uniform(300.0, 720.0)),
        accel_scale_ppm=float(rng.uniform(5_000.0, 12_000.0)),
        mount_roll_deg=signed(0.0, 1.5),
        mount_pitch_deg=signed(1.0, 4.0),
        mount_yaw_deg=signed(1.0, 3.0),
        imu_time_offset_s=signed(0.01, 0.05),
    )


def build_imu_only(spec: ImuOnlySpec) -> Drive:
    """The drive of ``spec``: simulated with the drawn IMU errors, the wheel speed left out,
    the IMU's axes turned by the mounting and its stamps shifted by the clock offset."""
    sc = get_scenario(spec.base)
    sc = dataclasses.replace(
        sc,
        imu=dataclasses.replace(
            sc.imu,
            gyro_turn_on_bias_deg_h=spec.gyro_bias_deg_h,
            accel_scale_ppm=spec.accel_scale_ppm,
        ),
    )
    sim = simulate(sc, seed=spec.seed)
    log = sim.log()
    r_bi = dcm_from_euler(
        math.radians(spec.mount_roll_deg),
        math.radians(spec.mount_pitch_deg),
        math.radians(spec.mount_yaw_deg),
    ).reshape(3, 3)
    imu = log.imu
    # body = r_bi @ imu, so what the turned IMU measures is r_bi.T @ body (rows: @ r_bi)
    mounted = dataclasses.replace(
        imu,
        t=imu.t + spec.imu_time_offset_s,
        gyro=np.ascontiguousarray(imu.gyro @ r_bi),
        accel=np.ascontiguousarray(imu.accel @ r_bi),
    )
    log = dataclasses.replace(log, imu=mounted, wheel=None)
    road = sim.route()
    stress_spec = DriveSpec(
        index=spec.index,
        base=spec.base,
        seed=spec.seed,
        fault="no_odometer",
        bias_along_m=0.0,
        bias_across_m=0.0,
        bias_rotation_deg=0.0,
        gyro_bias_deg_h=spec.gyro_bias_deg_h,
        wheel_scale_error=0.0,
        first_fix_off_m=0.0,
        imu_gap_s=0.0,
    )
    return Drive(stress_spec, Inputs(log, road, sim.frame), road, sim.tunnels)
