"""The exit check: an outage's estimate against the fixes the filter accepted after it."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation import results_document, run_notes
from estimator.evaluation.exits import outage_exits
from estimator.params import Params
from estimator.pipeline import Inputs, open_inputs, run_methods
from estimator.results import EXIT_CHI2_2DOF, Epochs, Run

SAMPLE = Path(__file__).resolve().parents[3] / "sample_logs" / "long_tunnel.mcap"
T0 = 1_700_000_000.0
OUTAGE = (T0 + 10.0, T0 + 20.0)
SPEED = 10.0


def drive(off_m: float, sigma_m: float, *, jump_after: bool = True) -> Epochs:
    """Due East at 10 m/s, sampled at 10 Hz; in the outage the estimate drifts ``off_m``
    north under a sigma of ``sigma_m``; from 22 s fixes are accepted again, and (as a
    filter's updates do) each pulls the position back to the road."""
    t = T0 + np.arange(0.0, 30.0 + 1e-9, 0.1)
    n = len(t)
    inside = (t >= OUTAGE[0]) & (t < OUTAGE[1])
    pos = np.zeros((n, 3))
    pos[:, 0] = SPEED * (t - T0)
    pos[:, 1] = np.where(t >= OUTAGE[0], off_m * np.clip((t - OUTAGE[0]) / 5.0, 0, 1), 0.0)
    accepted = (t < OUTAGE[0]) | (t >= T0 + 22.0)
    if jump_after:
        pos[t >= T0 + 22.0, 1] = 0.0
    vel = np.zeros((n, 3))
    vel[:, 0] = SPEED
    sig = np.ones((n, 3))
    sig[inside, :2] = sigma_m
    return Epochs(
        t=t,
        position=pos,
        velocity=vel,
        attitude=np.zeros((n, 3)),
        position_sigma=sig,
        position_cov_en=np.zeros(n),
        yaw_sigma=np.ones(n),
        gnss_used=accepted,
        degraded=inside,
    )


def fixes(rate: float = 5.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """On the road, at ``rate`` Hz, each 1 m^2 per axis."""
    ft = T0 + np.arange(0.0, 30.0, 1.0 / rate) + 0.01
    pos = np.column_stack([SPEED * (ft - T0), np.zeros(len(ft))])
    return ft, pos, np.ones((len(ft), 2))


def test_an_estimate_off_under_a_small_sigma_is_overconfident() -> None:
    (x,) = outage_exits(drive(10.0, 1.0), [OUTAGE], *fixes(), (0.0, 0.0, 0.0))
    # carried on by its velocity, the estimate stays 10 m north of the fixes, though the
    # positions after the first accepted fix were pulled back to the road
    np.testing.assert_allclose(x.error, [0.0, 10.0], atol=1e-9)
    assert x.chi2 == pytest.approx(100.0 / 2.0)
    assert x.overconfident
    assert x.estimate_sigma_m == pytest.approx(1.0)
    assert x.fix_t[0] == pytest.approx(T0 + 22.01) and x.fix_t[1] <= T0 + 22.1 + 3.0
    assert x.n_fixes == 15


def test_the_same_error_under_an_honest_sigma_is_not() -> None:
    (x,) = outage_exits(drive(10.0, 8.0), [OUTAGE], *fixes(), (0.0, 0.0, 0.0))
    assert x.chi2 == pytest.approx(100.0 / 65.0)
    assert x.chi2 < EXIT_CHI2_2DOF and not x.overconfident


def test_one_multipath_jump_does_not_move_the_median() -> None:
    ft, pos, var = fixes()
    first = int(np.searchsorted(ft, T0 + 22.0))
    pos[first + 2] += [40.0, -40.0]
    (x,) = outage_exits(drive(0.0, 1.0), [OUTAGE], ft, pos, var, (0.0, 0.0, 0.0))
    assert x.distance_m < 1e-9


def test_the_antenna_is_where_the_lever_arm_and_the_yaw_put_it() -> None:
    """An antenna 2 m forward and 1 m left on a car heading north is 2 m north and 1 m west
    of the body: fixes there are no error."""
    ep = drive(0.0, 1.0)
    ep = dataclasses.replace(
        ep, attitude=np.column_stack([np.zeros((len(ep), 2)), np.full(len(ep), math.pi / 2)])
    )
    ft, pos, var = fixes()
    pos = pos + np.array([-1.0, 2.0])
    (x,) = outage_exits(ep, [OUTAGE], ft, pos, var, (2.0, 1.0, 0.5))
    assert x.distance_m < 1e-9


def test_no_exit_without_a_fix_accepted_after_the_outage() -> None:
    ep = drive(10.0, 1.0)
    ep = dataclasses.replace(ep, gnss_used=ep.t < OUTAGE[0])
    assert outage_exits(ep, [OUTAGE], *fixes(), (0.0, 0.0, 0.0)) == ()


def test_fixes_after_the_next_outage_do_not_judge_this_one() -> None:
    """No fix accepted between two outages: the first has no exit of its own, and the second
    is judged from its own end."""
    ep = drive(10.0, 1.0)
    second = (T0 + 21.0, T0 + 21.5)
    (x,) = outage_exits(ep, [OUTAGE, second], *fixes(), (0.0, 0.0, 0.0))
    assert (x.start, x.end) == second


def test_dozens_of_flagged_outages_are_a_few_lines() -> None:
    from estimator.errors import WARNING_LINES_NAMED
    from estimator.evaluation.exits import exit_warnings

    ep = drive(10.0, 1.0)
    (x,) = outage_exits(ep, [OUTAGE], *fixes(), (0.0, 0.0, 0.0))
    many = [dataclasses.replace(x, start=x.start + 30 * i, end=x.end + 30 * i) for i in range(12)]
    worst = dataclasses.replace(many[9], error=np.array([0.0, 30.0]))
    many[9] = worst
    lines = exit_warnings("baseline", many, [False] * 12, T0)
    assert len(lines) == WARNING_LINES_NAMED
    assert all(w.startswith("baseline run: the outage at ") for w in lines[:-1])
    assert "dead reckoning drifted beyond its noise model" in lines[0]
    assert lines[-1].startswith("... and 8 more outages of the baseline run, between 130.0 ")
    assert "worst: the outage at 280.0-290.0 s, 30.0 m, " in lines[-1]
    assert all(len(w) <= 300 for w in lines)
    assert exit_warnings("proposed", many[:5], [True] * 5, T0)[4].startswith("proposed run: ")


@pytest.fixture(scope="module")
def long_tunnel() -> Inputs:
    return open_inputs(SAMPLE, SAMPLE.with_name("long_tunnel.route.geojson"))


@pytest.fixture(scope="module")
def long_tunnel_runs(long_tunnel: Inputs) -> dict[str, Run]:
    runs = run_methods(long_tunnel, Params(), methods=("baseline", "proposed", "paper"))
    return {m: runs[m] for m in ("baseline", "proposed", "paper")}


@pytest.mark.slow
def test_the_papers_confident_exit_is_a_warning_and_routefuses_is_a_note(
    long_tunnel_runs: dict[str, Run],
) -> None:
    """The paper's filter leaves the long tunnel tens of metres from the fixes under a
    sigma of under a metre; routefuse within a few metres and its claimed sigmas."""
    paper, proposed = long_tunnel_runs["paper"], long_tunnel_runs["proposed"]
    (p_exit,) = paper.exits
    assert p_exit.distance_m > 20.0 and p_exit.estimate_sigma_m < 1.0 and p_exit.overconfident
    flagged = [w for w in paper.warnings if "m from the fixes after it" in w]
    assert len(flagged) == 1 and "103.2-459.0 s" in flagged[0] and "route updates" in flagged[0]
    assert len(flagged[0]) <= 300
    (r_exit,) = proposed.exits
    assert r_exit.distance_m < 6.0 and not r_exit.overconfident
    assert not [w for w in proposed.warnings if "from the fixes after it" in w]
    assert any(n.startswith("exit of the outage at 103.2-459.0 s") for n in run_notes(proposed))


@pytest.mark.slow
def test_the_exit_is_against_the_fixes_not_the_truth(
    long_tunnel: Inputs, long_tunnel_runs: dict[str, Run]
) -> None:
    """On the simulator's log the fixes after the tunnel are within their few metres of the
    truth: the exit's distance is the estimate's error there, give or take them."""
    log = long_tunnel.log
    assert log.truth is not None
    for run in long_tunnel_runs.values():
        (x,) = run.exits
        e = run.epochs
        k = int(np.flatnonzero(e.t < x.end)[-1])
        truth = run.frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
        at = np.array([np.interp(e.t[k], log.truth.t, truth[:, i]) for i in range(2)])
        assert abs(x.distance_m - float(np.hypot(*(e.position[k, :2] - at)))) < 5.0


@pytest.mark.slow
def test_the_exit_starts_on_the_track_just_before_the_first_fix_moved_it(
    long_tunnel_runs: dict[str, Run],
) -> None:
    """After the long tunnel the road runs straight: nothing but fixes moves the track."""
    for run in long_tunnel_runs.values():
        (x,) = run.exits
        e = run.epochs
        k = int(np.searchsorted(e.t, x.fix_t[0])) - 1  # the last row before that fix's update
        here = e.position[k, :2] + e.velocity[k, :2] * (x.fix_t[0] - e.t[k])
        assert float(np.hypot(*(x.estimate_at - here))) < 0.2


@pytest.mark.slow
def test_the_results_document_carries_every_exit(
    long_tunnel: Inputs, long_tunnel_runs: dict[str, Run]
) -> None:
    from estimator.evaluation import method_metrics

    runs, inp = long_tunnel_runs, long_tunnel
    assert inp.route is not None
    metrics = {m: method_metrics(r, inp.route, inp.log) for m, r in runs.items()}
    doc = results_document("log.mcap", "route.geojson", inp.log, runs, metrics)
    assert [e["overconfident"] for e in doc["exits"]["paper"]] == [True]
    (x,) = doc["exits"]["proposed"]
    assert x["outage"] == pytest.approx([103.2, 459.0], abs=0.05)
    assert x["chi2"] == pytest.approx(runs["proposed"].exits[0].chi2)
    assert x["fixes"][0] >= x["outage"][1]


def test_the_check_does_not_depend_on_where_the_frame_is() -> None:
    """A run and its fixes moved together give the same exit."""
    a = outage_exits(drive(3.0, 1.0), [OUTAGE], *fixes(), (0.0, 0.0, 0.0))
    ft, pos, var = fixes()
    ep = drive(3.0, 1.0)
    shifted = dataclasses.replace(ep, position=ep.position + np.array([500.0, -200.0, 7.0]))
    b = outage_exits(shifted, [OUTAGE], ft, pos + np.array([500.0, -200.0]), var, (0.0, 0.0, 0.0))
    np.testing.assert_allclose(a[0].error, b[0].error, atol=1e-9)
