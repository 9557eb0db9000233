"""Headless export of one simulated tunnel drive: every file is written, readable by the tool it
is meant for (evo's TUM layout, GeoJSON lon/lat, CSV), and consistent with the run itself."""

from __future__ import annotations

import csv
import html
import io
import json
import math
import re
from pathlib import Path

import matplotlib.image
import msgspec
import numpy as np
import pytest
import zstandard
from fake_runs import make_route, make_run

from estimator.errors import ConfigError
from estimator.sim import simulate
from inspector.cli.main import main
from inspector.export import ReplayOptions, export_log, replay_times
from inspector.scene_data import SceneData

EXPECTED = {
    "replay.html",
    "replay.viser",
    "deviation.png",
    "deviation.svg",
    "trajectory.png",
    "metrics.json",
    "metrics.csv",
    "matches.csv",
    "trajectory_baseline.csv",
    "trajectory_proposed.csv",
    "trajectory_baseline.tum",
    "trajectory_proposed.tum",
    "trajectory_truth.tum",
    "trajectories.geojson",
    "report.html",
}


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("sim")
    return simulate("short_tunnel", seed=2, duration_s=60.0).write(out)


@pytest.fixture(scope="module")
def exported(bag, tmp_path_factory):
    log, route = bag
    out = tmp_path_factory.mktemp("export") / "short"
    stages: list[str] = []
    result = export_log(
        log, route, out, progress=lambda stage, f: stages.append(stage), replay=ReplayOptions()
    )
    return result, stages


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_every_file_is_written_and_listed(exported):
    result, stages = exported
    names = {p.name for p in result.files}
    assert names == EXPECTED
    for p in result.files:
        assert p.parent == result.out_dir and p.stat().st_size > 0, p
    assert stages[0] == "loading" and stages[-1] == "done"
    assert {"baseline run", "proposed run", "replay"} <= set(stages)


def test_metrics_json_is_the_run_json(exported, bag, tmp_path):
    result, _ = exported
    log, route = bag
    run_json = tmp_path / "run.json"
    assert main(["run", str(log), "--route", str(route), "--json", str(run_json), "--quiet"]) == 0
    ours = json.loads((result.out_dir / "metrics.json").read_text())
    theirs = json.loads(run_json.read_text())
    assert ours == theirs
    assert ours["matches"]["attempted"] > 0


def test_metrics_csv_has_a_row_per_method(exported):
    result, _ = exported
    rows = _rows(result.out_dir / "metrics.csv")
    doc = result.metrics
    assert [r["method"] for r in rows] == ["baseline", "proposed"]
    for r in rows:
        m = doc["methods"][r["method"]]
        assert float(r["rmse_pos_dev_m"]) == pytest.approx(m["route"]["rmse_pos_dev_m"], rel=1e-5)
        assert float(r["rmse_h_err_m"]) == pytest.approx(m["truth"]["rmse_h_err_m"], rel=1e-5)


def test_matches_csv_one_row_per_attempt_with_every_gate(exported):
    result, _ = exported
    rows = _rows(result.out_dir / "matches.csv")
    assert len(rows) == result.metrics["matches"]["attempted"]
    gate_names = [c.removesuffix("_verdict") for c in rows[0] if c.endswith("_verdict")]
    assert gate_names, "no gate columns"
    for g in gate_names:
        assert {f"{g}_value", f"{g}_threshold"} <= set(rows[0])
    accepted = [r for r in rows if r["verdict"] == "accepted"]
    assert len(accepted) == result.metrics["matches"]["accepted"]
    for r in accepted:
        assert all(r[f"{g}_verdict"] == "pass" for g in gate_names)
        assert r["accepted"] == "1"
        assert math.hypot(float(r["correction_e_m"]), float(r["correction_n_m"])) > 0
    for r in rows:
        if r["verdict"].startswith("rejected: "):
            assert r[f"{r['verdict'].removeprefix('rejected: ')}_verdict"] == "fail"
    t = [float(r["t_s"]) for r in rows]
    assert t == sorted(t)
    a, b = result.metrics["degraded_intervals"][-1]
    assert a <= t[0] and t[-1] <= b + 1e-6
    for key in ("rotation_deg", "translation_e_m", "residual_m", "pairs", "innovation_n_m"):
        assert math.isfinite(float(accepted[0][key]))


