"""``routefuse simulate`` end to end into tmp_path."""

from __future__ import annotations

import json

from estimator.io import load_log
from estimator.sim import SCENARIOS
from inspector.cli.main import main


def test_list(capsys) -> None:
    assert main(["simulate", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(SCENARIOS)
    assert all(len(line.split(maxsplit=1)) == 2 for line in lines)


def test_writes_bag_and_route(tmp_path, capsys) -> None:
    out = tmp_path / "out"
    argv = ["simulate", "short_tunnel", "--out", str(out), "--seed", "3", "--duration", "45"]
    assert main(argv) == 0
    bag = out / "short_tunnel.mcap"
    route = out / "short_tunnel.route.geojson"
    assert bag.is_file() and route.is_file()
    report = capsys.readouterr()
    assert "tunnels 38.1-" in report.out
    assert "simulating" in report.err  # progress
    log = load_log(bag, cache_dir=tmp_path / "cache")
    assert log.duration_s == 45.0
    assert len(log.imu.t) == 4501
    assert not log.gnss.valid[
        (log.gnss.t - log.t_start > 39) & (log.gnss.t - log.t_start < 45)
    ].any()
    assert json.loads(route.read_text())["features"][0]["geometry"]["type"] == "LineString"
    # the same command again refuses to overwrite, --force rewrites the same bytes
    first = bag.read_bytes()
    assert main(argv) == 2
    assert "already exists" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert bag.read_bytes() == first


def test_errors_are_one_line(tmp_path, capsys) -> None:
    assert main(["simulate", "nowhere", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("routefuse: error: unknown scenario 'nowhere'")
    assert "\n" not in err
    assert main(["simulate", "short_tunnel"]) == 2
    assert "--out" in capsys.readouterr().err


def test_imu_rate_and_perfect(tmp_path) -> None:
    argv = ["simulate", "short_tunnel", "--out", str(tmp_path), "--duration", "5"]
    assert main([*argv, "--imu-rate", "200", "--perfect"]) == 0
    log = load_log(tmp_path / "short_tunnel.mcap", cache_dir=tmp_path / "cache")
    assert len(log.imu.t) == 1001
