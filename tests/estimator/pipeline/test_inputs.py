from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError, RouteError
from estimator.io.bagwrite import write_bag
from estimator.log import GnssData, ImuData, TruthData
from estimator.pipeline import frame_of, open_inputs, route_distances

T0 = 1_600_000_000.0


def _log(tmp_path: Path, *, status: np.ndarray | None = None, truth: bool = False) -> Path:
    n = 500
    t = T0 + 0.01 * np.arange(n)
    imu = ImuData(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.8], (n, 1)))
    m = n // 10
    lat = 45.0 + 1e-5 * np.arange(m)  # driving north, 1.1 m per fix
    st = np.zeros(m, np.int8) if status is None else status
    gnss = GnssData(t[::10], lat, np.full(m, 7.0), np.full(m, 300.0), st, np.ones((m, 3)))
    tr = None
    if truth:
        tr = TruthData(t[::10], lat + 1e-6, np.full(m, 7.0), np.full(m, 301.0), np.zeros(m))
    path = tmp_path / "log.mcap"
    write_bag(path, imu=imu, gnss=gnss, truth=tr)
    return path


def _route(tmp_path: Path, dlat: float = 0.0) -> Path:
    coords = [[7.0, 44.999 + dlat], [7.0, 45.002 + dlat]]
    path = tmp_path / f"route{dlat}.geojson"
    path.write_text(json.dumps({"type": "LineString", "coordinates": coords}))
    return path


def test_frame_sits_at_the_first_valid_fix(tmp_path: Path) -> None:
    status = np.zeros(50, np.int8)
    status[:3] = -1
    inputs = open_inputs(_log(tmp_path, status=status), cache_dir=tmp_path / "c")
    assert inputs.route is None
    assert (inputs.frame.lat0, inputs.frame.lon0, inputs.frame.h0) == (45.00003, 7.0, 300.0)


def test_frame_falls_back_to_truth_then_fails(tmp_path: Path) -> None:
    no_fix = np.full(50, -1, np.int8)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    inputs = open_inputs(_log(tmp_path / "a", status=no_fix, truth=True), cache_dir=tmp_path)
    assert inputs.frame.lat0 == pytest.approx(45.000001) and inputs.frame.h0 == 301.0
    path = _log(tmp_path / "b", status=no_fix)
    with pytest.raises(LogError, match="no valid GNSS fix and no ground truth"):
        open_inputs(path, cache_dir=tmp_path)


def test_route_shares_the_frame_and_lies_on_the_track(tmp_path: Path) -> None:
    fractions: list[float] = []
    inputs = open_inputs(
        _log(tmp_path), _route(tmp_path), cache_dir=tmp_path / "c", progress=fractions.append
    )
    assert fractions[-1] == 1.0
    assert inputs.route is not None
    # the route starts 0.001 deg (111 m) south of the first fix, where the frame is
    np.testing.assert_allclose(inputs.route.xy[0], [0.0, -111.1], atol=0.2)
    d = route_distances(inputs.log, inputs.route, inputs.frame)
    assert len(d) == 50 and d.max() < 0.01
    assert frame_of(inputs.log) == inputs.frame


def test_route_far_from_the_log_is_refused(tmp_path: Path) -> None:
    log = _log(tmp_path)
    route = _route(tmp_path, dlat=0.1)  # starts 0.0985 deg north of the last fix
    with pytest.raises(RouteError) as err:
        open_inputs(log, route, cache_dir=tmp_path / "c")
    assert str(err.value) == (
        f"{route}: route is 10.9 km from the nearest position of log.mcap "
        "(more than 5 km): wrong route for this log?"
    )
    near = _route(tmp_path, dlat=0.045)  # 4.9 km: still accepted
    assert open_inputs(log, near, cache_dir=tmp_path / "c").route is not None


def test_real_car_log_and_route(shared_data: Path) -> None:
    inputs = open_inputs(
        shared_data / "comma2k19" / "i280.mcap", shared_data / "comma2k19" / "i280_route.geojson"
    )
    assert inputs.route is not None and inputs.route.length == pytest.approx(1411, abs=1)
    d = route_distances(inputs.log, inputs.route, inputs.frame)
    assert 1.0 < np.median(d) < 3.0


def test_route_distances_through_the_tree_equal_the_exact_ones(
    shared_data: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Above ``EXACT_DISTANCE_PAIRS`` the distances come from the k-d tree, which ``routefuse
    run`` would otherwise import for every route."""
    import estimator.pipeline.inputs as inputs_module

    inputs = open_inputs(
        shared_data / "comma2k19" / "i280.mcap", shared_data / "comma2k19" / "i280_route.geojson"
    )
    assert inputs.route is not None
    exact = route_distances(inputs.log, inputs.route, inputs.frame)
    monkeypatch.setattr(inputs_module, "EXACT_DISTANCE_PAIRS", 0)
    through_tree = route_distances(inputs.log, inputs.route, inputs.frame)
    np.testing.assert_allclose(through_tree, exact, atol=1e-9)


def test_frame_sits_at_the_first_fix_that_agrees_with_the_bulk() -> None:
    """A first fix at 0, 0 (a receiver's cold start, audit F1) is not where the frame goes:
    the frame sits at the first fix near the median of the log's fixes. A Log built in
    Python, without the loader's checks, is placed the same way."""
    from estimator.log import Log

    n = 500
    t = T0 + 0.01 * np.arange(n)
    imu = ImuData(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.8], (n, 1)))
    m = n // 10
    lat = 45.0 + 1e-5 * np.arange(m)
    lon = np.full(m, 7.0)
    lat[0], lon[0] = 0.0, 0.0
    gnss = GnssData(t[::10], lat, lon, np.full(m, 300.0), np.zeros(m, np.int8), np.ones((m, 3)))
    frame = frame_of(Log("x.mcap", imu, gnss))
    assert (frame.lat0, frame.lon0) == (lat[1], 7.0)
