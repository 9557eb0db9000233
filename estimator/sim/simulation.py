"""Run a scenario: truth at every sensor's stamps, sensor errors, the map route."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from estimator.errors import ConfigError
from estimator.log import GNSS_NO_FIX, GnssData, ImuData, Log, TopicInfo, TruthData, WheelData
from estimator.nav.frames import LocalFrame
from estimator.route import Route
from estimator.sim.road import Road
from estimator.sim.scenario import Scenario
from estimator.sim.sdmap import map_route, write_geojson
from estimator.sim.sensors import ImuErrors, apply_imu_errors, apply_wheel_errors, gnss_errors
from estimator.sim.trajectory import Kinematics, Trajectory

F64 = NDArray[np.float64]
Progress = Callable[[str, float], None]

_CHUNK = 100_000
BAG_SUFFIX = {"mcap": ".mcap", "sqlite3": "", "ros1": ".bag"}
"""file name suffix of a bag per storage (a sqlite3 bag is a folder)"""


@dataclass(frozen=True)
class Simulation:
    """A simulated drive: truth, sensor streams (as :mod:`estimator.log` data) and the route.

    Every time is on the log clock (Unix seconds); ``truth`` holds the true state at the IMU
    stamps, ``ideal_gyro`` / ``ideal_accel`` what a perfect IMU measures there.
    """

    scenario: Scenario
    seed: int
    imu_rate_hz: float
    frame: LocalFrame
    trajectory: Trajectory
    t0: float
    """log time of the start of the drive, s"""
    truth: Kinematics
    ideal_gyro: F64
    ideal_accel: F64
    imu_errors: ImuErrors
    imu: ImuData
    wheel: WheelData
    gnss: GnssData
    truth_fix: TruthData
    route_xy: F64
    """(M, 2) EN route vertices in ``frame``"""
    tunnels: tuple[tuple[float, float], ...]
    """(entry, exit) log times of every tunnel"""
    gnss_degraded: tuple[tuple[float, float], ...]
    """intervals of degraded fixes at the portals, log times"""

    @property
    def duration_s(self) -> float:
        return float(self.truth.t[-1] - self.truth.t[0])

    @property
    def distance_m(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.truth.position, axis=0), axis=1)))

    def log(self, path: str = "") -> Log:
        """The sensor streams as the estimator's :class:`Log` (what the bag loader returns)."""
        topics = (
            TopicInfo("/imu/data", "sensor_msgs/msg/Imu", len(self.imu.t), "imu"),
            TopicInfo("/gnss/fix", "sensor_msgs/msg/NavSatFix", len(self.gnss.t), "gnss"),
            TopicInfo("/wheel/odom", "nav_msgs/msg/Odometry", len(self.wheel.t), "wheel"),
            TopicInfo(
                "/ground_truth/fix", "sensor_msgs/msg/NavSatFix", len(self.truth_fix.t), "truth"
            ),
        )
        return Log(
            path=path or f"<simulated {self.scenario.name}>",
            imu=self.imu,
            gnss=self.gnss,
            wheel=self.wheel,
            truth=self.truth_fix,
            topics=topics,
        )

    def route(self) -> Route:
        return Route(self.route_xy, name=self.scenario.name, source="simulated")

    def route_geojson(self) -> dict[str, Any]:
        sc = self.scenario
        return sc.route_geojson(
            self.route_xy,
            self.frame,
            name=f"{sc.name} route",
            derived_from=f"routefuse simulate {sc.name} --seed {self.seed}",
        )

    def write(
        self,
        out_dir: str | Path,
        *,
        storage: Literal["mcap", "sqlite3", "ros1"] = "mcap",
        overwrite: bool = False,
    ) -> tuple[Path, Path]:
        """Write the bag (``<name>.mcap``, a ``<name>/`` sqlite3 bag folder or ``<name>.bag``)
        and ``<name>.route.geojson`` into ``out_dir``; returns both paths."""
        return write_drive(
            out_dir,
            self.scenario.name,
            self.log(),
            self.route_geojson(),
            storage=storage,
            overwrite=overwrite,
        )


