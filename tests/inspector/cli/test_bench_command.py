"""``routefuse bench`` from the command line: the JSON document of a short smoke run (no timing
assertions: speed targets live in the benchmark's own figures), and usage errors."""

from __future__ import annotations

import json

import pytest

from inspector.cli.main import main


def test_quick_load_json(tmp_path, capsys):
    argv = ["bench", "--quick", "--only", "load", "--duration", "20", "--repeat", "1"]
    assert main([*argv, "--dir", str(tmp_path), "--json"]) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert set(doc) >= {"machine", "settings", "items", "total_s"}
    assert doc["machine"]["cores"] >= 1 and doc["settings"]["quick"] is True
    names = [(r["name"], r["log"]) for r in doc["items"]]
    assert names == [("load_first", "10min"), ("load_cached", "10min")]
    for r in doc["items"]:
        assert r["error"] is None
        assert set(r) >= {"name", "log", "figures", "peak_rss_mb", "targets"}
        assert {"wall_s", "cpu_s", "peak_rss_mb"} <= set(r["figures"])
        assert r["peak_rss_mb"] > 0
    first = doc["items"][0]["figures"]
    assert first["messages"] > 20 * 200 and first["messages_per_s"] > 0
    assert "simulating long_drive_10min" in captured.err  # progress on stderr
    # the simulated log and its decoded cache are kept for the next run
    assert list((tmp_path / "logs").glob("*/long_drive_10min.mcap"))
    assert list((tmp_path / "cache").glob("log-*.npz"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--only", "nonsense"], "unknown item nonsense"),
        (["--repeat", "0"], "--repeat: must be at least 1"),
        (["--duration", "-5"], "--duration: must be a positive"),
    ],
)
def test_usage_errors(argv, message, tmp_path, capsys):
    assert main(["bench", "--dir", str(tmp_path), *argv]) == 3
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "logs").exists()


def test_startup_figures(tmp_path, capsys):
    """``routefuse bench`` reports the start-up figures: ``routefuse --help`` and ``routefuse
    run`` as whole commands, each with its target."""
    argv = ["bench", "--quick", "--only", "startup", "--duration", "20", "--repeat", "1"]
    assert main([*argv, "--dir", str(tmp_path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    items = {r["name"]: r for r in doc["items"]}
    assert set(items) == {"startup_help", "startup_run"}
    for r in items.values():
        assert r["error"] is None and r["log"] == "5min"
        assert 0 < r["figures"]["wall_s"] <= r["figures"]["wall_median_s"]
        assert [t["figure"] for t in r["targets"]] == ["wall_s"]
    assert items["startup_run"]["figures"]["log_s"] > 10


def test_without_a_source_checkout_one_line_says_what_to_do(tmp_path, monkeypatch, capsys):
    """An installed package has no benchmarks/ beside it: one line says to use a checkout."""
    from inspector.cli import bench

    installed = tmp_path / "site-packages" / "inspector" / "cli" / "bench.py"
    monkeypatch.setattr(bench, "__file__", str(installed))
    assert main(["bench", "--dir", str(tmp_path / "bench")]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "source checkout" in err
    assert not (tmp_path / "bench").exists()
