from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.nav import LocalFrame

R_EARTH = 6_371_000.0


@settings(max_examples=25, deadline=None)
@given(
    lat0=st.floats(-80.0, 80.0),
    lon0=st.floats(-180.0, 180.0),
    h0=st.floats(-100.0, 3000.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_enu_round_trip_below_a_micrometre_over_20_km(lat0, lon0, h0, seed) -> None:
    frame = LocalFrame(lat0, lon0, h0)
    rng = np.random.default_rng(seed)
    enu = np.column_stack([rng.uniform(-20_000, 20_000, (200, 2)), rng.uniform(-200, 200, 200)])
    back = frame.to_enu(*frame.to_geodetic(enu).T)
    assert np.max(np.abs(back - enu)) < 1e-6


def test_geodetic_round_trip_and_origin() -> None:
    frame = LocalFrame(48.137, 11.575, 519.0)
    np.testing.assert_allclose(frame.to_enu(48.137, 11.575, 519.0), [[0.0, 0.0, 0.0]], atol=1e-9)
    lat = 48.137 + np.linspace(-0.18, 0.18, 50)  # +-20 km
    lon = 11.575 + np.linspace(0.27, -0.27, 50)
    h = np.linspace(400.0, 900.0, 50)
    geo = frame.to_geodetic(frame.to_enu(lat, lon, h))
    np.testing.assert_allclose(geo[:, 0], lat, atol=1e-11)  # 1e-11 deg = 1 micrometre
    np.testing.assert_allclose(geo[:, 1], lon, atol=1e-11)
    np.testing.assert_allclose(geo[:, 2], h, atol=1e-6)


def test_axes_point_east_north_up() -> None:
    frame = LocalFrame(0.0, 30.0, 0.0)
    north = frame.to_enu(0.1, 30.0, 0.0)[0]
    east = frame.to_enu(0.0, 30.1, 0.0)[0]
    up = frame.to_enu(0.0, 30.0, 50.0)[0]
    assert north[1] > 11_000 and abs(north[0]) < 1e-6
    assert east[0] > 11_000 and abs(east[1]) < 1e-6
    np.testing.assert_allclose(up, [0.0, 0.0, 50.0], atol=1e-6)
    # the ellipsoid falls away below the tangent plane: about -d^2 / 2R
    d = np.hypot(*east[:2])
    assert east[2] == pytest.approx(-(d**2) / (2 * R_EARTH), rel=0.01)


def test_nan_in_nan_out_and_bad_origin() -> None:
    frame = LocalFrame(10.0, 20.0)
    out = frame.to_enu([10.0, np.nan, 10.0], [20.0, 20.0, np.inf])
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))
    with pytest.raises(ValueError, match="not finite"):
        LocalFrame(np.nan, 0.0)


def test_frame_at_the_first_finite_fix() -> None:
    frame = LocalFrame.at([np.nan, 45.5, 46.0], [7.0, 7.25, 7.5], [np.nan, 300.0, 400.0])
    assert (frame.lat0, frame.lon0, frame.h0) == (45.5, 7.25, 300.0)
    assert LocalFrame.at([1.0], [2.0], [np.nan]).h0 == 0.0
    frame = LocalFrame.at(np.float64(45.5), np.float64(7.0))
    assert type(frame.lat0) is float
    with pytest.raises(ValueError, match="no finite position"):
        LocalFrame.at([np.nan], [np.nan])