def write_drive(
    out_dir: str | Path,
    name: str,
    log: Log,
    route_doc: dict[str, Any],
    *,
    storage: Literal["mcap", "sqlite3", "ros1"] = "mcap",
    overwrite: bool = False,
) -> tuple[Path, Path]:
    """Write ``log``'s streams as a bag named ``name`` and ``route_doc`` as
    ``<name>.route.geojson`` into ``out_dir`` (a simulated scenario or a stress-corpus drive:
    one writer, so both open the same way); returns both paths."""
    from estimator.io.bagwrite import write_bag

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bag = out / f"{name}{BAG_SUFFIX[storage]}"
    route = out / f"{name}.route.geojson"
    if bag.exists():
        if not overwrite:
            raise ConfigError(bag, "already exists (pass overwrite to replace it)")
        if bag.is_dir():
            shutil.rmtree(bag)
        else:
            bag.unlink()
    write_bag(bag, imu=log.imu, gnss=log.gnss, wheel=log.wheel, truth=log.truth, storage=storage)
    write_geojson(route, route_doc)
    return bag, route


def _stamps(t0_ns: int, rate_hz: float, duration_s: float) -> tuple[NDArray[np.int64], F64]:
    n = int(np.floor(duration_s * rate_hz + 1e-9)) + 1
    rel_ns = np.round(np.arange(n) * (1e9 / rate_hz)).astype(np.int64)
    return t0_ns + rel_ns, rel_ns / 1e9


def _at(traj: Trajectory, t: F64, progress: Progress | None, stage: str) -> Kinematics:
    parts = []
    for i in range(0, len(t), _CHUNK):
        parts.append(traj.at(t[i : i + _CHUNK]))
        if progress:
            progress(stage, min(i + _CHUNK, len(t)) / len(t))
    if len(parts) == 1:
        return parts[0]
    return Kinematics(
        **{
            f: np.concatenate([getattr(p, f) for p in parts])
            for f in Kinematics.__dataclass_fields__
        }
    )


def _in_any(t: F64, intervals: list[tuple[float, float]]) -> NDArray[np.bool_]:
    out = np.zeros(len(t), bool)
    for a, b in intervals:
        out |= (t >= a) & (t < b)
    return out


def _gnss(
    sc: Scenario,
    traj: Trajectory,
    frame: LocalFrame,
    rng: np.random.Generator,
    t0_ns: int,
    duration: float,
    tunnel_t: list[tuple[float, float]],
) -> tuple[GnssData, list[tuple[float, float]]]:
    """The receiver's fixes (none in a tunnel and until reacquisition, degraded around the
    portals) and the degraded intervals, relative to the start."""
    g = sc.gnss
    blocked = [(a, b + g.reacquisition_s) for a, b in tunnel_t]
    windows = [(a - g.degraded_before_s, a, 0.0, 1.0) for a, _ in tunnel_t] + [
        (b + g.reacquisition_s, b + g.reacquisition_s + g.degraded_after_s, 1.0, 0.0)
        for _, b in tunnel_t
    ]
    degraded = [(a, b) for a, b, _, _ in windows if b > a]
    gnss_ns, gnss_rel = _stamps(t0_ns, g.rate_hz, duration)
    no_fix = _in_any(gnss_rel, blocked)
    err, var, _ = gnss_errors(g, rng, gnss_rel, windows)
    kg = traj.at(gnss_rel)
    geo = frame.to_geodetic(kg.position + err)
    geo[no_fix] = np.nan
    var[no_fix] = np.nan
    status = np.where(no_fix, GNSS_NO_FIX, 0).astype(np.int8)
    keep = ~no_fix if sc.gnss_outage == "silent" else np.ones(len(gnss_rel), bool)
    gnss = GnssData(
        t=(gnss_ns / 1e9)[keep],
        lat=geo[keep, 0],
        lon=geo[keep, 1],
        alt=geo[keep, 2],
        status=status[keep],
        cov_enu=var[keep],
    )
    return gnss, degraded


def _truth_fix(
    sc: Scenario, traj: Trajectory, frame: LocalFrame, t0_ns: int, duration: float
) -> TruthData:
    truth_ns, truth_rel = _stamps(t0_ns, sc.truth_rate_hz, duration)
    kt = traj.at(truth_rel)
    tgeo = frame.to_geodetic(kt.position)
    return TruthData(
        t=truth_ns / 1e9, lat=tgeo[:, 0], lon=tgeo[:, 1], alt=tgeo[:, 2], heading=kt.heading
    )


