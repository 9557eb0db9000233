"""The sweep's tidy table: one row per (log, set), written as ``results.parquet`` and
``results.csv``.

A row holds every figure of ``routefuse run --json`` (the route deviations and, with ground
truth, the truth errors of each method run; the set's own method's again without a prefix, so
sets of different methods compare in one column), the match attempts, acceptances and the
refusals per gate, the seconds of each stage, the worker's peak memory, the one-line error of a
failed task, and the parameter values that differ from the reference set.

Rows are built on the workers (:func:`task_row`) from the results document; the columns that
depend on the whole plan (the differing values) are added on the client when the table is
written (:func:`write_table`), which streams the per-task files in chunks so the client never
holds every row."""

from __future__ import annotations

import contextlib
import csv
import itertools
import json
import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

from estimator.evaluation.metrics import RouteDeviation, TruthErrors
from estimator.results import Gate
from inspector.fleet.plan import SweepPlan, Task, format_values

METHODS = ("baseline", "proposed", "paper")
ROUTE_KEYS = tuple(f.name for f in fields(RouteDeviation))
TRUTH_KEYS = tuple(f.name for f in fields(TruthErrors))
REFUSAL_KEYS = (*(g.value for g in Gate), "other")

ColumnType = type
"""str, int, float or bool: the Parquet type of a column"""

_IDENTITY: tuple[tuple[str, ColumnType], ...] = (
    ("task_id", str),
    ("log", str),
    ("label", str),
    ("route", str),
    ("tags", str),
    ("outages", str),
    ("set", str),
    ("set_index", int),
    ("reference", bool),
    ("method", str),
    ("status", str),
    ("error", str),
)
_LOG: tuple[tuple[str, ColumnType], ...] = (
    ("duration_s", float),
    ("distance_m", float),
    ("degraded_s", float),
    ("degraded_intervals", int),
    ("matches_attempted", int),
    ("matches_accepted", int),
    *((f"refused_{k}", int) for k in REFUSAL_KEYS),
    ("exits", int),
    ("exits_overconfident", int),
    ("exit_chi2_max", float),
)
_HEADLINE = tuple((k, float) for k in (*ROUTE_KEYS, *TRUTH_KEYS))
_PER_METHOD = tuple((f"{m}_{k}", float) for m in METHODS for k in (*ROUTE_KEYS, *TRUTH_KEYS))
_COST: tuple[tuple[str, ColumnType], ...] = (
    ("load_s", float),
    ("baseline_s", float),
    ("method_s", float),
    ("metrics_s", float),
    ("export_s", float),
    ("total_s", float),
    ("worker", str),
    ("worker_peak_rss_mb", float),
    ("worker_rss_mb", float),
    ("warnings", str),
    ("export_dir", str),
)
TASK_COLUMNS: tuple[tuple[str, ColumnType], ...] = (
    *_IDENTITY,
    *_LOG,
    *_HEADLINE,
    *_PER_METHOD,
    *_COST,
)
"""What a worker's row holds, in table order."""

KEY_METRICS = ("rmse_pos_dev_m", "max_pos_dev_m", "rmse_heading_dev_deg", "rmse_h_err_m")
"""The headline figures the report plots (the set's method, over the degraded intervals)."""


def identity_row(task: Task) -> dict[str, Any]:
    """The columns a row has before (or without) a run: what the plan says about the task."""
    e, s = task.log, task.set
    return {
        "task_id": task.id,
        "log": str(e.log),
        "label": e.label,
        "route": "" if e.route is None else str(e.route),
        "tags": ";".join(e.tags),
        "outages": " ".join(f"{a:g}:{b:g}" for a, b in e.outages),
        "set": s.name,
        "set_index": task.set_index,
        "reference": task.set_index == 0,
        "method": s.method,
        "status": "ok",
        "error": "",
    }


def failed_row(task: Task, error: str, **extra: Any) -> dict[str, Any]:
    """A task that produced no results: its identity and the one-line error."""
    row = identity_row(task)
    row.update(status="failed", error=one_line(error), **extra)
    return row


