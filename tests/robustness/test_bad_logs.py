"""Logs that cannot be used: each is a one-line LogError naming the file, through the Python API
and through ``routefuse info`` / ``routefuse run`` (exit code 3, one line on stderr)."""

from __future__ import annotations

import shutil
import struct
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from _badinputs import (
    COMMANDS,
    Corpus,
    assert_cli_error,
    assert_one_line,
    base_sim,
    cli_argv,
    finite_log,
    write_log,
)

from estimator.errors import LogError
from estimator.io import load_log
from estimator.log import GnssData, ImuData
from estimator.pipeline.inputs import open_inputs

HUGE_BYTES = 210_000_000
"""Just over the inspector's 200 MB upload limit."""


def _truncated(tmp: Path, c: Corpus, storage: str) -> Path:
    src = c.valid(storage)
    if storage == "sqlite3":
        bag = tmp / "cut"
        shutil.copytree(src, bag)
        db = next(bag.glob("*.db3"))
        db.write_bytes(db.read_bytes()[: db.stat().st_size // 2])
        return bag
    cut = tmp / f"cut{src.suffix}"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size * 2 // 3])
    return cut


def _mcap_chunks(data: bytes) -> list[tuple[int, int]]:
    """(offset, length) of every Chunk record (opcode 0x06) of an mcap file."""
    out, pos = [], 8
    while pos + 9 <= len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if op == 0x06:
            out.append((pos, length))
        if op == 0x0F:  # footer
            break
        pos += 9 + length
    return out


def _corrupt_chunk(tmp: Path, c: Corpus) -> Path:
    """64 bytes in the middle of the second chunk's compressed records overwritten."""
    data = bytearray(c.valid().read_bytes())
    pos, length = _mcap_chunks(bytes(data))[1]
    at = pos + 9 + length // 2
    data[at : at + 64] = bytes(range(64))
    out = tmp / "corrupt_chunk.mcap"
    out.write_bytes(bytes(data))
    return out


def _text_file(tmp: Path, name: str) -> Path:
    path = tmp / name
    path.write_text("timestamp,ax,ay,az\n0.0,0.1,0.2,9.8\n")
    return path


def _zero(tmp: Path, name: str) -> Path:
    path = tmp / name
    path.write_bytes(b"")
    return path


def _sparse(tmp: Path, name: str, head: bytes = b"", size: int = HUGE_BYTES) -> Path:
    path = tmp / name
    with path.open("wb") as fh:
        fh.write(head)
        fh.truncate(size)
    return path


def _no_imu(tmp: Path, c: Corpus) -> Path:
    return write_log(tmp / "no_imu.mcap", imu=None)


def _no_gnss(tmp: Path, c: Corpus) -> Path:
    return write_log(tmp / "no_gnss.mcap", gnss=None)


def _too_few_imu(tmp: Path, c: Corpus) -> Path:
    imu = base_sim().imu
    return write_log(tmp / "few_imu.mcap", imu=ImuData(imu.t[:5], imu.gyro[:5], imu.accel[:5]))


def _all_imu_nan(tmp: Path, c: Corpus) -> Path:
    imu = base_sim().imu
    nan = np.full_like(imu.gyro, np.nan)
    return write_log(tmp / "imu_nan.mcap", imu=ImuData(imu.t, nan, imu.accel))


def _no_valid_fix(tmp: Path) -> Path:
    """Every fix NO_FIX and no truth: nothing to place the map frame at."""
    g = base_sim().gnss
    n = len(g.t)
    gnss = GnssData(g.t, g.lat, g.lon, g.alt, np.full(n, -1, np.int8), g.cov_enu)
    return write_log(tmp / "no_fix.mcap", gnss=gnss, truth=None)


def _folder_without_metadata(tmp: Path, c: Corpus) -> Path:
    folder = tmp / "just_a_folder"
    folder.mkdir()
    (folder / "notes.txt").write_text("hello")
    return folder


def _bad_metadata(tmp: Path, c: Corpus) -> Path:
    bag = tmp / "bag"
    shutil.copytree(c.valid("sqlite3"), bag)
    (bag / "metadata.yaml").write_text("rosbag2: [unclosed\n")
    return bag


Case = tuple[str, Callable[[Path, Corpus], Path], str]
CASES: list[Case] = [
    ("zero-byte .bag", lambda t, c: _zero(t, "empty.bag"), "file is empty"),
    ("zero-byte .mcap", lambda t, c: _zero(t, "empty.mcap"), "file is empty"),
    ("text file named .bag", lambda t, c: _text_file(t, "notes.bag"), "not a ROS 1 bag"),
    ("text file named .mcap", lambda t, c: _text_file(t, "notes.mcap"), "not a ROS 2 bag / mcap"),
    ("truncated ROS 1 bag", lambda t, c: _truncated(t, c, "ros1"), "truncated or corrupt"),
    ("truncated sqlite3 bag", lambda t, c: _truncated(t, c, "sqlite3"), "truncated or corrupt"),
    ("mcap with a corrupt chunk", _corrupt_chunk, "truncated or corrupt"),
    ("unreadable metadata.yaml", _bad_metadata, "truncated or corrupt"),
    ("folder without metadata.yaml", _folder_without_metadata, "no metadata.yaml"),
    ("unknown file type", lambda t, c: _text_file(t, "drive.csv"), "unknown log format '.csv'"),
    ("no IMU topic", _no_imu, "no IMU topic (Imu); topics: /gnss/fix"),
    ("no GNSS topic", _no_gnss, "no GNSS topic (NavSatFix); topics: /ground_truth"),
    ("5 IMU samples", _too_few_imu, "too few IMU samples on /imu/data: 5"),
    ("every IMU sample NaN", _all_imu_nan, "too few IMU samples on /imu/data: 0"),
    ("huge file of zeros named .bag", lambda t, c: _sparse(t, "huge.bag"), "not a ROS 1 bag"),
]
IDS = [c[0] for c in CASES]


@pytest.mark.parametrize(("name", "make", "problem"), CASES, ids=IDS)
def test_api_raises_one_line_log_error(tmp_path: Path, corpus, name, make, problem) -> None:
    path = corpus.build(name, make)
    with pytest.raises(LogError) as err:
        load_log(path, cache_dir=tmp_path / "cache")
    assert_one_line(err.value, path, problem)


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("name", "make", "problem"), CASES, ids=IDS)
def test_cli_exits_3_with_one_line(
    corpus: Corpus, capsys, route: Path, command: str, name, make, problem
) -> None:
    path = corpus.build(name, make)
    assert_cli_error(capsys, cli_argv(command, path, route), path, problem)


def test_a_truncated_mcap_loads_its_whole_records_with_a_warning(tmp_path: Path, corpus) -> None:
    """A .mcap cut at two thirds (a recording stopped mid-write) is not refused: the records
    before the cut are read (estimator.io.recover), finite, and a warning names the loss."""
    path = corpus.build("truncated mcap", lambda t, c: _truncated(t, c, "mcap"))
    log = load_log(path, cache_dir=tmp_path / "cache")
    finite_log(log)
    (line,) = [w for w in log.warnings if "cut off (no mcap footer" in w]
    assert line.startswith(f"{path.name}: ")
    whole = load_log(corpus.valid("mcap"), cache_dir=tmp_path / "cache")
    assert 0 < log.t_end - log.t_start < whole.t_end - whole.t_start


def test_no_valid_fix_is_a_map_frame_error(tmp_path: Path, capsys, route: Path) -> None:
    """The log loads (a whole-log outage is a fact, reported as a warning), but nothing places
    the map frame, so pairing it with a route or running it fails with one line."""
    path = _no_valid_fix(tmp_path)
    log = load_log(path, cache_dir=tmp_path / "cache")
    assert not log.gnss.valid.any()
    assert any("no valid fix in the whole log" in w for w in log.warnings)
    with pytest.raises(LogError) as err:
        open_inputs(path, route, cache_dir=tmp_path / "cache")
    assert_one_line(err.value, path, "no valid GNSS fix and no ground truth")
    for command in COMMANDS:
        assert_cli_error(capsys, cli_argv(command, path, route), path, "no valid GNSS fix")


@pytest.mark.parametrize(("name", "head"), [("huge.bag", b""), ("huge.mcap", b"\x89MCAP0\r\n")])
def test_huge_file_is_never_read_into_memory(tmp_path: Path, name: str, head: bytes) -> None:
    """A sparse file of 210 MB (zeros: refused from its first bytes) or 100 MB (a valid magic:
    hashed in 1 MB pieces, then refused by the reader): Python never holds more than a few MB."""
    path = _sparse(tmp_path, name, head, HUGE_BYTES if not head else 100_000_000)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(LogError):
            load_log(path, cache_dir=tmp_path / "cache")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 20e6, f"peak {peak / 1e6:.1f} MB"
    if not head:  # wrong magic: nothing beyond the first bytes is read
        assert time.perf_counter() - t0 < 1.0


def test_wrong_magic_is_refused_before_hashing(tmp_path: Path, monkeypatch) -> None:
    import estimator.io.cache as bagio

    def no_hash(*args, **kwargs):
        raise AssertionError("the file was hashed")

    monkeypatch.setattr(bagio, "_content_hash", no_hash)
    path = _sparse(tmp_path, "zeros.bag")
    with pytest.raises(LogError, match="not a ROS 1 bag"):
        load_log(path, cache_dir=tmp_path / "cache")


def test_a_corrupt_chunk_is_never_silently_half_read(tmp_path: Path, corpus: Corpus) -> None:
    """Whatever chunk is damaged, the loader either refuses the file or returns a log whose
    arrays are finite and time-ordered (a flipped bit can decompress to other values)."""
    data = corpus.valid().read_bytes()
    for k, (pos, length) in enumerate(_mcap_chunks(data)[:3]):
        for mode in ("zeros", "flip"):
            damaged = bytearray(data)
            at = pos + 9 + length // 3
            if mode == "zeros":
                damaged[at : at + 32] = bytes(32)
            else:
                damaged[at] ^= 0x40
            path = tmp_path / f"chunk{k}_{mode}.mcap"
            path.write_bytes(bytes(damaged))
            try:
                log = load_log(path, cache_dir=tmp_path / "cache")
            except LogError as err:
                assert_one_line(err, path, "truncated or corrupt")
            else:
                finite_log(log)
