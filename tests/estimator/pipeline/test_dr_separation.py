"""``extensions.dr_separation`` (issue 17): each outage's route updates are tested against a
dead-reckoning twin of the filter that took none of them; when they have moved the position
further than the information they added allows, they are undone and the outage is
dead-reckoned."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.evaluation.metrics import outage_errors
from estimator.filter.layout import E_POS, NE, NX, X_POS
from estimator.filter.twin import separation
from estimator.params import Params, with_values
from estimator.pipeline import run, run_methods
from estimator.results import Gate, Run
from estimator.sim.stress import build, drive_spec
from tests._session11_fit import SESSION_11_FIT, undoing_params


def _state(position: tuple[float, float], cov: list[float]) -> tuple[np.ndarray, np.ndarray]:
    x, P = np.zeros(NX), np.zeros((NE, NE))
    x[X_POS : X_POS + 2] = position
    P[E_POS : E_POS + 2, E_POS : E_POS + 2] = np.diag(cov)
    return x, P


def test_the_separation_is_tested_against_what_the_updates_added() -> None:
    x_dr, P_dr = _state((10.0, 20.0), [25.0, 9.0])
    x, P = _state((13.0, 18.0), [9.0, 5.0])  # P_dr - P = diag(16, 4)
    sep = separation(x, P, x_dr, P_dr, floor_m=0.5)
    np.testing.assert_allclose(sep.offset, [3.0, -2.0])
    assert sep.chi2 == pytest.approx(9.0 / 16.0 + 4.0 / 4.0)
    assert sep.metres == pytest.approx(np.hypot(3.0, 2.0))
    # where the route added nothing, the floor stands for P_dr - P
    x, P = _state((13.0, 18.0), [9.0, 9.0])
    assert separation(x, P, x_dr, P_dr, floor_m=0.5).chi2 == pytest.approx(9.0 / 16.0 + 16.0)


def _figures(r: Run, index: int) -> float:
    inputs = build(drive_spec(index)).inputs
    assert inputs.log.truth is not None
    err, _ = outage_errors(r, inputs.log, inputs.frame)
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


@pytest.fixture(scope="module")
def drive5() -> dict[str, Run]:
    """Corpus drive 5: the spiral tunnel with its route 4.7 m along and 5.0 m across the road,
    a shift the approach tests as insignificant; its matches pull the estimate off the road."""
    inputs = build(drive_spec(5)).inputs
    untied = undoing_params()
    runs = run_methods(inputs, untied, methods=("baseline", "proposed"))
    off = with_values(untied, {"extensions.dr_separation": False})
    without = run_methods(inputs, off, methods=("proposed",))["proposed"]
    return {"baseline": runs["baseline"], "proposed": runs["proposed"], "without": without}


def test_a_route_pulling_away_from_dead_reckoning_is_undone(drive5: dict[str, Run]) -> None:
    base, prop, without = (_figures(drive5[m], 5) for m in ("baseline", "proposed", "without"))
    assert prop <= base + 0.2 < without
    records = drive5["proposed"].matches
    undone = [m for m in records if "dr_separation_m" in m.extra]
    assert len(undone) == 1
    first = undone[0]
    gate = first.failed_gates[0]
    assert gate.gate is Gate.DR_SEPARATION and gate.value > gate.threshold
    assert not first.accepted and first.verdict == "rejected: dr_separation"
    # none taken for the rest of the outage, each saying why
    end = next(b for a, b in drive5["proposed"].degraded_intervals if a <= first.t <= b)
    later = [m for m in records if first.t < m.t <= end]
    assert later and not any(m.accepted for m in later)
    assert all(m.gates[-1].gate is Gate.DR_SEPARATION for m in later)
    assert all("undone" in m.gates[-1].note for m in later)
    lines = [w for w in drive5["proposed"].warnings if w.startswith("route updates undone")]
    assert len(lines) == 1 and f"{first.extra['dr_separation_m']:.1f} m" in lines[0]


def test_accepted_updates_carry_their_passing_separation(drive5: dict[str, Run]) -> None:
    accepted = [m for m in drive5["proposed"].matches if m.accepted]
    assert accepted
    for m in accepted:
        gate = m.gates[-1]
        assert gate.gate is Gate.DR_SEPARATION and gate.passed and gate.value >= 0.0
    assert not any(g.gate is Gate.DR_SEPARATION for m in drive5["without"].matches for g in m.gates)


def test_a_rerun_after_an_undo_equals_a_fresh_run(drive5: dict[str, Run]) -> None:
    """Re-run reuse replays the attempts before the undo and runs live from it (with the twin
    the checkpoint kept)."""
    inputs = build(drive_spec(5)).inputs
    p = undoing_params(**{"gates.max_residual_m": 2.5})
    old = drive5["proposed"]
    again = run(inputs.log, inputs.route, p, frame=old.frame, reuse=old)
    fresh = run(inputs.log, inputs.route, p, frame=old.frame)
    np.testing.assert_array_equal(again.epochs.position, fresh.epochs.position)
    assert [(m.accepted, m.gates) for m in again.matches] == [
        (m.accepted, m.gates) for m in fresh.matches
    ]


def test_a_right_route_through_a_spiral_is_not_taken_for_a_wrong_one() -> None:
    """Drive 5 on a map that draws the road as driven: its dead reckoning turns with the
    gyro's scale-factor error. With the filter not considering it (``gyro_scale_consider``
    off), a twin without it does not cover that turn, and the right route's updates were
    undone (7.4 m against the baseline's 7.56); a twin that considers the scale
    (``dr_separation_gyro_scale``) keeps them, as does the filter with its defaults, whose
    covariance (and so its twin's) carries the scale itself."""
    drive = build(drive_spec(5))
    road = drive.on_the_road()
    assert road.log.truth is not None
    unscaled = {"extensions.gyro_scale_consider": False}
    values = {
        "defaults": {},
        "twin_scaled": unscaled,
        "twin_unscaled": {**unscaled, "extensions.dr_separation_gyro_scale": False},
    }
    runs = {
        n: run_methods(road, with_values(Params(), v), methods=("proposed",))["proposed"]
        for n, v in values.items()
    }
    runs["baseline"] = run_methods(road, Params(), methods=("baseline",))["baseline"]
    rmse = {}
    for name, r in runs.items():
        err, _ = outage_errors(r, road.log, road.frame)
        rmse[name] = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    undone = {n: any("dr_separation_m" in m.extra for m in r.matches) for n, r in runs.items()}
    assert undone["twin_unscaled"]
    assert not undone["twin_scaled"] and not undone["defaults"]
    assert max(rmse["twin_scaled"], rmse["defaults"]) < 0.5 * rmse["baseline"]
    assert 0.5 * rmse["baseline"] < rmse["twin_unscaled"]
    # every attempt on the right road is taken
    assert all(m.accepted for m in runs["twin_scaled"].matches)


def test_an_undone_outage_leaves_the_next_fix_to_dead_reckoning() -> None:
    """Drive 10 on a map that draws the road as driven: its first tunnel's updates are undone
    (its twin's heading is off by three of its sigmas before the portal). The filter then
    holds the twin's state, which took no route update, so the first fix after the tunnel is
    tested against dead reckoning's own covariance, whose position-heading correlation
    corrects the heading; widened to its innovation as after route updates, it left the
    heading 0.5 deg off, the next portal's fixes turned it to 0.7 deg, and the second
    tunnel's right updates were undone too (11.56 m against the baseline's 3.75). With
    today's map-bias fit the first tunnel is not undone: run with session 11's."""
    road = build(drive_spec(10)).on_the_road()
    assert road.log.truth is not None
    fit = with_values(Params(), SESSION_11_FIT)
    both = run_methods(road, fit, methods=("baseline", "proposed"))
    runs = {n: both[n] for n in ("baseline", "proposed")}
    prop = runs["proposed"]
    (a1, b1), (a2, b2) = prop.degraded_intervals[:2]
    undone = [m for m in prop.matches if "dr_separation_m" in m.extra]
    assert undone and a1 <= undone[0].t <= b1
    # the first fix used after the first tunnel narrows the heading, as dead reckoning's does
    e = {n: r.epochs for n, r in runs.items()}
    for name in ("baseline", "proposed"):
        after = np.flatnonzero((e[name].t > b1) & e[name].gnss_used)
        k = int(after[0])
        assert e[name].yaw_sigma[k + 5] < e[name].yaw_sigma[k - 1]
    # so the second tunnel's updates, on the right road, are taken
    second = [m for m in prop.matches if a2 <= m.t <= b2]
    assert second and all(m.accepted for m in second)
    rmse = {}
    for name, r in runs.items():
        err, _ = outage_errors(r, road.log, road.frame)
        rmse[name] = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    assert rmse["proposed"] <= rmse["baseline"] + 0.2
