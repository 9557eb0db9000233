"""The clock-step check judges the wheels on the GNSS speed's scale
(estimator.io.plausibility._wheels_on_the_gnss_scale). It dead-reckons with the wheel speed over
a whole tunnel: wheels reading 15-20 % fast (a tyre, a wheel radius configured wrong: within
what the wheel check takes, and the filter estimates as a state) made monaco's 1600 m tunnel
look 20 s too short, named as a step of the GNSS clock that was not there, and every fix after
the tunnel was left out of the run. A real step is still named with such wheels."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest

from estimator.io.plausibility import checked
from estimator.log import Log
from estimator.pipeline import Inputs, open_inputs
from estimator.sim import Simulation, simulate

REPO = Path(__file__).resolve().parents[3]
STEP_WORDS = "its clock steps"


@functools.cache
def _monaco() -> Inputs:
    return open_inputs(
        REPO / "sample_logs" / "monaco_tunnel.mcap",
        REPO / "sample_logs" / "monaco_tunnel.route.geojson",
    )


def _wheels_scaled(log: Log, scale: float) -> Log:
    assert log.wheel is not None
    wheel = dataclasses.replace(log.wheel, speed=scale * log.wheel.speed)
    return dataclasses.replace(log, wheel=wheel, warnings=())


@pytest.mark.parametrize("scale", [1.15, 1.2])
def test_wheels_reading_fast_make_no_clock_step_and_keep_the_fixes(scale: float) -> None:
    log = _wheels_scaled(_monaco().log, scale)
    out = checked(Path("monaco_tunnel.mcap"), log)
    assert not [w for w in out.warnings if STEP_WORDS in w], out.warnings
    assert np.array_equal(out.gnss.valid, log.gnss.valid)
    assert out.wheel is not None and np.array_equal(out.wheel.speed, log.wheel.speed)  # type: ignore[union-attr]


@functools.cache
def _drive() -> Simulation:
    return simulate("short_tunnel", seed=0)


def test_a_real_step_is_still_named_with_wheels_reading_fast() -> None:
    """+20 s at 20 s of the corpus drive, its wheels 15 % fast."""
    sim = _drive()
    t = sim.gnss.t
    gnss = dataclasses.replace(sim.gnss, t=np.where(t >= sim.imu.t[0] + 20.0, t + 20.0, t))
    log = Log("step.mcap", sim.imu, gnss, sim.wheel)
    out = checked(Path("step.mcap"), _wheels_scaled(log, 1.15))
    (line,) = [w for w in out.warnings if STEP_WORDS in w]
    assert "its clock steps 20.0 s forward after 19.8 s" in line, line
