"""Per-run display arrays: decimation keeps the shape, markers and extents are right."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from fake_runs import T0, make_route, make_run

from estimator.evaluation.metrics import NEES_95_2DOF
from inspector.scene_data import (
    SceneData,
    decimate_polyline,
    ellipse_axes,
    masked_segments,
)


def _max_deviation(xy: np.ndarray, kept: np.ndarray) -> float:
    """Largest distance of any original vertex from the kept polyline."""
    k = xy[kept]
    worst = 0.0
    for a, b in itertools.pairwise(kept):
        p, q = xy[a], xy[b]
        d = q - p
        rel = xy[a : b + 1] - p
        u = np.clip(rel @ d / max(d @ d, 1e-12), 0, 1)
        worst = max(worst, float(np.max(np.hypot(*(rel - u[:, None] * d).T))))
    assert len(k) >= 2
    return worst


def test_decimation_respects_the_tolerance_and_drops_most_points():
    s = np.linspace(0, 5000, 50_001)
    xy = np.column_stack([s, 200 * np.sin(s / 400)])
    kept = decimate_polyline(xy, 0.05)
    assert kept[0] == 0 and kept[-1] == len(xy) - 1
    assert len(kept) < len(xy) / 20
    assert _max_deviation(xy, kept) <= 0.05 + 1e-9


def test_decimation_drops_nan_rows():
    xy = np.array([[0, 0], [1, 0], [np.nan, np.nan], [2, 1.0], [3, 3.0]])
    kept = decimate_polyline(xy, 0.01)
    assert 2 not in kept and kept[0] == 0 and kept[-1] == 4


def test_masked_segments_cover_only_the_masked_runs():
    xy = np.column_stack([np.arange(10.0), np.zeros(10)])
    mask = np.zeros(10, bool)
    mask[2:5] = True
    mask[7:9] = True
    seg = masked_segments(xy, mask)
    xs = seg[:, :, 0].ravel()
    assert set(np.round(xs)) <= {2, 3, 4, 7, 8}
    assert xs.min() == 2 and xs.max() == 8


def test_scene_data_indexes_attempts_by_time():
    base, prop = make_run(drift=30, method="baseline"), make_run()
    data = SceneData.build(baseline=base, proposed=prop, route=make_route(), log=None)
    assert data.truth is None and len(data.gnss_fixes) == 0
    assert len(data.match_xy) == 5 and data.match_accepted.tolist() == [1, 1, 0, 1, 1]
    assert data.match_index_at(T0 + 39) is None
    assert data.match_index_at(T0 + 45) == 1
    assert data.match_index_at(T0 + 49.9, max_age_s=2.0) is None
    assert len(data.degraded_segments) > 0
    assert 900 < data.extent_m < 1200
    xy, _yaw = data.proposed.pose_at(T0 + 10)
    assert np.allclose(xy, prop.epochs.position[200, :2])


def test_the_ring_is_the_ellipse_of_the_covariance_along_a_diagonal_road():
    along = np.array([1.0, 1.0]) / np.sqrt(2.0)
    across = np.array([-along[1], along[0]])
    P = 10.0**2 * np.outer(along, along) + 1.0**2 * np.outer(across, across)
    a, b, angle = ellipse_axes(np.array([P[0, 0], P[1, 1], P[0, 1]]), NEES_95_2DOF)
    assert a == pytest.approx(10.0 * np.sqrt(NEES_95_2DOF))
    assert b == pytest.approx(1.0 * np.sqrt(NEES_95_2DOF))
    assert angle == pytest.approx(np.pi / 4)
    assert ellipse_axes(np.array([1.0, 1.0, 1.0]), NEES_95_2DOF) is None  # singular
    assert ellipse_axes(np.array([np.nan, 1.0, 0.0]), NEES_95_2DOF) is None
