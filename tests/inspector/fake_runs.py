"""Small hand-built runs for testing the inspector's logic without the estimator (its own tests
use the real runner on a sample log)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimator.nav.frames import LocalFrame
from estimator.params import Params
from estimator.results import Epochs, Gate, GateDecision, MatchRecord, Run
from estimator.route import Route

T0 = 1_700_000_000.0


@dataclass(frozen=True)
class FakeInputs:
    log: object
    route: Route
    frame: LocalFrame


def make_route() -> Route:
    s = np.linspace(0, 1000, 101)
    return Route(np.column_stack([s, 20 * np.sin(s / 200)]), name="synthetic")


def make_run(
    *,
    drift: float = 0.0,
    rejected: tuple[int, ...] = (2,),
    method="proposed",
    params: Params | None = None,
    n_matches: int = 5,
) -> Run:
    route = make_route()
    t = T0 + np.arange(0, 100, 0.05)
    s = 10.0 * (t - T0)
    xy = route.point_at(s) + drift * ((t - T0) / 100)[:, None] * np.array([0.0, 1.0])
    yaw = route.heading_at(s)
    n = len(t)
    epochs = Epochs(
        t=t,
        position=np.column_stack([xy, np.zeros(n)]),
        velocity=np.zeros((n, 3)),
        attitude=np.column_stack([np.zeros(n), np.zeros(n), yaw]),
        position_sigma=np.ones((n, 3)),
        position_cov_en=np.zeros(n),
        yaw_sigma=np.full(n, 0.01),
        gnss_used=(t - T0 < 30) | (t - T0 > 80),
        degraded=(t - T0 >= 30) & (t - T0 <= 80),
    )
    matches = []
    for k in range(n_matches if method != "baseline" else 0):
        tm = T0 + 40 + 5 * k
        e = int(np.searchsorted(t, tm))
        sm = 10.0 * (tm - T0)
        win_s = np.arange(sm - 100, sm + 1e-9, 5.0)
        win = route.point_at(win_s) + np.array([0.0, 3.0])
        ok = k not in rejected
        gates = (
            GateDecision(Gate.MIN_PAIRS, 21.0, 20.0, ">=", True),
            GateDecision(Gate.HEADING, 0.999, float(np.cos(np.radians(10))), ">=", True),
            GateDecision(Gate.RESIDUAL, 1.0 if ok else 7.5, 3.0, "<=", ok),
        )
        matches.append(
            MatchRecord(
                index=k,
                t=tm,
                epoch=e,
                accepted=ok,
                gates=gates,
                window_dr=win,
                route_points=route.point_at(win_s),
                route_segment=route.segment(sm - 110, sm + 10),
                route_s=(sm - 110, sm + 10),
                n_pairs=len(win_s),
                rotation_rad=0.001,
                translation=np.array([0.0, -3.0]),
                residual_m=1.0 if ok else 7.5,
                heading_cos=0.999,
                p_dr=win[-1],
                p_ref=win[-1] - [0, 3],
                lane_offset_m=0.0,
                pseudo_position=win[-1] - [0, 3],
                obs_cov=np.eye(2) * 4,
                innovation=np.array([0.0, -3.0]),
                correction=np.array([0.0, -2.0]) if ok else np.zeros(2),
            )
        )
    return Run(
        method=method,
        params=params or Params(),
        frame=LocalFrame(45.0, 7.0),
        epochs=epochs,
        matches=tuple(matches),
        degraded_intervals=((T0 + 30, T0 + 80),),
        t0=T0,
    )


def fake_open(log_path, route_path, progress, route_feature=None, topics=None):
    progress(0.5, "reading")
    if "bad" in str(log_path):
        from estimator.errors import LogError

        raise LogError(log_path, "not a bag")
    return FakeInputs(log=None, route=make_route(), frame=LocalFrame(45.0, 7.0))


def fake_run(inputs, params, method, progress, reuse, *, outages=()):
    progress(0.5, "running")
    drift = 30.0 if method == "baseline" else params.gates.max_residual_m
    return make_run(drift=drift, method=method, params=params)


def data_folder(tmp_path: Path) -> Path:
    """A data folder with a log, a route, a ROS 2 bag folder and a file that is neither."""
    d = tmp_path / "data"
    (d / "sub").mkdir(parents=True)
    (d / "drive.mcap").write_bytes(b"x")
    (d / "drive.route.geojson").write_text("{}")
    (d / "sub" / "old.bag").write_bytes(b"x")
    (d / "sub" / "old.gpx").write_text("<gpx/>")
    (d / "notes.txt").write_text("not offered")
    bag2 = d / "ros2_bag"
    bag2.mkdir()
    (bag2 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}")
    (bag2 / "ros2_bag_0.db3").write_bytes(b"x")
    return d


HOSTILE_LINE = "<img src=x onerror=alert(1)>"
"""a route line's name that runs script if a page renders it as HTML"""
MONACO_LOG = Path(__file__).resolve().parents[2] / "sample_logs" / "monaco_tunnel.mcap"
MONACO_ROUTE = MONACO_LOG.with_name("monaco_tunnel.route.geojson")


def two_line_route(path: Path) -> Path:
    """A GeoJSON FeatureCollection of two lines along the monaco sample's route: line 0 named
    :data:`HOSTILE_LINE` (the route drawn backwards), line 1 'east' (the route)."""
    import json

    doc = json.loads(MONACO_ROUTE.read_text())
    coords = doc["features"][0]["geometry"]["coordinates"]
    feats = [
        {
            "type": "Feature",
            "properties": {"name": name},
            "geometry": {"type": "LineString", "coordinates": c},
        }
        for name, c in ((HOSTILE_LINE, coords[::-1]), ("east", coords))
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def two_imu_log(folder: Path) -> tuple[Path, Path]:
    """A ROS 1 bag of a simulated 40 s drive holding two IMU topics, /imu/data and /imu/raw
    (the same samples), with its GNSS and wheel topics, and its route beside it:
    ``two_imu.bag`` and ``two_imu.route.geojson`` in ``folder``."""
    import shutil

    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    from estimator.io import BagTopics, write_bag
    from estimator.sim.simulation import simulate

    folder.mkdir(parents=True, exist_ok=True)
    work = folder / ".two_imu_parts"
    work.mkdir()
    sim = simulate("short_tunnel", duration_s=40.0)
    drive, route = sim.write(work, storage="ros1")
    raw = work / "raw.bag"
    write_bag(raw, imu=sim.imu, storage="ros1", topics=BagTopics(imu="/imu/raw"))
    out = folder / "two_imu.bag"
    typestore = get_typestore(Stores.ROS1_NOETIC)
    messages = []
    with Writer(out) as writer:
        connections = {}
        for source in (drive, raw):
            with AnyReader([source]) as reader:
                for c in reader.connections:
                    if c.topic not in connections:
                        connections[c.topic] = writer.add_connection(
                            c.topic, c.msgtype, typestore=typestore
                        )
                messages += [(t, c.topic, data) for c, t, data in reader.messages()]
        for t, topic, data in sorted(messages, key=lambda m: (m[0], m[1])):
            writer.write(connections[topic], t, data)
    shutil.copy(route, folder / "two_imu.route.geojson")
    shutil.rmtree(work)
    return out, folder / "two_imu.route.geojson"
