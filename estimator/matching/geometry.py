"""Route geometry for the matcher: resampling a window, local route pieces (a stretch of the
route, shifted sideways, maybe reversed), and where points fall on the route (globally, near a
guess, or followed along a drive).

The hot paths call the compiled kernels of :mod:`estimator.matching.route_kernels`, which
compute what :class:`~estimator.route.Route`'s numpy methods do, bit for bit.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.errors import RouteError, RoutefuseError
from estimator.matching.route_kernels import (
    nearest_all,
    nearest_arc,
    offset_polyline,
    project_window,
    route_piece,
    segment_index,
    segment_points,
    track_chunks,
)
from estimator.params import Params
from estimator.route import Route

F64 = NDArray[np.float64]


class Polyline(NamedTuple):
    """The arrays of a route (or of a local piece of it) the fit reads, as
    :class:`~estimator.route.Route` holds them."""

    xy: F64
    """(K + 1, 2) vertices"""
    s: F64
    """(K + 1,) arc length of each vertex, m"""
    unit: F64
    """(K, 2) unit direction of each segment"""
    seglen: F64
    """(K,) segment lengths, m"""

    @classmethod
    def of(cls, route: Route) -> Polyline:
        return cls(route.xy, route.s, route.unit, route.seglen)

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def arc_of(self, point: F64) -> float:
        """Arc length of the point of the polyline nearest to ``point`` (short pieces)."""
        return float(nearest_arc(self.xy, self.s, float(point[0]), float(point[1])))

    def tangent(self, s: float) -> F64:
        """Unit tangent of the segment arc length ``s`` falls in (``Route.tangent_at``)."""
        out: F64 = self.unit[segment_index(self.s, float(s))].copy()
        return out

    def segment(self, s0: float, s1: float) -> F64:
        """The polyline between two arc lengths with its vertices (``Route.segment``)."""
        out: F64 = segment_points(self.xy, self.s, self.unit, float(s0), float(s1))
        return out


def resample_polyline(
    xy: ArrayLike, spacing: float, *, anchor: Literal["start", "end"] = "end"
) -> F64:
    """Points every ``spacing`` metres of arc length along a polyline, in its order.

    Removes the effect of speed and sampling rate on the window's shape. With ``anchor="end"``
    the last point is the polyline's last point (the current position), so the terminal pair
    and ``p_ref`` refer to where the vehicle is now; the first point is up to one spacing after
    the polyline's start.
    """
    p = np.asarray(xy, np.float64)[:, :2]
    d = p[1:] - p[:-1]
    c = np.empty(len(p))
    c[0] = 0.0
    np.cumsum(np.hypot(d[:, 0], d[:, 1]), out=c[1:])
    total = float(c[-1])
    n = int(np.floor(total / spacing + 1e-9)) + 1
    steps = spacing * np.arange(n)
    at = total - steps[::-1] if anchor == "end" else steps
    out = np.empty((n, 2))
    out[:, 0] = np.interp(at, c, p[:, 0])
    out[:, 1] = np.interp(at, c, p[:, 1])
    return out


def local_piece(
    road: Polyline, lateral_m: float, lo: float, hi: float, *, reverse: bool = False
) -> Polyline | None:
    """A local candidate road: ``road`` between two arc lengths, shifted sideways (positive =
    to the left), maybe driven backwards; None when nothing of it is left."""
    ok, xy, seglen, unit, s = route_piece(
        road.xy, road.s, road.unit, float(lateral_m), float(lo), float(hi), reverse
    )
    return Polyline(xy, s, unit, seglen) if ok else None


def shifted_route(
    route: Route, lateral_m: float, *, s0: float = 0.0, s1: float | None = None
) -> Route:
    """The part of ``route`` between two arc lengths, offset sideways (positive = to the left).

    Vertices move along their miter direction, so each segment stays parallel to the original
    at exactly ``lateral_m`` (a parallel carriageway). Where the offset exceeds the radius of a
    bend, the offset segments fold back into a loop; their vertices are dropped, since a real
    parallel road does not loop either.
    """
    end = route.length if s1 is None else s1
    out = offset_polyline(Polyline.of(route).segment(s0, end), float(lateral_m))
    if len(out) == 0:
        raise RouteError(route.source or None, "route piece to shift has no length")
    return Route(out, name=route.name, source=route.source)


def project_near(
    road: Polyline, xy: ArrayLike, s_guess: ArrayLike, search_m: float
) -> tuple[F64, F64]:
    """``Route.project(xy, s_guess, search_m)``'s arc lengths and lateral offsets, compiled
    for the matcher's few points per attempt."""
    p = np.ascontiguousarray(np.asarray(xy, np.float64).reshape(-1, np.shape(xy)[-1])[:, :2])
    g = np.empty(len(p))
    g[:] = s_guess
    s = np.empty(len(p))
    lat = np.empty(len(p))
    project_window(road.xy, road.s, road.unit, road.seglen, p, g, float(search_m), s, lat)
    return s, lat


def project_on_route(route: Route, xy: ArrayLike) -> tuple[F64, F64]:
    """Arc length and signed lateral offset (positive = left) of every point, nearest over
    the whole route; as :meth:`Route.project` without a search window, but fast and lean on
    memory for long logs and long routes."""
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(xy, np.float64))[:, :2])
    s = np.empty(len(p))
    lat = np.empty(len(p))
    nearest_all(route.xy, route.s, p, s, lat)
    return s, lat


