"""Re-acquiring the heading from the route after an IMU gap inside a tunnel
(``extensions.gap_reacquire``), where the gap is not bridged along the route
(``extensions.gap_route_bridge`` off, or no match placed the vehicle just before the gap): the
multi-tunnel sample with no IMU for 20 s inside its second tunnel, where the road turns 36 deg.
The wheels carry the position across along the last heading; nothing but the route can tell
the heading afterwards."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run, run_methods
from estimator.pipeline.inputs import Inputs
from estimator.results import Run
from tests.estimator._gaps import SAMPLES, errors_after, truth_turn_deg, without_imu

F64 = NDArray[np.float64]

GAP = (237.0, 257.0)
"""s after the log start: inside the multi-tunnel sample's second tunnel (197-291 s)"""
NO_BRIDGE = {"extensions.gap_route_bridge": False}


@pytest.fixture(scope="module")
def gapped() -> Inputs:
    multi = open_inputs(SAMPLES / "multi_tunnel.mcap", SAMPLES / "multi_tunnel.route.geojson")
    return without_imu(multi, *GAP)


@pytest.fixture(scope="module")
def runs(gapped: Inputs) -> dict[str, Run]:
    p = with_values(Params(), NO_BRIDGE)
    off = with_values(p, {"extensions.gap_reacquire": False})
    return {
        "proposed": run_methods(gapped, p, methods=("proposed",))["proposed"],
        "off": run_methods(gapped, off, methods=("proposed",))["proposed"],
    }


def test_the_road_turns_inside_the_gap(gapped: Inputs) -> None:
    assert truth_turn_deg(gapped, *GAP) == pytest.approx(-36.1, abs=0.5)


def test_the_route_re_acquires_the_heading_the_gap_hid(
    runs: dict[str, Run], gapped: Inputs
) -> None:
    (first, *_) = [m for m in runs["proposed"].matches if "gap_end_s" in m.extra]
    assert first.accepted and first.reanchored
    # turned beyond what the rotation gate lets through without a gap, within the gap's bound
    turn = abs(math.degrees(first.rotation_rad))
    assert runs["proposed"].params.gates.max_rotation_deg < turn < 45.0
    since = first.t - gapped.log.t_start + 0.5
    err, yaw_err = errors_after(runs["proposed"], gapped, GAP[1], since)
    err_off, yaw_err_off = errors_after(runs["off"], gapped, GAP[1], since)
    # heading and velocity turned by the whole rotation: the heading is the road's after it
    assert np.abs(yaw_err).max() < 2.0
    assert np.abs(yaw_err_off).min() > 30.0
    assert np.sqrt(np.mean(err**2)) < 0.3 * np.sqrt(np.mean(err_off**2))
    # the heading observation only narrows the variance of a heading already turned
    assert first.heading_observation is not None
    assert abs(first.heading_observation.yaw_rad) == 0.0
    assert abs(first.heading_observation.correction_rad) < math.radians(0.5)
    assert not any("gap_end_s" in m.extra for m in runs["off"].matches)


def test_the_re_acquisition_is_named(runs: dict[str, Run]) -> None:
    (line,) = [w for w in runs["proposed"].warnings if w.startswith("heading re-acquired")]
    assert "after the IMU gap that ended at 257.0 s" in line
    assert not any(w.startswith("heading re-acquired") for w in runs["off"].warnings)


@pytest.mark.parametrize("before", [False, True], ids=["switched on", "switched off"])
def test_a_re_run_with_the_switch_flipped_is_a_fresh_run(gapped: Inputs, before: bool) -> None:
    """The inspector re-runs from the first attempt whose outcome changes: a re-acquisition
    depends on the attempts before it, so flipping the switch must re-run from the first one
    after the gap that could re-anchor, not copy the old refusals."""

    def params(on: bool) -> Params:
        return with_values(Params(), {**NO_BRIDGE, "extensions.gap_reacquire": on})

    old = run(gapped.log, gapped.route, params(before), frame=gapped.frame)
    reused = run(gapped.log, gapped.route, params(not before), frame=gapped.frame, reuse=old)
    fresh = run(gapped.log, gapped.route, params(not before), frame=gapped.frame)
    np.testing.assert_array_equal(reused.epochs.position, fresh.epochs.position)
    assert [m.accepted for m in reused.matches] == [m.accepted for m in fresh.matches]
    assert any(m.reanchored for m in fresh.matches) == (not before)
