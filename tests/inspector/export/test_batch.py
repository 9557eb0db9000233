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
