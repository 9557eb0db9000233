"""Route files are parsed as they are read (GPX and KML element by element, CSV row by row,
GeoJSON positions part by part into one array): the lines, their order, names, parts and
messages are those of reading the whole file first, and no point past MAX_ROUTE_POINTS is
kept."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import RouteError
from estimator.io import routefile
from estimator.io.routefile import read_route_file, read_route_lines, route_line_names


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _points(path: Path) -> list[list[tuple[float, float, float]]]:
    return [
        list(zip(x.lat.tolist(), x.lon.tolist(), x.alt.tolist(), strict=True))
        for x in read_route_lines(path)
    ]


def test_gpx_tracks_come_before_routes_with_their_first_name_and_height(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "mixed.gpx",
        '<gpx xmlns="http://www.topografix.com/GPX/1/1"><rte><name> R </name>'
        '<rtept lat="48.1" lon="11.5"/><rtept lat="48.2" lon="11.5"><ele>7</ele></rtept></rte>'
        '<wpt lat="1" lon="1"/><trk><name></name><name>second</name>'
        '<trkseg><trkpt lat="48.3" lon="11.5"><ele/><ele>5</ele></trkpt></trkseg>'
        '<trkpt lat="9" lon="9"/><trkseg/><trkseg><trkpt lat="48.4" lon="11.5"><ele> 6 </ele>'
        '</trkpt></trkseg></trk><trk><name>T</name><trkseg><trkpt lat="48.5" lon="11.5"/>'
        '<trkpt lat="48.6" lon="11.5"/></trkseg></trk></gpx>',
    )
    assert route_line_names(path) == ("track 0", "T", "R")
    nan = math.nan
    got = _points(path)
    assert str(got) == str(
        [
            [(48.3, 11.5, nan), (48.4, 11.5, 6.0)],
            [(48.5, 11.5, nan), (48.6, 11.5, nan)],
            [(48.1, 11.5, nan), (48.2, 11.5, 7.0)],
        ]
    )


def test_gpx_segments_far_apart_name_their_join(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "parts.gpx",
        '<gpx><trk><trkseg><trkpt lat="43.70" lon="7.40"/><trkpt lat="43.71" lon="7.41"/>'
        '</trkseg><trkseg/><trkseg><trkpt lat="40.0" lon="-100.0"/>'
        '<trkpt lat="40.1" lon="-100.1"/></trkseg></trk></gpx>',
    )
    with pytest.raises(RouteError, match=r"points 1 and 2 .* \(the join of trksegs 0 and 1\)"):
        read_route_file(path)


def test_a_kml_placemark_holds_the_linestrings_of_one_nested_in_it(tmp_path: Path) -> None:
    """As an ElementTree's ``iter`` found them: the outer placemark comes first and holds every
    LineString inside it, in the file's order; a LineString outside a placemark is no line."""
    path = _write(
        tmp_path / "nested.kml",
        "<kml><LineString><coordinates>1,1 2,2</coordinates></LineString>"
        "<Placemark><name>outer</name><LineString><coordinates>7.40,43.70 7.41,43.71"
        "</coordinates></LineString><Placemark><name>inner</name><LineString>"
        "<coordinates>7.42,43.72,5 7.43,43.73</coordinates></LineString></Placemark>"
        "<LineString><coordinates>7.44,43.74</coordinates></LineString></Placemark>"
        "<Placemark><name>no line</name></Placemark>"
        "<Placemark><LineString><coordinates>7.5,43.8 7.51,43.81</coordinates></LineString>"
        "</Placemark></kml>",
    )
    assert route_line_names(path) == ("outer", "inner", "placemark 3")
    outer, inner, last = read_route_lines(path)
    assert outer.lat.tolist() == [43.70, 43.71, 43.72, 43.73, 43.74]
    assert inner.lon.tolist() == [7.42, 7.43] and inner.alt[0] == 5.0
    assert last.lat.tolist() == [43.8, 43.81]


def test_a_wrong_kml_coordinate_is_the_first_in_placemark_order(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "wrong.kml",
        "<kml><Placemark><LineString><coordinates>1,1 first</coordinates></LineString>"
        "</Placemark><Placemark><LineString><coordinates>second</coordinates></LineString>"
        "</Placemark></kml>",
    )
    with pytest.raises(RouteError, match="KML coordinate 'first' is not lon,lat"):
        read_route_file(path)


def test_an_xml_error_comes_before_a_wrong_coordinate_and_the_root(tmp_path: Path) -> None:
    wrong = _write(
        tmp_path / "wrong.kml",
        "<kml><Placemark><LineString><coordinates>x</coordinates></LineString></Placemark>",
    )
    with pytest.raises(RouteError, match="not valid KML XML"):
        read_route_file(wrong)
    html = _write(tmp_path / "page.gpx", "<html><trk></trk><p></html>")
    with pytest.raises(RouteError, match="not valid GPX XML"):
        read_route_file(html)


