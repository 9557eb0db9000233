"""From decoded columns to a :class:`Log`: the repairs of ``docs/robustness.md``, each reported
in ``Log.warnings``, and the IMU rotated into the body frame."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError
from estimator.io import plausibility
from estimator.io.decode import Decoded, rotation_between
from estimator.io.topics import TopicRoles
from estimator.log import GnssData, ImuData, Log, TopicInfo, TruthData, WheelData
from estimator.nav.rotation import yaw_from_quaternion

F64 = NDArray[np.float64]

MIN_IMU_SAMPLES = 10
IMU_LIMITS = (100.0,) * 3 + (2000.0,) * 3
"""|gyro| rad/s and |accel| m/s^2 beyond any vehicle IMU's range: such samples are corrupt."""
WHEEL_LIMIT = 200.0
"""|speed| m/s beyond any vehicle: a corrupt wheel sample."""
MAX_ABS_ALTITUDE_M = 100_000.0
IRREGULAR_FRACTION = 0.01
"""An IMU stream is reported as irregular when more than this fraction of its sample intervals
is off the median interval by more than half of it (dropped samples, jittery stamps)."""
JUMP_MIN_S = 1.0
JUMP_MIN_INTERVALS = 50
"""A step back in a stream's stamps of more than both is its clock jumping back, not samples
arriving out of order."""
GNSS_JUMP_MIN_INTERVALS = 5
"""The same for fixes, a few a second: a receiver's messages do not arrive seconds out of order,
while its clock stepping back 2-10 s (a leap second applied late, a time-source switch) left
fixes of two stretches of the drive interleaved after sorting, named only as samples out of
order and repeated stamps (50 intervals is 10 s at 5 Hz, 50 s at 1 Hz)."""
ISOLATED_GAP_MIN_S = 10.0
ISOLATED_GAP_INTERVALS = 1000
"""Samples separated from the rest of their stream by more than both (and few: see
:func:`_drop_isolated`) carry a corrupt stamp."""
SAME_JUMP_S = 1.0
"""Streams whose clocks jump back within this of each other jumped together (one clock)."""


def _median_step(t: F64) -> float:
    dt = np.diff(t)
    dt = dt[np.isfinite(dt) & (dt > 0)]
    return float(np.median(dt)) if len(dt) else 0.0


def _mend_jumps(
    name: str,
    t: F64,
    warnings: list[str],
    shared: list[float],
    min_intervals: int = JUMP_MIN_INTERVALS,
) -> F64:
    """A clock that jumps back (an NTP step, a recorder restart) leaves the samples after the
    jump stamped earlier than those before it: sorted by stamp, two stretches of the drive would
    interleave, and without sorting every sample after the jump is behind its predecessor. The
    samples after each jump are moved forward to continue the stream at its median rate (all of
    the data is kept). ``shared``: the shifts of the streams mended before; a stream that jumps
    by about the same (one clock for all) takes that shift, so the streams stay paired to the
    IMU's resolution, not to their own sample interval."""
    step = _median_step(t)
    if step <= 0:
        return t
    d = np.diff(t)
    jumps = np.flatnonzero(d < -max(JUMP_MIN_S, min_intervals * step))
    if not len(jumps):
        return t
    t = t.copy()
    for k in jumps:
        if _outlier_around(t, int(k), JUMP_MIN_INTERVALS * step):
            continue
        back = float(t[k] - t[k + 1])
        shift = back + step
        same = [x for x in shared if abs(x - shift) < SAME_JUMP_S]
        if same:
            shift = same[0]
        else:
            shared.append(shift)
        warnings.append(
            f"{name}: clock jumps back {back:.3f} s after {t[k] - t[0]:.3f} s of the stream; "
            f"the {len(t) - k - 1} samples after the jump moved {shift:.3f} s forward to "
            "continue it (data kept)"
        )
        t[k + 1 :] += shift
    return t


def _outlier_around(t: F64, k: int, near: float, most: int = 4) -> bool:
    """Whether the step back between samples k and k+1 is a few corrupt stamps (ahead of the
    stream before it, or behind it after) rather than the clock jumping: the stream resumes
    within ``near`` of where it was after at most ``most`` samples."""
    n = len(t)
    for m in range(1, most + 1):
        if k + 1 + m < n and 0 < t[k + 1 + m] - t[k] <= near:
            return True
        if k - m >= 0 and 0 < t[k + 1] - t[k - m] <= near:
            return True
    return False


