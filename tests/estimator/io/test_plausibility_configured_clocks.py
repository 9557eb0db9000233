"""A clock offset measured when the log is read is judged against the run's configuration
(estimator.io.plausibility.configured_clock_warnings): the load cannot know the configuration,
so its line "set sensors.gnss_time_offset_s = v" stayed after the user had set it, and a
setting the log contradicts (1.5 s on a log whose clocks agree) went unsaid."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import pytest

from estimator.io import load_log, write_bag
from estimator.io.plausibility import checked
from estimator.log import ClockOffset, Log
from estimator.params import Params, with_values
from estimator.pipeline import run

REPO = Path(__file__).resolve().parents[3]
MONACO = REPO / "sample_logs" / "monaco_tunnel.mcap"
GNSS_SETTING = "sensors.gnss_time_offset_s"
WHEEL_SETTING = "sensors.wheel_time_offset_s"


@functools.cache
def _monaco() -> Log:
    return dataclasses.replace(load_log(MONACO), warnings=(), clock_offsets=())


def _shifted(gnss_s: float = 0.0, wheel_s: float = 0.0) -> Log:
    log = _monaco()
    assert log.wheel is not None
    return checked(
        MONACO,
        dataclasses.replace(
            log,
            gnss=dataclasses.replace(log.gnss, t=log.gnss.t + gnss_s),
            wheel=dataclasses.replace(log.wheel, t=log.wheel.t + wheel_s),
        ),
    )


def _offset(log: Log, setting: str) -> ClockOffset:
    (found,) = [o for o in log.clock_offsets if o.setting == setting]
    return found


def _baseline_warnings(log: Log, **values: float) -> tuple[str, ...]:
    p = with_values(Params(), values) if values else Params()
    return run(log, None, p, method="baseline").warnings


def test_every_clear_measurement_is_kept_even_when_small() -> None:
    log = _shifted()
    assert _offset(log, GNSS_SETTING).offset_s == pytest.approx(0.0, abs=0.06)
    assert _offset(log, WHEEL_SETTING).offset_s == pytest.approx(0.0, abs=0.03)
    assert not any(o.warning for o in log.clock_offsets)


def test_the_load_s_line_goes_once_the_run_is_set_to_correct_it() -> None:
    log = _shifted(gnss_s=18.0)
    offset = _offset(log, GNSS_SETTING)
    assert offset.warning in log.warnings and offset.warning.endswith(
        f"set {GNSS_SETTING} = {offset.offset_s:.2f}"
    )
    assert offset.warning in _baseline_warnings(log)
    corrected = _baseline_warnings(log, **{GNSS_SETTING: offset.offset_s})
    assert not [w for w in corrected if GNSS_SETTING in w]


def test_a_setting_the_log_contradicts_is_named() -> None:
    (line,) = [
        w for w in _baseline_warnings(_shifted(), **{GNSS_SETTING: 1.5}) if GNSS_SETTING in w
    ]
    assert line.startswith("monaco_tunnel.mcap: GNSS /gnss/fix: its clock agrees with the IMU's (")
    assert line.endswith(f"configured with {GNSS_SETTING} = 1.50: set {GNSS_SETTING} = 0.00")


def test_the_wheels_alike() -> None:
    log = _shifted(wheel_s=1.0)
    offset = _offset(log, WHEEL_SETTING)
    assert offset.offset_s == pytest.approx(-1.0, abs=0.05)
    assert offset.warning in _baseline_warnings(log)
    assert not [
        w for w in _baseline_warnings(log, **{WHEEL_SETTING: offset.offset_s}) if WHEEL_SETTING in w
    ]
    wrong = _baseline_warnings(log, **{WHEEL_SETTING: 1.0})
    assert [w for w in wrong if f"configured with {WHEEL_SETTING} = 1.00" in w]


def test_the_measurements_survive_the_decode_cache(tmp_path: Path) -> None:
    log = _monaco()
    path = tmp_path / "late.mcap"
    write_bag(
        path, imu=log.imu, gnss=dataclasses.replace(log.gnss, t=log.gnss.t + 18.0), wheel=log.wheel
    )
    first = load_log(path, cache_dir=tmp_path / "cache")
    again = load_log(path, cache_dir=tmp_path / "cache")
    assert first.clock_offsets and again.clock_offsets == first.clock_offsets
    assert _offset(again, GNSS_SETTING).warning.startswith("late.mcap: ")
