"""``routefuse sweep`` argument errors: one line, exit 3, before any cluster starts."""

from __future__ import annotations

from pathlib import Path

import pytest

from inspector.cli.main import main


def test_a_missing_log_is_named_missing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nonexistent.mcap"
    assert main(["sweep", str(missing), "--out", str(tmp_path / "out")]) == 3
    assert capsys.readouterr().err == f"routefuse: error: {missing}: no such file or folder\n"
    assert not (tmp_path / "out").exists()


def test_a_glob_matching_nothing_still_says_no_logs_found(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pattern = str(tmp_path / "nothing-*.mcap")
    assert main(["sweep", pattern, "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{pattern}: no logs found" in err


def test_the_failed_tasks_are_named_after_the_summary_even_when_quiet(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Exit 4 says some task failed; the output says which and why (it used to give only the
    count with --quiet, so a CI log could not tell what failed)."""
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    out = tmp_path / "out"
    assert main(["sweep", str(empty), "--out", str(out), "--quiet"]) == 4
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    assert "1 failed" in lines[0]
    assert lines[-1] == f"failed: empty.mcap default: {empty}: file is empty"
    assert captured.err == ""


def test_a_log_named_inside_an_unreadable_folder_is_a_failed_row_not_the_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], unreadable
) -> None:
    """It used to stop the whole sweep before anything ran ("cannot open it"), or end it
    with an internal PermissionError; a missing path still does (a typo)."""
    locked = tmp_path / "locked"
    locked.mkdir()
    (locked / "a.mcap").write_bytes(b"x")
    (locked / "a.route.geojson").write_text("{}")
    empty = tmp_path / "b.mcap"
    empty.write_bytes(b"")
    unreadable(locked)
    out = tmp_path / "out"
    assert main(["sweep", str(locked / "a.mcap"), str(empty), "--out", str(out), "--quiet"]) == 4
    lines = capsys.readouterr().out.splitlines()
    assert "2 failed" in lines[0]
    assert (
        f"failed: a.mcap default: {locked / 'a.mcap'}: cannot open it (Permission denied)" in lines
    )
    assert f"failed: b.mcap default: {empty}: file is empty" in lines
