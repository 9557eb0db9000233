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


def test_an_error_through_the_console_is_one_line_and_exit_2(tmp_path: Path) -> None:
    done = _console("info", str(tmp_path / "missing.mcap"), cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "missing.mcap" in done.stderr


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
