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


def test_many_refused_outages_get_a_few_warning_lines() -> None:
    """Dozens of outages refused alike (a route against the travel throughout) name the first
    four and sum the rest up in one line, as the IMU gaps' and the exits' warnings do."""
    from types import SimpleNamespace

    from estimator.errors import WARNING_LINES_NAMED
    from estimator.pipeline.driver import REFUSED_OUTAGE_MIN_ATTEMPTS, refused_outage_warnings

    gate = SimpleNamespace(name="heading")
    outages = [(100.0 + 60 * k, 130.0 + 60 * k) for k in range(9)]
    records = [
        SimpleNamespace(t=a + 2 * j, accepted=False, failed_gates=(gate,))
        for a, _ in outages
        for j in range(REFUSED_OUTAGE_MIN_ATTEMPTS)
    ]
    lines = refused_outage_warnings("proposed", records, outages, 0.0)  # type: ignore[arg-type]
    assert len(lines) == WARNING_LINES_NAMED
    assert lines[0].startswith("proposed run: all 5 match attempts in the outage at 100.0-130.0 s")
    assert lines[-1] == (
        "proposed run: ... and 5 more outages whose match attempts were all refused"
    )
    few = refused_outage_warnings("proposed", records[:25], outages[:5], 0.0)  # type: ignore[arg-type]
    assert len(few) == WARNING_LINES_NAMED and not any("more outages" in w for w in few)
