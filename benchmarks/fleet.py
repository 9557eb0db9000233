"""Fleet benchmarks (issue 18): the sweep engine on this machine.

    python3 benchmarks/fleet.py [--json OUT]

1. scaling: the four sample logs x four parameter sets (proposed, paper, two configs), a whole
   ``run_sweep`` (cluster start, decode, tasks, table, report) with 1 worker, then with 2;
2. scheduling overhead: one task on the 10-minute bench drive, on a warm worker, as the client
   sees it (submit to result) against the task's own time inside the worker;
3. peak memory per worker: the 10- and 60-minute bench drives, each on a fresh worker;
4. client memory: the client's resident set as rows come in, over a sweep of 4 logs x 12 sets.

The bench drives are the ``routefuse bench`` ones (simulated once into the bench folder); the
decoded-log cache is a fresh one under a temporary folder, filled before anything is timed
except in 1. (where decoding is part of the sweep, once per log)."""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

REPO = Path(__file__).resolve().parents[1]
REPEATS = 3


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _sets(work: Path) -> list[tuple[str, str]]:
    window = work / "short_window.toml"
    window.write_text("[window]\nlength_m = 100.0\n")
    residual = work / "tight_residual.toml"
    residual.write_text("[gates]\nmax_residual_m = 1.5\n")
    return [("method", "proposed"), ("method", "paper"), ("config", str(window)),
            ("config", str(residual))]  # fmt: skip


def scaling(work: Path) -> dict[str, Any]:
    """The whole sweep (cluster start, decoding, tasks, table, report) once per worker count,
    then the task phase alone on warm workers (each has run a task: numba's kernels loaded),
    :data:`REPEATS` times."""
    import pyarrow.parquet as pq

    from inspector.fleet import SweepPlan, build_sets, collect_logs, run_sweep
    from inspector.fleet.engine import (
        QuietProgress,
        SweepLayout,
        _drive,
        open_client,
        prepare_output,
        run_task,
    )

    plan = SweepPlan(collect_logs([str(REPO / "sample_logs")]), build_sets(_sets(work)))
    tasks = plan.tasks()
    out: dict[str, Any] = {"tasks": len(tasks)}
    for n in (1, 2):
        _say(f"scaling: {len(tasks)} tasks on {n} worker(s)")
        started = time.perf_counter()
        result = run_sweep(
            plan,
            work / f"scale-{n}",
            workers=n,
            cache_dir=work / f"cache-scale-{n}",
            progress=QuietProgress(),
        )
        wall = time.perf_counter() - started
        rows = pq.read_table(result.parquet, columns=["total_s", "status"]).to_pylist()
        figures: dict[str, Any] = {
            "whole_sweep_wall_s": wall,
            "failed": result.failed,
            "task_s_sum": sum(r["total_s"] or 0.0 for r in rows),
            "task_s_median": statistics.median(r["total_s"] or 0.0 for r in rows),
        }
        phases = []
        with open_client(workers=n, scheduler=None) as client:
            client.run(run_task, _job_of(tasks[0], plan, work, work / f"cache-scale-{n}"), None)
            for r in range(REPEATS):
                layout = SweepLayout(work / f"warm-{n}-{r}")
                prepare_output(plan, layout)
                t0 = time.perf_counter()
                _drive(
                    client,
                    plan,
                    tasks,
                    layout,
                    cache=str(work / f"cache-scale-{n}"),
                    export=None,
                    retries=1,
                    window=None,
                    record=lambda row: None,
                )
                phases.append(time.perf_counter() - t0)
        figures["warm_task_phase_s"] = phases
        figures["warm_task_phase_s_min"] = min(phases)
        out[f"workers_{n}"] = figures
    one, two = out["workers_1"], out["workers_2"]
    out["ratio_whole_2_over_1"] = two["whole_sweep_wall_s"] / one["whole_sweep_wall_s"]
    out["ratio_warm_2_over_1"] = two["warm_task_phase_s_min"] / one["warm_task_phase_s_min"]
    return out


def _job_of(task: Any, plan: Any, work: Path, cache: Path) -> Any:
    from inspector.fleet.engine import TaskJob

    return TaskJob(task, plan.topics, str(cache), str(work / "warm.json"), None, None)


def _bench_plan(work: Path, key: str) -> Any:
    from benchmarks.harness import default_bench_dir, ensure_log
    from inspector.fleet import SweepPlan, build_sets, collect_logs

    paths = ensure_log(default_bench_dir(), key, say=_say)
    return SweepPlan(collect_logs([str(paths.bag)]), build_sets([("method", "proposed")]))


