"""A step of the GNSS clock under a minute (estimator.io.plausibility._clock_step): the fixes
after it were taken at the wrong time (300 m off after 20 s at road speed) or hid in a fake
outage, without a word. It is found at the gap between fixes it leaves, named in one line and
the fixes after it left out; a real outage, a 1 Hz receiver, a vehicle standing still, the
bundled samples and the real logs are not named."""

from __future__ import annotations

import dataclasses
import functools
import re
from pathlib import Path

import numpy as np
import pytest

from estimator.io import load_log, write_bag
from estimator.io.plausibility import _clock_step
from estimator.log import GnssData, ImuData, Log, WheelData
from estimator.sim import Simulation, simulate

REPO = Path(__file__).resolve().parents[3]
SAMPLES = sorted((REPO / "sample_logs").glob("*.mcap"))
REAL_LOGS = ("comma2k19/i280.mcap", "robot_localization/test1.bag")
STEP_WORDS = "its clock steps"


@functools.cache
def _drive() -> Simulation:
    """75 s: open sky, a tunnel at 38.0-66.8 s (GNSS lost), open sky to 74.8 s; 5 Hz fixes."""
    return simulate("short_tunnel", seed=0)


def _stepped(tmp_path: Path, at_s: float, step_s: float) -> Path:
    """The drive with the GNSS receiver's stamps ``step_s`` off from ``at_s`` after its start
    (the recorder's receive times run on)."""
    sim = _drive()
    t = sim.gnss.t
    stamps = np.where(t >= sim.imu.t[0] + at_s, t + step_s, t)
    path = tmp_path / f"step_{step_s:+g}s_at_{at_s:g}s.mcap"
    write_bag(
        path,
        imu=sim.imu,
        gnss=sim.gnss,
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
    """-10 s inside the tunnel: the stamps stay in order, the outage looks 10 s shorter and
    the fixes after it are 10 s early."""
    log = load_log(_stepped(tmp_path, 50.0, -10.0), cache_dir=tmp_path / "cache")
    (line,) = _named(log)
    assert "its clock steps 10.0 s back after 38.0 s" in line
    assert "the 40 fixes stamped 56.8-64.6 s are left out" in line


def test_the_clean_drive_is_not_named_and_its_fixes_untouched(tmp_path: Path) -> None:
    sim = _drive()
    path = tmp_path / "clean.mcap"
    write_bag(path, imu=sim.imu, gnss=sim.gnss, wheel=sim.wheel, truth=sim.truth_fix)
    log = load_log(path, cache_dir=tmp_path / "cache")
    assert not _named(log)
    assert np.array_equal(log.gnss.status, sim.gnss.status)


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.name)
def test_no_bundled_sample_is_named(tmp_path: Path, sample: Path) -> None:
    """Their tunnels (63-356 s without a fix) are real outages."""
    assert not _named(load_log(sample, cache_dir=tmp_path / "cache"))


@pytest.mark.parametrize("name", REAL_LOGS)
def test_no_real_log_is_named(tmp_path: Path, shared_data: Path, name: str) -> None:
    path = shared_data / name
    if not path.exists():
        pytest.skip(f"real data not found: {path}")
    assert not _named(load_log(path, cache_dir=tmp_path / "cache"))


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
    _clock_step(Path(log.path), log, warnings)
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