def test_a_byte_order_mark_and_a_declaration_still_read(tmp_path: Path) -> None:
    path = tmp_path / "bom.gpx"
    path.write_bytes(
        b'\xef\xbb\xbf<?xml version="1.0" encoding="UTF-8"?>\n<gpx><trk><trkseg>'
        b'<trkpt lat="48.1" lon="11.5"/><trkpt lat="48.2" lon="11.5"/></trkseg></trk></gpx>'
    )
    assert read_route_file(path).lat.tolist() == [48.1, 48.2]
    broken = tmp_path / "broken.gpx"
    broken.write_bytes(b"\xef\xbb\xbf<gpx>\n<trk></gpx>")
    with pytest.raises(RouteError, match=r"mismatched tag: line 2, column 7"):
        read_route_file(broken)


def test_a_csv_error_anywhere_comes_before_a_wrong_row(tmp_path: Path) -> None:
    """As when every row was read before any was looked at."""
    limit = 131_072
    path = _write(tmp_path / "r.csv", f'lat,lon\n48.1,east\n48.2,11.6\n"{"x" * (limit + 1)}"\n')
    with pytest.raises(RouteError, match="not a readable CSV route"):
        read_route_file(path)
    no_header = _write(tmp_path / "h.csv", f'a,b\n1,2\n"{"x" * (limit + 1)}"\n')
    with pytest.raises(RouteError, match="not a readable CSV route"):
        read_route_file(no_header)


def test_csv_line_numbers_count_rows_with_something_in_them(tmp_path: Path) -> None:
    path = _write(tmp_path / "r.csv", "\ufefflat,lon\r\n\r\n , \r\n48.1,11.5\r\n\r\n48.2,east\r\n")
    with pytest.raises(RouteError, match=r"CSV line 3: lat/lon '48.2', 'east'"):
        read_route_file(path)


def test_csv_rows_split_on_newlines_only(tmp_path: Path) -> None:
    """A carriage return alone ends no row (the text was read by ``io.StringIO``)."""
    path = _write(tmp_path / "r.csv", "lat,lon\r48.1,11.5\r48.2,11.6\r")
    with pytest.raises(RouteError, match="not a readable CSV route"):
        read_route_file(path)


@pytest.mark.parametrize(
    "positions",
    [
        [[11.5, 48.1], [11.6, 48.2, 3], [11.7, 48.3, 4, 9]],
        [["11.5", 48.1], [11.6, "48.2", "3"], [11.7, 48.3, 4, 9]],
        [[11.5, 48.1, None], [11.6, 48.2, 3], [11.7, 48.3, 4.0]],
    ],
)
def test_geojson_positions_of_numbers_and_of_anything_else_read_alike(
    tmp_path: Path, positions: list[list[object]]
) -> None:
    """Plain numbers go to numpy a part at a time, anything else one position at a time."""
    doc = {"type": "LineString", "coordinates": positions}
    line = read_route_file(_write(tmp_path / "l.geojson", json.dumps(doc)))
    np.testing.assert_array_equal(line.lat, [48.1, 48.2, 48.3])
    np.testing.assert_array_equal(line.lon, [11.5, 11.6, 11.7])
    assert np.isnan(line.alt[0]) and line.alt[1:].tolist() == [3.0, 4.0]


def test_geojson_true_and_integers_read_as_float_does(tmp_path: Path) -> None:
    text = '{"type":"MultiLineString","coordinates":[[[1,1],[true,1]],[[1,true,-0.0]]]}'
    line = read_route_file(_write(tmp_path / "l.geojson", text))
    assert line.lon.tolist() == line.lat.tolist() == [1.0, 1.0, 1.0]
    assert np.signbit(line.alt[2]) and np.isnan(line.alt[:2]).all()


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("p.gpx", "<gpx><trk><trkseg>{}</trkseg></trk><rte>{}</rte></gpx>"),
        ("p.kml", "<kml><Placemark><LineString><coordinates>{}</coordinates></LineString>"),
        ("p.csv", "lat,lon\n{}"),
        ("p.geojson", '{{"type": "MultiLineString", "coordinates": [[{}], [{}]]}}'),
    ],
)
def test_the_point_cap_counts_every_point(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, text: str
) -> None:
    monkeypatch.setattr(routefile, "MAX_ROUTE_POINTS", 10)
    fmt = {
        ".gpx": ('<trkpt lat="48.{0}" lon="11"/>', '<rtept lat="48.{0}" lon="11"/>'),
        ".kml": ("11,48.{0} ", ""),
        ".csv": ("48.{0},11\n", ""),
        ".geojson": ("[11, 48.{0}],", ""),
    }[Path(name).suffix]
    first = "".join(fmt[0].format(i) for i in range(1, 10)).rstrip(",")
    second = "".join((fmt[1] or fmt[0]).format(i) for i in range(1, 8)).rstrip(",")
    if name.endswith(".kml"):
        body = text.format(first + second) + "</Placemark></kml>"
    elif name.endswith(".csv"):
        body = text.format(first + second)
    else:
        body = text.format(first, second)
    with pytest.raises(RouteError, match="route file has 16 points; more than 10 are refused"):
        read_route_file(_write(tmp_path / name, body))


def test_no_point_past_the_cap_is_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(routefile, "MAX_ROUTE_POINTS", 10)
    table = routefile._LineTable()
    for i in range(25):
        table.add_point(48.0 + i * 1e-4, 11.0, math.nan)
    table.end_line("")
    lines = table.lines()
    assert lines.counted == 25 and lines.points.shape == (10, 3)
