"""Logs whose chunks declare (or expand to) far more bytes than the file holds are refused before
rosbags decompresses them: a 64 kB .mcap of zeros used to take 4.3 GB and two minutes."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import pytest

from estimator.errors import LogError
from estimator.io import describe_topics, load_log

MCAP_MAGIC = b"\x89MCAP0\r\n"


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


def _mcap_with_chunk(path: Path, *, payload: bytes, declared: int) -> Path:
    header = _record(0x01, struct.pack("<I", 4) + b"ros2" + struct.pack("<I", 0))
    chunk = _record(
        0x06,
        struct.pack("<QQQI", 0, 0, declared, 0)
        + struct.pack("<I", 4)
        + b"zstd"
        + struct.pack("<Q", len(payload))
        + payload,
    )
    footer = _record(0x02, struct.pack("<QQI", 0, 0, 0))
    data_end = _record(0x0F, struct.pack("<I", 0))
    path.write_bytes(MCAP_MAGIC + header + chunk + data_end + footer + MCAP_MAGIC)
    return path


@pytest.mark.parametrize("declared_truthfully", [True, False])
def test_mcap_chunk_of_zeros_is_refused_fast(tmp_path: Path, declared_truthfully: bool) -> None:
    size = 2_000_000_000
    zstd = pytest.importorskip("zstandard")
    cctx = zstd.ZstdCompressor(level=1)
    writer = cctx.compressobj(size=size)
    block = b"\0" * (1 << 24)
    parts = [writer.compress(block) for _ in range(size // len(block))]
    parts.append(writer.compress(b"\0" * (size % len(block))))
    parts.append(writer.flush())
    payload = b"".join(parts)
    declared = size if declared_truthfully else 1000
    path = _mcap_with_chunk(tmp_path / "bomb.mcap", payload=payload, declared=declared)
    assert path.stat().st_size < 1_000_000
    for call in (
        lambda: load_log(path, cache_dir=tmp_path / "cache"),
        lambda: describe_topics(path),
    ):
        start = time.perf_counter()
        with pytest.raises(LogError, match="decompress") as err:
            call()
        assert time.perf_counter() - start < 2.0
        assert str(path) in str(err.value) and "\n" not in str(err.value)


def _ros1_record(fields: dict[str, bytes], data: bytes) -> bytes:
    header = b"".join(
        struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v for k, v in fields.items()
    )
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def _ros1_bag(path: Path, chunk: bytes) -> Path:
    """A ROS 1 bag of a bag header (one chunk, no connections) and ``chunk``."""
    head = _ros1_record(
        {
            "op": b"\x03",
            "index_pos": struct.pack("<Q", 0),
            "conn_count": struct.pack("<I", 0),
            "chunk_count": struct.pack("<I", 1),
        },
        b" " * 4000,
    )
    path.write_bytes(b"#ROSBAG V2.0\n" + head + chunk)
    return path


def test_ros1_chunk_declaring_gigabytes_is_refused(tmp_path: Path) -> None:
    import bz2

    payload = bz2.compress(b"\0" * 10_000_000)
    chunk = _ros1_record(
        {"op": b"\x05", "compression": b"bz2", "size": struct.pack("<I", 4_000_000_000)}, payload
    )
    path = _ros1_bag(tmp_path / "bomb.bag", chunk)
    with pytest.raises(LogError, match="decompress") as err:
        describe_topics(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_ros1_chunk_holding_more_than_it_declares_is_refused(
    tmp_path: Path, compression: str
) -> None:
    """bz2 and lz4 streams carry no trusted size: a chunk declaring 1 kB and holding 20 MB of
    zeros is found out, decompressing at most what it declares, before rosbags trusts it."""
    import bz2

    import lz4.frame

    zeros = b"\0" * 20_000_000
    payload = bz2.compress(zeros) if compression == "bz2" else lz4.frame.compress(zeros)
    chunk = _ros1_record(
        {"op": b"\x05", "compression": compression.encode(), "size": struct.pack("<I", 1000)},
        payload,
    )
    path = _ros1_bag(tmp_path / "liar.bag", chunk)
    start = time.perf_counter()
    with pytest.raises(LogError, match="holds more than its declared 1000 bytes") as err:
        describe_topics(path)
    assert time.perf_counter() - start < 2.0
    assert str(path) in str(err.value) and "\n" not in str(err.value)
