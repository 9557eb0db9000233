"""Read a mission route from GeoJSON, GPX, KML or CSV into a :class:`Route` in the session's ENU
frame.

GPX and KML are parsed by defusedxml with DTDs and entities forbidden at the parser (a text
filter for '<!DOCTYPE' was bypassed by UTF-16 without a byte-order mark), in UTF-8 only, and a
route file's cost is bounded: bytes, points, XML elements and nesting.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
import re
import stat
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimator.errors import RouteError, RouteLineError
from estimator.io.routeformats import ROUTE_SUFFIXES_TEXT, route_format
from estimator.nav.earth import great_circle_m
from estimator.nav.frames import LocalFrame
from estimator.route import Route

F64 = NDArray[np.float64]

MAX_ROUTE_BYTES = 50_000_000
"""Route files are read whole; a larger file is refused before it is read (a 1000 km route at
one vertex per metre is about 40 MB of GeoJSON)."""
MAX_ROUTE_POINTS = 2_000_000
"""Points in all the lines of a route file together (2000 km at one vertex per metre)."""
MAX_XML_DEPTH = 64
"""GPX and KML nest a few levels (KML folders a few more)."""
MAX_XML_ELEMENTS = 4_000_000
"""Elements of a GPX or KML file: each costs memory in the parsed tree."""
MAX_ROUTE_HEIGHT_M = 10_000.0
"""|height| of a route point, m: roads lie between the Dead Sea's shore (-0.43 km) and Umling La
(5.8 km), and ellipsoidal heights differ from sea level by at most about 0.1 km. A height
beyond this is another unit (centimetres, millimetres) or corrupt; 1e300 overflowed the frame's
conversion (a numpy warning, then a route placed nowhere)."""
MAX_ROUTE_SEGMENT_M = 50_000.0
"""Distance between consecutive points of a route, m. A road-level map has a vertex at every
bend (routes built by :mod:`estimator.io.routebuild` every 25 m), so a straight segment of tens
of km is already rare and one over 50 km joins places no road joins directly: MultiLineString
parts from different regions, a stray point, a route across continents. It would be taken for a
road (matched against, counted in the route's length), so it is refused, not joined silently.
Tens of km, not a few: a hand-drawn motorway with a click every 20 km is still a usable route."""
MAX_LISTED_LINES = 12
"""Lines named in a message; the rest are counted."""


@dataclass(frozen=True)
class RouteLine:
    """One route polyline as read from the file, in geodetic degrees (height NaN if absent)."""

    lat: F64
    lon: F64
    alt: F64
    name: str
    source: str


@dataclass(frozen=True)
class _Candidate:
    name: str
    points: list[tuple[float, float, float]]
    part_starts: tuple[int, ...] = ()
    """index of the first point of each part after the first (a MultiLineString's lines, a
    track's segments, a placemark's LineStrings), which the file's line joins end to end"""
    part_kind: str = "part"
    """what the file calls a part, for messages"""


def read_route_file(path: str | Path, *, feature: str | int | None = None) -> RouteLine:
    """The route polyline of a file. With several lines in the file (features, tracks,
    placemarks), ``feature`` picks one by name or index (:func:`choose_line`); without it
    that is a :class:`RouteLineError` listing them."""
    p = Path(path)
    return _to_line(p, _choose(p, _candidates(p), feature))


def read_route_lines(path: str | Path) -> tuple[RouteLine, ...]:
    """Every line of a route file (to list them, e.g. in ``routefuse info``)."""
    p = Path(path)
    return tuple(_to_line(p, c) for c in _candidates(p))


def _candidates(p: Path) -> list[_Candidate]:
    fmt = route_format(p)
    if fmt is None:
        raise RouteError(
            p, f"unknown route format '{p.suffix or p.name}': expected {ROUTE_SUFFIXES_TEXT}"
        )
    text = _read_text(p)
    cands = {
        "geojson": _geojson_lines,
        "gpx": _gpx_lines,
        "kml": _kml_lines,
        "csv": _csv_lines,
    }[fmt](p, text)
    total = sum(len(c.points) for c in cands)
    if total > MAX_ROUTE_POINTS:
        raise RouteError(
            p, f"route file has {total} points; more than {MAX_ROUTE_POINTS} are refused"
        )
    return cands


def _to_line(p: Path, chosen: _Candidate) -> RouteLine:
    pts = np.array(chosen.points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 2:
        raise RouteError(p, f"route has {len(pts)} point{'s' * (len(pts) != 1)}; need at least 2")
    lat, lon, alt = pts[:, 0], pts[:, 1], pts[:, 2]
    bad = ~(np.isfinite(lat) & np.isfinite(lon))
    if bad.any():
        raise RouteError(
            p, f"route point {int(np.flatnonzero(bad)[0])} has a non-finite coordinate"
        )
    if np.any(np.abs(lat) > 90.0) or np.any(np.abs(lon) > 180.0):
        i = int(np.flatnonzero((np.abs(lat) > 90.0) | (np.abs(lon) > 180.0))[0])
        raise RouteError(
            p,
            f"route point {i} is out of range (lat {lat[i]:g}, lon {lon[i]:g}); "
            "expected degrees with |lat| <= 90 and |lon| <= 180",
        )
    wild = ~np.isnan(alt) & ~(np.abs(alt) <= MAX_ROUTE_HEIGHT_M)
    if wild.any():
        i = int(np.flatnonzero(wild)[0])
        raise RouteError(
            p,
            f"route point {i} has a height of {alt[i]:g} m; a road lies within "
            f"{MAX_ROUTE_HEIGHT_M / 1000:g} km of sea level (heights in another unit?)",
        )
    _check_segments(p, chosen, lat, lon)
    return RouteLine(lat, lon, alt, chosen.name or p.stem, str(p))


def _check_segments(p: Path, chosen: _Candidate, lat: F64, lon: F64) -> None:
    """A one-line :class:`RouteError` at the first segment longer than
    :data:`MAX_ROUTE_SEGMENT_M`, naming its points, where they are and, where the file joins
    two of its parts there, which part begins."""
    length = great_circle_m(lat[:-1], lon[:-1], lat[1:], lon[1:])
    too_long = np.flatnonzero(length > MAX_ROUTE_SEGMENT_M)
    if not len(too_long):
        return
    i = int(too_long[0])
    joined = ""
    if i + 1 in chosen.part_starts:
        k = chosen.part_starts.index(i + 1) + 1
        joined = f" (the join of {chosen.part_kind}s {k - 1} and {k})"
    raise RouteError(
        p,
        f"route points {i} and {i + 1} are {length[i] / 1000:.1f} km apart{joined}, from "
        f"{lat[i]:.5f}, {lon[i]:.5f} to {lat[i + 1]:.5f}, {lon[i + 1]:.5f} (lat, lon); a road "
        f"route has points at most {MAX_ROUTE_SEGMENT_M / 1000:g} km apart: two places joined?",
    )


def load_route(path: str | Path, frame: LocalFrame, *, feature: str | int | None = None) -> Route:
    """A route file as a :class:`Route` in ``frame``'s EN plane."""
    return route_in_frame(read_route_file(path, feature=feature), frame)


def route_in_frame(line: RouteLine, frame: LocalFrame) -> Route:
    """Points without a height are placed at the frame origin's height, so a missing height
    does not tilt them off the plane."""
    h = np.where(np.isfinite(line.alt), line.alt, frame.h0)
    enu = frame.to_enu(line.lat, line.lon, h)
    if not np.all(np.isfinite(enu)):
        raise RouteError(line.source, "route cannot be placed in the local frame (non-finite ENU)")
    return Route(enu[:, :2], name=line.name, source=line.source)


# ---------------------------------------------------------------------------------------------


def route_file_stat(p: Path) -> os.stat_result:
    """``p``'s status once it exists and is not a folder; else a one-line :class:`RouteError`
    (checked before its suffix is looked up, so a folder is not "an unknown route format")."""
    try:
        info = p.stat()
    except FileNotFoundError:
        raise RouteError(p, "no such file") from None
    except OSError as exc:
        raise RouteError(p, f"cannot read the file ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise RouteError(p, "is a folder, expected a route file")
    return info


def _read_text(p: Path) -> str:
    info = route_file_stat(p)
    if not stat.S_ISREG(info.st_mode):
        raise RouteError(p, "not a regular file, expected a route file")
    size = info.st_size
    if size > MAX_ROUTE_BYTES:
        raise RouteError(
            p,
            f"file is {size / 1e6:.1f} MB; route files over {MAX_ROUTE_BYTES / 1e6:g} MB are "
            "refused (a route is a polyline of at most a few MB)",
        )
    try:
        text = p.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RouteError(p, f"not a UTF-8 text file (byte {exc.start})") from None
    except OSError as exc:
        raise RouteError(p, f"cannot read the file ({exc.strerror or exc})") from None
    if not text.strip():
        raise RouteError(p, "file is empty")
    return text


def _choose(p: Path, cands: list[_Candidate], feature: str | int | None) -> _Candidate:
    if not cands:
        raise RouteError(p, "no line geometry found (need a LineString, track or route)")
    return cands[choose_line(p, tuple(c.name for c in cands), feature)]


def choose_line(path: str | Path, names: tuple[str, ...], feature: str | int | None) -> int:
    """The index of the line ``feature`` picks among a route file's lines ``names``: an ``int``
    is an index; text is a name, else an index (``--route-feature``'s NAME_OR_INDEX). Without
    ``feature`` the only line; with several, or a ``feature`` naming none, a one-line
    :class:`RouteLineError` listing them (saying where to choose on the command line: a caller
    with other controls re-words it, :meth:`RouteLineError.choose`)."""
    if feature is None:
        if len(names) > 1:
            raise RouteLineError(path, f"the file has {_listing(names)}", lines=names)
        return 0
    if isinstance(feature, int):
        if -len(names) <= feature < len(names):
            return feature % len(names)
        raise RouteLineError(
            path,
            f"no line numbered {feature}; the file has {_listing(names)}",
            lines=names,
        )
    key = str(feature).strip()
    by_name = [i for i, name in enumerate(names) if name == key]
    if len(by_name) == 1:
        return by_name[0]
    if key.lstrip("-").isdigit() and -len(names) <= int(key) < len(names):
        return int(key) % len(names)
    what = "several" if by_name else "no"
    raise RouteLineError(
        path,
        f"{what} line feature{'s' if by_name else ''} named or numbered {_short(key)!r}; "
        f"the file has {_listing(names)}",
        lines=names,
    )


def route_line_names(path: str | Path) -> tuple[str, ...]:
    """The names of a route file's lines, in order (what :func:`choose_line` chooses among;
    a line without a name in the file has its place's, e.g. 'feature 1', or '')."""
    return tuple(c.name for c in _candidates(Path(path)))


def line_label(index: int, name: str) -> str:
    """How a route file's line is named to a person: its index and (shortened) name."""
    return f"{index}: {_short(name) or '(unnamed)'}"


def _listing(names: tuple[str, ...]) -> str:
    shown = ", ".join(line_label(i, n) for i, n in enumerate(names[:MAX_LISTED_LINES]))
    more = f", ... {len(names) - MAX_LISTED_LINES} more" if len(names) > MAX_LISTED_LINES else ""
    return f"{len(names)} line{'s' * (len(names) != 1)} ({shown}{more})"


def _short(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _num(value: Any) -> float:
    """A coordinate as a float: NaN when it is not a number, and an integer too large for a
    float (JSON's 400-digit integers) infinite, as a float would read it, so that it is refused
    as a non-finite coordinate."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf
    except (TypeError, ValueError):
        return float("nan")


# --- GeoJSON ---------------------------------------------------------------------------------


def _geojson_lines(p: Path, text: str) -> list[_Candidate]:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RouteError(p, f"not valid JSON (line {exc.lineno}: {exc.msg})") from None
    except RecursionError:
        raise RouteError(p, "JSON nested too deeply to be a route") from None
    except ValueError:  # an integer of more digits than Python converts
        raise RouteError(
            p,
            f"not valid JSON for a route: an integer of more than "
            f"{sys.get_int_max_str_digits()} digits",
        ) from None
    if not isinstance(doc, dict) or "type" not in doc:
        raise RouteError(p, "not GeoJSON (no 'type' member)")
    kind = doc["type"]
    if kind == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list):
            raise RouteError(p, "FeatureCollection without a 'features' list")
        out = []
        for i, f in enumerate(feats):
            line = _geojson_geometry(p, (f or {}).get("geometry") if isinstance(f, dict) else None)
            if line is not None:
                props = f.get("properties") or {}
                name = props.get("name") if isinstance(props, dict) else None
                out.append(
                    dataclasses.replace(
                        line, name=str(name) if name is not None else f"feature {i}"
                    )
                )
        return out
    if kind == "Feature":
        line = _geojson_geometry(p, doc.get("geometry"))
        props = doc.get("properties") or {}
        name = str(props.get("name", "")) if isinstance(props, dict) else ""
        return [] if line is None else [dataclasses.replace(line, name=name)]
    line = _geojson_geometry(p, doc)
    return [] if line is None else [line]


def _geojson_geometry(p: Path, geom: Any) -> _Candidate | None:
    """The points of a LineString or MultiLineString (its lines joined end to end), unnamed."""
    if not isinstance(geom, dict):
        return None
    kind, coords = geom.get("type"), geom.get("coordinates")
    parts: Any
    if kind == "LineString":
        parts = [coords]
    elif kind == "MultiLineString":
        parts = coords
    else:
        return None
    if not isinstance(parts, list):
        raise RouteError(p, f"{kind} without a coordinate list")
    points: list[tuple[float, float, float]] = []
    starts: list[int] = []
    for part in parts:
        if not isinstance(part, list):
            raise RouteError(p, f"{kind} coordinates are not a list of positions")
        if points:
            starts.append(len(points))
        for pos in part:
            if not isinstance(pos, list | tuple) or len(pos) < 2:
                raise RouteError(p, f"{kind} position {pos!r} is not [lon, lat(, alt)]")
            alt = _num(pos[2]) if len(pos) > 2 else float("nan")
            points.append((_num(pos[1]), _num(pos[0]), alt))
    return _Candidate("", points, tuple(starts), f"{kind} line")


# --- XML: GPX and KML ------------------------------------------------------------------------

_XML_ENCODING = re.compile(r"""^\s*<\?xml[^>]*?\bencoding\s*=\s*["']([^"']*)["']""")


def _parse_xml(p: Path, text: str, kind: str) -> ET.Element:
    from defusedxml import DefusedXmlException
    from defusedxml.ElementTree import iterparse

    if "\0" in text:
        raise RouteError(p, f"{kind} file is not UTF-8 (it holds NUL bytes: UTF-16?)")
    declared = _XML_ENCODING.match(text)
    if declared and declared.group(1).strip().lower().replace("_", "-") not in ("utf-8", "utf8"):
        raise RouteError(
            p, f"{kind} file declares encoding {_short(declared.group(1))!r}; only UTF-8 is read"
        )
    depth = elements = 0
    root: ET.Element | None = None
    try:
        for event, el in iterparse(
            io.BytesIO(text.encode("utf-8")), events=("start", "end"), forbid_dtd=True
        ):
            if event == "end":
                depth -= 1
                continue
            root = el if root is None else root
            depth, elements = depth + 1, elements + 1
            if depth > MAX_XML_DEPTH:
                raise RouteError(p, f"{kind} elements nested over {MAX_XML_DEPTH} deep; refused")
            if elements > MAX_XML_ELEMENTS:
                raise RouteError(p, f"{kind} file has over {MAX_XML_ELEMENTS} elements; refused")
    except DefusedXmlException as exc:
        raise RouteError(
            p, f"{kind} file declares a DOCTYPE or ENTITY; refused for safety ({exc})"
        ) from None
    except ET.ParseError as exc:
        raise RouteError(p, f"not valid {kind} XML ({_short(str(exc), 120)})") from None
    if root is None:
        raise RouteError(p, f"not valid {kind} XML (no element)")
    return root


def _local(tag: Any) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _children(el: ET.Element, name: str) -> list[ET.Element]:
    return [c for c in el if _local(c.tag) == name]


def _child_text(el: ET.Element, name: str) -> str | None:
    found = _children(el, name)
    return found[0].text.strip() if found and found[0].text else None


def _gpx_lines(p: Path, text: str) -> list[_Candidate]:
    root = _parse_xml(p, text, "GPX")
    if _local(root.tag) != "gpx":
        raise RouteError(p, f"not a GPX file (root element <{_local(root.tag)}>)")

    def point(el: ET.Element) -> tuple[float, float, float]:
        ele = _child_text(el, "ele")
        return (_num(el.get("lat")), _num(el.get("lon")), _num(ele) if ele else float("nan"))

    out = []
    for i, trk in enumerate(_children(root, "trk")):
        pts: list[tuple[float, float, float]] = []
        starts: list[int] = []
        for seg in _children(trk, "trkseg"):
            if pts:
                starts.append(len(pts))
            pts.extend(point(pt) for pt in _children(seg, "trkpt"))
        name = _child_text(trk, "name") or f"track {i}"
        out.append(_Candidate(name, pts, tuple(starts), "trkseg"))
    for i, rte in enumerate(_children(root, "rte")):
        pts = [point(pt) for pt in _children(rte, "rtept")]
        out.append(_Candidate(_child_text(rte, "name") or f"route {i}", pts))
    return out


def _kml_lines(p: Path, text: str) -> list[_Candidate]:
    root = _parse_xml(p, text, "KML")
    if _local(root.tag) != "kml":
        raise RouteError(p, f"not a KML file (root element <{_local(root.tag)}>)")
    out = []
    for i, mark in enumerate(el for el in root.iter() if _local(el.tag) == "Placemark"):
        lines = [el for el in mark.iter() if _local(el.tag) == "LineString"]
        pts: list[tuple[float, float, float]] = []
        starts: list[int] = []
        for line in lines:
            if pts:
                starts.append(len(pts))
            for tup in (_child_text(line, "coordinates") or "").split():
                v = tup.split(",")
                if len(v) < 2:
                    raise RouteError(p, f"KML coordinate {tup!r} is not lon,lat[,alt]")
                pts.append((_num(v[1]), _num(v[0]), _num(v[2]) if len(v) > 2 else float("nan")))
        if lines:
            name = _child_text(mark, "name") or f"placemark {i}"
            out.append(_Candidate(name, pts, tuple(starts), "LineString"))
    return out


# --- CSV -------------------------------------------------------------------------------------

_LAT = ("lat", "latitude")
_LON = ("lon", "lng", "long", "longitude")
_ALT = ("alt", "altitude", "ele", "elevation", "height", "h")


def _csv_lines(p: Path, text: str) -> list[_Candidate]:
    try:
        dialect = csv.Sniffer().sniff(text[:4096], delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    try:
        rows = [r for r in csv.reader(io.StringIO(text), dialect) if any(c.strip() for c in r)]
    except csv.Error as exc:
        raise RouteError(p, f"not a readable CSV route ({_short(str(exc), 120)})") from None
    if not rows:
        raise RouteError(p, "CSV has no header and no rows (only separators or quotes)")
    header = [c.strip().lower() for c in rows[0]]

    def column(names: tuple[str, ...]) -> int | None:
        return next((header.index(n) for n in names if n in header), None)

    i_lat, i_lon, i_alt = column(_LAT), column(_LON), column(_ALT)
    if i_lat is None or i_lon is None:
        raise RouteError(
            p,
            f"CSV header {_short(repr(rows[0]))} has no lat/lon columns; expected a header "
            "with lat,lon[,alt] or latitude,longitude",
        )
    pts = []
    for k, row in enumerate(rows[1:], start=2):
        if len(row) <= max(i_lat, i_lon):
            raise RouteError(p, f"CSV line {k} has {len(row)} fields, expected {len(header)}")
        alt = _num(row[i_alt]) if i_alt is not None and i_alt < len(row) else float("nan")
        lat, lon = _num(row[i_lat]), _num(row[i_lon])
        if not (np.isfinite(lat) and np.isfinite(lon)):
            raise RouteError(
                p, f"CSV line {k}: lat/lon {row[i_lat]!r}, {row[i_lon]!r} are not finite numbers"
            )
        pts.append((lat, lon, alt))
    return [_Candidate("", pts)]
