"""One session over a log (run_methods): the methods in order with reuse, the outage check,
and a previous session taken over only on the same inputs and outages."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator.errors import ConfigError
from estimator.params import Params, with_values
from estimator.pipeline import Inputs, MethodRuns, checked_outages, run, run_methods
from estimator.results import Run
from estimator.sim import simulate

OUTAGES = ((20.0, 60.0),)


@pytest.fixture(scope="module")
def inputs() -> Inputs:
    sim = simulate("short_tunnel", seed=1)
    return Inputs(sim.log(), sim.route(), sim.frame)


@pytest.fixture(scope="module")
def session(inputs: Inputs) -> MethodRuns:
    return run_methods(inputs, Params(), methods=("baseline", "proposed", "paper"), outages=OUTAGES)


def _same(a: Run, b: Run) -> bool:
    fields = [f.name for f in dataclasses.fields(a.epochs)]
    return all(np.array_equal(getattr(a.epochs, f), getattr(b.epochs, f)) for f in fields)


def test_every_method_is_the_run_of_that_method_alone(inputs: Inputs, session: MethodRuns):
    assert session.methods == ("baseline", "proposed", "paper")
    assert set(session.seconds) == set(session.methods)
    for method in session.methods:
        alone = run(
            inputs.log, inputs.route, Params(), method=method, frame=inputs.frame, outages=OUTAGES
        )
        got = session[method]
        assert got.method == method and _same(got, alone)
        assert [m.accepted for m in got.matches] == [m.accepted for m in alone.matches]


def test_the_same_parameters_take_the_previous_runs_over(inputs: Inputs, session: MethodRuns):
    again = run_methods(
        inputs, Params(), methods=("baseline", "proposed"), outages=OUTAGES, reuse=session
    )
    assert again["baseline"] is session["baseline"]
    assert again["proposed"] is session["proposed"]


def test_a_gate_change_reruns_the_method_and_copies_the_baseline(
    inputs: Inputs, session: MethodRuns
):
    p = with_values(Params(), {"gates.max_residual_m": 1.5})
    again = run_methods(inputs, p, outages=OUTAGES, reuse=session)
    fresh = run_methods(inputs, p, outages=OUTAGES)
    assert again["baseline"].epochs is session["baseline"].epochs  # the filter did not run
    assert again["proposed"] is not session["proposed"]
    assert _same(again["proposed"], fresh["proposed"])


def test_a_previous_session_counts_only_on_the_same_inputs_and_outages(
    inputs: Inputs, session: MethodRuns
):
    calls: list[tuple[str, Run | None]] = []

    def recording(inputs, params, method, progress, reuse, *, outages):
        calls.append((method, reuse))
        return session[method]

    run_methods(inputs, Params(), outages=(), reuse=session, run_one=recording)
    copy = dataclasses.replace(inputs)
    run_methods(copy, Params(), outages=OUTAGES, reuse=session, run_one=recording)
    # never the previous session's run; the method resumes from this session's baseline
    assert [(m, r) for m, r in calls] == [
        ("baseline", None),
        ("proposed", session["baseline"]),
    ] * 2


def test_progress_names_the_method_and_ends_each_run_at_one(inputs: Inputs):
    seen: list[tuple[str, float]] = []
    run_methods(inputs, Params(), outages=OUTAGES, progress=lambda m, f: seen.append((m, f)))
    assert list(dict.fromkeys(m for m, _ in seen)) == ["baseline", "proposed"]
    last = {m: f for m, f in seen}
    assert seen[0] == ("baseline", 0.0) and last == {"baseline": 1.0, "proposed": 1.0}


def test_an_outage_after_the_log_ends_is_refused_with_the_option_named(inputs: Inputs):
    with pytest.raises(ConfigError) as err:
        run_methods(inputs, Params(), outages=[(1e6, 1e6 + 10)], outage_option="GNSS outages")
    assert "GNSS outages" in str(err.value) and "starts after the log ends" in str(err.value)


def test_checked_outages_are_float_pairs_and_ask_the_duration_only_if_needed():
    def no_duration() -> float:
        raise AssertionError("asked")

    assert checked_outages([], no_duration, where="--outage") == ()
    assert checked_outages([(1, 2)], lambda: 10.0, where="--outage") == ((1.0, 2.0),)


def test_a_run_carries_no_public_resume_data(session: MethodRuns):
    r = session["proposed"]
    public = [f.name for f in dataclasses.fields(Run) if not f.name.startswith("_")]
    assert "resume" not in public
    assert "_reuse" not in repr(r)
