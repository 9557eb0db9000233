"""``offset.map_bias_walk_turned_only`` (issue 17's moved map): where the approach saw no
rotation, an applied bias's error does not walk in the outage, so it stays correlated with the
position error it was cloned from at the portal and the tunnel's first bend refines it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.sim.stress import moved_route
from tests._session11_fit import SESSION_11_FIT

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"


@pytest.mark.slow
def test_the_long_tunnel_bends_refine_an_unwalked_bias() -> None:
    """The long tunnel on its route moved 10 m along and 3.5 m across: the approach turns
    (the along-track bias is learned) but fits no rotation. Without the walk the learned
    bias's along-track error has shrunk by the stretch between the two bends (60-80 % of the
    outage), and the truth RMSE comes down to
    what the right map gives (2 m); with it the bend moves the bias the wrong way. With
    session 11's approach (800 m): the 1600 m one's bias starts nearer the truth."""
    inp = open_inputs(SAMPLES / "long_tunnel.mcap", SAMPLES / "long_tunnel.route.geojson")
    assert inp.route is not None
    moved = dataclasses.replace(inp, route=moved_route(inp.route))
    shift = moved.route.xy[0] - inp.route.xy[0]  # type: ignore[union-attr]
    rmse, along_err = {}, {}
    for on in (True, False):
        p = with_values(Params(), {**SESSION_11_FIT, "offset.map_bias_walk_turned_only": on})
        run = run_methods(moved, p, methods=("proposed",))["proposed"]
        recs = [m for m in run.matches if m.map_bias is not None and m.fit is not None]
        assert recs and all(m.map_bias.applied for m in recs)  # type: ignore[union-attr]
        assert all(m.map_bias.rotation_rad == 0.0 for m in recs)  # type: ignore[union-attr]
        a, b = run.degraded_intervals[0]
        between = [m for m in recs if a + 0.6 * (b - a) <= m.t <= a + 0.8 * (b - a)]
        errs = []
        for m in (recs[0], between[-1]):
            n = m.normal
            u = np.array([n[1], -n[0]])
            errs.append(abs(float(u @ (m.map_bias.offset - shift))))  # type: ignore[union-attr]
        along_err[on] = errs
        truth = method_metrics(run, moved.route, moved.log).truth  # type: ignore[arg-type]
        assert truth is not None and truth.rmse_h_err_m is not None
        rmse[on] = truth.rmse_h_err_m
    first, last = along_err[True]
    assert last < 0.5 * first
    assert along_err[False][1] > along_err[False][0]
    assert rmse[True] < rmse[False] - 0.1
    assert rmse[True] <= 2.0
