"""Read a mission route from GeoJSON, GPX, KML or CSV into a :class:`Route` in the session's ENU
frame.

GPX and KML are parsed by defusedxml with DTDs and entities forbidden at the parser (a text
filter for '<!DOCTYPE' was bypassed by UTF-16 without a byte-order mark), in UTF-8 only, and a
route file's cost is bounded: bytes, points, XML elements and nesting.

A file's memory is bounded too (a file at the caps took 0.7-1.1 GB when its text, a whole
element tree and a Python tuple per point were held at once): GPX and KML are parsed element by
element (only the open elements kept), CSV row by row, GeoJSON's positions converted a part at a
time; the points of all the lines go into one array, where none is kept past
:data:`MAX_ROUTE_POINTS` (they are still counted, for the message). Messages and their order
are those of reading the whole file first: a wrong row or coordinate is reported after the
file's syntax is checked to its end.
"""

from __future__ import annotations

import codecs
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
from array import array
from collections.abc import Iterator, Sequence
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
"""Elements of a GPX or KML file: each costs parsing time (the parser keeps only the open
elements)."""
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
_DECODE_BYTES = 1 << 20
"""A route file's bytes are checked as UTF-8 this many at a time (its whole text was another
copy of the file, four for one character beyond U+FFFF); the XML declaration is looked for in
the first of them."""
GEOJSON_POSITIONS_AT_ONCE = 65_536
"""GeoJSON positions converted to numbers together (then dropped from the parsed document): a
whole LineString at once was 75 MB more at the peak, for 2 M positions."""
CSV_SNIFF_CHARS = 4096
"""Characters at the start of a CSV route from which its delimiter is guessed."""


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
    points: F64
    """(n, 3): lat, lon, height"""
    part_starts: tuple[int, ...] = ()
    """index of the first point of each part after the first (a MultiLineString's lines, a
    track's segments, a placemark's LineStrings), which the file's line joins end to end"""
    part_kind: str = "part"
    """what the file calls a part, for messages"""


@dataclass(frozen=True)
class _Lines:
    """The lines of a route file: all their points in one array, line ``i`` its rows
    ``bounds[i]:bounds[i + 1]`` (one array, not one per line: a file of 800 k short tracks
    made 800 k Python lists of tuples)."""

    names: tuple[str, ...]
    points: F64
    """(n, 3): lat, lon, height"""
    bounds: NDArray[np.int64]
    joins: dict[int, tuple[tuple[int, ...], str]]
    """line index -> its part starts and what the file calls a part (lines of several parts)"""
    counted: int
    """points in the file's lines, also those past :data:`MAX_ROUTE_POINTS` (not kept)"""

    def line(self, i: int) -> _Candidate:
        starts, kind = self.joins.get(i, ((), "part"))
        points = self.points[self.bounds[i] : self.bounds[i + 1]]
        return _Candidate(self.names[i], points, starts, kind)


