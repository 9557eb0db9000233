"""``extensions.exit_adapt``: an outage that ended beyond its sigmas widens the later ones' position
covariance by the walk that would have held it, and moves no dead-reckoned estimate inside them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator.evaluation.metrics import NEES_95_2DOF
from estimator.params import Params, with_values
from estimator.pipeline import Inputs, run
from estimator.pipeline.driver import isotropic_excess
from estimator.results import Run
from estimator.sim.imu_only import build_imu_only, imu_only_spec


def _excess_by_bisection(e: np.ndarray, C: np.ndarray, bound: float) -> float:
    def chi2(d: float) -> float:
        return float(e @ np.linalg.solve(C + d * np.eye(2), e))

    if chi2(0.0) <= bound:
        return 0.0
    lo, hi = 0.0, 1.0
    while chi2(hi) > bound:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2(mid) > bound else (lo, mid)
    return hi


def test_the_excess_is_the_least_isotropic_variance_that_holds_the_error() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        A = rng.normal(size=(2, 2)) * rng.uniform(0.1, 30.0)
        C = A @ A.T + 1e-3 * np.eye(2)
        e = rng.normal(size=2) * rng.uniform(0.1, 100.0)
        d = isotropic_excess(e, C, NEES_95_2DOF)
        assert d == pytest.approx(_excess_by_bisection(e, C, NEES_95_2DOF), rel=1e-7, abs=1e-9)
        if d > 0.0:
            chi2 = float(e @ np.linalg.solve(C + d * np.eye(2), e))
            assert chi2 == pytest.approx(NEES_95_2DOF, rel=1e-9)


def test_an_error_within_the_bound_needs_no_excess() -> None:
    C = np.diag([4.0, 1.0])
    assert isotropic_excess(np.array([2.0, 0.0]), C, NEES_95_2DOF) == 0.0
    assert isotropic_excess(np.zeros(2), C, NEES_95_2DOF) == 0.0


@pytest.fixture(scope="module")
def sim6() -> Inputs:
    """IMU-only sim 6 (multi tunnel, no wheel speed, the IMU mounted 1-3 deg off, its scale
    1.1 % off, none of it told to the filter): dead reckoning ends its first outage 110 m from
    the returning fixes under a 31 m sigma, beyond the exit check's bound."""
    return build_imu_only(imu_only_spec(6)).inputs


def test_it_is_on_by_default() -> None:
    assert Params().extensions.exit_adapt


def _baseline(inputs: Inputs, on: bool) -> Run:
    p = with_values(Params(), {"extensions.exit_adapt": on})
    return run(inputs.log, inputs.route, p, method="baseline", frame=inputs.frame)


def test_the_next_outage_is_widened_by_the_walk_its_predecessor_lacked_and_nothing_moves(
    sim6: Inputs,
) -> None:
    off, on = _baseline(sim6, False), _baseline(sim6, True)
    first, second = off.exits[0], off.exits[1]
    assert first.overconfident and second.overconfident
    walk = isotropic_excess(first.error, first.estimate_cov + first.fix_cov, NEES_95_2DOF) / (
        first.fix_t[0] - first.start
    )
    a2, b2 = off.degraded_intervals[1]
    t = off.epochs.t
    assert np.array_equal(on.epochs.t, t)
    # up to the second outage's start nothing differs; inside it only the position's variance
    before = t < a2
    inside = (t >= a2) & (t < b2)
    for f in dataclasses.fields(off.epochs):
        a, b = getattr(off.epochs, f.name), getattr(on.epochs, f.name)
        assert np.array_equal(a[before], b[before]), f.name
    assert np.array_equal(off.epochs.position[inside], on.epochs.position[inside])
    assert np.array_equal(off.epochs.velocity[inside], on.epochs.velocity[inside])
    assert np.array_equal(off.epochs.attitude[inside], on.epochs.attitude[inside])
    assert np.array_equal(off.epochs.position_cov_en[inside], on.epochs.position_cov_en[inside])
    k = np.flatnonzero(inside)
    added = on.epochs.position_sigma[k, :2] ** 2 - off.epochs.position_sigma[k, :2] ** 2
    grown = walk * (t[k] - a2)
    np.testing.assert_allclose(added[:, 0], grown, rtol=0.02, atol=0.5 * walk)
    np.testing.assert_allclose(added[:, 0], added[:, 1], rtol=1e-9)
    # the second outage, flagged without the walk, is within its sigmas with it
    assert on.exits[1].start == second.start
    assert not on.exits[1].overconfident
    assert on.exits[1].estimate_sigma_m > 2.0 * second.estimate_sigma_m


