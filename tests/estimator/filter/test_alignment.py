"""Initial alignment robust to bad first fixes (issue 17, item 3): the heading is taken from a
chord whose fixes between agree with it and whose length the wheels confirm; the fixes left
out are named. Without wheel speed, a car accelerating as the log begins is levelled with the
GNSS track's acceleration (``extensions.align_track_accel``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics, outage_errors
from estimator.filter.alignment import ACCEL_PRIOR_SIGMA_M_S2, _tilt, _track_accel
from estimator.io import TopicChoice
from estimator.params import Params, load_params, with_values
from estimator.pipeline import open_inputs, run, run_methods
from estimator.pipeline.inputs import Inputs
from inspector.app.playback import MAX_WARNING_CHARS

REPO = Path(__file__).resolve().parents[3]
SAMPLES = REPO / "sample_logs"
COMMA = REPO.parent / "shared" / "data" / "comma2k19" / "i280.mcap"
COMMA_CONFIG = SAMPLES / "configs" / "comma2k19_i280.toml"
needs_comma = pytest.mark.skipif(not COMMA.exists(), reason=f"real data not found: {COMMA}")
M_PER_DEG_LAT = 111_320.0


@pytest.fixture(scope="module")
def monaco() -> Inputs:
    return open_inputs(SAMPLES / "monaco_tunnel.mcap", SAMPLES / "monaco_tunnel.route.geojson")


def _moved(inputs: Inputs, metres: float, which: list[int]) -> Inputs:
    g = inputs.log.gnss
    lat = g.lat.copy()
    valid = np.flatnonzero(g.valid)
    lat[valid[which]] += metres / M_PER_DEG_LAT
    log = dataclasses.replace(inputs.log, gnss=dataclasses.replace(g, lat=lat))
    return dataclasses.replace(inputs, log=log)


def _truth_rmse(inputs: Inputs, method: str = "proposed") -> tuple[float, tuple[str, ...]]:
    run = run_methods(inputs, Params(), methods=(method,))[method]
    assert inputs.route is not None
    truth = method_metrics(run, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return truth.rmse_h_err_m, run.warnings


@pytest.mark.parametrize(
    ("metres", "which"),
    [(50.0, [0]), (10.0, [0]), (50.0, [0, 3, 6])],
    ids=["first fix 50 m off", "first fix 10 m off", "three of the first ten 50 m off"],
)
def test_bad_first_fixes_neither_turn_the_heading_nor_go_unsaid(
    monaco: Inputs, metres: float, which: list[int]
) -> None:
    clean, _ = _truth_rmse(monaco)
    rmse, warnings = _truth_rmse(_moved(monaco, metres, which))
    assert rmse <= max(3.0, clean + 0.3)
    if metres >= 50.0:
        left_out = [w for w in warnings if "left out of the initial alignment" in w]
        assert len(left_out) == len(which)
        assert all(f"{metres:.0f} m off" in w or f"{metres + 1:.0f} m off" in w for w in left_out)


def _told(t: np.ndarray, pos: np.ndarray, heading: np.ndarray) -> tuple[float, float]:
    told = _track_accel(t, pos, heading)
    assert told is not None
    return told


def test_the_tracks_acceleration_is_the_parabolas_where_the_fixes_tell_it() -> None:
    t = np.arange(0.0, 1.01, 0.1)
    yaw = np.radians(30.0)
    along = 9.0 * t + 0.5 * 1.4 * t**2
    pos = np.column_stack([np.cos(yaw) * along, np.sin(yaw) * along])
    noise = np.random.default_rng(3).normal(0.0, 0.005, pos.shape)
    heading = np.full_like(t, yaw)
    acc, var = _told(t, pos + noise, heading)
    assert acc == pytest.approx(1.4, abs=0.1)
    assert var < 0.01 * ACCEL_PRIOR_SIGMA_M_S2**2
    # scattered by 10 cm the fit is still surer than the prior, which pulls it in a little
    fair = pos + np.random.default_rng(5).normal(0.0, 0.1, pos.shape)
    acc, var = _told(t, fair, heading)
    assert 0.0 < var < 0.5 * ACCEL_PRIOR_SIGMA_M_S2**2 and abs(acc - 1.4) < 3 * np.sqrt(var) + 0.1
    # scattered by a metre, or too few for a parabola and its scatter, they tell nothing: the
    # alignment levels as without them (no acceleration, its tilt sigma not widened)
    noisy = pos + np.random.default_rng(4).normal(0.0, 1.0, pos.shape)
    assert _track_accel(t, noisy, heading) is None
    assert _track_accel(t[:5], pos[:5], heading[:5]) is None


def test_a_turning_chord_at_a_steady_speed_has_no_track_acceleration() -> None:
    """A chord may turn 30 deg (``_chord_heading``): its steps are taken along the yaw between
    the fixes, or the arc's shortening against one direction would read as 1.3 m/s^2 (8 deg of
    pitch) at a steady 10 m/s."""
    t = np.arange(0.0, 1.01, 0.1)
    yaw = np.radians(30.0) * t
    radius = 10.0 / np.radians(30.0)
    pos = np.column_stack([radius * np.sin(yaw), radius * (1.0 - np.cos(yaw))])
    acc, _ = _told(t, pos, yaw)
    assert abs(acc) < 0.02
    acc, _ = _told(t, pos, np.full_like(t, yaw[-1]))
    assert acc > 1.0


def _comma_first_pitch(no_wheel: bool, track_accel: bool = True) -> float:
    inputs = open_inputs(COMMA, topics=TopicChoice(no_wheel=no_wheel))
    params = with_values(
        load_params(COMMA_CONFIG), {"extensions.align_track_accel": track_accel}
    )
    r = run(inputs.log, None, params, method="baseline", frame=inputs.frame)
    return float(np.degrees(r.epochs.attitude[0, 1]))


@needs_comma
def test_an_alignment_without_wheel_speed_levels_with_the_tracks_acceleration() -> None:
    """comma2k19 starts at 8 m/s, accelerating 1.4 m/s^2. With its wheel speed the alignment
    takes that acceleration out of the accelerometer before levelling; without it, it used to
    level the acceleration too, 8 deg nose-up (under a 1.5 deg sigma). The GNSS track's
    parabola now stands in for the wheels."""
    with_wheels = _comma_first_pitch(no_wheel=False)
    assert abs(_comma_first_pitch(no_wheel=True) - with_wheels) < 1.0
    assert _comma_first_pitch(no_wheel=True, track_accel=False) - with_wheels > 5.0


def _thinned(inputs: Inputs, step: int) -> Inputs:
    g = inputs.log.gnss
    keep = np.arange(len(g.t)) % step == 0
    fields = ("t", "lat", "lon", "alt", "status", "cov_enu")
    thinned = dataclasses.replace(g, **{f: getattr(g, f)[keep] for f in fields})
    return dataclasses.replace(inputs, log=dataclasses.replace(inputs.log, gnss=thinned))


@needs_comma
def test_a_two_hertz_receiver_levels_with_the_fixes_after_its_chord() -> None:
    """comma2k19 thinned to 2 Hz: the one-second aligning chord holds three fixes, too few for
    a parabola, and it was levelled as if the car held its speed, 6.6 deg nose-up (the wheels'
    run: -1.4 deg). ``extensions.align_track_accel_ahead`` adds the fixes after the aligning one
    (six within 5 s of the chord's start) and the level is the wheels' to a degree."""
    with_wheels = _comma_first_pitch(no_wheel=False)
    inputs = _thinned(open_inputs(COMMA, topics=TopicChoice(no_wheel=True)), 5)
    pitch = {}
    for ahead in (True, False):
        params = with_values(
            load_params(COMMA_CONFIG), {"extensions.align_track_accel_ahead": ahead}
        )
        r = run(inputs.log, None, params, method="baseline", frame=inputs.frame)
        pitch[ahead] = float(np.degrees(r.epochs.attitude[0, 1]))
        warned = [w for w in r.warnings if w.startswith("initial alignment")]
        assert bool(warned) is not ahead
    assert abs(pitch[True] - with_wheels) < 1.5
    assert pitch[False] - with_wheels > 5.0


@needs_comma
def test_an_outage_from_the_logs_third_second_is_dead_reckoned_honestly() -> None:
    """GNSS removed 3 s after comma2k19's start, wheel speed left out: levelled through the
    car's acceleration, dead reckoning ran 125.6 m RMS off truth while claiming a sigma a
    fifth of that (mean NEES 26.9); levelled with the track's acceleration 24.8 m, NEES 2.7."""
    inputs = open_inputs(COMMA, topics=TopicChoice(no_wheel=True))
    figures = {}
    for on in (True, False):
        params = with_values(load_params(COMMA_CONFIG), {"extensions.align_track_accel": on})
        r = run(
            inputs.log, None, params, method="baseline", frame=inputs.frame, outages=[(3.0, 61.0)]
        )
        err, nees = outage_errors(r, inputs.log, inputs.frame)
        figures[on] = (float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), float(nees.mean()))
    assert figures[True][0] < 40.0 and figures[True][1] < 4.0
    assert figures[False][0] > 80.0 and figures[False][1] > 10.0


