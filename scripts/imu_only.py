#!/usr/bin/env python3
"""IMU-only cases (issue 17, item 4): does routefuse help, or leave alone, a log without wheel
speed? Runs the baseline and routefuse on every case on dask.distributed and writes the table
into ``docs/integrity.md``.

    python scripts/imu_only.py [--sims 24] [--workers 2] [--out DIR] [--write]

The cases:

- comma2k19 I-280 (``../shared/data/comma2k19``), a real car, read with its wheel topic left
  out (``TopicChoice(no_wheel=True)``, ``--no-wheel``) and the example config
  ``sample_logs/configs/comma2k19_i280.toml``; GNSS removed by injected outages of 15, 30 and
  45 s at several places along the 60 s drive, and to its end. Errors against the log's
  ground truth (comma's post-fit pose, read with the config's truth time offset).
- simulated IMU-only drives (:mod:`estimator.sim.imu_only`): gyro turn-on biases of 300-720
  deg/h, accelerometer scale errors of 0.5-1.2 %, the IMU mounted 1-4 deg off in pitch and
  1-3 deg in yaw, its clock 10-50 ms off the receiver's, none of it told to the filter; the
  GNSS outages are the scenarios' tunnels.
- the stress corpus's no-odometer drives (:mod:`estimator.sim.stress`, with its map biases).

Every case runs ``baseline``, ``routefuse`` (the defaults) and ``routefuse`` with
``extensions.no_wheel_caution`` off (what the defaults did before it); the measure is the
truth RMSE over the GNSS outages. ``--out`` gets ``imu_only.csv``; ``--write`` replaces the
table between the ``imu_only.py`` markers of ``docs/integrity.md``.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _doc_blocks import check_values, run_in_workers, write_block, write_rows  # noqa: E402

COMMA = REPO.parent / "shared" / "data" / "comma2k19"
COMMA_CONFIG = REPO / "sample_logs" / "configs" / "comma2k19_i280.toml"
COMMA_OUTAGES: tuple[tuple[float, float], ...] = (
    (5, 20),
    (15, 30),
    (25, 40),
    (35, 50),
    (45, 60),
    (5, 35),
    (15, 45),
    (25, 55),
    (28, 58),
    (5, 50),
    (10, 55),
    (14, 59),
    (3, 61),
)
"""(start, end) s after the log start: 15, 30 and 45 s at places from braking to cruising,
and to the end of the 60 s log (GNSS never returns)"""
STRESS_NO_ODOMETER = (2, 12, 22, 32, 42)
"""the stress corpus's no-odometer drives (drive i has that fault when i % 10 == 2)"""
RUNS: dict[str, tuple[str, dict[str, Any]]] = {
    "baseline": ("baseline", {}),
    "routefuse": ("proposed", {}),
    "no_caution": ("proposed", {"extensions.no_wheel_caution": False}),
}
"""label: (method, parameters)"""
MARK = "<!-- imu_only.py: {} -->"


def run_values_of(
    label: str, run_values: dict[str, Any], values: dict[str, Any] | None, everywhere: bool
) -> dict[str, Any]:
    """The parameter values of run ``label``: its own (``RUNS``), with ``values`` on top for the
    ``routefuse`` run, or for every run with ``everywhere``."""
    if values and (everywhere or label == "routefuse"):
        return {**run_values, **values}
    return run_values


def run_case(
    case: tuple[str, Any], values: dict[str, Any] | None = None, everywhere: bool = False
) -> dict[str, Any]:
    """One case's row (runs in a Dask worker): ("comma", (start, end)), ("sim", index) or
    ("stress", index); ``values``: parameter values of the ``routefuse`` run (``--values``),
    or of every run with ``everywhere`` (``--values-everywhere``: a filter switch as a
    default would be, the baseline's dead reckoning included)."""
    import numpy as np

    from estimator.evaluation.metrics import method_metrics
    from estimator.io import TopicChoice
    from estimator.params import Params, load_params, with_values
    from estimator.pipeline import open_inputs, run_methods
    from estimator.sim.imu_only import build_imu_only, imu_only_spec
    from estimator.sim.stress import build, drive_spec

    kind, arg = case
    started = time.perf_counter()
    row: dict[str, Any] = {"kind": kind, "case": "", "outage": "", "faults": "", "error": ""}
    try:
        outages: tuple[tuple[float, float], ...] = ()
        if kind == "comma":
            inputs = open_inputs(
                COMMA / "i280.mcap",
                COMMA / "i280_route.geojson",
                topics=TopicChoice(no_wheel=True),
            )
            params = load_params(COMMA_CONFIG)
            outages = (tuple(arg),)
            row["case"] = "comma2k19 I-280"
            row["outage"] = f"{arg[0]:g}-{arg[1]:g} s"
            row["faults"] = "real car, wheel topic left out"
        elif kind == "sim":
            spec = imu_only_spec(int(arg))
            drive = build_imu_only(spec)
            inputs, params = drive.inputs, Params()
            row["case"] = f"sim {spec.index} ({spec.base})"
            row["outage"] = "tunnels"
            row["faults"] = (
                f"gyro {spec.gyro_bias_deg_h:.0f} deg/h, accel scale "
                f"{spec.accel_scale_ppm / 1e4:.1f} %, mount pitch {spec.mount_pitch_deg:+.1f} "
                f"yaw {spec.mount_yaw_deg:+.1f} deg, clock {1e3 * spec.imu_time_offset_s:+.0f} ms"
            )
        else:
            sspec = drive_spec(int(arg))
            drive = build(sspec)
            inputs, params = drive.inputs, Params()
            row["case"] = f"stress {sspec.index} ({sspec.base})"
            row["outage"] = "tunnels"
            row["faults"] = (
                f"no odometer, gyro {sspec.gyro_bias_deg_h:.0f} deg/h, map "
                f"{sspec.bias_along_m:+.1f} m along {sspec.bias_across_m:+.1f} m across "
                f"{sspec.bias_rotation_deg:+.1f} deg"
            )
        assert inputs.log.wheel is None and inputs.route is not None
        for label, (method, run_values) in RUNS.items():
            p = with_values(params, run_values_of(label, run_values, values, everywhere))
            run = run_methods(inputs, p, methods=(method,), outages=outages).runs[method]
            truth = method_metrics(run, inputs.route, inputs.log, params=p).truth
            rmse = truth.rmse_h_err_m if truth is not None else None
            row[f"{label}_truth_rmse_m"] = None if rmse is None else round(float(rmse), 3)
            row[f"{label}_accepted"] = sum(m.accepted for m in run.matches)
            row[f"{label}_attempted"] = len(run.matches)
            row[f"{label}_exits"] = len(run.exits)
            row[f"{label}_exits_overconfident"] = sum(x.overconfident for x in run.exits)
        b, r = row["baseline_truth_rmse_m"], row["routefuse_truth_rmse_m"]
        row["routefuse_le_baseline"] = bool(np.isfinite(b) and np.isfinite(r) and r <= b)
    except Exception as exc:  # a failing case is a row, not the end of the table
        row["error"] = f"{type(exc).__name__}: {exc}"[:300]
    row["seconds"] = round(time.perf_counter() - started, 1)
    return row


