from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import RouteError, WhereToChoose
from estimator.io import load_route, read_route_file
from estimator.io.routefile import MAX_ROUTE_SEGMENT_M
from estimator.nav import LocalFrame

LAT = [48.1000, 48.1010, 48.1020, 48.1025]
LON = [11.5000, 11.5005, 11.5015, 11.5030]
ALT = [520.0, 521.0, 522.5, 523.0]
POINTS = list(zip(LAT, LON, ALT, strict=True))


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _gpx_track(path: Path) -> Path:
    pts = [f'<trkpt lat="{a}" lon="{o}"><ele>{h}</ele></trkpt>' for a, o, h in POINTS]
    half = len(LAT) // 2
    segs = "".join(f"<trkseg>{''.join(pts[i:j])}</trkseg>" for i, j in ((0, half), (half, None)))
    return _write(
        path,
        '<?xml version="1.0"?><gpx version="1.1" '
        'xmlns="http://www.topografix.com/GPX/1/1"><trk><name>T</name>'
        f"{segs}</trk></gpx>",
    )


def _every_format(tmp_path: Path) -> dict[str, Path]:
    coords = [[o, a, h] for a, o, h in POINTS]
    files = {
        "linestring": _write(
            tmp_path / "a.geojson", json.dumps({"type": "LineString", "coordinates": coords})
        ),
        "multi": _write(
            tmp_path / "b.json",
            json.dumps(
                {
                    "type": "Feature",
                    "properties": {"name": "M"},
                    "geometry": {
                        "type": "MultiLineString",
                        "coordinates": [coords[:2], coords[2:]],
                    },
                }
            ),
        ),
        "collection": _write(
            tmp_path / "c.geojson",
            json.dumps(
                {
                    "type": "FeatureCollection",
                    "features": [
                        {
                            "type": "Feature",
                            "properties": {"name": "pin"},
                            "geometry": {"type": "Point", "coordinates": coords[0]},
                        },
                        {
                            "type": "Feature",
                            "properties": {"name": "R"},
                            "geometry": {"type": "LineString", "coordinates": coords},
                        },
                    ],
                }
            ),
        ),
        "gpx_track": _gpx_track(tmp_path / "d.gpx"),
        "gpx_route": _write(
            tmp_path / "e.gpx",
            '<gpx version="1.0"><rte>'
            + "".join(f'<rtept lat="{a}" lon="{o}"><ele>{h}</ele></rtept>' for a, o, h in POINTS)
            + "</rte></gpx>",
        ),
        "kml": _write(
            tmp_path / "f.kml",
            '<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark>'
            "<name>K</name><LineString><coordinates>\n"
            + "\n".join(f"  {o},{a},{h}" for a, o, h in POINTS)
            + "\n</coordinates></LineString></Placemark></Document></kml>",
        ),
        "csv": _write(
            tmp_path / "g.csv",
            "lat,lon,alt\n" + "".join(f"{a},{o},{h}\n" for a, o, h in POINTS),
        ),
        "csv_swapped": _write(
            tmp_path / "h.csv",
            "Longitude;Latitude;Elevation\n" + "".join(f"{o};{a};{h}\n" for a, o, h in POINTS),
        ),
    }
    return files


@pytest.mark.parametrize(
    "kind",
    ["linestring", "multi", "collection", "gpx_track", "gpx_route", "kml", "csv", "csv_swapped"],
)
def test_every_format_parses_to_the_same_points(tmp_path: Path, kind: str) -> None:
    line = read_route_file(_every_format(tmp_path)[kind])
    np.testing.assert_array_equal(line.lat, LAT)
    np.testing.assert_array_equal(line.lon, LON)
    np.testing.assert_array_equal(line.alt, ALT)


def test_names_come_from_the_file_or_its_stem(tmp_path: Path) -> None:
    files = _every_format(tmp_path)
    assert read_route_file(files["collection"]).name == "R"
    assert read_route_file(files["kml"]).name == "K"
    assert read_route_file(files["gpx_track"]).name == "T"
    assert read_route_file(files["csv"]).name == "g"


def test_load_route_places_points_in_the_frame(tmp_path: Path) -> None:
    frame = LocalFrame(LAT[0], LON[0], ALT[0])
    route = load_route(_every_format(tmp_path)["kml"], frame)
    enu = frame.to_enu(LAT, LON, ALT)
    np.testing.assert_allclose(route.xy, enu[:, :2], atol=1e-9)
    assert route.length == pytest.approx(np.sum(np.hypot(*np.diff(enu[:, :2], axis=0).T)))
    assert route.xy[0] == pytest.approx([0.0, 0.0], abs=1e-9)


def test_missing_heights_sit_at_the_frame_height(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "r.csv",
        "lat,lon\n" + "".join(f"{a},{o}\n" for a, o in zip(LAT, LON, strict=True)),
    )
    frame = LocalFrame(LAT[0], LON[0], 800.0)
    route = load_route(path, frame)
    np.testing.assert_allclose(route.xy, frame.to_enu(LAT, LON, 800.0)[:, :2], atol=1e-9)


