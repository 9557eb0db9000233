"""The SD-map route: sparse on straights, tens of metres on curves, close to the centreline."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.route import Route
from estimator.sim import Road, RouteModel, straight, turn
from estimator.sim.sdmap import douglas_peucker, map_route


def test_douglas_peucker_keeps_ends_and_corners() -> None:
    pts = np.array([[0, 0], [1, 0.01], [2, 0], [3, 0], [3, 1], [3, 2.0]])
    assert list(douglas_peucker(pts, 0.1)) == [0, 3, 5]
    assert list(douglas_peucker(pts, 0.001)) == [0, 1, 2, 3, 5]


def test_map_route_vertex_spacing() -> None:
    road = Road(straight(1000) + turn(90, 300) + straight(1000))
    sig = np.linspace(0, road.length, 2000)
    centre = road.xy(sig)
    model = RouteModel(vertex_spacing_m=25.0, simplify_m=0.3, extend_m=200.0)
    v = map_route(centre, model)
    seg = np.hypot(*np.diff(v, axis=0).T)
    # the straights collapse to one segment each (plus the 200 m extensions)
    assert seg.max() > 1000.0
    assert seg[0] == pytest.approx(200.0) and seg[-1] == pytest.approx(200.0)
    # on the curve the map has vertices tens of metres apart
    on_curve = seg[(seg < 100)]
    assert len(on_curve) >= 10
    assert 20.0 <= np.median(on_curve) <= 50.0
    # and cuts the corner by at most a few decimetres
    d = Route(v).project(centre).distance
    assert 0.05 < d.max() < 0.5


def test_map_bias_is_a_constant_shift() -> None:
    road = Road(straight(300) + turn(45, 200) + straight(300))
    centre = road.xy(np.linspace(0, road.length, 500))
    a = map_route(centre, RouteModel())
    b = map_route(centre, RouteModel(bias_enu_m=(1.5, -0.5)))
    np.testing.assert_allclose(b - a, np.tile([1.5, -0.5], (len(a), 1)))
