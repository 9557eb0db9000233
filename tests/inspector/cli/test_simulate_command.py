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
    assert main(argv) == 3
    assert "already exists" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert bag.read_bytes() == first


def test_errors_are_one_line(tmp_path, capsys) -> None:
    assert main(["simulate", "nowhere", "--out", str(tmp_path)]) == 3
    err = capsys.readouterr().err.strip()
    assert err.startswith("routefuse: error: unknown scenario 'nowhere'")
    assert "\n" not in err
    assert main(["simulate", "short_tunnel"]) == 3
    assert "--out" in capsys.readouterr().err


def test_imu_rate_and_perfect(tmp_path) -> None:
    argv = ["simulate", "short_tunnel", "--out", str(tmp_path), "--duration", "5"]
    assert main([*argv, "--imu-rate", "200", "--perfect"]) == 0
    log = load_log(tmp_path / "short_tunnel.mcap", cache_dir=tmp_path / "cache")
    assert len(log.imu.t) == 1001


def _truth_rmse(inputs) -> tuple[float, tuple[str, ...], list[bool]]:
    from estimator.evaluation.metrics import method_metrics
    from estimator.pipeline import run_methods
    from tests._session11_fit import undoing_params

    run = run_methods(inputs, undoing_params(), methods=("proposed",))["proposed"]
    truth = method_metrics(run, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return truth.rmse_h_err_m, run.warnings, [m.accepted for m in run.matches]


def test_stress_drive_reads_back_as_the_corpus_builds_it(tmp_path, capsys) -> None:
    """``--stress 5`` writes the corpus drive (its spiral tunnel trips dr_separation): the bag
    holds the in-memory log's streams bit for bit and runs the same. Not bit for bit in the
    run: a bag's frame sits at its first fix (the simulation's at the scenario's origin) and the
    route file rounds vertices to 1e-8 deg (~1 mm); measured 2e-5 m on this drive."""
    import numpy as np

    from estimator.pipeline.inputs import open_inputs
    from estimator.sim.stress import build, drive_spec

    assert main(["simulate", "--stress", "5", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    spec = drive_spec(5)
    assert f"faults: {spec.fault}; map bias {spec.bias_along_m:+.2f} m along" in out
    assert f"wheel scale error {100 * spec.wheel_scale_error:+.2f} %" in out
    bag, route = tmp_path / "stress_5.mcap", tmp_path / "stress_5.route.geojson"
    props = json.loads(route.read_text())["features"][0]["properties"]
    assert props["stress_drive"]["fault"] == spec.fault
    drive = build(spec)
    disk = open_inputs(bag, route, cache_dir=tmp_path / "cache")
    for stream in ("imu", "gnss", "wheel"):
        a, b = getattr(drive.inputs.log, stream), getattr(disk.log, stream)
        for name, value in vars(a).items():
            if isinstance(value, np.ndarray):
                assert np.array_equal(value, getattr(b, name), equal_nan=True), (stream, name)
    assert np.array_equal(drive.inputs.log.truth.lat, disk.log.truth.lat)
    memory_rmse, memory_warnings, memory_accepted = _truth_rmse(drive.inputs)
    disk_rmse, disk_warnings, disk_accepted = _truth_rmse(disk)  # the chi-square in the
    # warning may differ in its last digit shown
    assert abs(disk_rmse - memory_rmse) < 1e-3
    assert disk_accepted == memory_accepted
    assert [w.split(":")[0] for w in disk_warnings] == [w.split(":")[0] for w in memory_warnings]
    assert any(w.startswith("route updates undone at") for w in disk_warnings)


def test_stress_without_odometer_and_errors(tmp_path, capsys) -> None:
    from estimator.sim.stress import drive_spec

    assert drive_spec(2).fault == "no_odometer"
    assert main(["simulate", "--stress", "2", "--out", str(tmp_path)]) == 0
    assert "wheel none" in capsys.readouterr().out
    log = load_log(tmp_path / "stress_2.mcap", cache_dir=tmp_path / "cache")
    assert log.wheel is None and log.truth is not None
    for argv, message in (
        (["--stress", "2"], "already exists (use --force"),
        (["short_tunnel", "--stress", "2"], "give a SCENARIO or --stress N, not both"),
        (["--stress", "-1"], "--stress: -1 is not a corpus index"),
        (["--stress", "2", "--seed", "4"], "--seed: does not apply to --stress"),
        (["--stress", "2", "--perfect"], "--perfect: does not apply to --stress"),
        (["--stress", "2", "--corpus", "-1"], "--corpus: -1: 0 or a held-out corpus"),
        (["short_tunnel", "--corpus", "1"], "--corpus: applies to --stress N only"),
    ):
        assert main(["simulate", *argv, "--out", str(tmp_path)]) == 3
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err, err
    assert main(["simulate", "--stress", "2", "--out", str(tmp_path), "--force"]) == 0


def test_a_held_out_stress_drive_is_written_under_its_own_name(tmp_path, capsys) -> None:
    """``--corpus K`` writes drive N of held-out corpus K beside corpus 0's drive N, with its
    own draws, and the route file says which corpus it came from."""
    import json

    from estimator.sim.stress import drive_spec

    held = drive_spec(2, corpus=1)
    assert held.fault == "no_odometer" and held != drive_spec(2)
    assert main(["simulate", "--stress", "2", "--corpus", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"{held.bias_along_m:+.2f} m along" in out
    doc = json.loads((tmp_path / "stress_c1_2.route.geojson").read_text())
    props = doc["features"][0]["properties"]
    assert props["stress_drive"]["corpus"] == 1 and props["stress_drive"]["seed"] == held.seed
    assert (tmp_path / "stress_c1_2.mcap").exists() and not (tmp_path / "stress_2.mcap").exists()
