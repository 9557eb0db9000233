"""The IMU's mounting yaw, from the data: where its forward axis points against the direction
of travel.

The filter takes the IMU's axes for the body's (forward-left-up) once ``sensors.imu_*_deg``
are applied. An IMU yawed 90 deg the other way (mounted sideways, or backwards) feels the
vehicle's braking on its lateral axis; the non-holonomic constraints and the wheel speed then
fight the accelerometer, the filter throws away most fixes and the outages drift kilometres,
while the run's warnings speak of refused fixes and matches, never of the mounting.

The vehicle's horizontal acceleration is known without the IMU: forward, the change of the
wheel speed (or of the GNSS speed without wheels); to the left, the speed times the yaw rate
(the rate about gravity, whatever the IMU's yaw). The accelerometer's horizontal specific force
(levelled by its mean direction, gravity) is that acceleration turned by the IMU's yaw, or
mirrored as well when its axes are left-handed (x and y swapped by a driver). A 2x2 least-
squares fit of one on the other over windows of a few seconds tells which, and by how much.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimator.nav.rotation import dcm_from_euler, euler_from_dcm

F64 = NDArray[np.float64]

WINDOW_S = 4.0
"""The accelerations are compared as means over windows this long, every half window: the
mean of the forward acceleration over one is the change of speed across it, which needs no
derivative of a noisy speed, and the wheels' and fixes' noise is seconds' worth of averaging
smaller."""
GNSS_SPEED_SPAN_S = 2.0
"""Without wheels, the speed at a time is the distance between the (interpolated) fix
positions this long before and after it, over twice this: fix noise of a metre gives tenths of
a m/s, and its error is uncorrelated with the IMU, which the fitted angle does not feel."""
MAX_FIX_GAP_S = 1.5
"""A window without wheels needs fixes no further apart than this around it."""
MIN_ACCELERATION_M_S2 = 0.3
"""Windows whose vehicle acceleration is below this (m/s^2, 0.03 g) say little about the
direction and are left out of the count of evidence (they stay in the fit)."""
MIN_EVIDENCE_S = 20.0
"""Seconds of windows with at least :data:`MIN_ACCELERATION_M_S2` needed before the mounting
is judged: a few stops and turns."""
MIN_CORRELATION = 0.5
"""The fit's correlation (the share of the specific force's variance it explains, square-
rooted) below which the data say nothing certain (a vehicle standing, or a road so bumpy the
accelerometer is mostly vibration)."""
MAX_YAW_SIGMA_RAD = math.radians(3.0)
"""The fitted yaw's standard error above which it is not judged."""
PLAUSIBLE_SCALE = (0.5, 2.0)
"""The accelerometer's horizontal specific force is the vehicle's acceleration, scale 1; a fit
outside this range matched something else."""
YAW_WARN_RAD = math.radians(5.0)
"""A forward axis off the direction of travel by more than this, at two standard errors, is
named. The fit's standard error is 0.5-1.5 deg on the samples and simulated drives (with and
without wheels), its bias within 0.5 deg on the samples and 2.6 deg on the spiral drives;
mounts are commonly off by 1-3 deg, which the filter's alignment and noise absorb, while
10 deg already cost 1-2 km of truth error in long_tunnel's outage."""
SQUARE_SNAP_RAD = math.radians(1.0)
"""A recommended yaw within this (or two standard errors) of a multiple of 90 deg is given as
that multiple: IMUs are mounted square to the vehicle, or turned by the few degrees this
check does not name."""
TILT_NAMED_RAD = math.radians(20.0)
"""An IMU whose z axis lies further than this from gravity's direction (on its side) needs roll
and pitch along with the yaw: the yaw alone would stand its forward axis on end. Below, the
road's grade and the mount's tilt are the filter's alignment's to take."""
TILT_SNAP_RAD = math.radians(10.0)
"""A recommended roll or pitch (from the mean specific force, which the vehicle's and the
road's tilt move by degrees) within this of a multiple of 90 deg is given as that multiple."""


