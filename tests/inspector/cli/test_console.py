"""The console script ends ``run`` and ``info`` without the interpreter's teardown: what they
print and write must be complete, and the exit codes the same as :func:`main`'s."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
CONSOLE = "from inspector.cli.main import console; console()"


def _console(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", CONSOLE, *argv],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_run_through_the_console_writes_and_prints_everything(tmp_path: Path) -> None:
    log = REPO / "sample_logs" / "monaco_tunnel.mcap"
    route = REPO / "sample_logs" / "monaco_tunnel.route.geojson"
    out = tmp_path / "run.json"
    done = _console("run", str(log), "--route", str(route), "--json", str(out), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "matches accepted" in done.stdout
    assert json.loads(out.read_text(encoding="utf-8"))["methods"]["proposed"]["truth"]


def test_an_error_through_the_console_is_one_line_and_exit_3(tmp_path: Path) -> None:
    done = _console("info", str(tmp_path / "missing.mcap"), cwd=tmp_path)
    assert done.returncode == 3
    assert done.stderr.count("\n") == 1 and "missing.mcap" in done.stderr


def test_a_usage_error_and_a_refused_file_have_different_exit_codes(tmp_path: Path) -> None:
    """argparse's 2 means the command line itself is wrong; a file the command cannot use is
    3 (both were 2, so a script could not tell them apart), and --help lists every code."""
    usage = _console("info", "--no-such-option", str(tmp_path / "a.mcap"), cwd=tmp_path)
    refused = _console("info", str(tmp_path / "a.mcap"), cwd=tmp_path)
    assert (usage.returncode, refused.returncode) == (2, 3)
    assert usage.stderr.startswith("usage: ")
    assert refused.stderr.startswith("routefuse: error: ")
    listed = _console("--help", cwd=tmp_path).stdout.split("exit codes:")[1].split()
    assert [word for word in listed if word.isdigit()] == ["0", "1", "2", "3", "4", "5", "130"]


def test_version_prints_the_installed_version_and_exits_0(tmp_path: Path) -> None:
    from importlib.metadata import version

    done = _console("--version", cwd=tmp_path)
    assert done.returncode == 0 and done.stderr == ""
    assert done.stdout == f"routefuse {version('routefuse')}\n"


def test_version_without_an_installed_distribution(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import importlib.metadata

    from inspector.cli.main import main

    def not_installed(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out == "routefuse unknown (not installed)\n"
