"""A stress corpus no default was tuned on (issue 17): simulated tunnel drives with the faults
the world has and the samples do not: a mission route rigidly offset and rotated from the road
driven, large gyro biases, wheel-scale errors, no odometer, bad first fixes, IMU gaps, and the
parallel-road and reversed-route traps.

Every drive is a pure function of its index (:func:`drive_spec`, then :func:`build`): the same
index gives bit for bit the same log and route, so a figure measured on the corpus can be
reproduced and a drive that fails can be opened on its own. Drives are built in memory (a
:class:`~estimator.pipeline.inputs.Inputs`); ``routefuse simulate --stress N --out DIR`` writes
drive N as ``DIR/stress_N.mcap`` and ``DIR/stress_N.route.geojson`` (:meth:`Drive.route_geojson`,
through :func:`~estimator.sim.simulation.write_drive`) to open it in the inspector.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from estimator.log import Log
from estimator.nav.frames import LocalFrame
from estimator.pipeline.inputs import Inputs
from estimator.route import Route
from estimator.sim.scenarios import get_scenario
from estimator.sim.sensors import ImuErrors
from estimator.sim.simulation import Progress, simulate

Fault = Literal[
    "map_bias", "no_odometer", "bad_first_fix", "imu_gap", "parallel_road", "reversed_route"
]
BASES = ("long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel")
FAULT_CYCLE: tuple[Fault, ...] = (
    "map_bias",
    "map_bias",
    "no_odometer",
    "map_bias",
    "bad_first_fix",
    "map_bias",
    "imu_gap",
    "map_bias",
    "parallel_road",
    "reversed_route",
)
"""the fault of drive i is FAULT_CYCLE[i % 10] (and every drive has some map bias)"""
PARALLEL_SHIFT_M = 25.0
HELD_OUT_SEED_STRIDE = 100_000
"""a held-out corpus K simulates drive i with seed 1000 + i + K * this (corpus 0: 1000 + i)"""
M_PER_DEG_LAT = 111_320.0


@dataclass(frozen=True)
class DriveSpec:
    """What one corpus drive is: its base scenario, seed and the faults drawn for it."""

    index: int
    base: str
    seed: int
    fault: Fault
    bias_along_m: float
    bias_across_m: float
    bias_rotation_deg: float
    gyro_bias_deg_h: float
    """1-sigma of the simulated gyro's turn-on bias (drawn per axis)"""
    wheel_scale_error: float
    first_fix_off_m: float
    imu_gap_s: float
    corpus: int = 0
    """0: the corpus the defaults were chosen with; 1, 2, ...: held-out corpora, the same
    faults in the same proportions drawn afresh (and simulated with other seeds), on which no
    default was ever tried before it was chosen"""

    @property
    def name(self) -> str:
        """the drive's file name (``routefuse simulate --stress N [--corpus K]`` writes
        ``stress_N.*``, ``stress_cK_N.*``)"""
        return f"stress_{self.index}" if self.corpus == 0 else f"stress_c{self.corpus}_{self.index}"

    @property
    def route_is_right(self) -> bool:
        """The route is the road driven (up to its map bias), not a trap."""
        return self.fault not in ("parallel_road", "reversed_route")


def drive_spec(index: int, *, corpus: int = 0) -> DriveSpec:
    """The faults of drive ``index`` of ``corpus`` (drawn from its own generator). Corpus 0 is
    the one the defaults were chosen with (its drives were studied one by one); a held-out
    corpus (``corpus`` 1, 2, ...) draws the same kinds of fault afresh and simulates them with
    other seeds: the figures a default was not fitted to."""
    if corpus < 0:
        raise ValueError(f"corpus {corpus}: 0 (the corpus) or a held-out corpus 1, 2, ...")
    key = [20261123, index] if corpus == 0 else [20261123, index, corpus]
    rng = np.random.default_rng(key)
    fault = FAULT_CYCLE[index % len(FAULT_CYCLE)]
    return DriveSpec(
        index=index,
        base=BASES[index % len(BASES)],
        seed=1000 + index + HELD_OUT_SEED_STRIDE * corpus,
        fault=fault,
        bias_along_m=float(rng.uniform(0.0, 15.0)) * float(rng.choice([-1.0, 1.0])),
        bias_across_m=float(rng.uniform(0.0, 5.0)) * float(rng.choice([-1.0, 1.0])),
        bias_rotation_deg=float(rng.uniform(-2.0, 2.0)),
        gyro_bias_deg_h=float(rng.uniform(0.0, 720.0)),
        wheel_scale_error=float(rng.uniform(-0.02, 0.02)),
        first_fix_off_m=float(rng.uniform(20.0, 60.0)) if fault == "bad_first_fix" else 0.0,
        imu_gap_s=float(rng.uniform(20.0, 60.0)) if fault == "imu_gap" else 0.0,
        corpus=corpus,
    )


