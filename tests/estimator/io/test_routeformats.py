"""Route file names: the format a suffix says, and the route that belongs to a log."""

from __future__ import annotations

from pathlib import Path

from estimator.io import ROUTE_FORMATS, ROUTE_FORMATS_TEXT, route_beside, route_format


def test_formats_by_suffix() -> None:
    assert route_format("a/drive.GeoJSON") == "geojson" and route_format("x.json") == "geojson"
    assert route_format("x.gpx") == "gpx" and route_format("x.kml") == "kml"
    assert route_format("x.csv") == "csv" and route_format("x.shp") is None
    assert set(ROUTE_FORMATS.values()) == {"geojson", "gpx", "kml", "csv"}
    assert ROUTE_FORMATS_TEXT == "GeoJSON, GPX, KML or CSV"


def test_route_beside_a_log_prefers_the_route_infix(tmp_path: Path) -> None:
    log = tmp_path / "drive.mcap"
    assert route_beside(log) is None
    (tmp_path / "drive.csv").write_text("")  # a bare .csv is not taken for the route
    assert route_beside(log) is None
    (tmp_path / "drive.gpx").write_text("")
    assert route_beside(log) == tmp_path / "drive.gpx"
    (tmp_path / "drive.route.csv").write_text("")
    assert route_beside(log) == tmp_path / "drive.route.csv"
    (tmp_path / "drive.route.geojson").write_text("")
    assert route_beside(tmp_path / "drive.tar.mcap") == tmp_path / "drive.route.geojson"