def test_the_walk_is_capped(sim6: Inputs) -> None:
    """Fixes worse than they claim could flag every outage; the walks must not add up without
    end (``noise.exit_walk_max_m2_s``; sim 6's first exit asks 12.7 m^2/s)."""
    capped = with_values(Params(), {"noise.exit_walk_max_m2_s": 1.0})
    on = run(sim6.log, sim6.route, capped, method="baseline", frame=sim6.frame)
    off = _baseline(sim6, False)
    a2, b2 = off.degraded_intervals[1]
    t = off.epochs.t
    k = np.flatnonzero((t >= a2) & (t < b2))
    added = on.epochs.position_sigma[k, 0] ** 2 - off.epochs.position_sigma[k, 0] ** 2
    np.testing.assert_allclose(added, 1.0 * (t[k] - a2), rtol=0.02, atol=0.5)


def test_an_outage_the_route_updates_pulled_off_widens_nothing(sim6: Inputs) -> None:
    """routefuse's second outage on sim 6 ends beyond its sigmas with route updates applied:
    the route's error, which a wider dead-reckoning covariance would let pull harder."""
    p = with_values(Params(), {"extensions.exit_adapt": True})
    on = run(sim6.log, sim6.route, p, method="proposed", frame=sim6.frame)
    off = run(sim6.log, sim6.route, _off(), method="proposed", frame=sim6.frame)
    assert [x.overconfident for x in off.exits] == [False, True, False]
    assert any(m.accepted and m.t <= off.exits[1].end for m in off.matches)
    for f in dataclasses.fields(off.epochs):
        assert np.array_equal(getattr(off.epochs, f.name), getattr(on.epochs, f.name)), f.name


def _off() -> Params:
    return with_values(Params(), {"extensions.exit_adapt": False})


def _dead_reckoned_first(on: bool, **values: object) -> Params:
    """routefuse with the first outage left to dead reckoning (2 km of GNSS driving asked
    before route updates; sim 6 has 1.7 km before its first tunnel)."""
    return with_values(
        Params(),
        {"extensions.exit_adapt": on, "trigger.min_approach_m": 2000.0, **values},
    )


def test_routefuse_after_a_dead_reckoned_outage_beyond_its_sigmas(sim6: Inputs) -> None:
    runs = {
        on: run(sim6.log, sim6.route, _dead_reckoned_first(on), frame=sim6.frame)
        for on in (False, True)
    }
    off, on = runs[False], runs[True]
    a1, b1 = off.degraded_intervals[0]
    assert not any(a1 <= m.t <= b1 for m in off.matches)
    assert off.exits[0].overconfident and on.exits[0].overconfident
    # the second outage's route updates were weighed against the wider covariance
    assert on.exits[1].estimate_sigma_m > off.exits[1].estimate_sigma_m
    assert on.exits[1].chi2 < off.exits[1].chi2


def test_a_matching_change_resumed_from_the_old_run_equals_starting_over(sim6: Inputs) -> None:
    """The run's walk is carried in the filter's state, so a re-run that resumes from an
    attempt saved in the widened outage has the walk the earlier exit gave, as a run from
    the start would."""
    old = run(sim6.log, sim6.route, _dead_reckoned_first(True), frame=sim6.frame)
    changed = _dead_reckoned_first(True, **{"window.length_m": 150.0})
    again = run(sim6.log, sim6.route, changed, frame=sim6.frame, reuse=old)
    fresh = run(sim6.log, sim6.route, changed, frame=sim6.frame)
    for f in dataclasses.fields(fresh.epochs):
        assert np.array_equal(getattr(again.epochs, f.name), getattr(fresh.epochs, f.name)), f.name
    assert [m.accepted for m in again.matches] == [m.accepted for m in fresh.matches]
    assert not np.array_equal(old.epochs.position, fresh.epochs.position)


def test_the_paper_method_has_no_walk(sim6: Inputs) -> None:
    p = with_values(Params(), {"extensions.exit_adapt": True})
    on = run(sim6.log, sim6.route, p, method="paper", frame=sim6.frame)
    off = run(sim6.log, sim6.route, _off(), method="paper", frame=sim6.frame)
    assert np.array_equal(on.epochs.position_sigma, off.epochs.position_sigma)


def test_an_imu_gap_widens_nothing_after_it() -> None:
    """60 s without IMU in open sky on the long tunnel: the position carried along the wheels
    ends its gap far beyond its sigmas (the road turned), but the filter is aligned afresh
    after it; a walk from it took the tunnel that follows 2.7 -> 72 m."""
    from pathlib import Path

    from estimator.pipeline import open_inputs
    from tests.robustness.test_imu_gaps import without_imu

    samples = Path(__file__).resolve().parents[3] / "sample_logs"
    inputs = open_inputs(samples / "long_tunnel.mcap", samples / "long_tunnel.route.geojson")
    gapped = without_imu(inputs, 20.0, 80.0)
    on = run(gapped.log, gapped.route, Params(), frame=gapped.frame)
    off = run(gapped.log, gapped.route, _off(), frame=gapped.frame)
    assert on.exits[0].overconfident and on.exits[0].chi2 > 1e3
    for f in dataclasses.fields(off.epochs):
        assert np.array_equal(getattr(off.epochs, f.name), getattr(on.epochs, f.name)), f.name
