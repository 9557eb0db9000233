"""Re-acquiring the heading from the route after an IMU gap inside a tunnel
(``extensions.gap_reacquire``): stress-corpus drive 36, a 28 s gap 2.3 km into the long tunnel,
which turns about 18 deg inside it. The wheels carry the position across along the last
heading; nothing but the route can tell the heading afterwards."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.evaluation.metrics import deviation_series
from estimator.params import Params, with_values
from estimator.pipeline import run, run_methods
from estimator.results import Run
from estimator.sim.stress import Drive, build, drive_spec


@pytest.fixture(scope="module")
def drive() -> Drive:
    return build(drive_spec(36))


@pytest.fixture(scope="module")
def runs(drive: Drive) -> dict[str, Run]:
    both = run_methods(drive.inputs, Params(), methods=("baseline", "proposed"))
    off = with_values(Params(), {"extensions.gap_reacquire": False})
    return {
        "baseline": both["baseline"],
        "proposed": both["proposed"],
        "off": run_methods(drive.inputs, off, methods=("proposed",))["proposed"],
    }


def _rmse_after_gap(run: Run, drive: Drive) -> float:
    route = drive.inputs.route
    assert route is not None
    truth = deviation_series(run, route, drive.inputs.log).truth
    assert truth is not None
    t = run.epochs.t[truth.index] - drive.inputs.log.t_start
    (_, b), *_ = run.degraded_intervals
    after = (t > 300.0) & (t < b - drive.inputs.log.t_start)
    assert after.sum() > 100
    return float(np.sqrt(np.mean(truth.h_err_m[after] ** 2)))


def test_the_gap_is_where_the_drive_says(drive: Drive) -> None:
    gap = np.diff(drive.inputs.log.imu.t)
    assert gap.max() == pytest.approx(drive.spec.imu_gap_s, abs=0.05)


def test_the_route_re_acquires_the_heading_the_gap_hid(runs: dict[str, Run], drive: Drive) -> None:
    baseline = _rmse_after_gap(runs["baseline"], drive)
    proposed = _rmse_after_gap(runs["proposed"], drive)
    off = _rmse_after_gap(runs["off"], drive)
    assert baseline > 300.0
    # without the switch the run after the gap is about dead reckoning's (within 10 %: the
    # map bias learned before the tunnel holds it closer to the road up to the gap)
    assert off > 0.85 * baseline
    assert proposed < 0.2 * baseline
    (first, *_) = [m for m in runs["proposed"].matches if "gap_end_s" in m.extra]
    assert first.accepted and first.reanchored
    # turned beyond what the rotation gate lets through without a gap, within the gap's bound
    turn = abs(math.degrees(first.rotation_rad))
    assert runs["proposed"].params.gates.max_rotation_deg < turn < 45.0
    assert first.heading_observation is not None
    assert first.heading_observation.correction_rad == pytest.approx(first.rotation_rad, rel=0.1)
    assert not any("gap_end_s" in m.extra for m in runs["off"].matches)


def test_the_re_acquisition_is_named(runs: dict[str, Run]) -> None:
    (line,) = [w for w in runs["proposed"].warnings if w.startswith("heading re-acquired")]
    assert "after the IMU gap that ended at 294." in line
    assert not any(w.startswith("heading re-acquired") for w in runs["off"].warnings)


@pytest.mark.parametrize("before", [False, True], ids=["switched on", "switched off"])
def test_a_re_run_with_the_switch_flipped_is_a_fresh_run(drive: Drive, before: bool) -> None:
    """The inspector re-runs from the first attempt whose outcome changes: a re-acquisition
    depends on the attempts before it, so flipping the switch must re-run from the first one
    after the gap that could re-anchor, not copy the old refusals."""
    inp = drive.inputs

    def params(on: bool) -> Params:
        return with_values(Params(), {"extensions.gap_reacquire": on})

    old = run(inp.log, inp.route, params(before), frame=inp.frame)
    reused = run(inp.log, inp.route, params(not before), frame=inp.frame, reuse=old)
    fresh = run(inp.log, inp.route, params(not before), frame=inp.frame)
    np.testing.assert_array_equal(reused.epochs.position, fresh.epochs.position)
    assert [m.accepted for m in reused.matches] == [m.accepted for m in fresh.matches]
    assert any(m.reanchored for m in fresh.matches) == (not before)
