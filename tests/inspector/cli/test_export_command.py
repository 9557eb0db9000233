"""``routefuse export`` from the command line: one log with injected outages, a batch that keeps
going past a corrupt log and a log without a route, and usage errors as one line with exit 2."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from estimator.sim import simulate
from inspector.cli.main import main


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("sim")
    return simulate("short_tunnel", seed=3, duration_s=50.0).write(out)


def test_one_log_with_outages(bag, tmp_path, capsys):
    log, route = bag
    out = tmp_path / "out"
    argv = ["export", str(log), "--route", str(route), "--out", str(out)]
    assert main([*argv, "--outage", "10:20", "--fps", "1", "--time-lapse", "5"]) == 0
    captured = capsys.readouterr()
    assert "wrote 15 files" in captured.out and "report.html" in captured.out
    # the error against truth first (the log has truth), the route deviation beside it
    doc_truth = json.loads((out / "metrics.json").read_text())["methods"]["proposed"]
    assert (
        f"proposed  over the outages: error against truth RMSE "
        f"{doc_truth['truth']['rmse_h_err_m']:.2f} m; position deviation RMSE" in captured.out
    ), captured.out
    assert "short_tunnel.mcap: replay" in captured.err  # progress on stderr
    doc = json.loads((out / "metrics.json").read_text())
    a, b = doc["degraded_intervals"][0]
    assert a == pytest.approx(10.0, abs=0.25) and b == pytest.approx(20.0, abs=0.25)
    assert doc["outages"] == [[10.0, 20.0]]
    with (out / "matches.csv").open() as fh:
        t = [float(r["t_s"]) for r in csv.DictReader(fh)]
    assert any(10.0 <= x <= 20.5 for x in t), "no attempt in the injected outage"


def _summary(path: Path) -> dict[str, dict[str, str]]:
    with path.open(newline="") as fh:
        return {Path(r["log"]).name: r for r in csv.DictReader(fh)}


def test_batch_keeps_going_past_bad_logs(bag, tmp_path, capsys):
    log, route = bag
    data = tmp_path / "logs"
    data.mkdir()
    shutil.copy(log, data / log.name)
    shutil.copy(route, data / route.name)
    (data / "corrupt.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\x00garbage" * 100)
    shutil.copy(route, data / "corrupt.route.geojson")
    shutil.copy(log, data / "orphan.mcap")  # no orphan.route.geojson beside it
    out = tmp_path / "out"
    code = main(["export", "--batch", str(data), "--out", str(out), "--fps", "0.5"])
    captured = capsys.readouterr()
    assert code != 0
    rows = _summary(out / "summary.csv")
    assert set(rows) == {"corrupt.mcap", "orphan.mcap", "short_tunnel.mcap"}
    good = rows["short_tunnel.mcap"]
    assert good["status"] == "ok" and good["error"] == ""
    assert float(good["proposed_rmse_pos_dev_m"]) >= 0 and int(good["attempts"]) > 0
    assert (out / "short_tunnel" / "replay.html").stat().st_size > 100_000
    assert (out / "short_tunnel" / "metrics.json").exists()
    for name, reason in (("corrupt.mcap", "corrupt.mcap: "), ("orphan.mcap", "orphan.route")):
        row = rows[name]
        assert row["status"] == "failed"
        assert reason in row["error"] and "\n" not in row["error"]
        assert "Traceback" not in row["error"]
    assert not (out / "corrupt" / "replay.html").exists()
    # printed summary and per-log progress
    assert "short_tunnel.mcap" in captured.out and "failed: " in captured.out
    assert "[1/3]" in captured.err and "[3/3]" in captured.err


def test_batch_glob(bag, tmp_path, capsys):
    log, _ = bag
    out = tmp_path / "out"
    code = main(["export", "--batch", str(log.parent / "nothing-*.mcap"), "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no logs found" in err[0]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], "give a LOG"),
        (["LOG"], "--route"),
        (["LOG", "--route", "R", "--batch", "D"], "either"),
        (["LOG", "--route", "ROUTE", "--outage", "30:20"], "END must be after START"),
        (["LOG", "--route", "ROUTE", "--outage", "abc"], "START:END"),
        (["LOG", "--route", "ROUTE", "--fps", "-1"], "--fps"),
    ],
)
def test_usage_errors_are_one_line(bag, tmp_path, capsys, extra, message):
    log, route = bag
    argv = [str(log) if a == "LOG" else str(route) if a == "ROUTE" else a for a in extra]
    assert main(["export", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("routefuse: error: ") and message in err[0]


def test_missing_log(tmp_path, capsys):
    code = main(["export", str(tmp_path / "nope.mcap"), "--route", "r.geojson", "--out", "o"])
    assert code == 2
    assert "nope.mcap: no such file" in capsys.readouterr().err


def test_output_folder_that_is_a_file(bag, tmp_path, capsys):
    log, route = bag
    out = tmp_path / "taken"
    out.write_text("not a folder")
    assert main(["export", str(log), "--route", str(route), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"routefuse: error: {out}: cannot create the output folder")


def test_help_lists_the_options(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["export", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for option in ("--batch", "--outage", "--fps", "--time-lapse", "--config", "--imu-topic"):
        assert option in text


def test_subtract_lane_offset_is_offered_and_every_table_says_which_measure(tmp_path, capsys):
    """As the README's table: route deviations from the learned lane (issue 19)."""
    import json

    from estimator.sim import simulate
    from inspector.cli.main import main

    sim = simulate("short_tunnel", seed=3, duration_s=60.0)
    log, route = sim.write(tmp_path)
    outs = {}
    for flag in ([], ["--subtract-lane-offset"]):
        out = tmp_path / ("lane" if flag else "line")
        argv = ["export", str(log), "--route", str(route), "--out", str(out), "--fps", "2", *flag]
        assert main(argv) == 0
        printed = capsys.readouterr().out
        doc = json.loads((out / "metrics.json").read_text())
        outs[bool(flag)] = doc
        measure = "learned lane" if flag else "route line"
        assert doc["route_deviation_from"] == measure
        assert f"(from the {measure})" in printed
        assert measure in (out / "metrics.csv").read_text()
        assert f"measured from the {measure}" in (out / "report.html").read_text()
    assert outs[True]["methods"] != outs[False]["methods"]
    code = main(
        ["export", "--batch", str(tmp_path), "--out", str(tmp_path / "b"), "--subtract-lane-offset"]
    )
    assert code == 2
