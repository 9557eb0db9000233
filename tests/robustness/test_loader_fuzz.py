"""Fuzzing the log loader: random bytes, and random byte mutations of a small valid bag of every
storage kind. Every outcome must be a Log with finite, time-ordered arrays or a one-line
LogError naming the file - never another exception type, never a hang."""

from __future__ import annotations

import shutil
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _badinputs import finite_log
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from estimator.errors import LogError
from estimator.io import StaticTransform, load_log, write_bag
from estimator.log import GnssData, ImuData, Log, TruthData, WheelData

STORAGES = ("mcap", "mcap-folder", "sqlite3", "ros1")
NAMES = {"mcap": "log.mcap", "mcap-folder": "mcapbag", "sqlite3": "sqlbag", "ros1": "log.bag"}
TIME_LIMIT_S = 20.0
"""One load of a ~40 kB bag takes well under a second; more than this is a hang."""


def _small_streams() -> dict[str, Any]:
    rng = np.random.default_rng(11)
    t0 = 1_700_000_000.0
    n = 200
    t = t0 + 0.01 * np.arange(n)
    imu = ImuData(t, rng.normal(scale=0.01, size=(n, 3)), rng.normal([0, 0, 9.8], 0.05, (n, 3)))
    m = 20
    status = np.zeros(m, np.int8)
    status[7:9] = -1
    gnss = GnssData(
        t[::10],
        45.0 + 1e-5 * np.arange(m),
        np.full(m, 7.0),
        np.full(m, 300.0),
        status,
        np.tile([0.5, 0.5, 2.0], (m, 1)),
    )
    wheel = WheelData(t[::4], np.linspace(0.0, 2.0, n // 4))
    truth = TruthData(t[::20], gnss.lat[::2], gnss.lon[::2], gnss.alt[::2], np.zeros(10))
    return {"imu": imu, "gnss": gnss, "wheel": wheel, "truth": truth}


@pytest.fixture(scope="module")
def valid_bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One small bag per storage kind, with an IMU in its own frame and a /tf_static to the
    body (so mutations can hit the transform as well)."""
    root = tmp_path_factory.mktemp("fuzz-src")
    tf = StaticTransform("base_link", "imu_link", (0.0, 0.0, 0.7071068, 0.7071068))
    bags = {}
    for storage in STORAGES:
        path = root / NAMES[storage]
        write_bag(
            path, storage=storage, imu_frame="imu_link", static_transforms=[tf], **_small_streams()
        )
        bags[storage] = path
    return bags


def _data_file(bag: Path) -> Path:
    if bag.is_dir():
        return next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    return bag


def _bounded_load(path: Path, cache: Path) -> Log | BaseException:
    """load_log in a thread: its result, or the exception it raised; fails on a hang."""
    box: list[Log | BaseException] = []

    def work() -> None:
        try:
            box.append(load_log(path, cache_dir=cache))
        except BaseException as exc:
            box.append(exc)

    worker = threading.Thread(target=work, daemon=True)
    worker.start()
    worker.join(TIME_LIMIT_S)
    assert not worker.is_alive(), f"load_log({path}) still running after {TIME_LIMIT_S} s"
    return box[0]


def _check_outcome(outcome: Log | BaseException, path: Path) -> None:
    if isinstance(outcome, BaseException):
        if not isinstance(outcome, LogError):
            raise AssertionError(f"{type(outcome).__name__} instead of LogError") from outcome
        text = str(outcome)
        # a bag folder's error may name the file inside it that is at fault (a hostile chunk)
        named = text.startswith(f"{path}: ") or (
            path.is_dir() and text.split(": ", 1)[0].startswith(f"{path}/")
        )
        assert "\n" not in text and named, text
        return
    finite_log(outcome)


MUTATION = st.tuples(
    st.sampled_from(["flip", "set", "zero", "delete", "insert", "truncate"]),
    st.floats(0.0, 1.0),
    st.integers(1, 64),
    st.integers(0, 255),
)


def _mutate(data: bytes, mutations: list[tuple[str, float, int, int]]) -> bytes:
    buf = bytearray(data)
    for kind, where, size, value in mutations:
        at = min(int(where * len(buf)), max(len(buf) - 1, 0))
        if kind == "flip" and buf:
            buf[at] ^= 1 << (value % 8)
        elif kind == "set":
            buf[at : at + size] = bytes([value]) * len(buf[at : at + size])
        elif kind == "zero":
            buf[at : at + size] = bytes(len(buf[at : at + size]))
        elif kind == "delete":
            del buf[at : at + size]
        elif kind == "insert":
            buf[at:at] = bytes([value]) * size
        elif kind == "truncate":
            del buf[at:]
    return bytes(buf)


@settings(
    max_examples=120,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    storage=st.sampled_from(STORAGES),
    mutations=st.lists(MUTATION, min_size=1, max_size=4),
)
def test_mutated_bags_load_or_fail_cleanly(
    valid_bags: dict[str, Path], storage: str, mutations: list[tuple[str, float, int, int]]
) -> None:
    src = valid_bags[storage]
    with tempfile.TemporaryDirectory(dir=src.parent) as tmp:
        dst = Path(tmp) / src.name
        if src.is_dir():
            shutil.copytree(src, dst)
        else:
            shutil.copy(src, dst)
        target = _data_file(dst)
        target.write_bytes(_mutate(target.read_bytes(), mutations))
        _check_outcome(_bounded_load(dst, Path(tmp) / "cache"), dst)


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    suffix=st.sampled_from([".bag", ".mcap"]),
    head=st.sampled_from([b"", b"#ROSBAG V2.0\n", b"\x89MCAP0\r\n"]),
    body=st.binary(min_size=0, max_size=4096),
)
def test_random_bytes_fail_cleanly(
    tmp_path_factory: pytest.TempPathFactory, suffix: str, head: bytes, body: bytes
) -> None:
    root = tmp_path_factory.mktemp("fuzz-random")
    path = root / f"random{suffix}"
    path.write_bytes(head + body)
    _check_outcome(_bounded_load(path, root / "cache"), path)


def test_the_fuzz_sources_load(valid_bags: dict[str, Path], tmp_path: Path) -> None:
    """The unmutated bags are valid (so the mutations above start from a readable file)."""
    for storage, bag in valid_bags.items():
        log = load_log(bag, cache_dir=tmp_path / storage)
        finite_log(log)
        assert len(log.imu.t) == 200 and log.wheel is not None and log.truth is not None
        assert any("rotated from imu_link into base_link" in w for w in log.warnings)
