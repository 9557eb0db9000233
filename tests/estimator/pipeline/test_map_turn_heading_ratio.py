"""``offset.map_turn_min_heading_ratio`` (issue 17's moved map): a rotation fitted on the
approach but not applied is estimated in the outage only where its prior stands out against
the heading's; otherwise the matches take the heading's drift for the map's rotation."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from estimator.evaluation.metrics import method_metrics
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.sim.stress import moved_route
from tests._session11_fit import SESSION_11_FIT

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
KEY = "offset.map_turn_min_heading_ratio"


def test_an_unturned_map_moved_is_not_turned_by_the_heading_drift() -> None:
    """Monaco on its route moved 10 m along and 3.5 m across (not turned): the approach fits
    0.2 deg of rotation, not applied, with a prior sigma (0.14 deg) below the heading's at the
    portal (0.145 deg). Estimated, the matches learn the heading's drift as the map's rotation.
    With session 11's approach (800 m): the 1600 m one's rotation (within two of its sigmas) is
    not considered at all."""
    inp = open_inputs(SAMPLES / "monaco_tunnel.mcap", SAMPLES / "monaco_tunnel.route.geojson")
    assert inp.route is not None
    moved = dataclasses.replace(inp, route=moved_route(inp.route))
    rmse, turns = {}, {}
    for ratio in (Params().offset.map_turn_min_heading_ratio, 0.0):
        runs = run_methods(moved, with_values(Params(), {**SESSION_11_FIT, KEY: ratio}))
        for method in ("baseline", "proposed"):
            r = runs[method]
            mm = method_metrics(
                r, moved.route, moved.log, subtract_lane_offset=True, params=r.params
            )
            assert mm.truth is not None and mm.truth.rmse_h_err_m is not None
            rmse[ratio, method] = mm.truth.rmse_h_err_m
        turns[ratio] = {m.map_bias.rotation_rad for m in runs["proposed"].matches if m.map_bias}
    default = Params().offset.map_turn_min_heading_ratio
    assert turns[default] == {0.0}  # nothing learned of a rotation
    assert turns[0.0] != {0.0}
    assert rmse[default, "proposed"] <= min(1.5, rmse[default, "baseline"])
    assert rmse[default, "proposed"] < rmse[0.0, "proposed"]