def _drop_isolated(name: str, t: F64, v: F64, warnings: list[str]) -> tuple[F64, F64]:
    """A single corrupt stamp (a sample years away, or at t = 1 s) would stretch the stream's
    span over years: the log's start, its frame's time base and every buffer sized from the
    span would follow it. Stretches of at most max(3, 0.1 %) samples set apart from the rest by
    a gap of more than max(10 s, 1000 sample intervals) are dropped, each named."""
    if len(t) < 8:
        return t, v
    step = _median_step(t)
    gap = max(ISOLATED_GAP_MIN_S, ISOLATED_GAP_INTERVALS * step)
    cuts = np.flatnonzero(np.diff(t) > gap) + 1
    if not len(cuts):
        return t, v
    bounds = np.r_[0, cuts, len(t)]
    small = max(3, len(t) // 1000)
    keep = np.ones(len(t), bool)
    for a, b in itertools.pairwise(bounds):
        if b - a <= small:
            keep[a:b] = False
            stamps = ", ".join(f"{x:.3f}" for x in t[a:b][:3])
            warnings.append(
                f"{name}: dropped {b - a} samples stamped far from the rest of the stream "
                f"(corrupt stamps: {stamps} s)"
            )
    if keep.all() or not keep.any():
        return t, v
    return t[keep], v[keep]


def _clean(
    name: str,
    t: F64,
    v: F64,
    warnings: list[str],
    *,
    drop_nonfinite: bool,
    limits: tuple[float, ...] | None = None,
    jumps: list[float] | None = None,
    jump_min_intervals: int = JUMP_MIN_INTERVALS,
) -> tuple[F64, F64]:
    if jumps is not None:
        t = _mend_jumps(name, t, warnings, jumps, jump_min_intervals)
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(len(t))):
        moved = int(np.count_nonzero(np.diff(t) < 0))
        warnings.append(f"{name}: {moved} samples out of time order, sorted by stamp")
        t, v = t[order], v[order]
    dup = np.r_[False, np.diff(t) == 0]
    if dup.any():
        warnings.append(f"{name}: dropped {int(dup.sum())} samples with a repeated stamp")
        t, v = t[~dup], v[~dup]
    t, v = _drop_isolated(name, t, v, warnings)
    bad = ~np.isfinite(t)
    if drop_nonfinite:
        bad |= ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        warnings.append(f"{name}: dropped {int(bad.sum())} samples with non-finite values")
        t, v = t[~bad], v[~bad]
    if limits is not None:
        wild = np.any(np.abs(v) > np.asarray(limits), axis=1)
        if wild.any():
            warnings.append(
                f"{name}: dropped {int(wild.sum())} samples with physically impossible values "
                f"(beyond {', '.join(f'{x:g}' for x in dict.fromkeys(limits))})"
            )
            t, v = t[~wild], v[~wild]
    return t, v


def _note_irregular(name: str, t: F64, warnings: list[str]) -> None:
    """Irregular IMU intervals need no repair (the filter integrates over the actual
    intervals), but they degrade the mechanisation, so they are reported."""
    dt = np.diff(t)
    if len(dt) < 2:
        return
    med = float(np.median(dt))
    off = np.abs(dt - med) > 0.5 * med
    if np.mean(off) > IRREGULAR_FRACTION:
        warnings.append(
            f"{name}: irregular sample intervals ({100 * np.mean(off):.0f} % differ from the "
            f"median {1e3 * med:.1f} ms by more than half; longest {1e3 * float(dt.max()):.0f} "
            "ms), integrated over the actual intervals"
        )


def _imu(
    path: Path, roles: TopicRoles, raw: Decoded, warnings: list[str], jumps: list[float]
) -> ImuData:
    t, v, imu_frame = raw.streams["imu"]
    t, v = _clean(
        f"IMU {roles.imu}", t, v, warnings, drop_nonfinite=True, limits=IMU_LIMITS, jumps=jumps
    )
    if len(t) < MIN_IMU_SAMPLES:
        raise LogError(
            path, f"too few IMU samples on {roles.imu}: {len(t)} (need at least {MIN_IMU_SAMPLES})"
        )
    _note_irregular(f"IMU {roles.imu}", t, warnings)
    gyro, accel = v[:, :3], v[:, 3:6]
    body = next((b for b in raw.body_candidates if b), "base_link")
    if raw.bad_tf:
        warnings.append(
            f"/tf_static: ignored {len(raw.bad_tf)} transforms with a zero or non-finite "
            f"rotation ({', '.join(raw.bad_tf[:3])})"
        )
    if raw.edges and imu_frame and imu_frame != body:
        rot = rotation_between(raw.edges, body, imu_frame)
        if rot is not None:
            gyro, accel = gyro @ rot.T, accel @ rot.T
            warnings.append(f"IMU rotated from {imu_frame} into {body} by /tf_static")
        else:
            warnings.append(f"IMU frame {imu_frame}: no /tf_static path to {body}, not rotated")
    return ImuData(t, np.ascontiguousarray(gyro), np.ascontiguousarray(accel))