class _LineTable:
    """The lines of a route file as its parser finds them, their points appended to one buffer;
    every point is counted, none kept past :data:`MAX_ROUTE_POINTS` (the file is refused then,
    with its count: :func:`_candidates`)."""

    def __init__(self) -> None:
        self.counted = 0
        self.in_line = 0
        """points of the line being read"""
        self._values = array("d")
        self._names: list[str] = []
        self._bounds = array("q", [0])
        self._order = array("q")
        self._joins: dict[int, tuple[tuple[int, ...], str]] = {}

    def add_point(self, lat: float, lon: float, alt: float) -> None:
        self.counted += 1
        self.in_line += 1
        if self.counted <= MAX_ROUTE_POINTS:
            self._values.extend((lat, lon, alt))

    def add_rows(self, rows: F64) -> None:
        """Points as (n, 3) lat, lon, height."""
        self.counted += len(rows)
        self.in_line += len(rows)
        if self.counted <= MAX_ROUTE_POINTS:
            self._values.frombytes(np.ascontiguousarray(rows, dtype=np.float64).data.cast("B"))

    def add_points(self, values: array[float], count: int) -> None:
        """``count`` points, of which ``values`` holds those kept (lat, lon, height each)."""
        self.counted += count
        self.in_line += count
        if self.counted <= MAX_ROUTE_POINTS:
            self._values.extend(values)

    def end_line(
        self,
        name: str,
        part_starts: Sequence[int] = (),
        part_kind: str = "part",
        order: int | None = None,
    ) -> None:
        """The line read since the last one ended; ``order`` ranks it among the file's lines
        where the parser meets them out of order (the file's order by default)."""
        if part_starts:
            self._joins[len(self._names)] = (tuple(part_starts), part_kind)
        self._names.append(name)
        self._bounds.append(len(self._values) // 3)
        self._order.append(len(self._order) if order is None else order)
        self.in_line = 0

    def lines(self) -> _Lines:
        points = np.frombuffer(self._values, dtype=np.float64).reshape(-1, 3)
        bounds = np.frombuffer(self._bounds, dtype=np.int64)
        names, joins = tuple(self._names), self._joins
        order = np.frombuffer(self._order, dtype=np.int64)
        if np.any(order[1:] < order[:-1]):
            rank = np.argsort(order, kind="stable")
            sizes = np.diff(bounds)[rank]
            new_bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
            shift = np.repeat(bounds[:-1][rank] - new_bounds[:-1], sizes)
            points = points[np.arange(len(shift), dtype=np.int64) + shift]
            bounds = new_bounds
            names = tuple(names[i] for i in rank)
            joins = {k: joins[int(i)] for k, i in enumerate(rank) if int(i) in joins}
        return _Lines(names, points, bounds, joins, self.counted)


def read_route_file(path: str | Path, *, feature: str | int | None = None) -> RouteLine:
    """The route polyline of a file. With several lines in the file (features, tracks,
    placemarks), ``feature`` picks one by name or index (:func:`choose_line`); without it
    that is a :class:`RouteLineError` listing them."""
    p = Path(path)
    lines = _candidates(p)
    chosen = lines.line(_choose(p, lines.names, feature))
    if len(chosen.points) < len(lines.points):
        chosen = dataclasses.replace(chosen, points=chosen.points.copy())
    return _to_line(p, chosen)


def read_route_lines(path: str | Path) -> tuple[RouteLine, ...]:
    """Every line of a route file (to list them, e.g. in ``routefuse info``)."""
    p = Path(path)
    lines = _candidates(p)
    return tuple(_to_line(p, lines.line(i)) for i in range(len(lines.names)))


def _candidates(p: Path) -> _Lines:
    fmt = route_format(p)
    if fmt is None:
        raise RouteError(
            p, f"unknown route format '{p.suffix or p.name}': expected {ROUTE_SUFFIXES_TEXT}"
        )
    lines = {
        "geojson": _geojson_lines,
        "gpx": _gpx_lines,
        "kml": _kml_lines,
        "csv": _csv_lines,
    }[fmt](p)
    if lines.counted > MAX_ROUTE_POINTS:
        raise RouteError(
            p, f"route file has {lines.counted} points; more than {MAX_ROUTE_POINTS} are refused"
        )
    return lines


def _to_line(p: Path, chosen: _Candidate) -> RouteLine:
    pts = chosen.points
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


def _read_checked(p: Path) -> bytes:
    """The bytes of a route file that exists, is not too large, is UTF-8 (a byte-order mark
    allowed) and is not blank; else a one-line :class:`RouteError`. The text is decoded piece
    by piece to check it, not kept: a parser reads the bytes."""
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
        data = p.read_bytes()
    except OSError as exc:
        raise RouteError(p, f"cannot read the file ({exc.strerror or exc})") from None
    decoder = codecs.getincrementaldecoder("utf-8-sig")()
    blank = True
    try:
        for at in range(0, len(data) + 1, _DECODE_BYTES):
            piece = decoder.decode(
                data[at : at + _DECODE_BYTES], final=at + _DECODE_BYTES > len(data)
            )
            blank = blank and (not piece or piece.isspace())
    except UnicodeDecodeError:
        try:
            data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise RouteError(p, f"not a UTF-8 text file (byte {exc.start})") from None
        raise
    if blank:
        raise RouteError(p, "file is empty")
    return data


def _text_start(data: bytes) -> str:
    """The start of a checked route file's text: its first :data:`_DECODE_BYTES` bytes."""
    return codecs.getincrementaldecoder("utf-8-sig")().decode(data[:_DECODE_BYTES])


def _choose(p: Path, names: tuple[str, ...], feature: str | int | None) -> int:
    if not names:
        raise RouteError(p, "no line geometry found (need a LineString, track or route)")
    return choose_line(p, names, feature)


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
    return _candidates(Path(path)).names


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


def _geojson_lines(p: Path) -> _Lines:
    text = _read_checked(p).decode("utf-8-sig")
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
    del text
    if not isinstance(doc, dict) or "type" not in doc:
        raise RouteError(p, "not GeoJSON (no 'type' member)")
    table = _LineTable()
    kind = doc["type"]
    if kind == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list):
            raise RouteError(p, "FeatureCollection without a 'features' list")
        for i, f in enumerate(feats):
            geom = (f or {}).get("geometry") if isinstance(f, dict) else None
            joins = _geojson_geometry(p, geom, table)
            if joins is not None:
                props = f.get("properties") or {}
                name = props.get("name") if isinstance(props, dict) else None
                table.end_line(str(name) if name is not None else f"feature {i}", *joins)
    elif kind == "Feature":
        joins = _geojson_geometry(p, doc.get("geometry"), table)
        if joins is not None:
            props = doc.get("properties") or {}
            table.end_line(str(props.get("name", "")) if isinstance(props, dict) else "", *joins)
    elif (joins := _geojson_geometry(p, doc, table)) is not None:
        table.end_line("", *joins)
    return table.lines()


