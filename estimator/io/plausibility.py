"""Data that is finite but cannot be right: the unit and sign mistakes, dead sensors and clock
offsets that would otherwise give a confident wrong answer without a word.

Each check compares a stream with physics or with another stream, and says what it found with
the likely cause: the IMU's specific force at rest is gravity (9.81 m/s^2, about 1 when the
driver reports g); its yaw rate follows the GNSS course rate (57 times it in deg/s, with the
opposite sign in a NED or FRD frame, shifted in time when the clocks disagree); the wheel
speed follows the GNSS speed (3.6 times it in km/h, its negative with the wrong sign), and its
changes the IMU's horizontal specific force (shifted in time when their clocks disagree); a fix's
variance lies between a millimetre and a kilometre squared. A log no estimate can be made from
(a dead IMU, accelerations in g, rates in deg/s) is refused in one line; the rest is repaired
where the repair is sure (a wheel stream in other units is left out, fixes that claim a
kilometre of variance are no fixes) and warned about, with the span affected.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError, named_and_summed
from estimator.log import ClockOffset, GnssData, Log, WheelData, wheel_gap_s
from estimator.nav.earth import great_circle_m
from estimator.nav.frames import LocalFrame

F64 = NDArray[np.float64]

GRAVITY = 9.80665
G_UNITS = (0.6, 1.6)
"""median |specific force| in this range: the accelerations are in g"""
PLAUSIBLE_GRAVITY = (7.0, 13.0)
MOVING_M_S = 3.0
MIN_TURN_RAD = 3.0
"""summed |course change| over the windows needed to judge the gyro's units, sign and timing"""
MAX_SPEED_JUMP_M_S = 3.0
"""a step whose speed differs more from its neighbours' holds a jumping fix"""
MIN_TURN_WINDOW_RAD = 0.15
"""windows turning less than this say nothing about the gyro's scale"""
TURN_OUTLIER_RAD = 0.3
TURN_STEPS = 5
"""course changes are taken over this many ~1 s steps"""
DEG_S_RATIO = (20.0, 120.0)
"""gyro yaw rate / GNSS course rate in this range: the rates are in deg/s (57.3)"""
GYRO_SCALE_OK = (0.8, 1.25)
"""The gyro's heading change about gravity over the GNSS course's, outside this range: its
angular rates are scaled wrong (raw counts, mrad/s, a wrong full-scale setting); a MEMS gyro's
scale is within a few per cent, the course's turns within several."""
MRAD_S_RATIO = (800.0, 1250.0)
LAG_WARN_S = 0.2
MIN_LAG_CORRELATION = 0.7
LAG_COARSE_STEP_S = 0.25
"""The offset between the IMU's and the GNSS clocks is searched on this grid first: a turn is
seen over ~5 s windows, whose correlation with the gyro's falls by under 0.01 in a quarter of a
second, so the grid cannot step over a match."""
LAG_STEP_S = 0.02
"""then on this one, over a coarse step either side of the best coarse shift"""
LAG_PEAK_WINDOW_S = 10.0
LAG_PEAK_MARGIN = 0.05
"""A measured offset is a clear peak: its correlation beats every one further than the window
from it by the margin. Shifts within the window still overlap the peak's turns (0.8 at 4 s on
the samples); beyond it, another match beating the peak by less is another place on a route
that repeats itself (laps, a slalom), and the offset cannot be told. The samples' peaks beat
their rivals by 0.10-0.34."""
WHEEL_LAG_WINDOW_S = 1.0
"""The wheel speed's offset against the IMU's clock is measured from the change of its mean
over abutting windows this long against the IMU's (levelled) horizontal specific force's over
the same windows: an acceleration without a noisy derivative. Its peak is sharp and unbiased
on the samples (correlation 0.79-0.95, measured within 0.02 s, falling by 0.01-0.06 over
0.25 s), while the wheel speed against the GNSS speed peaks at 0.78-0.85, flat within 0.01 over
+-0.5 s and up to 0.3 s off, on the GNSS clock rather than the IMU's."""
MIN_WHEEL_LAG_ACCELERATION_M_S2 = 0.3
MIN_WHEEL_LAG_WINDOWS = 20
"""A shift is judged over at least this many window pairs in which the wheels say the vehicle
accelerated by this much (0.03 g): a few starts and stops, not a standing or cruising
vehicle's noise."""
MIN_WHEEL_LAG_OVERLAP = 0.5
"""and over at least this share of the wheel stream's windows: a minute-long log shifted by
half a minute matched its other half by chance (comma2k19's i280, 0.90 at -34 s)."""
WHEEL_LAG_IMU_HOLE_S = 0.2
"""Window pairs over IMU samples further apart than this are not judged: the specific force
over the hole is not known (a 56 s hole in a stress drive moved a 1 s offset to 1.12 s)."""
WHEEL_LAG_WARN_S = 0.2
"""Wheel stamps this far off the IMU's are named, as the GNSS clock's are: stamped 0.2 s late
they took monaco's proposed truth RMSE from 0.76 to 0.96 m and long_tunnel's from 1.99 to
2.29 m (0.86 and 2.10 m at 0.1 s, 1.11 and 2.59 m at 0.3 s). The samples' and comma2k19's
wheels are measured within 0.02 s of the IMU's clock."""
WHEEL_UNITS = {"km/h": (3.3, 3.9), "mph": (2.1, 2.4), "the wrong sign": (-1.3, -0.7)}
WHEEL_RATIO_OK = (0.8, 1.25)
MIN_WHEEL_PAIRS = 20
WHEEL_STEP_NAMED_M_S = 0.05
"""A wheel speed that comes in steps this coarse (m/s) or coarser is named: its error at a
steady speed is up to half a step, held for as long as the speed is, not noise the filter
averages out (1 km/h, an OBD-II vehicle speed: monaco's routefuse 0.76 -> 3.38 m, and a wider
wheel sigma does not help). The samples step 0.004 m/s, comma2k19's 0.0014."""
MIN_WHEEL_STEP_SAMPLES = 200
VARIANCE_CEILING_M2 = 1e6
VARIANCE_FLOOR_M2 = 1e-6
FAR_FIX_M = 100_000.0
FAR_FIX_SPREADS = 4.0
"""A valid fix farther than both this and this many times the fixes' median distance from
their median position is not where the vehicle was (a receiver's cold-start 0, 0, a corrupt
message): at its straight drive's ends a log's fixes are twice their median distance away."""
OTHER_CLOCK_S = 60.0
"""GNSS or wheel samples stamped further than this outside the IMU's span are on another clock
(or their stream's clock stepped): the filter runs over the IMU's span, so they go unused."""
MAX_LAG_S = OTHER_CLOCK_S
"""Offsets between the IMU's and the GNSS clocks are measured up to this: GNSS time against UTC
(18 s), a receiver stamping its fixes a few seconds late. Further ones are named as another
clock (:func:`_on_the_imu_clock`)."""
GPS_UTC_S = 18.0
"""GPS time runs this far ahead of UTC (the leap seconds since 1980, as of 2017): one stream
stamped in GPS time, the other in UTC."""
CLOCK_STEP_GAP_S = 2.0
CLOCK_STEP_GAP_INTERVALS = 3
"""Valid fixes further apart than both (seconds, median fix intervals) bracket a gap: where a
step of the GNSS clock shows, the stamps leaping while the fixes ran on (or back, into an
outage). Nearer fixes are a receiver's ordinary rate."""
MAX_CLOCK_STEP_GAP_S = 2 * OTHER_CLOCK_S
"""Longer gaps are not judged: over minutes the wheels' scale error and the gyro's drift put
the dead-reckoned track hundreds of metres off, as far as a step of a few seconds would."""
MIN_CLOCK_STEP_S = 2.0
"""A smaller step is within a 1 Hz receiver's stamp resolution and the fixes' noise at town
speeds, and is not named."""
CLOCK_STEP_WINDOW_S = 5.0
CLOCK_STEP_PAIRS = 8
"""Up to this many fixes from this long before a gap and after it are compared, each pair's
distance against the dead-reckoned one: a few seconds of track each side, so that the
dead-reckoning over the pairs is mostly the gap's."""
CLOCK_STEP_SHIFT_S = 0.1
"""the resolution of the step's size"""
CLOCK_STEP_NOISE_M = 8.0
CLOCK_STEP_DRIFT = 0.05
"""A fix pair's distance agrees with the dead-reckoned one within this (m) plus this fraction
of the distance driven: the fixes' metres of noise and re-acquisition jumps, a wheel scale off
by 2 % and the chord of a track bent by a drifting gyro."""
CLOCK_STEP_DISAGREE = 2.0
"""At their stamps the fixes after a step disagree with the wheels and the gyro by more than
this many tolerances (the median over the pairs); shifted by the step, they agree within one."""
MAX_IMU_GAP_IN_STEP_S = 1.0
"""A gap judged needs the IMU without a hole of more than this (s) around it: no dead-reckoning
is made across one."""
HELD_FIX_MIN_S = 2.0
"""Consecutive valid fixes at the very same latitude and longitude for this long are one
position repeated: a receiver that lost its fix and holds the last one with a valid status (some
do through a tunnel), or one in static hold while the vehicle stands. A receiver's own fixes,
moving, are never equal to the last bit for two seconds."""
HELD_FIX_MOVED_M_S = 2.0
"""The repeats are a held fix, not a vehicle standing, when the first fix after them lies this
far per second of their span from the position held (the vehicle drove on; one in static hold
starts near it), or, with no fix after them, the wheels drove that far."""
WHEEL_SCALE_RESCALED = 0.03
"""The clock-step and coasting checks put the wheels on the GNSS speed's scale when their
median ratio to it is off 1 by more than this: a scale the checks' tolerance
(:data:`CLOCK_STEP_DRIFT`) does not hold. Within it the ratio is the fixes' noise as much as
the wheels' (the corpus drive's 29 pairs: 1.002, their 10-90 % 0.97-1.05)."""
COAST_JUMP_M = 30.0
"""Two consecutive valid fixes, no gap between them, farther apart than this (m) beyond what
the wheels drove between them are a jump of the fix stream; it is named when it stays (the
fixes :data:`COAST_SIDE_S` either side of it agree with the wheels among themselves, within
:data:`CLOCK_STEP_NOISE_M`, and disagree across it by this much): a receiver that coasted
through an outage on its own dead reckoning, its status valid and its sigma small, and
re-acquired. The samples' and the stress drives' largest jumps are 7-14 m (re-acquisition at
a portal), comma2k19's and the Husky's 1 m; a 27 m multipath fix comes back at the next."""
COAST_SIDE_S = 3.0
COAST_SIGMA_RISE = 1.5
"""A receiver dead-reckoning says so, when it does, by its variance: the fixes up to a jump
over which the horizontal variance grew steadily (never falling from one fix to the next) by
this factor or more, and over the fixes up to :data:`COAST_SKY_S` after it, the sky back, is
this factor below the jump's, are its coasting, left out of the run. Without it the fixes are
named and kept: which side of the jump is wrong, and since when, the fixes do not say."""
COAST_SKY_S = 10.0
MIN_IMU_INTERVAL_S = 1e-4
"""A median IMU interval below this (over 10 kHz; vehicle IMUs run at up to a few hundred
Hz) is stamps on another time scale: a 75 s drive squeezed into milliseconds."""