def test_matches_csv_has_the_filter_sigma_beside_the_fit_sigma(exported):
    """The Match tab's route-axes pair of the filter (before the update) is in the table as
    the diagnostics' extra_* columns, beside the fit's own along and cross sigmas."""
    result, _ = exported
    rows = _rows(result.out_dir / "matches.csv")
    fitted = [r for r in rows if r["extra_cross_sigma_m"]]
    assert fitted
    for r in fitted:
        along, cross = (
            float(r["extra_filter_along_sigma_m"]),
            float(r["extra_filter_cross_sigma_m"]),
        )
        assert along > 0 and cross > 0
    columns = list(rows[0])
    assert columns.index("extra_filter_along_sigma_m") > columns.index("extra_cross_sigma_m")


def _tum(path: Path) -> np.ndarray:
    """Read as evo's file_interface does: whitespace-separated, 8 columns, '#' comments."""
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    rows = [ln.split() for ln in lines]
    assert all(len(r) == 8 for r in rows), "TUM rows need exactly 8 columns"
    return np.array(rows, dtype=float)


@pytest.mark.parametrize("name", ["baseline", "proposed", "truth"])
def test_tum_files_have_the_layout_evo_reads(exported, name):
    result, _ = exported
    data = _tum(result.out_dir / f"trajectory_{name}.tum")
    assert len(data) > 100
    assert np.all(np.isfinite(data))
    assert np.all(np.diff(data[:, 0]) > 0), "timestamps must increase"
    assert np.allclose(np.linalg.norm(data[:, 4:8], axis=1), 1.0, atol=1e-6)
    assert 1.6e9 < data[0, 0] < 1.8e9  # the log's Unix clock, not seconds after start


def test_tum_pose_is_the_trajectory(exported):
    """Same epochs, positions and heading as the CSV: the quaternion's yaw (qx qy qz qw,
    body -> ENU) is the run's yaw."""
    result, _ = exported
    tum = _tum(result.out_dir / "trajectory_proposed.tum")
    rows = _rows(result.out_dir / "trajectory_proposed.csv")
    t = np.array([float(r["time"]) for r in rows])
    east = np.array([float(r["east_m"]) for r in rows])
    yaw = np.radians([float(r["yaw_deg"]) for r in rows])
    idx = np.searchsorted(t, tum[:, 0] - 1e-7)
    assert np.allclose(t[idx], tum[:, 0], atol=2e-6)
    assert np.allclose(east[idx], tum[:, 1], atol=1e-3)
    qx, qy, qz, qw = tum[:, 4:8].T
    yaw_q = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2))
    assert np.allclose(np.angle(np.exp(1j * (yaw_q - yaw[idx]))), 0.0, atol=1e-3)


def test_truth_tum_is_close_to_the_estimate_outside_the_tunnel(exported):
    result, _ = exported
    truth = _tum(result.out_dir / "trajectory_truth.tum")
    est = _tum(result.out_dir / "trajectory_proposed.tum")
    t0 = est[0, 0]
    pick = (est[:, 0] > t0 + 5) & (est[:, 0] < t0 + 30)  # open sky, GNSS fused
    e = est[pick]
    tx = np.interp(e[:, 0], truth[:, 0], truth[:, 1])
    ty = np.interp(e[:, 0], truth[:, 0], truth[:, 2])
    assert np.median(np.hypot(e[:, 1] - tx, e[:, 2] - ty)) < 3.0


def test_geojson_is_lon_lat(exported):
    result, _ = exported
    doc = json.loads((result.out_dir / "trajectories.geojson").read_text())
    assert doc["type"] == "FeatureCollection"
    lines = {
        f["properties"]["name"]: f["geometry"]["coordinates"]
        for f in doc["features"]
        if f["geometry"]["type"] == "LineString"
    }
    assert {"route", "baseline", "proposed", "truth"} <= set(lines)
    rows = _rows(result.out_dir / "trajectory_proposed.csv")
    lon0, lat0 = lines["proposed"][0]
    assert lon0 == pytest.approx(float(rows[0]["lon_deg"]), abs=1e-7)
    assert lat0 == pytest.approx(float(rows[0]["lat_deg"]), abs=1e-7)
    for coords in lines.values():
        arr = np.array(coords)
        assert np.all(np.abs(arr[:, 0] - 7.0) < 0.1) and np.all(np.abs(arr[:, 1] - 45.0) < 0.1)
    # decimated to the display tolerance, far fewer vertices than epochs
    assert 2 <= len(lines["proposed"]) < len(rows) / 2
    points = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    assert len(points) == result.metrics["matches"]["attempted"]
    assert all(p["properties"]["verdict"] for p in points)


def test_figures_are_images(exported):
    result, _ = exported
    for name in ("deviation.png", "trajectory.png"):
        img = matplotlib.image.imread(result.out_dir / name)
        assert img.shape[0] > 500 and img.shape[1] > 800
        assert img[..., :3].std() > 0.05, f"{name} looks blank"
    svg = (result.out_dir / "deviation.svg").read_text()
    assert "<svg" in svg and "baseline" in svg and "proposed" in svg


