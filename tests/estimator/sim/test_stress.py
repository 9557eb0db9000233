"""The stress corpus (issue 17): reproducible drives whose faults are really there."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.sim.stress import FAULT_CYCLE, build, drive_spec


def test_a_drive_is_a_pure_function_of_its_index() -> None:
    a, b = build(drive_spec(3)), build(drive_spec(3))
    assert a.spec == b.spec
    np.testing.assert_array_equal(a.inputs.log.imu.gyro, b.inputs.log.imu.gyro)
    np.testing.assert_array_equal(a.inputs.route.xy, b.inputs.route.xy)
    assert drive_spec(3) != drive_spec(13)


def test_a_held_out_corpus_draws_afresh_and_leaves_the_corpus_as_it_was() -> None:
    """Corpus 0 is the one every figure in docs/integrity.md was measured on: its drives must
    not change. A held-out corpus keeps each index's base and fault but draws the rest and
    the simulator's seed afresh, the same for the same (index, corpus)."""
    zero = drive_spec(7)
    assert (zero.seed, zero.corpus, zero.name) == (1007, 0, "stress_7")
    assert zero.bias_along_m == pytest.approx(drive_spec(7, corpus=0).bias_along_m)
    one, two = drive_spec(7, corpus=1), drive_spec(7, corpus=2)
    assert one == drive_spec(7, corpus=1) and one.name == "stress_c1_7"
    assert (one.base, one.fault) == (zero.base, zero.fault) == (two.base, two.fault)
    assert len({zero.seed, one.seed, two.seed}) == 3
    assert len({zero.bias_rotation_deg, one.bias_rotation_deg, two.bias_rotation_deg}) == 3
    with pytest.raises(ValueError, match="corpus -1"):
        drive_spec(7, corpus=-1)


@pytest.mark.parametrize("corpus", [0, 1])
def test_the_corpus_draws_every_fault_within_its_bounds(corpus: int) -> None:
    specs = [drive_spec(i, corpus=corpus) for i in range(50)]
    assert {s.fault for s in specs} == set(FAULT_CYCLE)
    assert all(abs(s.bias_along_m) <= 15 and abs(s.bias_across_m) <= 5 for s in specs)
    assert all(abs(s.bias_rotation_deg) <= 2 and 0 <= s.gyro_bias_deg_h <= 720 for s in specs)
    assert all(abs(s.wheel_scale_error) <= 0.02 for s in specs)


@pytest.mark.parametrize("fault", ["map_bias", "no_odometer", "bad_first_fix", "imu_gap"])
def test_each_fault_is_in_the_drive(fault: str) -> None:
    index = FAULT_CYCLE.index(fault)
    drive = build(drive_spec(index))
    spec, log, route = drive.spec, drive.inputs.log, drive.inputs.route
    assert route is not None
    # the map is the road moved by the drawn shift and rotation: metres away from it
    shift = max(abs(spec.bias_along_m), abs(spec.bias_across_m))
    assert route.project(drive.road.xy).distance.max() >= 0.5 * shift
    if fault == "no_odometer":
        assert log.wheel is None
    if fault == "bad_first_fix":
        clean = build(drive_spec(index + 10)).inputs.log  # same fault, other draws: just types
        assert clean.gnss.valid.any()
        first = int(np.flatnonzero(log.gnss.valid)[0])
        frame = drive.inputs.frame
        fix = frame.to_enu(log.gnss.lat[first], log.gnss.lon[first])[0, :2]
        truth = frame.to_enu(log.truth.lat, log.truth.lon)[:, :2]
        assert np.hypot(*(truth - fix).T).min() > 0.8 * spec.first_fix_off_m
    if fault == "imu_gap":
        assert np.max(np.diff(log.imu.t)) == pytest.approx(spec.imu_gap_s, abs=0.05)


def test_the_runner_gives_a_row_of_finite_figures() -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "scripts"))
    from stress_corpus import RUNS, run_drive, summary

    row = run_drive(1)
    assert row["error"] == ""
    for label in RUNS:
        assert np.isfinite(row[f"{label}_truth_rmse_m"]) and np.isfinite(row[f"{label}_nees_mean"])
    assert "| all (1) | baseline |" in summary([row])
    assert row["routefuse_exits"] == 1 and row["routefuse_exits_overconfident"] == 0
    assert summary([row]).splitlines()[4].endswith("| 0 of 1 |")
    held = run_drive(1, corpus=1)
    assert (held["corpus"], row["corpus"]) == (1, 0)
    assert held["bias_rotation_deg"] != row["bias_rotation_deg"]
    assert summary([held], 1).startswith("Held-out corpus 1: 1 drives")


def test_the_control_drives_the_road_and_keeps_the_trap() -> None:
    turned = build(drive_spec(0))  # map turned -0.27 deg about the long tunnel's middle
    road = turned.on_the_road().route
    assert road is not None
    np.testing.assert_array_equal(road.xy, turned.road.xy)
    trap = build(drive_spec(8))  # the parallel road: 25 m to the left
    trapped = trap.on_the_road().route
    assert trapped is not None
    assert np.median(trapped.project(trap.road.xy).distance) > 20.0


def test_the_map_drift_is_the_turn_along_the_tunnel() -> None:
    drive = build(drive_spec(0))
    drift = drive.map_error_across()
    start, end = drive.tunnels[0]
    assert len(drift) > 0 and drift[0] == 0.0
    # a -0.27 deg turn over a tunnel kilometres long: metres across by its end
    truth = drive.inputs.log.truth
    assert truth is not None
    xy = drive.inputs.frame.to_enu(truth.lat, truth.lon, truth.alt)[:, :2]
    inside = xy[(truth.t >= start) & (truth.t <= end)]
    length = float(np.sum(np.hypot(*np.diff(inside, axis=0).T)))
    turn = np.radians(abs(drive.spec.bias_rotation_deg))
    assert abs(drift[len(inside) - 1]) == pytest.approx(turn * length, rel=0.2)


def test_the_map_bias_field_is_where_the_map_draws_the_road() -> None:
    drive = build(drive_spec(32))  # map turned +0.56 deg about the long tunnel's middle
    route = drive.inputs.route
    assert route is not None
    xy = drive.road.point_at(np.linspace(100.0, drive.road.length - 100.0, 40))
    drawn = xy + drive.map_bias_at(xy)
    # each road point moved by the field lies on the map, and the field is not a constant
    assert route.project(drawn).distance.max() < 0.05
    bias = drive.map_bias_at(xy)
    assert np.ptp(np.hypot(bias[:, 0], bias[:, 1])) > 20.0
