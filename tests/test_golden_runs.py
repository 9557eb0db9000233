"""Whole runs of every bundled sample, compared with what the code produced when the goldens were
recorded: the ``routefuse run`` JSON document (full-precision metrics of every method) and the
SHA-256 of its epoch CSV must be identical. A refactoring that changes any bit of a result
fails here.

The goldens were recorded at 44dae27 (before the restructure of issue 15). To record them
again after a deliberate change of results: ``ROUTEFUSE_UPDATE_GOLDEN=1 pytest
tests/test_golden_runs.py``, and say in the commit why the results moved.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest

from inspector.cli.main import main

REPO = Path(__file__).resolve().parents[1]
GOLDEN = Path(__file__).resolve().parent / "golden"

CASES: dict[str, tuple[str, ...]] = {
    "long_tunnel": ("sample_logs/long_tunnel.mcap",),
    "spiral_tunnel": ("sample_logs/spiral_tunnel.mcap",),
    "multi_tunnel": ("sample_logs/multi_tunnel.mcap",),
    "monaco_tunnel": ("sample_logs/monaco_tunnel.mcap",),
    "monaco_tunnel_outage": ("sample_logs/monaco_tunnel.mcap", "--outage", "20:70"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_run_matches_golden(
    case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    log, *extra = CASES[case]
    route = log.replace(".mcap", ".route.geojson")
    monkeypatch.chdir(REPO)
    out_json, out_csv = tmp_path / "run.json", tmp_path / "run.csv"
    argv = ["run", log, "--route", route, "--method", "baseline", "proposed", "paper", "--quiet"]
    code = main([*argv, *extra, "--json", str(out_json), "--csv", str(out_csv)])
    assert code == 0, capsys.readouterr().err
    got = {
        "json": json.loads(out_json.read_text(encoding="utf-8")),
        "csv_sha256": hashlib.sha256(out_csv.read_bytes()).hexdigest(),
    }
    path = GOLDEN / f"{case}.json"
    if os.environ.get("ROUTEFUSE_UPDATE_GOLDEN") == "1":
        path.write_text(json.dumps(got, indent=1) + "\n", encoding="utf-8")
    want = json.loads(path.read_text(encoding="utf-8"))
    assert got["json"] == want["json"]
    assert got["csv_sha256"] == want["csv_sha256"]


EXPORT_FILES = ("matches.csv", "trajectory_proposed.csv", "trajectory_baseline.csv", "metrics.csv")


@pytest.mark.slow
@pytest.mark.parametrize("case", ["long_tunnel", "monaco_tunnel"])
def test_export_tables_match_golden(
    case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The exported per-attempt gate table and trajectories: every gate value, threshold and
    verdict of every attempt, bit for bit as text."""
    log = f"sample_logs/{case}.mcap"
    monkeypatch.chdir(REPO)
    out = tmp_path / "export"
    argv = ["export", log, "--route", log.replace(".mcap", ".route.geojson"), "--out", str(out)]
    code = main(argv)
    assert code == 0, capsys.readouterr().err
    got = {name: hashlib.sha256((out / name).read_bytes()).hexdigest() for name in EXPORT_FILES}
    path = GOLDEN / f"export_{case}.json"
    if os.environ.get("ROUTEFUSE_UPDATE_GOLDEN") == "1":
        path.write_text(json.dumps(got, indent=1) + "\n", encoding="utf-8")
    assert got == json.loads(path.read_text(encoding="utf-8"))
