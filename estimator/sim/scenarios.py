"""The named scenarios: the bundled sample logs, a short one for tests, and long drives for
benchmarks.

Each sample scenario begins with at least a minute of open sky with turns (so a filter can
calibrate its biases and wheel scale) and ends with open sky after its last tunnel. The three
synthetic ones are modelled on the paper's experiments in a spiral extra-long expressway tunnel
in Hebei (a long, a curved and a multi-segment stretch), placed in Hebei's mountains.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.errors import ConfigError
from estimator.nav.frames import LocalFrame
from estimator.sim.monaco import ATTRIBUTION, LONLAT, TUNNEL_END_VERTEX, TUNNEL_START_VERTEX
from estimator.sim.road import Piece, Road, pieces_from_polyline, straight, turn
from estimator.sim.scenario import Scenario
from estimator.sim.sdmap import RouteModel, map_route
from estimator.sim.trajectory import Trajectory

F64 = NDArray[np.float64]


def _open_sky_warmup(speed: float) -> tuple[Piece, ...]:
    """About 80 s of open road with left and right turns."""
    return (
        straight(150, speed_m_s=speed * 0.8)
        + turn(50, 250, speed_m_s=speed * 0.7)
        + straight(200, speed_m_s=speed)
        + turn(-75, 220, speed_m_s=speed * 0.7)
        + straight(200, speed_m_s=speed)
        + turn(35, 400)
        + straight(100)
    )


def long_tunnel() -> Scenario:
    pieces = (
        _open_sky_warmup(20.0)
        + straight(150, speed_m_s=22.0, grade=0.01)
        + straight(3000, tunnel=True)
        + turn(-12, 2500, transition_m=120, tunnel=True)
        + straight(2600, tunnel=True, grade=-0.005)
        + turn(8, 3000, transition_m=120, tunnel=True)
        + straight(1000, tunnel=True)
        + straight(400, speed_m_s=22.0, grade=0.0)
        + turn(-30, 400, speed_m_s=18.0)
        + straight(300)
    )
    return Scenario(
        name="long_tunnel",
        description="7.8 km almost straight expressway tunnel at 79 km/h after 103 s of open "
        "sky with turns; the paper's long-tunnel case (DR drift of tens of metres)",
        pieces=pieces,
        origin=(40.12, 115.21, 620.0),
        heading0_deg=20.0,
        gnss_outage="no_fix",
    )


def spiral_tunnel() -> Scenario:
    pieces = (
        _open_sky_warmup(18.0)
        + straight(250, speed_m_s=18.0, grade=0.03)
        + straight(300, tunnel=True)
        + turn(280, 330, transition_m=90, tunnel=True, speed_m_s=17.0)
        + straight(600, tunnel=True)
        + turn(-40, 500, tunnel=True)
        + straight(700, tunnel=True, grade=0.0)
        + straight(400, speed_m_s=20.0)
        + turn(30, 350)
        + straight(200)
    )
    return Scenario(
        name="spiral_tunnel",
        description="3.7 km climbing spiral tunnel (280 deg at R 330 m, 3 % grade, the exit "
        "passes under the entry) at 61 km/h; the paper's curved-tunnel case",
        pieces=pieces,
        origin=(40.31, 115.47, 780.0),
        heading0_deg=-35.0,
        gnss_outage="no_fix",
    )


def multi_tunnel() -> Scenario:
    pieces = (
        _open_sky_warmup(20.0)
        + straight(150, speed_m_s=22.0)
        + straight(1500, tunnel=True)
        + straight(150)
        + turn(25, 600)
        + straight(100)
        + straight(800, tunnel=True, grade=0.02)
        + turn(-45, 700, tunnel=True)
        + straight(600, tunnel=True)
        + straight(150, grade=0.0)
        + turn(-20, 500)
        + straight(150)
        + straight(600, tunnel=True)
        + turn(15, 1500, tunnel=True)
        + straight(300, tunnel=True)
        + straight(500)
        + turn(40, 300, speed_m_s=17.0)
        + straight(200)
    )
    return Scenario(
        name="multi_tunnel",
        description="three tunnels (1.5, 2.0 and 1.35 km) with short open gaps at 79 km/h; the "
        "paper's multi-segment case; the receiver is silent in tunnels (no NavSatFix at all)",
        pieces=pieces,
        origin=(39.87, 114.68, 450.0),
        heading0_deg=75.0,
        gnss_outage="silent",
    )


def polyline_scenario(
    name: str,
    lonlat: ArrayLike,
    *,
    tunnel_intervals_m: Sequence[tuple[float, float]],
    description: str = "",
    origin_h_m: float = 0.0,
    smoothing_m: float = 20.0,
    speed_m_s: float = 15.0,
    tunnel_speed_m_s: float | None = None,
    grade: float = 0.0,
    approach: Sequence[Piece] | None = None,
    exit_m: float = 300.0,
    exit_speed_m_s: float | None = None,
    max_lateral_accel_m_s2: float = 2.0,
    **scenario_options: Any,
) -> Scenario:
    """A drive along a given route polyline (lon, lat), e.g. a real road from a map.

    The polyline is smoothed into a drivable road (:func:`pieces_from_polyline`); the
    ``approach`` pieces (default: :func:`_open_sky_warmup`, about 80 s with turns) are joined
    tangentially before its start and a straight of ``exit_m`` after its end. Where a curve
    would need more than ``max_lateral_accel_m_s2`` the vehicle slows down for it.
    ``tunnel_intervals_m`` are arc-length intervals of the given polyline. The route written is
    the given polyline's own vertices (a real map's spacing), with the approach and exit mapped
    as :func:`.sdmap.map_route` does and 200 m straight extensions.
    """
    ll = np.asarray(lonlat, np.float64)
    lat0, lon0 = float(ll[0, 1]), float(ll[0, 0])
    frame = LocalFrame(lat0, lon0, origin_h_m)
    xy = frame.to_enu(ll[:, 1], ll[:, 0])[:, :2]
    road_pieces, road_start, road_heading = pieces_from_polyline(
        xy,
        smoothing_m=smoothing_m,
        speed_m_s=speed_m_s,
        grade=grade,
        tunnel_intervals=tunnel_intervals_m,
    )
    approach = tuple(_open_sky_warmup(speed_m_s) if approach is None else approach)
    probe = Road(approach)
    start, heading0 = _approach_placement(probe, road_start, road_heading)
    road_pieces = _tunnel_speed_and_exit_grade(road_pieces, tunnel_speed_m_s)
    road_pieces = _cap_speed_in_curves(road_pieces, speed_m_s, max_lateral_accel_m_s2)
    exit_road = straight(exit_m, speed_m_s=exit_speed_m_s)
    pieces = approach + road_pieces + exit_road
    road = Road(pieces, start_xy=start, heading0=heading0)
    route_model: RouteModel = scenario_options.pop("route", RouteModel())
    route_lonlat = _polyline_route(
        road,
        xy,
        frame,
        route_model,
        polyline_sigma=(probe.length, probe.length + sum(p.length_m for p in road_pieces)),
    )
    return Scenario(
        name=name,
        description=description or f"a drive along the given polyline {name}",
        pieces=pieces,
        origin=(lat0, lon0, origin_h_m),
        heading0_deg=float(np.degrees(heading0)),
        start_xy=start,
        route_lonlat=route_lonlat,
        route=route_model,
        **scenario_options,
    )


def _approach_placement(
    approach: Road, road_start: tuple[float, float], road_heading: float
) -> tuple[tuple[float, float], float]:
    """Start point and heading that make ``approach`` end tangentially where the road starts."""
    end_xy = approach.xy(approach.length)[0]
    heading0 = road_heading - float(approach.heading(approach.length)[0])
    c, s = np.cos(heading0), np.sin(heading0)
    start = np.asarray(road_start) - np.array(
        [c * end_xy[0] - s * end_xy[1], s * end_xy[0] + c * end_xy[1]]
    )
    return (float(start[0]), float(start[1])), heading0


def _tunnel_speed_and_exit_grade(
    pieces: tuple[Piece, ...], tunnel_speed_m_s: float | None
) -> tuple[Piece, ...]:
    """The tunnel's own speed from its first piece on, level road again after its last."""
    in_tunnel = [i for i, p in enumerate(pieces) if p.tunnel]
    if not in_tunnel:
        return pieces
    n_in, n_out = in_tunnel[0], in_tunnel[-1] + 1
    pieces_list = list(pieces)
    if tunnel_speed_m_s is not None:
        pieces_list[n_in] = replace(pieces_list[n_in], speed_m_s=tunnel_speed_m_s)
    if n_out < len(pieces_list):
        pieces_list[n_out] = replace(pieces_list[n_out], grade=0.0)
    return tuple(pieces_list)