def one_line(text: str, limit: int = 500) -> str:
    """The error on one line (whitespace collapsed), at most ``limit`` characters."""
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def task_row(
    task: Task,
    doc: Mapping[str, Any],
    *,
    seconds: Mapping[str, float],
    worker: str = "",
    peak_rss_mb: float | None = None,
    rss_mb: float | None = None,
    export_dir: str = "",
) -> dict[str, Any]:
    """A finished task's row from its results document (``routefuse run --json``)."""
    row = identity_row(task)
    method = task.set.method
    matches = doc["matches_by_method"].get(method) or {
        "attempted": 0,
        "accepted": 0,
        "rejected": {},
    }
    exits = doc.get("exits", {}).get(method, ())
    refused = dict.fromkeys(REFUSAL_KEYS, 0)
    for gate, n in matches["rejected"].items():
        refused[gate if gate in refused else "other"] += int(n)
    row.update(
        duration_s=float(doc["duration_s"]),
        distance_m=float(doc["distance_m"]),
        degraded_s=float(sum(b - a for a, b in doc["degraded_intervals"])),
        degraded_intervals=len(doc["degraded_intervals"]),
        matches_attempted=int(matches["attempted"]),
        matches_accepted=int(matches["accepted"]),
        **{f"refused_{k}": v for k, v in refused.items()},
        exits=len(exits),
        exits_overconfident=sum(bool(x["overconfident"]) for x in exits),
        exit_chi2_max=max((float(x["chi2"]) for x in exits), default=None),
    )
    for m, figures in doc["methods"].items():
        route = figures.get("route") or {}
        truth = figures.get("truth") or {}
        for k in ROUTE_KEYS:
            row[f"{m}_{k}"] = route.get(k)
        for k in TRUTH_KEYS:
            row[f"{m}_{k}"] = truth.get(k)
        if m == method:
            row.update({k: route.get(k) for k in ROUTE_KEYS})
            row.update({k: truth.get(k) for k in TRUTH_KEYS})
    row.update(
        {k: seconds.get(k) for k in ("load_s", "baseline_s", "method_s", "metrics_s", "export_s")},
        total_s=seconds.get("total_s"),
        worker=worker,
        worker_peak_rss_mb=peak_rss_mb,
        worker_rss_mb=rss_mb,
        warnings="; ".join(doc.get("warnings", ())),
        export_dir=export_dir,
    )
    return row


# ---------------------------------------------------------------------------------------------
# the table files


def table_columns(plan: SweepPlan) -> list[tuple[str, ColumnType]]:
    """Every column of the sweep's table: the task columns, ``differs`` (the set's values
    that differ from the reference, as text) and one ``param.<name>`` per varied value."""
    cols = [*TASK_COLUMNS, ("differs", str)]
    for name in plan.varied_names():
        sample = next((v for s in plan.sets if (v := plan.differing(s).get(name)) is not None), "")
        tp: ColumnType = type(sample) if isinstance(sample, bool | int | float) else str
        cols.append((f"param.{name}", float if tp is int else tp))
    return cols


def plan_columns(plan: SweepPlan, task: Task) -> dict[str, Any]:
    """The columns a row gets from the whole plan: ``differs`` and ``param.<name>``."""
    from estimator.params import get_param

    differing = plan.differing(task.set)
    out: dict[str, Any] = {"differs": format_values(differing)}
    for name in plan.varied_names():
        value = task.set.method if name == "method" else get_param(task.set.effective, name)
        out[f"param.{name}"] = ",".join(map(str, value)) if isinstance(value, tuple) else value
    return out


def read_task_file(path: Path) -> dict[str, Any] | None:
    """The content of a per-task file, or None when it is missing or unreadable."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("row"), dict) else None


def iter_rows(
    plan: SweepPlan, tasks: Sequence[Task], task_file: Any, *, fallback: Mapping[str, Any]
) -> Iterator[dict[str, Any]]:
    """The rows of ``tasks`` in plan order, read from their task files (``task_file(task)``),
    else taken from ``fallback`` by task id, with the plan's columns added."""
    for task in tasks:
        data = read_task_file(task_file(task))
        row = data["row"] if data is not None else fallback.get(task.id)
        if row is None:
            row = failed_row(task, "no result (the task file is missing)")
        yield {**row, **plan_columns(plan, task)}


CHUNK_ROWS = 1000


def write_table(
    rows: Iterable[Mapping[str, Any]],
    columns: Sequence[tuple[str, ColumnType]],
    out_dir: Path,
) -> tuple[Path, Path]:
    """``results.parquet`` and ``results.csv``, written in chunks of :data:`CHUNK_ROWS`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    kinds = {str: pa.string(), int: pa.int64(), float: pa.float64(), bool: pa.bool_()}
    schema = pa.schema([(name, kinds[tp]) for name, tp in columns])
    parquet, text = out_dir / "results.parquet", out_dir / "results.csv"
    # written under temporary names and renamed once whole: an interrupted write leaves no
    # table that looks complete
    parquet_tmp, text_tmp = (p.with_name(f".{p.name}.tmp") for p in (parquet, text))
    names = [name for name, _ in columns]
    try:
        with (
            pq.ParquetWriter(parquet_tmp, schema) as writer,
            text_tmp.open("w", newline="", encoding="utf-8") as fh,
        ):
            out = csv.writer(fh)
            out.writerow(names)
            chunk: list[Mapping[str, Any]] = []
            for row in itertools.chain(rows, [None]):  # streamed: one chunk in memory
                if row is not None:
                    chunk.append(row)
                if chunk and (row is None or len(chunk) >= CHUNK_ROWS):
                    data = {name: [_typed(r.get(name), tp) for r in chunk] for name, tp in columns}
                    writer.write_table(pa.table(data, schema=schema))
                    out.writerows([_csv_cell(r.get(n)) for n in names] for r in chunk)
                    chunk = []
    except BaseException:
        for tmp in (parquet_tmp, text_tmp):
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise
    os.replace(parquet_tmp, parquet)
    os.replace(text_tmp, text)
    return parquet, text


def _typed(value: Any, tp: ColumnType) -> Any:
    if value is None or (value == "" and tp is not str):
        return None
    if tp is float:
        return float(value)
    if tp is int:
        return int(value)
    if tp is bool:
        return bool(value)
    return str(value)


def _csv_cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return f"{v:.6g}" if v == v else ""
    return str(v)
