"""The decode cache: a decoded :class:`Log` saved as ``.npz``, keyed by a hash of the log's bytes,
the topic choice and :data:`CACHE_VERSION`, so the second load of a log is near-instant."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import tempfile
import time
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from estimator.io.topics import TopicChoice
from estimator.log import (
    ClockOffset,
    GnssData,
    ImuData,
    Log,
    TopicInfo,
    TruthData,
    WheelData,
)

CACHE_VERSION = 19
"""5: logs whose IMU and GNSS share no time are refused (they were cached as decoded); 7: a
warning naming the log's file is stored without the name (:func:`_stored_warning`); 8: fixes
far from the bulk of a log's are left out, streams on another clock than the IMU's named; 10:
the fixes after a step of the GNSS clock under a minute are left out; 11: so are the
repeats of a fix a receiver held while the vehicle drove on; 12: an IMU without accelerations
is refused, a gyro or axis reading zero named; 13: an offset of the GNSS clock against the
IMU's is measured up to a minute (it was up to 1 s); 14: a gyro scaled wrong is named; 15: a
receiver's clock stepping back over 1 s and 5 fix intervals is mended; 16: an offset of the
wheel stream's clock against the IMU's is named; 17: the clock offsets are kept as measured
(:class:`~estimator.log.ClockOffset`); 18: the clock-step check judges the wheels on the GNSS
speed's scale, and a jump of the fixes that stays is named (the fixes before it left out when
their variance says the receiver coasted); 19: a wheel speed in coarse steps is named"""
CACHE_MAX_BYTES = 2_000_000_000
"""Least recently used cache entries are removed beyond this total size."""


def default_cache_dir() -> Path:
    """``$ROUTEFUSE_CACHE_DIR``, else ``$XDG_CACHE_HOME/routefuse``, else ``~/.cache/routefuse``."""
    if env := os.environ.get("ROUTEFUSE_CACHE_DIR"):
        return Path(env)
    if xdg := os.environ.get("XDG_CACHE_HOME"):
        return Path(xdg) / "routefuse"
    return Path.home() / ".cache" / "routefuse"


def cached_log(
    path: Path,
    source: Path,
    topics: TopicChoice,
    *,
    cache_dir: Path | None,
    read: Callable[[], Log],
) -> Log:
    """The log from the cache when ``source`` was decoded before with these topics, else
    ``read()`` saved into the cache. ``path`` is what the user named (``Log.path``)."""
    cache = cache_dir if cache_dir is not None else default_cache_dir()
    key = hashlib.sha256(
        json.dumps(
            [_content_hash(source, cache), dataclasses.astuple(topics), CACHE_VERSION]
        ).encode()
    ).hexdigest()[:40]
    entry = cache / f"log-{key}.npz"
    if entry.is_file():
        try:
            with np.load(entry, allow_pickle=False) as data:
                log = _from_npz(path, data)
            with contextlib.suppress(OSError):
                os.utime(entry)  # recently used: pruned last
            return log
        except _DAMAGED_ENTRY:
            pass  # decoded again below, and the entry replaced
    log = read()
    _save(entry, log)
    return log


_DAMAGED_ENTRY = (
    OSError,
    ValueError,
    KeyError,
    TypeError,
    EOFError,
    zipfile.BadZipFile,
)
"""What reading an entry cut short, overwritten or of another layout raises: a cache miss. A
crash or a full disk leaves an entry cut short only when it was written in place; :func:`_save`
writes a temporary file and renames it, but an entry from another tool or a damaged disk is
still read as a miss, never an error."""


def _files_of(path: Path) -> list[Path]:
    return sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]


_RACY_SECONDS = 2.0
"""A file changed this recently may change again within the same timestamp tick: not memoised."""


def _content_hash(path: Path, cache: Path | None) -> str:
    """sha256 of the log's bytes (65 ms per 100 MB here, faster than blake2b with SHA
    instructions). A memo in the cache skips re-hashing a file whose (device, inode, size,
    mtime, ctime) are unchanged: ``cp -p`` or ``touch -r`` restore a size and an mtime but not
    the ctime, which only the kernel sets. As git does, a file changed within the last
    :data:`_RACY_SECONDS` is not memoised."""
    files = _files_of(path)
    stats = [f.stat() for f in files]
    stat_key = hashlib.sha256(
        json.dumps(
            [
                [str(f.resolve()), s.st_dev, s.st_ino, s.st_size, s.st_mtime_ns, s.st_ctime_ns]
                for f, s in zip(files, stats, strict=True)
            ]
        ).encode()
    ).hexdigest()[:32]
    newest = max((max(s.st_mtime, s.st_ctime) for s in stats), default=0.0)
    settled = time.time() - newest > _RACY_SECONDS
    memo = cache / f"stat-{stat_key}.txt" if cache is not None and settled else None
    if memo is not None and memo.is_file():
        with contextlib.suppress(OSError):
            text = memo.read_bytes().decode("ascii", "replace").strip()
            if len(text) == 64 and all(c in "0123456789abcdef" for c in text):
                return text
    h = hashlib.sha256()
    for f in files:
        h.update(str(f.relative_to(path) if path.is_dir() else "").encode())
        with f.open("rb") as fh:
            while chunk := fh.read(1 << 20):
                h.update(chunk)
    digest = h.hexdigest()
    if memo is not None:
        _atomic_write(memo, digest.encode())
    return digest


def _atomic_write(target: Path, data: bytes) -> None:
    with contextlib.suppress(OSError):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, target)


def _to_npz(log: Log) -> dict[str, Any]:
    arrays: dict[str, Any] = {}
    for name in ("imu", "gnss", "wheel", "truth"):
        part = getattr(log, name)
        if part is not None:
            for f in dataclasses.fields(part):
                arrays[f"{name}.{f.name}"] = getattr(part, f.name)
    name = Path(log.path).name
    meta = {
        "topics": [dataclasses.asdict(t) for t in log.topics],
        "warnings": [_stored_warning(w, name) for w in log.warnings],
        "clock_offsets": [
            {**dataclasses.asdict(o), "warning": _stored_warning(o.warning, name)}
            for o in log.clock_offsets
        ],
    }
    arrays["meta"] = np.array(json.dumps(meta))
    return arrays


def _from_npz(path: Path, data: Any) -> Log:
    def part(name: str, cls: type) -> Any:
        keys = [f.name for f in dataclasses.fields(cls)]
        if f"{name}.{keys[0]}" not in data:
            return None
        return cls(**{k: data[f"{name}.{k}"] for k in keys})

    meta = json.loads(str(data["meta"]))
    return Log(
        str(path),
        part("imu", ImuData),
        part("gnss", GnssData),
        part("wheel", WheelData),
        part("truth", TruthData),
        tuple(TopicInfo(**t) for t in meta["topics"]),
        tuple(_told_warning(w, path.name) for w in meta["warnings"]),
        tuple(
            ClockOffset(**{**o, "warning": _told_warning(o["warning"], path.name)})
            for o in meta["clock_offsets"]
        ),
    )


_FILE_NAMED = "file"


def _stored_warning(warning: str, name: str) -> list[str]:
    """A warning as the cache keeps it: ``["file", rest]`` when it begins with the log's file
    name (``first.mcap: cut off ...``), else ``["", warning]``. The cache is keyed by content,
    so a byte-identical copy under another name is served the same entry, and must be told its
    own name, not the first file's."""
    prefix = f"{name}: "
    if name and warning.startswith(prefix):
        return [_FILE_NAMED, warning[len(prefix) :]]
    return ["", warning]


def _told_warning(stored: list[str], name: str) -> str:
    """The warning of :func:`_stored_warning` for the log named ``name``."""
    kind, text = stored
    return f"{name}: {text}" if kind == _FILE_NAMED else str(text)


def _save(target: Path, log: Log) -> None:
    """Write the entry whole or not at all: into a temporary file in the cache folder, flushed
    to the disk, then renamed over ``target`` (a rename within a folder is atomic), so a crash
    or a full disk leaves the old entry or none, and no temporary file behind."""
    with contextlib.suppress(OSError):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-", suffix=".npz")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **_to_npz(log))
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, target)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
        prune(target.parent, keep=target)


def prune(cache: Path, *, keep: Path, max_bytes: int | None = None) -> None:
    """Remove the least recently used entries until the cache fits in ``max_bytes``
    (default :data:`CACHE_MAX_BYTES`)."""
    limit = CACHE_MAX_BYTES if max_bytes is None else max_bytes
    entries = []
    for p in cache.glob("log-*.npz"):
        with contextlib.suppress(OSError):
            st = p.stat()
            entries.append((st.st_mtime, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries):
        if total <= limit:
            break
        if p != keep:
            with contextlib.suppress(OSError):
                p.unlink()
                total -= size
