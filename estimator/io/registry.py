"""The one registry of log formats, as rosbags keeps its storage plugins: each format is a
:class:`LogReader` that says which paths it recognises, how it is called, and reads them. A new
format is one class and one entry in :data:`LOG_FORMATS`; loading, the decode cache, the CLI help,
the inspector's file list and upload hints and the export's batch finder all follow from here."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from estimator.errors import LogError
from estimator.io.rosbag import McapFile, Ros1Bag, Ros2BagFolder
from estimator.io.topics import AUTO_TOPICS, TopicChoice

if TYPE_CHECKING:
    from estimator.log import Log


@runtime_checkable
class LogReader(Protocol):
    """One log format."""

    @property
    def name(self) -> str:
        """Short identifier, the key in :data:`LOG_FORMATS`."""
        ...

    @property
    def wording(self) -> str:
        """How help texts and messages call it, with its article: 'a ROS 1 .bag'."""
        ...

    @property
    def suffixes(self) -> tuple[str, ...]:
        """Suffixes of single files that are a log of this format (lower case, with the dot)."""
        ...

    def recognises(self, path: Path) -> bool:
        """Whether ``path`` is a log of this format, by its name and shape (no content read; a
        path that does not exist yet, such as an upload's file name, by its name): what file
        pickers, upload checks and batch finders accept."""
        ...

    def locate(self, path: Path) -> Path | None:
        """The file or folder to read for ``path``; None if ``path`` is not of this format; a
        :class:`LogError` if it is but cannot be (empty, wrong first bytes, incomplete)."""
        ...

    def topics(self, path: Path, source: Path) -> dict[str, tuple[str, int]]:
        """Topic -> (message type, count) of ``source``, without decoding messages."""
        ...

    def read(
        self,
        path: Path,
        source: Path,
        choice: TopicChoice,
        progress: Callable[[float], None] | None,
    ) -> Log:
        """Decode and repair ``source`` (``path`` names the log in messages and ``Log.path``)."""
        ...


LOG_FORMATS: dict[str, LogReader] = {
    "ros2": Ros2BagFolder(),
    "mcap": McapFile(),
    "ros1": Ros1Bag(),
}
"""Every log format routefuse reads, in the order a path is offered to them (a folder, or a file
inside one, is a ROS 2 bag folder's before a bare file format's) and named in help texts."""


def _either(words: list[str]) -> str:
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


def log_suffixes() -> tuple[str, ...]:
    """Suffixes of single-file logs, e.g. ``('.mcap', '.bag')``."""
    return tuple(s for fmt in LOG_FORMATS.values() for s in fmt.suffixes)


LOG_FORMATS_TEXT = _either([fmt.wording for fmt in LOG_FORMATS.values()])
"""'a ROS 2 bag folder, a .mcap file or a ROS 1 .bag': for help texts and messages."""
LOG_SUFFIXES_TEXT = _either(list(log_suffixes()))
"""'.mcap or .bag': the single files an upload accepts."""


def is_log_path(path: str | Path) -> bool:
    """Whether some format recognises ``path`` as a log, by its name and shape (a path that
    does not exist yet, such as an upload's file name, by its name alone)."""
    p = Path(path)
    return any(fmt.recognises(p) for fmt in LOG_FORMATS.values())


def check_log_exists(path: str | Path) -> None:
    """A one-line :class:`LogError` when ``path`` (a log file or folder) does not exist or
    cannot be looked at."""
    try:
        Path(path).stat()
    except FileNotFoundError:
        raise LogError(path, "no such file or folder") from None
    except OSError as exc:
        raise LogError(path, f"cannot open it ({exc.strerror or exc})") from None


def open_log_path(path: Path) -> tuple[LogReader, Path]:
    """The format of ``path`` and what it reads, or a one-line :class:`LogError` saying why
    this is not a log."""
    check_log_exists(path)
    for fmt in LOG_FORMATS.values():
        try:
            source = fmt.locate(path)
        except OSError as exc:  # a folder that cannot be looked into, a file not read
            raise LogError(path, f"cannot open it ({exc.strerror or exc})") from None
        if source is not None:
            return fmt, source
    raise LogError(
        path, f"unknown log format '{path.suffix or path.name}': expected {LOG_FORMATS_TEXT}"
    )


def load_log(
    path: str | Path,
    *,
    topics: TopicChoice = AUTO_TOPICS,
    cache_dir: Path | None = None,
    progress: Callable[[float], None] | None = None,
) -> Log:
    """Decode a log into numpy arrays (from the cache when this file was decoded before).

    Raises :class:`LogError` (one line naming the file) for anything that is not a readable
    log with an IMU and a GNSS topic.
    """
    from estimator.io.cache import cached_log  # numpy: not needed for the names above

    path = Path(path)
    fmt, source = open_log_path(path)
    log = cached_log(
        path,
        source,
        topics,
        cache_dir=cache_dir,
        read=lambda: fmt.read(path, source, topics, progress),
    )
    if progress is not None:
        progress(1.0)
    return log


def describe_topics(path: str | Path) -> dict[str, tuple[str, int]]:
    """Topic -> (message type, count) without decoding messages (for error messages, info)."""
    p = Path(path)
    fmt, source = open_log_path(p)
    return fmt.topics(p, source)
