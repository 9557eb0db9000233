"""An outage whose match attempts were all refused is named: the run was dead reckoning there,
which its figures alone do not tell from a route that helped nothing."""

from __future__ import annotations

import json
from pathlib import Path

from estimator.params import Params
from estimator.pipeline import open_inputs, run_methods

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"


def _monaco_on(route: Path) -> tuple[str, ...]:
    inputs = open_inputs(SAMPLES / "monaco_tunnel.mcap", route)
    return run_methods(inputs, Params(), methods=("proposed",)).runs["proposed"].warnings


def test_a_route_drawn_against_the_travel_is_named_with_the_gate_that_refused_it(
    tmp_path: Path,
) -> None:
    drawn = json.loads((SAMPLES / "monaco_tunnel.route.geojson").read_text())
    coords = drawn["features"][0]["geometry"]["coordinates"]
    reversed_route = tmp_path / "reversed.geojson"
    reversed_route.write_text(json.dumps({"type": "LineString", "coordinates": coords[::-1]}))
    lines = [w for w in _monaco_on(reversed_route) if "match attempts in the outage" in w]
    assert len(lines) == 1
    line = lines[0]
    assert line.startswith("proposed run: all ") and "were refused (heading " in line
    assert "dead-reckoned" in line and len(line) < 300


def test_a_run_that_matched_says_nothing_of_it() -> None:
    warnings = _monaco_on(SAMPLES / "monaco_tunnel.route.geojson")
    assert not any("match attempts in the outage" in w for w in warnings)