@dataclass(frozen=True)
class MountYaw:
    """Where the IMU's forward axis points, relative to the direction of travel."""

    yaw_rad: float
    """the yaw that turns the axes given (the IMU's, turned by the configured ``sensors.imu_*``
    rotation) onto the body's, in the sense of ``sensors.imu_yaw_deg``: their x axis points
    this far left of the direction of travel"""
    sigma_rad: float
    """its standard error"""
    left_handed: bool
    """the horizontal axes are mirrored (x and y swapped): no rotation makes them the body's"""
    correlation: float
    scale: float
    """specific force per m/s^2 of the vehicle's acceleration: 1 for an accelerometer in m/s^2"""
    evidence_s: float
    """seconds of windows in which the vehicle accelerated by :data:`MIN_ACCELERATION_M_S2`"""
    source: str
    """what the forward acceleration came from: ``"wheel speed"`` or ``"GNSS speed"``"""
    tilt_rad: float
    """the angle between the IMU's z axis and its mean specific force (gravity's direction)"""
    up: F64
    """unit mean specific force, in the IMU's axes"""
    forward: F64
    """unit horizontal direction of travel, in the IMU's axes"""

    @property
    def judged(self) -> bool:
        """Whether the data are clear enough to say anything."""
        return (
            self.evidence_s >= MIN_EVIDENCE_S
            and self.correlation >= MIN_CORRELATION
            and self.sigma_rad <= MAX_YAW_SIGMA_RAD
            and PLAUSIBLE_SCALE[0] <= self.scale <= PLAUSIBLE_SCALE[1]
        )

    def body_from_imu(self) -> F64:
        """The rotation (3, 3) taking a vector in the IMU's axes to the body's: its rows are the
        direction of travel, left and up, in the IMU's axes (meaningless when left-handed)."""
        left = np.cross(self.up, self.forward)
        out: F64 = np.vstack([self.forward, left, self.up])
        return out


def _snapped_deg(angle_rad: float, tolerance_rad: float) -> float:
    """The angle in degrees, as the nearest multiple of 90 when within ``tolerance_rad`` of it,
    else to a degree; wrapped to (-180, 180]."""
    square = math.pi / 2 * round(angle_rad / (math.pi / 2))
    deg = (
        math.degrees(square)
        if abs(angle_rad - square) <= tolerance_rad
        else math.degrees(angle_rad)
    )
    deg = float(round(deg))
    deg = (deg + 180.0) % 360.0 - 180.0
    return 180.0 if deg == -180.0 else deg + 0.0


def mount_warning(
    name: str, topic: str, m: MountYaw | None, roll_deg: float, pitch_deg: float, yaw_deg: float
) -> str | None:
    """One line when the IMU (after the configured ``sensors.imu_*_deg``, given here) is
    mirrored or its forward axis is more than :data:`YAW_WARN_RAD` off the direction of travel,
    naming the setting that fixes it; None otherwise, or when the data cannot tell."""
    if m is None or not m.judged:
        return None
    evidence = (
        f"over {m.evidence_s:.0f} s of acceleration from the {m.source} and the yaw rate, "
        f"correlation {m.correlation:.2f}"
    )
    where = f"{name}: IMU {topic}"
    if m.left_handed:
        return (
            f"{where}: its horizontal specific force is the vehicle's acceleration mirrored, not "
            f"turned ({evidence}): its axes are left-handed (x and y swapped, or one negated, by "
            "its driver), which no sensors.imu_*_deg can undo; fix the driver's frame"
        )
    if abs(m.yaw_rad) - 2 * m.sigma_rad <= YAW_WARN_RAD:
        return None
    yaw = math.degrees(m.yaw_rad)
    side = "left" if yaw > 0 else "right"
    off = f"{abs(yaw):.0f} deg {side} of" if abs(yaw) < 170 else f"{abs(yaw):.0f} deg from"
    how = "backwards" if abs(yaw) > 135 else "sideways" if abs(yaw) > 45 else "turned"
    configured = dcm_from_euler(
        math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg)
    ).reshape(3, 3)
    mounting = m.body_from_imu() @ configured
    roll, pitch, yaw_total = (float(a) for a in euler_from_dcm(mounting)[0])
    yaw_tolerance = max(SQUARE_SNAP_RAD, 2 * m.sigma_rad)
    if m.tilt_rad > TILT_NAMED_RAD:
        setting = (
            f"sensors.imu_roll_deg = {_snapped_deg(roll, TILT_SNAP_RAD):g}, "
            f"sensors.imu_pitch_deg = {_snapped_deg(pitch, TILT_SNAP_RAD):g}, "
            f"sensors.imu_yaw_deg = {_snapped_deg(yaw_total, yaw_tolerance):g}"
        )
    else:
        recommended = _snapped_deg(math.radians(yaw_deg) + m.yaw_rad, yaw_tolerance)
        setting = f"sensors.imu_yaw_deg = {recommended:g}"
    now = f"sensors.imu_yaw_deg = {yaw_deg:g}"
    if roll_deg or pitch_deg:
        now = f"sensors.imu_roll_deg = {roll_deg:g}, imu_pitch_deg = {pitch_deg:g}, imu_{now[8:]}"
    return (
        f"{where}: its x axis points {off} the direction of travel with "
        f"{now} (the yaw that turns its horizontal specific force onto the vehicle's "
        f"acceleration is {yaw:+.1f} +- {math.degrees(m.sigma_rad):.1f} deg, {evidence}): the "
        f"IMU is mounted {how}; set {setting}"
    )