@dataclasses.dataclass(frozen=True)
class _GnssMotion:
    """Speed and course between valid fixes about a second apart."""

    t: F64
    """mid-times"""
    dt: F64
    speed: F64
    course: F64
    moving: NDArray[np.bool_]

    def turns(self, span: int = TURN_STEPS) -> tuple[F64, F64, F64]:
        """(start, end, course change) over ``span`` consecutive moving steps: a turn seen
        over seconds stands out of the fixes' noise, a one-second course rate does not."""
        run = np.convolve(self.moving.astype(np.int64), np.ones(span + 1, np.int64), "valid")
        k = np.flatnonzero(run == span + 1)  # every step from k to k + span moving, no gap
        turn = np.angle(np.exp(1j * (self.course[k + span] - self.course[k])))
        return self.t[k], self.t[k + span], turn


def checked(path: Path, log: Log) -> Log:
    """``log`` with the warnings of every check added (and a wheel stream in the wrong units
    left out, fixes with a kilometre of variance made no fixes); refused when no estimate can
    be meaningful."""
    warnings: list[str] = []
    offsets: list[ClockOffset] = []
    _imu_rate(path, log)
    log = _on_the_imu_clock(path, log, warnings)
    gyro_alive = _imu_alive(path, log, warnings)
    _gravity(path, log, warnings)
    log = dataclasses.replace(log, gnss=_far_fixes(path, log, warnings))
    log = dataclasses.replace(log, gnss=_held_fixes(path, log, warnings))
    gnss = _variances(log, warnings)
    log = dataclasses.replace(log, gnss=gnss)
    log = dataclasses.replace(log, gnss=_coasting_fixes(path, log, warnings))
    motion = _gnss_motion(log)
    if motion is not None:
        gyro_alive &= _gyro(path, log, motion, warnings, offsets)
        if log.wheel is not None and not _wheel_plausible(log, motion, warnings):
            log = dataclasses.replace(log, wheel=None)
    if log.wheel is not None:
        _wheel_resolution(path, log, warnings)
    wheel_lag = _wheel_lag(path, log, warnings, offsets) if log.wheel is not None else 0.0
    if gyro_alive:
        # judged against the wheels put on the IMU's clock: 45 s early, they made monaco's
        # GNSS clock step 3.8 s
        judged = log
        if log.wheel is not None and wheel_lag:
            judged = dataclasses.replace(
                log, wheel=dataclasses.replace(log.wheel, t=log.wheel.t - wheel_lag)
            )
        log = dataclasses.replace(log, gnss=_clock_step(path, judged, warnings, motion))
    if offsets:
        log = dataclasses.replace(log, clock_offsets=(*log.clock_offsets, *offsets))
    if not warnings:
        return log
    return dataclasses.replace(log, warnings=(*log.warnings, *warnings))


CLOCK_SETTING_TOLERANCE_S = LAG_WARN_S
"""A configured clock offset within this of the one measured is taken as that one: an offset
this small is not named when nothing is configured either (:data:`LAG_WARN_S`,
:data:`WHEEL_LAG_WARN_S`)."""


def configured_clock_warnings(log: Log, configured: Mapping[str, float]) -> tuple[str, ...]:
    """The log's warnings for a run with the clock offsets ``configured`` (setting -> s): the
    load's line for an offset the run is set to correct is dropped (it read "set X = v" after
    the user had), and a setting the measured offset contradicts is named (a configured 1.5 s
    on a log whose clocks agree went unsaid)."""
    out = [w for w in log.warnings if w not in {o.warning for o in log.clock_offsets}]
    for o in log.clock_offsets:
        setting = configured.get(o.setting, 0.0)
        if abs(setting - o.offset_s) < CLOCK_SETTING_TOLERANCE_S:
            continue
        if setting == 0.0 and o.warning:
            out.append(o.warning)
            continue
        agrees = abs(o.offset_s) < CLOCK_SETTING_TOLERANCE_S
        measured = (
            f"agrees with the IMU's ({o.offset_s:+.2f} s as measured)"
            if agrees
            else f"is {o.offset_s:+.2f} s off the IMU's as measured"
        )
        out.append(
            f"{Path(log.path).name}: {o.stream}: its clock {measured}, where the run is "
            f"configured with {o.setting} = {setting:.2f}: set {o.setting} = "
            f"{0.0 if agrees else o.offset_s:.2f}"
        )
    return tuple(out)


def in_bulk(lat: F64, lon: F64) -> NDArray[np.bool_]:
    """Which of the positions (degrees, finite) agree with the bulk of them: within
    :data:`FAR_FIX_M` (or :data:`FAR_FIX_SPREADS` times their median distance) of their
    median. The session frame is placed at the first of them and the rest are left out
    (:func:`_far_fixes`); a first fix at 0, 0 would put the frame, and every route and fix
    in it, thousands of km off."""
    everyone = np.ones(len(lat), bool)
    if len(lat) < 3:
        return everyone
    d = _from_median_m(lat, lon)
    bulk: NDArray[np.bool_] = d <= max(FAR_FIX_M, FAR_FIX_SPREADS * float(np.median(d)))
    return bulk if 2 * np.count_nonzero(bulk) > len(lat) else everyone


def _from_median_m(lat: F64, lon: F64) -> F64:
    """Great-circle distance of each position from their median latitude and longitude."""
    return great_circle_m(float(np.median(lat)), float(np.median(lon)), lat, lon)


def topic_of(log: Log, role: str) -> str:
    """The topic the log's ``role`` stream (``'imu'``, ``'gnss'``, ``'wheel'``) was read from."""
    return next((t.topic for t in log.topics if t.role == role), role)


def _far_fixes(path: Path, log: Log, warnings: list[str]) -> GnssData:
    """The fixes with those far from the bulk of the log's (:func:`in_bulk`) made no fix,
    named in one line."""
    g = log.gnss
    ok = np.flatnonzero(g.valid)
    far = ~in_bulk(g.lat[ok], g.lon[ok])
    if not far.any():
        return g
    km = _from_median_m(g.lat[ok], g.lon[ok])[far] / 1000.0
    n = int(far.sum())
    t = g.t[ok[far]] - log.t_start
    at = f"{t[0]:.1f} s" if n == 1 else f"{t.min():.1f}-{t.max():.1f} s"
    away = f"{km[0]:.0f} km" if n == 1 else f"{km.min():.0f}-{km.max():.0f} km"
    warnings.append(
        f"{path.name}: GNSS {topic_of(log, 'gnss')}: {n} fix{'es' if n > 1 else ''} at {at}, "
        f"{away} from the bulk of the log's fixes, left out of the run (a receiver's "
        "cold-start position such as 0, 0, or corrupt messages)"
    )
    status = g.status.copy()
    status[ok[far]] = -1
    return dataclasses.replace(g, status=status)


