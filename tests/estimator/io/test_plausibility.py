"""Clocks that disagree (estimator.io.plausibility).

A step of the GNSS clock under a minute (``_clock_step``): the fixes after it were taken at the
wrong time (300 m off after 20 s at road speed) or hid in a fake outage, without a word. It is
found at the gap between fixes it leaves, named in one line and the fixes after it left out; a
real outage, a 1 Hz receiver, a vehicle standing still, the bundled samples and the real logs
are not named.

A constant offset of the GNSS clock against the IMU's (``_gyro``): it was searched within 1 s,
so 1.5 s or 5 s were named as 1.00 s (the search's edge: a confident wrong setting) and 18 s
(GPS time against UTC) not at all, the run 234 m off. It is measured up to a minute, named with
the setting that gives the clean run back, and not named where the route repeats itself."""

from __future__ import annotations

import dataclasses
import functools
import re
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError
from estimator.evaluation import method_metrics
from estimator.io import load_log, write_bag
from estimator.io.plausibility import MAX_LAG_S, _clock_step, _gnss_motion, _LagPeak, checked
from estimator.log import GnssData, ImuData, Log, WheelData
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run
from estimator.sim import Simulation, simulate

REPO = Path(__file__).resolve().parents[3]
STEP_WORDS = "its clock steps"


@functools.cache
def _drive() -> Simulation:
    """75 s: open sky, a tunnel at 38.0-66.8 s (GNSS lost), open sky to 74.8 s; 5 Hz fixes."""
    return simulate("short_tunnel", seed=0)


def _stepped(tmp_path: Path, at_s: float, step_s: float, *, silent_in_tunnel: bool = False) -> Path:
    """The drive with the GNSS receiver's stamps ``step_s`` off from ``at_s`` after its start
    (the recorder's receive times run on); ``silent_in_tunnel``: the receiver sends nothing
    without a fix (the simulated one sends NO_FIX messages)."""
    sim = _drive()
    gnss = sim.gnss
    if silent_in_tunnel:
        keep = gnss.valid
        gnss = GnssData(
            gnss.t[keep],
            gnss.lat[keep],
            gnss.lon[keep],
            gnss.alt[keep],
            gnss.status[keep],
            gnss.cov_enu[keep],
        )
    t = gnss.t
    stamps = np.where(t >= sim.imu.t[0] + at_s, t + step_s, t)
    path = tmp_path / f"step_{step_s:+g}s_at_{at_s:g}s.mcap"
    write_bag(
        path,
        imu=sim.imu,
        gnss=gnss,
        wheel=sim.wheel,
        truth=sim.truth_fix,
        header_stamps={"gnss": stamps},
    )
    return path


def _named(log: Log) -> list[str]:
    return [w for w in log.warnings if STEP_WORDS in w]


@pytest.mark.parametrize("step_s", [5.0, 20.0, 50.0])
def test_a_forward_step_in_open_sky_is_named_and_the_fixes_after_it_left_out(
    tmp_path: Path, step_s: float
) -> None:
    path = _stepped(tmp_path, 20.0, step_s)
    log = load_log(path, cache_dir=tmp_path / "cache")
    (line,) = _named(log)
    assert line.startswith(
        f"{path.name}: GNSS /gnss/fix: its clock steps {step_s:.1f} s forward after 19.8 s "
    ), line
    assert "the 131 fixes stamped" in line and line.endswith("are left out of the run")
    assert not log.gnss.valid[log.gnss.t - log.t_start > 19.9].any()
    assert log.gnss.valid[log.gnss.t - log.t_start < 19.9].all()


def test_a_step_near_the_end_is_named_not_dropped_in_silence(tmp_path: Path) -> None:
    """+20 s inside the tunnel: every fix after it is stamped past the IMU's end, within 60 s
    of it, and the run ended in a 37 s outage without a word."""
    log = load_log(_stepped(tmp_path, 60.0, 20.0), cache_dir=tmp_path / "cache")
    (line,) = _named(log)
    assert "its clock steps 20.0 s forward after 38.0 s" in line
    assert "the 40 fixes stamped 86.8-94.6 s are left out" in line


