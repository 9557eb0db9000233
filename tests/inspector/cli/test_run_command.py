"""``routefuse run`` end to end on a simulated bag written into tmp_path."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from estimator.sim import simulate
from inspector.cli.main import main

DATA = Path(__file__).resolve().parents[3] / ".." / "shared" / "data"

ROUTE_KEYS = {
    "max_pos_dev_m",
    "mean_pos_dev_m",
    "rmse_pos_dev_m",
    "mean_heading_dev_deg",
    "rmse_heading_dev_deg",
}
TRUTH_KEYS = {
    "max_h_err_m",
    "mean_h_err_m",
    "rmse_h_err_m",
    "rmse_along_m",
    "rmse_cross_m",
    "rmse_heading_err_deg",
}


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    sim = simulate("short_tunnel", seed=2, duration_s=60.0)
    return sim.write(out)


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ROUTEFUSE_CACHE_DIR", str(tmp_path / "cache"))


def test_table_and_json(bag, tmp_path, capsys):
    log, route = bag
    out = tmp_path / "result.json"
    argv = ["run", str(log), "--route", str(route), "--json", str(out), "--outage", "20:30"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert lines[0].split()[:2] == ["Scenario", "Method"]
    assert "Max pos. dev. [m]" in lines[0] and "H. err RMSE [m]" in lines[0]
    assert [line.split()[1] for line in lines[2:4]] == ["baseline", "proposed"]
    spans = re.search(r"GNSS-degraded: ([\d.]+)-([\d.]+) s, ([\d.]+)-", text)
    assert spans is not None
    assert float(spans[1]) == pytest.approx(20.0, abs=0.25)
    assert float(spans[2]) == pytest.approx(30.0, abs=0.25)
    assert float(spans[3]) == pytest.approx(38.0, abs=0.5)  # the tunnel
    doc = json.loads(out.read_text())
    assert set(doc) >= {
        "log",
        "route",
        "duration_s",
        "distance_m",
        "degraded_intervals",
        "methods",
        "matches",
    }
    assert doc["log"] == str(log) and doc["route"] == str(route)
    assert doc["duration_s"] == pytest.approx(60.0, abs=0.05)
    assert 700 < doc["distance_m"] < 1000  # 15 m/s for 60 s, minus the alignment second
    assert len(doc["degraded_intervals"]) == 2  # the injected outage and the tunnel
    a, b = doc["degraded_intervals"][0]
    assert a == pytest.approx(20.0, abs=0.25) and b == pytest.approx(30.0, abs=0.25)
    assert set(doc["methods"]) == {"baseline", "proposed"}
    for m in doc["methods"].values():
        assert set(m) == {"route", "truth"}
        assert set(m["route"]) == ROUTE_KEYS
        assert set(m["truth"]) == TRUTH_KEYS
        assert all(isinstance(v, float) for v in m["route"].values())
    matches = doc["matches"]
    assert set(matches) == {"attempted", "accepted", "rejected"}
    assert matches["attempted"] >= matches["accepted"] > 0
    assert sum(matches["rejected"].values()) == matches["attempted"] - matches["accepted"]
    for m in doc["methods"].values():
        assert all(v is not None and v >= 0 for v in m["truth"].values() if v is not None)
        assert m["truth"]["rmse_h_err_m"] < 10.0


def test_methods_and_csv(bag, tmp_path, capsys):
    log, route = bag
    out = tmp_path / "epochs.csv"
    argv = ["run", str(log), "--route", str(route), "--method", "paper", "--csv", str(out)]
    assert main([*argv, "--quiet"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[1] for line in lines[2:3]] == ["paper"]
    with out.open() as f:
        rows = list(csv.DictReader(f))
    assert {r["method"] for r in rows} == {"paper"}
    assert 55 * 20 < len(rows) < 61 * 20 + 60
    assert {r["degraded"] for r in rows} == {"0", "1"}
    assert all(float(r["sigma_east_m"]) > 0 for r in rows)
    assert all(
        abs(float(r["cov_east_north_m2"]))
        <= 1.001 * float(r["sigma_east_m"]) * float(r["sigma_north_m"])
        for r in rows
    )


def test_parameters_reach_the_filter(bag, tmp_path):
    log, route = bag
    cfg = tmp_path / "p.toml"
    cfg.write_text("[gates]\nmin_pairs = 500\n")
    out = tmp_path / "r.json"
    argv = ["run", str(log), "--route", str(route), "--json", str(out), "--quiet"]
    assert main([*argv, "--config", str(cfg)]) == 0
    doc = json.loads(out.read_text())
    assert doc["matches"]["accepted"] == 0
    assert doc["matches"]["rejected"] == {"min_pairs": doc["matches"]["attempted"]}
    # the per-parameter flag wins over the file
    assert main([*argv, "--config", str(cfg), "--gates-min-pairs", "5"]) == 0
    assert json.loads(out.read_text())["matches"]["accepted"] > 0


def test_errors_are_one_line(bag, tmp_path, capsys):
    log, route = bag
    assert main(["run", str(tmp_path / "missing.mcap"), "--route", str(route)]) == 3
    err = capsys.readouterr().err.strip()
    assert err.startswith("routefuse: error:") and "missing.mcap" in err
    assert "\n" not in err
    assert main(["run", str(log), "--route", str(route), "--outage", "30:20"]) == 3
    err = capsys.readouterr().err
    assert "END must be after START" in err and err.count("\n") == 1
    assert main(["run", str(log), "--route", str(route), "--outage", "30-60"]) == 3
    assert "'30-60' is not START:END in seconds" in capsys.readouterr().err
    assert main(["run", str(log), "--route", str(route), "--outage", "500:600"]) == 3
    assert "starts after the log ends" in capsys.readouterr().err
    bad = ["run", str(log), "--route", str(route), "--json", str(tmp_path / "no" / "x.json")]
    assert main([*bad, "--quiet"]) == 3
    assert "cannot write" in capsys.readouterr().err


def test_comma_bag_with_an_outage(tmp_path, capsys):
    log = DATA / "comma2k19" / "i280.mcap"
    if not log.exists():
        pytest.skip(f"{log} not present (shared sample data)")
    out = tmp_path / "r.json"
    argv = [
        "run", str(log), "--route", str(DATA / "comma2k19" / "i280_route.geojson"),
        "--outage", "20:50", "--sensors-imu-pitch-deg", "-3.8", "--sensors-imu-yaw-deg", "0.9",
        "--json", str(out), "--quiet",
    ]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    base, prop = doc["methods"]["baseline"], doc["methods"]["proposed"]
    assert prop["route"]["rmse_pos_dev_m"] < base["route"]["rmse_pos_dev_m"]
    assert prop["truth"]["rmse_cross_m"] < base["truth"]["rmse_cross_m"]


def test_without_route_the_one_beside_the_log_is_used(bag, tmp_path, capsys):
    """As ``serve`` does: ``<name>.route.*`` beside the log; none is one line, exit 3."""
    import shutil

    log, route = bag
    assert route.name.split(".")[0] == log.name.split(".")[0]
    out = tmp_path / "r.json"
    assert main(["run", str(log), "--json", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["route"] == str(route)
    lone = tmp_path / "lone.mcap"
    shutil.copy(log, lone)
    capsys.readouterr()
    assert main(["run", str(lone)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"routefuse: error: {lone}: no route given and none beside the log (<name>.route.*): "
        "give one with --route"
    ]


def _bad_logs(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """Logs with no route beside them, each with the problem ``run`` must name."""
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    noise = tmp_path / "noise.mcap"
    noise.write_bytes(bytes(range(256)) * 4)
    folder = tmp_path / "folder"
    folder.mkdir()
    unknown = tmp_path / "x.foo"
    unknown.write_text("x\n")
    return {
        "missing": (tmp_path / "missing.mcap", "missing.mcap: no such file or folder"),
        "empty": (empty, "empty.mcap: file is empty"),
        "random bytes": (noise, "noise.mcap: not a ROS 2 bag / mcap file"),
        "folder": (folder, "folder: folder is not a ROS 2 bag (it has no metadata.yaml)"),
        "unknown extension": (unknown, "x.foo: unknown log format '.foo'"),
    }


BAD_LOGS = ["missing", "empty", "random bytes", "folder", "unknown extension"]


@pytest.mark.parametrize("case", BAD_LOGS)
def test_without_route_a_bad_log_is_reported_as_such(case, tmp_path, capsys):
    """The log's own problem, not "no route given and none beside the log"."""
    log, problem = _bad_logs(tmp_path)[case]
    assert main(["run", str(log)]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("routefuse: error: "), err
    assert problem in err and "--route" not in err, err


def test_a_bag_folder_is_still_a_log_without_route(tmp_path, capsys):
    """A ROS 2 bag folder passes the log check: what is missing is its route."""
    bag_folder = tmp_path / "drive"
    bag_folder.mkdir()
    (bag_folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert main(["run", str(bag_folder)]) == 3
    assert "no route given and none beside the log" in capsys.readouterr().err


@pytest.fixture
def no_estimation(monkeypatch):
    """Fails the test if ``run`` starts loading the log."""
    import estimator.pipeline

    def refuse(*args, **kwargs):
        raise AssertionError("the log was loaded before the arguments were checked")

    monkeypatch.setattr(estimator.pipeline, "open_inputs", refuse)


@pytest.mark.parametrize("option", ["--json", "--csv"])
def test_output_folders_are_checked_before_running(bag, tmp_path, capsys, option, no_estimation):
    log, route = bag
    out = tmp_path / "no" / "such" / "x.out"
    assert main(["run", str(log), "--route", str(route), option, str(out), "--quiet"]) == 3
    err = capsys.readouterr().err
    assert err == f"routefuse: error: {out}: cannot write: no folder {out.parent}\n"
    assert main(["run", str(log), "--route", str(route), option, str(tmp_path), "--quiet"]) == 3
    assert capsys.readouterr().err == f"routefuse: error: {tmp_path}: cannot write: is a folder\n"


def test_a_folder_given_as_route_is_named_a_folder(bag, tmp_path, capsys, no_estimation):
    log, _ = bag
    folder = tmp_path / "routes"
    folder.mkdir()
    assert main(["run", str(log), "--route", str(folder)]) == 3
    err = capsys.readouterr().err
    assert err == f"routefuse: error: {folder}: is a folder, expected a route file\n"


def test_a_log_without_truth_says_the_table_is_route_deviation_only(bag, tmp_path, capsys):
    """The table of a log without ground truth had no truth columns and no word about it: the
    route deviation read as the accuracy."""
    from estimator.io import load_log, write_bag

    log, route = bag
    sim = load_log(log, cache_dir=tmp_path / "c")
    bare = tmp_path / "bare.mcap"
    write_bag(bare, imu=sim.imu, gnss=sim.gnss, wheel=sim.wheel)
    assert main(["run", str(bare), "--route", str(route), "--quiet"]) == 0
    assert "no ground truth in this log: the table gives the deviation from the route only" in (
        capsys.readouterr().out
    )
    assert main(["run", str(log), "--route", str(route), "--quiet"]) == 0
    assert "no ground truth" not in capsys.readouterr().out


def test_check_exits_fails_a_run_that_followed_a_wrong_map(tmp_path, capsys):
    """The monaco sample on its route drawn 10 m north, with the map's bias unlearned and the
    separation from dead reckoning unwatched: every route update follows the wrong map, and
    ``--check-exits`` turns the exit warning into status 5 for CI; with the defaults the same
    map passes. Without proposed among the methods there is nothing to check: refused."""
    from inspector.cli.exit_codes import ExitCode

    samples = Path(__file__).resolve().parents[3] / "sample_logs"
    data = json.loads((samples / "monaco_tunnel.route.geojson").read_text(encoding="utf-8"))
    for feature in data["features"]:
        feature["geometry"]["coordinates"] = [
            [lon, lat + 0.00009, *rest] for lon, lat, *rest in feature["geometry"]["coordinates"]
        ]
    route = tmp_path / "north.route.geojson"
    route.write_text(json.dumps(data), encoding="utf-8")
    log = str(samples / "monaco_tunnel.mcap")
    trusting = ["--set", "extensions.map_bias=false", "--set", "extensions.dr_separation=false"]
    argv = ["run", log, "--route", str(route), "--quiet", "--check-exits"]
    out = tmp_path / "run.json"
    assert main([*argv, *trusting, "--json", str(out)]) == ExitCode.EXIT_CHECK_FAILED
    err = capsys.readouterr().err
    assert "proposed run: the outage at 108.4-224.4 s ended " in err
    assert [x["overconfident"] for x in json.loads(out.read_text())["exits"]["proposed"]] == [True]
    assert main(argv) == ExitCode.OK
    assert main([*argv, "--method", "baseline"]) == ExitCode.REFUSED
    assert "routefuse: error: --check-exits: " in capsys.readouterr().err
