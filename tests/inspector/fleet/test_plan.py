"""A sweep's plan: logs from folders, globs and a manifest CSV, parameter sets from configs, a
grid and methods, the reference set, the values that differ from it, and stable task ids."""

from __future__ import annotations

from pathlib import Path

import pytest

from estimator.errors import ConfigError, RoutefuseError
from estimator.params import Params, get_param, with_values
from inspector.cli.main import build_parser
from inspector.fleet import SweepPlan, build_sets, collect_logs, differing_values, expand_grid
from inspector.fleet.plan import format_values, task_id


def _touch(folder: Path, *names: str) -> None:
    for name in names:
        (folder / name).write_text("x")


def test_logs_from_a_folder_a_glob_and_a_manifest(tmp_path):
    _touch(tmp_path, "a.mcap", "a.route.geojson", "b.mcap", "b.route.gpx", "c.bag", "notes.txt")
    (tmp_path / "c.bag").write_bytes(b"#ROSBAG V2.0\n")  # a log without a route, not a bad log
    sub = tmp_path / "sub"
    sub.mkdir()
    _touch(sub, "a.mcap", "a.route.geojson", "other.geojson")
    manifest = tmp_path / "drives.csv"
    manifest.write_text(
        "log,route,outages,tags\nsub/a.mcap,sub/other.geojson,20:50 80:95,night;rain\nb.mcap,,,\n"
    )
    entries = collect_logs([str(tmp_path / "c.*"), str(tmp_path), str(manifest)], outages=[(5, 9)])
    by_label = {e.label: e for e in entries}
    # c.bag from the glob and again from the folder: once; a.mcap of two folders: two labels
    assert sorted(by_label) == ["a", "a-2", "b", "c"]
    assert by_label["c"].route is None and "no route c.route.geojson" in str(
        by_label["c"].route_error
    )
    assert by_label["a"].route == (tmp_path / "a.route.geojson").absolute()
    assert by_label["b"].route == (tmp_path / "b.route.gpx").absolute()  # any route format
    assert by_label["a"].outages == ((5.0, 9.0),)  # the command's outages
    from_manifest = by_label["a-2"]
    assert from_manifest.log == (sub / "a.mcap").absolute()
    assert from_manifest.route == (sub / "other.geojson").absolute()
    assert from_manifest.outages == ((20.0, 50.0), (80.0, 95.0))
    assert from_manifest.tags == ("night", "rain")
    # b.mcap from the folder and the manifest row with no outages: the same task, once
    assert [e.log.name for e in entries].count("b.mcap") == 1


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("log,weather\na.mcap,sunny\n", "unknown column 'weather'"),
        ("log,outages\na.mcap,50:20\n", "line 2: outages"),
        ("log\n", "lists no log"),
    ],
)
def test_manifest_errors_name_the_file_and_line(tmp_path, text, message):
    _touch(tmp_path, "a.mcap")
    manifest = tmp_path / "m.csv"
    manifest.write_text(text)
    with pytest.raises(ConfigError) as err:
        collect_logs([str(manifest)])
    assert str(err.value).startswith(str(manifest)) and message in str(err.value)
    assert "\n" not in str(err.value)


def test_no_logs_is_one_line(tmp_path):
    with pytest.raises(RoutefuseError, match="no logs found"):
        collect_logs([str(tmp_path / "nothing-*.mcap")])


def test_grid_expands_every_combination_in_order():
    sets = expand_grid(
        {
            "method": ["proposed", "paper"],
            "gates": {"max_residual_m": [1.0, 2.5, 4.0]},
            "window": {"length_m": 300.0},
        },
        source="grid.toml",
    )
    assert len(sets) == 6
    assert [s.method for s in sets] == ["proposed"] * 3 + ["paper"] * 3
    assert [get_param(s.params, "gates.max_residual_m") for s in sets] == [1.0, 2.5, 4.0] * 2
    assert all(get_param(s.params, "window.length_m") == 300.0 for s in sets)
    assert sets[0].name == "method=proposed,max_residual_m=1"
    assert {s.kind for s in sets} == {"grid"}


