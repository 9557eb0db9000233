#!/usr/bin/env python3
"""Run the stress corpus (``estimator.sim.stress``, issue 17) on dask.distributed and write its
table and summary figures.

    python scripts/stress_corpus.py [--drives 50] [--corpus K] [--workers 2] [--out DIR] [--write]

Every drive runs the baseline, routefuse with its defaults, routefuse with
``extensions.map_bias`` switched off, and routefuse on a map that draws the road as driven (the
control: what the method gains where the route is right, apart from what the map's bias costs);
per drive the map's drift across the road inside the outages (after its offset at each portal,
:meth:`Drive.map_error_across`); per run: truth RMSE over the GNSS outages, the route deviation
(reported, never alone: it rewards following a wrong map), match counts and the horizontal
position NEES (the error against the truth over the filter's own sigmas, 2 dof). ``--out``
gets ``stress.csv``; ``--write`` puts the summary into ``docs/integrity.md`` between its
markers. ``--corpus K`` (1, 2, ...) runs a held-out corpus instead: the same kinds of fault
drawn afresh and simulated with other seeds (:func:`estimator.sim.stress.drive_spec`), which
no default was chosen with; ``--write`` then fills its own block. Each drive is a Dask task (a
LocalCluster of ``--workers`` processes).
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _doc_blocks import check_values, run_in_workers, write_block, write_rows  # noqa: E402

RUNS: dict[str, tuple[str, dict[str, Any], bool]] = {
    "baseline": ("baseline", {}, False),
    "routefuse": ("proposed", {}, False),
    "map_bias_off": ("proposed", {"extensions.map_bias": False}, False),
    "on_the_road": ("proposed", {}, True),
}
"""label: (method, parameters, whether the map draws the road as driven instead of the biased
map: the control that separates the map's bias from the method, :meth:`Drive.on_the_road`)"""
MARK = "<!-- stress_corpus.py: {} -->"


def run_drive(index: int, corpus: int = 0, values: dict[str, Any] | None = None) -> dict[str, Any]:
    """One corpus drive's row (runs in a Dask worker); ``values`` (``--values``) are given to
    every run, the baseline's dead reckoning included, as a default would be."""
    import numpy as np

    from estimator.evaluation.metrics import NEES_95_2DOF, method_metrics, outage_errors
    from estimator.params import Params, with_values
    from estimator.pipeline import run_methods
    from estimator.sim.stress import build, drive_spec

    started = time.perf_counter()
    spec = drive_spec(index, corpus=corpus)
    row: dict[str, Any] = {
        "corpus": corpus,
        "drive": index,
        "base": spec.base,
        "fault": spec.fault,
        "route_is_right": spec.route_is_right,
        "bias_along_m": round(spec.bias_along_m, 2),
        "bias_across_m": round(spec.bias_across_m, 2),
        "bias_rotation_deg": round(spec.bias_rotation_deg, 2),
        "gyro_bias_deg_h": round(spec.gyro_bias_deg_h, 0),
        "wheel_scale_error": round(spec.wheel_scale_error, 4),
        "error": "",
    }
    try:
        drive = build(spec)
        log, frame = drive.inputs.log, drive.inputs.frame
        assert log.truth is not None
        drift = drive.map_error_across()
        row["map_drift_across_rms_m"] = round(float(np.sqrt(np.mean(drift**2))), 2)
        for label, (method, run_values, on_the_road) in RUNS.items():
            inputs = drive.on_the_road() if on_the_road else drive.inputs
            route = inputs.route
            assert route is not None
            params = with_values(Params(), {**run_values, **(values or {})})
            run = run_methods(inputs, params, methods=(method,))[method]
            metrics = method_metrics(run, route, log)
            _, nees = outage_errors(run, log, frame)
            t = metrics.truth
            row[f"{label}_truth_rmse_m"] = (
                round(t.rmse_h_err_m, 3) if t and t.rmse_h_err_m is not None else None
            )
            row[f"{label}_route_rmse_m"] = round(metrics.route.rmse_pos_dev_m or 0.0, 3)
            row[f"{label}_nees_mean"] = round(float(nees.mean()), 2) if len(nees) else None
            row[f"{label}_nees_over_95"] = (
                round(float(np.mean(nees > NEES_95_2DOF)), 3) if len(nees) else None
            )
            row[f"{label}_accepted"] = sum(m.accepted for m in run.matches)
            row[f"{label}_attempted"] = len(run.matches)
            row[f"{label}_exits"] = len(run.exits)
            row[f"{label}_exits_overconfident"] = sum(x.overconfident for x in run.exits)
    except Exception as exc:  # a failing drive is a row, not the end of the corpus
        row["error"] = f"{type(exc).__name__}: {exc}"[:300]
    row["seconds"] = round(time.perf_counter() - started, 1)
    return row


def summary(rows: list[dict[str, Any]], corpus: int = 0) -> str:
    """The markdown summary of the corpus: overall and per fault."""
    ok = [r for r in rows if not r["error"] and r.get("baseline_truth_rmse_m") is not None]
    which = f"Held-out corpus {corpus}: " if corpus else ""
    lines = [
        f"{which}{len(rows)} drives, {len(rows) - len(ok)} failed. Truth RMSE over the GNSS "
        "outages; "
        "NEES = horizontal position error over the filter's horizontal covariance, its E-N "
        "term included (2 dof: 2 on average, "
        "5 % of epochs over 5.99 when the covariance is honest). The last column is the exit "
        "check: outages whose estimate ended farther from the fixes after them than it and "
        "they claim (chi-square over 13.8, one in a thousand when honest).",
        "",
        "| drives | run | <= baseline + 0.2 m | median run / baseline | median truth RMSE [m] | "
        "mean NEES | epochs NEES > 5.99 | outages ended beyond their sigmas |",
        "|---|---|---|---|---|---|---|---|",
    ]
    groups: list[tuple[str, list[dict[str, Any]]]] = [
        ("all", ok),
        ("route right", [r for r in ok if r["route_is_right"]]),
    ]
    faults = sorted({r["fault"] for r in ok})
    groups += [(f, [r for r in ok if r["fault"] == f]) for f in faults]
    for name, group in groups:
        if not group:
            continue
        for label in RUNS:
            vals = [r for r in group if r[f"{label}_truth_rmse_m"] is not None]
            within = sum(
                r[f"{label}_truth_rmse_m"] <= r["baseline_truth_rmse_m"] + 0.2 for r in vals
            )
            ratio = statistics.median(
                r[f"{label}_truth_rmse_m"] / max(r["baseline_truth_rmse_m"], 1e-6) for r in vals
            )
            rmse = statistics.median(r[f"{label}_truth_rmse_m"] for r in vals)
            nees = [r[f"{label}_nees_mean"] for r in vals if r[f"{label}_nees_mean"] is not None]
            over = [
                r[f"{label}_nees_over_95"] for r in vals if r[f"{label}_nees_over_95"] is not None
            ]
            flagged = sum(r.get(f"{label}_exits_overconfident", 0) for r in vals)
            exits = sum(r.get(f"{label}_exits", 0) for r in vals)
            lines.append(
                f"| {name} ({len(vals)}) | {label} | {100 * within / len(vals):.0f} % | "
                f"{ratio:.2f} | {rmse:.2f} | {statistics.mean(nees):.1f} | "
                f"{100 * statistics.mean(over):.0f} % | {flagged} of {exits} |"
            )
    drifts = sorted(r["map_drift_across_rms_m"] for r in ok if r["route_is_right"])
    if drifts:
        lines += [
            "",
            "Where the route is right, the map's drift across the road inside the outages (after "
            f"its offset at each portal; RMS per drive) is {drifts[0]:.1f} m at least, "
            f"{statistics.median(drifts):.1f} m median: what learning the map's shift at the "
            "portal leaves, against dead reckoning's own error. `on_the_road` is routefuse on "
            "a map that draws the road as driven.",
        ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=50)
    parser.add_argument(
        "--corpus",
        type=int,
        default=0,
        metavar="K",
        help="0: the corpus the defaults were chosen with; 1, 2, ...: a held-out corpus",
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="folder for stress.csv")
    parser.add_argument("--write", action="store_true", help="write docs/integrity.md's summary")
    parser.add_argument(
        "--values",
        type=json.loads,
        default=None,
        help='parameter values given to every run, JSON ({"extensions.x": true}); not with --write',
    )
    args = parser.parse_args(argv)
    check_values(parser, args.values, write=args.write)
    if args.corpus < 0:
        parser.error(f"--corpus {args.corpus}: 0 or a held-out corpus 1, 2, ...")
    started = time.perf_counter()
    task = functools.partial(run_drive, corpus=args.corpus, values=args.values)
    rows = run_in_workers(task, range(args.drives), workers=args.workers, label="stress")
    text = summary(rows, args.corpus)
    print(text)
    print(f"stress: {time.perf_counter() - started:.0f} s", file=sys.stderr)
    if args.out is not None:
        write_rows(args.out / "stress.csv", rows)
    if args.write:
        block = "summary" if args.corpus == 0 else "held-out"
        write_block(REPO / "docs" / "integrity.md", MARK, block, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
