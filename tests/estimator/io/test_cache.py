"""The decode cache is keyed by the log's content: a different log with the same path, size and
modification time (``cp -p``) is decoded again, not answered with the old log's arrays."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import NoReturn

import numpy as np
import pytest

from estimator.io import load_log
from estimator.io.cache import cached_log
from estimator.io.topics import AUTO_TOPICS
from estimator.log import Log

SAMPLE = Path(__file__).resolve().parents[3] / "sample_logs" / "long_tunnel.mcap"


class _ReadAgain(Exception):
    pass


def _read_again() -> NoReturn:
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


@pytest.fixture(scope="module")
def sample_log(tmp_path_factory: pytest.TempPathFactory) -> Log:
    return load_log(SAMPLE, cache_dir=tmp_path_factory.mktemp("decoded"))


@pytest.mark.parametrize("damage", ["cut", "garbage", "empty"])
def test_a_damaged_entry_is_a_miss_and_replaced(
    tmp_path: Path, sample_log: Log, damage: str
) -> None:
    """An entry cut short (a crash or a full disk while another tool wrote it), overwritten or
    emptied is decoded again and replaced, never an error on every later run."""
    cache = tmp_path / "cache"
    cached_log(SAMPLE, SAMPLE, AUTO_TOPICS, cache_dir=cache, read=lambda: sample_log)
    (entry,) = cache.glob("log-*.npz")
    whole = entry.read_bytes()
    entry.write_bytes({"cut": whole[:1000], "garbage": b"garbage", "empty": b""}[damage])
    again = cached_log(SAMPLE, SAMPLE, AUTO_TOPICS, cache_dir=cache, read=lambda: sample_log)
    assert again is sample_log
    assert entry.stat().st_size == len(whole)
    served = cached_log(SAMPLE, SAMPLE, AUTO_TOPICS, cache_dir=cache, read=_read_again)
    assert np.array_equal(served.imu.t, sample_log.imu.t)


def test_a_failed_write_leaves_no_entry_and_no_temporary_file(
    tmp_path: Path, sample_log: Log, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full_disk(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    cache = tmp_path / "cache"
    cached_log(SAMPLE, SAMPLE, AUTO_TOPICS, cache_dir=cache, read=lambda: sample_log)
    assert [p.name for p in cache.iterdir() if not p.name.startswith("stat-")] == []


def test_a_cached_warning_names_the_file_given(tmp_path: Path) -> None:
    """The cache is keyed by content: a byte-identical copy is served the first file's entry,
    and its warnings name the copy, even once the first file is gone."""
    first, second = tmp_path / "first.mcap", tmp_path / "second.mcap"
    first.write_bytes(SAMPLE.read_bytes()[:100_000])
    shutil.copyfile(first, second)
    cache = tmp_path / "cache"
    decoded = load_log(first, cache_dir=cache)
    assert any(w.startswith("first.mcap: cut off") for w in decoded.warnings)
    first.unlink()
    served = load_log(second, cache_dir=cache)
    assert len(list(cache.glob("log-*.npz"))) == 1
    assert any(w.startswith("second.mcap: cut off") for w in served.warnings)
    assert not any("first.mcap" in w for w in served.warnings)
    assert len(served.warnings) == len(decoded.warnings)
