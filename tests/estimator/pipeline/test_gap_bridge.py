"""Bridging an IMU gap along the route (``extensions.gap_route_bridge``): the spiral sample with
no IMU for 20 s inside its tunnel, where the road turns 58.7 deg. The wheels carry the position
across the gap along the heading before it; the route says where the same distance along the
road is, and which way the road runs there."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.typing import NDArray

from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run, run_methods
from estimator.pipeline.driver import road_turn
from estimator.pipeline.inputs import Inputs
from estimator.results import Gate, MatchRecord, Run
from estimator.route import Route
from tests.estimator._gaps import SAMPLES, errors_after, truth_turn_deg, without_imu

F64 = NDArray[np.float64]

GAP = (176.0, 196.0)
"""s after the log start: 20 s inside the spiral tunnel (121-341 s)"""


@pytest.fixture(scope="module")
def gapped() -> Inputs:
    spiral = open_inputs(SAMPLES / "spiral_tunnel.mcap", SAMPLES / "spiral_tunnel.route.geojson")
    return without_imu(spiral, *GAP)


@pytest.fixture(scope="module")
def runs(gapped: Inputs) -> dict[str, Run]:
    both = run_methods(gapped, Params(), methods=("baseline", "proposed"))
    off = with_values(Params(), {"extensions.gap_route_bridge": False})
    return {
        "baseline": both["baseline"],
        "proposed": both["proposed"],
        "off": run_methods(gapped, off, methods=("proposed",))["proposed"],
    }


def _truth_turn(gapped: Inputs) -> float:
    return truth_turn_deg(gapped, *GAP)


def _after_gap(run: Run, gapped: Inputs, since: float = GAP[1]) -> tuple[F64, F64]:
    return errors_after(run, gapped, GAP[1], since)


def _bridged(run: Run) -> list[MatchRecord]:
    return [m for m in run.matches if "gap_bridge_end_s" in m.extra]


def test_the_road_turns_inside_the_gap(gapped: Inputs) -> None:
    assert np.diff(gapped.log.imu.t).max() == pytest.approx(GAP[1] - GAP[0], abs=0.05)
    assert _truth_turn(gapped) > 45.0


def test_the_bridge_puts_the_vehicle_where_the_road_goes(
    runs: dict[str, Run], gapped: Inputs
) -> None:
    def rmse(name: str) -> float:
        err, _ = _after_gap(runs[name], gapped)
        return float(np.sqrt(np.mean(err**2)))

    proposed = rmse("proposed")
    assert proposed < 10.0
    # without it the position comes out of the gap on the chord of a 59 deg turn, and the
    # heading off by the turn; nothing in the outage brings either back
    assert rmse("off") > 20 * proposed
    assert rmse("baseline") > 20 * proposed


def test_the_bridge_turns_the_heading_by_the_roads_turn(
    runs: dict[str, Run], gapped: Inputs
) -> None:
    (first,) = _bridged(runs["proposed"])
    assert first.t - gapped.log.t_start == pytest.approx(GAP[1], abs=1.0)
    assert first.extra["gap_bridge_turn_deg"] == pytest.approx(_truth_turn(gapped), abs=3.0)
    assert first.extra["gap_bridge_along_m"] > 300.0  # 20 s at about 17 m/s
    _, yaw_err = _after_gap(runs["proposed"], gapped, since=first.t - gapped.log.t_start)
    # turned exactly, not through the linear gain (which turns the velocity by the tangent)
    assert np.abs(yaw_err).max() < 2.0
    assert not _bridged(runs["off"])


def test_no_window_reaches_back_across_the_gap(runs: dict[str, Run], gapped: Inputs) -> None:
    """Across the gap the DR track is a straight line: a window is only what was dead-reckoned
    after it, too short at first to pair (``gates.min_pairs``)."""
    t0 = gapped.log.t_start
    p = runs["proposed"].params
    soon = [m for m in runs["proposed"].matches if GAP[1] < m.t - t0 < GAP[1] + 3.0]
    assert soon
    for m in soon:
        assert m.window_length_m < p.window.length_m / 2
        assert [g.gate for g in m.failed_gates] == [Gate.MIN_PAIRS]
    before = [m for m in runs["off"].matches if GAP[1] < m.t - t0 < GAP[1] + 3.0]
    assert all(m.window_length_m >= p.window.length_m for m in before)


def test_the_bridge_is_named(runs: dict[str, Run]) -> None:
    (line,) = [w for w in runs["proposed"].warnings if "bridged along the route" in w]
    assert line.startswith("IMU gap that ended at 196.0 s bridged along the route there: ")
    assert "turned its heading +5" in line
    assert not any("bridged along the route" in w for w in runs["off"].warnings)


@pytest.mark.parametrize(
    ("before", "after"),
    [
        ({"extensions.gap_route_bridge": False}, {}),
        ({}, {"extensions.gap_route_bridge": False}),
        ({}, {"gates.max_rotation_deg": 10.0}),
        ({}, {"pseudo.gap_bridge_heading_sigma_deg": 3.0}),
    ],
    ids=["switched on", "switched off", "a gate moved", "the bridge's sigma moved"],
)
def test_a_re_run_is_a_fresh_run(gapped: Inputs, before: dict, after: dict) -> None:
    """The inspector re-runs from the first attempt whose outcome changes: the bridge changes
    the filter before the attempt it comes with, so the re-run goes live from there."""
    old = run(gapped.log, gapped.route, with_values(Params(), before), frame=gapped.frame)
    p = with_values(Params(), after)
    reused = run(gapped.log, gapped.route, p, frame=gapped.frame, reuse=old)
    fresh = run(gapped.log, gapped.route, p, frame=gapped.frame)
    np.testing.assert_array_equal(reused.epochs.position, fresh.epochs.position)
    assert [m.extra for m in reused.matches] == [m.extra for m in fresh.matches]
    assert reused.warnings == fresh.warnings


def _sigma_after_bridge(r: Run) -> float:
    (first,) = _bridged(r)
    k = first.epoch
    return float(np.hypot(*r.epochs.position_sigma[k, :2]))


def test_without_wheel_speed_the_bridge_is_as_unsure_along_the_road_as_the_speed(
    runs: dict[str, Run], gapped: Inputs
) -> None:
    """Without wheel speed the kernel carried the position by the last velocity, whose
    5 m/s over 20 s leave it 100 m unsure along the road: the bridge still turns the heading to
    the road's and puts the vehicle on it, but claims no more along the road than that."""
    no_wheel = dataclasses.replace(gapped, log=dataclasses.replace(gapped.log, wheel=None))
    r = run_methods(no_wheel, Params(), methods=("proposed",))["proposed"]
    (first,) = _bridged(r)
    assert first.extra["gap_bridge_turn_deg"] == pytest.approx(_truth_turn(gapped), abs=3.0)
    assert _sigma_after_bridge(r) > 50.0
    assert _sigma_after_bridge(runs["proposed"]) < 10.0


