"""The files the inspector may open: the data folders it lists (and nothing outside them) and
the private folder uploads are written to. Which files are logs is the log-format registry's
call (:mod:`estimator.io`)."""

from __future__ import annotations

import errno
import itertools
import os
import re
import shutil
import signal
import tempfile
import threading
import time
import weakref
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

from estimator.errors import RoutefuseError
from estimator.io import (
    LOG_SUFFIXES_TEXT,
    ROUTE_SUFFIXES_TEXT,
    is_log_path,
    is_route_path,
    log_suffixes,
    route_format,
)

Kind = Literal["log", "route"]
DEFAULT_UPLOAD_LIMIT = 100 * 1024 * 1024
UPLOAD_FOLDER_FILES = 4
"""the upload folder holds at most this many uploads of the largest size (its total cap)"""


@dataclass(frozen=True)
class Listing:
    """Display name -> path of every log and route under the data folders, and what the walk
    skipped or could not finish (symlink loops, unreadable folders, files leading outside, a
    folder too large to walk)."""

    logs: dict[str, Path]
    routes: dict[str, Path]
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class DataFolders:
    """The folders the server may read from. Only what :meth:`listing` found can be opened, so a
    name can never reach outside them (no ``..``, no symlink leading out, not even one file of a
    ROS 2 bag folder). The walk is bounded in depth, entries looked at, candidates and time, so a
    huge folder costs the UI a second, not a hang."""

    roots: tuple[Path, ...]
    max_depth: int = 4
    max_entries: int = 5000
    """logs and routes listed at most"""
    max_scanned: int = 200_000
    """directory entries looked at, at most, per listing"""
    max_seconds: float = 2.0
    """time one listing may take"""

    @classmethod
    def of(
        cls,
        *roots: str | Path,
        max_scanned: int = 200_000,
        max_seconds: float = 2.0,
    ) -> DataFolders:
        seen: list[Path] = []
        for r in roots:
            try:
                p = Path(r).expanduser().resolve(strict=True)
            except (OSError, RuntimeError):  # RuntimeError: a symlink loop (Python < 3.13)
                continue
            if p.is_dir() and p not in seen:
                seen.append(p)
        return cls(tuple(seen), max_scanned=max_scanned, max_seconds=max_seconds)

    def with_root(self, root: Path) -> DataFolders:
        root = root.resolve()
        return self if root in self.roots else replace(self, roots=(*self.roots, root))

    def _labels(self) -> list[str]:
        labels: list[str] = []
        for root in self.roots:
            label = root.name or "data"
            n = 2
            base = label
            while label in labels:
                label = f"{base}#{n}"
                n += 1
            labels.append(label)
        return labels

    def listing(self) -> Listing:
        logs: dict[str, Path] = {}
        routes: dict[str, Path] = {}
        walk = _Walk(self)
        for label, root in zip(self._labels(), self.roots, strict=True):
            for path in walk.candidates(root):
                name = f"{label}/{path.relative_to(root).as_posix()}"
                if path.is_dir() or is_log_path(path):
                    logs[name] = path
                elif is_route_path(path):
                    routes[name] = path
        return Listing(
            dict(sorted(logs.items())), dict(sorted(routes.items())), tuple(walk.warnings)
        )

    def resolve(self, name: str, kind: Kind) -> Path:
        """The path behind a display name from :meth:`listing`, checked again as it is opened
        (a file swapped for a symlink since the listing is refused)."""
        listing = self.listing()
        table = listing.logs if kind == "log" else listing.routes
        path = table.get(name)
        if path is None:
            raise RoutefuseError(name, f"no such {kind} under the data folders")
        root = next(r for r in self.roots if path == r or r in path.parents)
        problem = _leak(path, root)
        if problem is not None:
            raise RoutefuseError(name, problem)
        return path

    def default_route(self, log_name: str) -> str | None:
        """The route that belongs to a log: ``<stem>.route.*`` or ``<stem>.<route suffix>``
        beside it."""
        listing = self.listing()
        log = listing.logs.get(log_name)
        if log is None:
            return None
        stem = log.name.split(".")[0]
        for name, path in listing.routes.items():
            if path.parent == log.parent and path.name.split(".")[0] == stem:
                return name
        return None