def _viser_payload(path: Path) -> dict:
    """Decode a .viser recording (zstd of: 8-byte length, msgpack, buffers)."""
    raw = path.read_bytes()
    inner = zstandard.ZstdDecompressor().decompressobj().decompress(raw[8:])
    n = int.from_bytes(inner[:8], "little")
    return msgspec.msgpack.decode(inner[8 : 8 + n])


def test_replay_records_the_layers_frame_by_frame(exported):
    result, _ = exported
    payload = _viser_payload(result.out_dir / "replay.viser")
    messages = payload["messages"]
    names = {m.get("name", "") for _, m in messages}
    for layer in ("route", "baseline", "proposed", "truth", "verdicts", "match"):
        assert any(n.startswith(f"/routefuse/{layer}/") for n in names), layer
    for part in ("window", "aligned", "pseudo", "segment"):
        assert f"/routefuse/match/{part}" in names, part
    times = [t for t, _ in messages]
    assert times == sorted(times)
    assert 20.0 < payload["durationSeconds"] < 120.0
    pose_updates = {
        t
        for t, m in messages
        if m.get("name") == "/routefuse/proposed/pose" and m["type"] == "SetPositionMessage"
    }
    assert len(pose_updates) >= result.frames - 1  # the vehicle moves in every frame
    scales = [
        m["updates"]["scale"]
        for _, m in messages
        if m.get("name") == "/routefuse/proposed/pose" and "scale" in m.get("updates", {})
    ]
    assert scales and scales[-1] > 5.0  # enlarged to show in the overview
    # verdict markers appear as the attempts happen, not all at once
    verdict_nodes = [  # (re)created with the attempts so far
        t for t, m in messages if m.get("name") == "/routefuse/verdicts/markers" and "props" in m
    ]
    assert len(verdict_nodes) > 3 and verdict_nodes[-1] > verdict_nodes[0]
    clock = [
        m["updates"]["text"]
        for _, m in messages
        if m.get("name") == "/routefuse/export/clock" and "text" in m.get("updates", {})
    ]
    assert "GNSS outage" in " ".join(clock) and clock[0].endswith("attempts 0")
    assert clock[-1].endswith(f"attempts {result.metrics['matches']['attempted']}")
    assert 50 <= result.frames <= 300
    html = (result.out_dir / "replay.html").read_text()
    assert "__VISER_EMBED_DATA__" in html
    assert 'src="http' not in html  # self-contained: no network fetch


def test_report_links_every_file(exported):
    result, _ = exported
    page = (result.out_dir / "report.html").read_text()
    links = set(re.findall(r'href="([^"]+)"', page))
    assert links >= EXPECTED - {"report.html"}
    assert all((result.out_dir / link).exists() for link in links)
    assert 'src="deviation.svg"' in page and 'src="trajectory.png"' in page
    rmse = result.metrics["methods"]["proposed"]["route"]["rmse_pos_dev_m"]
    assert "rmse pos dev [m]" in page and f"<td>{rmse:.3f}</td>" in page
    assert "Error against ground truth" in page
    from inspector.layers import legend_entries

    for _, meaning in legend_entries():  # the replay's legend: the layers' own
        assert html.escape(meaning) in page


def _scene(n_matches: int) -> SceneData:
    return SceneData.build(
        baseline=make_run(method="baseline"),
        proposed=make_run(n_matches=n_matches),
        route=make_route(),
        log=None,
    )


def test_replay_times_include_every_attempt_and_fit_the_budget():
    scene = _scene(n_matches=8)
    t = replay_times(scene, ReplayOptions(max_frames=120))
    assert len(t) <= 120
    assert np.all(np.diff(t) > 0)
    assert np.all(np.isin(scene.match_t, t))
    assert t[0] == scene.proposed.t[0] and t[-1] == scene.proposed.t[-1]


def test_replay_times_thin_attempts_when_there_are_too_many():
    scene = _scene(n_matches=9)
    t = replay_times(scene, ReplayOptions(max_frames=10))
    assert len(t) <= 10
    assert np.isin(scene.match_t, t).sum() == 5


