"""The route file formats, by suffix, and how help texts call them: names only (no numpy), so
that the CLI's parser and the inspector's file checks can use them cheaply; reading is
:mod:`estimator.io.routefile`."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

RouteFormat = Literal["geojson", "gpx", "kml", "csv"]

ROUTE_FORMATS: dict[str, RouteFormat] = {
    ".geojson": "geojson",
    ".json": "geojson",
    ".gpx": "gpx",
    ".kml": "kml",
    ".csv": "csv",
}
"""suffix (lower case) -> format"""
ROUTE_FORMATS_TEXT = "GeoJSON, GPX, KML or CSV"
"""How help texts name the route formats."""
ROUTE_SUFFIXES_TEXT = ".geojson/.json, .gpx, .kml or .csv"
"""The suffixes, for messages."""


def route_format(path: str | Path) -> RouteFormat | None:
    """The format a route file's suffix says, or None."""
    return ROUTE_FORMATS.get(Path(path).suffix.lower())


LISTED_ROUTE_SUFFIXES = (".geojson", ".gpx", ".kml", ".csv", ".route.json")
"""What a folder listing or an upload takes for a route file (a bare ``.json`` is as likely
anything else)."""


def is_route_path(path: str | Path) -> bool:
    """Whether a file picker, an upload check or a batch finder takes ``path`` for a route, by
    its name."""
    return Path(path).name.lower().endswith(LISTED_ROUTE_SUFFIXES)


def route_beside(log: str | Path) -> Path | None:
    """The route that belongs to a log, by name: ``<stem>.route.<suffix>`` (the simulator and the
    samples name them so), else ``<stem>.<suffix>``, in the log's folder."""
    p = Path(log)
    stem = p.name.split(".")[0]
    for infix in (".route", ""):
        for suffix in (".geojson", ".gpx", ".kml", ".csv"):
            if infix == "" and suffix == ".csv":
                continue  # a bare <stem>.csv is as likely a data table as a route
            candidate = p.parent / f"{stem}{infix}{suffix}"
            try:
                if candidate.is_file():
                    return candidate
            except OSError:  # a folder that cannot be looked into: no route found there
                return None
    return None
