"""The files the inspector may open: the data folders it lists (and nothing outside them) and
the private folder uploads are written to. Which files are logs is the log-format registry's
call (:mod:`estimator.io`)."""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import threading
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


@dataclass(frozen=True)
class Listing:
    """Display name -> path of every log and route under the data folders."""

    logs: dict[str, Path]
    routes: dict[str, Path]


@dataclass(frozen=True)
class DataFolders:
    """The folders the server may read from. Only what :meth:`listing` found can be opened, so a
    name can never reach outside them (no ``..``, no symlink leading out)."""

    roots: tuple[Path, ...]
    max_depth: int = 4
    max_entries: int = 5000

    @classmethod
    def of(cls, *roots: str | Path) -> DataFolders:
        seen: list[Path] = []
        for r in roots:
            p = Path(r).expanduser().resolve()
            if p.is_dir() and p not in seen:
                seen.append(p)
        return cls(tuple(seen))

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
        count = 0
        for label, root in zip(self._labels(), self.roots, strict=True):
            for path in self._walk(root):
                count += 1
                if count > self.max_entries:
                    break
                name = f"{label}/{path.relative_to(root).as_posix()}"
                if path.is_dir() or is_log_path(path):
                    logs[name] = path
                elif is_route_path(path):
                    routes[name] = path
        return Listing(dict(sorted(logs.items())), dict(sorted(routes.items())))

    def _walk(self, root: Path) -> Iterable[Path]:
        """Candidate files and ROS 2 bag folders under ``root`` whose real path stays inside it."""
        root_depth = len(root.parts)
        for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
            here = Path(dirpath)
            dirnames.sort()
            if len(here.parts) - root_depth >= self.max_depth:
                dirnames.clear()
            if "metadata.yaml" in filenames and here != root:
                dirnames.clear()
                if _inside(here, root):
                    yield here
                continue
            dirnames[:] = [d for d in dirnames if not d.startswith(".")]
            for name in sorted(filenames):
                p = here / name
                if (is_log_path(p) or is_route_path(p)) and _inside(p, root):
                    yield p

    def resolve(self, name: str, kind: Kind) -> Path:
        """The path behind a display name from :meth:`listing`."""
        listing = self.listing()
        table = listing.logs if kind == "log" else listing.routes
        path = table.get(name)
        if path is None:
            raise RoutefuseError(name, f"no such {kind} under the data folders")
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


def _inside(path: Path, root: Path) -> bool:
    try:
        real = path.resolve(strict=True)
    except OSError:
        return False
    return real == root or root in real.parents


class UploadFolder:
    """A private temporary folder for uploaded files (mode 0700, removed on :meth:`close`),
    with a size limit per file."""

    def __init__(self, *, max_bytes: int = DEFAULT_UPLOAD_LIMIT) -> None:
        self.max_bytes = max_bytes
        self.path = Path(tempfile.mkdtemp(prefix="routefuse-uploads-")).resolve()
        self._lock = threading.Lock()
        self._count = 0

    def check_size(self, filename: str, size: int) -> None:
        if size > self.max_bytes:
            raise RoutefuseError(
                filename,
                f"upload of {size / 1e6:.1f} MB exceeds the limit of "
                f"{self.max_bytes / 1e6:.0f} MB (put large logs in a --data-dir instead)",
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
            self._count += 1
            target = self.path / f"{self._count:03d}-{base}"
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(content)
        return target

    def close(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)
