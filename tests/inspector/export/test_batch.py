"""Which logs a batch covers, and the route it pairs each with."""

from __future__ import annotations

import pytest

from estimator.errors import RoutefuseError
from inspector.export import find_logs, route_beside


def test_find_logs_in_a_folder_and_by_glob(tmp_path):
    for name in ("a.mcap", "a.route.geojson", "b.bag", "notes.txt"):
        (tmp_path / name).write_text("x")
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "metadata.yaml").write_text("x")
    (tmp_path / "d").mkdir()  # not a bag folder
    assert [p.name for p in find_logs(tmp_path)] == ["a.mcap", "b.bag", "c"]
    assert [p.name for p in find_logs(str(tmp_path / "a.*"))] == ["a.mcap"]
    assert route_beside(tmp_path / "a.mcap") == tmp_path / "a.route.geojson"
    with pytest.raises(RoutefuseError, match=r"b\.bag: no route b\.route\.geojson beside"):
        route_beside(tmp_path / "b.bag")
    with pytest.raises(RoutefuseError, match="no logs found"):
        find_logs(tmp_path / "d")


def test_the_batch_pairs_a_log_with_a_route_of_any_format_named_after_it(tmp_path):
    (tmp_path / "drive.bag").write_text("x")
    (tmp_path / "drive.route.gpx").write_text("x")
    assert route_beside(tmp_path / "drive.bag") == tmp_path / "drive.route.gpx"
    assert [p.name for p in find_logs(str(tmp_path / "drive.*"))] == ["drive.bag"]


def test_the_terminal_summary_gives_the_error_against_truth_beside_the_route_deviation(tmp_path):
    """The batch's terminal table used to show only the route deviation, titled "proposed RMSE
    [m]": a figure that rewards following a wrong map, read as the accuracy."""
    from inspector.export.batch import BatchItem
    from inspector.export.replay import ExportResult
    from inspector.export.tables import format_summary

    def run(route: float, truth: float | None) -> dict:
        m = {"route": {"max_pos_dev_m": route * 2, "rmse_pos_dev_m": route}}
        if truth is not None:
            m["truth"] = {"rmse_h_err_m": truth}
        return m

    doc = {
        "duration_s": 100.0,
        "distance_m": 900.0,
        "degraded_intervals": [[10.0, 40.0]],
        "matches": {"attempted": 20, "accepted": 18},
        "methods": {"baseline": run(3.5, 12.25), "paper": run(0.5, 7.75)},
    }
    log = tmp_path / "drive.mcap"
    result = ExportResult(log, tmp_path / "r.geojson", tmp_path, (), doc, 10)
    items = [
        BatchItem(log, tmp_path, result, None, 1.0),
        BatchItem(tmp_path / "bad.mcap", tmp_path, None, "bad.mcap: file is empty", 0.0),
    ]
    lines = format_summary(items).splitlines()
    head = lines[0].split("  ")
    assert [t.strip() for t in head if t.strip()] == [
        "log", "status", "outage [s]", "attempts", "accepted",
        "baseline truth RMSE [m]", "paper truth RMSE [m]",
        "baseline route dev. RMSE [m]", "paper route dev. RMSE [m]", "time [s]",
    ]  # fmt: skip
    assert lines[1].split() == ["drive.mcap", "ok", "30.00", "20", "18", "12.25", "7.75",
                                "3.50", "0.50", "1.0"]  # fmt: skip
    assert lines[2].split()[:2] == ["bad.mcap", "failed"]
    assert "error against ground truth" in lines[3] and "route line" in lines[3]
    assert lines[4] == "failed: bad.mcap: file is empty"