def test_a_broken_chord_gives_no_acceleration_rather_than_an_error() -> None:
    """NaN in a fix or a heading, or every fix at one time, leave the alignment as without the
    track's acceleration (and never a NaN in the state)."""
    t = np.arange(0.0, 1.01, 0.1)
    pos = np.column_stack([9.0 * t + 0.7 * t**2, np.zeros_like(t)])
    heading = np.zeros_like(t)
    bad_fix = pos.copy()
    bad_fix[3, 0] = np.nan
    bad_heading = heading.copy()
    bad_heading[2] = np.nan
    assert _track_accel(t, bad_fix, heading) is None
    assert _track_accel(t, pos, bad_heading) is None
    assert _track_accel(np.zeros_like(t), pos, heading) is None
    acc, var = _told(t, pos, heading)
    assert acc == pytest.approx(1.4) and var == pytest.approx(0.0, abs=1e-9)


def test_a_dead_accelerometer_is_levelled_without_a_division_by_its_zero() -> None:
    """An accelerometer reading zeros over the alignment's second (a dead sensor) was levelled
    flat with its 1.5 deg sigma; the track's acceleration must not turn that into a
    ZeroDivisionError (it did, between 2d65fb6 and this test)."""
    t = np.arange(0.0, 2.0, 0.01)
    zeros = np.zeros((len(t), 3))
    moving = np.zeros(len(t), bool)
    roll, pitch, sigma = _tilt(t, zeros, zeros, moving, 1.5, 150, 10.0, 0.0, 0.0)
    assert (roll, pitch) == (0.0, 0.0) and sigma == pytest.approx(np.radians(1.5))
    *_, sigma = _tilt(t, zeros, zeros, moving, 1.5, 150, 10.0, 0.5, 0.01)
    assert np.isfinite(sigma) and sigma > np.radians(1.5)