class _Walk:
    """One bounded walk over the data folders: candidate files and ROS 2 bag folders whose
    every file stays inside their root, and a warning for each thing skipped."""

    def __init__(self, folders: DataFolders) -> None:
        self.folders = folders
        self.warnings: list[str] = []
        self.scanned = 0
        self.found = 0
        self.deadline = time.monotonic() + folders.max_seconds
        self.stopped = False

    def _stop(self, why: str) -> None:
        self.stopped = True
        self.warnings.append(
            f"stopped listing the data folders after {why}: not all files are "
            "listed (point --data-dir at a smaller folder)"
        )

    def _entries(self, folder: Path) -> list[os.DirEntry[str]] | None:
        try:
            with os.scandir(folder) as it:
                entries = list(itertools.islice(it, self.folders.max_scanned - self.scanned + 1))
        except OSError as exc:
            self.warnings.append(f"{folder}: cannot read this folder ({exc.strerror}); skipped")
            return None
        self.scanned += len(entries)
        if self.scanned > self.folders.max_scanned:
            self._stop(f"{self.folders.max_scanned} entries")
        elif time.monotonic() > self.deadline:
            self._stop(f"{self.folders.max_seconds:g} s; {self.scanned} entries looked at")
        return sorted(entries, key=lambda e: e.name)

    def candidates(self, root: Path) -> Iterable[Path]:
        stack: list[tuple[Path, int]] = [(root, 0)]
        while stack and not self.stopped:
            here, depth = stack.pop()
            entries = self._entries(here)
            if entries is None:
                continue
            names = {e.name for e in entries}
            if "metadata.yaml" in names and here != root:
                yield from self._accept(here, root)
                continue
            below: list[tuple[Path, int]] = []
            for entry in entries:
                p = Path(entry.path)
                if _is_real_dir(entry):
                    if depth + 1 < self.folders.max_depth and not entry.name.startswith("."):
                        below.append((p, depth + 1))
                elif is_log_path(p) or is_route_path(p):
                    yield from self._accept(p, root)
                elif _is_folder_link(entry) and not entry.name.startswith("."):
                    # said, not skipped silently: the logs under it are missing from the list
                    self.warnings.append(
                        f"{p}: a link to a folder; links to folders are not followed (pass the "
                        "folder itself with --data-dir); not listed"
                    )
            stack.extend(reversed(below))

    def _accept(self, path: Path, root: Path) -> Iterable[Path]:
        if self.found >= self.folders.max_entries:
            if self.found == self.folders.max_entries:
                self.found += 1
                self._stop(f"{self.folders.max_entries} logs and routes")
            return
        problem = _leak(path, root)
        if problem is not None:
            self.warnings.append(f"{path}: {problem}; not listed")
            return
        self.found += 1
        yield path


def _is_real_dir(entry: os.DirEntry[str]) -> bool:
    """A folder to walk into: not a symlink (those are never followed) and readable as one."""
    try:
        return entry.is_dir(follow_symlinks=False)
    except OSError:
        return False


def _is_folder_link(entry: os.DirEntry[str]) -> bool:
    """A symlink to a folder (which the walk does not follow)."""
    try:
        return entry.is_symlink() and entry.is_dir(follow_symlinks=True)
    except OSError:
        return False


def _leak(path: Path, root: Path) -> str | None:
    """Why ``path`` (and, for a folder, every file in it) cannot be read inside ``root``, or
    None when it can."""
    problem = _outside(path, root)
    if problem is not None or not path.is_dir():
        return problem
    try:
        with os.scandir(path) as it:
            members = list(itertools.islice(it, 10_000))
    except OSError as exc:
        return f"cannot read this folder ({exc.strerror})"
    for member in members:
        problem = _outside(Path(member.path), root)
        if problem is not None:
            return f"{member.name} in this bag folder {problem}"
    return None


