"""A route within the few kilometres ``open_inputs`` lets through but farther from the vehicle
at an outage's start than any route update may move it (``driver.far_route_warnings``): the
run says so instead of reading as a right route that matched nothing."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from estimator.evaluation import map_bias_notes
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.pipeline.driver import far_route_warnings
from estimator.results import Epochs, MapBiasUse
from estimator.route import Route
from estimator.sim.stress import build, drive_spec
from inspector.app.playback import MAX_WARNING_CHARS

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
LINE = re.compile(
    r"the route is (?P<d>\d+) m from the vehicle at the start of the outage at "
    r"(?P<a>[\d.]+) s(?: \(and of (?P<n>\d+) more, up to (?P<up>\d+) m\))?, farther than a "
    r"route update may move it \(gates.max_correction_m (?P<cap>[\d.]+) m\): no match can be "
    r"accepted, the outage is dead-reckoned. The wrong route for this drive\?$"
)


def _epochs(t, east):
    n = len(t)
    position = np.zeros((n, 3))
    position[:, 0] = east
    return Epochs(
        t=np.asarray(t, float),
        position=position,
        velocity=np.zeros((n, 3)),
        attitude=np.zeros((n, 3)),
        position_sigma=np.ones((n, 3)),
        position_cov_en=np.zeros(n),
        yaw_sigma=np.zeros(n),
        gnss_used=np.zeros(n, bool),
        degraded=np.zeros(n, bool),
    )


def test_each_far_outage_start_is_counted_in_one_line_with_the_nearest_named_first():
    # the route runs north along x = 0; the vehicle is 5, 50, 80 and 40 m east of it at the
    # starts of four outages
    route = Route(np.array([[0.0, -1000.0], [0.0, 1000.0]]))
    t = np.arange(0.0, 100.0, 1.0)
    east = np.select([t < 20, t < 40, t < 60], [5.0, 50.0, 80.0], 40.0)
    outages = [(10.5, 15.0), (30.5, 35.0), (50.5, 55.0), (70.5, 75.0)]
    (line,) = far_route_warnings(_epochs(t, east), route, (), outages, 0.0, Params())
    m = LINE.match(line)
    assert m is not None, line
    assert (m["d"], m["a"], m["n"], m["up"], m["cap"]) == ("50", "30.5", "2", "80", "30")
    assert len(line) <= MAX_WARNING_CHARS
    wide = with_values(Params(), {"gates.max_correction_m": 100.0})
    assert far_route_warnings(_epochs(t, east), route, (), outages, 0.0, wide) == ()
    (one,) = far_route_warnings(_epochs(t, east), route, (), outages[2:3], 0.0, Params())
    assert LINE.match(one)["n"] is None  # type: ignore[index]


def test_the_distance_is_to_the_route_as_the_outage_s_applied_map_bias_moves_it_back():
    # the vehicle is 50 m east of the route at the outage's start; the approach learned that
    # the route is drawn 48 m west of the road (and the matches use it moved back), or learned
    # the same but did not apply it
    route = Route(np.array([[0.0, -1000.0], [0.0, 1000.0]]))
    t = np.arange(0.0, 20.0, 1.0)
    epochs = _epochs(t, np.full(len(t), 50.0))
    outage = [(10.5, 15.0)]

    def attempt(applied: bool) -> SimpleNamespace:
        bias = MapBiasUse(
            offset=np.array([-48.0, 0.0]), cov=np.eye(2), along_observed=True, applied=applied
        )
        return SimpleNamespace(t=11.0, map_bias=bias)

    assert far_route_warnings(epochs, route, [attempt(True)], outage, 0.0, Params()) == ()
    (line,) = far_route_warnings(epochs, route, [attempt(False)], outage, 0.0, Params())
    assert LINE.match(line)["d"] == "50"  # type: ignore[index]
    late = [SimpleNamespace(t=16.0, map_bias=attempt(True).map_bias)]
    assert len(far_route_warnings(epochs, route, late, outage, 0.0, Params())) == 1


def test_a_map_drawn_far_off_whose_bias_was_learned_and_matched_is_not_called_wrong():
    # held-out stress drive 24 of corpus 3: a map turned +1.78 deg about the long tunnel's
    # middle, 120 m across the road at the portal; the approach learns it and every match is
    # accepted
    run = run_methods(build(drive_spec(24, corpus=3)).inputs, Params(), methods=("proposed",))
    proposed = run["proposed"]
    assert proposed.matches and all(m.accepted for m in proposed.matches)
    assert any(m.map_bias is not None and m.map_bias.applied for m in proposed.matches)
    assert not any(w.startswith("the route is ") for w in proposed.warnings)


@pytest.fixture(scope="module")
def monaco():
    return open_inputs(SAMPLES / "monaco_tunnel.mcap", SAMPLES / "monaco_tunnel.route.geojson")


def test_a_route_drawn_100_m_off_the_road_is_named_and_nothing_is_said_learned_from_it(monaco):
    xy = monaco.route.xy
    u = (xy[-1] - xy[0]) / np.hypot(*(xy[-1] - xy[0]))
    off = Route(xy + 100.0 * np.array([-u[1], u[0]]), name="off")
    runs = run_methods(
        dataclasses.replace(monaco, route=off), Params(), methods=("baseline", "proposed")
    )
    run = runs["proposed"]
    # the line belongs to the run that matches against the route
    assert not any(w.startswith("the route is ") for w in runs["baseline"].warnings)
    assert not any(m.accepted for m in run.matches)
    (line,) = [w for w in run.warnings if w.startswith("the route is ")]
    m = LINE.match(line)
    assert m is not None, line
    assert m["a"] == "108.4"
    assert 60 <= int(m["d"]) <= 110
    (note,) = map_bias_notes(run)
    assert note == (
        "map bias for the outage at 108.4 s: nothing measured (too little GNSS-good driving "
        "before it, or its GNSS track does not follow the route); the route taken as right"
    )


def test_the_route_as_driven_is_not_warned_about(monaco):
    run = run_methods(monaco, Params(), methods=("proposed",))["proposed"]
    assert any(m.accepted for m in run.matches)
    assert not any(w.startswith("the route is ") for w in run.warnings)
