"""Re-run reuse: a run resumed from a previous one equals a run from scratch, and resumes only
from where a parameter change makes a difference."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator.log import ImuData
from estimator.params import Params, matching_params, with_values
from estimator.pipeline import run
from tests.robustness._faultdrive import make_drive, route_along


def _same_epochs(a, b):
    fields = [f.name for f in dataclasses.fields(a.epochs)]
    return all(np.array_equal(getattr(a.epochs, f), getattr(b.epochs, f)) for f in fields)


@pytest.mark.parametrize(
    "change",
    [
        {"gates.max_residual_m": 0.2},
        {"window.length_m": 150.0},
        {"trigger.interval_s": 2.5},
        {"pseudo.sigma_m": 5.0},
        {"noise.nhc_sigma_m_s": 0.3},
        {"extensions.map_bias": True},
        {"extensions.map_bias": True, "offset.map_bias_prior_sigma_m": 3.0},
    ],
)
def test_reuse_gives_the_same_run_as_starting_over(tunnel, tunnel_proposed, change):
    log, route, frame = tunnel
    p = with_values(Params(), change)
    again = run(log, route, p, method="proposed", frame=frame, reuse=tunnel_proposed)
    fresh = run(log, route, p, method="proposed", frame=frame)
    assert _same_epochs(again, fresh)
    assert len(again.matches) == len(fresh.matches)
    for a, b in zip(again.matches, fresh.matches, strict=True):
        assert (a.index, a.epoch, a.accepted, a.verdict) == (
            b.index,
            b.epoch,
            b.accepted,
            b.verdict,
        )
        np.testing.assert_array_equal(a.correction, b.correction)
        assert a.gates == b.gates


def test_reuse_of_a_baseline_run_for_proposed(tunnel):
    log, route, frame = tunnel
    base = run(log, route, Params(), method="baseline", frame=frame)
    again = run(log, route, Params(), method="proposed", frame=frame, reuse=base)
    fresh = run(log, route, Params(), method="proposed", frame=frame)
    assert _same_epochs(again, fresh)
    assert [m.accepted for m in again.matches] == [m.accepted for m in fresh.matches]


def test_reuse_is_ignored_for_another_log(tunnel, tunnel_proposed):
    log, route, frame = tunnel
    gyro = log.imu.gyro.copy()
    gyro[:, 2] += np.radians(0.01)  # another log: same times, a different gyro
    other = dataclasses.replace(log, imu=ImuData(t=log.imu.t, gyro=gyro, accel=log.imu.accel))
    again = run(other, route, Params(), method="proposed", frame=frame, reuse=tunnel_proposed)
    fresh = run(other, route, Params(), method="proposed", frame=frame)
    assert _same_epochs(again, fresh)
    assert not _same_epochs(again, tunnel_proposed)
    # a copy of the same log is the same log (a Run can be pickled and reused)
    same = dataclasses.replace(log)
    assert _same_epochs(
        run(same, route, Params(), frame=frame, reuse=tunnel_proposed), tunnel_proposed
    )


def test_baseline_after_baseline_reuses_the_whole_run(tunnel, monkeypatch):
    """Matching parameters do not touch the baseline: the re-run is the previous run."""
    log, route, frame = tunnel
    base = run(log, route, Params(), method="baseline", frame=frame)
    p = with_values(Params(), {"gates.max_residual_m": 0.5, "window.length_m": 150.0})
    fresh = run(log, route, p, method="baseline", frame=frame)
    from estimator.filter import engine

    def no_filter(*args, **kwargs):
        raise AssertionError("the filter ran")

    monkeypatch.setattr(engine, "run_until", no_filter)
    again = run(log, route, p, method="baseline", frame=frame, reuse=base)
    assert _same_epochs(again, fresh) and again.params == p and again.matches == ()
    assert again.dropped_fix_times == fresh.dropped_fix_times
    assert again.epochs is base.epochs  # shared: what was computed from them is recognised


@pytest.mark.parametrize(
    "change",
    [{"gates.max_residual_m": 2.9}, {"gates.min_pairs": 52}, {"gates.max_rotation_deg": 1}],
)
def test_a_gate_change_refits_no_attempt_before_the_first_changed_outcome(
    tunnel, tunnel_proposed, monkeypatch, change
):
    log, route, frame = tunnel
    p = with_values(Params(), change)
    fresh = run(log, route, p, method="proposed", frame=frame)
    changed = [
        i
        for i, (a, b) in enumerate(zip(fresh.matches, tunnel_proposed.matches, strict=False))
        if a.accepted != b.accepted
    ]
    from estimator.pipeline import driver

    fits = []
    real = driver.match_geometry

    def counting(*args, **kwargs):
        fits.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(driver, "match_geometry", counting)
    again = run(log, route, p, method="proposed", frame=frame, reuse=tunnel_proposed)
    assert _same_epochs(again, fresh)
    assert [m.gates for m in again.matches] == [m.gates for m in fresh.matches]
    if not changed:
        assert not fits  # only re-judged
    else:
        # live again from the first changed attempt on (long windows may add fits)
        assert 0 < len(fits) <= 2 * (len(fresh.matches) - changed[0])


def test_reuse_of_a_map_bias_run_after_its_prior_changes(tunnel):
    """The map bias's covariance is a filter state: a run whose bias prior changed is not
    taken over attempt by attempt from the previous one, yet equals a fresh run."""
    log, route, frame = tunnel
    on = with_values(Params(), {"extensions.map_bias": True})
    first = run(log, route, on, method="proposed", frame=frame)
    p = with_values(on, {"offset.map_bias_prior_sigma_m": 2.0})
    again = run(log, route, p, method="proposed", frame=frame, reuse=first)
    fresh = run(log, route, p, method="proposed", frame=frame)
    assert _same_epochs(again, fresh)
    assert [m.verdict for m in again.matches] == [m.verdict for m in fresh.matches]


def test_reuse_of_a_re_anchored_run_equals_starting_over():
    """Re-anchoring depends on the live filter: a re-run after a gate change that shares the
    attempts before a re-anchor judges it live again, and equals a fresh run."""
    drive = make_drive(
        [(0, 15), (400, 15)],
        [(0, 0), (200, 0)],
        duration=160,
        outages=[(60, 130)],
        gyro_bias_deg_h=(10.0, -8.0, 0.0),
    )
    gyro = drive.log.imu.gyro.copy()
    t = drive.log.imu.t - drive.log.imu.t[0]
    gyro[(t > 60) & (t < 130), 2] += np.radians(0.15)
    log = dataclasses.replace(drive.log, imu=dataclasses.replace(drive.log.imu, gyro=gyro))
    route = route_along(drive, 0, 160, extend_m=100)
    on = with_values(Params(), {"extensions.reanchor": True})
    first = run(log, route, on, method="proposed", frame=drive.frame)
    assert any(m.reanchored for m in first.matches)
    p = with_values(on, {"gates.max_lateral_jump_m": 4.0})
    again = run(log, route, p, method="proposed", frame=drive.frame, reuse=first)
    fresh = run(log, route, p, method="proposed", frame=drive.frame)
    assert _same_epochs(again, fresh)
    assert [m.verdict for m in again.matches] == [m.verdict for m in fresh.matches]


@pytest.fixture(scope="module")
def turned_map_drive():
    from estimator.sim.stress import build, drive_spec

    inputs = build(drive_spec(10)).inputs  # three tunnels, a map shifted and turned
    return inputs, run(inputs.log, inputs.route, Params(), frame=inputs.frame)


@pytest.mark.parametrize(
    "change",
    [
        {"extensions.geometry_covariance": False},
        {"extensions.weak_along_track": False},
        {"extensions.map_turn_two_places": False},
        {"extensions.map_turn_honest_consider": True},
        {"extensions.map_turn_release": False},
        {"extensions.rotation_consistency": True, "gates.rotation_chi2": 1.0},
        {"offset.map_bias_estimated": False},
        {"pseudo.shape_noise_m": 1.5},
        {"pseudo.along_sigma_min_m": 0.75},
        {"window.length_m": 375.0},
        {"window.spacing_m": 7.5},
    ],
)
def test_reuse_on_a_turned_map_gives_the_same_run_as_starting_over(turned_map_drive, change):
    """Changes that a re-judged attempt does not show: how an accepted match is applied
    (geometry_covariance, weak_along_track), what is learned of the map before each outage and
    cloned into the filter there (the map bias's fit reads the shape and window parameters
    too), the kernel's own flag for estimating the route's errors, and the attempts' spacing.
    Each differed from a fresh run by 1 mm to 22 m before it was handled."""
    inputs, before = turned_map_drive
    p = with_values(Params(), change)
    again = run(inputs.log, inputs.route, p, frame=inputs.frame, reuse=before)
    fresh = run(inputs.log, inputs.route, p, frame=inputs.frame)
    assert _same_epochs(again, fresh)
    assert [m.accepted for m in again.matches] == [m.accepted for m in fresh.matches]


def test_reuse_with_the_along_drift_evidence_flipped_gives_the_same_run_as_starting_over() -> None:
    """``extensions.along_drift_evidence`` grows the filter's covariance between attempts, so
    the old run's saved states are not the new run's: a re-run with it flipped must run the
    outages live, not re-judge the old attempts (a no-odometer corpus drive, the rest of the
    wheel-less caution as it is)."""
    from estimator.sim.stress import build, drive_spec

    inputs = build(drive_spec(2)).inputs
    assert inputs.log.wheel is None
    cautious = matching_params(Params(), have_wheel=False)

    def params(on: bool) -> Params:
        values = {"extensions.no_wheel_caution": False, "extensions.along_drift_evidence": on}
        return with_values(cautious, values)

    old = run(inputs.log, inputs.route, params(False), frame=inputs.frame)
    again = run(inputs.log, inputs.route, params(True), frame=inputs.frame, reuse=old)
    fresh = run(inputs.log, inputs.route, params(True), frame=inputs.frame)
    assert not np.array_equal(old.epochs.position, fresh.epochs.position)
    assert _same_epochs(again, fresh)


def test_the_replay_compares_extensions_that_exist() -> None:
    from estimator.params.declarations import ExtensionParams
    from estimator.pipeline.reuse import MATCHING_EXTENSIONS

    fields = {f.name for f in dataclasses.fields(ExtensionParams)}
    assert set(MATCHING_EXTENSIONS) <= fields
    assert len(set(MATCHING_EXTENSIONS)) == len(MATCHING_EXTENSIONS)


REPLAYED_ATTEMPT_BY_ATTEMPT = frozenset(
    {
        "candidate_validation",
        "along_track_search",
        "lane_path_matching",
        "long_window",
        "overlap_inflation",
        "curvature_covariance",
        "covariance_search",
        "window_scale_covariance",
        "search_correction_cap",
        "map_bias_portal_cut",
        "dr_separation_gyro_scale",
        "rotation_consistency",
    }
)
"""extensions a re-run meets by replaying the old attempts (the map bias's fit is redone at
each outage's start and compared): neither the filter's key nor the trigger's"""


def test_every_extension_is_placed_for_re_runs() -> None:
    """A new switch must say how a re-run meets it: in the filter's key (the filter runs
    again), among the extensions that decide where attempts fall (replayed from the first
    outage), or replayed attempt by attempt. ``portal_rerun_after_alignment`` was in none
    of them, and a re-run after flipping it was served the old filter."""
    from estimator.params.declarations import ExtensionParams
    from estimator.pipeline.reuse import MATCHING_EXTENSIONS, filter_key

    base = Params()
    in_key = set()
    for f in dataclasses.fields(ExtensionParams):
        flipped = with_values(base, {f"extensions.{f.name}": not getattr(base.extensions, f.name)})
        if filter_key(flipped) != filter_key(base):
            in_key.add(f.name)
    fields = {f.name for f in dataclasses.fields(ExtensionParams)}
    placed = in_key | set(MATCHING_EXTENSIONS) | REPLAYED_ATTEMPT_BY_ATTEMPT
    assert fields == placed, sorted(fields - placed)
    assert "portal_rerun_after_alignment" in in_key