def _polyline_route(
    road: Road,
    polyline_xy: F64,
    frame: LocalFrame,
    route_model: RouteModel,
    *,
    polyline_sigma: tuple[float, float],
) -> tuple[tuple[float, float], ...]:
    """(lon, lat) route: the given polyline's own vertices, the approach and the exit mapped
    as :func:`.sdmap.map_route` does, and straight extensions of ``route_model.extend_m``.
    ``polyline_sigma`` is where the polyline's part of ``road`` starts and ends."""
    a_len, b_len = polyline_sigma
    unextended = replace(route_model, extend_m=0)
    before = map_route(road.xy(np.linspace(0.0, a_len, 200)), unextended)
    after = map_route(road.xy(np.linspace(b_len, road.length, 100)), unextended)
    vertices = np.vstack([before[:-1], polyline_xy, after[1:]])
    d0 = (vertices[0] - vertices[1]) / np.hypot(*(vertices[0] - vertices[1]))
    d1 = (vertices[-1] - vertices[-2]) / np.hypot(*(vertices[-1] - vertices[-2]))
    vertices = np.vstack(
        [
            vertices[0] + route_model.extend_m * d0,
            vertices,
            vertices[-1] + route_model.extend_m * d1,
        ]
    )
    geo = frame.to_geodetic(vertices + np.asarray(route_model.bias_enu_m, np.float64))
    return tuple((round(float(lon), 8), round(float(lat), 8)) for lat, lon, _ in geo)