def test_grid_errors():
    with pytest.raises(ConfigError, match=r"unknown parameter 'gates\.nope'"):
        expand_grid({"gates": {"nope": [1, 2]}}, source="g.toml")
    with pytest.raises(ConfigError, match="empty list"):
        expand_grid({"gates": {"max_residual_m": []}}, source="g.toml")
    with pytest.raises(ConfigError, match="max_residual_m"):
        expand_grid({"gates": {"max_residual_m": [1.0, -5.0]}}, source="g.toml")
    with pytest.raises(ConfigError, match="'fast' is not one of"):
        expand_grid({"method": ["fast"]}, source="g.toml")


def test_sets_in_command_line_order_the_first_is_the_reference(tmp_path):
    tuned = tmp_path / "tuned.toml"
    tuned.write_text("[gates]\nmax_residual_m = 2.25\n")
    grid = tmp_path / "grid.toml"
    grid.write_text("[window]\nlength_m = [250.0, 350.0]\n")
    args = build_parser().parse_args(
        ["sweep", "L", "--out", "o", "--method", "paper", "--config", str(tuned), "--grid",
         str(grid), "--method", "paper"]
    )  # fmt: skip
    sets = build_sets(args.sets, base=with_values(Params(), {"trigger.min_outage_s": 2.0}))
    assert [s.name for s in sets] == ["paper", "tuned", "length_m=250", "length_m=350", "paper-2"]
    plan = SweepPlan(collect_logs([str(_log(tmp_path))]), sets)
    assert plan.reference.name == "paper"
    # --set is under every set; the files and the grid override it
    assert all(get_param(s.params, "trigger.min_outage_s") == 2.0 for s in sets)
    tuned_differs = plan.differing(sets[1])
    assert tuned_differs["method"] == "proposed"
    assert tuned_differs["gates.max_residual_m"] == 2.25
    assert tuned_differs["extensions.portal_rerun"] is True  # paper switches extensions off
    assert plan.differing(sets[0]) == {} and plan.differing(sets[4]) == {}
    assert "window.length_m" in plan.varied_names() and plan.varied_names()[0] == "method"
    assert format_values(plan.differing(sets[3])).startswith("method=proposed; ")


def test_no_set_is_the_defaults_with_the_proposed_method():
    (only,) = build_sets([])
    assert only.method == "proposed" and only.params == Params()


def test_differing_values_compares_what_the_methods_run():
    a, b = build_sets([("method", "paper"), ("method", "proposed")])
    assert differing_values(a, a) == {}
    assert set(differing_values(b, a)) >= {"method", "extensions.portal_rerun"}


def test_task_ids_are_stable_and_change_with_what_the_row_depends_on(tmp_path):
    log = _log(tmp_path)
    (entry,) = collect_logs([str(log)])
    (s,) = build_sets([("method", "proposed")])
    renamed = type(s)("another name", s.params, s.method, s.kind, s.source)
    changed = type(s)(s.name, with_values(s.params, {"gates.max_residual_m": 2.0}), s.method)
    (moved,) = collect_logs([str(log)], outages=[(1, 2)])
    assert task_id(entry, s) == task_id(entry, renamed)
    assert len({task_id(entry, s), task_id(entry, changed), task_id(moved, s)}) == 3
    plan = SweepPlan((entry,), build_sets([("method", "proposed"), ("method", "paper")]))
    ids = [t.id for t in plan.tasks()]
    assert ids == [t.id for t in plan.tasks()] and len(set(ids)) == 2


def test_hostile_names_become_safe_file_names():
    (s,) = expand_grid({"gates": {"max_residual_m": 2.0}}, source="<b>/../x.toml")
    assert "/" not in s.slug and "<" not in s.slug


def _log(folder: Path) -> Path:
    log = folder / "drive.mcap"
    _touch(folder, "drive.mcap", "drive.route.geojson")
    return log


