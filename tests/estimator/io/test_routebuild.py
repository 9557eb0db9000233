"""Routes derived from a recorded track (estimator/io/routebuild.py)."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.io.routebuild import moving_average, route_geojson, route_polyline
from estimator.nav import LocalFrame
from estimator.route import Route


def _arc_track(noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """A 100 m straight, then a quarter circle of radius 50 m (counter-clockwise), 1 m steps."""
    straight = np.column_stack([np.arange(0.0, 100.0), np.zeros(100)])
    a = np.linspace(0, np.pi / 2, 79)
    arc = np.column_stack([100 + 50 * np.sin(a), 50 - 50 * np.cos(a)])
    xy = np.vstack([straight, arc])
    return xy + np.random.default_rng(seed).normal(0, noise, xy.shape)


def test_moving_average_centred_and_shorter_at_the_ends():
    x = np.arange(10.0)
    m = moving_average(x, 5)
    assert m[5] == pytest.approx(5.0)
    assert m[0] == pytest.approx(np.mean([0, 1, 2]))
    assert moving_average(x, 1) == pytest.approx(x)


def test_route_follows_the_track_shifted_left():
    xy = _arc_track()
    v = route_polyline(xy, offset_left_m=1.8, extend_m=0.0, sigma_m=1.0, spacing_m=5.0)
    route = Route(v)
    proj = route.project(xy[5:-5])
    # the track lies to the right of the route by the offset (lateral positive = left)
    assert np.median(proj.lateral) == pytest.approx(-1.8, abs=0.15)
    assert np.max(np.abs(proj.lateral + 1.8)) < 0.6
    # the straight keeps few vertices; 25 m spacing cuts the R 50 m corner by about 25^2 / 400
    assert np.sum(v[:, 0] < 95) <= 3
    coarse = Route(route_polyline(xy, offset_left_m=1.8, extend_m=0.0, sigma_m=1.0))
    cut = coarse.project(xy[5:-5]).lateral + 1.8
    assert 0.8 < np.max(np.abs(cut)) < 2.5


def test_route_from_noisy_fixes_is_smooth_and_close():
    xy = _arc_track(noise=1.0)
    smooth = moving_average(xy, 5)
    v = route_polyline(smooth, sigma_m=3.0, extend_m=0.0, spacing_m=5.0)
    proj = Route(v).project(_arc_track()[10:-10])
    assert np.sqrt(np.mean(proj.lateral**2)) < 0.8


def test_extension_adds_straight_ends():
    xy = _arc_track()
    v = route_polyline(xy, extend_m=20.0)
    assert np.hypot(*(v[1] - v[0])) == pytest.approx(20.0)
    assert np.hypot(*(v[-1] - v[-2])) == pytest.approx(20.0)


def test_standing_track_is_refused():
    with pytest.raises(ValueError, match="does not move"):
        route_polyline(np.zeros((50, 2)))


def test_geojson_round_trip_in_lon_lat():
    frame = LocalFrame(42.3765, -71.1474, 0.0)
    geo = frame.to_geodetic(np.column_stack([_arc_track(), np.zeros(179)]))
    gj = route_geojson(
        geo[:, 0], geo[:, 1], name="t", derived_from="test", extend_m=0.0, spacing_m=5.0
    )
    (feature,) = gj["features"]
    coords = np.array(feature["geometry"]["coordinates"])
    assert feature["properties"]["lateral_offset_m"] == 0.0
    assert np.all(np.abs(coords[:, 0] + 71.1474) < 0.01)  # lon first
    back = frame.to_enu(coords[:, 1], coords[:, 0])[:, :2]
    proj = Route(back).project(_arc_track()[5:-5])
    assert np.max(np.abs(proj.lateral)) < 0.6


def test_route_from_a_logs_gnss_follows_its_fixes():
    from estimator.io import route_from_gnss
    from estimator.log import GnssData, ImuData, Log

    frame = LocalFrame(42.3765, -71.1474, 0.0)
    xy = _arc_track(noise=0.5, seed=1)
    geo = frame.to_geodetic(np.column_stack([xy, np.zeros(len(xy))]))
    n = len(xy)
    status = np.ones(n, np.int8)
    status[::10] = -1  # no-fix epochs are skipped
    geo[::10, :2] = np.nan
    t = np.arange(n, dtype=float)
    gnss = GnssData(t, geo[:, 0], geo[:, 1], geo[:, 2], status, np.ones((n, 3)))
    log = Log("lot.bag", ImuData(t, np.zeros((n, 3)), np.zeros((n, 3))), gnss)
    gj = route_from_gnss(log, name="lot", extend_m=10.0, spacing_m=5.0)
    props = gj["features"][0]["properties"]
    assert props["lateral_offset_m"] == 0.0 and "lot.bag" in props["derived_from"]
    coords = np.array(gj["features"][0]["geometry"]["coordinates"])
    back = frame.to_enu(coords[:, 1], coords[:, 0])[:, :2]
    lateral = Route(back).project(_arc_track()[10:-10]).lateral
    assert np.sqrt(np.mean(lateral**2)) < 0.5
