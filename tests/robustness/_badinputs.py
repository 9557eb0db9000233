"""Builders and assertions shared by the bad-input corpus: a small valid simulated drive, bags
written from (modified) copies of its arrays, bags rewritten message by message (for defects
``write_bag`` normalises away), and the one-line-error checks for the API and the CLI."""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from estimator.errors import RoutefuseError
from estimator.io import write_bag
from estimator.log import Log
from estimator.results import Run
from estimator.sim import Simulation, simulate
from inspector.cli import main as cli

SCENARIO = "short_tunnel"
"""75 s: a turn, a 400 m tunnel (GNSS lost for about 27 s), open sky; ~0.5 s per run."""

HAS_RUN_COMMAND = (
    "inspector.cli.run" in cli.COMMANDS
    and importlib.util.find_spec("inspector.cli.run") is not None
)
COMMANDS = ("info", "run")


@functools.cache
def base_sim() -> Simulation:
    """The valid drive every corpus case is derived from (simulated once per session)."""
    return simulate(SCENARIO, seed=0)


def write_log(path: Path, *, storage: str = "mcap", **streams: Any) -> Path:
    """A bag of the base drive with some streams replaced (``imu=...``) or left out
    (``wheel=None``)."""
    sim = base_sim()
    chosen = {"imu": sim.imu, "gnss": sim.gnss, "wheel": sim.wheel, "truth": sim.truth_fix}
    chosen.update(streams)
    write_bag(path, storage=storage, **chosen)  # type: ignore[arg-type]
    return path


def write_route(path: Path) -> Path:
    """The base drive's route as GeoJSON."""
    from estimator.sim.sdmap import write_geojson

    write_geojson(path, base_sim().route_geojson())
    return path


def route_lonlat() -> list[list[float]]:
    """The base route's vertices as GeoJSON [lon, lat] pairs."""
    geo = base_sim().route_geojson()
    feats = geo["features"] if geo.get("type") == "FeatureCollection" else [geo]
    return [list(map(float, c[:2])) for c in feats[0]["geometry"]["coordinates"]]


Edit = Callable[[str, int, Any], Any]