def test_regressions_are_ranked_against_truth_where_the_logs_have_it():
    """A route-relative deviation rewards following a wrong map: the report ranks by the error
    against ground truth when any task has it, else by the route deviation."""
    from inspector.fleet.report import ranking_metric

    with_truth = [{"rmse_pos_dev_m": 0.3, "rmse_h_err_m": 2.0}, {"rmse_pos_dev_m": 0.4}]
    assert ranking_metric(with_truth) == "rmse_h_err_m"
    assert ranking_metric([{"rmse_pos_dev_m": 0.3, "rmse_h_err_m": None}]) == "rmse_pos_dev_m"


def test_a_folder_that_cannot_be_read_is_a_member_named_for_its_problem(tmp_path, unreadable):
    """An unreadable folder beside the logs neither stops the sweep (it used to end it with
    "internal error: PermissionError") nor vanishes: its task fails saying why."""
    _touch(tmp_path, "a.mcap", "a.route.geojson")
    locked = tmp_path / "locked"
    locked.mkdir()
    _touch(locked, "b.mcap", "b.route.geojson")
    unreadable(locked)
    entries = {e.label: e for e in collect_logs([str(tmp_path)])}
    assert sorted(entries) == ["a", "locked"]
    assert entries["locked"].route_error == f"{locked}: cannot open it (Permission denied)"
    assert entries["a"].route_error is None
    # named alone: one member, the same one-line problem
    (alone,) = collect_logs([str(locked)])
    assert alone.route_error == f"{locked}: cannot open it (Permission denied)"
    # a glob inside it matches nothing, said as such
    with pytest.raises(RoutefuseError, match="no logs found"):
        collect_logs([str(locked / "*.mcap")])


def test_a_log_that_cannot_be_opened_is_named_for_that_not_for_its_missing_route(tmp_path):
    (tmp_path / "empty.mcap").write_bytes(b"")
    (entry,) = collect_logs([str(tmp_path / "empty.mcap")])
    assert entry.route_error == f"{tmp_path / 'empty.mcap'}: file is empty"


def test_labels_keep_the_letters_of_any_script(tmp_path):
    """Labels dropped every letter outside ASCII: "東京トンネル.mcap" was labelled "set" in the
    table and the report, and "tunnel <b>bold é ü.mcap" "tunnel_b_bold"."""
    _touch(tmp_path, "東京トンネル.mcap", "tunnel <b>bold é ü.mcap", "..mcap")
    labels = sorted(e.label for e in collect_logs([str(tmp_path)]))
    assert labels == ["log", "tunnel_b_bold_é_ü", "東京トンネル"]


def test_a_manifest_row_whose_log_or_route_is_missing_is_a_failed_member(tmp_path):
    """One deleted file in a nightly manifest used to stop the whole sweep before it began."""
    (tmp_path / "a.mcap").write_bytes(b"\x89MCAP0\r\n")
    (tmp_path / "a.route.geojson").write_text("{}")
    manifest = tmp_path / "m.csv"
    manifest.write_text("log,route\na.mcap,nowhere.geojson\nmissing.mcap,\na.mcap,\n")
    entries = collect_logs([str(manifest)])
    assert [e.label for e in entries] == ["a", "missing"]  # a.mcap once (same outages)
    assert entries[0].route_error == (
        f"{tmp_path / 'nowhere.geojson'}: no such route file (manifest m.csv, line 2)"
    )
    assert entries[1].route_error == f"{tmp_path / 'missing.mcap'}: no such file or folder"


def test_a_code_change_makes_new_tasks(tmp_path, monkeypatch):
    """Task ids ignored the code: the same command after a commit resumed every task, and a
    regression run into the same folder compared the earlier code's rows with themselves."""
    import inspector.fleet.plan as plan

    (entry,) = collect_logs([str(_log(tmp_path))])
    (s,) = build_sets([("method", "proposed")])
    before = task_id(entry, s)
    assert len(plan.estimator_source()) == 16 and task_id(entry, s) == before
    monkeypatch.setattr(plan, "estimator_source", lambda: "another commit")
    assert task_id(entry, s) != before