def _held_fixes(path: Path, log: Log, warnings: list[str]) -> GnssData:
    """The fixes that repeat the position of the fix before them while the vehicle drove on
    (:data:`HELD_FIX_MIN_S`, :data:`HELD_FIX_MOVED_M_S`) made no fix, named in one line each
    (:func:`~estimator.errors.named_and_summed`); the first of the repeated position, the
    receiver's last real fix, is kept. Without this a receiver holding its last fix through the
    long tunnel gave no outage (so no route update) and pulled the estimate back to the
    portal: 4.5 km RMS in the tunnel, the only warning a low share of fixes used."""
    g = log.gnss
    ok = np.flatnonzero(g.valid)
    if len(ok) < 3:
        return g
    t, lat, lon = g.t[ok], g.lat[ok], g.lon[ok]
    repeats = np.r_[False, (lat[1:] == lat[:-1]) & (lon[1:] == lon[:-1]), False]
    edges = np.flatnonzero(np.diff(repeats.astype(np.int8)))
    held: list[tuple[int, int, float, float]] = []
    for first, last in zip(edges[::2], edges[1::2], strict=True):
        span = float(t[last] - t[first])
        if span < HELD_FIX_MIN_S:
            continue
        after = last + 1
        if after < len(ok):
            moved = float(great_circle_m(lat[first], lon[first], lat[after], lon[after]))
            over = float(t[after] - t[first])
        elif log.wheel is not None and len(log.wheel.t) > 1:
            moved, over = _wheel_distance(log, float(t[first]), float(t[last])), span
        else:
            continue
        if moved >= HELD_FIX_MOVED_M_S * over:
            held.append((first, last, moved, over))
    if not held:
        return g
    rel = g.t - log.t_start
    named, summed = named_and_summed(held)
    topic = topic_of(log, "gnss")
    for first, last, moved, over in named:
        warnings.append(
            f"{path.name}: GNSS {topic}: the {last - first} fixes stamped "
            f"{rel[ok[first + 1]]:.1f}-{rel[ok[last]]:.1f} s repeat the position of the fix at "
            f"{rel[ok[first]]:.1f} s while the vehicle drove on ({moved:.0f} m in {over:.1f} s): "
            "a receiver holding its last fix (in a tunnel?); left out of the run, which takes "
            "them as an outage"
        )
    if summed:
        n = sum(last - first for first, last, _, _ in summed)
        warnings.append(
            f"{path.name}: GNSS {topic}: ... and {len(summed)} more stretches repeating a fix "
            f"while the vehicle drove on, {rel[ok[summed[0][0]]]:.1f}-"
            f"{rel[ok[summed[-1][1]]]:.1f} s ({n} fixes), left out of the run"
        )
    status = g.status.copy()
    for first, last, _, _ in held:
        status[ok[first + 1 : last + 1]] = -1
    return dataclasses.replace(g, status=status)


def _coasting_fixes(path: Path, log: Log, warnings: list[str]) -> GnssData:
    """Name a jump of the fix stream that stays (:data:`COAST_JUMP_M`); leave the fixes before
    it out when the receiver's own variance says it coasted there (:data:`COAST_SIGMA_RISE`).
    Some receivers go on through a tunnel on their own dead reckoning with a valid status:
    there was no outage, so no route update, and the filter followed their drift; monaco's
    tunnel so coasting (3 % and 0.1 deg/s) ran 71 m RMS off, the long tunnel 1094 m, with not
    one warning. Only the jump when the sky comes back shows it: 148 m and 2436 m in 0.2 s."""
    g = log.gnss
    ok = np.flatnonzero(g.valid)
    if log.wheel is None or len(ok) < 10:
        return g
    t = g.t[ok]
    dt = np.diff(t)
    unbroken = dt <= _fix_gap_s(dt)
    xy = _fixes_xy(g, ok)
    judged = _wheels_on_the_gnss_scale(log, _gnss_motion(log))
    w = judged.wheel
    assert w is not None
    driven = np.r_[0.0, np.cumsum(0.5 * np.abs(w.speed[1:] + w.speed[:-1]) * np.diff(w.t))]
    at = np.interp(t, w.t, driven)
    jump = np.linalg.norm(np.diff(xy, axis=0), axis=1) - np.diff(at)
    var = g.cov_enu[ok, 0] + g.cov_enu[ok, 1]
    status = g.status
    rel = g.t - log.t_start
    for c in np.flatnonzero(unbroken & (jump > COAST_JUMP_M))[:10]:
        if not _stays(judged, t, xy, int(c)):
            continue
        head = (
            f"{path.name}: GNSS {topic_of(log, 'gnss')}: its fixes jump "
            f"{jump[c] + at[c + 1] - at[c]:.0f} m from {rel[ok[c]]:.1f} to "
            f"{rel[ok[c + 1]]:.1f} s, where the wheels drove {at[c + 1] - at[c]:.1f} m, and "
            "stay there (the wheels and the gyro agree with the fixes either side of it): "
        )
        first = _coast_onset(t, var, int(c), unbroken)
        if first is not None:
            warnings.append(
                head + f"their variance grew steadily from {rel[ok[first]]:.1f} s (a sigma of "
                f"{math.sqrt(var[first] / 2):.2f} m) to the jump ({math.sqrt(var[c] / 2):.2f} "
                "m) and fell back after it, a receiver coasting on its own dead reckoning with a "
                f"valid status (through a tunnel?); the {c + 1 - first} fixes stamped "
                f"{rel[ok[first]]:.1f}-{rel[ok[c]]:.1f} s are left out of the run, which takes "
                "them as an outage"
            )
            status = status.copy()
            status[ok[first : c + 1]] = -1
            continue
        said = f"{math.sqrt(var[c] / 2):.2f} m" if np.isfinite(var[c]) else "unknown"
        warnings.append(
            head + f"the fixes before it (their status valid, their sigma {said}) were off by "
            "that much, a receiver coasting on its own dead reckoning (through a tunnel?) and "
            "re-acquiring, or those after it are (a step: another datum or base station). The "
            "run takes them as fixes, with no outage there; if the receiver coasted, give the "
            f"span it did as an outage (--outage START:{rel[ok[c]]:.1f})"
        )
    return g if status is g.status else dataclasses.replace(g, status=status)


def _fix_gap_s(dt: F64) -> float:
    """Valid fixes further apart than this (``dt``: their intervals) bracket a gap
    (:data:`CLOCK_STEP_GAP_S`, :data:`CLOCK_STEP_GAP_INTERVALS`)."""
    return max(CLOCK_STEP_GAP_S, CLOCK_STEP_GAP_INTERVALS * float(np.median(dt)))


def _fixes_xy(g: GnssData, ok: NDArray[np.intp]) -> F64:
    """The fixes ``ok`` east and north (N, 2), m, in a frame at the first of them."""
    xy: F64 = LocalFrame.at(g.lat[ok], g.lon[ok], g.alt[ok]).to_enu(g.lat[ok], g.lon[ok])[:, :2]
    return xy


def _coast_onset(t: F64, var: F64, c: int, unbroken: NDArray[np.bool_]) -> int | None:
    """The first fix of the run up to ``c`` over which the fixes' horizontal variance ``var``
    grew steadily to :data:`COAST_SIGMA_RISE` times its first value or more, when the fixes
    up to :data:`COAST_SKY_S` after the jump following ``c`` fall back below the jump's by the
    same factor: a receiver saying, by its variance, that it coasted. None otherwise."""
    if not np.isfinite(var[c]):
        return None
    first = c
    while first > 0 and unbroken[first - 1] and var[first - 1] <= var[first]:
        first -= 1
    sky = var[(t > t[c]) & (t <= t[c + 1] + COAST_SKY_S)]
    if var[c] < COAST_SIGMA_RISE * var[first] or not np.all(
        np.isfinite(sky) & (COAST_SIGMA_RISE * sky <= var[c])
    ):
        return None
    return first


