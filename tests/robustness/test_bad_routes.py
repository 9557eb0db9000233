"""Route files that cannot be used with the base drive (one-line RouteError through the API,
exit 3 through ``routefuse info`` / ``routefuse run``), and routes that are odd but usable
(repeated vertices, zero-length segments, a self-crossing loop): repaired or used as they are,
with no match accepted onto the wrong branch."""

from __future__ import annotations

import json
import time
import tracemalloc
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from _badinputs import (
    COMMANDS,
    Corpus,
    assert_cli_error,
    assert_cli_ok,
    assert_one_line,
    base_sim,
    cli_argv,
    finite_run,
    route_lonlat,
)

from estimator.errors import RouteError
from estimator.io.routefile import MAX_ROUTE_BYTES, read_route_file
from estimator.params import Params
from estimator.pipeline import run
from estimator.pipeline.inputs import open_inputs

BOMB = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
 <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
 <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
 <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
 <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<{root}><{track}><name>&lol9;</name></{track}></{root}>
"""


def _linestring(tmp: Path, name: str, coords: list[list[float]]) -> Path:
    path = tmp / name
    path.write_text(json.dumps({"type": "LineString", "coordinates": coords}))
    return path


def _text(tmp: Path, name: str, text: str) -> Path:
    path = tmp / name
    path.write_text(text)
    return path


USA = [[-100.0, 40.0], [-100.1, 40.1]]


def _multilinestring(tmp: Path, name: str, parts: list[list[list[float]]]) -> Path:
    path = tmp / name
    path.write_text(json.dumps({"type": "MultiLineString", "coordinates": parts}))
    return path


def _bytes(tmp: Path, name: str, data: bytes) -> Path:
    path = tmp / name
    path.write_bytes(data)
    return path


def _shifted(dlat: float) -> list[list[float]]:
    return [[lon, lat + dlat] for lon, lat in route_lonlat()]


def _huge(tmp: Path, name: str) -> Path:
    path = tmp / name
    with path.open("wb") as fh:
        fh.write(b'{"type": "LineString", "coordinates": [')
        fh.truncate(210_000_000)
    return path


Make = Callable[[Path, Corpus], Path]
CASES: list[tuple[str, Make, str]] = [
    (
        "one point",
        lambda t, c: _linestring(t, "one.geojson", route_lonlat()[:1]),
        "route has 1 point; need at least 2",
    ),
    (
        "one point repeated",
        lambda t, c: _linestring(t, "same.geojson", route_lonlat()[:1] * 5),
        "fewer than 2 distinct points",
    ),
    (
        "50 km from the log",
        lambda t, c: _linestring(t, "far.geojson", _shifted(0.45)),
        "km from the nearest position of drive.mcap (more than 5 km): wrong route",
    ),
    (
        "lon/lat swapped",
        lambda t, c: _linestring(t, "swapped.geojson", [[a, b] for b, a in route_lonlat()]),
        "with latitude and longitude swapped: the file has them in the wrong order",
    ),
    (
        "lat out of range",
        lambda t, c: _linestring(t, "range.geojson", [[7.0, 95.0], [7.0, 96.0]]),
        "route point 0 is out of range (lat 95, lon 7)",
    ),
    (
        "GPX with no track",
        lambda t, c: _text(
            t, "waypoints.gpx", '<gpx version="1.1"><wpt lat="45.0" lon="7.0"/></gpx>'
        ),
        "no line geometry found",
    ),
    (
        "GPX entity-expansion bomb",
        lambda t, c: _text(t, "bomb.gpx", BOMB.format(root="gpx", track="trk")),
        "GPX file declares a DOCTYPE or ENTITY; refused for safety",
    ),
    (
        "KML entity-expansion bomb",
        lambda t, c: _text(t, "bomb.kml", BOMB.format(root="kml", track="Placemark")),
        "KML file declares a DOCTYPE or ENTITY; refused for safety",
    ),
    (
        "unknown file type",
        lambda t, c: _text(t, "route.shp", "not a route"),
        "unknown route format '.shp'",
    ),
    ("empty file", lambda t, c: _text(t, "empty.geojson", "  \n"), "file is empty"),
    (
        "binary file named .gpx",
        lambda t, c: _bytes(t, "bin.gpx", b"\x89PNG\r\n\x1a\n\xff\xfe"),
        "not a UTF-8 text file",
    ),
    (
        "deeply nested JSON",
        lambda t, c: _text(t, "deep.geojson", "[" * 100_000),
        "JSON nested too deeply",
    ),
    ("huge file", lambda t, c: _huge(t, "huge.geojson"), "route files over 50 MB are refused"),
    (
        "MultiLineString parts 8000 km apart",
        lambda t, c: _multilinestring(t, "multi_far.geojson", [route_lonlat(), USA]),
        "are 8",
    ),
    (
        "two points, from the drive to the USA",
        lambda t, c: _linestring(t, "to_usa.geojson", [route_lonlat()[0], USA[0]]),
        "route points 0 and 1 are 8",
    ),
    (
        "heights of 1e300 m",
        lambda t, c: _linestring(t, "alt.geojson", [[*p, 1e300] for p in route_lonlat()]),
        "route point 0 has a height of 1e+300 m; a road lies within 10 km of sea level",
    ),
    (
        "heights in millimetres",
        lambda t, c: _linestring(t, "alt_mm.geojson", [[*p, 250_000.0] for p in route_lonlat()]),
        "route point 0 has a height of 250000 m",
    ),
]
IDS = [c[0] for c in CASES]


@pytest.mark.parametrize(("name", "make", "problem"), CASES, ids=IDS)
def test_api_raises_one_line_route_error(
    tmp_path: Path, corpus: Corpus, name: str, make: Make, problem: str
) -> None:
    path = corpus.build(f"route: {name}", make)
    with pytest.raises(RouteError) as err:
        open_inputs(corpus.valid(), path, cache_dir=tmp_path / "cache")
    assert_one_line(err.value, path, problem)


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("name", "make", "problem"), CASES, ids=IDS)
def test_cli_exits_3_with_one_line(
    corpus: Corpus, capsys, command: str, name: str, make: Make, problem: str
) -> None:
    path = corpus.build(f"route: {name}", make)
    assert_cli_error(capsys, cli_argv(command, corpus.valid(), path), path, problem)


def test_a_wild_height_warns_nothing_before_its_error(tmp_path: Path, corpus: Corpus) -> None:
    """1e300 m overflowed the frame's conversion: a numpy RuntimeWarning on stderr, then a
    refusal saying the route was 0.0 km away and more than 5 km away."""
    path = corpus.build("route: heights of 1e300 m", CASES[-2][1])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(RouteError, match="height of 1e\\+300 m"):
            open_inputs(corpus.valid(), path, cache_dir=tmp_path / "cache")
    assert [str(w.message) for w in caught] == []


def test_far_route_error_measures_the_distance(tmp_path: Path, corpus: Corpus) -> None:
    """0.45 deg of latitude is 50 km: the error says so (within the route's own extent)."""
    path = corpus.build("route: 50 km from the log", CASES[2][1])
    with pytest.raises(RouteError, match=r"route is (\d+\.\d) km") as err:
        open_inputs(corpus.valid(), path, cache_dir=tmp_path / "cache")
    km = float(str(err.value).split("route is ")[1].split(" km")[0])
    assert 45.0 < km < 50.5


def test_swap_is_only_suggested_when_it_helps(tmp_path: Path, corpus: Corpus) -> None:
    """A route far away in both orders gets the plain far-route error."""
    coords = [[lat + 1.0, lon] for lon, lat in route_lonlat()]  # swapped and 1 deg off
    path = _linestring(tmp_path, "swapped_far.geojson", coords)
    with pytest.raises(RouteError) as err:
        open_inputs(corpus.valid(), path, cache_dir=tmp_path / "cache")
    assert "wrong route for this log" in err.value.problem
    assert "swapped" not in err.value.problem


def test_huge_route_file_is_not_read(tmp_path: Path) -> None:
    path = _huge(tmp_path, "huge.geojson")
    assert path.stat().st_size > MAX_ROUTE_BYTES
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(RouteError, match="refused"):
            read_route_file(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1e6 and time.perf_counter() - t0 < 1.0


def test_entity_bomb_is_refused_at_the_dtd(tmp_path: Path) -> None:
    """defusedxml stops at the DOCTYPE, before any entity is declared or expanded."""
    path = _text(tmp_path, "bomb.gpx", BOMB.format(root="gpx", track="trk"))
    start = time.perf_counter()
    with pytest.raises(RouteError, match="refused for safety"):
        read_route_file(path)
    assert time.perf_counter() - start < 0.5


# --- odd but usable --------------------------------------------------------------------------


def _doubled(tmp: Path, c: Corpus) -> Path:
    """Every vertex twice (a common export artefact)."""
    return _linestring(tmp, "doubled.geojson", [p for p in route_lonlat() for _ in (0, 1)])


def _zero_segments(tmp: Path, c: Corpus) -> Path:
    """Three zero-length segments inside the route and one at its end."""
    pts = route_lonlat()
    pts = pts[:3] + [pts[2]] * 3 + pts[3:] + [pts[-1]]
    return _linestring(tmp, "zero_segments.geojson", pts)


USABLE: dict[str, tuple[Make, int]] = {
    "duplicate vertices": (_doubled, len(route_lonlat())),
    "zero-length segments": (_zero_segments, 4),
}


@pytest.mark.parametrize("name", list(USABLE))
def test_repeated_vertices_are_removed_with_a_warning(
    tmp_path: Path, corpus: Corpus, capsys, name: str
) -> None:
    make, removed = USABLE[name]
    path = corpus.build(f"route: {name}", make)
    inputs = open_inputs(corpus.valid(), path, cache_dir=tmp_path / "cache")
    assert inputs.route is not None
    assert len(inputs.route.xy) == len(route_lonlat())
    assert np.all(np.diff(inputs.route.s) > 0)
    warning = f"route {path}: removed {removed} repeated vertices (zero-length segments)"
    assert inputs.route.warnings == (warning,)
    result = run(inputs.log, inputs.route, Params(), frame=inputs.frame)
    finite_run(result)
    assert warning in result.warnings
    assert sum(m.accepted for m in result.matches) > 0
    assert warning in assert_cli_ok(capsys, cli_argv("info", corpus.valid(), path))
    assert_cli_ok(capsys, cli_argv("run", corpus.valid(), path))


def _loop_back(tmp: Path, c: Corpus) -> Path:
    """The route out, then back over itself 30 m to the side (crossing the way out at the
    turn): the return branch is parallel to the driven road all along."""
    sim = base_sim()
    xy = sim.route_xy
    normal = np.diff(xy, axis=0)
    normal = np.column_stack([-normal[:, 1], normal[:, 0]]) / np.hypot(*normal.T)[:, None]
    back = (xy[1:] - 30.0 * normal)[::-1]
    turn_out = xy[-1] + np.array([0.0, 40.0])
    turn_in = back[-1] + np.array([40.0, -40.0])
    loop = np.vstack([xy, turn_out, back, turn_in, xy[2]])
    geo = sim.frame.to_geodetic(loop)
    return _linestring(tmp, "loop.geojson", [[lon, lat] for lat, lon, _ in geo])


def test_self_crossing_loop_never_matches_the_other_branch(tmp_path: Path, corpus: Corpus) -> None:
    path = corpus.build("route: self-crossing loop", _loop_back)
    inputs = open_inputs(corpus.valid(), path, cache_dir=tmp_path / "cache")
    assert inputs.route is not None
    result = run(inputs.log, inputs.route, Params(), frame=inputs.frame)
    finite_run(result)
    sim = base_sim()
    t_true = sim.truth.t  # log clock
    xy_true = result.frame.to_enu(*sim.frame.to_geodetic(sim.truth.position).T)[:, :2]
    accepted = [m for m in result.matches if m.accepted]
    assert accepted, [m.verdict for m in result.matches]
    for m in accepted:
        k = int(np.argmin(np.abs(t_true - m.t)))
        err = float(np.hypot(*(m.pseudo_position - xy_true[k])))
        assert err < 10.0, f"match {m.index} at {m.t - sim.t0:.1f} s is {err:.1f} m off"
