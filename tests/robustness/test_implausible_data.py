"""Finite data that cannot be right (issue 16): dead sensors, unit and sign mistakes, an IMU
late against GNSS, absurd fix variances. Each is refused in one line where no estimate can be
meaningful, else warned about with its likely cause (:mod:`estimator.io.plausibility`); a
clean drive and the bundled samples raise no alarm."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from _badinputs import base_sim, write_log

from estimator.errors import LogError
from estimator.io import load_log
from estimator.log import Log

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def _load(tmp_path: Path, **streams: object) -> Log:
    return load_log(write_log(tmp_path / "drive.mcap", **streams), cache_dir=tmp_path / "cache")


def _imu(**arrays: np.ndarray) -> object:
    return dataclasses.replace(base_sim().imu, **arrays)


def test_a_clean_drive_raises_no_alarm(tmp_path: Path) -> None:
    assert _load(tmp_path).warnings == ()


@pytest.mark.parametrize("name", ["long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel"])
def test_the_samples_raise_no_alarm(tmp_path: Path, name: str) -> None:
    assert load_log(SAMPLES / f"{name}.mcap", cache_dir=tmp_path).warnings == ()


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        (lambda imu: {"gyro": 0 * imu.gyro, "accel": 0 * imu.accel}, "every sample is zero"),
        (lambda imu: {"accel": imu.accel / 9.80665}, "accelerations look like g"),
        (lambda imu: {"gyro": np.degrees(imu.gyro)}, "angular rates look like deg/s"),
    ],
    ids=["dead IMU", "accelerations in g", "rates in deg/s"],
)
def test_an_imu_no_estimate_can_use_is_refused_in_one_line(
    tmp_path: Path, change, problem: str
) -> None:
    imu = base_sim().imu
    with pytest.raises(LogError) as info:
        _load(tmp_path, imu=_imu(**change(imu)))
    text = str(info.value)
    assert problem in text and "\n" not in text and str(tmp_path / "drive.mcap") in text


def test_a_mirrored_yaw_rate_is_named(tmp_path: Path) -> None:
    gyro = base_sim().imu.gyro * np.array([1.0, 1.0, -1.0])
    log = _load(tmp_path, imu=_imu(gyro=gyro))
    assert any("opposite sign" in w and "forward-left-up" in w for w in log.warnings)


def test_an_imu_half_a_second_late_is_measured(tmp_path: Path) -> None:
    imu = base_sim().imu
    log = _load(tmp_path, imu=_imu(t=imu.t + 0.5))
    late = [w for w in log.warnings if "s late against GNSS" in w]
    assert len(late) == 1
    lag = float(late[0].split("look ")[1].split(" s")[0])
    assert lag == pytest.approx(0.5, abs=0.08)


@pytest.mark.parametrize(
    ("factor", "cause"), [(3.6, "km/h"), (-1.0, "the wrong sign")], ids=["km/h", "sign"]
)
def test_a_wheel_speed_in_other_units_is_named_and_left_out(
    tmp_path: Path, factor: float, cause: str
) -> None:
    wheel = base_sim().wheel
    log = _load(tmp_path, wheel=dataclasses.replace(wheel, speed=factor * wheel.speed))
    assert log.wheel is None
    assert any(f"looks like {cause}" in w and "left out" in w for w in log.warnings)


def test_fixes_claiming_a_kilometre_of_variance_are_no_fixes(tmp_path: Path) -> None:
    gnss = base_sim().gnss
    cov = gnss.cov_enu.copy()
    cov[100:150] = 1e30
    log = _load(tmp_path, gnss=dataclasses.replace(gnss, cov_enu=cov))
    assert not log.gnss.valid[100:150].any() and log.gnss.valid[150:200].any()
    assert any("50 fixes claim a variance above" in w for w in log.warnings)


def test_the_warning_reaches_run_info_and_the_export(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Said wherever the user looks: on stderr by run, in info, on the export's report page and
    in the batch summary (the inspector's status line: tests/inspector/app)."""
    from _badinputs import run_cli, write_route

    wheel = base_sim().wheel
    log = write_log(
        tmp_path / "drive.mcap", wheel=dataclasses.replace(wheel, speed=3.6 * wheel.speed)
    )
    route = write_route(tmp_path / "drive.route.geojson")
    code, _, err = run_cli(capsys, ["run", str(log), "--route", str(route)])
    assert code == 0 and "routefuse run: warning: wheel speed is 3.6" in err and "km/h" in err
    code, out, _ = run_cli(capsys, ["info", str(log)])
    assert code == 0 and "looks like km/h" in out
    code, _, _ = run_cli(capsys, ["export", "--batch", str(tmp_path), "--out", str(tmp_path / "x")])
    assert code == 0
    report = (tmp_path / "x" / "drive" / "report.html").read_text(encoding="utf-8")
    assert "Warnings about this log" in report and "looks like km/h" in report
    summary = (tmp_path / "x" / "summary.csv").read_text(encoding="utf-8")
    assert "looks like km/h" in summary


def test_a_first_fix_at_null_island_is_left_out_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The first valid fix reports 0, 0 with status OK (a receiver's cold start, audit F1):
    the frame went to null island (198 m errors, info's 905 km of GNSS travel) without a word.
    Now that fix is left out, named once in run and info, and the run is the one of the log
    without that fix, estimate for estimate."""
    from _badinputs import run_cli, write_route

    from estimator.params import Params
    from estimator.pipeline import open_inputs, run_methods

    g = base_sim().gnss
    first = int(np.flatnonzero(g.valid)[0])
    lat, lon, status = g.lat.copy(), g.lon.copy(), g.status.copy()
    lat[first] = lon[first] = 0.0
    status[first] = -1
    bad = write_log(tmp_path / "null_island.mcap", gnss=dataclasses.replace(g, lat=lat, lon=lon))
    ref = write_log(tmp_path / "no_first_fix.mcap", gnss=dataclasses.replace(g, status=status))
    route = write_route(tmp_path / "drive.route.geojson")
    runs = {}
    for path in (bad, ref):
        inputs = open_inputs(path, route, cache_dir=tmp_path / "cache")
        runs[path] = run_methods(inputs, Params(), methods=("proposed",))["proposed"]
    assert np.array_equal(runs[bad].epochs.position, runs[ref].epochs.position)
    assert runs[bad].frame == runs[ref].frame
    code, _, err = run_cli(capsys, ["run", str(bad), "--route", str(route), "--quiet"])
    lines = err.splitlines()
    assert code == 0 and len(lines) == 1, err
    assert lines[0].startswith("routefuse run: warning: null_island.mcap: GNSS /gnss/fix: 1 fix ")
    assert "at 0.0 s" in lines[0] and "left out" in lines[0]
    code, out, _ = run_cli(capsys, ["info", str(bad)])
    assert code == 0 and out.count("null_island.mcap: GNSS /gnss/fix: 1 fix at 0.0 s") == 1
    gnss_travel = next(line for line in out.splitlines() if "m from GNSS fixes" in line)
    assert float(gnss_travel.split()[0]) < 1200.0, gnss_travel