def _geojson_geometry(p: Path, geom: Any, table: _LineTable) -> tuple[tuple[int, ...], str] | None:
    """The points of a LineString or MultiLineString (its lines joined end to end) added to
    ``table`` as a line left open, and its part starts and what a part is; None for another
    geometry. Positions are dropped from the document as they are read."""
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
    starts: list[int] = []
    nan = float("nan")
    add_point = table.add_point
    for part in parts:
        if not isinstance(part, list):
            raise RouteError(p, f"{kind} coordinates are not a list of positions")
        if table.in_line:
            starts.append(table.in_line)
        while part:
            positions = part[:GEOJSON_POSITIONS_AT_ONCE]
            numbers = _number_rows(positions)
            if numbers is not None:
                table.add_rows(numbers)
            for pos in positions if numbers is None else ():
                if not isinstance(pos, list | tuple) or len(pos) < 2:
                    raise RouteError(p, f"{kind} position {pos!r} is not [lon, lat(, alt)]")
                add_point(_num(pos[1]), _num(pos[0]), _num(pos[2]) if len(pos) > 2 else nan)
            del part[:GEOJSON_POSITIONS_AT_ONCE]
    return tuple(starts), f"{kind} line"


def _number_rows(positions: list[Any]) -> F64 | None:
    """(n, 3) lat, lon, height of GeoJSON positions that are all plain numbers, 2 or more each
    (numpy converts them as :func:`_num` does); None for anything else (strings, nulls,
    integers beyond 64 bits, positions of different lengths), which is read one by one."""
    try:
        numbers = np.array(positions)
    except (ValueError, TypeError, OverflowError):
        return None
    if numbers.ndim != 2 or numbers.shape[1] < 2 or numbers.dtype.kind not in "biuf":
        return None
    rows = np.full((len(numbers), 3), np.nan)
    rows[:, 0], rows[:, 1] = numbers[:, 1], numbers[:, 0]
    if numbers.shape[1] > 2:
        rows[:, 2] = numbers[:, 2]
    return rows


# --- XML: GPX and KML ------------------------------------------------------------------------

_XML_ENCODING = re.compile(r"""^\s*<\?xml[^>]*?\bencoding\s*=\s*["']([^"']*)["']""")


def _xml_events(p: Path, data: bytes, kind: str) -> Iterator[tuple[str, ET.Element, list[str]]]:
    """The start and end events of a GPX or KML file's elements, each with the local names of
    the elements open there (its own last), parsed as they come. An element is dropped from
    the tree after its end event, so the tree holds only the open elements: a handler reads an
    element (its text, attributes) at its end. Bounded by :data:`MAX_XML_DEPTH` and
    :data:`MAX_XML_ELEMENTS`; a DOCTYPE or ENTITY is refused by defusedxml."""
    from defusedxml import DefusedXmlException
    from defusedxml.ElementTree import iterparse

    if b"\0" in data:
        raise RouteError(p, f"{kind} file is not UTF-8 (it holds NUL bytes: UTF-16?)")
    declared = _XML_ENCODING.match(_text_start(data))
    if declared and declared.group(1).strip().lower().replace("_", "-") not in ("utf-8", "utf8"):
        raise RouteError(
            p, f"{kind} file declares encoding {_short(declared.group(1))!r}; only UTF-8 is read"
        )
    source = io.BytesIO(data)
    if data.startswith(codecs.BOM_UTF8):
        source.seek(len(codecs.BOM_UTF8))
    open_elements: list[ET.Element] = []
    names: list[str] = []
    elements = 0
    try:
        for event, el in iterparse(source, events=("start", "end"), forbid_dtd=True):
            if event == "end":
                yield event, el, names
                open_elements.pop()
                names.pop()
                if open_elements:
                    open_elements[-1].remove(el)
                continue
            open_elements.append(el)
            names.append(_local(el.tag))
            elements += 1
            if len(open_elements) > MAX_XML_DEPTH:
                raise RouteError(p, f"{kind} elements nested over {MAX_XML_DEPTH} deep; refused")
            if elements > MAX_XML_ELEMENTS:
                raise RouteError(p, f"{kind} file has over {MAX_XML_ELEMENTS} elements; refused")
            yield event, el, names
    except DefusedXmlException as exc:
        raise RouteError(
            p, f"{kind} file declares a DOCTYPE or ENTITY; refused for safety ({exc})"
        ) from None
    except ET.ParseError as exc:
        raise RouteError(p, f"not valid {kind} XML ({_short(str(exc), 120)})") from None
    if not elements:
        raise RouteError(p, f"not valid {kind} XML (no element)")


