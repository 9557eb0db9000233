"""An accelerometer bias estimated far beyond its prior is named (``driver.accel_bias_warnings``):
most often it is gravity seen through an IMU mounted tilted that the config does not give, and
the outages then drift along the road while the filter's sigma says they do not."""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from estimator.filter.alignment import MG
from estimator.filter.layout import NE, NX, X_BA
from estimator.io import TopicChoice
from estimator.params import Params, load_params, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.pipeline.driver import accel_bias_warnings
from inspector.app.playback import MAX_WARNING_CHARS

CONFIG = Path(__file__).resolve().parents[3] / "sample_logs" / "configs" / "comma2k19_i280.toml"
LINE = re.compile(
    r"the accelerometer's (?P<axis>forward|lateral) bias is estimated at (?P<mg>[-+]\d+) mg, "
    r"(?P<n>\d+) times its 10 mg prior sigma, at the outage at (?P<a>[\d.]+) s: gravity through "
    r"an IMU mounted (?P<deg>[\d.]+) deg (?P<how>nose-down|nose-up|rolled left|rolled right)\? "
    r"The outages drift with it; give the mount \(sensors\.imu_(?:pitch|roll)_deg\) or, if "
    r"unknown, a sigma for it \(noise\.nhc_mount_sigma_deg\)$"
)


def _outage(bias: tuple[float, float, float], sigma: float) -> SimpleNamespace:
    x = np.zeros(NX)
    x[X_BA : X_BA + 3] = bias
    P = np.eye(NE) * sigma**2
    return SimpleNamespace(kind="outage", interval=0, state=(x, P, None, None))


def test_a_bias_beyond_four_prior_sigmas_and_three_of_its_own_is_named_with_its_tilt():
    g = 9.80665
    nose_down = _outage((-g * math.sin(math.radians(4.0)), 0.0, 0.0), 0.02)
    (line,) = accel_bias_warnings([nose_down], [(110.0, 150.0)], 10.0, Params())
    m = LINE.match(line)
    assert m is not None, line
    assert len(line) <= MAX_WARNING_CHARS  # shown whole in the inspector
    assert (m["axis"], m["a"], m["deg"], m["how"], m["mg"]) == (
        "forward",
        "100.0",
        "4.0",
        "nose-down",
        "-70",
    )
    rolled = _outage((0.0, 0.5, 0.0), 0.02)
    (line,) = accel_bias_warnings([rolled], [(110.0, 150.0)], 10.0, Params())
    assert LINE.match(line)["how"] == "rolled right"  # type: ignore[index]


def test_a_bias_within_its_prior_or_its_own_noise_is_not():
    prior = 10.0 * MG
    within = _outage((-3.9 * prior, 3.9 * prior, 0.0), 0.01)
    noisy = _outage((-0.5, 0.0, 0.0), 0.2)  # 2.5 of its own sigmas
    vertical = _outage((0.0, 0.0, 0.8), 0.01)  # the z bias: not a tilt
    for outage in (within, noisy, vertical):
        assert accel_bias_warnings([outage], [(0.0, 10.0)], 0.0, Params()) == ()
    wider = with_values(Params(), {"noise.accel_bias_init_sigma_mg": 20.0})
    assert accel_bias_warnings([_outage((-0.5, 0.0, 0.0), 0.01)], [(0.0, 10.0)], 0.0, wider) == ()


@pytest.fixture
def comma(shared_data: Path):
    log = shared_data / "comma2k19" / "i280.mcap"
    return open_inputs(log, log.with_name("i280_route.geojson"), topics=TopicChoice(no_wheel=True))


@pytest.mark.parametrize("method", ["baseline", "proposed"])
def test_comma2k19_without_its_mount_is_told_and_with_it_is_not(comma, method):
    """The EON is mounted 3.8 deg nose-down: run without the config, the forward bias comes out
    at about -64 mg against a 10 mg prior (the line names a 3.6 deg tilt), and the outage's
    error reaches tens of metres while the filter's sigma stays a fraction of it. With the
    config's mount the line is not there."""
    bare = run_methods(comma, Params(), methods=(method,), outages=[(20.0, 50.0)])[method]
    (line,) = [w for w in bare.warnings if w.startswith("the accelerometer")]
    m = LINE.match(line)
    assert m is not None, line
    assert m["axis"] == "forward" and m["how"] == "nose-down" and m["a"] == "20.0"
    assert 3.0 <= float(m["deg"]) <= 7.0
    mounted = run_methods(comma, load_params(CONFIG), methods=(method,), outages=[(20.0, 50.0)])[
        method
    ]
    assert not any(w.startswith("the accelerometer") for w in mounted.warnings)
