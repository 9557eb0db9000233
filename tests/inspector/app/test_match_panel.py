"""The match panel text (the rest of the app is driven in tests/e2e)."""

from __future__ import annotations

import numpy as np
import pytest
from fake_runs import make_run

from inspector.app import match_markdown


def test_match_panel_lists_every_gate_and_marks_the_failed_one():
    run = make_run(rejected=(2,))
    text = match_markdown(run.matches[2], t_rel=50.0, total=5)
    assert "Attempt #2 (3 of 5) at t = 50.00 s: REJECTED" in text
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    gate_rows = {r.split("|")[1].strip(): r for r in rows[1:4]}
    assert set(gate_rows) == {"min_pairs", "heading", "residual"}
    assert "✗ **FAILED**" in gate_rows["residual"] and "<= 3.000" in gate_rows["residual"]
    assert "✓ passed" in gate_rows["min_pairs"]
    assert "| residual (RMS) | 7.500 m |" in text
    assert "| correction E, N | (0.00, 0.00) m" in text


def test_match_panel_for_an_accepted_attempt_and_for_none():
    run = make_run(rejected=())
    text = match_markdown(run.matches[0], t_rel=40.0, age_s=1.5, total=5)
    assert "ACCEPTED" in text and "(1.50 s ago)" in text and "FAILED" not in text
    assert "| correction E, N | (0.00, -2.00) m" in text
    assert "No match attempt" in match_markdown(None)


def test_match_panel_says_why_route_updates_were_undone():
    """An attempt whose dr_separation gate failed passed every other gate: the head names the
    failed gate and the line under it says the outage's route updates were undone."""
    import dataclasses

    from estimator.matching.gates import DR_SEPARATION
    from estimator.results import Gate, GateDecision
    from inspector.app.match import UNDONE_HERE

    m = make_run(rejected=()).matches[1]
    failed = GateDecision(Gate.DR_SEPARATION, 14.4, 13.8, "<=", False, DR_SEPARATION.note)
    # as the driver records it: the undoing attempt carries how far the updates had moved it
    extra = {**m.extra, "dr_separation_m": 3.8}
    undone = dataclasses.replace(m, accepted=False, gates=(*m.gates, failed), extra=extra)
    text = match_markdown(undone, t_rel=50.0, total=5)
    assert "Attempt #1 (2 of 5) at t = 50.00 s: REJECTED by dr_separation**" in text
    assert UNDONE_HERE in text
    note = "the outage's route updates were undone at 45.0 s: none taken since"
    later = dataclasses.replace(
        undone, gates=(*m.gates, dataclasses.replace(failed, note=note)), extra=m.extra
    )
    text = match_markdown(later, t_rel=60.0, total=5)
    assert f"*{note}*" in text.splitlines()[2] and UNDONE_HERE not in text
    rejected = make_run(rejected=(2,)).matches[2]
    assert ": REJECTED by residual**" in match_markdown(rejected, total=5)


def test_match_panel_says_why_a_refused_match_was_applied():
    """A re-anchored attempt is accepted with failed gates: the head says re-anchored and the
    line under it why, naming the IMU gap when it was a re-acquisition after one."""
    import dataclasses
    import math

    from estimator.results import Gate, GateDecision
    from inspector.app.match import REANCHORED

    m = make_run(rejected=()).matches[1]
    failed = GateDecision(Gate.ROTATION, 19.9, 15.0, "<=", False, "fitted rotation, deg")
    turned = dataclasses.replace(
        m, gates=(*m.gates, failed), reanchored=True, rotation_rad=math.radians(-19.9)
    )
    text = match_markdown(turned, t_rel=50.0, total=5)
    assert "Attempt #1 (2 of 5) at t = 50.00 s: ACCEPTED (re-anchored)**" in text
    assert REANCHORED in text
    after_gap = dataclasses.replace(turned, extra={**m.extra, "gap_end_s": 294.2})
    text = match_markdown(after_gap, t_rel=50.0, total=5)
    assert "the IMU gap that ended at 294.2 s" in text and "(-19.9 deg here)" in text
    assert REANCHORED not in text


def test_match_panel_says_an_imu_gap_was_bridged_before_the_attempt():
    """The attempt an IMU gap was bridged along the route before carries a line saying so,
    with how far along the road, how far the position moved and how the heading turned."""
    import dataclasses

    m = make_run(rejected=()).matches[1]
    plain = match_markdown(m, t_rel=50.0, total=5)
    assert "bridged along the route" not in plain
    extra = {
        "gap_bridge_end_s": 196.0,
        "gap_bridge_along_m": 344.2,
        "gap_bridge_moved_m": 173.7,
        "gap_bridge_turn_deg": 59.1,
    }
    text = match_markdown(dataclasses.replace(m, extra={**m.extra, **extra}), total=5)
    assert (
        "*Before this attempt the IMU gap that ended at 196.0 s was bridged along the route: the "
        "wheels' 344 m along the road moved the position 173.7 m from the straight line the gap "
        "left it on and turned its heading +59.1 deg to the road's "
        "(extensions.gap_route_bridge).*"
    ) in text


