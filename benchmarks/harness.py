"""``routefuse bench``: speed and memory of start-up, loading, the estimator, live re-runs, the
inspector and the export, on simulated 5-, 10- and 60-minute drives with a 200 Hz IMU.

Every item runs in a fresh Python process (:mod:`benchmarks.measures`), so its peak memory
(the process's maximum resident set size) and its numba/cache state do not leak into the next
item. Times are the minimum over ``repeat`` runs, wall clock and CPU time of the process (on a
machine shared with other jobs, CPU time is the stable figure; on an idle machine the two agree
for this single-threaded code). The start-up items time whole ``routefuse`` commands (wall
clock, after one warm-up run: warm caches).

The logs are simulated once (:data:`benchmarks.items.LOGS`, seed 0, 200 Hz) into the bench
folder (default ``<routefuse cache>/bench``), and decoded once into the bench's own decoded-log
cache there; later benchmarks reuse both.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks.items import (
    IMU_RATE_HZ,
    ITEM_NAMES,
    ITEMS,
    LOGS,
    QUICK_LOGS,
    SEED,
    BenchLog,
    Figures,
    Item,
    Target,
    select_items,
)

__all__ = [
    "ITEMS",
    "ITEM_NAMES",
    "BenchLog",
    "Target",
    "format_table",
    "run_benchmarks",
    "select_items",
]

# ---------------------------------------------------------------------------------------------
# the logs


def default_bench_dir() -> Path:
    from estimator.io import default_cache_dir

    return default_cache_dir() / "bench"


def _duration(key: str, duration_s: float | None) -> float | None:
    """The drive's own cut, or the smoke test's shorter one."""
    own = LOGS[key].duration_s
    if own is None or duration_s is None:
        return duration_s if own is None else own
    return min(own, duration_s)


def bench_log_paths(folder: Path, key: str, duration_s: float | None = None) -> BenchLog:
    scenario = LOGS[key].scenario
    duration_s = _duration(key, duration_s)
    stem = scenario if duration_s is None else f"{scenario}-{duration_s:g}s"
    sub = folder / "logs" / stem
    return BenchLog(key, sub / f"{scenario}.mcap", sub / f"{scenario}.route.geojson")


def ensure_log(
    folder: Path,
    key: str,
    *,
    duration_s: float | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> BenchLog:
    """Simulate the log (once) and fill the bench's decoded-log cache with it."""
    from estimator.io import load_log
    from estimator.sim import simulate

    paths = bench_log_paths(folder, key, duration_s)
    scenario, duration_s = LOGS[key].scenario, _duration(key, duration_s)
    if not (paths.bag.exists() and paths.route.exists()):
        say(f"simulating {scenario} at {IMU_RATE_HZ:g} Hz into {paths.bag.parent} (once)")
        last = [""]

        def progress(stage: str, fraction: float) -> None:
            line = f"  {stage} {100 * fraction:3.0f} %"
            if line != last[0] and (fraction >= 1.0 or int(100 * fraction) % 25 == 0):
                last[0] = line
                say(line)

        sim = simulate(
            scenario, seed=SEED, imu_rate_hz=IMU_RATE_HZ, duration_s=duration_s, progress=progress
        )
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            bag, route = sim.write(tmp)
            paths.bag.parent.mkdir(parents=True, exist_ok=True)
            os.replace(route, paths.route)
            os.replace(bag, paths.bag)
    cache = folder / "cache"
    say(f"decoding {paths.bag.name} into the bench cache (once)")
    load_log(paths.bag, cache_dir=cache)
    return paths


# ---------------------------------------------------------------------------------------------
# the driver


@dataclass(frozen=True)
class Result:
    item: str
    log: str
    figures: Figures
    targets: tuple[dict[str, Any], ...]
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.item,
            "log": self.log,
            "figures": self.figures,
            "peak_rss_mb": self.figures.get("peak_rss_mb"),
            "targets": list(self.targets),
            "error": self.error,
        }


def run_item(
    item: Item, paths: BenchLog, *, repeat: int, cache: Path, timeout_s: float = 3600.0
) -> Result:
    env = dict(os.environ, ROUTEFUSE_CACHE_DIR=str(cache))
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.measures",
        item.name,
        str(paths.bag),
        str(paths.route),
        str(repeat),
    ]
    root = Path(__file__).resolve().parents[1]
    env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    try:
        proc = subprocess.run(
            cmd, env=env, capture_output=True, text=True, timeout=timeout_s, check=False
        )
    except subprocess.TimeoutExpired:
        return Result(item.name, paths.key, {}, (), f"timed out after {timeout_s:g} s")
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return Result(item.name, paths.key, {}, (), f"exit {proc.returncode}: {tail}")
    figures = {k: float(v) for k, v in json.loads(lines[-1]).items()}
    targets = tuple(
        {"figure": t.figure, "target": t.text, "met": t.met(figures)}
        for t in item.targets.get(paths.key, ())
    )
    return Result(item.name, paths.key, figures, targets)


def machine() -> dict[str, Any]:
    cpu = platform.processor() or ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    commit = ""
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).resolve().parents[1],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        ).stdout.strip()
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "commit": commit,
    }