@dataclass(frozen=True)
class Drive:
    spec: DriveSpec
    inputs: Inputs
    """the log and the (faulty) route, in the drive's frame"""
    road: Route
    """the route as the road really is (for the route-relative figures, reported apart)"""
    tunnels: tuple[tuple[float, float], ...]
    """GNSS outages of the drive, log time"""
    imu_errors: ImuErrors | None = None
    """the IMU errors the simulator drew (what a calibration is checked against)"""
    imu_t: np.ndarray | None = None
    """the simulated IMU stamps ``imu_errors``' rows are at (an IMU gap cuts the log's)"""
    biased_map: Route | None = None
    """the road as the biased map draws it, before a trap moves or reverses it"""

    def on_the_road(self) -> Inputs:
        """The same drive on a map that draws the road as driven (its trap kept): the control
        that tells what the method gains from a right route from what the map's bias costs."""
        return dataclasses.replace(self.inputs, route=_trapped(self.road, self.spec.fault))

    def map_error_across(self) -> np.ndarray:
        """The biased map's offset across the road at the truth inside each GNSS outage, less
        its value at the outage's start: what even a map bias learned exactly at the portal
        leaves (the map's turn along the tunnel), concatenated over the outages."""
        log, frame = self.inputs.log, self.inputs.frame
        assert log.truth is not None and self.biased_map is not None
        truth = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)[:, :2]
        parts = []
        for start, end in self.tunnels:
            xy = truth[(log.truth.t >= start) & (log.truth.t <= end)]
            if len(xy):
                across = self.road.project(xy).lateral - self.biased_map.project(xy).lateral
                parts.append(across - across[0])
        return np.concatenate(parts) if parts else np.empty(0)

    def map_bias_at(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) the biased map's offset from the road at road points ``xy`` (N, 2): where
        the map draws each point less where it is (the quantity ``extensions.map_bias`` learns
        at its pivot, route minus road), from the drive's spec rather than from projections,
        so that a fit's error can be told from the truth's lane offset."""
        spec, points = self.spec, np.asarray(xy, np.float64)
        pivot = _position_at(self.inputs.log, self.inputs.frame, 0.5 * sum(self.tunnels[0]))
        drawn = _drawn(
            points,
            self.road,
            spec.bias_along_m,
            spec.bias_across_m,
            spec.bias_rotation_deg,
            pivot=pivot,
        )
        return drawn - points

    def route_geojson(self) -> dict[str, Any]:
        """The drive's route file (biased or a trap, as drawn), its spec in the properties;
        ``routefuse simulate --stress N`` writes it beside the log."""
        route = self.inputs.route
        assert route is not None
        doc = get_scenario(self.spec.base).route_geojson(
            route.xy,
            self.inputs.frame,
            name=f"{self.spec.name} route",
            derived_from=f"routefuse simulate --stress {self.spec.index}"
            + (f" --corpus {self.spec.corpus}" if self.spec.corpus else ""),
        )
        doc["features"][0]["properties"]["stress_drive"] = dataclasses.asdict(self.spec)
        return doc


def build(spec: DriveSpec, *, progress: Progress | None = None) -> Drive:
    """The drive of ``spec``: simulated, then its faults applied to the log and the route."""
    sc = get_scenario(spec.base)
    sc = dataclasses.replace(
        sc,
        imu=dataclasses.replace(sc.imu, gyro_turn_on_bias_deg_h=spec.gyro_bias_deg_h),
        wheel=dataclasses.replace(sc.wheel, scale_error=spec.wheel_scale_error),
    )
    sim = simulate(sc, seed=spec.seed, progress=progress)
    road = sim.route()
    log = sim.log()
    if spec.fault == "no_odometer":
        log = dataclasses.replace(log, wheel=None)
    elif spec.fault == "bad_first_fix":
        log = _first_fix_moved(log, spec.first_fix_off_m)
    elif spec.fault == "imu_gap":
        log = _imu_gap(log, sim.tunnels, spec.imu_gap_s)
    pivot = _position_at(log, sim.frame, 0.5 * sum(sim.tunnels[0]))
    route = map_biased(
        road, spec.bias_along_m, spec.bias_across_m, spec.bias_rotation_deg, pivot=pivot
    )
    return Drive(
        spec,
        Inputs(log, _trapped(route, spec.fault), sim.frame),
        road,
        sim.tunnels,
        sim.imu_errors,
        sim.imu.t,
        route,
    )


def _trapped(route: Route, fault: Fault) -> Route:
    """The route a trap drive is given: moved sideways onto a parallel road, or reversed."""
    if fault == "parallel_road":
        return Route(route.xy + PARALLEL_SHIFT_M * _left_of(route), name=route.name)
    if fault == "reversed_route":
        return Route(route.xy[::-1], name=route.name)
    return route


def _direction(route: Route) -> np.ndarray:
    d = route.xy[-1] - route.xy[0]
    out: np.ndarray = d / np.hypot(*d)
    return out


def _left_of(route: Route) -> np.ndarray:
    u = _direction(route)
    return np.array([-u[1], u[0]])


def map_biased(
    road: Route, along_m: float, across_m: float, rotation_deg: float, *, pivot: np.ndarray
) -> Route:
    """The road as a biased map draws it: rotated by ``rotation_deg`` about ``pivot`` (the
    first tunnel's middle: the offset there is the one drawn, the rotation turns it along the
    tunnel), then moved ``along_m`` along its overall direction and ``across_m`` to its left."""
    xy = _drawn(road.xy, road, along_m, across_m, rotation_deg, pivot=pivot)
    return Route(xy, name=road.name, source=road.source)


def _drawn(
    xy: np.ndarray,
    road: Route,
    along_m: float,
    across_m: float,
    rotation_deg: float,
    *,
    pivot: np.ndarray,
) -> np.ndarray:
    """Where a map biased as :func:`map_biased` says draws the road's points ``xy``."""
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    moved = xy if a == 0.0 else (xy - pivot) @ rot.T + pivot
    out: np.ndarray = moved + along_m * _direction(road) + across_m * _left_of(road)
    return out


