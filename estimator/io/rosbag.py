"""The log formats rosbags reads: a ROS 1 ``.bag``, a ROS 2 bag folder (sqlite3 or mcap) and a
bare ``.mcap``. Each is one :class:`estimator.io.registry.LogReader`; all three decode through
rosbags' ``AnyReader`` (:mod:`estimator.io.decode`) and are repaired alike
(:mod:`estimator.io.repair`)."""

from __future__ import annotations

import contextlib
import dataclasses
import re
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from estimator.errors import LogError
from estimator.io.bounds import check_decompressed_size
from estimator.io.recover import MCAP_MAGIC, Recovered, ends_whole, recover_mcap
from estimator.io.topics import TopicChoice, topic_roles

if TYPE_CHECKING:
    from estimator.log import Log

ROS1_MAGIC = b"#ROSBAG V2.0\n"
"""First bytes of a ROS 1 bag and of an mcap file: checked before the (whole-file) content hash,
so a large file of the wrong kind is refused at once."""
ROS2_METADATA = "metadata.yaml"
MAX_METADATA_BYTES = 4_000_000
"""A ROS 2 bag's ``metadata.yaml`` lists its topics and files: a few kB, about 1 MB for a bag of
a thousand topics. rosbags parses it whole, at about 3 MB/s and 3x its size in memory (a
150 MB one took 46 s and 500 MB), so a larger one is refused from its size, before it is read
(as route files are over ``MAX_ROUTE_BYTES`` and configs over ``MAX_CONFIG_BYTES``)."""


class _CallbackRaised(Exception):
    """Carries an exception raised by the caller's progress callback (e.g. a cancellation)
    through :func:`_reading` unchanged."""

    def __init__(self, exc: Exception) -> None:
        self.exc = exc


def _guarded(progress: Callable[[float], None] | None) -> Callable[[float], None] | None:
    if progress is None:
        return None

    def report(fraction: float) -> None:
        try:
            progress(fraction)
        except Exception as exc:
            raise _CallbackRaised(exc) from exc

    return report


_ARGS_REPR = re.compile(r"""\((['"])(.*?)\1,?\)""")


def _plain(reason: str) -> str:
    """A library's message as a user reads it: rosbags words a damaged ROS 1 index as
    ``Bag index looks damaged: ('Header could not be read from file.',)``, the repr of the
    inner error's arguments; the tuple's text is kept, its Python punctuation dropped."""
    return _ARGS_REPR.sub(lambda m: m.group(2), reason)


@contextlib.contextmanager
def _reading(path: Path, kind: str) -> Iterator[None]:
    """Turn rosbags' (and the storage libraries') exceptions into one-line LogErrors."""
    try:
        yield
    except LogError:
        raise
    except _CallbackRaised as passed:
        raise passed.exc from None
    except Exception as exc:
        reason = (
            _plain(str(exc).strip().splitlines()[0]) if str(exc).strip() else type(exc).__name__
        )
        if reason.lower().startswith("file magic is invalid"):
            raise LogError(path, f"not a {kind} ({reason})") from None
        raise LogError(
            path, f"cannot read the bag, it is truncated or corrupt ({reason})"
        ) from None


def _starts_with(path: Path, magic: bytes, kind: str) -> Path:
    """``path`` if it is a non-empty file that starts with ``magic``, else a LogError."""
    info = path.stat()
    if not stat.S_ISREG(info.st_mode):
        raise LogError(path, "not a regular file (a fifo or a device is not read)")
    if info.st_size == 0:
        raise LogError(path, "file is empty")
    try:
        with path.open("rb") as fh:
            head = fh.read(max(len(m) for m in (magic, *_OTHER_FORMATS)))
    except OSError as exc:
        raise LogError(path, f"cannot open the file ({exc.strerror or exc})") from None
    if not head.startswith(magic):
        for other, (what, suffix) in _OTHER_FORMATS.items():
            if other != magic and head.startswith(other):
                raise LogError(path, f"not a {kind}: it is {what} (name it {suffix})")
        raise LogError(path, f"not a {kind} (it does not start with {magic!r})")
    return path


_OTHER_FORMATS = {MCAP_MAGIC: ("an MCAP file", ".mcap"), ROS1_MAGIC: ("a ROS 1 bag", ".bag")}
"""the first bytes of each single-file format, to name a log given the other's suffix"""


def _in_bag_folder(path: Path) -> bool:
    return (path.parent / ROS2_METADATA).is_file()


class _RosbagsLog:
    """Reading and topic listing shared by the formats rosbags' ``AnyReader`` opens."""

    name: str = ""
    wording: str = ""
    suffixes: tuple[str, ...] = ()
    kind: str = ""
    """What the file is called in 'not a ...' messages."""

    def topics(self, path: Path, source: Path) -> dict[str, tuple[str, int]]:
        from rosbags.highlevel import AnyReader

        check_decompressed_size(source)
        out: dict[str, tuple[str, int]] = {}
        with _reading(path, self.kind), AnyReader([source]) as reader:
            for conn in reader.connections:
                mtype, n = out.get(conn.topic, (conn.msgtype, 0))
                out[conn.topic] = (mtype, n + int(conn.msgcount or 0))
        return out

    def read(
        self,
        path: Path,
        source: Path,
        choice: TopicChoice,
        progress: Callable[[float], None] | None,
    ) -> Log:
        from rosbags.highlevel import AnyReader

        from estimator.io.decode import decode
        from estimator.io.repair import assemble

        check_decompressed_size(source)
        reader: Any
        with _reading(path, self.kind), AnyReader([source]) as reader:
            types: dict[str, str] = {}
            counts: dict[str, int] = {}
            for conn in reader.connections:
                types.setdefault(conn.topic, conn.msgtype)
                counts[conn.topic] = counts.get(conn.topic, 0) + int(conn.msgcount or 0)
            roles = topic_roles(path, types, choice)
            raw = decode(path, reader, roles, _guarded(progress))
        return assemble(path, roles, raw, types, counts)


