"""Shared fixtures: no test writes to the user's cache; real data is found relative to the repo."""

from __future__ import annotations

import os
from collections.abc import Iterator
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