def track_on_route(
    route: Route, xy: ArrayLike, *, search_m: float = 50.0, chunk: int = 64
) -> tuple[F64, F64]:
    """Arc length and signed lateral offset of a trajectory, followed along the route: each
    chunk of points is projected within ``search_m`` (plus the distance the chunk covers) of
    where the previous chunk ended. A route that passes over or near itself (a climbing spiral,
    a loop, a return carriageway) then keeps the vehicle on the stretch it is driving, where a
    nearest-point search would jump to the other level."""
    p = np.atleast_2d(np.asarray(xy, np.float64))[:, :2]
    n = len(p)
    s = np.empty(n)
    lat = np.empty(n)
    if n == 0:
        return s, lat
    s_prev = float(project_on_route(route, p[:1])[0][0])
    step = np.r_[0.0, np.hypot(*np.diff(p, axis=0).T)]
    reach = np.array([search_m + float(np.sum(step[i : i + chunk])) for i in range(0, n, chunk)])
    if np.all(np.isfinite(p)) and np.all(np.isfinite(reach)) and search_m >= 0:
        track_chunks(
            route.xy,
            route.s,
            route.unit,
            route.seglen,
            np.ascontiguousarray(p),
            s_prev,
            reach,
            int(chunk),
            s,
            lat,
        )
        return s, lat
    for c, i in enumerate(range(0, n, chunk)):
        j = min(i + chunk, n)
        proj = route.project(p[i:j], np.full(j - i, s_prev), float(reach[c]))
        s[i:j], lat[i:j] = proj.s, proj.lateral
        s_prev = float(proj.s[-1])
    return s, lat


SAME_PLACE_M = 5.0
"""stretches of a route this much farther from a position than the nearest are as near: an
out-and-back route draws the road twice, once each way, on the same line"""


def route_arc_length(
    route: Route,
    xy: ArrayLike,
    *,
    s_guess: float | None = None,
    params: Params,
    heading_xy: ArrayLike | None = None,
) -> float:
    """Route arc length of a position, searched within ``window.route_search_m`` of ``s_guess``
    (globally when None), so the pipeline can track where on the route the vehicle is.
    Searched globally with the vehicle's horizontal velocity ``heading_xy``, where the nearest
    stretch is drawn against the vehicle's travel, of the stretches as near as it
    (:data:`SAME_PLACE_M`) the one drawn most nearly the way the vehicle drives: on a route
    that comes back along the road it went out on, the nearest point alone may be on the leg
    drawn the other way, where every match is then refused for its heading."""
    p = np.asarray(xy, np.float64).reshape(-1)[:2]
    if not np.all(np.isfinite(p)):
        raise RoutefuseError(None, "route match: position to project is not finite")
    if s_guess is None:
        s_near = float(project_on_route(route, p)[0][0])
        if heading_xy is None:
            return s_near
        return _along_the_heading(route, p, np.asarray(heading_xy, np.float64)[:2], s_near)
    road = Polyline.of(route)
    return float(project_near(road, p, s_guess, params.window.route_search_m)[0][0])


def _along_the_heading(route: Route, p: F64, heading: F64, s_near: float) -> float:
    speed = float(np.hypot(*heading))
    if not (math.isfinite(speed) and speed > 0.0) or len(route.seglen) == 0:
        return s_near
    if float(route.tangent_at(np.array([s_near]))[0] @ heading) > 0.0:
        return s_near  # drawn the way the vehicle drives: the nearest point is the place
    segments = np.arange(len(route.seglen))
    along, distance = route.segment_feet(np.broadcast_to(p, (len(segments), 2)), segments)
    near = distance <= float(distance.min()) + SAME_PLACE_M
    agreement = np.where(near, route.unit @ (heading / speed), -np.inf)
    k = int(np.argmax(agreement))
    if agreement[k] <= 0.0:
        return s_near
    return float(route.s[k] + along[k])


def learn_lane_offset(
    t: ArrayLike,
    xy: ArrayLike,
    gnss_used: ArrayLike,
    route: Route,
    *,
    t_end: float,
    params: Params,
    s_guess: float | None = None,
) -> float:
    """The vehicle's lateral offset from the route (m, positive = vehicle LEFT of the route),
    exponentially weighted with ``offset.time_constant_s`` over the good-GNSS epochs up to
    ``t_end``: a lane is not the road centreline, and the pseudo-position should keep the lane.

    0 when offset compensation is off, when no epoch is usable (no GNSS, off the route's ends),
    or when the offset is larger than ``offset.max_offset_m`` (the vehicle is not on this road).
    """
    op = params.offset
    if not op.enabled:
        return 0.0
    t_a = np.asarray(t, np.float64).reshape(-1)
    p = np.asarray(xy, np.float64).reshape(len(t_a), -1)[:, :2]
    used = np.asarray(gnss_used, bool).reshape(-1)
    horizon = 5.0 * op.time_constant_s
    sel = (
        used
        & (t_a <= t_end)
        & (t_a >= t_end - horizon)
        & np.isfinite(t_a)
        & np.all(np.isfinite(p), axis=1)
    )
    if not sel.any():
        return 0.0
    pts, ts = p[sel], t_a[sel]
    if s_guess is None:
        s, lateral = project_on_route(route, pts)
    else:
        travel = float(np.sum(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0
        proj = route.project(pts, s_guess, travel + params.window.route_search_m)
        s, lateral = proj.s, proj.lateral
    inside = (s > 1e-6) & (s < route.length - 1e-6)
    if not inside.any():
        return 0.0
    w = np.exp(-(t_end - ts[inside]) / op.time_constant_s)
    offset = float(np.sum(w * lateral[inside]) / np.sum(w))
    if not np.isfinite(offset) or abs(offset) > op.max_offset_m:
        return 0.0
    return offset
