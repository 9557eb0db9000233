"""The in-memory log: every sensor stream as numpy arrays, times in seconds (float64, the bag's
clock), IMU already rotated into the body frame (forward-left-up)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

GNSS_NO_FIX = -1


@dataclass(frozen=True)
class ImuData:
    t: F64
    """(N,) s"""
    gyro: F64
    """(N, 3) body angular rate, rad/s, FLU"""
    accel: F64
    """(N, 3) specific force, m/s^2, FLU (+g on z when level and still)"""


@dataclass(frozen=True)
class WheelData:
    t: F64
    speed: F64
    """(N,) forward speed, m/s"""


def wheel_gap_s(t: F64) -> float:
    """Wheel samples further apart than this (s) have a gap between them: five of the stream's
    median intervals, half a second at least. The filter does not interpolate the speed across
    it, nor ``info`` integrate it: over a paused recording, or a clock that jumped, the last
    speed times the gap is no distance driven."""
    interval = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return max(0.5, 5 * interval)


@dataclass(frozen=True)
class GnssData:
    t: F64
    lat: F64
    lon: F64
    alt: F64
    """ellipsoidal height, m"""
    status: NDArray[np.int8]
    """NavSatStatus: -1 no fix, 0 fix, 1 SBAS, 2 GBAS"""
    cov_enu: F64
    """(N, 3) variances E, N, U in m^2 (NaN when the message has none)"""

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Fixes that carry a position: NO_FIX or NaN both mean 'no GNSS'."""
        return (
            (self.status >= 0)
            & np.isfinite(self.lat)
            & np.isfinite(self.lon)
            & np.isfinite(self.alt)
        )


@dataclass(frozen=True)
class TruthData:
    t: F64
    lat: F64
    lon: F64
    alt: F64
    heading: F64
    """(N,) ENU yaw of the body x axis, rad, counter-clockwise from East; NaN if unknown"""


@dataclass(frozen=True)
class TopicInfo:
    topic: str
    msgtype: str
    count: int
    role: str
    """'imu', 'gnss', 'wheel', 'truth', 'truth_pose', 'tf_static' or '' (unused)"""


@dataclass(frozen=True)
class ClockOffset:
    """A stream's clock offset against the IMU's, measured when the log was read (its turns or
    its speed's changes against the IMU's, :mod:`estimator.io.plausibility`): the value of
    ``setting`` that puts it on the IMU's clock. Kept with the log, because only a run knows
    the configuration: the line the load printed for the default setting must go once the
    user has set it, and a setting the log contradicts must be named."""

    setting: str
    """``sensors.gnss_time_offset_s`` or ``sensors.wheel_time_offset_s``"""
    offset_s: float
    stream: str
    """the stream and its topic, as a warning names it (``GNSS /gnss/fix``)"""
    warning: str = ""
    """the load's line for the default setting (0 s), or "" when that is within tolerance"""


@dataclass(frozen=True)
class Log:
    """One decoded log. Immutable; the estimator never changes it."""

    path: str
    imu: ImuData
    gnss: GnssData
    wheel: WheelData | None = None
    truth: TruthData | None = None
    topics: tuple[TopicInfo, ...] = ()
    warnings: tuple[str, ...] = field(default=())
    clock_offsets: tuple[ClockOffset, ...] = ()

    @property
    def t_start(self) -> float:
        return float(self.imu.t[0])

    @property
    def t_end(self) -> float:
        return float(self.imu.t[-1])

    @property
    def duration_s(self) -> float:
        return self.t_end - self.t_start
