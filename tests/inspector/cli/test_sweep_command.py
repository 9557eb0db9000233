"""``routefuse sweep`` argument errors: one line, exit 2, before any cluster starts."""

from __future__ import annotations

from pathlib import Path

import pytest

from inspector.cli.main import main


def test_a_missing_log_is_named_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nonexistent.mcap"
    assert main(["sweep", str(missing), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == f"routefuse: error: {missing}: no such file or folder\n"
    assert not (tmp_path / "out").exists()


def test_a_glob_matching_nothing_still_says_no_logs_found(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pattern = str(tmp_path / "nothing-*.mcap")
    assert main(["sweep", pattern, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{pattern}: no logs found" in err