def _stays(log: Log, t: F64, xy: F64, c: int) -> bool:
    """Whether the jump of the fixes after valid fix ``c`` (stamps ``t``, positions ``xy``)
    stays: the dead-reckoned track, laid on the fixes :data:`COAST_SIDE_S` either side of it
    (turned and moved onto them in the plane), passes within :data:`CLOCK_STEP_NOISE_M` of
    each side's fixes, and the track laid on those before it misses those after it by
    :data:`COAST_JUMP_M` or more. A fix that jumped and came back, or noise, does not stay. In
    the plane, not by distances alone: a coasting receiver's error along the road cancels in a
    pair's distance at some separation."""
    before = np.flatnonzero((t >= t[c] - COAST_SIDE_S) & (t <= t[c]))
    after = np.flatnonzero((t > t[c]) & (t <= t[c + 1] + COAST_SIDE_S))
    dr = _DeadReckoning.over(log, float(t[before[0]]), float(t[after[-1]]))
    if dr is None:
        return False
    p, driven, inside = dr.at(t)
    before, after = before[inside[before]], after[inside[after]]
    if len(before) < 3 or len(after) < 3:
        return False
    if min(driven[before[-1]] - driven[before[0]], driven[after[-1]] - driven[after[0]]) < (
        COAST_SIDE_S * MOVING_M_S
    ):
        return False  # too little track either side to turn it onto the fixes
    on_before = _laid_on(p[before], xy[before])
    on_after = _laid_on(p[after], xy[after])

    def off(fixes: NDArray[np.intp], laid: Callable[[F64], F64]) -> float:
        return float(np.median(np.linalg.norm(xy[fixes] - laid(p[fixes]), axis=1)))

    return (
        off(before, on_before) <= CLOCK_STEP_NOISE_M
        and off(after, on_after) <= CLOCK_STEP_NOISE_M
        and off(after, on_before) >= COAST_JUMP_M
    )


def _laid_on(track: F64, fixes: F64) -> Callable[[F64], F64]:
    """The rigid motion of the plane (a turn and a shift) taking the dead-reckoned points
    ``track`` closest to ``fixes`` (least squares), as a function of points."""
    mt, mf = track.mean(axis=0), fixes.mean(axis=0)
    h = (track - mt).T @ (fixes - mf)
    angle = float(np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1]))
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])

    def laid(points: F64) -> F64:
        out: F64 = (points - mt) @ rot.T + mf
        return out

    return laid


def _wheel_distance(log: Log, t0: float, t1: float) -> float:
    """The distance the wheels say was driven from ``t0`` to ``t1`` (s, log stamps)."""
    w = log.wheel
    assert w is not None
    t = np.r_[t0, w.t[(w.t > t0) & (w.t < t1)], t1]
    v = np.abs(np.interp(t, w.t, w.speed))
    return float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(t)))


def _imu_rate(path: Path, log: Log) -> None:
    """Refuse IMU stamps on another time scale than the other streams' seconds: the drive
    would be integrated over milliseconds, with no fix inside it."""
    t = log.imu.t
    step = float(np.median(np.diff(t)))
    if step >= MIN_IMU_INTERVAL_S:
        return
    g = log.gnss.t
    raise LogError(
        path,
        f"IMU {topic_of(log, 'imu')}: its {len(t)} samples are stamped within "
        f"{float(t[-1] - t[0]) * 1e3:.3g} ms (a median interval of {step * 1e6:.3g} us), while "
        f"GNSS spans {float(g[-1] - g[0]):.1f} s: its stamps are not in seconds, or its clock "
        "runs at another rate; no estimate can be made",
    )


def _on_the_imu_clock(path: Path, log: Log, warnings: list[str]) -> Log:
    """GNSS and wheel samples stamped more than :data:`OTHER_CLOCK_S` outside the IMU's span
    named in one line a stream: fixes after a step of the GNSS clock are left out; a wheel
    stream wholly outside goes unused (:func:`estimator.filter.setup.prepare_inputs` runs
    without a wheel stream that does not overlap the IMU). Without this the run went on in
    silence: GNSS stamped two days late mid-log showed as a 48-hour outage, a wheel stream
    an hour late was an IMU-and-GNSS run with the parameters of one with wheels."""
    g = log.gnss
    out = off_the_imu_clock(log.imu.t, g.t)
    if out.any() and not out.all():
        warnings.append(_off_clock(path, log, "GNSS", g.t, out, "left out of the run"))
        keep = ~out
        log = dataclasses.replace(
            log,
            gnss=GnssData(
                g.t[keep], g.lat[keep], g.lon[keep], g.alt[keep], g.status[keep], g.cov_enu[keep]
            ),
        )
    w = log.wheel
    if w is not None and len(w.t):
        out = off_the_imu_clock(log.imu.t, w.t)
        if out.all():
            warnings.append(_off_clock(path, log, "wheel", w.t, out, "IMU and GNSS only"))
        elif out.any():
            warnings.append(_off_clock(path, log, "wheel", w.t, out, "unused"))
    return log


def off_the_imu_clock(imu_t: F64, t: F64) -> NDArray[np.bool_]:
    """Which of the stamps ``t`` lie more than :data:`OTHER_CLOCK_S` outside the IMU's span."""
    out: NDArray[np.bool_] = (t < imu_t[0] - OTHER_CLOCK_S) | (t > imu_t[-1] + OTHER_CLOCK_S)
    return out


def _off_clock(path: Path, log: Log, role: str, t: F64, out: NDArray[np.bool_], what: str) -> str:
    """One line naming the samples of ``role`` stamped outside the IMU's span, and a step of
    the stream's clock that put them there."""
    rel = t - log.t_start
    k = int(np.argmax(out))
    step = ""
    if k > 0 and rel[k] - rel[k - 1] > OTHER_CLOCK_S:
        step = f"its clock steps {rel[k] - rel[k - 1]:.1f} s forward after {rel[k - 1]:.1f} s; "
    n = int(out.sum())
    many = f"all {n}" if n == len(t) else f"{n} of its {len(t)}"
    unit = {"GNSS": "fixes", "wheel": "samples"}[role]
    stamped = f"{float(rel[out].min()):.1f}-{float(rel[out].max()):.1f} s"
    return (
        f"{path.name}: {role} {topic_of(log, role.lower())}: {step}{many} {unit} are stamped "
        f"{stamped}, more than {OTHER_CLOCK_S:g} s outside the IMU's 0.0-"
        f"{log.t_end - log.t_start:.1f} s (another clock, or a step of it): {what}"
    )


@dataclasses.dataclass(frozen=True)
class _DeadReckoning:
    """The track the wheel speed and the yaw rate draw over a stretch of the IMU's span: its
    shape only (it starts at 0, 0, heading along x), which distances between its points
    compare with the distances between fixes whatever the heading."""

    t: F64
    xy: F64
    """(N, 2) m"""
    driven: F64
    """(N,) distance driven since the start, m"""

    @classmethod
    def over(cls, log: Log, t0: float, t1: float) -> _DeadReckoning | None:
        """The track over ``t0``-``t1`` (cut to the IMU's and the wheels' spans); None without
        wheels, or with a hole in either stream there."""
        w, imu = log.wheel, log.imu
        if w is None or len(w.t) < 2:
            return None
        t0, t1 = max(t0, float(w.t[0]), log.t_start), min(t1, float(w.t[-1]), log.t_end)
        k = slice(int(np.searchsorted(imu.t, t0)), int(np.searchsorted(imu.t, t1, "right")))
        t = imu.t[k]
        wk = slice(int(np.searchsorted(w.t, t0)), int(np.searchsorted(w.t, t1, "right")))
        if len(t) < 2 or np.max(np.diff(t)) > MAX_IMU_GAP_IN_STEP_S:
            return None
        if np.max(np.diff(w.t[wk]), initial=0.0) > wheel_gap_s(w.t):
            return None
        heading = _running_integral(t, imu.gyro[k] @ _gravity_up(imu.accel[k]))
        dt = np.diff(t)
        speed = np.interp(t, w.t, w.speed)
        step = 0.5 * (speed[1:] + speed[:-1]) * dt
        mid = 0.5 * (heading[1:] + heading[:-1])
        xy = np.vstack([np.zeros((1, 2)), np.cumsum(step[:, None] * _unit(mid), axis=0)])
        return cls(t, xy, np.r_[0.0, np.cumsum(np.abs(step))])

    def at(self, t: F64) -> tuple[F64, F64, NDArray[np.bool_]]:
        """Position (..., 2), distance driven and whether inside the track's span, at ``t``."""
        xy = np.stack([np.interp(t, self.t, self.xy[:, i]) for i in (0, 1)], axis=-1)
        inside: NDArray[np.bool_] = (t >= self.t[0]) & (t <= self.t[-1])
        return xy, np.interp(t, self.t, self.driven), inside


def _unit(angle: F64) -> F64:
    out: F64 = np.column_stack([np.cos(angle), np.sin(angle)])
    return out