def _cap_speed_in_curves(
    pieces: tuple[Piece, ...], speed_m_s: float, max_lateral_accel: float
) -> tuple[Piece, ...]:
    """Slow down for curves: per-piece targets capped at sqrt(a_lat / |curvature|) (over the
    piece and 40 m either side), reached with 0.5 m/s^2 planning, in 0.5 m/s steps."""
    target = []
    cur = speed_m_s
    for p in pieces:
        cur = cur if p.speed_m_s is None else p.speed_m_s
        target.append(cur)
    v = np.array(target)
    length = np.array([p.length_m for p in pieces])
    kmax = np.maximum(
        np.abs([p.curvature_start for p in pieces]), np.abs([p.curvature_end for p in pieces])
    )
    mid = np.cumsum(length) - 0.5 * length
    lo = np.searchsorted(mid, mid - 40.0)
    hi = np.searchsorted(mid, mid + 40.0, side="right")
    window = np.array([kmax[a:b].max() for a, b in zip(lo, hi, strict=True)])
    cap = np.sqrt(max_lateral_accel / np.maximum(window, 1e-9))
    if np.all(v <= cap):
        return pieces
    v = np.minimum(v, cap)
    accel = 0.5
    for i in range(1, len(v)):  # speeding up
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + 2 * accel * length[i - 1]))
    for i in range(len(v) - 2, -1, -1):  # slowing down before a curve
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * accel * length[i]))
    v = np.maximum(np.floor(v * 2.0) / 2.0, 1.0)
    out = []
    prev = None
    for p, vi in zip(pieces, v, strict=True):
        out.append(replace(p, speed_m_s=float(vi) if vi != prev else None))
        prev = vi
    return tuple(out)


