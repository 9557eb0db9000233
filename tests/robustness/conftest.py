"""Session fixtures of the bad-input corpus."""

from __future__ import annotations

from pathlib import Path

import pytest
from _badinputs import Corpus, write_route


@pytest.fixture(scope="session")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Corpus:
    return Corpus(tmp_path_factory.mktemp("corpus"))


@pytest.fixture(scope="session")
def route(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The valid route of the base drive."""
    return write_route(tmp_path_factory.mktemp("route") / "route.geojson")