def _alignment_warnings(inputs: Inputs, params: Params) -> list[str]:
    r = run(inputs.log, None, params, method="baseline", frame=inputs.frame)
    return [w for w in r.warnings if w.startswith("initial alignment")]


def test_an_alignment_that_cannot_tell_the_cars_acceleration_says_so() -> None:
    """A 5-10 Hz receiver gives a one-second chord five or six fixes, too few for the track's
    parabola; without wheel speed the alignment then levels as if the car held its speed, and
    the run's warnings say where, from how many fixes, and what tilt sigma it claimed. With
    wheel speed (or where the fixes tell the acceleration) nothing is said."""
    path = SAMPLES / "monaco_tunnel.mcap"
    wheel_less = open_inputs(path, topics=TopicChoice(no_wheel=True))
    (said,) = _alignment_warnings(wheel_less, Params())
    assert "no wheel speed" in said and "6 fixes over 1.0 s" in said and "claims 0.3 deg" in said
    assert len(said) <= MAX_WARNING_CHARS  # the inspector shows it whole
    assert _alignment_warnings(open_inputs(path), Params()) == []
    off = with_values(Params(), {"extensions.align_track_accel": False})
    assert _alignment_warnings(wheel_less, off) == []


@needs_comma
def test_a_ten_hertz_track_that_tells_the_acceleration_draws_no_warning() -> None:
    inputs = open_inputs(COMMA, topics=TopicChoice(no_wheel=True))
    assert _alignment_warnings(inputs, load_params(COMMA_CONFIG)) == []
