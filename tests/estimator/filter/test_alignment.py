"""Initial alignment robust to bad first fixes (issue 17, item 3): the heading is taken from a
chord whose fixes between agree with it and whose length the wheels confirm; the fixes left
out are named."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.params import Params
from estimator.pipeline import open_inputs, run_methods
from estimator.pipeline.inputs import Inputs

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
M_PER_DEG_LAT = 111_320.0


@pytest.fixture(scope="module")
def monaco() -> Inputs:
    return open_inputs(SAMPLES / "monaco_tunnel.mcap", SAMPLES / "monaco_tunnel.route.geojson")


def _moved(inputs: Inputs, metres: float, which: list[int]) -> Inputs:
    g = inputs.log.gnss
    lat = g.lat.copy()
    valid = np.flatnonzero(g.valid)
    lat[valid[which]] += metres / M_PER_DEG_LAT
    log = dataclasses.replace(inputs.log, gnss=dataclasses.replace(g, lat=lat))
    return dataclasses.replace(inputs, log=log)


def _truth_rmse(inputs: Inputs, method: str = "proposed") -> tuple[float, tuple[str, ...]]:
    run = run_methods(inputs, Params(), methods=(method,))[method]
    assert inputs.route is not None
    truth = method_metrics(run, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return truth.rmse_h_err_m, run.warnings


@pytest.mark.parametrize(
    ("metres", "which"),
    [(50.0, [0]), (10.0, [0]), (50.0, [0, 3, 6])],
    ids=["first fix 50 m off", "first fix 10 m off", "three of the first ten 50 m off"],
)
def test_bad_first_fixes_neither_turn_the_heading_nor_go_unsaid(
    monaco: Inputs, metres: float, which: list[int]
) -> None:
    clean, _ = _truth_rmse(monaco)
    rmse, warnings = _truth_rmse(_moved(monaco, metres, which))
    assert rmse <= max(3.0, clean + 0.3)
    if metres >= 50.0:
        left_out = [w for w in warnings if "left out of the initial alignment" in w]
        assert len(left_out) == len(which)
        assert all(f"{metres:.0f} m off" in w or f"{metres + 1:.0f} m off" in w for w in left_out)
