"""A mission route that comes back along the road it went out on draws that road twice, once
each way: the vehicle is placed on the leg drawn the way it drives."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.matching.geometry import route_arc_length
from estimator.params import Params
from estimator.pipeline import open_inputs, run_methods
from estimator.route import Route

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"


def _out_and_back() -> Route:
    out = np.column_stack([np.linspace(0.0, 1000.0, 11), np.zeros(11)])
    back = out[::-1][1:] + np.array([0.0, 0.5])  # the return drawn half a metre aside
    return Route(np.vstack([out, back]))


@pytest.mark.parametrize(
    ("heading", "leg"), [((15.0, 0.3), "out"), ((-15.0, 0.2), "back"), ((0.0, 0.0), "nearest")]
)
def test_placed_on_the_leg_drawn_the_way_it_drives(heading: tuple[float, float], leg: str) -> None:
    route = _out_and_back()
    here = np.array([400.0, 0.6])  # nearer the return's line
    s = route_arc_length(route, here, params=Params(), heading_xy=np.array(heading))
    nearest = route_arc_length(route, here, params=Params())
    assert nearest == pytest.approx(1600.0, abs=0.01)  # 1000 m out, 600 m back
    expected = {"out": 400.0, "back": 1600.0, "nearest": nearest}[leg]
    assert s == pytest.approx(expected, abs=0.01)


def test_a_route_drawn_the_way_it_drives_keeps_its_nearest_point() -> None:
    route = Route(np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]]))
    here = np.array([103.0, -3.0])  # outside the corner: the two legs' feet differ
    for heading in ((10.0, 0.0), (0.0, 10.0), (7.0, 7.0)):
        s = route_arc_length(route, here, params=Params(), heading_xy=np.array(heading))
        assert s == route_arc_length(route, here, params=Params())


def test_monaco_on_an_out_and_back_route_is_matched_as_on_its_own(tmp_path: Path) -> None:
    """The sample's route followed by the same road back: every match was refused for its
    heading (0 of 112) and routefuse ran as dead reckoning, saying nothing."""
    drawn = json.loads((SAMPLES / "monaco_tunnel.route.geojson").read_text())
    coords = drawn["features"][0]["geometry"]["coordinates"]
    route = tmp_path / "out_and_back.geojson"
    route.write_text(json.dumps({"type": "LineString", "coordinates": coords + coords[::-1][1:]}))
    log = SAMPLES / "monaco_tunnel.mcap"
    figures = {}
    for name, path in (("own", SAMPLES / "monaco_tunnel.route.geojson"), ("twice", route)):
        inputs = open_inputs(log, path)
        run = run_methods(inputs, Params(), methods=("proposed",)).runs["proposed"]
        truth = method_metrics(run, inputs.route, inputs.log).truth
        assert truth is not None and truth.rmse_h_err_m is not None
        figures[name] = (sum(m.accepted for m in run.matches), truth.rmse_h_err_m)
    assert figures["twice"][0] >= 0.95 * figures["own"][0]
    assert figures["twice"][1] <= figures["own"][1] + 0.1
