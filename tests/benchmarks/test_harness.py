"""The bench's item selection, targets and table (the measuring itself is exercised by
``tests/inspector/cli/test_bench_command.py``)."""

from __future__ import annotations

import pytest

from benchmarks.harness import ITEM_NAMES, Target, format_table, select_items
from benchmarks.measures import MEASURES
from estimator.errors import ConfigError


def test_every_item_has_a_measure():
    assert set(ITEM_NAMES) == set(MEASURES)


def test_select_by_name_and_prefix():
    assert [i.name for i in select_items(["load"])] == ["load_first", "load_cached"]
    assert [i.name for i in select_items(["proposed", "export"])] == ["proposed", "export"]
    assert {i.name for i in select_items(["rerun"])} == {
        "rerun_matching",
        "rerun_early",
        "rerun_window",
        "rerun_noise",
    }
    assert len(select_items([])) == len(ITEM_NAMES)
    with pytest.raises(ConfigError, match="unknown item bogus"):
        select_items(["bogus"])


def test_target_verdicts():
    upper = Target("wall_s", "<=", 0.5, "<= 0.5 s")
    lower = Target("x_realtime", ">=", 1000.0, ">= 1000x")
    assert upper.met({"wall_s": 0.4}) is True and upper.met({"wall_s": 0.6}) is False
    assert lower.met({"x_realtime": 1500.0}) is True
    assert upper.met({}) is None and upper.met({"wall_s": float("nan")}) is None


def test_table_names_figures_targets_and_failures():
    doc = {
        "machine": {
            "cpu": "cpu X",
            "cores": 2,
            "python": "3.11",
            "commit": "abc",
            "load_average": [3.0, 2.0, 1.0],
        },
        "items": [
            {
                "name": "proposed",
                "log": "60min",
                "error": None,
                "peak_rss_mb": 512.0,
                "figures": {"cpu_s": 2.5, "wall_s": 3.0, "x_realtime": 1441.2, "attempts": 12},
                "targets": [{"figure": "x_realtime", "target": ">= 1000x real time", "met": True}],
            },
            {
                "name": "export",
                "log": "10min",
                "error": "exit 1: boom",
                "peak_rss_mb": None,
                "figures": {},
                "targets": [],
            },
        ],
    }
    text = format_table(doc)
    assert "x real time (cpu) 1,441" in text and ">= 1000x real time: met" in text
    assert "FAILED: exit 1: boom" in text
    assert "cpu X, 2 cores" in text and "load average at start 3.0" in text


def test_timed_commands_read_byte_code_even_where_the_shell_turns_it_off(tmp_path, monkeypatch):
    """With ``PYTHONDONTWRITEBYTECODE`` set, the start-up commands would compile routefuse's
    modules from source at every run, which no installed routefuse does: their byte code goes
    to the bench's cache folder instead (the checkout untouched). Otherwise nothing changes."""
    from benchmarks.measures import _command_env

    monkeypatch.setenv("ROUTEFUSE_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("PYTHONPYCACHEPREFIX", raising=False)
    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    env = _command_env()
    assert "PYTHONDONTWRITEBYTECODE" not in env
    assert env["PYTHONPYCACHEPREFIX"] == str(tmp_path / "pycache")
    monkeypatch.delenv("PYTHONDONTWRITEBYTECODE")
    env = _command_env()
    assert "PYTHONPYCACHEPREFIX" not in env and "PYTHONDONTWRITEBYTECODE" not in env
