from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.errors import RouteError
from estimator.route import Route

# East 100 m, then North 50 m
L_ROUTE = Route(np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 50.0]]), name="L")


def test_arc_length_point_tangent_heading_normal() -> None:
    r = L_ROUTE
    assert r.length == 150.0
    np.testing.assert_array_equal(r.s, [0.0, 100.0, 150.0])
    np.testing.assert_allclose(
        r.point_at([0.0, 50.0, 120.0, 150.0]), [[0, 0], [50, 0], [100, 20], [100, 50]]
    )
    np.testing.assert_allclose(r.tangent_at([10.0, 120.0]), [[1, 0], [0, 1]])
    np.testing.assert_allclose(r.heading_at([10.0, 120.0]), [0.0, np.pi / 2])
    np.testing.assert_allclose(r.normal_at([10.0, 120.0]), [[0, 1], [-1, 0]])  # to the left
    # beyond the ends the end segments are extended
    np.testing.assert_allclose(r.point_at([-10.0, 160.0]), [[-10, 0], [100, 60]])


def test_projection_sign_is_positive_left_of_travel() -> None:
    proj = L_ROUTE.project([[30.0, 2.0], [30.0, -3.0], [103.0, 20.0], [96.0, 40.0]])
    np.testing.assert_allclose(proj.s, [30.0, 30.0, 120.0, 140.0])
    np.testing.assert_allclose(proj.lateral, [2.0, -3.0, -3.0, 4.0])
    np.testing.assert_allclose(proj.distance, [2.0, 3.0, 3.0, 4.0])
    np.testing.assert_allclose(proj.foot, [[30, 0], [30, 0], [100, 20], [100, 40]])


def test_outside_corner_keeps_distance_and_side() -> None:
    proj = L_ROUTE.project([[103.0, -4.0]])  # beyond the corner, right of travel
    assert proj.s[0] == pytest.approx(100.0)
    assert proj.lateral[0] == pytest.approx(-5.0)


def test_windowed_projection_stays_on_its_branch() -> None:
    # out along y=0 and back along y=6: a point at y=2.5 is nearer the outbound branch
    out_and_back = Route(np.array([[0.0, 0.0], [500.0, 0.0], [500.0, 6.0], [0.0, 6.0]]))
    point = [[200.0, 3.5]]
    assert out_and_back.project(point).s[0] == pytest.approx(1006.0 - 200.0)  # global: y=6
    near_out = out_and_back.project(point, s_guess=210.0, search_m=50.0)
    assert near_out.s[0] == pytest.approx(200.0) and near_out.lateral[0] == pytest.approx(3.5)
    many = out_and_back.project([[100.0, 3.5], [300.0, 3.5]], s_guess=[90.0, 310.0], search_m=30.0)
    np.testing.assert_allclose(many.s, [100.0, 300.0])


def test_resample_and_segment() -> None:
    pts = L_ROUTE.resample(25.0)
    assert len(pts) == 7
    np.testing.assert_allclose(pts[-1], [100.0, 50.0])
    np.testing.assert_allclose(np.hypot(*np.diff(pts, axis=0).T), 25.0)
    np.testing.assert_allclose(L_ROUTE.resample(40.0, 20.0, 100.0), [[20, 0], [60, 0], [100, 0]])
    np.testing.assert_allclose(L_ROUTE.segment(90.0, 110.0), [[90, 0], [100, 0], [100, 10]])


def test_construction_cleans_and_rejects() -> None:
    r = Route(np.array([[0.0, 0.0], [0.0, 0.0], [3.0, 4.0], [3.0, 4.0]]))
    assert len(r.xy) == 2 and r.length == 5.0
    with pytest.raises(RouteError, match="fewer than 2 distinct points"):
        Route(np.array([[1.0, 1.0], [1.0, 1.0]]), source="same.gpx")
    with pytest.raises(RouteError, match="non-finite"):
        Route(np.array([[0.0, 0.0], [np.nan, 1.0]]))
    with pytest.raises(RouteError, match=r"\(N, 2\)"):
        Route(np.array([1.0, 2.0]))
    assert not r.xy.flags.writeable


def _brute_distance(xy: np.ndarray, p: np.ndarray) -> float:
    a, b = xy[:-1], xy[1:]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    return float(np.min(np.hypot(*(a + t[:, None] * ab - p).T)))


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 30))
def test_projection_is_the_nearest_point(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.uniform(-50, 50, (n, 2)), axis=0)
    route = Route(xy)
    pts = rng.uniform(xy.min(0) - 20, xy.max(0) + 20, (20, 2))
    proj = route.project(pts)
    brute = np.array([_brute_distance(route.xy, p) for p in pts])
    np.testing.assert_allclose(proj.distance, brute, atol=1e-9)
    np.testing.assert_allclose(route.point_at(proj.s), proj.foot, atol=1e-9)
    np.testing.assert_allclose(np.hypot(*(pts - proj.foot).T), brute, atol=1e-9)


@pytest.mark.parametrize("seed", range(12))
def test_distance_to_is_the_projection_s_distance(seed: int) -> None:
    """Routes of short, long and mixed segments, points on, near and far from them."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 400))
    steps = rng.normal(size=(n, 2)) * rng.choice([0.5, 30.0, 3000.0], size=(n, 1))
    route = Route(np.cumsum(steps, axis=0))
    points = np.vstack(
        [
            rng.normal(size=(300, 2)) * rng.choice([1.0, 100.0, 1e4]) + route.xy.mean(axis=0),
            route.xy[rng.integers(0, len(route.xy), 20)],
        ]
    )
    np.testing.assert_allclose(
        route.distance_to(points), route.project(points).distance, rtol=1e-9, atol=1e-6
    )


def test_distance_to_a_route_of_a_million_vertices_takes_seconds_not_minutes() -> None:
    """2000 fixes against 1 M vertices: project() without a window measured every fix against
    every segment (56 s in routefuse info)."""
    s = np.linspace(0.0, 5000.0, 1_000_000)
    route = Route(np.column_stack([s, 30.0 * np.sin(s / 200.0)]))
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0, 5000, 2000), rng.normal(0, 20, 2000)])
    started = time.perf_counter()
    distance = route.distance_to(points)
    assert time.perf_counter() - started < 10.0
    sample = slice(0, 2000, 100)
    np.testing.assert_allclose(
        distance[sample], route.project(points[sample]).distance, rtol=1e-9, atol=1e-6
    )
    assert distance.shape == (2000,) and route.distance_to(np.zeros((0, 2))).shape == (0,)
