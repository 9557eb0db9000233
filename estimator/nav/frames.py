"""Geodetic <-> local East-North-Up, exact and grid-free.

One pyproj pipeline (geodetic -> ECEF -> topocentric) instead of a map projection: transverse
Mercator is off by metres at 20 km, the topocentric frame is exact at any distance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyproj
from numpy.typing import ArrayLike, NDArray

pyproj.network.set_network_enabled(False)  # type: ignore[attr-defined]  # imported there from pyproj._network, not re-exported by name

_PIPELINE = (
    "+proj=pipeline +step +proj=axisswap +order=2,1 "
    "+step +proj=unitconvert +xy_in=deg +xy_out=rad "
    "+step +proj=cart +ellps=WGS84 "
    "+step +proj=topocentric +ellps=WGS84 +lat_0={lat} +lon_0={lon} +h_0={h}"
)


@dataclass(frozen=True)
class LocalFrame:
    """A local ENU frame tangent to the WGS84 ellipsoid at (lat0, lon0, h0), degrees and metres.

    One frame is chosen per session and shared by the log and the route, so both live in the
    same metric plane.
    """

    lat0: float
    lon0: float
    h0: float = 0.0
    _transformer: pyproj.Transformer = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.lat0) and np.isfinite(self.lon0) and np.isfinite(self.h0)):
            raise ValueError(f"local frame origin is not finite: {self.lat0}, {self.lon0}")
        pipeline = _PIPELINE.format(
            lat=repr(float(self.lat0)), lon=repr(float(self.lon0)), h=repr(float(self.h0))
        )
        object.__setattr__(self, "_transformer", pyproj.Transformer.from_pipeline(pipeline))

    def to_enu(
        self, lat: ArrayLike, lon: ArrayLike, h: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Geodetic degrees (and ellipsoidal height) -> (N, 3) ENU metres; NaN in, NaN out."""
        lat_a = np.atleast_1d(np.asarray(lat, dtype=np.float64))
        lon_a = np.atleast_1d(np.asarray(lon, dtype=np.float64))
        h_a = np.zeros_like(lat_a) if h is None else np.atleast_1d(np.asarray(h, np.float64))
        h_a = np.broadcast_to(h_a, lat_a.shape)
        e, n, u = self._transformer.transform(lat_a, lon_a, h_a)
        out = np.column_stack([e, n, u]).astype(np.float64)
        bad = ~np.isfinite(lat_a) | ~np.isfinite(lon_a) | ~np.isfinite(h_a)
        out[bad | ~np.all(np.isfinite(out), axis=1)] = np.nan
        return out

    def to_geodetic(self, enu: ArrayLike) -> NDArray[np.float64]:
        """(N, 2 or 3) ENU metres -> (N, 3) lat, lon degrees and ellipsoidal height."""
        p = np.atleast_2d(np.asarray(enu, dtype=np.float64))
        up = p[:, 2] if p.shape[1] > 2 else np.zeros(len(p))
        lat, lon, h = self._transformer.transform(p[:, 0], p[:, 1], up, direction="INVERSE")
        return np.column_stack([lat, lon, h]).astype(np.float64)

    @classmethod
    def at(cls, lat: ArrayLike, lon: ArrayLike, h: ArrayLike | None = None) -> LocalFrame:
        """A frame at the first finite fix of a set of points (deterministic, data-derived)."""
        lat_a = np.atleast_1d(np.asarray(lat, np.float64))
        lon_a = np.atleast_1d(np.asarray(lon, np.float64))
        ok = np.isfinite(lat_a) & np.isfinite(lon_a)
        if not ok.any():
            raise ValueError("no finite position to place the local frame at")
        i = int(np.flatnonzero(ok)[0])
        h0 = 0.0
        if h is not None:
            h_a = np.atleast_1d(np.asarray(h, np.float64))
            h0 = float(h_a[i]) if np.isfinite(h_a[i]) else 0.0
        return cls(float(lat_a[i]), float(lon_a[i]), h0)