def cases(sims: int) -> list[tuple[str, Any]]:
    return (
        [("comma", o) for o in COMMA_OUTAGES]
        + [("sim", i) for i in range(sims)]
        + [("stress", i) for i in STRESS_NO_ODOMETER]
    )


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def table(rows: list[dict[str, Any]]) -> str:
    """The markdown summary and table of the cases."""
    ok = [r for r in rows if not r["error"]]
    lines = []
    for kind, name in (
        ("comma", "comma2k19 I-280 placements"),
        ("sim", "simulated IMU-only"),
        ("stress", "stress corpus, no odometer"),
    ):
        group = [r for r in ok if r["kind"] == kind]
        if not group:
            continue
        better = sum(r["routefuse_le_baseline"] for r in group)
        before = sum(r["no_caution_truth_rmse_m"] <= r["baseline_truth_rmse_m"] for r in group)
        flagged = {k: sum(r[f"{k}_exits_overconfident"] for r in group) for k in RUNS}
        exits = sum(r["routefuse_exits"] for r in group)
        lines.append(
            f"- {name}: routefuse <= baseline on **{better} of {len(group)}** "
            f"(with `no_wheel_caution` off: {before} of {len(group)}); outages ended beyond "
            f"their sigmas (the exit check): baseline {flagged['baseline']}, routefuse "
            f"{flagged['routefuse']} of {exits}"
        )
    failed = [r for r in rows if r["error"]]
    if failed:
        lines.append(
            f"- {len(failed)} cases failed: "
            + "; ".join(f"{r['kind']} {r['case']}: {r['error']}" for r in failed)
        )
    lines += [
        "",
        "| case | outage | faults | baseline [m] | routefuse [m] | <= baseline | "
        "`no_wheel_caution` off [m] | matches accepted / attempted | exits beyond their "
        "sigmas, baseline / routefuse |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in ok:
        lines.append(
            f"| {r['case']} | {r['outage']} | {r['faults']} | {_f(r['baseline_truth_rmse_m'])} "
            f"| {_f(r['routefuse_truth_rmse_m'])} | "
            f"{'yes' if r['routefuse_le_baseline'] else '**no**'} | "
            f"{_f(r['no_caution_truth_rmse_m'])} | "
            f"{r['routefuse_accepted']} / {r['routefuse_attempted']} | "
            f"{r['baseline_exits_overconfident']} / {r['routefuse_exits_overconfident']} "
            f"of {r['routefuse_exits']} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--sims", type=int, default=24, help="simulated IMU-only drives")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="folder for imu_only.csv")
    parser.add_argument("--write", action="store_true", help="write docs/integrity.md's table")
    parser.add_argument(
        "--values",
        type=json.loads,
        default={},
        help='parameter values of the routefuse run, JSON ({"extensions.x": true})',
    )
    parser.add_argument(
        "--values-everywhere",
        action="store_true",
        help="give --values to every run (baseline too), as a default would be",
    )
    args = parser.parse_args(argv)
    check_values(parser, args.values, write=args.write)
    started = time.perf_counter()
    job = (
        functools.partial(run_case, values=args.values, everywhere=args.values_everywhere)
        if args.values
        else run_case
    )
    rows = run_in_workers(job, cases(args.sims), workers=args.workers, label="imu_only")
    text = table(rows)
    print(text)
    print(f"imu_only: {time.perf_counter() - started:.0f} s", file=sys.stderr)
    if args.out is not None:
        write_rows(args.out / "imu_only.csv", rows)
    if args.write:
        write_block(REPO / "docs" / "integrity.md", MARK, "table", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
