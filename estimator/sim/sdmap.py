"""The SD-map mission route of a simulated drive: the road centreline as a map stores it.

A map keeps the centreline at road level, with vertices tens of metres apart on curves and
few on straights: the centreline is resampled every ``vertex_spacing_m`` and simplified with
Douglas-Peucker at ``simplify_m``, then extended straight beyond both ends and optionally
shifted by a constant map bias. Written as the GeoJSON route convention of
``shared/data/README.md`` (one LineString, lon/lat, ``lateral_offset_m`` positive = the route
lies to the left of the driven path).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.nav.frames import LocalFrame
from estimator.route import Route

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class RouteModel:
    """How the map represents the road."""

    vertex_spacing_m: float = 25.0
    simplify_m: float = 0.3
    """Douglas-Peucker tolerance: straights keep only their end vertices"""
    extend_m: float = 200.0
    """straight extension beyond both ends of the drive"""
    bias_enu_m: tuple[float, float] = (0.0, 0.0)
    """constant map error (east, north) added to every vertex"""


def douglas_peucker(pts: ArrayLike, tol: float) -> NDArray[np.intp]:
    """Indices of the vertices Douglas-Peucker keeps (iterative, ends always kept)."""
    p = np.asarray(pts, np.float64)
    n = len(p)
    keep = np.zeros(n, bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, d = p[i], p[j] - p[i]
        length = np.hypot(*d)
        rel = p[i + 1 : j] - a
        dist = (
            np.abs(d[0] * rel[:, 1] - d[1] * rel[:, 0]) / length
            if length > 1e-9
            else np.hypot(rel[:, 0], rel[:, 1])
        )
        k = int(np.argmax(dist))
        if dist[k] > tol:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(keep)


def map_route(centreline: ArrayLike, model: RouteModel = RouteModel()) -> F64:
    """(M, 2) EN route vertices from a densely sampled centreline (<= a few metres apart)."""
    c = np.asarray(centreline, np.float64)[:, :2]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(c, axis=0).T))]
    n = max(int(np.round(s[-1] / model.vertex_spacing_m)), 1)
    si = np.linspace(0.0, s[-1], n + 1)
    res = np.column_stack([np.interp(si, s, c[:, 0]), np.interp(si, s, c[:, 1])])
    v = res[douglas_peucker(res, model.simplify_m)]
    if model.extend_m > 0:
        d0 = (v[0] - v[1]) / np.hypot(*(v[0] - v[1]))
        d1 = (v[-1] - v[-2]) / np.hypot(*(v[-1] - v[-2]))
        v = np.vstack([v[0] + model.extend_m * d0, v, v[-1] + model.extend_m * d1])
    return v + np.asarray(model.bias_enu_m, np.float64)


def route_geojson(
    xy: ArrayLike,
    frame: LocalFrame,
    *,
    name: str,
    source: str,
    derived_from: str,
    model: RouteModel,
    lateral_offset_m: float,
    attribution: str = "",
) -> dict[str, Any]:
    """The route convention's FeatureCollection (coordinates rounded to 1e-8 deg, ~1 mm)."""
    geo = frame.to_geodetic(np.asarray(xy, np.float64))
    props: dict[str, Any] = {
        "name": name,
        "source": source,
        "derived_from": derived_from,
        "vertex_spacing_m": model.vertex_spacing_m,
        "lateral_offset_m": lateral_offset_m,
        "offset_convention": "positive = the route (road centreline) lies this many metres to "
        "the LEFT of the driven path",
        "map_bias_enu_m": list(model.bias_enu_m),
    }
    if attribution:
        props["attribution"] = attribution
    return {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": props,
                "geometry": {
                    "type": "LineString",
                    "coordinates": [
                        [round(float(lon), 8), round(float(lat), 8)] for lat, lon, _ in geo
                    ],
                },
            }
        ],
    }


def write_geojson(path: str | Path, doc: dict[str, Any]) -> None:
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")


def parallel_bore(
    route: Route, s0: float, s1: float, shift_m: float, *, ramp_m: float = 80.0
) -> Route:
    """``route`` with its stretch from arc length ``s0`` to ``s1`` drawn ``shift_m`` to the left
    (a map routing through the other bore of a twin tunnel), joined by cosine ramps of
    ``ramp_m`` at both ends; vertices every 10 m over the stretch and its ramps."""
    lo, hi = s0 - ramp_m, s1 + ramp_m
    s_new = np.unique(np.r_[route.s[route.s < lo], np.arange(lo, hi, 10.0), route.s[route.s > hi]])
    s_new = s_new[(s_new >= 0) & (s_new <= route.length)]
    weight = np.clip(np.minimum(s_new - lo, hi - s_new) / ramp_m, 0.0, 1.0)
    weight = 0.5 - 0.5 * np.cos(np.pi * weight)
    xy = route.point_at(s_new) + (shift_m * weight)[:, None] * route.normal_at(s_new)
    return Route(xy, name=route.name, source=route.source)