def run_benchmarks(
    *,
    only: Sequence[str] = (),
    quick: bool = False,
    repeat: int = 3,
    folder: Path | None = None,
    duration_s: float | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> dict[str, Any]:
    """Run the chosen items on the chosen logs; the JSON-ready document."""
    folder = Path(folder) if folder is not None else default_bench_dir()
    folder.mkdir(parents=True, exist_ok=True)
    items = select_items(only)
    keys = QUICK_LOGS if quick else tuple(LOGS)
    todo = [(i, k) for k in keys for i in items if k in i.logs]
    started = time.perf_counter()
    doc: dict[str, Any] = {
        "machine": machine(),
        "settings": {
            "quick": quick,
            "repeat": repeat,
            "imu_rate_hz": IMU_RATE_HZ,
            "seed": SEED,
            "duration_s": duration_s,
            "folder": str(folder),
        },
        "items": [],
    }
    logs: dict[str, BenchLog] = {}
    for n, (item, key) in enumerate(todo, 1):
        if key not in logs:
            logs[key] = ensure_log(folder, key, duration_s=duration_s, say=say)
        say(f"[{n}/{len(todo)}] {item.name} on the {key} log")
        res = run_item(item, logs[key], repeat=repeat, cache=folder / "cache")
        if res.error:
            say(f"  failed: {res.error}")
        doc["items"].append(res.as_dict())
    doc["machine"]["load_average_end"] = (
        list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    )
    doc["total_s"] = time.perf_counter() - started
    return doc


# ---------------------------------------------------------------------------------------------
# the table

_SHOWN: dict[str, tuple[tuple[str, str, str], ...]] = {
    # item -> (figure, label, format)
    "load_first": (
        ("messages_per_s", "msg/s", "{:,.0f}"),
        ("wall_s", "wall s", "{:.2f}"),
        ("cpu_s", "cpu s", "{:.2f}"),
    ),
    "load_cached": (("wall_s", "wall s", "{:.3f}"), ("cpu_s", "cpu s", "{:.3f}")),
    "baseline": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("x_realtime", "x real time (cpu)", "{:,.0f}"),
    ),
    "proposed": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("x_realtime", "x real time (cpu)", "{:,.0f}"),
        ("attempts", "attempts", "{:.0f}"),
    ),
    "rerun_matching": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
        ("views_s", "views s", "{:.3f}"),
        ("first_changed_fraction", "first changed at", "{:.0%}"),
    ),
    "rerun_early": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
        ("first_changed_fraction", "first changed at", "{:.0%}"),
    ),
    "rerun_window": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
        ("first_changed_fraction", "first changed at", "{:.0%}"),
    ),
    "rerun_noise": (
        ("cpu_s", "cpu s", "{:.3f}"),
        ("wall_s", "wall s", "{:.3f}"),
        ("baseline_s", "baseline s", "{:.3f}"),
        ("proposed_s", "proposed s", "{:.3f}"),
    ),
    "inspector": (
        ("step_median_ms", "step median ms", "{:.1f}"),
        ("step_p95_ms", "step p95 ms", "{:.1f}"),
        ("scrub_median_ms", "scrub median ms", "{:.1f}"),
        ("scrub_p95_ms", "scrub p95 ms", "{:.1f}"),
    ),
    "export": (("wall_s", "wall s", "{:.1f}"), ("cpu_s", "cpu s", "{:.1f}")),
    "route_parse": (
        ("worst_peak_rss_mb", "worst peak MB", "{:.0f}"),
        ("xml_csv_route_peak_rss_mb", "GPX/KML/CSV route MB", "{:.0f}"),
        ("line_geojson_file_cpu_s", "GeoJSON line cpu s", "{:.1f}"),
        ("long_gpx_file_cpu_s", "GPX track cpu s", "{:.1f}"),
    ),
    "startup_help": (
        ("wall_s", "wall s", "{:.3f}"),
        ("wall_median_s", "median s", "{:.3f}"),
        ("command_peak_rss_mb", "command MB", "{:.0f}"),
    ),
    "startup_run": (
        ("wall_s", "wall s", "{:.3f}"),
        ("wall_median_s", "median s", "{:.3f}"),
        ("command_peak_rss_mb", "command MB", "{:.0f}"),
    ),
}


def format_table(doc: dict[str, Any]) -> str:
    """A plain-text table: one row per item and log."""
    rows = [("item", "log", "figures", "peak MB", "target")]
    for r in doc["items"]:
        if r["error"]:
            rows.append((r["name"], r["log"], f"FAILED: {r['error']}", "", ""))
            continue
        f = r["figures"]
        shown = ", ".join(
            f"{label} {fmt.format(f[key])}"
            for key, label, fmt in _SHOWN.get(r["name"], ())
            if key in f and math.isfinite(f[key])
        )
        verdicts = "; ".join(
            f"{t['target']}: {'met' if t['met'] else 'MISSED' if t['met'] is False else '?'}"
            for t in r["targets"]
        )
        peak = r["peak_rss_mb"]
        rows.append((r["name"], r["log"], shown, f"{peak:.0f}" if peak else "", verdicts))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    m = doc["machine"]
    load = m.get("load_average")
    lines.append("")
    lines.append(
        f"{m['cpu']}, {m['cores']} cores, Python {m['python']}, commit {m['commit'] or '?'}; "
        + (f"load average at start {load[0]:.1f}" if load else "")
    )
    lines.append(
        "times: minimum over repeats; cpu = CPU time of the benchmark process (stable on a "
        "shared machine); peak MB = maximum resident set of the item's process"
    )
    return "\n".join(lines)
