"""The results document: one JSON-ready dict per session (``routefuse run --json``, and the
export's metrics.json): the log, the degraded intervals, every method's metrics and the match
summaries."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimator.evaluation.metrics import MethodMetrics, match_summary
from estimator.log import Log
from estimator.results import Run


def results_document(
    log_path: str | Path,
    route_path: str | Path,
    log: Log,
    runs: Mapping[str, Run],
    metrics: Mapping[str, MethodMetrics],
    *,
    outages: Sequence[tuple[float, float]] = (),
    lane_offset_subtracted: bool = False,
) -> dict[str, Any]:
    """The document of ``runs`` (by method, in the order they ran) and their ``metrics``;
    ``lane_offset_subtracted`` says which measure the route deviations are (from the route
    line, or from the lane learned under GNSS)."""
    methods = list(runs)
    first = next(iter(runs.values()))
    matching = [m for m in methods if m != "baseline"]
    summaries = {m: match_summary(runs[m]) for m in matching}
    key = "proposed" if "proposed" in summaries else (matching[0] if matching else None)
    return {
        "log": str(log_path),
        "route": str(route_path),
        "duration_s": log.duration_s,
        "distance_m": distance_m(first),
        "degraded_intervals": [[a - first.t0, b - first.t0] for a, b in first.degraded_intervals],
        "route_deviation_from": "learned lane" if lane_offset_subtracted else "route line",
        "methods": {m: metrics[m].to_dict() for m in methods},
        "matches": summaries[key]
        if key is not None
        else {"attempted": 0, "accepted": 0, "rejected": {}},
        "matches_by_method": summaries,
        "t0": first.t0,
        "outages": [list(o) for o in outages],
        "n_epochs": {m: metrics[m].n_epochs for m in methods},
        "exits": {m: exits_document(runs[m]) for m in methods},
        "warnings": list(dict.fromkeys(w for r in runs.values() for w in r.warnings)),
    }


def exits_document(run: Run) -> list[dict[str, Any]]:
    """The run's exit checks (:class:`~estimator.results.OutageExit`), times from the log's
    start: what a report or a CI job reads to tell a trustworthy outage from a lucky one."""
    return [
        {
            "outage": [x.start - run.t0, x.end - run.t0],
            "fixes": [x.fix_t[0] - run.t0, x.fix_t[1] - run.t0],
            "n_fixes": x.n_fixes,
            "distance_m": x.distance_m,
            "estimate_sigma_m": x.estimate_sigma_m,
            "chi2": x.chi2,
            "overconfident": x.overconfident,
        }
        for x in run.exits
    ]


def distance_m(run: Run) -> float:
    """Horizontal distance along a run's estimated track."""
    p = run.epochs.position
    return float(np.sum(np.hypot(*np.diff(p[:, :2], axis=0).T))) if len(p) > 1 else 0.0