def _local(tag: Any) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _stripped_text(el: ET.Element) -> str | None:
    return el.text.strip() if el.text else None


_GPX_POINT_PATHS = (["gpx", "trk", "trkseg", "trkpt"], ["gpx", "rte", "rtept"])
"""the elements of a GPX file read as points (the names of the elements open there)"""


def _gpx_lines(p: Path) -> _Lines:
    """Tracks (their segments joined), then routes: the children of the root ``<gpx>``."""
    table = _LineTable()
    root: str | None = None
    tracks = routes = 0
    name: str | None = None
    named = ele_seen = False
    ele: str | None = None
    starts: list[int] = []
    for event, el, names in _xml_events(p, _read_checked(p), "GPX"):
        root = names[0] if root is None else root
        if root != "gpx":
            continue
        tag, depth = names[-1], len(names)
        if event == "start":
            if depth == 2 and tag in ("trk", "rte"):
                name, named, starts = None, False, []
            elif depth == 3 and tag == "trkseg" and names[1] == "trk" and table.in_line:
                starts.append(table.in_line)
            elif names in _GPX_POINT_PATHS:
                ele, ele_seen = None, False
        elif names in _GPX_POINT_PATHS:
            lat, lon = _num(el.get("lat")), _num(el.get("lon"))
            table.add_point(lat, lon, _num(ele) if ele else math.nan)
        elif tag == "ele" and names[:-1] in _GPX_POINT_PATHS and not ele_seen:
            ele, ele_seen = _stripped_text(el), True
        elif depth == 3 and tag == "name" and names[1] in ("trk", "rte") and not named:
            name, named = _stripped_text(el), True
        elif depth == 2 and tag == "trk":
            table.end_line(name or f"track {tracks}", starts, "trkseg", order=tracks)
            tracks += 1
        elif depth == 2 and tag == "rte":
            table.end_line(name or f"route {routes}", order=MAX_XML_ELEMENTS + routes)
            routes += 1
    if root != "gpx":
        raise RouteError(p, f"not a GPX file (root element <{root}>)")
    return table.lines()


@dataclass
class _OpenPlacemark:
    """A KML placemark being read: its index among the file's placemarks, its name, and its
    LineStrings' points as (index among the file's LineStrings, points kept, points)."""

    index: int
    name: str | None = None
    named: bool = False
    lines: list[tuple[int, array[float], int]] = dataclasses.field(default_factory=list)


@dataclass
class _OpenLineString:
    index: int
    coordinates: str = ""
    has_coordinates: bool = False


_KML_TUPLE = re.compile(r"\S+")


