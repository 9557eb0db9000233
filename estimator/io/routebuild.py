"""Build an SD-map-like route from a recorded track (the convention of the shared data notes).

A real log rarely comes with a mission route. ``shared/data/README.md`` documents how the
comma2k19 route was derived from the reference trajectory; :func:`route_from_track` does the
same for any track (a ground-truth track, or smoothed GNSS fixes when a log has no truth):

1. drop points closer than ``min_step_m`` to the last kept one (standstill jitter);
2. densify to 1 m and Gaussian-smooth along the arc length (``sigma_m``);
3. shift ``offset_left_m`` to the LEFT of the direction of travel (a road centreline left of
   the driven lane);
4. resample every ``spacing_m`` and simplify with Douglas-Peucker (``dp_tol_m``);
5. extend ``extend_m`` straight beyond both ends.

A route built from the log's own GNSS is not independent of the log: use it to exercise the
method, not as evidence that a map would help (see docs/validation.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.log import Log
from estimator.nav.frames import LocalFrame

F64 = NDArray[np.float64]


def moving_average(x: ArrayLike, n: int) -> F64:
    """Centred ``n``-sample moving average of (N, ...) samples (shorter at the ends)."""
    a = np.asarray(x, np.float64)
    if n <= 1 or len(a) == 0:
        return a.copy()
    half = n // 2
    c = np.cumsum(np.r_[np.zeros((1, *a.shape[1:])), a], axis=0)
    i = np.arange(len(a))
    lo = np.clip(i - half, 0, len(a))
    hi = np.clip(i - half + n, 0, len(a))
    mean: F64 = (c[hi] - c[lo]) / (hi - lo).reshape(-1, *([1] * (a.ndim - 1)))
    return mean


def _resample(xy: F64, step: float) -> F64:
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    n = max(round(s[-1] / step), 1)
    si = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(si, s, xy[:, 0]), np.interp(si, s, xy[:, 1])])


def _gauss_smooth(xy: F64, sigma_pts: float) -> F64:
    """Gaussian smoothing of an evenly spaced polyline; odd reflection keeps straight ends
    straight."""
    if sigma_pts <= 0 or len(xy) < 3:
        return xy.copy()
    r = min(int(np.ceil(4 * sigma_pts)), len(xy) - 1)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_pts) ** 2)
    k /= k.sum()
    out = np.empty_like(xy)
    for c in range(2):
        v = xy[:, c]
        vv = np.r_[2 * v[0] - v[r:0:-1], v, 2 * v[-1] - v[-2 : -r - 2 : -1]]
        out[:, c] = np.convolve(vv, k, mode="valid")
    return out


def _douglas_peucker(pts: F64, tol: float) -> NDArray[np.intp]:
    keep = np.zeros(len(pts), bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        d = pts[j] - pts[i]
        length = float(np.hypot(*d))
        seg = pts[i + 1 : j] - pts[i]
        if length < 1e-9:
            dist = np.hypot(seg[:, 0], seg[:, 1])
        else:
            dist = np.abs(d[0] * seg[:, 1] - d[1] * seg[:, 0]) / length
        k = int(np.argmax(dist))
        if dist[k] > tol:
            keep[i + 1 + k] = True
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return np.flatnonzero(keep)


def route_polyline(
    xy: ArrayLike,
    *,
    sigma_m: float = 3.0,
    offset_left_m: float = 0.0,
    spacing_m: float = 25.0,
    dp_tol_m: float = 0.3,
    extend_m: float = 200.0,
    min_step_m: float = 0.5,
) -> F64:
    """The route vertices (M, 2) in the plane of ``xy`` (a track in metres, in time order)."""
    pts = np.asarray(xy, np.float64)[:, :2]
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    keep = [0]
    for i in range(1, len(pts)):
        if np.hypot(*(pts[i] - pts[keep[-1]])) >= min_step_m:
            keep.append(i)
    if len(keep) < 2:
        raise ValueError("the track does not move: no route can be built from it")
    dense = _resample(pts[keep], 1.0)
    smooth = _gauss_smooth(dense, sigma_m)
    tangent = np.gradient(smooth, axis=0)
    tangent /= np.maximum(np.hypot(tangent[:, 0], tangent[:, 1]), 1e-12)[:, None]
    shifted = smooth + offset_left_m * np.column_stack([-tangent[:, 1], tangent[:, 0]])
    res = _resample(shifted, spacing_m)
    v = res[_douglas_peucker(res, dp_tol_m)]
    if extend_m > 0:
        d0 = (v[0] - v[1]) / np.hypot(*(v[0] - v[1]))
        d1 = (v[-1] - v[-2]) / np.hypot(*(v[-1] - v[-2]))
        v = np.vstack([v[0] + extend_m * d0, v, v[-1] + extend_m * d1])
    return v


def route_geojson(
    lat: ArrayLike,
    lon: ArrayLike,
    *,
    name: str,
    derived_from: str,
    sigma_m: float = 3.0,
    offset_left_m: float = 0.0,
    spacing_m: float = 25.0,
    dp_tol_m: float = 0.3,
    extend_m: float = 200.0,
    min_step_m: float = 0.5,
) -> dict[str, Any]:
    """A one-LineString GeoJSON route (the shared data's route convention) from a geodetic
    track."""
    lat = np.asarray(lat, np.float64)
    lon = np.asarray(lon, np.float64)
    ok = np.isfinite(lat) & np.isfinite(lon)
    frame = LocalFrame.at(lat[ok], lon[ok])
    enu = frame.to_enu(lat[ok], lon[ok])
    v = route_polyline(
        enu[:, :2],
        sigma_m=sigma_m,
        offset_left_m=offset_left_m,
        spacing_m=spacing_m,
        dp_tol_m=dp_tol_m,
        extend_m=extend_m,
        min_step_m=min_step_m,
    )
    geo = frame.to_geodetic(np.column_stack([v, np.zeros(len(v))]))
    return {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {
                    "name": name,
                    "source": "routefuse estimator.io.routebuild.route_geojson",
                    "derived_from": derived_from,
                    "vertex_spacing_m": spacing_m,
                    "lateral_offset_m": offset_left_m,
                    "smoothing_sigma_m": sigma_m,
                    "offset_convention": "positive = the route lies this many metres to the "
                    "LEFT of the driven path",
                },
                "geometry": {
                    "type": "LineString",
                    "coordinates": [[round(float(g[1]), 9), round(float(g[0]), 9)] for g in geo],
                },
            }
        ],
    }


def route_from_gnss(
    log: Log,
    *,
    name: str,
    average: int = 5,
    sigma_m: float = 3.0,
    spacing_m: float = 25.0,
    dp_tol_m: float = 0.3,
    extend_m: float = 20.0,
) -> dict[str, Any]:
    """A route from a log's own valid GNSS fixes (``average``-fix moving average first), for a
    log that has neither a route nor a ground truth to derive one from. No lateral offset: the
    vehicle drove on the line it defines. The route shares the fixes' wander, so it is not an
    independent map (see the module docstring)."""
    g = log.gnss
    ok = g.valid
    if ok.sum() < 2:
        raise ValueError(f"{log.path}: fewer than two valid GNSS fixes: no route can be built")
    ll = moving_average(np.column_stack([g.lat[ok], g.lon[ok]]), average)
    return route_geojson(
        ll[:, 0],
        ll[:, 1],
        name=name,
        derived_from=f"{Path(log.path).name}: valid GNSS fixes, {average}-fix moving average",
        sigma_m=sigma_m,
        offset_left_m=0.0,
        spacing_m=spacing_m,
        dp_tol_m=dp_tol_m,
        extend_m=extend_m,
    )
