"""The named scenarios: the bundled sample logs, a short one for tests, and long drives for
benchmarks.

Each sample scenario begins with at least a minute of open sky with turns (so a filter can
calibrate its biases and wheel scale) and ends with open sky after its last tunnel. The three
synthetic ones are modelled on the paper's experiments in a spiral extra-long expressway tunnel
in Hebei (a long, a curved and a multi-segment stretch), placed in Hebei's mountains.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..errors import ConfigError
from ..geo import LocalFrame
from .monaco import ATTRIBUTION, LONLAT, TUNNEL_END_VERTEX, TUNNEL_START_VERTEX
from .road import Piece, Road, pieces_from_polyline, straight, turn
from .scenario import Scenario
from .sdmap import RouteModel, map_route
from .trajectory import Trajectory


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
        "sky with turns; the paper's long-tunnel case (DR drift of 100+ m)",
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


def monaco_tunnel() -> Scenario:
    ll = np.asarray(LONLAT, np.float64)
    lat0, lon0, h0 = float(ll[0, 1]), float(ll[0, 0]), 120.0
    frame = LocalFrame(lat0, lon0, h0)
    xy = frame.to_enu(ll[:, 1], ll[:, 0])[:, :2]
    s_v = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    tunnel = [(float(s_v[TUNNEL_START_VERTEX]), float(s_v[TUNNEL_END_VERTEX]))]
    osm, osm_start, osm_heading = pieces_from_polyline(
        xy, smoothing_m=20.0, speed_m_s=12.0, grade=-0.02, tunnel_intervals=tunnel
    )
    # a synthetic approach ending where the OSM lead-in starts, tangent to it
    approach = (
        straight(100, speed_m_s=12.0)
        + turn(-70, 120, transition_m=40, speed_m_s=10.0)
        + straight(150, speed_m_s=14.0)
        + turn(60, 150, transition_m=40, speed_m_s=11.0)
        + straight(100, speed_m_s=13.0)
        + turn(-25, 250)
        + straight(50)
    )
    probe = Road(approach)
    end_xy = probe.xy(probe.length)[0]
    heading0 = osm_heading - float(probe.heading(probe.length)[0])
    c, s = np.cos(heading0), np.sin(heading0)
    start = np.asarray(osm_start) - np.array(
        [c * end_xy[0] - s * end_xy[1], s * end_xy[0] + c * end_xy[1]]
    )
    # tunnel speed after the lead-in; open road again after it
    n_in = next(i for i, p in enumerate(osm) if p.tunnel)
    n_out = max(i for i, p in enumerate(osm) if p.tunnel) + 1
    osm = (
        *osm[:n_in],
        replace(osm[n_in], speed_m_s=14.0),
        *osm[n_in + 1 : n_out],
        replace(osm[n_out], grade=0.0),
        *osm[n_out + 1 :],
    )
    exit_road = straight(350, speed_m_s=15.0)
    pieces = approach + osm + exit_road
    # the map: the approach and exit as a map would draw them, the OSM vertices unchanged
    road = Road(pieces, start_xy=(float(start[0]), float(start[1])), heading0=heading0)
    a_len, o_len = probe.length, sum(p.length_m for p in osm)
    route_model = RouteModel()
    before = map_route(road.xy(np.linspace(0.0, a_len, 200)), replace(route_model, extend_m=0))
    after = map_route(
        road.xy(np.linspace(a_len + o_len, road.length, 100)), replace(route_model, extend_m=0)
    )
    vertices = np.vstack([before[:-1], xy, after[1:]])
    d0 = (vertices[0] - vertices[1]) / np.hypot(*(vertices[0] - vertices[1]))
    d1 = (vertices[-1] - vertices[-2]) / np.hypot(*(vertices[-1] - vertices[-2]))
    vertices = np.vstack(
        [
            vertices[0] + route_model.extend_m * d0,
            vertices,
            vertices[-1] + route_model.extend_m * d1,
        ]
    )
    geo = frame.to_geodetic(vertices)
    route_lonlat = tuple((round(float(lon), 8), round(float(lat), 8)) for lat, lon, _ in geo)
    return Scenario(
        name="monaco_tunnel",
        description="the real Tunnel de Monaco (A 500, 1.6 km, S-bend; OSM geometry smoothed "
        "with sigma 20 m) at 50 km/h after 108 s of synthetic approach and OSM lead-in; the "
        "route is the raw OSM "
        "polyline (segments up to 512 m) plus the mapped approach and exit; silent receiver",
        pieces=pieces,
        origin=(lat0, lon0, h0),
        heading0_deg=float(np.degrees(heading0)),
        start_xy=(float(start[0]), float(start[1])),
        gnss_outage="silent",
        attribution=ATTRIBUTION,
        route_lonlat=route_lonlat,
        route=route_model,
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
    ends = traj.time_at(road._s0[1:])
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