def _job(plan: Any, work: Path, cache: Path, name: str) -> Any:
    from inspector.fleet.engine import TaskJob

    (task,) = plan.tasks()
    return TaskJob(task, plan.topics, str(cache), str(work / f"{name}.json"), None, None)


def overhead(work: Path) -> dict[str, Any]:
    """Client round trip against the task's own time, on one warm worker."""
    from estimator.io import load_log
    from inspector.fleet.engine import open_client, run_task

    plan = _bench_plan(work, "10min")
    cache = work / "cache-bench"
    load_log(plan.logs[0].log, cache_dir=cache)
    samples = []
    with open_client(workers=1, scheduler=None) as client:
        client.submit(run_task, _job(plan, work, cache, "warm"), None, pure=False).result()
        for i in range(REPEATS):
            started = time.perf_counter()
            future = client.submit(run_task, _job(plan, work, cache, f"o{i}"), None, pure=False)
            row = future.result()
            round_trip = time.perf_counter() - started
            samples.append({"round_trip_s": round_trip, "task_s": row["total_s"]})
            future.release()
    direct = []
    for i in range(REPEATS):
        started = time.perf_counter()
        run_task(_job(plan, work, cache, f"d{i}"), None)
        direct.append(time.perf_counter() - started)
    trip = statistics.median(s["round_trip_s"] for s in samples)
    task = statistics.median(s["task_s"] for s in samples)
    return {
        "log": "10min",
        "samples": samples,
        "round_trip_s_median": trip,
        "task_s_median": task,
        "in_process_s_median": statistics.median(direct),
        "overhead_s": trip - task,
        "overhead_fraction": (trip - task) / task,
    }


def memory(work: Path) -> dict[str, Any]:
    """Peak resident set of a fresh worker after one task on each bench drive."""
    from estimator.io import load_log
    from inspector.fleet.engine import open_client, run_task

    out: dict[str, Any] = {}
    cache = work / "cache-bench"
    for key in ("10min", "60min"):
        plan = _bench_plan(work, key)
        load_log(plan.logs[0].log, cache_dir=cache)
        _say(f"memory: the {key} drive on a fresh worker")
        with open_client(workers=1, scheduler=None) as client:
            row = client.submit(run_task, _job(plan, work, cache, f"m{key}"), None).result()
        out[key] = {
            "worker_peak_rss_mb": row["worker_peak_rss_mb"],
            "task_s": row["total_s"],
            "status": row["status"],
            "duration_s": row["duration_s"],
        }
    return out


def client_memory(work: Path) -> dict[str, Any]:
    import psutil

    from inspector.fleet import SweepPlan, build_sets, collect_logs, run_sweep
    from inspector.fleet.engine import QuietProgress

    grid = work / "grid.toml"
    grid.write_text(
        "[gates]\nmax_residual_m = [1.5, 2.0, 3.0]\n[window]\nlength_m = [100.0, 150.0, 200.0, "
        "250.0]\n"
    )
    plan = SweepPlan(collect_logs([str(REPO / "sample_logs")]), build_sets([("grid", str(grid))]))
    me = psutil.Process()
    rss: list[float] = []
    _say(f"client memory: {len(plan.tasks())} tasks on 2 workers")
    run_sweep(
        plan,
        work / "client",
        workers=2,
        cache_dir=work / "cache-client",
        progress=QuietProgress(),
        report=False,
        on_row=lambda row: rss.append(me.memory_info().rss / 2**20),
    )
    n = len(rss)
    return {
        "tasks": n,
        "client_rss_mb_after_row_1": rss[0],
        "client_rss_mb_after_row_n_half": rss[n // 2],
        "client_rss_mb_after_last_row": rss[-1],
        "client_rss_mb_max": max(rss),
    }


PARTS = {
    "scaling": scaling,
    "overhead": overhead,
    "memory": memory,
    "client_memory": client_memory,
}


def main() -> int:
    from benchmarks.harness import machine

    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--only", nargs="+", choices=tuple(PARTS), default=list(PARTS))
    args = parser.parse_args()
    doc: dict[str, Any] = {"machine": machine()}
    with tempfile.TemporaryDirectory(prefix="routefuse-fleet-bench-") as tmp:
        for name in args.only:
            doc[name] = PARTS[name](Path(tmp))
    doc["machine"]["load_average_end"] = list(__import__("os").getloadavg())
    text = json.dumps(doc, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