def test_a_backward_step_inside_an_outage_is_named(tmp_path: Path) -> None:
    """-10 s inside the tunnel, the receiver silent there: the stamps stay in order, the
    outage looks 10 s shorter and the fixes after it are 10 s early."""
    path = _stepped(tmp_path, 50.0, -10.0, silent_in_tunnel=True)
    log = load_log(path, cache_dir=tmp_path / "cache")
    (line,) = _named(log)
    assert "its clock steps 10.0 s back after 38.0 s" in line
    assert "the 40 fixes stamped 56.8-64.6 s are left out" in line


@pytest.mark.parametrize(("at_s", "step_s"), [(50.0, -10.0), (20.0, -2.0), (20.0, -5.0)])
def test_a_receiver_sending_on_that_steps_back_is_mended_exactly(
    tmp_path: Path, at_s: float, step_s: float
) -> None:
    """A receiver that keeps sending (no-fix messages in the tunnel, fixes in open sky)
    shows the step back in its own stamps: the repair moves the messages after it forward to
    continue the stream (:data:`~estimator.io.repair.GNSS_JUMP_MIN_INTERVALS`), every stamp
    as the receiver should have stamped it. Under 10 s at 5 Hz this was sorted into two
    interleaved stretches of the drive, named only as samples out of order."""
    log = load_log(_stepped(tmp_path, at_s, step_s), cache_dir=tmp_path / "cache")
    (line,) = log.warnings
    assert line.startswith(f"GNSS /gnss/fix: clock jumps back {-step_s - 0.2:.3f} s after ")
    assert line.endswith(f"moved {-step_s:.3f} s forward to continue it (data kept)")
    assert np.array_equal(log.gnss.t, _drive().gnss.t)
    assert not _named(log)


def test_the_clean_drive_is_not_named_and_its_fixes_untouched(tmp_path: Path) -> None:
    sim = _drive()
    path = tmp_path / "clean.mcap"
    write_bag(path, imu=sim.imu, gnss=sim.gnss, wheel=sim.wheel, truth=sim.truth_fix)
    log = load_log(path, cache_dir=tmp_path / "cache")
    assert not _named(log)
    assert np.array_equal(log.gnss.status, sim.gnss.status)


T0 = 1_700_000_000.0
SPEED = 15.0


def _straight(speed: float, fix_hz: float, gap: tuple[float, float], step_s: float) -> Log:
    """A 120 s drive east at ``speed`` (m/s), fixes at ``fix_hz`` except over ``gap`` (s after
    the start), the fixes after the gap stamped ``step_s`` late."""
    t = T0 + np.arange(0.0, 120.0, 0.01)
    imu = ImuData(t, np.zeros((len(t), 3)), np.tile([0.0, 0.0, 9.81], (len(t), 1)))
    wheel = WheelData(t[::2], np.full(len(t[::2]), speed))
    ft = T0 + np.arange(0.0, 120.0, 1.0 / fix_hz)
    ft = ft[((ft - T0) <= gap[0]) | ((ft - T0) > gap[1])]
    east = speed * (ft - T0)
    lat = 48.0 + 0.0 * east
    lon = 11.0 + east / (111_320.0 * np.cos(np.radians(48.0)))
    stamps = np.where(ft - T0 > gap[1], ft + step_s, ft)
    n = len(ft)
    gnss = GnssData(
        stamps, lat, lon, np.full(n, 500.0), np.zeros(n, np.int8), np.tile([1.0, 1.0, 4.0], (n, 1))
    )
    return Log("straight.mcap", imu, gnss, wheel)


def _steps_named(log: Log) -> list[str]:
    warnings: list[str] = []
    _clock_step(Path(log.path), log, warnings, _gnss_motion(log))
    return warnings