def _kml_lines(p: Path) -> _Lines:
    """Every placemark with a LineString, its LineStrings joined in the file's order (those of
    a placemark nested in it too, as an ElementTree's ``iter`` finds them). A wrong coordinate
    is reported once the file is parsed, the first in the placemarks' order, after any error
    of the XML itself."""
    table = _LineTable()
    root: str | None = None
    marks: list[_OpenPlacemark] = []
    lines: list[_OpenLineString] = []
    placemarks = linestrings = pending = 0
    wrong: tuple[tuple[int, int], RouteError] | None = None
    for event, el, names in _xml_events(p, _read_checked(p), "KML"):
        root = names[0] if root is None else root
        if root != "kml":
            continue
        tag, parent = names[-1], names[-2] if len(names) > 1 else ""
        if event == "start":
            if tag == "Placemark":
                marks.append(_OpenPlacemark(placemarks))
                placemarks += 1
            elif tag == "LineString" and marks:
                lines.append(_OpenLineString(linestrings))
                linestrings += 1
        elif tag == "coordinates" and parent == "LineString" and lines:
            if not lines[-1].has_coordinates:
                lines[-1].coordinates, lines[-1].has_coordinates = el.text or "", True
        elif tag == "name" and parent == "Placemark" and not marks[-1].named:
            marks[-1].name, marks[-1].named = _stripped_text(el), True
        elif tag == "LineString" and marks:
            line = lines.pop()
            room = MAX_ROUTE_POINTS - table.counted - pending
            try:
                kept, count = _kml_coordinates(p, line.coordinates, room // len(marks))
            except RouteError as exc:
                key = (marks[0].index, line.index)
                wrong = (key, exc) if wrong is None or key < wrong[0] else wrong
                continue
            for mark in marks:
                mark.lines.append((line.index, kept, count))
            pending += count * len(marks)
        elif tag == "Placemark":
            mark = marks.pop()
            if mark.lines:
                starts = []
                for _, kept, count in sorted(mark.lines, key=lambda piece: piece[0]):
                    if table.in_line:
                        starts.append(table.in_line)
                    table.add_points(kept, count)
                    pending -= count
                name = mark.name or f"placemark {mark.index}"
                table.end_line(name, starts, "LineString", order=mark.index)
    if root != "kml":
        raise RouteError(p, f"not a KML file (root element <{root}>)")
    if wrong is not None:
        raise wrong[1]
    return table.lines()


def _kml_coordinates(p: Path, text: str, room: int) -> tuple[array[float], int]:
    """A LineString's points (lat, lon, height) and their count; only the first ``room`` are
    kept (the file is refused beyond)."""
    kept: array[float] = array("d")
    count = 0
    nan = math.nan
    for match in _KML_TUPLE.finditer(text):
        v = match.group().split(",")
        if len(v) < 2:
            raise RouteError(p, f"KML coordinate {match.group()!r} is not lon,lat[,alt]")
        count += 1
        if count <= room:
            kept.extend((_num(v[1]), _num(v[0]), _num(v[2]) if len(v) > 2 else nan))
    return kept, count


# --- CSV -------------------------------------------------------------------------------------

_LAT = ("lat", "latitude")
_LON = ("lon", "lng", "long", "longitude")
_ALT = ("alt", "altitude", "ele", "elevation", "height", "h")


def _csv_lines(p: Path) -> _Lines:
    """The rows read one by one (not all held); a wrong header or row is reported once every
    row is read, after any error of the CSV itself, as when the rows were read whole first."""
    data = _read_checked(p)
    try:
        dialect = csv.Sniffer().sniff(_text_start(data)[:CSV_SNIFF_CHARS], delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig", newline="\n")
    table = _LineTable()
    header: list[str] | None = None
    wrong: RouteError | None = None
    try:
        for row in csv.reader(text, dialect):
            if wrong is not None or not any(c.strip() for c in row):
                continue
            try:
                if header is None:
                    header = row
                    columns = _csv_columns(p, row)
                else:
                    _csv_row(p, row, columns, len(header), table)
            except RouteError as exc:
                wrong = exc
    except csv.Error as exc:
        raise RouteError(p, f"not a readable CSV route ({_short(str(exc), 120)})") from None
    if header is None:
        raise RouteError(p, "CSV has no header and no rows (only separators or quotes)")
    if wrong is not None:
        raise wrong
    table.end_line("")
    return table.lines()


def _csv_columns(p: Path, header: list[str]) -> tuple[int, int, int | None]:
    names = [c.strip().lower() for c in header]

    def column(choices: tuple[str, ...]) -> int | None:
        return next((names.index(n) for n in choices if n in names), None)

    i_lat, i_lon, i_alt = column(_LAT), column(_LON), column(_ALT)
    if i_lat is None or i_lon is None:
        raise RouteError(
            p,
            f"CSV header {_short(repr(header))} has no lat/lon columns; expected a header "
            "with lat,lon[,alt] or latitude,longitude",
        )
    return i_lat, i_lon, i_alt


def _csv_row(
    p: Path, row: list[str], columns: tuple[int, int, int | None], fields: int, table: _LineTable
) -> None:
    i_lat, i_lon, i_alt = columns
    k = table.in_line + 2
    if len(row) <= max(i_lat, i_lon):
        raise RouteError(p, f"CSV line {k} has {len(row)} fields, expected {fields}")
    alt = _num(row[i_alt]) if i_alt is not None and i_alt < len(row) else math.nan
    lat, lon = _num(row[i_lat]), _num(row[i_lon])
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise RouteError(
            p, f"CSV line {k}: lat/lon {row[i_lat]!r}, {row[i_lon]!r} are not finite numbers"
        )
    table.add_point(lat, lon, alt)
