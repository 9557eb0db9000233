"""The gates as data: the table's order and decisions, "no rival" as a typed value."""

from __future__ import annotations

import numpy as np

from estimator.matching import SHAPE_GATES, ShapeValues, gate_table
from estimator.matching.gates import Validation, alternative_gate, shape_passes
from estimator.params import Params
from estimator.results import Gate, Rival

GOOD = ShapeValues(40, 0.9999, 0.3, 0.5)


def test_the_table_holds_every_gate_in_gate_order():
    validation = Validation(
        d2=1.0,
        jump=0.2,
        cost=3.0,
        rivals=tuple((r, GOOD, 50.0) for r in Rival),
    )
    table = gate_table(GOOD, validation, 2.0, Params())
    # the dead-reckoning separation is the filter's gate, tested after the update, and the
    # rotation's consistency the driver's, against the filter's yaw
    driver_gates = (Gate.DR_SEPARATION, Gate.ROTATION_CONSISTENCY)
    assert [d.gate for d in table] == [g for g in Gate if g not in driver_gates]
    assert all(d.passed for d in table)
    assert [d.name for d in table][:4] == [s.gate.value for s in SHAPE_GATES]
    without = gate_table(GOOD, None, 2.0, Params())
    assert [d.gate for d in without] == [*(s.gate for s in SHAPE_GATES), Gate.CORRECTION_CAP]


def test_a_rival_failing_the_shape_gates_is_no_rival():
    g = Params().gates
    bad_shape = ShapeValues(40, 0.9999, 50.0, 0.5)
    d = alternative_gate(Rival.LEFT, bad_shape, 1.0, 3.0, g)
    assert d.gate is Gate.ALTERNATIVE_LEFT and d.gate.rival is Rival.LEFT
    assert d.no_rival and d.value == float("inf") and d.passed
    assert "fails the shape gates" in d.note
    close = alternative_gate(Rival.REVERSED, GOOD, 3.1, 3.0, g)
    assert not close.no_rival and not close.passed
    assert "direction" in close.note


def test_shape_passes_is_every_shape_gate_passing():
    rng = np.random.default_rng(0)
    g = Params().gates
    cos_edge = float(np.cos(np.radians(g.max_heading_diff_deg)))
    for _ in range(2000):
        values = ShapeValues(
            int(rng.choice([0, g.min_pairs - 1, g.min_pairs, 80])),
            float(rng.choice([cos_edge, 1.0, 0.5, np.nan, np.nextafter(cos_edge, 0)])),
            float(rng.choice([g.max_residual_m, 0.1, 7.0, np.nan])),
            float(rng.choice([g.max_rotation_deg, 0.2, 30.0])),
        )
        table = gate_table(values, None, 0.0, Params())
        assert shape_passes(values, g) == all(d.passed for d in table[:4])


def test_off_route_gates_are_the_candidate_validation_gates():
    refusing = {g for g in Gate if g.refuses_off_route}
    assert refusing == {
        Gate.LANE_CONTINUITY,
        Gate.ALTERNATIVE_LEFT,
        Gate.ALTERNATIVE_RIGHT,
        Gate.ALTERNATIVE_REVERSED,
    }
    assert {Gate.alternative(r) for r in Rival} == refusing - {Gate.LANE_CONTINUITY}