@pytest.mark.parametrize(
    ("case", "speed", "fix_hz", "gap", "step_s", "named"),
    [
        ("a 30 s outage", SPEED, 1.0, (40.0, 70.0), 0.0, False),
        ("a 1 Hz receiver", SPEED, 1.0, (0.0, 0.0), 0.0, False),
        ("a 10 Hz receiver dropping 3 s", SPEED, 10.0, (40.0, 43.0), 0.0, False),
        ("a step while standing still", 0.0, 1.0, (40.0, 40.5), 20.0, False),
        ("a 20 s step at 1 Hz", SPEED, 1.0, (40.0, 40.5), 20.0, True),
        ("a 20 s step in a 30 s outage", SPEED, 1.0, (40.0, 70.0), 20.0, True),
        ("a 3 s step at 10 Hz", SPEED, 10.0, (40.0, 40.05), 3.0, True),
        ("a 1 s step (not named: a 1 Hz stamp's resolution)", SPEED, 1.0, (40.0, 40.5), 1.0, False),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_named_only_where_a_step_is_what_the_fixes_say(
    case: str,
    speed: float,
    fix_hz: float,
    gap: tuple[float, float],
    step_s: float,
    named: bool,
) -> None:
    warnings = _steps_named(_straight(speed, fix_hz, gap, step_s))
    assert bool(warnings) == named, warnings
    if named:
        found = re.search(r"its clock steps ([0-9.]+) s forward after ([0-9.]+) s", warnings[0])
        assert found, warnings[0]
        assert float(found[1]) == pytest.approx(step_s, abs=0.15)
        assert float(found[2]) == gap[0]


def test_without_wheels_nothing_is_judged() -> None:
    """No distance driven to hold the fixes against: the check is skipped."""
    log = dataclasses.replace(_straight(SPEED, 1.0, (40.0, 40.5), 20.0), wheel=None)
    assert not _steps_named(log)


OFFSET_SETTING = re.compile(r"set sensors\.gnss_time_offset_s = (-?[0-9.]+)$")


def _gnss_late(log: Log, offset_s: float) -> Log:
    """``log`` with every GNSS stamp ``offset_s`` later, checked again."""
    g = log.gnss
    return checked(
        Path(log.path), dataclasses.replace(log, gnss=dataclasses.replace(g, t=g.t + offset_s))
    )


def _offset_lines(log: Log) -> list[str]:
    return [w for w in log.warnings if "gnss_time_offset_s" in w or "clocks disagree" in w]


def _setting(log: Log) -> float:
    (line,) = _offset_lines(log)
    found = OFFSET_SETTING.search(line)
    assert found, line
    return float(found[1])


@functools.cache
def _monaco() -> Log:
    return load_log(REPO / "sample_logs" / "monaco_tunnel.mcap", cache_dir=None)


@pytest.mark.parametrize("offset_s", [-0.5, 1.5, 5.0, 18.0, -18.0, 45.0])
def test_an_offset_of_the_gnss_clock_is_measured_up_to_a_minute(offset_s: float) -> None:
    """Was -1.00 s for 1.5 and 5 s (the edge of a 1 s search), nothing for 18 s."""
    log = _gnss_late(_monaco(), offset_s)
    (line,) = _offset_lines(log)
    assert line.startswith("monaco_tunnel.mcap: IMU /imu/data: its stamps look "), line
    assert "against GNSS /gnss/fix" in line and "correlation 0.9" in line
    assert _setting(log) == pytest.approx(-offset_s, abs=0.08)
    assert ("GPS time against UTC" in line) == (abs(offset_s) == 18.0)


def test_rates_in_deg_s_are_refused_at_the_measured_offset() -> None:
    """The units are judged where the turns match, not as stamped 18 s apart."""
    log = _gnss_late(_monaco(), 18.0)
    imu = dataclasses.replace(log.imu, gyro=np.degrees(log.imu.gyro))
    with pytest.raises(LogError, match="look like deg/s"):
        checked(Path(log.path), dataclasses.replace(log, imu=imu, warnings=()))


@functools.cache
def _truth_rmse(seed: int, offset_s: float, setting_s: float | None) -> tuple[float, float | None]:
    """The proposed run's truth RMSE over the simulated drive's tunnel with its GNSS stamped
    ``offset_s`` late, with ``sensors.gnss_time_offset_s`` at ``setting_s`` (None: the one the
    warning recommends), and the setting used."""
    sim = simulate("short_tunnel", seed=seed)
    log = _gnss_late(sim.log("drive.mcap"), offset_s)
    setting = _setting(log) if setting_s is None else setting_s
    params = with_values(Params(), {"sensors.gnss_time_offset_s": setting})
    route = sim.route()
    r = run(log, route, params, method="proposed", frame=sim.frame)
    truth = method_metrics(r, route, log, params=r.params).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return truth.rmse_h_err_m, setting


@pytest.mark.parametrize("offset_s", [1.5, 18.0])
def test_the_recommended_setting_gives_the_clean_run_back(offset_s: float) -> None:
    """Left as stamped the run is 47 m (1.5 s) and 323 m (18 s) off the truth over the tunnel;
    with the setting named it is the clean run's 0.4 m within the measurement's 0.06 s (on this
    drive), 1 m at 15 m/s."""
    clean, _ = _truth_rmse(0, 0.0, 0.0)
    as_stamped, _ = _truth_rmse(0, offset_s, 0.0)
    repaired, setting = _truth_rmse(0, offset_s, None)
    assert setting == pytest.approx(-offset_s, abs=0.08)
    assert as_stamped > 40.0
    assert repaired < clean + 1.2


@pytest.mark.slow
@pytest.mark.parametrize("offset_s", [1.5, 18.0])
def test_the_recommended_setting_gives_the_sample_its_clean_run_back(offset_s: float) -> None:
    """monaco_tunnel: 23 m (1.5 s) and 234 m (18 s) left as stamped; 0.98 m with the setting
    (-1.56, -18.06 s) against 0.76 m clean."""
    inputs = open_inputs(
        REPO / "sample_logs" / "monaco_tunnel.mcap",
        REPO / "sample_logs" / "monaco_tunnel.route.geojson",
        cache_dir=None,
    )
    assert inputs.route is not None

    def rmse(log: Log, setting: float) -> float:
        params = with_values(Params(), {"sensors.gnss_time_offset_s": setting})
        r = run(log, inputs.route, params, method="proposed", frame=inputs.frame)
        truth = method_metrics(r, inputs.route, log, params=r.params).truth
        assert truth is not None and truth.rmse_h_err_m is not None
        return truth.rmse_h_err_m

    late = _gnss_late(inputs.log, offset_s)
    assert rmse(late, _setting(late)) < rmse(inputs.log, 0.0) + 0.3


def _laps(offset_s: float) -> Log:
    """400 s at 10 m/s round a circuit of 40 s laps, each a left turn then a straight (a route
    that repeats itself), fixes at 5 Hz stamped ``offset_s`` late."""
    t = T0 + np.arange(0.0, 400.0, 0.01)
    yaw_rate = 0.3 * np.maximum(np.sin(2 * np.pi * (t - T0) / 40.0), 0.0) ** 2
    heading = np.cumsum(yaw_rate) * 0.01
    gyro = np.column_stack([np.zeros_like(t), np.zeros_like(t), yaw_rate])
    imu = ImuData(t, gyro, np.tile([0.0, 0.0, 9.81], (len(t), 1)))
    east = np.cumsum(10.0 * np.cos(heading)) * 0.01
    north = np.cumsum(10.0 * np.sin(heading)) * 0.01
    k = np.arange(0, len(t), 20)
    lat = 48.0 + north[k] / 111_320.0
    lon = 11.0 + east[k] / (111_320.0 * np.cos(np.radians(48.0)))
    n = len(k)
    gnss = GnssData(
        t[k] + offset_s,
        lat,
        lon,
        np.full(n, 500.0),
        np.zeros(n, np.int8),
        np.tile([1.0, 1.0, 4.0], (n, 1)),
    )
    return Log("laps.mcap", imu, gnss, WheelData(t[::2], np.full(len(t[::2]), 10.0)))


def test_a_route_that_repeats_itself_gives_no_offset_but_says_the_clocks_disagree() -> None:
    """Its turns match at -18 s and at -18 s +- 40 s alike: no one offset is named."""
    (line,) = _offset_lines(checked(Path("laps.mcap"), _laps(18.0)))
    assert line.startswith(
        "laps.mcap: IMU imu: its turns match the GNSS gnss course's about as well"
    )
    assert "the clocks disagree" in line and "gnss_time_offset_s" not in line
    assert not _offset_lines(checked(Path("laps.mcap"), _laps(0.0)))


def test_a_match_at_the_edge_of_the_search_is_no_offset() -> None:
    """Correlations still rising at the search's end: the offset lies beyond it, not there."""
    shifts = np.linspace(-MAX_LAG_S, MAX_LAG_S, 481)
    peak = _LagPeak.of(shifts, np.linspace(0.0, 0.99, 481))
    assert peak is not None and peak.shift == MAX_LAG_S
    assert not peak.clear and not peak.ambiguous
