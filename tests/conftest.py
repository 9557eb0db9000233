"""Shared fixtures: no test writes to the user's cache; real data is found relative to the repo."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


@pytest.fixture(autouse=True, scope="session")
def _private_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Point the log cache at a per-session temporary folder."""
    old = os.environ.get("ROUTEFUSE_CACHE_DIR")
    path = tmp_path_factory.mktemp("routefuse-cache")
    os.environ["ROUTEFUSE_CACHE_DIR"] = str(path)
    yield path
    if old is None:
        os.environ.pop("ROUTEFUSE_CACHE_DIR", None)
    else:
        os.environ["ROUTEFUSE_CACHE_DIR"] = old


@pytest.fixture
def shared_data() -> Path:
    """The folder of real logs and routes (``../shared/data``); skips the test if absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture
def unreadable(monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[[Path], Path]]:
    """``unreadable(folder)`` takes away the permission to look into ``folder`` (mode 0); where
    that does not stop this process (root), listing it and looking at anything inside it raise
    PermissionError as they would for another user. Restored afterwards."""
    locked: list[Path] = []

    def inside(path: object) -> bool:
        if isinstance(path, int):
            return False
        p = Path(os.fsdecode(path)).absolute()  # type: ignore[arg-type]
        return any(p == f or f in p.parents for f in locked)

    def below(path: object) -> bool:
        if isinstance(path, int):
            return False
        p = Path(os.fsdecode(path)).absolute()  # type: ignore[arg-type]
        return any(f in p.parents for f in locked)

    def denied(path: object) -> PermissionError:
        return PermissionError(13, "Permission denied", os.fsdecode(path))  # type: ignore[arg-type]

    real_stat, real_listdir, real_scandir = os.stat, os.listdir, os.scandir

    def stat(path, *args, **kwargs):  # type: ignore[no-untyped-def]
        if below(path):
            raise denied(path)
        return real_stat(path, *args, **kwargs)

    def listdir(path=".", *args, **kwargs):  # type: ignore[no-untyped-def]
        if inside(path):
            raise denied(path)
        return real_listdir(path, *args, **kwargs)

    def scandir(path=".", *args, **kwargs):  # type: ignore[no-untyped-def]
        if inside(path):
            raise denied(path)
        return real_scandir(path, *args, **kwargs)

    def lock(folder: Path) -> Path:
        folder.chmod(0)
        locked.append(folder.absolute())
        if os.access(folder, os.R_OK):  # root: make it behave as for anyone else
            monkeypatch.setattr(os, "stat", stat)
            monkeypatch.setattr(os, "listdir", listdir)
            monkeypatch.setattr(os, "scandir", scandir)
        return folder

    yield lock
    monkeypatch.undo()
    for folder in locked:
        folder.chmod(0o755)