def test_several_lines_need_a_choice(tmp_path: Path) -> None:
    coords = [[o, a] for a, o in zip(LAT, LON, strict=True)]
    feats = [
        {
            "type": "Feature",
            "properties": {"name": n},
            "geometry": {"type": "LineString", "coordinates": c},
        }
        for n, c in (("north", coords), ("south", coords[::-1]))
    ]
    path = _write(
        tmp_path / "two.geojson", json.dumps({"type": "FeatureCollection", "features": feats})
    )
    with pytest.raises(RouteError) as err:
        read_route_file(path)
    assert str(err.value) == (
        f"{path}: the file has 2 lines (0: north, 1: south); choose one "
        "with --route-feature NAME_OR_INDEX"
    )
    assert read_route_file(path, feature="south").lat[0] == LAT[-1]
    assert read_route_file(path, feature=1).lat[0] == LAT[-1]
    assert read_route_file(path, feature="0").lat[0] == LAT[0]
    with pytest.raises(RouteError, match="no line feature named or numbered 'east'"):
        read_route_file(path, feature="east")


def test_an_int_choice_is_an_index_and_the_message_says_where_to_choose(tmp_path: Path) -> None:
    """The inspector's line dropdown passes an index: a line named '1' must not shadow line 1
    (text is a name first, as --route-feature reads it). The caller names where to choose."""
    from estimator.errors import RouteLineError
    from estimator.io.routefile import choose_line, route_line_names

    coords = [[o, a] for a, o in zip(LAT, LON, strict=True)]
    feats = [
        {
            "type": "Feature",
            "properties": {"name": n},
            "geometry": {"type": "LineString", "coordinates": c},
        }
        for n, c in (("1", coords), ("south", coords[::-1]))
    ]
    path = _write(
        tmp_path / "two.geojson", json.dumps({"type": "FeatureCollection", "features": feats})
    )
    names = route_line_names(path)
    assert names == ("1", "south")
    assert choose_line(path, names, 1) == 1 and choose_line(path, names, "1") == 0
    assert choose_line(path, names, -1) == 1
    assert read_route_file(path, feature=1).name == "south"
    with pytest.raises(RouteLineError) as err:
        read_route_file(path)
    assert str(err.value).endswith(
        "(0: 1, 1: south); choose one with --route-feature NAME_OR_INDEX"
    )
    in_picker = err.value.choose(WhereToChoose(route_line="in the picker"))
    assert str(in_picker).endswith("(0: 1, 1: south); choose one in the picker")
    assert err.value.lines == in_picker.lines == ("1", "south")
    with pytest.raises(RouteLineError, match=r"no line numbered 2; the file has 2 lines"):
        choose_line(path, names, 2)
    with pytest.raises(RouteLineError, match=r"the file has 1 line \(0: x\); choose one with"):
        choose_line(path, ("x",), "y")