def _gnss_speed(gnss_t: F64, gnss_xy: F64, t: F64) -> tuple[F64, NDArray[np.bool_]]:
    """Horizontal speed from the fixes at ``t`` and where fixes cover it without a gap."""
    h = GNSS_SPEED_SPAN_S
    a = np.column_stack([np.interp(t - h, gnss_t, gnss_xy[:, k]) for k in (0, 1)])
    b = np.column_stack([np.interp(t + h, gnss_t, gnss_xy[:, k]) for k in (0, 1)])
    speed = np.hypot(*(b - a).T) / (2 * h)
    covered = _covered(gnss_t, t - h, t + h)
    return speed, covered


def _covered(ts: F64, t0: F64, t1: F64) -> NDArray[np.bool_]:
    """Whether samples ``ts`` span each interval without a gap above :data:`MAX_FIX_GAP_S`."""
    if len(ts) < 2:
        return np.zeros(len(t0), bool)
    gap = np.diff(ts) > MAX_FIX_GAP_S
    before_gaps = np.r_[0, np.cumsum(gap)]
    i0 = np.searchsorted(ts, t0, "right") - 1
    i1 = np.searchsorted(ts, t1, "left")
    inside = (i0 >= 0) & (i1 < len(ts))
    i0c, i1c = np.clip(i0, 0, len(ts) - 1), np.clip(i1, 0, len(ts) - 1)
    out: NDArray[np.bool_] = inside & (before_gaps[i1c] == before_gaps[i0c])
    return out


def _half_window_edges(imu_t: F64) -> F64:
    """The edges of the half-windows, :data:`WINDOW_S` / 2 apart from the first sample: every
    one over the log's span, or, when that span holds far more of them than there are samples
    (a clock that jumps years forward: 158 million edges, 12 GB, the run killed), only those
    next to a sample, so that every window with data in it is the same."""
    step = WINDOW_S / 2
    if (imu_t[-1] - imu_t[0]) / step <= 4 * len(imu_t) + 16:
        out: F64 = np.arange(imu_t[0], imu_t[-1], step)
        return out
    cell = np.floor((imu_t - imu_t[0]) / step)
    near = np.unique(np.concatenate([cell - 1, cell, cell + 1, cell + 2]))
    edges: F64 = imu_t[0] + step * near[near >= 0]
    inside: F64 = edges[edges < imu_t[-1]]
    return inside