def test_replay_times_explicit_fps():
    scene = _scene(n_matches=0)
    span = scene.proposed.t[-1] - scene.proposed.t[0]
    t = replay_times(scene, ReplayOptions(fps=4.0))
    assert len(t) == pytest.approx(4.0 * span, abs=2)
    with pytest.raises(ConfigError, match="frames"):
        replay_times(scene, ReplayOptions(fps=1000.0))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (ReplayOptions(fps=0.0), "--fps"),
        (ReplayOptions(fps=float("nan")), "--fps"),
        (ReplayOptions(time_lapse=-2.0), "--time-lapse"),
    ],
)
def test_bad_replay_options_are_one_line_errors(bag, tmp_path, options, message):
    log, route = bag
    with pytest.raises(ConfigError) as err:
        export_log(log, route, tmp_path / "x", replay=options)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)
    assert not (tmp_path / "x").exists()


def test_svg_has_no_timestamp(exported):
    """An unchanged export gives an identical figure file (no date in the metadata)."""
    result, _ = exported
    svg = (result.out_dir / "deviation.svg").read_text()
    assert "<dc:date>" not in svg


def test_trajectory_csv_columns(exported):
    result, _ = exported
    rows = _rows(result.out_dir / "trajectory_baseline.csv")
    data = np.genfromtxt(
        io.StringIO((result.out_dir / "trajectory_baseline.csv").read_text()),
        delimiter=",",
        names=True,
    )
    assert len(data) == len(rows)
    assert np.all(np.diff(data["time"]) >= 0)
    assert set(np.unique(data["degraded"])) <= {0.0, 1.0}
    assert data["degraded"].sum() > 0 and data["gnss_used"].sum() > 0
    # the E-N covariance, last: a correlation within [-1, 1] (its 6 digits' rounding aside)
    corr = data["cov_east_north_m2"] / (data["sigma_east_m"] * data["sigma_north_m"])
    assert np.all(np.abs(corr) <= 1.001) and np.any(data["cov_east_north_m2"] != 0.0)


def test_log_without_truth_as_ros1_bag(bag, tmp_path):
    """A real log has no ground truth: no truth TUM, no truth columns, no truth table."""
    from estimator.io import load_log
    from estimator.io.bagwrite import write_bag

    log_path, route = bag
    log = load_log(log_path)
    ros1 = tmp_path / "drive.bag"
    write_bag(ros1, imu=log.imu, gnss=log.gnss, wheel=log.wheel, storage="ros1")
    result = export_log(ros1, route, tmp_path / "out", replay=ReplayOptions(fps=0.5))
    names = {p.name for p in result.files}
    assert names == EXPECTED - {"trajectory_truth.tum"}
    assert all(m["truth"] is None for m in result.metrics["methods"].values())
    header = (result.out_dir / "metrics.csv").read_text().splitlines()[0].split(",")
    assert "rmse_pos_dev_m" in header and "rmse_h_err_m" not in header
    page = (result.out_dir / "report.html").read_text()
    assert "Error against ground truth" not in page
    lines = json.loads((result.out_dir / "trajectories.geojson").read_text())["features"]
    assert "truth" not in {f["properties"]["name"] for f in lines}


def _panel_data(page: str) -> dict:
    found = re.search(
        r'<script type="application/json" id="routefuse-replay-data">(.*?)</script>', page, re.S
    )
    assert found, "no panel data in the page"
    return json.loads(found.group(1))


