"""GPX and KML are parsed by a parser that forbids DTDs and entities (defusedxml), whatever the
file's encoding, and a route file's cost is bounded (bytes, points, nesting, message length)."""

from __future__ import annotations

from pathlib import Path

import pytest

from estimator.errors import RouteError
from estimator.io import routefile
from estimator.io.routefile import read_route_file

LAUGHS = (
    '<?xml version="1.0" encoding="UTF-16"?>\n'
    '<!DOCTYPE kml [<!ENTITY a "0,0 1,1 ">'
    '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
    '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]>\n'
    "<kml><Placemark><LineString><coordinates>&c;</coordinates></LineString></Placemark></kml>\n"
)


def _kml(tmp_path: Path, body: str, *, encoding: str = "utf-8") -> Path:
    path = tmp_path / "route.kml"
    path.write_bytes(body.encode(encoding))
    return path


@pytest.mark.parametrize("encoding", ["utf-8", "utf-16-le", "utf-16-be"])
def test_entities_are_refused_in_any_encoding(tmp_path: Path, encoding: str) -> None:
    with pytest.raises(RouteError, match=r"DOCTYPE|UTF-8") as err:
        read_route_file(_kml(tmp_path, LAUGHS, encoding=encoding))
    assert "\n" not in str(err.value)


def test_a_declared_encoding_other_than_utf8_is_refused(tmp_path: Path) -> None:
    body = (
        '<?xml version="1.0" encoding="ISO-8859-1"?><kml><Placemark><LineString>'
        "<coordinates>0,0 1,1</coordinates></LineString></Placemark></kml>"
    )
    with pytest.raises(RouteError, match="UTF-8"):
        read_route_file(_kml(tmp_path, body))


def test_deep_nesting_is_refused(tmp_path: Path) -> None:
    body = "<kml>" + "<Folder>" * 5000 + "</Folder>" * 5000 + "</kml>"
    with pytest.raises(RouteError, match="nested"):
        read_route_file(_kml(tmp_path, body))


def test_too_many_points_are_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(routefile, "MAX_ROUTE_POINTS", 10)
    coords = " ".join(f"{i * 1e-4},0" for i in range(11))
    line = f"<LineString><coordinates>{coords}</coordinates></LineString>"
    body = f"<kml><Placemark>{line}</Placemark></kml>"
    with pytest.raises(RouteError, match="points"):
        read_route_file(_kml(tmp_path, body))


def test_many_placemarks_make_a_short_message(tmp_path: Path) -> None:
    mark = (
        "<Placemark><name>p{}</name>"
        "<LineString><coordinates>0,0 1,1</coordinates></LineString></Placemark>"
    )
    body = "<kml>" + "".join(mark.format(i) for i in range(5000)) + "</kml>"
    with pytest.raises(RouteError, match="5000 lines") as err:
        read_route_file(_kml(tmp_path, body))
    assert len(str(err.value)) < 1000


def test_a_plain_kml_still_reads(tmp_path: Path) -> None:
    body = (
        '<?xml version="1.0" encoding="UTF-8"?><kml xmlns="http://www.opengis.net/kml/2.2">'
        "<Placemark><LineString><coordinates>7.42,43.73 7.43,43.74,10</coordinates>"
        "</LineString></Placemark></kml>"
    )
    line = read_route_file(_kml(tmp_path, body))
    assert line.lat.tolist() == [43.73, 43.74]
