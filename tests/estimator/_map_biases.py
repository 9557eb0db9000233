"""A map bias as the tests of the map-bias decisions build it: what :class:`MapBias` needs,
with the fields a test does not care about at neutral values."""

from __future__ import annotations

from typing import Any

import numpy as np

from estimator.matching.map_bias import MapBias
from estimator.results import Run


def map_bias(offset: Any = (0.0, 0.0), **fields: Any) -> MapBias:
    """``offset`` (E, N at the pivot, m) and any other :class:`MapBias` field given; the rest:
    no rotation, pivot at the origin, the lane 1.75 m right, no gain or covariance, measured as
    the offset with unit covariance, chi-square 0, along-track not observed."""
    offset = np.asarray(offset, np.float64)
    defaults: dict[str, Any] = {
        "offset": offset,
        "rotation": 0.0,
        "rotation_sigma": 0.0,
        "pivot": np.zeros(2),
        "lane": -1.75,
        "gain": np.zeros((3, 2)),
        "cov": np.zeros((3, 3)),
        "measured": offset,
        "measured_cov": np.eye(2),
        "chi2": 0.0,
        "along_observed": False,
    }
    return MapBias(**{**defaults, **fields})


def applied_per_outage(run: Run) -> list[bool]:
    """Per GNSS-degraded interval of ``run``, whether its first attempt matched with a map
    bias applied."""
    applied = []
    for a, b in run.degraded_intervals:
        uses = [m.map_bias for m in run.matches if a <= m.t <= b and m.map_bias is not None]
        applied.append(bool(uses and uses[0].applied))
    return applied