def rewrite_bag(
    src: Path,
    dst: Path,
    *,
    edit: Edit | None = None,
    order: dict[str, Sequence[int]] | None = None,
) -> Path:
    """Copy a ROS 2 bag message by message into the bare mcap ``dst``.

    ``edit(topic, i, msg)`` returns the (changed) i-th message of a topic, written exactly as
    returned (``write_bag`` would turn a NaN position into NO_FIX, for example).
    ``order[topic]`` permutes a topic's messages while every message keeps its slot in the
    file's receive-time order, so header stamps run backwards where the file does not.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([src]) as reader:
        conns = {c.topic: c.msgtype for c in reader.connections}
        rows = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    by_topic: dict[str, list[bytes]] = {}
    for topic, _, raw in rows:
        by_topic.setdefault(topic, []).append(raw)
    for topic, perm in (order or {}).items():
        by_topic[topic] = [by_topic[topic][i] for i in perm]
    if edit is not None:
        for topic, raws in by_topic.items():
            for i, raw in enumerate(raws):
                msg = edit(topic, i, ts.deserialize_cdr(raw, conns[topic]))
                if msg is not None:
                    raws[i] = bytes(ts.serialize_cdr(msg, conns[topic]))
    tmp = dst.parent / f".{dst.stem}-bag"
    writer = Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    try:
        out = {t: writer.add_connection(t, mtype, typestore=ts) for t, mtype in conns.items()}
        used = dict.fromkeys(conns, 0)
        for topic, t, _ in rows:
            writer.write(out[topic], t, by_topic[topic][used[topic]])
            used[topic] += 1
    finally:
        writer.close()
    shutil.move(str(tmp / f"{tmp.name}.mcap"), str(dst))
    shutil.rmtree(tmp)
    return dst


def replace_field(msg: Any, path: str, value: Any) -> Any:
    """A copy of a rosbags message with the dotted field ``path`` set (``a.b[3]`` for arrays)."""
    head, _, rest = path.partition(".")
    if "[" in head:
        name, idx = head[:-1].split("[")
        arr = np.array(getattr(msg, name), copy=True)
        arr[int(idx)] = value
        return dataclasses.replace(msg, **{name: arr})
    if rest:
        return dataclasses.replace(msg, **{head: replace_field(getattr(msg, head), rest, value)})
    return dataclasses.replace(msg, **{head: value})


# ---------------------------------------------------------------------------------------------
# assertions


def assert_one_line(err: RoutefuseError, path: Path | str, problem: str) -> None:
    """The message is ``"<file>: <problem...>"`` on one line."""
    text = str(err)
    assert "\n" not in text, text
    assert text.startswith(f"{path}: "), text
    assert problem in text, text


def run_cli(capsys: pytest.CaptureFixture[str], argv: Sequence[str]) -> tuple[int, str, str]:
    capsys.readouterr()
    try:
        code = cli.main(list(argv))
    except SystemExit as exc:  # argparse usage errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def cli_argv(command: str, log: Path, route: Path | None) -> list[str]:
    if command == "run" and not HAS_RUN_COMMAND:
        pytest.skip("routefuse run is not registered in inspector.cli.main.COMMANDS yet")
    return [command, str(log)] + ([] if route is None else ["--route", str(route)])


def assert_cli_error(
    capsys: pytest.CaptureFixture[str], argv: Sequence[str], path: Path | str, problem: str
) -> None:
    """Exit code 3 and one line on stderr: ``routefuse: error: <file>: <problem>``."""
    code, _, err = run_cli(capsys, argv)
    assert "Traceback" not in err, err
    assert code == 3, (code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"routefuse: error: {path}: "), lines[0]
    assert problem in lines[0], lines[0]


def assert_cli_ok(capsys: pytest.CaptureFixture[str], argv: Sequence[str]) -> str:
    """Exit code 0, nothing on stderr but routefuse's own lines (progress, warnings: no Python
    warning, no traceback); returns stdout."""
    code, out, err = run_cli(capsys, argv)
    assert "Traceback" not in err and "internal error" not in err, err
    assert code == 0, (code, err)
    assert all(line.startswith("routefuse") for line in err.splitlines()), err
    return out


def finite_log(log: Log) -> None:
    """Every array the estimator reads is finite where it must be (GNSS positions may be NaN
    only on NO_FIX epochs)."""
    for arr in (log.imu.t, log.imu.gyro, log.imu.accel, log.gnss.t):
        assert np.all(np.isfinite(arr))
    assert np.all(np.diff(log.imu.t) > 0) and np.all(np.diff(log.gnss.t) > 0)
    ok = log.gnss.valid
    assert np.all(np.abs(log.gnss.lat[ok]) <= 90) and np.all(np.abs(log.gnss.lon[ok]) <= 180)
    cov = log.gnss.cov_enu
    known = np.isfinite(cov)
    assert np.all(cov[known] > 0)
    assert np.all(np.abs(log.imu.gyro) <= 100.0) and np.all(np.abs(log.imu.accel) <= 2000.0)
    assert np.all(np.abs(log.gnss.alt[ok]) <= 100_000.0)
    if log.wheel is not None:
        assert np.all(np.isfinite(log.wheel.t)) and np.all(np.isfinite(log.wheel.speed))
        assert np.all(np.diff(log.wheel.t) > 0) and np.all(np.abs(log.wheel.speed) <= 200.0)


def finite_run(run: Run) -> None:
    """No NaN or inf anywhere in the run's epochs or match records."""
    e = run.epochs
    assert len(e) > 0
    for name in ("t", "position", "velocity", "attitude", "position_sigma", "yaw_sigma"):
        values = getattr(e, name)
        assert np.all(np.isfinite(values)), f"non-finite {name}"
    assert np.all(np.diff(e.t) >= 0)
    for m in run.matches:
        if m.accepted:
            for name in ("pseudo_position", "obs_cov", "innovation", "correction", "p_ref"):
                assert np.all(np.isfinite(getattr(m, name))), f"match {m.index}: {name}"


class Corpus:
    """Builds each named bad input once per session (the cases are read, never changed), from
    valid bags of every storage kind written once."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._built: dict[str, Path] = {}
        self._valid: dict[str, Path] = {}

    def valid(self, storage: str = "mcap") -> Path:
        if storage not in self._valid:
            name = {"mcap": "drive.mcap", "ros1": "drive.bag", "sqlite3": "drive"}[storage]
            folder = self.root / "valid"
            folder.mkdir(exist_ok=True)
            self._valid[storage] = write_log(folder / name, storage=storage)
        return self._valid[storage]

    def build(self, name: str, make: Callable[[Path, Corpus], Path]) -> Path:
        if name not in self._built:
            folder = self.root / f"case{len(self._built)}"
            folder.mkdir()
            self._built[name] = make(folder, self)
        return self._built[name]