def _truth(roles: TopicRoles, raw: Decoded, warnings: list[str]) -> TruthData | None:
    if "truth" not in raw.streams:
        return None
    tt, tv = _clean(
        f"truth {roles.truth}", *raw.streams["truth"][:2], warnings, drop_nonfinite=False
    )
    heading = np.full(len(tt), np.nan)
    if "truth_pose" in raw.streams:
        pt, pv = _clean(
            f"truth {roles.truth_pose}",
            *raw.streams["truth_pose"][:2],
            warnings,
            drop_nonfinite=True,
        )
        if len(pt):
            x, y, z, w = pv.T  # a ROS quaternion's order
            yaw = np.unwrap(yaw_from_quaternion(w, x, y, z))
            inside = (tt >= pt[0]) & (tt <= pt[-1])
            heading[inside] = np.angle(np.exp(1j * np.interp(tt[inside], pt, yaw)))
    if not len(tt):
        return None
    return TruthData(tt, tv[:, 0].copy(), tv[:, 1].copy(), tv[:, 2].copy(), heading)


def assemble(
    path: Path, roles: TopicRoles, raw: Decoded, types: dict[str, str], counts: dict[str, int]
) -> Log:
    """The repaired :class:`Log` of what :func:`estimator.io.decode.decode` read."""
    warnings: list[str] = []
    jumps: list[float] = []
    imu = _imu(path, roles, raw, warnings, jumps)

    gt, gv = _clean(
        f"GNSS {roles.gnss}",
        *raw.streams["gnss"][:2],
        warnings,
        drop_nonfinite=False,
        jumps=jumps,
        jump_min_intervals=GNSS_JUMP_MIN_INTERVALS,
    )
    if len(gt) == 0:
        raise LogError(path, f"GNSS topic {roles.gnss} has no messages")
    gnss = _gnss(gt, gv, f"GNSS {roles.gnss}", warnings)
    _check_shared_clock(path, imu.t, gnss.t)
    if not gnss.valid.any():
        warnings.append(f"GNSS {roles.gnss}: no valid fix in the whole log")

    wheel = None
    if "wheel" in raw.streams:
        wt, wv = _clean(
            f"wheel {roles.wheel}",
            *raw.streams["wheel"][:2],
            warnings,
            drop_nonfinite=True,
            limits=(WHEEL_LIMIT,),
            jumps=jumps,
        )
        wheel = WheelData(wt, wv[:, 0].copy()) if len(wt) else None

    truth = _truth(roles, raw, warnings)
    topics = tuple(
        TopicInfo(topic, types[topic], counts[topic], roles.role_of(topic))
        for topic in sorted(types)
    )
    return plausibility.checked(
        path, Log(str(path), imu, gnss, wheel, truth, topics, tuple(warnings))
    )


def _check_shared_clock(path: Path, imu_t: F64, gnss_t: F64) -> None:
    """IMU and GNSS that share no instant were stamped on different clocks (an IMU in time since
    boot, fixes in Unix time): no estimate can pair them, so the log is refused with both spans
    named rather than run into an empty result."""
    if imu_t[0] <= gnss_t[-1] and gnss_t[0] <= imu_t[-1]:
        return
    raise LogError(
        path,
        "IMU and GNSS are stamped on different clocks (no common time): "
        f"IMU {imu_t[0]:.1f}-{imu_t[-1]:.1f} s, GNSS {gnss_t[0]:.1f}-{gnss_t[-1]:.1f} s",
    )


def _gnss(t: F64, v: F64, name: str, warnings: list[str]) -> GnssData:
    """Fixes with a status but no usable position become NO_FIX; a variance that is not a
    positive number becomes unknown (NaN: the filter then uses its default sigma)."""
    status = np.where(np.isfinite(v[:, 3]), v[:, 3], -1).astype(np.int8)
    lat, lon, alt = v[:, 0].copy(), v[:, 1].copy(), v[:, 2].copy()
    with np.errstate(invalid="ignore"):
        no_pos = ~(
            np.isfinite(lat)
            & np.isfinite(lon)
            & np.isfinite(alt)
            & (np.abs(lat) <= 90.0)
            & (np.abs(lon) <= 180.0)
            & (np.abs(alt) <= MAX_ABS_ALTITUDE_M)
        )
    bad_pos = no_pos & (status >= 0)
    if bad_pos.any():
        warnings.append(
            f"{name}: {int(bad_pos.sum())} fixes without a finite, in-range position, "
            "treated as no fix"
        )
    status[no_pos] = -1
    lat[no_pos], lon[no_pos], alt[no_pos] = np.nan, np.nan, np.nan  # no inf, no 1e300
    cov = v[:, 4:7].copy()
    cov[(status < 0) | (v[:, 7] == 0)] = np.nan
    with np.errstate(invalid="ignore"):
        bad_cov = np.isfinite(cov).any(axis=1) & ~np.all(np.isfinite(cov) & (cov > 0), axis=1)
    if bad_cov.any():
        warnings.append(
            f"{name}: {int(bad_cov.sum())} fixes with a zero, negative or non-finite variance, "
            "treated as unknown (the filter's default sigma is used)"
        )
        cov[bad_cov] = np.nan
    return GnssData(t, lat, lon, alt, status, cov)
