"""The decode cache is keyed by the log's content: a different log with the same path, size and
modification time (``cp -p``) is decoded again, not answered with the old log's arrays."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest

from estimator.io import load_log
from estimator.io.cache import cached_log
from estimator.io.topics import AUTO_TOPICS

SAMPLE = Path(__file__).resolve().parents[3] / "sample_logs" / "long_tunnel.mcap"


class _ReadAgain(Exception):
    pass


def _read_again() -> None:
    raise _ReadAgain


def test_same_size_and_mtime_other_content_is_read_again(tmp_path: Path) -> None:
    log = load_log(SAMPLE, cache_dir=tmp_path / "first")
    target = tmp_path / "drive.mcap"
    shutil.copyfile(SAMPLE, target)
    stamp = target.stat().st_mtime_ns
    time.sleep(2.1)  # older than a timestamp tick: the stat memo is written
    cache = tmp_path / "cache"
    assert cached_log(target, target, AUTO_TOPICS, cache_dir=cache, read=lambda: log) is log
    assert cached_log(target, target, AUTO_TOPICS, cache_dir=cache, read=_read_again).path == str(
        target
    )
    other = bytearray(target.read_bytes())
    other[-100] ^= 0xFF
    target.write_bytes(bytes(other))
    os.utime(target, ns=(stamp, stamp))
    assert target.stat().st_size == SAMPLE.stat().st_size
    with pytest.raises(_ReadAgain):
        cached_log(target, target, AUTO_TOPICS, cache_dir=cache, read=_read_again)
