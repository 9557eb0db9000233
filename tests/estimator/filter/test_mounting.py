"""The IMU's mounting yaw against the direction of travel (estimator.filter.mounting, judged in
estimator.filter.setup.prepare_inputs where ``sensors.imu_*_deg`` are known): an IMU mounted
sideways or backwards cost 1-2 km of truth error on monaco_tunnel without a word about the
mounting. It is named in one line with the setting that fixes it, and that setting gives the
clean run back; a left-handed frame is named as such; the clean samples, a 2 deg mount, the
simulated drives and the real logs are not named."""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.filter.setup import prepare_inputs
from estimator.io import TopicChoice
from estimator.log import Log
from estimator.nav.rotation import dcm_from_euler
from estimator.params import Params, load_params, with_values
from estimator.pipeline import run
from estimator.pipeline.inputs import Inputs, open_inputs
from estimator.sim.imu_only import build_imu_only, imu_only_spec

REPO = Path(__file__).resolve().parents[3]
SAMPLES = REPO / "sample_logs"
HUSKY_CONFIG = SAMPLES / "configs" / "husky_test1.toml"
SETTING = re.compile(r"(sensors\.imu_(?:roll|pitch|yaw)_deg) = (-?[0-9.]+)")
NAMED = ("direction of travel", "mirrored")


@functools.cache
def _monaco(no_wheel: bool = False) -> Inputs:
    return open_inputs(
        SAMPLES / "monaco_tunnel.mcap",
        SAMPLES / "monaco_tunnel.route.geojson",
        topics=TopicChoice(no_wheel=no_wheel),
    )


def _mounted(log: Log, roll_deg: float, pitch_deg: float, yaw_deg: float) -> Log:
    """The log as an IMU mounted so that ``sensors.imu_*_deg`` = these undo it measures."""
    r_bi = dcm_from_euler(
        math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg)
    ).reshape(3, 3)
    i = log.imu
    return dataclasses.replace(
        log, imu=dataclasses.replace(i, gyro=i.gyro @ r_bi, accel=i.accel @ r_bi)
    )


def _swapped(log: Log) -> Log:
    """x and y exchanged: a left-handed frame."""
    i = log.imu
    swap = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    return dataclasses.replace(
        log, imu=dataclasses.replace(i, gyro=i.gyro @ swap, accel=i.accel @ swap)
    )


def _named(inputs: Inputs, log: Log, p: Params | None = None) -> list[str]:
    warnings = prepare_inputs(log, p or Params(), inputs.frame, ()).warnings
    return [w for w in warnings if any(n in w for n in NAMED)]


def _truth_rmse(inputs: Inputs, log: Log, p: Params) -> float:
    r = run(log, inputs.route, p, method="proposed", frame=inputs.frame)
    truth = method_metrics(r, inputs.route, log).truth  # type: ignore[arg-type]
    assert truth is not None and truth.rmse_h_err_m is not None
    return float(truth.rmse_h_err_m)


@pytest.mark.slow
@pytest.mark.parametrize("yaw_deg", [90.0, 180.0])
def test_the_setting_named_for_a_yawed_imu_gives_the_clean_run_back(yaw_deg: float) -> None:
    inputs = _monaco()
    log = _mounted(inputs.log, 0.0, 0.0, yaw_deg)
    (line,) = _named(inputs, log)
    assert "monaco_tunnel.mcap" in line and "s of acceleration" in line and "correlation" in line
    settings = dict((k, float(v)) for k, v in SETTING.findall(line))
    assert settings == {"sensors.imu_yaw_deg": yaw_deg}
    fixed = with_values(Params(), settings)
    assert _named(inputs, log, fixed) == []
    clean = _truth_rmse(inputs, inputs.log, Params())
    assert _truth_rmse(inputs, log, fixed) == pytest.approx(clean, abs=0.05)


@pytest.mark.parametrize("no_wheel", [False, True])
@pytest.mark.parametrize("yaw_deg", [10.0, 90.0, 180.0, -90.0])
def test_a_yawed_imu_is_named_with_or_without_wheels(no_wheel: bool, yaw_deg: float) -> None:
    inputs = _monaco(no_wheel)
    (line,) = _named(inputs, _mounted(inputs.log, 0.0, 0.0, yaw_deg))
    assert dict(SETTING.findall(line)) == {"sensors.imu_yaw_deg": f"{yaw_deg:g}"}
    source = "GNSS speed" if no_wheel else "wheel speed"
    assert source in line


def test_a_configured_yaw_is_corrected_from_not_replaced() -> None:
    """The IMU mounted at -90 with -100 configured: 10 deg off, and -90 is the fix."""
    inputs = _monaco()
    log = _mounted(inputs.log, 0.0, 0.0, -90.0)
    (line,) = _named(inputs, log, with_values(Params(), {"sensors.imu_yaw_deg": -100.0}))
    assert "with sensors.imu_yaw_deg = -100" in line
    assert dict(SETTING.findall(line)) == {"sensors.imu_yaw_deg": "-90"}


def test_an_imu_on_its_side_and_turned_is_given_roll_pitch_and_yaw() -> None:
    """The Husky's mounting (roll +90, yaw -90) on monaco: the yaw alone would stand the
    IMU's x axis on end, so all three are named, and they quieten the check."""
    inputs = _monaco()
    log = _mounted(inputs.log, 90.0, 0.0, -90.0)
    (line,) = _named(inputs, log)
    settings = dict((k, float(v)) for k, v in SETTING.findall(line))
    assert settings == {
        "sensors.imu_roll_deg": 90.0,
        "sensors.imu_pitch_deg": 0.0,
        "sensors.imu_yaw_deg": -90.0,
    }
    assert _named(inputs, log, with_values(Params(), settings)) == []


@pytest.mark.parametrize("no_wheel", [False, True])
def test_a_left_handed_imu_is_named_as_mirrored_without_a_setting(no_wheel: bool) -> None:
    inputs = _monaco(no_wheel)
    (line,) = _named(inputs, _swapped(inputs.log))
    assert "left-handed" in line and not SETTING.findall(line)


@pytest.mark.parametrize("no_wheel", [False, True])
@pytest.mark.parametrize("name", ["monaco_tunnel", "long_tunnel"])
def test_the_samples_and_a_2_deg_mount_are_not_named(name: str, no_wheel: bool) -> None:
    inputs = open_inputs(SAMPLES / f"{name}.mcap", topics=TopicChoice(no_wheel=no_wheel))
    assert _named(inputs, inputs.log) == []
    for yaw_deg in (2.0, -2.0):
        assert _named(inputs, _mounted(inputs.log, 0.0, 0.0, yaw_deg)) == []


@pytest.mark.parametrize("index", range(4))
def test_the_imu_only_drives_mounted_1_to_3_deg_are_not_named(index: int) -> None:
    inputs = build_imu_only(imu_only_spec(index)).inputs
    assert _named(inputs, inputs.log) == []


@pytest.mark.parametrize("no_wheel", [False, True])
@pytest.mark.parametrize("name", ["comma2k19/i280.mcap", "robot_localization/test1.bag"])
def test_the_real_logs_are_not_named(shared_data: Path, name: str, no_wheel: bool) -> None:
    path = shared_data / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    inputs = open_inputs(path, topics=TopicChoice(no_wheel=no_wheel))
    assert _named(inputs, inputs.log) == []
    if path.suffix == ".bag":
        assert _named(inputs, inputs.log, load_params(HUSKY_CONFIG)) == []