@pytest.mark.parametrize(
    ("name", "text", "problem"),
    [
        (
            "one.geojson",
            '{"type": "LineString", "coordinates": [[11.5, 48.1]]}',
            "route has 1 point; need at least 2",
        ),
        (
            "none.geojson",
            '{"type": "Point", "coordinates": [11.5, 48.1]}',
            "no line geometry found",
        ),
        (
            "bad.geojson",
            '{"type": "LineString", "coordinates": [[11.5, 48.1],',
            "not valid JSON (line 1",
        ),
        (
            "nan.geojson",
            '{"type": "LineString", "coordinates": [[11.5, 48.1], [NaN, 48.2]]}',
            "route point 1 has a non-finite coordinate",
        ),
        pytest.param(
            "bigint.geojson",
            f'{{"type": "LineString", "coordinates": [[{"9" * 400}, 43.7], [7.42, 43.73]]}}',
            "route point 0 has a non-finite coordinate",
            id="bigint.geojson",
        ),
        pytest.param(
            "bigint_alt.geojson",
            f'{{"type": "LineString", "coordinates": [[7.4, 43.7, -{"9" * 400}], [7.42, 43.73]]}}',
            "route point 0 has a height of -inf m",
            id="bigint_alt.geojson",
        ),
        ("cm.csv", "lat,lon,alt\n48.1,11.5,52000\n48.2,11.6,52100\n", "height of 52000 m"),
        pytest.param(
            "bigint5000.geojson",
            f'{{"type": "LineString", "coordinates": [[{"9" * 5000}, 43.7], [7.42, 43.73]]}}',
            "not valid JSON for a route: an integer of more than 4300 digits",
            id="bigint5000.geojson",
        ),
        ("range.csv", "lat,lon\n48.1,11.5\n148.1,11.5\n", "route point 1 is out of range"),
        (
            "swapped.geojson",
            '{"type": "LineString", "coordinates": [[11.5, 48.1], [200, 48]]}',
            "route point 1 is out of range",
        ),
        ("nohead.csv", "48.1,11.5\n48.2,11.6\n", "CSV header"),
        ("text.csv", "lat,lon\n48.1,east\n48.2,11.6\n", "CSV line 2"),
        ("route.txt", "48.1,11.5\n", "unknown route format '.txt'"),
        ("empty.gpx", "", "file is empty"),
        ("html.gpx", "<html><body>hi</body></html>", "not a GPX file (root element <html>)"),
        ("broken.kml", "<kml><Placemark>", "not valid KML XML"),
        (
            "bomb.kml",
            '<?xml version="1.0"?><!DOCTYPE kml [<!ENTITY a "aaaa">]><kml>&a;</kml>',
            "declares a DOCTYPE or ENTITY",
        ),
    ],
)
def test_bad_route_files(tmp_path: Path, name: str, text: str, problem: str) -> None:
    path = _write(tmp_path / name, text)
    with pytest.raises(RouteError) as err:
        read_route_file(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: ") and problem in msg and "\n" not in msg


FAR_PARTS = {
    "parts.geojson": json.dumps(
        {
            "type": "MultiLineString",
            "coordinates": [[[7.40, 43.70], [7.41, 43.71]], [[-100.0, 40.0], [-100.1, 40.1]]],
        }
    ),
    "parts.gpx": (
        '<gpx version="1.1"><trk><trkseg><trkpt lat="43.70" lon="7.40"/>'
        '<trkpt lat="43.71" lon="7.41"/></trkseg><trkseg><trkpt lat="40.0" lon="-100.0"/>'
        '<trkpt lat="40.1" lon="-100.1"/></trkseg></trk></gpx>'
    ),
    "parts.kml": (
        "<kml><Placemark><MultiGeometry><LineString><coordinates>7.40,43.70 7.41,43.71"
        "</coordinates></LineString><LineString><coordinates>-100.0,40.0 -100.1,40.1"
        "</coordinates></LineString></MultiGeometry></Placemark></kml>"
    ),
}


@pytest.mark.parametrize(
    ("name", "part"),
    [
        ("parts.geojson", "MultiLineString lines"),
        ("parts.gpx", "trksegs"),
        ("parts.kml", "LineStrings"),
    ],
)
def test_parts_far_apart_are_refused_where_they_are_joined(
    tmp_path: Path, name: str, part: str
) -> None:
    path = _write(tmp_path / name, FAR_PARTS[name])
    with pytest.raises(RouteError) as err:
        read_route_file(path)
    message = str(err.value)
    assert message.startswith(f"{path}: route points 1 and 2 are 8")
    assert f"km apart (the join of {part} 0 and 1), from 43.71000, 7.41000 to 40.00000" in message
    assert "at most 50 km apart" in message and "\n" not in message


def test_a_segment_just_over_the_limit_is_refused(tmp_path: Path) -> None:
    """49.5 km between two points is a (hand-drawn) road; 50.5 km is not."""
    dlat = MAX_ROUTE_SEGMENT_M / 111_195
    ok = _write(tmp_path / "ok.csv", f"lat,lon\n48,11\n{48 + 0.99 * dlat},11\n")
    assert len(read_route_file(ok).lat) == 2
    far = _write(tmp_path / "far.csv", f"lat,lon\n48,11\n{48 + 1.01 * dlat},11\n")
    with pytest.raises(RouteError, match=r"route points 0 and 1 are 50\.5 km apart, from 48"):
        read_route_file(far)


def test_missing_and_binary_files(tmp_path: Path) -> None:
    with pytest.raises(RouteError, match="no such file"):
        read_route_file(tmp_path / "nope.gpx")
    (tmp_path / "bin.geojson").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(RouteError, match="not a UTF-8 text file"):
        read_route_file(tmp_path / "bin.geojson")


def test_real_routes(shared_data: Path) -> None:
    i280 = read_route_file(shared_data / "comma2k19" / "i280_route.geojson")
    assert len(i280.lat) == 6
    frame = LocalFrame(float(i280.lat[0]), float(i280.lon[0]))
    assert load_route(shared_data / "comma2k19" / "i280_route.geojson", frame).length == (
        pytest.approx(1411, abs=1)
    )
    monaco = shared_data / "osm_monaco" / "monaco_tunnels.geojson"
    with pytest.raises(RouteError, match=r"the file has 41 lines .*--route-feature"):
        read_route_file(monaco)
    line = read_route_file(monaco, feature=0)
    frame = LocalFrame(float(line.lat[0]), float(line.lon[0]))
    route = load_route(monaco, frame, feature=0)
    assert route.name == "Tunnel de Monaco"
    assert route.length == pytest.approx(2215.9, rel=1e-3)