def test_the_head_counts_the_attempt_from_one_and_never_of_zero():
    """The attempt's number is its index (from 0, as on the map); the count beside it is from 1,
    so the last of five is '#4 (5 of 5)', not '#4 of 5'. The Compare tab's changed attempt,
    which passes no count, said 'Attempt #166 of 0'."""
    from inspector.app.compare import changed_markdown
    from inspector.export.compare import ChangedVerdict

    run = make_run(rejected=(2,))
    last = match_markdown(run.matches[4], t_rel=60.0, total=5)
    assert "**Attempt #4 (5 of 5) at t = 60.00 s: ACCEPTED**" in last
    other = make_run(rejected=())
    text = changed_markdown(ChangedVerdict(50.0, run.matches[2], other.matches[2]), 1, 0)
    assert "of 0" not in text
    assert "Attempt #2 at t = 50.00 s: REJECTED by residual**" in text
    assert "Attempt #2 at t = 50.00 s: ACCEPTED**" in text


def test_gate_rows_read_in_the_units_the_parameters_are_set_in():
    """gates.max_heading_diff_deg is set in degrees: the heading row gave only cosines
    ('0.922 >= 0.985'), so it shows the angles (the cosine stays in the fit table); a count of
    pairs has no decimals ('51.000 >= 20.000' read as a measured quantity)."""
    text = match_markdown(make_run(rejected=(2,)).matches[2], t_rel=50.0, total=5)
    assert "| min_pairs | 21 | >= 20 | ✓ passed |" in text
    assert "| heading | 2.6° | <= 10.0° | ✓ passed |" in text
    assert "| residual | 7.500 | <= 3.000 | ✗ **FAILED** |" in text
    assert "| heading cos | 0.9990 |" in text
    assert "*heading*: angle between the DR and route end directions, deg" in text


def _fitted(m, *, filter_cov, obs_cov, innovation):
    """``m`` with a fit on a road heading 30 deg left of East (E and N mix along and across)."""
    import dataclasses

    from estimator.results import FitSummary

    a = np.radians(30.0)
    normal = np.array([-np.sin(a), np.cos(a)])
    summary = FitSummary(
        along_offset_m=0.0,
        along_curvature=0.0,
        along_sigma_m=float(np.sqrt(obs_cov[0])),
        along_observed=True,
        cross_sigma_m=float(np.sqrt(obs_cov[1])),
        lane_path=False,
        innovation_along_m=innovation[0],
        innovation_cross_m=innovation[1],
        normal=normal,
        heading_sigma_rad=0.01,
    )
    axes = np.column_stack([[np.cos(a), np.sin(a)], normal])  # E-N of along, across

    def en(diag):
        return None if diag is None else axes @ np.diag(diag) @ axes.T

    return dataclasses.replace(
        m,
        fit=summary,
        obs_cov=en(obs_cov),
        innovation=axes @ np.asarray(innovation),
        **({} if filter_cov is None else {"filter_cov": en(filter_cov)}),
    )


def test_the_panel_puts_the_filter_sigma_beside_the_observation_sigma_in_route_axes():
    """The two parts of the Mahalanobis gate's S, along and across the route, beside the
    innovation: a refusal by a filter sure of itself (0.5 m across against a 3 m innovation)
    reads at a glance. The filter's pair is not repeated among the raw diagnostic rows."""
    m = _fitted(
        make_run(rejected=()).matches[1],
        filter_cov=(4.5**2, 0.5**2),
        obs_cov=(100.0**2, 1.25**2),
        innovation=(-2.0, 3.0),
    )
    assert m.diagnostics()["filter_along_sigma_m"] == pytest.approx(4.5)
    assert m.diagnostics()["filter_cross_sigma_m"] == pytest.approx(0.5)
    lines = match_markdown(m, total=5).splitlines()
    head = lines.index("| route axes, m | along | across (+ left) |")
    assert lines[head + 2 : head + 5] == [
        "| innovation | -2.00 | 3.00 |",
        "| filter 1-sigma, before the update | 4.50 | 0.50 |",
        "| observation 1-sigma | 100.00 | 1.25 |",
    ]
    assert not any(line.startswith("| filter_") for line in lines)
    assert head < lines.index("| fit | |")  # under the gates it explains


def test_the_route_axes_need_a_fit_and_say_when_the_filter_sigma_is_unknown():
    """No fit, no route direction: no table. A record built without ``filter_cov`` (NaN)
    shows dashes for the filter and no ``filter_*`` diagnostics."""
    plain = make_run(rejected=()).matches[1]
    assert plain.fit is None and "route axes" not in match_markdown(plain, total=5)
    m = _fitted(plain, filter_cov=None, obs_cov=(9.0, 1.0), innovation=(1.0, -1.0))
    assert "| filter 1-sigma, before the update | – | – |" in match_markdown(m, total=5)
    assert not any(k.startswith("filter_") for k in m.diagnostics())