def mount_yaw(
    imu_t: F64,
    gyro: F64,
    accel: F64,
    wheel_t: F64,
    wheel_v: F64,
    gnss_t: F64,
    gnss_xy: F64,
) -> MountYaw | None:
    """The IMU's mounting yaw against the direction of travel, from its specific force and the
    vehicle's acceleration (the wheel speed's, else the GNSS speed's); None when the log is
    too short or the IMU has holes."""
    if len(imu_t) < 10:
        return None
    mean_f = accel.mean(axis=0)
    norm = float(np.linalg.norm(mean_f))
    if norm < 1.0:
        return None
    up = mean_f / norm
    ref = np.eye(3)[0] if abs(up[0]) < 0.9 else np.eye(3)[1]
    e1 = ref - (ref @ up) * up
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    # windows of two half-windows each, whose IMU sums are added up once
    edges = _half_window_edges(imu_t)
    if len(edges) < 3:
        return None
    first = np.searchsorted(imu_t, edges)
    count = np.diff(np.r_[first, len(imu_t)])
    t0, t1 = edges[:-2], edges[2:]
    usable = _covered(imu_t, t0, t1) & (count[:-2] > 0) & (count[1:-1] > 0)
    if len(wheel_t) >= 2:
        usable &= (t0 >= wheel_t[0]) & (t1 <= wheel_t[-1])
        speed_t, speed_v = wheel_t, wheel_v
        v0, v1 = np.interp(t0, wheel_t, wheel_v), np.interp(t1, wheel_t, wheel_v)
        source = "wheel speed"
    else:
        if len(gnss_t) < 10:
            return None
        speed_t = edges
        speed_v, covered = _gnss_speed(gnss_t, gnss_xy, edges)
        v0, v1 = speed_v[:-2], speed_v[2:]
        usable &= covered[:-2] & covered[2:]
        source = "GNSS speed"
    if np.count_nonzero(usable) < 10:
        return None
    speed = np.interp(imu_t, speed_t, speed_v)
    n = (count[:-2] + count[1:-1])[usable]
    f_sums = np.add.reduceat(accel, first, axis=0)
    f = (f_sums[:-2] + f_sums[1:-1])[usable] / n[:, None]
    left_sums = np.add.reduceat(speed * (gyro @ up), first)
    left = (left_sums[:-2] + left_sums[1:-1])[usable] / n
    forward = (v1 - v0)[usable] / WINDOW_S
    x = np.column_stack([forward, left])
    y = np.column_stack([f @ e1, f @ e2])
    x = x - x.mean(axis=0)
    y = y - y.mean(axis=0)
    a, *_ = np.linalg.lstsq(x, y, rcond=None)
    m = a.T  # y ~ m @ x
    proper = complex(m[0, 0] + m[1, 1], m[1, 0] - m[0, 1]) / 2
    mirrored = complex(m[0, 0] - m[1, 1], m[1, 0] + m[0, 1]) / 2
    left_handed = abs(mirrored) > abs(proper)
    c = mirrored if left_handed else proper
    xz = x[:, 0] + 1j * x[:, 1]
    yz = y[:, 0] + 1j * y[:, 1]
    fit = c * (np.conj(xz) if left_handed else xz)
    residual = yz - fit
    n = len(xz)
    res2 = float(np.sum(np.abs(residual) ** 2))
    tot2 = float(np.sum(np.abs(yz) ** 2))
    correlation = math.sqrt(max(0.0, 1.0 - res2 / tot2)) if tot2 > 0 else 0.0
    energy = float(np.sum(np.abs(xz) ** 2))
    scale = abs(c)
    sigma = (
        math.sqrt(res2 / max(2 * n - 4, 1) / energy) / scale
        if energy > 0 and scale > 0
        else math.inf
    )
    # the specific force is the acceleration turned by minus the mounting yaw
    yaw = -math.atan2(c.imag, c.real)
    travel = math.cos(yaw) * e1 - math.sin(yaw) * e2
    accelerating = np.hypot(forward, left) >= MIN_ACCELERATION_M_S2
    evidence = float(np.count_nonzero(accelerating)) * WINDOW_S / 2
    tilt = math.acos(float(np.clip(up[2], -1.0, 1.0)))
    return MountYaw(
        yaw_rad=yaw,
        sigma_rad=sigma,
        left_handed=bool(left_handed),
        correlation=correlation,
        scale=scale,
        evidence_s=evidence,
        source=source,
        tilt_rad=tilt,
        up=up,
        forward=travel,
    )