def _clock_step(path: Path, log: Log, warnings: list[str], motion: _GnssMotion | None) -> GnssData:
    """The fixes with those after a step of the GNSS clock (under :data:`OTHER_CLOCK_S`:
    larger ones leave the fixes outside the IMU's span, :func:`_on_the_imu_clock`) made no
    fix, named in one line. A step shows at a gap between fixes (the stamps leaping forward
    while the fixes ran on, or back into an outage): the distances from the fixes before it to
    those after it are not those the wheels and the gyro say were driven between their stamps,
    and they are once the fixes after it are moved by the step. Without this the filter took
    every fix after a 20 s step at the wrong time, 300 m off, or a fake outage, in silence.
    The fixes are left out rather than moved back: the step is measured to a tenth of a second
    against a dead-reckoning, whose error would go into every fix moved. ``motion``: the
    fixes' (:func:`_gnss_motion`), which put the wheels on the GNSS speed's scale."""
    g = log.gnss
    ok = np.flatnonzero(g.valid)
    if log.wheel is None or len(ok) < 2:
        return g
    t = g.t[ok]
    dt = np.diff(t)
    gap = _fix_gap_s(dt)
    gaps = np.flatnonzero((dt > gap) & (dt <= MAX_CLOCK_STEP_GAP_S))
    if not len(gaps):
        return g
    xy = _fixes_xy(g, ok)
    judged = _wheels_on_the_gnss_scale(log, motion)
    for a in gaps:
        shift = _step_at(judged, t, xy, int(a))
        if shift is None:
            continue
        rel = g.t - log.t_start
        after = ok[a + 1 :]
        direction = "forward" if shift > 0 else "back"
        warnings.append(
            f"{path.name}: GNSS {topic_of(log, 'gnss')}: its clock steps {abs(shift):.1f} s "
            f"{direction} after {rel[ok[a]]:.1f} s (the fixes after it lie where the wheels and "
            f"the gyro put the vehicle {abs(shift):.1f} s {'before' if shift > 0 else 'after'} "
            f"their stamps); the {len(after)} fixes stamped {rel[after[0]]:.1f}-"
            f"{rel[after[-1]]:.1f} s are left out of the run"
        )
        status = g.status.copy()
        status[after] = -1
        return dataclasses.replace(g, status=status)
    return g


def _wheels_on_the_gnss_scale(log: Log, m: _GnssMotion | None) -> Log:
    """``log`` with its wheel speed divided by its median ratio to the GNSS speed while moving
    (within :data:`WHEEL_RATIO_OK`: a wheel radius or a tyre off by up to a quarter, which the
    filter estimates as a state), when that ratio is off 1 by more than
    :data:`WHEEL_SCALE_RESCALED`. The clock-step check dead-reckons with the wheels over up to
    two minutes and more: uncorrected, monaco's wheels reading 15 % fast (a tyre, a radius
    configured wrong) made its tunnel's 1600 m look 20.7 s too short, named as a GNSS clock
    step, and every fix after the tunnel was left out."""
    w = log.wheel
    if w is None or m is None:
        return log
    ratio = _wheel_speed_ratio(w, m)
    if (
        ratio is None
        or abs(ratio - 1.0) <= WHEEL_SCALE_RESCALED
        or not (WHEEL_RATIO_OK[0] <= ratio <= WHEEL_RATIO_OK[1])
    ):
        return log
    return dataclasses.replace(log, wheel=dataclasses.replace(w, speed=w.speed / ratio))


def _step_at(log: Log, t: F64, xy: F64, a: int) -> float | None:
    """The step of the GNSS clock (s, + forward) across the gap after valid fix ``a``
    (stamps ``t``, positions ``xy``), or None when the fixes agree with the wheels and the
    gyro at their stamps, or no step makes them agree."""
    before = np.flatnonzero((t <= t[a]) & (t >= t[a] - CLOCK_STEP_WINDOW_S))
    after = np.flatnonzero((t > t[a]) & (t <= t[a + 1] + CLOCK_STEP_WINDOW_S))
    i = before[np.linspace(0, len(before) - 1, min(len(before), CLOCK_STEP_PAIRS)).astype(int)]
    j = after[np.linspace(0, len(after) - 1, min(len(after), CLOCK_STEP_PAIRS)).astype(int)]
    dr = _DeadReckoning.over(log, float(t[i[0]]), float(t[j[-1]]) + OTHER_CLOCK_S)
    if dr is None:
        return None
    n = round(OTHER_CLOCK_S / CLOCK_STEP_SHIFT_S)
    if _step_misfit(dr, t, xy, a, i, j, np.zeros(1))[0] <= CLOCK_STEP_DISAGREE:
        return None
    steps = CLOCK_STEP_SHIFT_S * np.arange(-n, n + 1, dtype=np.float64)
    score = _step_misfit(dr, t, xy, a, i, j, steps)
    best = int(np.argmin(score))
    shift = float(steps[best])
    if score[best] <= 1.0 and abs(shift) >= MIN_CLOCK_STEP_S:
        return shift
    return None