def monaco_tunnel() -> Scenario:
    ll = np.asarray(LONLAT, np.float64)
    h0 = 120.0
    xy = LocalFrame(float(ll[0, 1]), float(ll[0, 0]), h0).to_enu(ll[:, 1], ll[:, 0])[:, :2]
    s_v = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    # a synthetic approach: the real lead-in is 310 m only
    approach = (
        straight(100, speed_m_s=12.0)
        + turn(-70, 120, transition_m=40, speed_m_s=10.0)
        + straight(150, speed_m_s=14.0)
        + turn(60, 150, transition_m=40, speed_m_s=11.0)
        + straight(100, speed_m_s=13.0)
        + turn(-25, 250)
        + straight(50)
    )
    return polyline_scenario(
        "monaco_tunnel",
        LONLAT,
        tunnel_intervals_m=[(float(s_v[TUNNEL_START_VERTEX]), float(s_v[TUNNEL_END_VERTEX]))],
        description="the real Tunnel de Monaco (A 500, 1.6 km, S-bend; OSM geometry smoothed "
        "with sigma 20 m) at 50 km/h after 108 s of synthetic approach and OSM lead-in; the "
        "route is the raw OSM polyline (segments up to 512 m) plus the mapped approach and "
        "exit; silent receiver",
        origin_h_m=h0,
        smoothing_m=20.0,
        speed_m_s=12.0,
        tunnel_speed_m_s=14.0,
        grade=-0.02,
        approach=approach,
        exit_m=350.0,
        exit_speed_m_s=15.0,
        gnss_outage="silent",
        attribution=ATTRIBUTION,
        source="routefuse simulate (OpenStreetMap geometry)",
    )


def short_tunnel() -> Scenario:
    """A 75 s drive for tests: a turn, a 400 m tunnel, open sky."""
    pieces = (
        straight(150, speed_m_s=15.0)
        + turn(60, 200)
        + straight(150)
        + straight(400, tunnel=True)
        + straight(150)
    )
    return Scenario(
        name="short_tunnel",
        description="75 s test drive with one 400 m tunnel",
        pieces=pieces,
        origin=(45.0, 7.0, 300.0),
        heading0_deg=0.0,
    )


def long_drive(minutes: float, *, seed: int = 0) -> Scenario:
    """A procedurally generated drive of about ``minutes`` (benchmarks): random straights and
    turns at 12-30 m/s, with a tunnel of 1-4 minutes every few minutes."""
    rng = np.random.Generator(np.random.PCG64(seed + 1_000_003))
    target = minutes * 60.0
    pieces: list[Piece] = list(_open_sky_warmup(20.0))
    t = 90.0
    next_tunnel = 180.0
    while t < 1.2 * target + 120.0:
        speed = float(rng.uniform(12.0, 30.0))
        grade = float(np.round(rng.uniform(-0.04, 0.04), 3))
        if t >= next_tunnel:
            length = float(rng.uniform(60.0, 240.0)) * speed
            pieces += straight(length, speed_m_s=speed, grade=grade, tunnel=True)
            pieces += straight(200.0)
            next_tunnel = t + length / speed + float(rng.uniform(120.0, 420.0))
            t += length / speed + 200.0 / speed
            continue
        length = float(rng.uniform(150.0, 1500.0))
        pieces += straight(length, speed_m_s=speed, grade=grade)
        radius = float(rng.uniform(max(150.0, speed**2 / 1.5), 900.0))
        angle = float(rng.uniform(15.0, 110.0)) * float(rng.choice([-1.0, 1.0]))
        pieces += turn(angle, radius)
        t += (length + abs(np.radians(angle)) * radius) / speed
    # cut at the last open straight that ends before the target time, then a final straight
    road = Road(tuple(pieces))
    traj = Trajectory(road)
    ends = traj.time_at(road.piece_bounds[1:])
    cut = max(
        i
        for i, p in enumerate(pieces)
        if p.curvature_start == p.curvature_end == 0.0 and not p.tunnel and ends[i] <= target - 20.0
    )
    final = max(300.0, (target - float(ends[cut])) * 20.0)
    pieces = [*pieces[: cut + 1], *straight(final, speed_m_s=20.0, grade=0.0)]
    return Scenario(
        name=f"long_drive_{minutes:g}min",
        description=f"about {minutes:g} minutes of random road with tunnels (benchmarks)",
        pieces=tuple(pieces),
        origin=(48.0, 11.0, 500.0),
    )


SCENARIOS: dict[str, Callable[[], Scenario]] = {
    "long_tunnel": long_tunnel,
    "spiral_tunnel": spiral_tunnel,
    "multi_tunnel": multi_tunnel,
    "monaco_tunnel": monaco_tunnel,
    "short_tunnel": short_tunnel,
    "long_drive_10min": lambda: long_drive(10.0),
    "long_drive_60min": lambda: long_drive(60.0),
}


def get_scenario(name: str) -> Scenario:
    try:
        return SCENARIOS[name]()
    except KeyError:
        raise ConfigError(
            None, f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})"
        ) from None