def test_a_paused_recording_is_not_bridged(gapped: Inputs) -> None:
    """The wheels fell silent with the IMU (a paused recording): the kernel held the position,
    and nothing says how far the vehicle went, so nothing is bridged."""
    wheel, t0 = gapped.log.wheel, gapped.log.t_start
    assert wheel is not None
    keep = ~((wheel.t >= t0 + GAP[0]) & (wheel.t < t0 + GAP[1]))
    silent = dataclasses.replace(wheel, t=wheel.t[keep], speed=wheel.speed[keep])
    paused = dataclasses.replace(gapped, log=dataclasses.replace(gapped.log, wheel=silent))
    r = run_methods(paused, Params(), methods=("proposed",))["proposed"]
    assert not _bridged(r)
    assert not any("bridged along the route" in w for w in r.warnings)


def test_the_road_turn_is_summed_along_the_road() -> None:
    """A lane 3 m left of the route is 3 m x pi/2 shorter round a quarter-circle left turn; the
    bridge adds that to the wheels' distance to find the route's arc length."""
    a = np.linspace(0.0, 1.5 * np.pi, 400)  # three quarters of a circle, radius 100 m, left
    road = Route(np.column_stack([100.0 * np.sin(a), 100.0 - 100.0 * np.cos(a)]))
    quarter = 100.0 * np.pi / 2
    assert road_turn(road, 10.0, 10.0 + quarter, 5.0) == pytest.approx(np.pi / 2, abs=0.01)
    assert road_turn(road, 10.0, 10.0 + 2 * quarter, 5.0) == pytest.approx(np.pi, abs=0.01)
    assert road_turn(road, 10.0 + quarter, 10.0, 5.0) == pytest.approx(-np.pi / 2, abs=0.01)


def test_many_bridged_gaps_get_a_few_warning_lines() -> None:
    """As the gaps' own lines: the first four named, the rest summed up in one line."""
    from types import SimpleNamespace

    from estimator.errors import WARNING_LINES_NAMED
    from estimator.pipeline.driver import gap_bridge_warnings

    def bridged(end: float, moved: float, turn: float) -> SimpleNamespace:
        extra = {
            "gap_bridge_end_s": end,
            "gap_bridge_along_m": 120.0,
            "gap_bridge_moved_m": moved,
            "gap_bridge_turn_deg": turn,
        }
        return SimpleNamespace(extra=extra)

    records = [bridged(10.0 + 7 * k, 0.5 + k, (-1) ** k * 0.1 * k) for k in range(60)]
    lines = gap_bridge_warnings(records, 0.0)  # type: ignore[arg-type]
    assert len(lines) == WARNING_LINES_NAMED
    assert lines[0].startswith("IMU gap that ended at 10.0 s bridged along the route there: ")
    assert lines[-1] == (
        "... and 56 more IMU gaps bridged along the route, ending between 38.0 and 423.0 s (the "
        "position moved 59.5 m at most, the heading turned 5.9 deg at most)"
    )
    few = gap_bridge_warnings(records[:WARNING_LINES_NAMED], 0.0)  # type: ignore[arg-type]
    assert len(few) == WARNING_LINES_NAMED and not any("more IMU gaps" in w for w in few)


def test_a_gap_before_any_attempt_is_bridged_only_on_the_road_the_approach_found() -> None:
    """A gap from 0.8 s into the outage, before its first attempt: only the GNSS-aided approach
    says whether the route is the road driven. On the right route it is bridged; on the route
    drawn 60 m away (another road: its map bias is refused) the projection at the outage's
    start would put the vehicle on it just as readily, and nothing is bridged."""
    spiral = open_inputs(SAMPLES / "spiral_tunnel.mcap", SAMPLES / "spiral_tunnel.route.geojson")
    early = without_imu(spiral, 122.0, 142.0)
    assert early.route is not None
    other = dataclasses.replace(early, route=Route(early.route.xy + np.array([0.0, 60.0])))
    t0 = early.log.t_start
    for inputs, bridges in ((early, 1), (other, 0)):
        r = run_methods(inputs, Params(), methods=("proposed",))["proposed"]
        assert not any(m.t - t0 < 122.0 for m in r.matches)
        assert len(_bridged(r)) == bridges