def moved_route(road: Route, along_m: float = 10.0, across_m: float = 3.5) -> Route:
    """The road as an SD map draws it, moved rigidly ``along_m`` along its overall direction
    and ``across_m`` to its left, unturned: issue 17's moved-map case (10 m along, 3.5 m
    across)."""
    return map_biased(road, along_m, across_m, 0.0, pivot=road.xy[0])


def _position_at(log: Log, frame: LocalFrame, t: float) -> np.ndarray:
    """The truth's E, N at log time ``t``."""
    truth = log.truth
    assert truth is not None
    enu = frame.to_enu(truth.lat, truth.lon, truth.alt)
    return np.array([np.interp(t, truth.t, enu[:, i]) for i in range(2)])


def _first_fix_moved(log: Log, metres: float) -> Log:
    g = log.gnss
    lat = g.lat.copy()
    first = int(np.flatnonzero(g.valid)[0])
    lat[first] += metres / M_PER_DEG_LAT
    return dataclasses.replace(log, gnss=dataclasses.replace(g, lat=lat))


def _imu_gap(log: Log, tunnels: tuple[tuple[float, float], ...], seconds: float) -> Log:
    """No IMU for ``seconds`` in the middle of the first tunnel (GNSS and wheels go on)."""
    a, b = tunnels[0]
    mid = 0.5 * (a + b)
    imu = log.imu
    keep = ~((imu.t >= mid - seconds / 2) & (imu.t < mid + seconds / 2))
    cut = dataclasses.replace(imu, t=imu.t[keep], gyro=imu.gyro[keep], accel=imu.accel[keep])
    return dataclasses.replace(log, imu=cut)
