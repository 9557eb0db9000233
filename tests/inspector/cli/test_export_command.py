"""``routefuse export`` from the command line: one log with injected outages, a batch that keeps
going past a corrupt log and a log without a route, and refused commands as one line with exit 3."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from estimator.errors import RoutefuseError
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
    assert code == 4  # ran to the end, two logs failed
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
    assert code == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no logs found" in err[0]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], "give a LOG"),
        (["LOG", "--route", "R", "--batch", "D"], "either"),
        (["LOG", "--route", "ROUTE", "--outage", "30:20"], "END must be after START"),
        (["LOG", "--route", "ROUTE", "--outage", "abc"], "START:END"),
        (["LOG", "--route", "ROUTE", "--fps", "-1"], "--fps"),
    ],
)
def test_usage_errors_are_one_line(bag, tmp_path, capsys, extra, message):
    log, route = bag
    argv = [str(log) if a == "LOG" else str(route) if a == "ROUTE" else a for a in extra]
    assert main(["export", *argv, "--out", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("routefuse: error: ") and message in err[0]


def test_missing_log(tmp_path, capsys):
    code = main(["export", str(tmp_path / "nope.mcap"), "--route", "r.geojson", "--out", "o"])
    assert code == 3
    assert "nope.mcap: no such file" in capsys.readouterr().err


def test_output_folder_that_is_a_file(bag, tmp_path, capsys):
    log, route = bag
    out = tmp_path / "taken"
    out.write_text("not a folder")
    assert main(["export", str(log), "--route", str(route), "--out", str(out)]) == 3
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
    assert code == 3


@pytest.fixture
def captured_export(monkeypatch):
    """``export_log`` replaced: records the route it was given, then stops the command."""
    import inspector.export

    routes: list[Path] = []

    def fake_export_log(log, route, out, **kwargs):
        routes.append(route)
        raise RoutefuseError(None, "stopped before exporting")

    monkeypatch.setattr(inspector.export, "export_log", fake_export_log)
    return routes


def test_without_route_the_one_beside_the_log_is_used(bag, tmp_path, capsys, captured_export):
    """As ``run`` and ``serve`` do; none beside it is ``run``'s one line."""
    log, route = bag
    assert main(["export", str(log), "--out", str(tmp_path / "o")]) == 3
    assert captured_export == [route]
    assert "stopped before exporting" in capsys.readouterr().err
    lone = tmp_path / "lone.mcap"
    shutil.copy(log, lone)
    assert main(["export", str(lone), "--out", str(tmp_path / "o")]) == 3
    assert capsys.readouterr().err == (
        f"routefuse: error: {lone}: no route given and none beside the log (<name>.route.*): "
        "give one with --route\n"
    )
    assert captured_export == [route]


def test_a_bad_log_and_a_folder_route_are_named(bag, tmp_path, capsys, captured_export):
    bad = tmp_path / "bad.foo"
    bad.write_text("x")
    assert main(["export", str(bad), "--out", str(tmp_path / "o")]) == 3
    assert "bad.foo: unknown log format '.foo'" in capsys.readouterr().err
    log, _ = bag
    assert main(["export", str(log), "--route", str(tmp_path), "--out", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err
    assert err == f"routefuse: error: {tmp_path}: is a folder, expected a route file\n"
    assert captured_export == []


def test_a_missing_batch_folder_is_named_missing(tmp_path, capsys):
    missing = tmp_path / "no-such-folder"
    assert main(["export", "--batch", str(missing), "--out", str(tmp_path / "o")]) == 3
    assert capsys.readouterr().err == f"routefuse: error: {missing}: no such file or folder\n"


@pytest.mark.parametrize(
    ("value", "text"),
    [(-0.0, "0.000"), (-4e-4, "0.000"), (-5e-17, "0.000"), (4e-4, "0.000"), (0.0, "0.000"),
     (-6e-4, "-0.001"), (0.0125, "+0.013"), (-1.5, "-1.500")],
)  # fmt: skip
def test_signed_differences_have_no_negative_zero(value, text):
    from inspector.numbers import signed

    assert signed(value) == text


def test_compare_prints_no_negative_zero_and_uses_the_route_beside(
    bag, tmp_path, capsys, monkeypatch
):
    """B - A of two equal figures whose float difference is -5.6e-17 prints 0.000."""
    from types import SimpleNamespace

    import inspector.export.compare

    log, route = bag
    given: list[Path] = []

    def fake_comparison(log_path, route_path, out, set_a, set_b, **kwargs):
        given.append(route_path)
        comparison = SimpleNamespace(
            metrics=[("RMSE [m]", 0.1 + 0.2, 0.3), ("max [m]", 1.0, 1.25)],
            accepted=(3, 3),
            attempts=(5, 5),
            changed=(),
        )
        return comparison, ()

    monkeypatch.setattr(inspector.export.compare, "export_comparison", fake_comparison)
    argv = ["export", str(log), "--out", str(tmp_path / "o"), "--compare", "a.toml", "b.toml"]
    assert main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "RMSE [m]: A 0.300, B 0.300 (B - A 0.000)"
    assert out[1] == "max [m]: A 1.000, B 1.250 (B - A +0.250)"
    assert given == [route]
    assert not any("no ground truth" in line for line in out)


def test_compare_without_truth_says_the_route_deviation_is_all_it_compares(
    bag, tmp_path, monkeypatch, capsys
):
    """Without ground truth the terminal printed the route deviation alone, as if it were the
    accuracy."""
    from types import SimpleNamespace

    import inspector.export.compare

    log, _ = bag

    def fake_comparison(log_path, route_path, out, set_a, set_b, **kwargs):
        metrics = [
            ("truth horizontal RMSE [m]", None, None),
            ("route deviation RMSE [m]", 1.0, 0.5),
        ]
        return SimpleNamespace(metrics=metrics, accepted=(3, 3), attempts=(5, 5), changed=()), ()

    monkeypatch.setattr(inspector.export.compare, "export_comparison", fake_comparison)
    argv = ["export", str(log), "--out", str(tmp_path / "o"), "--compare", "a.toml", "b.toml"]
    assert main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "route deviation RMSE [m]: A 1.000, B 0.500 (B - A -0.500)"
    assert out[1].startswith("no ground truth in this log: only the route deviation")
