"""A scenario: the road, the lane, the sensors and the map, everything a drive needs."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from estimator.nav.frames import LocalFrame
from estimator.sim.road import Piece, Road, scale_pieces
from estimator.sim.sdmap import RouteModel, route_geojson
from estimator.sim.sensors import GnssErrorModel, ImuErrorModel, WheelErrorModel

GnssOutage = Literal["no_fix", "silent"]
"""How a receiver reports a tunnel: ``no_fix`` = NavSatFix with status -1 and NaN position at
its usual rate, ``silent`` = no message at all."""


@dataclass(frozen=True)
class Scenario:
    """One simulated drive. ``origin`` is the local ENU frame's origin (lat, lon degrees,
    ellipsoidal height m); the road starts at ``start_xy`` in that frame, heading
    ``heading0_deg`` (ENU yaw, counter-clockwise from East), at height 0."""

    name: str
    description: str
    pieces: tuple[Piece, ...]
    origin: tuple[float, float, float]
    heading0_deg: float = 0.0
    start_xy: tuple[float, float] = (0.0, 0.0)
    lane_offset_m: float = -1.75
    """lateral offset of the driven lane from the centreline, positive = left"""
    imu: ImuErrorModel = field(default_factory=ImuErrorModel)
    wheel: WheelErrorModel = field(default_factory=WheelErrorModel)
    gnss: GnssErrorModel = field(default_factory=GnssErrorModel)
    gnss_outage: GnssOutage = "no_fix"
    route: RouteModel = field(default_factory=RouteModel)
    truth_rate_hz: float = 10.0
    start_unix_s: int = 1_700_000_000
    """time stamp of the first sample (whole seconds)"""
    max_accel_m_s2: float = 1.0
    """peak longitudinal acceleration of the speed ramps (below 2 m/s^2 by design)"""
    route_lonlat: tuple[tuple[float, float], ...] | None = None
    """a given map route (lon, lat) written instead of the mapped centreline"""
    source: str = "routefuse simulate"
    attribution: str = ""

    def road(self) -> Road:
        return Road(
            self.pieces,
            start_xy=self.start_xy,
            heading0=float(np.radians(self.heading0_deg)),
            max_accel_m_s2=self.max_accel_m_s2,
        )

    def scaled(self, duration_scale: float) -> Scenario:
        """The same scenario with its straights (open sky and tunnels) stretched."""
        if duration_scale == 1.0:
            return self
        return replace(self, pieces=scale_pieces(self.pieces, duration_scale))

    def route_geojson(
        self, xy: ArrayLike, frame: LocalFrame, *, name: str, derived_from: str
    ) -> dict[str, Any]:
        """The route file of a drive of this scenario (its route model, lane and attribution
        in the properties): the simulated route, or a stress drive's biased one."""
        return route_geojson(
            xy,
            frame,
            name=name,
            source=self.source,
            derived_from=derived_from,
            model=self.route,
            lateral_offset_m=-self.lane_offset_m,
            attribution=self.attribution,
        )

    def with_perfect_sensors(self) -> Scenario:
        """Ideal IMU and wheel speed, exact GNSS in open sky (tunnels still block it)."""
        return replace(
            self,
            imu=ImuErrorModel.perfect(),
            wheel=WheelErrorModel.perfect(self.wheel.rate_hz),
            gnss=GnssErrorModel.perfect(self.gnss.rate_hz),
        )
