"""Streams stamped on clocks that disagree. IMU and GNSS on different clocks (boot time against
Unix time) share no time: the log is refused with both spans named, instead of an empty table
(issue 16). GNSS whose clock steps two days mid-log, a wheel stream an hour late and IMU stamps
squeezed into milliseconds ran in silence (audit F8): each is now one line naming the file, the
topic and the span, in info and run, and the IMU one is refused."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from _badinputs import (
    assert_cli_error,
    base_sim,
    cli_argv,
    run_cli,
    write_log,
    write_route,
)

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


DAY_S = 86400.0


def _gnss_stepped_2_days(path: Path) -> Path:
    g = base_sim().gnss
    mid = float(base_sim().imu.t[len(base_sim().imu.t) // 2])
    return write_log(path, gnss=dataclasses.replace(g, t=np.where(g.t > mid, g.t + 2 * DAY_S, g.t)))


def _wheel_an_hour_late(path: Path) -> Path:
    w = base_sim().wheel
    return write_log(path, wheel=dataclasses.replace(w, t=w.t + 3600.0))


def _warned_once(
    capsys: pytest.CaptureFixture[str], log: Path, route: Path, text: str
) -> tuple[str, str]:
    """The one line holding ``text`` in info's output and on run's stderr; the run's stdout."""
    code, info, _ = run_cli(capsys, ["info", str(log)])
    assert code == 0
    in_info = [line for line in info.splitlines() if text in line]
    assert len(in_info) == 1 and in_info[0].startswith(f"warning   {log.name}: "), info
    code, out, err = run_cli(capsys, ["run", str(log), "--route", str(route), "--quiet"])
    assert code == 0, err
    in_run = [line for line in err.splitlines() if text in line]
    assert len(in_run) == 1 and in_run[0].startswith(f"routefuse run: warning: {log.name}: "), err
    return in_run[0], out


def test_gnss_whose_clock_steps_two_days_mid_log_is_named_and_left_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was a 48-hour outage in info and in the run's metrics, without a word."""
    log = _gnss_stepped_2_days(tmp_path / "gnss_step.mcap")
    route = write_route(tmp_path / "drive.route.geojson")
    line, _ = _warned_once(capsys, log, route, "GNSS /gnss/fix: its clock steps 172800.")
    assert "187 of its 374 fixes are stamped 172837.4-172874.6 s" in line
    assert "outside the IMU's 0.0-74.8 s" in line and "left out of the run" in line
    loaded = load_log(log, cache_dir=tmp_path / "cache")
    assert loaded.gnss.t[-1] < loaded.t_end


def test_wheel_speed_an_hour_late_is_named_and_the_run_is_one_without_wheels(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was silently unused, the run going on with the parameters of one with wheels."""
    from estimator.params import Params
    from estimator.pipeline import open_inputs, run_methods

    log = _wheel_an_hour_late(tmp_path / "wheel_late.mcap")
    route = write_route(tmp_path / "drive.route.geojson")
    line, _ = _warned_once(capsys, log, route, "wheel /wheel/odom: all 3738 samples")
    assert "stamped 3600.0-3674.7 s" in line and "IMU and GNSS only" in line
    no_wheel = write_log(tmp_path / "no_wheel.mcap", wheel=None)
    positions = []
    for path in (log, no_wheel):
        inputs = open_inputs(path, route, cache_dir=tmp_path / "cache")
        positions.append(run_methods(inputs, Params(), methods=("proposed",))["proposed"])
    assert np.array_equal(positions[0].epochs.position, positions[1].epochs.position)


def test_imu_stamps_squeezed_into_milliseconds_are_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 75 s drive's IMU stamped within 7.5 ms gave one output epoch and empty metrics."""
    imu = base_sim().imu
    squeezed = dataclasses.replace(imu, t=imu.t[0] + (imu.t - imu.t[0]) * 1e-4)
    log = write_log(tmp_path / "imu_1us.mcap", imu=squeezed)
    route = write_route(tmp_path / "drive.route.geojson")
    for command in ("info", "run"):
        assert_cli_error(
            capsys, cli_argv(command, log, route), log, "IMU /imu/data: its 7476 samples are"
        )
    with pytest.raises(LogError, match=r"stamped within 7\.47 ms"):
        load_log(log, cache_dir=tmp_path / "cache")


def test_gnss_whose_clock_steps_20_s_mid_log_is_named_in_info_and_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Under a minute the fixes stay inside the IMU's span: the run took them 20 s late (truth
    RMSE 196 m against 0.56 m), without a word."""
    from estimator.io import write_bag

    sim = base_sim()
    log = tmp_path / "gnss_step_20s.mcap"
    late = np.where(sim.gnss.t >= sim.imu.t[0] + 20.0, sim.gnss.t + 20.0, sim.gnss.t)
    write_bag(
        log,
        imu=sim.imu,
        gnss=sim.gnss,
        wheel=sim.wheel,
        truth=sim.truth_fix,
        header_stamps={"gnss": late},
    )
    route = write_route(tmp_path / "drive.route.geojson")
    line, _ = _warned_once(capsys, log, route, "GNSS /gnss/fix: its clock steps 20.0 s forward")
    assert "after 19.8 s" in line and "131 fixes stamped 40.0-94.6 s are left out" in line
