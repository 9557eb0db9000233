"""Open a log and its route together, in one local ENU frame shared by both."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
from numpy.typing import NDArray

from estimator.errors import (
    ON_THE_COMMAND_LINE,
    LogError,
    RouteError,
    WhereToChoose,
    choices_said,
)
from estimator.io import AUTO_TOPICS, TopicChoice, load_log
from estimator.io.plausibility import in_bulk
from estimator.io.routefile import RouteLine, read_route_file, route_in_frame
from estimator.log import Log
from estimator.nav.frames import LocalFrame
from estimator.route import Route

MAX_ROUTE_DISTANCE_M = 5000.0
"""A route whose every point is farther than this from every GNSS fix belongs to another log."""


@dataclass(frozen=True)
class Inputs:
    log: Log
    route: Route | None
    frame: LocalFrame


def frame_of(log: Log) -> LocalFrame:
    """The session frame: at the first valid GNSS fix that agrees with the bulk of them
    (:func:`~estimator.io.plausibility.in_bulk`), else at the first truth position."""
    g = log.gnss
    ok = np.flatnonzero(g.valid)
    if len(ok):
        ok = ok[in_bulk(g.lat[ok], g.lon[ok])]
        return LocalFrame.at(g.lat[ok], g.lon[ok], g.alt[ok])
    t = log.truth
    if t is not None and np.any(np.isfinite(t.lat) & np.isfinite(t.lon)):
        return LocalFrame.at(t.lat, t.lon, t.alt)
    raise LogError(log.path, "no valid GNSS fix and no ground truth: cannot place the map frame")


def fix_positions(log: Log, frame: LocalFrame) -> NDArray[np.float64]:
    """(N, 3) ENU of the valid GNSS fixes, or of the truth when the log has no valid fix."""
    g = log.gnss
    ok = g.valid
    if ok.any():
        return frame.to_enu(g.lat[ok], g.lon[ok], g.alt[ok])
    t = log.truth
    if t is None:
        return np.zeros((0, 3))
    enu = frame.to_enu(t.lat, t.lon, t.alt)
    return enu[np.all(np.isfinite(enu), axis=1)]


EXACT_DISTANCE_PAIRS = 4_000_000
"""fix-segment pairs up to which the route distance is measured pair by pair (2000 fixes
against a 50 km route at 25 m vertices); above, through a k-d tree, which would import scipy's
spatial module into every ``routefuse run`` for nothing"""


def route_distances(
    log: Log, route: Route, frame: LocalFrame, *, max_points: int = 2000
) -> NDArray[np.float64]:
    """Distance of (up to ``max_points`` evenly chosen) fixes from the route, m."""
    xy = fix_positions(log, frame)[:, :2]
    if len(xy) > max_points:
        xy = xy[np.linspace(0, len(xy) - 1, max_points).astype(np.intp)]
    if not len(xy):
        return np.zeros(0)
    if len(xy) * len(route.seglen) <= EXACT_DISTANCE_PAIRS:
        return route.project(xy).distance
    return route.distance_to(xy)


def _geodesic_gap(log: Log, frame: LocalFrame, line: RouteLine) -> float:
    """Smallest ellipsoidal distance between route vertices and log positions (a local
    plane shrinks distances of thousands of km, so a far route is measured on the ellipsoid)."""
    fixes = frame.to_geodetic(fix_positions(log, frame))
    fixes = fixes[np.linspace(0, len(fixes) - 1, min(len(fixes), 200)).astype(np.intp)]
    pick = np.linspace(0, len(line.lat) - 1, min(len(line.lat), 200)).astype(np.intp)
    lat_r, lon_r = line.lat[pick], line.lon[pick]
    lat_f = np.repeat(fixes[:, 0], len(pick))
    lon_f = np.repeat(fixes[:, 1], len(pick))
    _, _, d = pyproj.Geod(ellps="WGS84").inv(
        lon_f, lat_f, np.tile(lon_r, len(fixes)), np.tile(lat_r, len(fixes))
    )
    return float(np.min(d))


def _swapped(line: RouteLine) -> RouteLine | None:
    """The line with latitude and longitude exchanged, if that is still a valid position."""
    if np.any(np.abs(line.lon) > 90.0):
        return None
    return RouteLine(line.lon, line.lat, line.alt, line.name, line.source)


def open_inputs(
    log_path: str | Path,
    route_path: str | Path | None = None,
    *,
    topics: TopicChoice = AUTO_TOPICS,
    route_feature: str | int | None = None,
    where_to_choose: WhereToChoose = ON_THE_COMMAND_LINE,
    cache_dir: Path | None = None,
    progress: Callable[[float], None] | None = None,
) -> Inputs:
    """Load the log, place the frame at its first fix, load the route in that frame, and refuse
    a route that is nowhere near the log (a wrong file pairing). ``route_feature`` picks the
    line of a route file holding several; a log of several topics of a kind, or a route file of
    several lines, opened without a choice is a :class:`ChoiceError` saying where the user
    chooses, ``where_to_choose`` (the command line's flags by default)."""
    log_progress = None if progress is None else (lambda f: progress(0.95 * f))
    with choices_said(where_to_choose):
        log = load_log(log_path, topics=topics, cache_dir=cache_dir, progress=log_progress)
    frame = frame_of(log)
    route = None
    if route_path is not None:
        with choices_said(where_to_choose):
            line = read_route_file(route_path, feature=route_feature)
        route = route_in_frame(line, frame)
        dist = route_distances(log, route, frame, max_points=500)
        if len(dist) and dist.min() > MAX_ROUTE_DISTANCE_M:
            far = _geodesic_gap(log, frame, line)
            swapped = _swapped(line)
            if (
                swapped is not None
                and (near := _geodesic_gap(log, frame, swapped)) <= MAX_ROUTE_DISTANCE_M
            ):
                raise RouteError(
                    route_path,
                    f"route is {far / 1000:.1f} km from {Path(log_path).name}, but "
                    f"{near / 1000:.1f} km with latitude and longitude swapped: the file has "
                    "them in the wrong order (GeoJSON and KML want lon,lat)",
                )
            raise RouteError(
                route_path,
                f"route is {far / 1000:.1f} km from the nearest position of "
                f"{Path(log_path).name} (more than {MAX_ROUTE_DISTANCE_M / 1000:g} km): "
                "wrong route for this log?",
            )
    if progress is not None:
        progress(1.0)
    return Inputs(log, route, frame)