def test_the_replay_page_explains_every_attempt_in_log_time(exported):
    """Issue 19: the replay page carries every attempt's gate table and fit values (the page's
    panel shows the one on screen), the legend, and one clock: the recording's time is the
    log's time since its start, as the scene's clock label says."""
    from inspector.layers import legend_entries

    result, _ = exported
    page = (result.out_dir / "replay.html").read_text()
    data = _panel_data(page)
    with (result.out_dir / "matches.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) >= 2
    assert [a["index"] for a in data["attempts"]] == [int(r["index"]) for r in rows]
    assert [a["t"] for a in data["attempts"]] == pytest.approx([float(r["t_s"]) for r in rows])
    assert [a["accepted"] for a in data["attempts"]] == [r["accepted"] == "1" for r in rows]
    for a in data["attempts"]:
        assert [g["name"] for g in a["gates"]][:3] == ["min_pairs", "heading", "residual"]
        assert a["fit"].startswith("rotation ")
    messages = _viser_payload(result.out_dir / "replay.viser")["messages"]
    clock = [
        (t, m["updates"]["text"])
        for t, m in messages
        if m.get("name") == "/routefuse/export/clock" and "text" in m.get("updates", {})
    ]
    assert len(clock) > 10
    for t, text in clock:
        assert float(text.split()[2]) == pytest.approx(t, abs=0.06)
    assert data["duration"] == pytest.approx(clock[-1][0], abs=0.06)
    for _, meaning in legend_entries():
        assert html.escape(meaning) in page


def test_the_replay_panel_escapes_what_it_shows():
    """A hostile file name in the title is shown as text; the panel data stays one JSON value."""
    from inspector.export.replay import replay_panel
    from inspector.plots import DeviationPlot

    scene = _scene(n_matches=4)
    t = np.linspace(0.0, 10.0, 50)
    plot = DeviationPlot(t=t, position=(t, t), heading=(t, t), outages=((2.0, 6.0),))
    hostile = '<img src=x onerror="alert(1)">.mcap on </script><script>alert(2)</script>'
    panel = replay_panel(
        scene, plot, degraded=(), duration=10.0, speed=2.0, title=hostile, method="proposed"
    )
    assert "<img src=x" not in panel and "<script>alert(2)" not in panel
    assert "&lt;img src=x onerror=" in panel
    assert len(_panel_data(panel)["attempts"]) == 4
    assert "no ground truth" in panel


def test_an_export_stopped_midway_leaves_the_earlier_one_whole(bag, tmp_path, monkeypatch):
    """Stopped while writing its replay, an export into a folder holding an earlier one used to
    leave its new tables and figures beside the earlier replay and report: a folder that looks
    complete and is neither export."""
    import inspector.export.replay as replay

    log, route = bag
    out = tmp_path / "out"
    out.mkdir()
    earlier = {name: f"earlier {name}" for name in ("metrics.json", "replay.html", "report.html")}
    for name, text in earlier.items():
        (out / name).write_text(text)

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(replay, "write_replay", ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        export_log(log, route, out)
    assert {p.name: p.read_text() for p in out.iterdir()} == earlier
    monkeypatch.undo()
    result = export_log(log, route, out)
    assert {p.name for p in out.iterdir()} == EXPECTED
    assert all(f.parent == out and f.is_file() for f in result.files)
    assert (out / "metrics.json").read_text().startswith("{")


def test_a_failed_export_leaves_no_empty_folder(bag, tmp_path):
    """A batch or sweep --export left an empty folder for each log whose route could not be
    read, beside the real exports."""
    from estimator.errors import RoutefuseError

    log, _ = bag
    bad_route = tmp_path / "bad.route.geojson"
    bad_route.write_text("not json")
    out = tmp_path / "exports" / "bad"
    with pytest.raises(RoutefuseError, match="not valid JSON"):
        export_log(log, bad_route, out)
    assert not out.exists() and (tmp_path / "exports").is_dir()
    kept = tmp_path / "kept"
    kept.mkdir()
    with pytest.raises(RoutefuseError):
        export_log(log, bad_route, kept)
    assert kept.is_dir()  # a folder the user made stays


def test_the_replay_speed_menu_labels_the_exports_own_time_lapse_to_three_figures():
    """The default time lapse is the log's length over the replay's: the menu showed it as
    '4.44833x' beside '5x'. Its label is rounded; its value (what the page plays at) is not."""
    from inspector.export.replay import replay_panel
    from inspector.plots import DeviationPlot

    t = np.linspace(0.0, 10.0, 50)
    plot = DeviationPlot(t=t, position=(t, t), heading=(t, t), outages=())
    speed = 266.9 / 60.0
    panel = replay_panel(
        _scene(n_matches=2),
        plot,
        degraded=(),
        duration=10.0,
        speed=speed,
        title="x",
        method="proposed",
    )
    assert f'<option value="{speed:g}" selected>4.45x</option>' in panel
    assert '<option value="5">5x</option>' in panel
    assert "4.44833x" not in panel


def test_the_report_gives_each_outages_exit_check(tmp_path):
    """The long tunnel's results document (its golden): where each method's estimate ended
    against the fixes after the tunnel, the paper's beyond its sigmas in bold."""
    from inspector.export.tables import write_report

    golden = Path(__file__).resolve().parents[2] / "golden" / "long_tunnel.json"
    doc = json.loads(golden.read_text(encoding="utf-8"))["json"]
    page = write_report(tmp_path, doc, [], {}).read_text(encoding="utf-8")
    assert "Where each outage ended: the estimate against the fixes after it" in page
    for method, (x,) in doc["exits"].items():
        a, b = x["outage"]
        row = f"<tr><td>{method}</td><td>{a:.1f}–{b:.1f}</td><td>{x['distance_m']:.2f}</td>"
        assert row in page
        sigmas = f"{x['chi2'] ** 0.5:.1f}"
        assert (f"<b>{sigmas}</b>" in page) == x["overconfident"] == (method == "paper")
    without = {**doc, "exits": {}}
    assert "Where each outage ended" not in write_report(tmp_path, without, [], {}).read_text()
