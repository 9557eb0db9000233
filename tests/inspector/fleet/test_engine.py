"""Sweeps on a real Dask cluster (a ``dask scheduler`` and ``dask worker`` processes on
127.0.0.1): through ``routefuse sweep --scheduler``, resumed, past a corrupt log, and past a
worker killed mid-sweep."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from estimator.errors import RoutefuseError
from estimator.evaluation import method_metrics
from estimator.io import TopicChoice
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run_methods
from inspector.cli.main import main
from inspector.fleet import SweepPlan, build_sets, collect_logs, run_sweep
from inspector.fleet.engine import QuietProgress
from tests.inspector.fleet.conftest import REPO, copy_drive, dask_env

HOSTILE = "<img src=x onerror=alert(1)>&'\""
OUTAGE = "10:20"


@pytest.fixture(scope="module")
def cli_sweep(dask_cluster, short_drive, tmp_path_factory):
    """``routefuse sweep`` of three logs (one named to attack the report) x two sets (the
    second, named to attack it too, a shorter match window: it changes every log's figures)."""
    root = tmp_path_factory.mktemp("cli")
    data = root / "logs"
    for stem in ("drive_a", "drive_b", HOSTILE):
        copy_drive(short_drive, data, stem)
    config = root / "<svg onload=alert(2)>.toml"
    config.write_text("[window]\nlength_m = 100.0\n")
    out = root / "out"
    argv = ["sweep", str(data), "--out", str(out), "--scheduler", dask_cluster.address,
            "--method", "proposed", "--config", str(config), "--outage", OUTAGE,
            "--cache-dir", str(root / "cache"), "--quiet"]  # fmt: skip
    code = main(argv)
    return code, out, data, config


def test_sweep_through_a_running_scheduler(cli_sweep):
    code, out, data, _ = cli_sweep
    assert code == 0
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert len(rows) == 6 and all(r["status"] == "ok" for r in rows)
    assert {r["set"] for r in rows} == {"proposed", "<svg onload=alert(2)>"}
    assert sorted(r["reference"] for r in rows) == [False] * 3 + [True] * 3
    tuned = [r for r in rows if r["set"] != "proposed"]
    assert all(r["differs"] == "window.length_m=100" for r in tuned)
    assert all(r["param.window.length_m"] == 100.0 for r in tuned)
    assert all(r["worker"] and r["worker_peak_rss_mb"] > 50 for r in rows)
    assert all(r["outages"] == OUTAGE for r in rows)
    # the row holds the figures routefuse run computes for that log and set
    row = next(r for r in tuned if r["label"] == "drive_a")
    params = with_values(Params(), {"window.length_m": 100.0})
    inputs = open_inputs(data / "drive_a.mcap", data / "drive_a.route.geojson")
    session = run_methods(inputs, params, outages=[(10.0, 20.0)])
    assert inputs.route is not None
    for method in ("baseline", "proposed"):
        m = method_metrics(session[method], inputs.route, inputs.log, params=params)
        assert row[f"{method}_rmse_pos_dev_m"] == pytest.approx(m.route.rmse_pos_dev_m)
    assert row["rmse_pos_dev_m"] == row["proposed_rmse_pos_dev_m"]
    attempts = len(session["proposed"].matches)
    accepted = sum(r.accepted for r in session["proposed"].matches)
    refused = sum(v for k, v in row.items() if k.startswith("refused_"))
    assert (row["matches_attempted"], row["matches_accepted"]) == (attempts, accepted)
    assert refused == attempts - accepted
    # the outage, not the tunnel at 38 s that the drive ends in, is followed by fixes
    exits = session["proposed"].exits
    assert row["exits"] == len(exits) == 1
    assert row["exits_overconfident"] == sum(x.overconfident for x in exits)
    assert row["exit_chi2_max"] == pytest.approx(exits[0].chi2)
    # the CSV is the same table; the set's parameters are written for routefuse serve
    csv_lines = (out / "results.csv").read_text().splitlines()
    assert len(csv_lines) == 7 and csv_lines[0].startswith("task_id,log,label")
    (tuned_toml,) = (out / "sets").glob("*svg*.toml")
    assert "length_m = 100.0" in tuned_toml.read_text() and "<" not in tuned_toml.name


def test_the_report_escapes_names_and_is_self_contained(cli_sweep):
    _, out, _, _ = cli_sweep
    page = (out / "report.html").read_text()
    assert "<img src=x" not in page and "<svg onload" not in page
    assert "&lt;img src=x onerror=alert(1)&gt;&amp;" in page
    assert "&lt;svg onload=alert(2)&gt;" in page
    assert "http://" not in page and "https://" not in page
    assert "<script" not in page.lower()
    assert page.count("src='data:image/png;base64,") >= 3  # the distributions, inline
    # every (log, set) with a change is ranked with the command that opens it
    assert "routefuse serve " in page and "--config" in page and f"--outage {OUTAGE}" in page


def _plan(data: Path, *specs: tuple[str, str]) -> SweepPlan:
    return SweepPlan(collect_logs([str(data)], outages=[(10.0, 30.0)]), build_sets(list(specs)))


def test_a_second_run_skips_the_finished_tasks(dask_cluster, short_drive, tmp_path):
    data = tmp_path / "logs"
    copy_drive(short_drive, data, "drive")
    plan = _plan(data, ("method", "proposed"), ("method", "paper"))
    out = tmp_path / "out"
    kwargs = {"scheduler": dask_cluster.address, "progress": QuietProgress(), "report": False}
    first = run_sweep(plan, out, cache_dir=tmp_path / "cache", **kwargs)
    assert (first.total, first.ran, first.skipped, first.failed) == (2, 2, 0, 0)
    files = sorted((out / "tasks").glob("*.json"))
    assert len(files) == 2
    stamps = {f: f.stat().st_mtime_ns for f in files}
    second = run_sweep(plan, out, cache_dir=tmp_path / "cache", **kwargs)
    assert (second.ran, second.skipped) == (0, 2)
    assert {f: f.stat().st_mtime_ns for f in files} == stamps
    assert pq.read_table(second.parquet).num_rows == 2
    files[0].unlink()
    third = run_sweep(plan, out, cache_dir=tmp_path / "cache", **kwargs)
    assert (third.ran, third.skipped) == (1, 1) and files[0].is_file()


def test_a_corrupt_log_is_a_row_with_its_error(dask_cluster, short_drive, tmp_path):
    data = tmp_path / "logs"
    copy_drive(short_drive, data, "drive")
    (data / "corrupt.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\x00garbage" * 100)
    (data / "corrupt.route.geojson").write_bytes((data / "drive.route.geojson").read_bytes())
    plan = _plan(data, ("method", "proposed"), ("method", "paper"))
    result = run_sweep(
        plan,
        tmp_path / "out",
        scheduler=dask_cluster.address,
        progress=QuietProgress(),
        cache_dir=tmp_path / "cache",
    )
    assert (result.total, result.failed) == (4, 2)
    rows = {(r["label"], r["set"]): r for r in pq.read_table(result.parquet).to_pylist()}
    for s in ("proposed", "paper"):
        bad, good = rows[("corrupt", s)], rows[("drive", s)]
        assert bad["status"] == "failed" and "corrupt.mcap: " in bad["error"]
        assert "\n" not in bad["error"] and "Traceback" not in bad["error"]
        assert bad["rmse_pos_dev_m"] is None
        assert good["status"] == "ok" and good["error"] == "" and good["rmse_pos_dev_m"] > 0
    page = (tmp_path / "out" / "report.html").read_text()
    assert "Failed tasks (2)" in page and "corrupt.mcap: " in page


def test_a_worker_killed_mid_sweep_still_gives_every_row(dask_cluster, short_drive, tmp_path):
    extra = dask_cluster.start_worker(nanny=False)
    dask_cluster.wait_for_workers(3)
    data = tmp_path / "logs"
    for stem in ("a", "b", "c"):
        copy_drive(short_drive, data, stem)
    plan = _plan(data, ("method", "proposed"), ("method", "paper"))
    killed = []

    def kill_after_first_row(row: object) -> None:
        if not killed:
            os.kill(extra.pid, signal.SIGKILL)
            killed.append(extra.pid)

    result = run_sweep(
        plan,
        tmp_path / "out",
        scheduler=dask_cluster.address,
        progress=QuietProgress(),
        cache_dir=tmp_path / "cache",
        report=False,
        on_row=kill_after_first_row,
    )
    assert killed and extra.wait(timeout=15) == -signal.SIGKILL
    assert (result.total, result.failed) == (6, 0)
    rows = pq.read_table(result.parquet).to_pylist()
    assert len(rows) == 6 and all(r["status"] == "ok" for r in rows)


def test_exports_are_linked_from_the_report_and_resumed(dask_cluster, short_drive, tmp_path):
    from inspector.export.replay import ReplayOptions

    data = tmp_path / "logs"
    copy_drive(short_drive, data, "drive")
    plan = _plan(data, ("method", "proposed"), ("method", "paper"))
    out = tmp_path / "out"
    kwargs = {"scheduler": dask_cluster.address, "progress": QuietProgress()}
    replay = ReplayOptions(fps=0.5)
    first = run_sweep(plan, out, cache_dir=tmp_path / "cache", export=replay, **kwargs)
    assert (first.ran, first.failed) == (2, 0)
    for s in ("proposed", "paper"):
        assert (out / "exports" / s / "drive" / "replay.html").stat().st_size > 100_000
    page = (out / "report.html").read_text()
    assert "href='exports/paper/drive/replay.html'" in page
    again = run_sweep(plan, out, cache_dir=tmp_path / "cache", export=replay, **kwargs)
    assert (again.ran, again.skipped) == (0, 2)
    # other replay options: the exports are written again
    other = run_sweep(plan, out, cache_dir=tmp_path / "cache", export=ReplayOptions(), **kwargs)
    assert other.ran == 2


def test_local_workers_leave_ctrl_c_to_the_client():
    """Ctrl-C reaches the whole process group: the local workers used to take it too, each
    printing a KeyboardInterrupt traceback while the client was already closing the cluster.
    They start with SIGINT ignored; the client's own handler is back once they run."""
    from inspector.fleet.engine import open_client

    before = signal.getsignal(signal.SIGINT)
    with open_client(workers=1, scheduler=None) as client:
        assert signal.getsignal(signal.SIGINT) is before
        ignored = client.run(lambda: signal.getsignal(signal.SIGINT) == signal.SIG_IGN)
    assert list(ignored.values()) == [True]


def test_a_run_stopped_midway_leaves_no_table_or_report_that_looks_complete(tmp_path):
    """A second run into the same folder stopped by Ctrl-C used to leave the first run's
    results.csv and report.html beside the new plan.json, looking like this run's."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for stem in ("a", "b"):
        (logs / f"{stem}.mcap").write_bytes(b"")  # no route: rows made on the client
    out = tmp_path / "out"
    plan = SweepPlan(collect_logs([str(logs)]), build_sets([]))
    run_sweep(plan, out, progress=QuietProgress())
    assert (out / "results.csv").is_file() and (out / "report.html").is_file()

    def ctrl_c(row):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(plan, out, progress=QuietProgress(), on_row=ctrl_c)
    assert sorted(p.name for p in out.iterdir()) == ["plan.json", "sets", "tasks"]


def test_a_table_write_that_fails_midway_leaves_no_table(tmp_path):
    from inspector.fleet.table import write_table

    def rows():
        yield {"log": "a"}
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_table(rows(), [("log", str)], tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_the_table_is_written_in_chunks_without_holding_every_row(tmp_path, monkeypatch):
    """write_table took every row into one list before its first chunk (``[*rows, None]``): a
    sweep's client held the whole table at the end, however large."""
    import inspector.fleet.table as table

    monkeypatch.setattr(table, "CHUNK_ROWS", 2)
    yielded = 0
    first_write_after: list[int] = []
    real_typed = table._typed

    def typed(value, tp):
        if not first_write_after:
            first_write_after.append(yielded)
        return real_typed(value, tp)

    monkeypatch.setattr(table, "_typed", typed)

    def rows():
        nonlocal yielded
        for i in range(7):
            yielded += 1
            yield {"log": f"log{i}"}

    table.write_table(rows(), [("log", str)], tmp_path)
    assert first_write_after == [2]
    assert (tmp_path / "results.csv").read_text().splitlines()[1:] == [f"log{i}" for i in range(7)]


@contextlib.contextmanager
def _scheduler_without_workers():
    """An in-process scheduler on a loopback TCP port, with no worker of its own."""
    from distributed import LocalCluster

    cluster = LocalCluster(
        n_workers=0, processes=False, protocol="tcp", host="127.0.0.1", dashboard_address=None
    )
    try:
        yield cluster
    finally:
        cluster.close()


def test_waiting_for_a_worker_says_so_and_ends_with_one_line(monkeypatch):
    """With --scheduler and no worker, nothing was printed for the minute of the wait."""
    from inspector.fleet import engine

    monkeypatch.setattr(engine, "WORKERS_TIMEOUT_S", 2.5)
    monkeypatch.setattr(engine, "WAITING_NOTE_S", 1.0)
    notes: list[str] = []
    with _scheduler_without_workers() as cluster:
        address = cluster.scheduler_address
        with (
            pytest.raises(RoutefuseError) as refused,
            engine.open_client(workers=None, scheduler=address, note=notes.append),
        ):
            pass
    assert str(refused.value) == f"{address}: no Dask worker joined within 2.5 s"
    assert notes[0] == f"connecting to the Dask scheduler at {address} (up to 30 s)"
    assert notes[1] == "waiting for a Dask worker to join (up to 2.5 s)"
    waiting = notes[2:]  # one a second, while the 2.5 s run out (fewer on a busy machine)
    assert 1 <= len(waiting) <= 2, notes
    assert all(re.fullmatch(r"no Dask worker yet after \d+ s", n) for n in waiting), notes


def test_a_worker_on_other_code_is_refused_before_any_task(tmp_path, short_drive):
    """The task ids hash the client's estimator source: a worker running another routefuse
    would write rows a resumed sweep keeps as this code's. It is found before any task runs,
    with the library's client.run on every worker, and the sweep stops with one line."""
    other = tmp_path / "other"
    for package in ("estimator", "inspector"):
        shutil.copytree(
            REPO / package, other / package, ignore=shutil.ignore_patterns("__pycache__")
        )
    with (other / "estimator" / "errors.py").open("a") as f:
        f.write("\n# another commit\n")
    log = copy_drive(short_drive, tmp_path / "logs", "drive")
    plan = SweepPlan(collect_logs([str(log)]), build_sets([]))
    with _scheduler_without_workers() as cluster:
        address = cluster.scheduler_address
        cmd = [sys.executable, "-m", "dask", "worker", address, "--nthreads", "1",
               "--host", "127.0.0.1", "--no-dashboard", "--no-nanny",
               "--local-directory", str(tmp_path / "worker")]  # fmt: skip
        worker = subprocess.Popen(
            cmd,
            env=dict(dask_env(), PYTHONPATH=str(other)),
            cwd=other,  # python -m puts the working folder first on the path
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            with pytest.raises(RoutefuseError) as refused:
                run_sweep(plan, tmp_path / "out", scheduler=address, progress=QuietProgress())
        finally:
            worker.terminate()
            worker.wait(timeout=30)
    message = str(refused.value)
    assert message.startswith(f"{address}: 1 of 1 Dask workers run another routefuse")
    assert message.endswith("install this routefuse on every worker") and "\n" not in message
    assert not list((tmp_path / "out" / "tasks").glob("*.json"))  # nothing ran


def _task_job(task, tmp_path, *, estimator_source):
    from inspector.fleet.engine import TaskJob

    return TaskJob(
        task=task,
        topics=TopicChoice(),
        cache_dir=str(tmp_path / "cache"),
        task_file=str(tmp_path / "task.json"),
        export_dir=None,
        replay=None,
        estimator_source=estimator_source,
    )


def test_a_task_on_a_worker_of_other_code_fails_instead_of_writing_an_ok_row(tmp_path, short_drive):
    """A worker that joins after the check still cannot write a row under this code's id."""
    from inspector.fleet.engine import run_task

    log = copy_drive(short_drive, tmp_path / "logs", "drive")
    task = SweepPlan(collect_logs([str(log)]), build_sets([])).tasks()[0]
    job = _task_job(task, tmp_path, estimator_source="0123456789abcdef")
    row = run_task(job, None)
    assert row["status"] != "ok"
    assert "this worker runs another routefuse" in row["error"]
    assert "the client's 0123456789abcdef" in row["error"]


def test_a_library_warning_in_a_task_is_one_of_its_warnings_not_a_worker_printout(
    tmp_path, short_drive, monkeypatch, capfd
):
    """A worker process has no terminal of its own: a Python warning raised in a task (a
    figure of one instant, a numpy edge case) was printed by the worker with its source line
    into the client's terminal; now it is a line of the task's warnings, once."""
    import warnings

    import inspector.fleet.engine as engine
    from inspector.fleet.engine import run_task

    original = engine._run

    def run_warning_twice(job):
        for _ in range(2):
            warnings.warn("identical low and high xlims\nsecond line", UserWarning, stacklevel=1)
        return original(job)

    monkeypatch.setattr(engine, "_run", run_warning_twice)
    log = copy_drive(short_drive, tmp_path / "logs", "drive")
    task = SweepPlan(collect_logs([str(log)]), build_sets([])).tasks()[0]
    job = _task_job(task, tmp_path, estimator_source=None)
    row = run_task(job, None)
    assert row["status"] == "ok", row
    told = [w for w in row["warnings"].split("; ") if "xlims" in w]
    assert told == ["UserWarning: identical low and high xlims"]
    assert "xlims" not in capfd.readouterr().err