def _outside(path: Path, root: Path) -> str | None:
    try:
        real = path.resolve(strict=True)
    except RuntimeError:  # Python < 3.13 reports a symlink loop so
        return "is a symlink loop"
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "is a symlink loop"
        return f"cannot be read ({exc.strerror})"
    if real == root or root in real.parents:
        return None
    return "leads outside the data folder"


class UploadFolder:
    """A private temporary folder for uploaded files (mode 0700), with a size limit per file
    and for the whole folder; removed on :meth:`close` and, failing that, when the interpreter
    exits (see :func:`exit_on_termination_signals` for the signals that would skip that)."""

    def __init__(
        self, *, max_bytes: int = DEFAULT_UPLOAD_LIMIT, max_total_bytes: int | None = None
    ) -> None:
        self.max_bytes = max_bytes
        self.max_total_bytes = (
            max_total_bytes if max_total_bytes is not None else UPLOAD_FOLDER_FILES * max_bytes
        )
        self.path = Path(tempfile.mkdtemp(prefix="routefuse-uploads-")).resolve()
        self._remove = weakref.finalize(self, shutil.rmtree, self.path, ignore_errors=True)
        self._lock = threading.Lock()
        self._count = 0
        self._used = 0

    def used_bytes(self) -> int:
        """The bytes of the files saved so far."""
        with self._lock:
            return self._used

    def check_size(self, filename: str, size: int) -> None:
        if size > self.max_bytes:
            raise RoutefuseError(
                filename,
                f"upload of {size / 1e6:.1f} MB exceeds the limit of "
                f"{self.max_bytes / 1e6:.0f} MB (put large logs in a --data-dir instead)",
            )

    def check_room(self, filename: str, size: int) -> None:
        """Refuse ``size`` more bytes (an upload, or all of them still in flight) when the
        folder would pass its total cap."""
        used = self.used_bytes()
        if used + size > self.max_total_bytes:
            raise RoutefuseError(
                filename,
                f"the upload folder is full ({used / 1e6:.1f} MB used of "
                f"{self.max_total_bytes / 1e6:.0f} MB; restart the server to empty it, or put "
                "logs in a --data-dir)",
            )

    def check_received(self, filename: str, declared: int, received: int) -> None:
        """Refuse a transfer that has sent more than it declared or than the limit allows."""
        self.check_size(filename, received)
        if received > declared:
            raise RoutefuseError(
                filename,
                f"the browser sent {received} bytes but declared {declared}: upload dropped",
            )

    def save(self, filename: str, content: bytes) -> Path:
        """Write an upload under a sanitised name; the client's name never picks a folder."""
        self.check_size(filename, len(content))
        if not content:
            raise RoutefuseError(filename, "the uploaded file is empty")
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(filename.replace("\\", "/")).name)
        base = base.lstrip(".") or "upload"
        if not (Path(base).suffix.lower() in log_suffixes() or route_format(base) is not None):
            raise RoutefuseError(
                filename, f"not a log ({LOG_SUFFIXES_TEXT}) or route ({ROUTE_SUFFIXES_TEXT})"
            )
        with self._lock:
            if self._used + len(content) > self.max_total_bytes:
                raise RoutefuseError(
                    filename,
                    f"the upload folder is full ({self._used / 1e6:.1f} MB used of "
                    f"{self.max_total_bytes / 1e6:.0f} MB)",
                )
            self._used += len(content)
            self._count += 1
            target = self.path / f"{self._count:03d}-{base}"
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(content)
        return target

    def close(self) -> None:
        self._remove()


def exit_on_termination_signals() -> None:
    """Make SIGTERM and SIGHUP end the process as Ctrl+C does, through ``finally`` blocks and
    exit handlers (their default ends it at once, leaving the upload folder behind). Call
    from the main thread of a command that owns the process."""

    def leave(signum: int, _frame: object) -> None:
        raise SystemExit(128 + signum)

    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, leave)