def _step_misfit(
    dr: _DeadReckoning,
    t: F64,
    xy: F64,
    a: int,
    i: NDArray[np.intp],
    j: NDArray[np.intp],
    steps: F64,
) -> F64:
    """For each trial step: the median over the pairs of fixes ``i`` (before the gap after fix
    ``a``) and ``j`` (after it, taken ``step`` before their stamps) of their distance's misfit
    to the dead-reckoned one, in tolerances; inf where fewer than 3 pairs lie in the track."""
    apart = np.linalg.norm(xy[j][None, :, :] - xy[i][:, None, :], axis=-1)  # (I, J)
    p_i, d_i, in_i = dr.at(t[i])
    taken = t[j][None, :] - steps[:, None]  # (M, J)
    p_j, d_j, in_j = dr.at(taken)
    driven_apart = np.linalg.norm(p_j[:, None, :, :] - p_i[None, :, None, :], axis=-1)
    tolerance = CLOCK_STEP_NOISE_M + CLOCK_STEP_DRIFT * np.abs(d_j[:, None, :] - d_i[None, :, None])
    usable = (in_j & (taken > t[a]))[:, None, :] & in_i[None, :, None]
    misfit = np.where(usable, np.abs(driven_apart - apart[None]) / tolerance, np.inf)
    count = np.count_nonzero(usable.reshape(len(steps), -1), axis=1)
    ordered = np.sort(misfit.reshape(len(steps), -1), axis=1)
    median = ordered[np.arange(len(steps)), np.maximum(count - 1, 0) // 2]
    out: F64 = np.where(count >= 3, median, np.inf)
    return out


def _span(log: Log, t: F64) -> str:
    t0 = log.t_start
    return f"{float(t.min()) - t0:.1f}-{float(t.max()) - t0:.1f} s"


def _imu_alive(path: Path, log: Log, warnings: list[str]) -> bool:
    """Refuse an IMU without accelerations (nothing to dead-reckon with); name a gyro, or an
    axis, that reads exactly zero throughout. A ROS driver that does not fill
    ``angular_velocity`` (its covariance -1) publishes zeros: the heading then follows only
    the fixes, an outage is dead-reckoned straight on, and the run's own warnings (few fixes
    used, every match refused, a huge accelerometer bias) never said why. False when the gyro
    cannot be dead-reckoned with (frozen, or a dead axis)."""
    v = np.hstack([log.imu.gyro, log.imu.accel])
    if not np.any(v):
        raise LogError(path, "IMU: every sample is zero (a dead or unconnected sensor)")
    if np.all(np.ptp(v, axis=0) == 0):
        warnings.append(
            "IMU: every sample is the same, without any noise (a frozen sensor, or simulated)"
        )
        return False
    topic = topic_of(log, "imu")
    if not np.any(log.imu.accel):
        raise LogError(
            path,
            f"IMU {topic}: every linear_acceleration sample is zero (a driver that does not "
            "fill it, or a dead accelerometer): nothing to dead-reckon with",
        )
    dead = ~np.any(v, axis=0)
    if dead[:3].all():
        warnings.append(
            f"{path.name}: IMU {topic}: every angular_velocity sample is zero (a driver that "
            "does not fill it, or a dead gyro): the heading follows only the fixes, and an "
            "outage is dead-reckoned straight on"
        )
    elif dead.any():
        axes = ", ".join(f"{kind} {axis}" for k, (kind, axis) in enumerate(_IMU_AXES) if dead[k])
        warnings.append(
            f"{path.name}: IMU {topic}: every sample of its {axes} axis is zero (a dead axis, "
            "or a driver that does not fill it): the estimate is wrong wherever that axis moves"
        )
    return not dead[:3].any()


_IMU_AXES = tuple((kind, axis) for kind in ("gyro", "accelerometer") for axis in "xyz")


def _gravity(path: Path, log: Log, warnings: list[str]) -> None:
    f = float(np.median(np.linalg.norm(log.imu.accel, axis=1)))
    if G_UNITS[0] <= f <= G_UNITS[1]:
        raise LogError(
            path,
            f"IMU accelerations look like g, not m/s^2 (median |f| = {f:.2f}, gravity is "
            f"{GRAVITY:.2f} m/s^2): scale linear_acceleration by {GRAVITY}",
        )
    if not PLAUSIBLE_GRAVITY[0] <= f <= PLAUSIBLE_GRAVITY[1]:
        warnings.append(
            f"IMU: median |specific force| {f:.2f} m/s^2, far from gravity's {GRAVITY:.2f}: "
            "wrong units or a faulty accelerometer"
        )


def _variances(log: Log, warnings: list[str]) -> GnssData:
    g = log.gnss
    cov = g.cov_enu
    with np.errstate(invalid="ignore"):
        huge = g.valid & np.any(cov > VARIANCE_CEILING_M2, axis=1)
        tiny = g.valid & np.any(cov < VARIANCE_FLOOR_M2, axis=1)
    if tiny.any():
        warnings.append(
            f"GNSS: {int(tiny.sum())} fixes claim a variance below {VARIANCE_FLOOR_M2:g} m^2 "
            f"(at {_span(log, g.t[tiny])}); the filter's noise.gnss_sigma_floor_m applies"
        )
    if not huge.any():
        return g
    warnings.append(
        f"GNSS: {int(huge.sum())} fixes claim a variance above {VARIANCE_CEILING_M2:g} m^2 "
        f"(a kilometre; at {_span(log, g.t[huge])}): treated as no fix"
    )
    status = g.status.copy()
    status[huge] = -1
    return dataclasses.replace(g, status=status)


def _gnss_motion(log: Log) -> _GnssMotion | None:
    g = log.gnss
    ok = g.valid
    if np.count_nonzero(ok) < 10:
        return None
    # about one fix a second: at 5-20 Hz a metre of fix noise over a few metres of travel is
    # tenths of a radian of course, and its rate would be noise
    t_all = g.t[ok]
    pick = np.flatnonzero(np.diff(np.floor(t_all - t_all[0]), prepend=-1.0) > 0)
    t = t_all[pick]
    lat, lon, alt = g.lat[ok][pick], g.lon[ok][pick], g.alt[ok][pick]
    if len(t) < 10:
        return None
    xy = LocalFrame.at(lat, lon, alt).to_enu(lat, lon)[:, :2]
    dt = np.diff(t)
    step = np.diff(xy, axis=0)
    close = (dt > 0) & (dt <= 2.5)
    speed = np.where(close, np.hypot(*step.T) / np.where(close, dt, 1.0), np.nan)
    course = np.unwrap(np.arctan2(step[:, 1], step[:, 0]))
    # a fix that jumps (re-acquisition after a tunnel, multipath) shows as a speed jump
    steady = np.abs(np.diff(speed, prepend=np.nan)) < MAX_SPEED_JUMP_M_S
    steady &= np.abs(np.diff(speed, append=np.nan)) < MAX_SPEED_JUMP_M_S
    moving = close & (speed > MOVING_M_S) & steady
    return _GnssMotion(0.5 * (t[1:] + t[:-1]), dt, speed, course, moving)


def _mean_over(t: F64, v: F64, t0: F64, t1: F64) -> F64:
    """Mean of a sampled signal over each interval (its running integral's difference)."""
    c = _running_integral(t, v)
    width = np.maximum(t1 - t0, 1e-9)
    out: F64 = (np.interp(t1, t, c) - np.interp(t0, t, c)) / width
    return out


@dataclasses.dataclass(frozen=True)
class _LagPeak:
    """The shift (s) at which one stream's signal correlates best with another's on a grid of
    shifts, either way round (a yaw rate of the opposite sign correlates as well, negatively),
    against the best one further than :data:`LAG_PEAK_WINDOW_S` from it: the gyro's turns
    against the GNSS course's (+ the IMU's later, :func:`_gyro`), the wheel speed's changes
    against the IMU's specific force (+ the wheels' later, :func:`_wheel_lag`)."""

    shift: float
    correlation: float
    """signed: negative for a yaw rate of the opposite sign"""
    rival_shift: float
    rival_correlation: float
    """magnitude; -inf without a shift that far"""
    at_zero: float
    """magnitude as stamped"""
    inside: bool
    """the grid and the turns overlapping the IMU go on either side of the shift"""

    @property
    def clear(self) -> bool:
        c = abs(self.correlation)
        return (
            self.inside
            and c >= MIN_LAG_CORRELATION
            and c - self.rival_correlation >= LAG_PEAK_MARGIN
        )

    @property
    def ambiguous(self) -> bool:
        """Matches far apart, none of them as stamped: the offset cannot be told."""
        c = abs(self.correlation)
        return (
            not self.clear
            and self.inside
            and min(c, self.rival_correlation) >= MIN_LAG_CORRELATION
            and self.at_zero < c - LAG_PEAK_MARGIN
        )

    @classmethod
    def of(cls, shifts: F64, corr: F64) -> _LagPeak | None:
        score = np.abs(corr)
        if np.all(np.isnan(score)):
            return None
        best = int(np.nanargmax(score))
        far = (np.abs(shifts - shifts[best]) > LAG_PEAK_WINDOW_S) & ~np.isnan(score)
        rival = int(np.argmax(np.where(far, score, -np.inf)))
        return cls(
            shift=float(shifts[best]),
            correlation=float(corr[best]),
            rival_shift=float(shifts[rival]),
            rival_correlation=float(score[rival]) if far.any() else -math.inf,
            at_zero=float(np.nan_to_num(np.interp(0.0, shifts, score))),
            inside=0 < best < len(score) - 1 and not np.isnan(score[[best - 1, best + 1]]).any(),
        )


def _coarse_shifts() -> F64:
    """The grid an offset between two clocks is searched on first: :data:`LAG_COARSE_STEP_S`
    apart within :data:`MAX_LAG_S`."""
    n = round(MAX_LAG_S / LAG_COARSE_STEP_S)
    out: F64 = LAG_COARSE_STEP_S * np.arange(-n, n + 1, dtype=np.float64)
    return out


def _fine_shifts(at: float) -> F64:
    """The grid it is measured on then: :data:`LAG_STEP_S` apart, over a coarse step either
    side of the best coarse shift ``at``."""
    n = int(LAG_COARSE_STEP_S / LAG_STEP_S)
    fine = at + LAG_STEP_S * np.arange(-n, n + 1, dtype=np.float64)
    out: F64 = fine[np.abs(fine) <= MAX_LAG_S]
    return out


def _gyro(
    path: Path, log: Log, m: _GnssMotion, warnings: list[str], offsets: list[ClockOffset]
) -> bool:
    """The gyro's units, scale and sign, and the offset of the GNSS clock against the IMU's,
    from its turns against the GNSS course's over :data:`TURN_STEPS` s windows; False when its
    scale is wrong (:func:`_gyro_scale`), so that no other check dead-reckons with it. The
    offset is searched within :data:`MAX_LAG_S`, on a coarse grid and then a fine one around
    its best, and the units and sign are judged at that offset (the best of several on a route
    that repeats itself, as stamped when the turns match nowhere): 18 s apart, the yaw rate as
    stamped was the opposite of the course on a road swerving every 40 s. Before, the search
    went to 1 s: a 1.5 s or 5 s offset was named as 1.00 s, its edge, and 18 s (GPS time
    against UTC) not at all, while the run drifted 234 m off."""
    t0, t1, turn = m.turns()
    turning = np.abs(turn) > MIN_TURN_WINDOW_RAD
    if np.sum(np.abs(turn)) < MIN_TURN_RAD or np.count_nonzero(turning) < 5:
        return True
    it = log.imu.t
    heading = _running_integral(it, log.imu.gyro[:, 2])

    def imu_turn(shifts: F64) -> tuple[F64, NDArray[np.bool_]]:
        """The IMU's heading change over each window taken ``shift`` later (M, N), and which of
        those windows lie inside the IMU's span."""
        a, b = t0[None, :] + shifts[:, None], t1[None, :] + shifts[:, None]
        inside: NDArray[np.bool_] = (a >= it[0]) & (b <= it[-1])
        out: F64 = np.interp(b, it, heading) - np.interp(a, it, heading)
        return out, inside

    def correlations(shifts: F64, use: NDArray[np.bool_]) -> F64:
        """Per shift, over the windows ``use`` marks that lie inside the IMU's span; NaN where
        those turn too little to judge."""
        out = np.full(len(shifts), np.nan)
        for k in range(0, len(shifts), 64):  # (64, N) at a time: an hour's windows in 2 MB
            g, inside = imu_turn(shifts[k : k + 64])
            inside &= use
            enough = (np.abs(turn) @ inside.T >= MIN_TURN_RAD) & (
                (turning & inside).sum(axis=1) >= 5
            )
            out[k : k + 64] = np.where(enough, _correlations(g, turn, inside), np.nan)
        return out

    coarse = _coarse_shifts()
    every = np.ones(len(turn), bool)
    peak = _LagPeak.of(coarse, correlations(coarse, every))
    at = peak.shift if peak is not None and (peak.clear or peak.ambiguous) else 0.0
    g, inside = imu_turn(np.array([at]))
    g, use = g[0], inside[0] & turning
    if np.count_nonzero(use) < 5:
        return True
    ratio = float(np.median(g[use] / turn[use]))
    if DEG_S_RATIO[0] <= abs(ratio) <= DEG_S_RATIO[1]:
        raise LogError(
            path,
            f"IMU angular rates look like deg/s, not rad/s (its heading turns {abs(ratio):.0f} "
            "times the GNSS course): scale angular_velocity by pi/180",
        )
    every = inside[0]
    scale_ok = _gyro_scale(path, log, t0[every] + at, t1[every] + at, turn[every], warnings)
    if ratio < -0.5:
        warnings.append(
            f"IMU: yaw rate has the opposite sign of the GNSS course's turns (ratio {ratio:.2f}): "
            "the IMU axes are not forward-left-up (an FRD or NED IMU?); fix the driver's frame "
            "or its /tf_static"
        )
        return scale_ok
    if ratio < 0.3 or peak is None:
        return scale_ok
    imu, gnss = f"IMU {topic_of(log, 'imu')}", f"GNSS {topic_of(log, 'gnss')}"
    if peak.ambiguous:
        warnings.append(
            f"{path.name}: {imu}: its turns match the {gnss} course's about as well shifted by "
            f"{peak.shift:+.2f} s as by {peak.rival_shift:+.2f} s (correlation "
            f"{peak.correlation:.2f} and {peak.rival_correlation:.2f}; {peak.at_zero:.2f} "
            "as stamped): the clocks disagree, by an offset a route that repeats itself does "
            "not tell; check how each stream is stamped"
        )
        return scale_ok
    if not peak.clear:
        return scale_ok
    inliers = inside[0] & (np.abs(turn - g / ratio) < TURN_OUTLIER_RAD)
    fine = _fine_shifts(at)
    corr = correlations(fine, inliers)
    if np.all(np.isnan(corr)):
        return scale_ok
    best = int(np.nanargmax(corr))
    lag = float(fine[best])
    if corr[best] < MIN_LAG_CORRELATION:
        return scale_ok
    line = ""
    if abs(lag) >= LAG_WARN_S:
        late = "late" if lag > 0 else "early"
        utc = ""
        if abs(abs(lag) - GPS_UTC_S) < 0.5:
            utc = f"; {GPS_UTC_S:g} s is GPS time against UTC"
        line = (
            f"{path.name}: {imu}: its stamps look {abs(lag):.2f} s {late} against {gnss} (its "
            f"turns match the GNSS course's best shifted by {lag:+.2f} s, correlation "
            f"{corr[best]:.2f}{utc}): set sensors.gnss_time_offset_s = {lag:.2f}"
        )
        warnings.append(line)
    offsets.append(ClockOffset("sensors.gnss_time_offset_s", round(lag, 2), gnss, line))
    return scale_ok


def _gyro_scale(path: Path, log: Log, t0: F64, t1: F64, turn: F64, warnings: list[str]) -> bool:
    """Name a gyro whose heading change about gravity over the windows ``t0``-``t1`` (on the
    IMU clock) is not the GNSS course's ``turn`` there (:data:`GYRO_SCALE_OK`). Taken about
    gravity (the accelerometer's mean direction), not the z axis, so that an IMU mounted on
    its side (the Husky's) is judged by its real yaw rate; the course's turns regressed on the
    gyro's over every window, so that the course's noise costs no bias (a median of ratios
    over the windows the course says turn read a fine gyro at 0.67 on fixes jittering a
    metre); and only where the two turn alike (:data:`MIN_LAG_CORRELATION`: a course drawn by
    two receivers interleaved on one topic turns at every fix). A gyro in mrad/s or scaled
    by ten dead-reckoned monaco's tunnel 951 and 1639 m off while the run spoke of refused
    fixes and matches and a forward accelerometer bias of 150-230 mg, never of the gyro."""
    imu = log.imu
    if not np.all(np.any(imu.gyro, axis=0)):
        return False  # a dead gyro or axis: named by _imu_alive
    heading = _running_integral(imu.t, imu.gyro @ _gravity_up(imu.accel))
    turned = np.interp(t1, imu.t, heading) - np.interp(t0, imu.t, heading)
    alike = _correlations(turned[None, :], turn, np.ones((1, len(turn)), bool))[0]
    if not abs(alike) >= MIN_LAG_CORRELATION:
        return True  # the course's turns are not the gyro's shape: a scale says nothing
    scale = abs(float(turned @ turned) / float(turned @ turn))
    if GYRO_SCALE_OK[0] <= scale <= GYRO_SCALE_OK[1]:
        return True
    if MRAD_S_RATIO[0] <= scale <= MRAD_S_RATIO[1]:
        cause = "mrad/s, not rad/s: scale angular_velocity by 1e-3"
    elif scale < GYRO_SCALE_OK[0] / 10:
        cause = "a gyro that does not follow the turns (dead, or its rate not filled)"
    else:
        cause = "angular rates scaled wrong (raw counts, a wrong full-scale range)"
    warnings.append(
        f"{path.name}: IMU {topic_of(log, 'imu')}: its heading about gravity turns {scale:.3g} "
        f"times the GNSS course over {len(turn)} windows of {TURN_STEPS} s (1 within a few per "
        "cent when "
        f"right): looks like {cause}; every outage is dead-reckoned with the heading wrong"
    )
    return False


def _correlations(a: F64, b: F64, use: NDArray[np.bool_]) -> F64:
    """The correlation of each row of ``a`` (M, N) with ``b`` (N,) over the columns ``use``
    (M, N) marks; NaN where either does not vary."""
    w = use.astype(np.float64)
    count = np.maximum(w.sum(axis=1, keepdims=True), 1.0)
    da = (a - (a * w).sum(axis=1, keepdims=True) / count) * w
    db = (b[None, :] - (b[None, :] * w).sum(axis=1, keepdims=True) / count) * w
    den = np.sqrt((da * da).sum(axis=1) * (db * db).sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        out: F64 = np.where(den > 0, (da * db).sum(axis=1) / den, np.nan)
    return out


def _wheel_resolution(path: Path, log: Log, warnings: list[str]) -> None:
    """Name a wheel speed coarser than :data:`WHEEL_STEP_NAMED_M_S`: the step is the median gap
    between the distinct speeds it takes while moving (a quantised speed visits neighbouring
    steps; a fine one has gaps of its noise). Without this, a tunnel driven on a 1 km/h speed
    ended metres off and the run blamed the route or the fixes."""
    w = log.wheel
    assert w is not None
    moving = np.abs(w.speed[np.abs(w.speed) > MOVING_M_S])
    if len(moving) < MIN_WHEEL_STEP_SAMPLES:
        return
    levels = np.unique(moving)
    if len(levels) < 3:
        return
    step = float(np.median(np.diff(levels)))
    if step < WHEEL_STEP_NAMED_M_S:
        return
    unit = next(
        (f" ({name})" for name, q in WHEEL_STEP_UNITS.items() if abs(step - q) < 0.02 * q), ""
    )
    warnings.append(
        f"{path.name}: wheel {topic_of(log, 'wheel')}: its speed comes in steps of {step:.3f} "
        f"m/s{unit}: at a steady speed it is up to {step / 2:.2f} m/s off for as long as the "
        f"speed holds, not noise, so dead reckoning along the road drifts up to "
        f"{30 * step:.0f} m a minute"
    )


WHEEL_STEP_UNITS = {"1 km/h, an OBD-II vehicle speed?": 1 / 3.6, "1 mph": 0.44704, "0.1 m/s": 0.1}


def _wheel_speed_ratio(w: WheelData, m: _GnssMotion) -> float | None:
    """The wheel speed's median ratio to the GNSS speed while moving (each fix pair's speed
    against the wheels' mean over the same interval); None with fewer than
    :data:`MIN_WHEEL_PAIRS` such pairs."""
    sel = m.moving & (m.t >= w.t[0]) & (m.t <= w.t[-1])
    if np.count_nonzero(sel) < MIN_WHEEL_PAIRS:
        return None
    ws = _mean_over(w.t, w.speed, m.t[sel] - m.dt[sel] / 2, m.t[sel] + m.dt[sel] / 2)
    return float(np.median(ws / m.speed[sel]))


def _wheel_plausible(log: Log, m: _GnssMotion, warnings: list[str]) -> bool:
    w = log.wheel
    assert w is not None
    ratio = _wheel_speed_ratio(w, m)
    if ratio is None or WHEEL_RATIO_OK[0] <= ratio <= WHEEL_RATIO_OK[1]:
        return True
    sel = m.moving & (m.t >= w.t[0]) & (m.t <= w.t[-1])
    cause = next(
        (name for name, (lo, hi) in WHEEL_UNITS.items() if lo <= ratio <= hi),
        "a wrong unit or scale",
    )
    warnings.append(
        f"wheel speed is {ratio:.2f} times the GNSS speed while moving (looks like {cause}, "
        f"over {_span(log, m.t[sel])}): the wheel stream is left out (IMU and GNSS only)"
    )
    return False


def _wheel_lag(path: Path, log: Log, warnings: list[str], offsets: list[ClockOffset]) -> float:
    """Name an offset of the wheel stream's clock against the IMU's, with the setting that
    removes it: the change of the wheel speed's mean over abutting :data:`WHEEL_LAG_WINDOW_S`
    windows against the IMU's horizontal specific force over the same windows shifted, fitted
    on both its horizontal axes (so an IMU mounted turned, or on its side, is judged as well),
    searched and peaked as the GNSS clock's offset is (:func:`_gyro`). Before, a wheel stream
    stamped 1 s late put long_tunnel's outage 72 m off (2 m clean) without a word. The offset
    named (s, + the wheels' stamps late), else 0."""
    assert log.wheel is not None
    imu = log.imu
    t, speed = _longest_stretch(log.wheel.t, log.wheel.speed, imu.t)
    width = WHEEL_LAG_WINDOW_S
    if len(t) < 2:
        return 0.0
    edges = t[0] + width * np.arange(int((t[-1] - t[0]) / width) + 1, dtype=np.float64)
    if len(edges) < MIN_WHEEL_LAG_WINDOWS + 2:
        return 0.0
    hole_s = wheel_gap_s(t)
    mean_speed = np.diff(np.interp(edges, t, _running_integral(t, speed, hole_s))) / width
    change = np.diff(mean_speed)
    usable = _without_hole(t, hole_s, edges[:-2], edges[2:])
    accelerating = usable & (np.abs(change) >= MIN_WHEEL_LAG_ACCELERATION_M_S2 * width)
    if np.count_nonzero(accelerating) < MIN_WHEEL_LAG_WINDOWS:
        return 0.0
    horizontal = _levelled_horizontal(imu.accel)
    velocity = _running_integral(imu.t, horizontal, WHEEL_LAG_IMU_HOLE_S)
    displacement = _running_integral(imu.t, velocity, WHEEL_LAG_IMU_HOLE_S)
    rows = max(1, min(64, 2**18 // len(change)))  # (rows, windows) at a time: 2 MB an array
    coarse = _coarse_shifts()
    span = edges[-1] - edges[0] + 2 * coarse[-1]
    grid = (
        edges[0] - coarse[-1] + LAG_COARSE_STEP_S * np.arange(round(span / LAG_COARSE_STEP_S) + 1)
    )
    on_grid = np.column_stack([np.interp(grid, imu.t, displacement[:, c]) for c in (0, 1)])

    def moved(at: F64) -> F64:
        """The IMU's displacement (..., 2) at the times ``at``: read from the coarse grid's
        times (every coarse shift's windows lie on it), interpolated elsewhere."""
        index = (at - grid[0]) / LAG_COARSE_STEP_S
        nearest = np.rint(index)
        if np.all(np.abs(index - nearest) < 1e-6) and 0 <= nearest.min() <= nearest.max() < len(
            grid
        ):
            out: F64 = on_grid[nearest.astype(np.intp)]
            return out
        return np.stack([np.interp(at, imu.t, displacement[:, c]) for c in (0, 1)], -1)

    def correlations(shifts: F64) -> F64:
        """Per shift (+ the wheels' stamps later), over the window pairs inside the IMU's span;
        NaN where too few of those are judged (:data:`MIN_WHEEL_LAG_WINDOWS`,
        :data:`MIN_WHEEL_LAG_OVERLAP`)."""
        out = np.full(len(shifts), np.nan)
        for k in range(0, len(shifts), rows):
            at = edges[None, :] - shifts[k : k + rows, None]
            inside = usable & (at[:, :-2] >= imu.t[0]) & (at[:, 2:] <= imu.t[-1])
            inside &= _without_hole(imu.t, WHEEL_LAG_IMU_HOLE_S, at[:, :-2], at[:, 2:])
            specific = np.diff(np.diff(moved(at), axis=1), axis=1) / width
            enough = ((accelerating & inside).sum(axis=1) >= MIN_WHEEL_LAG_WINDOWS) & (
                inside.sum(axis=1) >= MIN_WHEEL_LAG_OVERLAP * len(change)
            )
            fit = _fitted_correlations(specific, change, inside)
            out[k : k + rows] = np.where(enough, fit, np.nan)
        return out

    peak = _LagPeak.of(coarse, correlations(coarse))
    if peak is None or not peak.clear:
        return 0.0
    fine = _fine_shifts(peak.shift)
    corr = correlations(fine)
    if np.all(np.isnan(corr)):
        return 0.0
    best = int(np.nanargmax(corr))
    lag = float(fine[best])
    if corr[best] < MIN_LAG_CORRELATION:
        return 0.0
    wheel = f"wheel {topic_of(log, 'wheel')}"
    line = ""
    if abs(lag) >= WHEEL_LAG_WARN_S:
        line = (
            f"{path.name}: {wheel}: its stamps look {abs(lag):.2f} s "
            f"{'late' if lag > 0 else 'early'} against IMU {topic_of(log, 'imu')} (its speed's "
            f"changes match the IMU's specific force {abs(lag):.2f} s "
            f"{'before' if lag > 0 else 'after'} their stamps, correlation {corr[best]:.2f}): "
            f"set sensors.wheel_time_offset_s = {-lag:.2f}"
        )
        warnings.append(line)
    offsets.append(ClockOffset("sensors.wheel_time_offset_s", round(-lag, 2), wheel, line))
    return lag if line else 0.0


def _without_hole(t: F64, hole_s: float, t0: F64, t1: F64) -> NDArray[np.bool_]:
    """Whether no two consecutive samples ``t`` further apart than ``hole_s`` bracket any
    part of each interval ``t0``-``t1``."""
    hole = np.diff(t) > hole_s
    out: NDArray[np.bool_] = np.searchsorted(t[:-1][hole], t1) == np.searchsorted(
        t[1:][hole], t0, "right"
    )
    return out


def _longest_stretch(t: F64, v: F64, imu_t: F64) -> tuple[F64, F64]:
    """The samples of the longest stretch of a stream without a hole of :data:`OTHER_CLOCK_S`,
    of those on the IMU's clock: a recording paused, or a clock that jumped years, would
    otherwise be searched window by window across the hole."""
    on_clock = ~off_the_imu_clock(imu_t, t)
    t, v = t[on_clock], v[on_clock]
    if len(t) < 2:
        return t, v
    bounds = np.r_[0, np.flatnonzero(np.diff(t) > OTHER_CLOCK_S) + 1, len(t)]
    k = int(np.argmax(t[bounds[1:] - 1] - t[bounds[:-1]]))
    return t[bounds[k] : bounds[k + 1]], v[bounds[k] : bounds[k + 1]]


def _running_integral(t: F64, v: F64, hole_s: float = math.inf) -> F64:
    """The trapezoidal integral of ``v`` (N, ...) over ``t`` from its first sample, nothing
    added across a hole longer than ``hole_s``: after a clock jumped years, the double integral
    of the specific force was too large for a second's difference to show."""
    dt = np.diff(t)
    dt = np.where(dt > hole_s, 0.0, dt)
    step = 0.5 * (v[1:] + v[:-1]) * dt.reshape(-1, *([1] * (v.ndim - 1)))
    out: F64 = np.concatenate([np.zeros((1, *v.shape[1:])), np.cumsum(step, axis=0)])
    return out


def _gravity_up(accel: F64) -> F64:
    """The unit vector along the specific force's mean (N, 3): up, gravity's direction against,
    whichever way the IMU is mounted (the vehicle's own accelerations average out)."""
    up = np.mean(accel, axis=0)
    out: F64 = up / max(float(np.linalg.norm(up)), 1e-9)
    return out


def _levelled_horizontal(accel: F64) -> F64:
    """The specific force (N, 3) on two horizontal axes (N, 2): perpendicular to its mean
    direction, gravity's, whichever way the IMU is mounted."""
    up = _gravity_up(accel)
    across = np.eye(3)[int(np.argmin(np.abs(up)))]
    first = across - (across @ up) * up
    first = first / np.linalg.norm(first)
    out: F64 = accel @ np.column_stack([first, np.cross(up, first)])
    return out


def _fitted_correlations(x: F64, y: F64, use: NDArray[np.bool_]) -> F64:
    """The correlation of ``y`` (N,) with its least-squares fit on the two columns of each row
    of ``x`` (M, N, 2) over the columns ``use`` (M, N) marks; NaN where either does not vary."""
    w = use.astype(np.float64)
    count = np.maximum(w.sum(axis=1, keepdims=True), 1.0)

    def centred(v: F64) -> F64:
        out: F64 = (v - (v * w).sum(axis=1, keepdims=True) / count) * w
        return out

    a, b, c = centred(x[..., 0]), centred(x[..., 1]), centred(np.broadcast_to(y, w.shape))
    aa, bb, ab = (a * a).sum(axis=1), (b * b).sum(axis=1), (a * b).sum(axis=1)
    ac, bc, cc = (a * c).sum(axis=1), (b * c).sum(axis=1), (c * c).sum(axis=1)
    det = aa * bb - ab * ab
    with np.errstate(invalid="ignore", divide="ignore"):
        explained = (ac * ac * bb - 2 * ac * bc * ab + bc * bc * aa) / (det * cc)
        out: F64 = np.where(
            (det > 1e-12 * aa * bb) & (cc > 0), np.sqrt(np.clip(explained, 0.0, 1.0)), np.nan
        )
    return out