@contextlib.contextmanager
def _whole(path: Path, source: Path, kind: str) -> Iterator[tuple[Path, Recovered | None]]:
    """``source``, or where it was cut off, a complete copy of its whole records (in a
    temporary folder for as long as it is read)."""
    if ends_whole(source):
        yield source, None
        return
    check_decompressed_size(source)  # before recovery decompresses its chunks
    with tempfile.TemporaryDirectory(prefix="routefuse-recovered-") as folder:
        with _reading(path, kind):
            recovered = recover_mcap(source, Path(folder) / source.name)
        yield recovered.path, recovered


class McapFile(_RosbagsLog):
    """A bare ``.mcap`` file (ROS 2 messages, no bag folder around it). One that was cut off
    (no footer) is read up to its last whole record (:mod:`estimator.io.recover`), with a
    warning naming what was lost."""

    name = "mcap"
    wording = "a .mcap file"
    suffixes = (".mcap",)
    kind = "ROS 2 bag / mcap file"

    def topics(self, path: Path, source: Path) -> dict[str, tuple[str, int]]:
        with _whole(path, source, self.kind) as (readable, _):
            return super().topics(path, readable)

    def read(
        self,
        path: Path,
        source: Path,
        choice: TopicChoice,
        progress: Callable[[float], None] | None,
    ) -> Log:
        with _whole(path, source, self.kind) as (readable, recovered):
            log = super().read(path, readable, choice, progress)
        if recovered is None:
            return log
        line = (
            f"{path.name}: cut off (no mcap footer: a recording stopped mid-write?): read its "
            f"{recovered.messages} whole messages, {log.t_end - log.t_start:.1f} s of log; the "
            f"last {recovered.lost_bytes} bytes, a record cut in two, are lost"
        )
        return dataclasses.replace(log, warnings=(line, *log.warnings))

    def recognises(self, path: Path) -> bool:
        return not path.is_dir() and path.suffix.lower() == ".mcap" and not _in_bag_folder(path)

    def locate(self, path: Path) -> Path | None:
        if path.suffix.lower() != ".mcap" or path.is_dir() or _in_bag_folder(path):
            return None
        return _starts_with(path, MCAP_MAGIC, self.kind)


class Ros1Bag(_RosbagsLog):
    """A ROS 1 ``.bag`` file."""

    name = "ros1"
    wording = "a ROS 1 .bag"
    suffixes = (".bag",)
    kind = "ROS 1 bag"

    def recognises(self, path: Path) -> bool:
        return not path.is_dir() and path.suffix.lower() == ".bag"

    def locate(self, path: Path) -> Path | None:
        if path.suffix.lower() != ".bag" or path.is_dir():
            return None
        return _starts_with(path, ROS1_MAGIC, self.kind)


class Ros2BagFolder(_RosbagsLog):
    """A ROS 2 bag folder (``metadata.yaml`` and sqlite3 ``.db3`` or ``.mcap`` files), named by
    the folder or by one of its files."""

    name = "ros2"
    wording = "a ROS 2 bag folder"
    suffixes = ()
    kind = "ROS 2 bag / mcap file"

    def recognises(self, path: Path) -> bool:
        if path.is_dir():
            return (path / ROS2_METADATA).is_file()
        return path.suffix.lower() in (".db3", ".mcap") and _in_bag_folder(path)

    def locate(self, path: Path) -> Path | None:
        if path.is_dir():
            if not (path / ROS2_METADATA).is_file():
                raise LogError(path, "folder is not a ROS 2 bag (it has no metadata.yaml)")
            return _metadata_bounded(path)
        suffix = path.suffix.lower()
        if suffix in (".db3", ".mcap") and _in_bag_folder(path):
            return _metadata_bounded(path.parent)
        if suffix == ".db3":
            raise LogError(
                path, "a .db3 file is read with its bag folder (metadata.yaml is missing)"
            )
        return None


def _metadata_bounded(folder: Path) -> Path:
    """``folder`` when its ``metadata.yaml`` is a regular file of at most
    :data:`MAX_METADATA_BYTES`; else a one-line :class:`LogError` naming that file."""
    metadata = folder / ROS2_METADATA
    info = metadata.stat()
    if not stat.S_ISREG(info.st_mode):
        raise LogError(metadata, "not a regular file (a fifo or a device is not read)")
    if info.st_size > MAX_METADATA_BYTES:
        raise LogError(
            metadata,
            f"file is {info.st_size / 1e6:.1f} MB; a bag's metadata over "
            f"{MAX_METADATA_BYTES / 1e6:g} MB is refused (it lists topics and files: a few kB)",
        )
    return folder
