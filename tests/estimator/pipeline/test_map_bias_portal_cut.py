"""``extensions.map_bias_portal_cut`` (issue 17, off): the map-bias fit's approach ends
``offset.map_bias_portal_cut_s`` before the outage starts, leaving out the portal's degraded
fixes the filter still used."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import estimator.pipeline.driver as driver
from estimator.filter.layout import O_T
from estimator.params import Params, with_values
from estimator.pipeline import run_methods
from estimator.sim.stress import build, drive_spec

CUT = "extensions.map_bias_portal_cut"


def _approaches(monkeypatch: pytest.MonkeyPatch, cut: bool) -> list[tuple[float, float]]:
    """(time of the approach's last row, the outage start that follows) for every map-bias
    fit of corpus drive 3 (Monaco, the map turned 0.75 deg, 20 of the 40 fixes of the last 8 s
    before the tunnel used by the filter)."""
    ends: list[float] = []
    bias_track = driver.Driver._bias_track

    def spy(self: Any, rows: np.ndarray, last: np.ndarray) -> np.ndarray | None:
        track = bias_track(self, rows, last)
        if track is not None:
            ends.append(float(track[-1, O_T]))
        return track

    monkeypatch.setattr(driver.Driver, "_bias_track", spy)
    inputs = build(drive_spec(3)).inputs
    run = run_methods(inputs, with_values(Params(), {CUT: cut}), methods=("proposed",))
    starts = [a for a, _ in run["proposed"].degraded_intervals]
    return [(e, min(s for s in starts if s >= e)) for e in ends]


@pytest.mark.slow
def test_the_approach_ends_before_the_portal_stretch(monkeypatch: pytest.MonkeyPatch) -> None:
    as_run = _approaches(monkeypatch, False)
    cut = _approaches(monkeypatch, True)
    assert len(as_run) == len(cut) >= 1
    # by default the fit takes the fixes the filter used up to the portal; cut, none of the
    # last 8 s before any outage
    assert any(start - end < 8.0 for end, start in as_run)
    assert all(start - end >= 8.0 for end, start in cut)
