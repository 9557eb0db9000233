"""A gyro or accelerometer that reads exactly zero throughout (estimator.io.plausibility.
_imu_alive), or a gyro scaled wrong (_gyro_scale): a ROS driver that does not fill
``angular_velocity`` publishes zeros, and the run then dead-reckoned every outage straight on
(monaco: 952 m RMS) while its warnings spoke of few fixes used and refused matches, never of
the gyro; a gyro in mrad/s or scaled by ten went as far. No accelerations at all is refused."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError
from estimator.io import load_log
from estimator.io.plausibility import checked
from estimator.log import Log

REPO = Path(__file__).resolve().parents[3]
MONACO = REPO / "sample_logs" / "monaco_tunnel.mcap"


@functools.cache
def _monaco() -> Log:
    return dataclasses.replace(load_log(MONACO), warnings=())


def _with(gyro_scale: tuple[float, float, float], accel_scale: float = 1.0) -> Log:
    log = _monaco()
    imu = dataclasses.replace(
        log.imu, gyro=log.imu.gyro * np.array(gyro_scale), accel=log.imu.accel * accel_scale
    )
    return dataclasses.replace(log, imu=imu)


def test_a_gyro_that_reads_zero_is_named() -> None:
    (line,) = checked(MONACO, _with((0.0, 0.0, 0.0))).warnings
    assert line.startswith(
        "monaco_tunnel.mcap: IMU /imu/data: every angular_velocity sample is zero"
    )
    assert "dead-reckoned straight on" in line


def test_one_dead_axis_is_named() -> None:
    (line,) = checked(MONACO, _with((1.0, 1.0, 0.0))).warnings
    assert "every sample of its gyro z axis is zero" in line


def test_no_accelerations_is_refused_in_one_line() -> None:
    with pytest.raises(LogError) as err:
        checked(MONACO, _with((1.0, 1.0, 1.0), accel_scale=0.0))
    message = str(err.value)
    assert "\n" not in message and message.startswith(str(MONACO))
    assert "every linear_acceleration sample is zero" in message


def test_a_live_imu_says_nothing() -> None:
    assert not checked(MONACO, _monaco()).warnings


@pytest.mark.parametrize(
    ("scale", "cause"),
    [(1000.0, "mrad/s, not rad/s"), (0.1, "scaled wrong"), (3.0, "scaled wrong")],
)
def test_a_gyro_scaled_wrong_is_named(scale: float, cause: str) -> None:
    (line,) = checked(MONACO, _with((scale, scale, scale))).warnings
    assert line.startswith("monaco_tunnel.mcap: IMU /imu/data: its heading about gravity turns ")
    found = float(line.split("turns ")[1].split(" times")[0])
    assert found == pytest.approx(scale, rel=0.05)
    assert cause in line


def test_a_gyro_on_its_side_is_judged_about_gravity() -> None:
    """The Husky's IMU lies on its side (roll +90 deg): its z axis is horizontal, and the yaw
    rate is its y axis's. Turned so, monaco's gyro is still right and says nothing; scaled by
    ten it is named."""
    from estimator.nav.rotation import dcm_from_euler

    R = dcm_from_euler(np.pi / 2, 0.0, 0.0)[0]
    log = _monaco()
    on_side = dataclasses.replace(log.imu, gyro=log.imu.gyro @ R, accel=log.imu.accel @ R)
    assert abs(np.mean(on_side.accel[:, 2])) < 1.0  # z horizontal
    quiet = checked(MONACO, dataclasses.replace(log, imu=on_side)).warnings
    assert not [w for w in quiet if "about gravity" in w]
    scaled = dataclasses.replace(on_side, gyro=on_side.gyro * 10.0)
    (line,) = [
        w
        for w in checked(MONACO, dataclasses.replace(log, imu=scaled)).warnings
        if "about gravity" in w
    ]
    assert float(line.split("turns ")[1].split(" times")[0]) == pytest.approx(10.0, rel=0.05)


@pytest.mark.parametrize("apart_m", [1.0, 3.0])
def test_a_jittering_course_does_not_make_a_fine_gyro_look_scaled(apart_m: float) -> None:
    """Two receivers interleaved on one topic, ``apart_m`` apart: the course turns at every
    fix. A median of ratios over the windows it says turn read the gyro at 0.67 (1 m) and
    0.0002 (3 m) and named it; regressed on the gyro's turns, and judged only where the two
    turn alike, it says nothing."""
    log = _monaco()
    g = log.gnss
    lon = g.lon.copy()
    lon[::2] += apart_m / (111_320.0 * np.cos(np.radians(g.lat[::2])))
    jittering = dataclasses.replace(log, gnss=dataclasses.replace(g, lon=lon))
    assert not [w for w in checked(MONACO, jittering).warnings if "about gravity" in w]