def _route_xy(sc: Scenario, road: Road, frame: LocalFrame) -> F64:
    """The scenario's own route vertices, or the map route of the road (a vertex every 2 m
    mapped by ``sc.route``)."""
    if sc.route_lonlat is not None:
        ll = np.asarray(sc.route_lonlat, np.float64)
        route_xy: F64 = frame.to_enu(ll[:, 1], ll[:, 0])[:, :2]
        return route_xy
    sig = np.linspace(0.0, road.length, max(int(np.ceil(road.length / 2.0)), 1) + 1)
    return map_route(road.xy(sig), sc.route)


def simulate(
    scenario: str | Scenario,
    *,
    seed: int = 0,
    imu_rate_hz: float = 100.0,
    duration_s: float | None = None,
    duration_scale: float = 1.0,
    perfect: bool = False,
    progress: Progress | None = None,
) -> Simulation:
    """Simulate a scenario (by name or given).

    ``duration_s`` cuts the drive short; ``duration_scale`` stretches its straights (see
    :meth:`Scenario.scaled`); ``perfect`` switches every sensor error off (tunnels still block
    GNSS). The same arguments give bit-for-bit the same simulation: each sensor draws from its
    own ``Generator(PCG64)`` spawned from ``seed``.
    """
    if isinstance(scenario, str):
        from estimator.sim.scenarios import get_scenario

        scenario = get_scenario(scenario)
    if not imu_rate_hz > 0:
        raise ConfigError(None, f"IMU rate must be positive, got {imu_rate_hz}")
    sc = scenario.scaled(duration_scale)
    if perfect:
        sc = sc.with_perfect_sensors()
    road: Road = sc.road()
    lat0, lon0, h0 = sc.origin
    frame = LocalFrame(lat0, lon0, h0)
    traj = Trajectory(road, lane_offset_m=sc.lane_offset_m, lat0_deg=lat0, h0_m=h0)
    duration = traj.duration_s if duration_s is None else min(duration_s, traj.duration_s)
    if not duration > 0:
        raise ConfigError(None, f"duration must be positive, got {duration_s}")
    rng_imu, rng_wheel, rng_gnss = (
        np.random.Generator(np.random.PCG64(s)) for s in np.random.SeedSequence(seed).spawn(3)
    )
    t0_ns = int(sc.start_unix_s) * 1_000_000_000
    t0 = t0_ns / 1e9

    imu_ns, imu_rel = _stamps(t0_ns, imu_rate_hz, duration)
    truth = _at(traj, imu_rel, progress, "truth")
    f_b, w_ib = traj.ideal_imu(truth)
    gyro, accel, imu_err = apply_imu_errors(sc.imu, rng_imu, imu_rate_hz, w_ib, f_b)
    imu = ImuData(t=imu_ns / 1e9, gyro=gyro, accel=accel)

    wheel_ns, wheel_rel = _stamps(t0_ns, sc.wheel.rate_hz, duration)
    wheel_speed = apply_wheel_errors(sc.wheel, rng_wheel, traj.at(wheel_rel).speed)
    wheel = WheelData(t=wheel_ns / 1e9, speed=wheel_speed)

    tunnel_t = [
        (float(a), float(b))
        for a, b in (traj.time_at([s0, s1]) for s0, s1 in road.tunnel_intervals())
    ]
    gnss, degraded = _gnss(sc, traj, frame, rng_gnss, t0_ns, duration, tunnel_t)
    truth_fix = _truth_fix(sc, traj, frame, t0_ns, duration)
    route_xy = _route_xy(sc, road, frame)
    if progress:
        progress("sensors", 1.0)
    return Simulation(
        scenario=sc,
        seed=seed,
        imu_rate_hz=float(imu_rate_hz),
        frame=frame,
        trajectory=traj,
        t0=t0,
        truth=replace(truth, t=imu.t.copy()),
        ideal_gyro=w_ib,
        ideal_accel=f_b,
        imu_errors=imu_err,
        imu=imu,
        wheel=wheel,
        gnss=gnss,
        truth_fix=truth_fix,
        route_xy=route_xy,
        tunnels=tuple((t0 + a, t0 + b) for a, b in tunnel_t if a < duration),
        gnss_degraded=tuple((t0 + a, t0 + b) for a, b in degraded if a < duration),
    )
