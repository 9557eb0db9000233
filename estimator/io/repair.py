"""From decoded columns to a :class:`Log`: the repairs of ``docs/robustness.md``, each reported
in ``Log.warnings``, and the IMU rotated into the body frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError
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


def _clean(
    name: str,
    t: F64,
    v: F64,
    warnings: list[str],
    *,
    drop_nonfinite: bool,
    limits: tuple[float, ...] | None = None,
) -> tuple[F64, F64]:
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(len(t))):
        moved = int(np.count_nonzero(np.diff(t) < 0))
        warnings.append(f"{name}: {moved} samples out of time order, sorted by stamp")
        t, v = t[order], v[order]
    dup = np.r_[False, np.diff(t) == 0]
    if dup.any():
        warnings.append(f"{name}: dropped {int(dup.sum())} samples with a repeated stamp")
        t, v = t[~dup], v[~dup]
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


def _imu(path: Path, roles: TopicRoles, raw: Decoded, warnings: list[str]) -> ImuData:
    t, v, imu_frame = raw.streams["imu"]
    t, v = _clean(f"IMU {roles.imu}", t, v, warnings, drop_nonfinite=True, limits=IMU_LIMITS)
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
    imu = _imu(path, roles, raw, warnings)

    gt, gv = _clean(f"GNSS {roles.gnss}", *raw.streams["gnss"][:2], warnings, drop_nonfinite=False)
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
        )
        wheel = WheelData(wt, wv[:, 0].copy()) if len(wt) else None

    truth = _truth(roles, raw, warnings)
    topics = tuple(
        TopicInfo(topic, types[topic], counts[topic], roles.role_of(topic))
        for topic in sorted(types)
    )
    return Log(str(path), imu, gnss, wheel, truth, topics, tuple(warnings))


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
