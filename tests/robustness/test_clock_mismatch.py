"""IMU and GNSS stamped on different clocks (boot time against Unix time) share no time: the
log is refused with both spans named, instead of an empty table (issue 16)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from _badinputs import assert_cli_error, base_sim, cli_argv, write_log, write_route

from estimator.errors import LogError
from estimator.io import load_log


def _boot_time_imu_log(path: Path) -> Path:
    imu = base_sim().imu
    since_boot = dataclasses.replace(imu, t=imu.t - imu.t[0] + 12.0)
    return write_log(path, imu=since_boot)


def test_an_imu_on_another_clock_is_refused_with_both_spans(tmp_path: Path) -> None:
    log = _boot_time_imu_log(tmp_path / "boot_clock.mcap")
    with pytest.raises(LogError) as info:
        load_log(log, cache_dir=tmp_path / "cache")
    text = str(info.value)
    assert text.startswith(f"{log}: IMU and GNSS are stamped on different clocks")
    assert "IMU 12.0-" in text and "GNSS 1700000000.0-" in text and "\n" not in text


def test_the_cli_refuses_it_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _boot_time_imu_log(tmp_path / "boot_clock.mcap")
    route = write_route(tmp_path / "boot_clock.route.geojson")
    assert_cli_error(capsys, cli_argv("run", log, route), log, "different clocks")
