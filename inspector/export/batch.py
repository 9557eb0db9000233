"""Exports of many logs: find them, pair each with the route beside it, export each into its
own folder and keep going past a bad one, then write one summary table.

The exports run on the sweep engine (:mod:`inspector.fleet.engine`): each log is a Dask task
(a local cluster of one worker per core, or ``scheduler=`` a running one), a failed log is a row
with its one-line error, and a second run skips the logs exported before."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from estimator.errors import RoutefuseError
from estimator.io import AUTO_TOPICS, TopicChoice
from estimator.io import route_beside as find_route_beside
from estimator.params import Method, Params
from inspector.export import tables as export_tables
from inspector.export.replay import ExportResult, ReplayOptions, make_dir
from inspector.fleet.plan import LogEntry, ParamSet, SweepPlan, collect_logs, find_logs

__all__ = ["BatchItem", "BatchResult", "export_batch", "find_logs", "route_beside"]

DEFAULT_REPLAY = ReplayOptions()
LegacyProgress = Callable[[int, int, Path, str, float], None]
"""``progress(i, n, log, stage, fraction)``, called as each log finishes (stage ``done`` or
``failed``)"""


@dataclass(frozen=True)
class BatchItem:
    """One log of a batch: its result, or the one-line reason it failed."""

    log: Path
    out_dir: Path
    result: ExportResult | None
    error: str | None
    seconds: float

    @property
    def ok(self) -> bool:
        return self.error is None


@dataclass(frozen=True)
class BatchResult:
    items: tuple[BatchItem, ...]
    summary_csv: Path

    @property
    def failed(self) -> tuple[BatchItem, ...]:
        return tuple(i for i in self.items if not i.ok)


def route_beside(log: Path) -> Path:
    """The route named after the log beside it (:func:`estimator.io.route_beside`)."""
    route = find_route_beside(log)
    if route is None:
        stem = log.name.split(".")[0]
        raise RoutefuseError(
            log,
            f"no route {stem}.route.geojson beside the log "
            "(nor a .gpx, .kml or .csv named after it)",
        )
    return route


def export_batch(
    logs: Sequence[Path],
    out_dir: str | Path,
    *,
    params: Params | None = None,
    method: Method = "proposed",
    outages: Sequence[tuple[float, float]] = (),
    topics: TopicChoice = AUTO_TOPICS,
    replay: ReplayOptions = DEFAULT_REPLAY,
    progress: LegacyProgress | Any | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    cache_dir: str | Path | None = None,
) -> BatchResult:
    """Export each log into ``out_dir/<stem>/`` and write ``out_dir/summary.csv`` (besides the
    sweep engine's ``results.parquet`` and ``results.csv``). A log that fails (no route beside
    it, unreadable, ...) is recorded with its one-line error and the batch goes on.

    ``progress``: a :class:`inspector.fleet.engine.SweepProgress`, or a function
    ``progress(i, n, log, stage, fraction)`` called as each log finishes. ``workers``,
    ``scheduler``, ``cache_dir``: as :func:`inspector.fleet.run_sweep`."""
    from inspector.fleet.engine import QuietProgress, SweepLayout, run_sweep
    from inspector.fleet.table import read_task_file

    out = Path(out_dir)
    make_dir(out)
    entries = collect_logs(list(logs), outages=outages)
    chosen = ParamSet(method, params or Params(), method, "method", f"--method {method}")
    plan = SweepPlan(entries, (chosen,), topics)
    sink: Any
    if progress is None:
        sink = QuietProgress()
    elif hasattr(progress, "advance"):
        sink = progress
    else:
        sink = _CallbackProgress(progress)
    run_sweep(
        plan,
        out,
        workers=workers,
        scheduler=scheduler,
        export=replay,
        export_layout="flat",
        progress=sink,
        cache_dir=cache_dir,
        report=False,
    )
    layout = SweepLayout(out, "flat")
    items = [
        _item(task.log, layout.export_dir(task), read_task_file(layout.task_file(task)))
        for task in plan.tasks()
    ]
    summary = export_tables.write_summary(out / "summary.csv", items)
    return BatchResult(tuple(items), summary)


def _item(entry: LogEntry, folder: Path, data: Mapping[str, Any] | None) -> BatchItem:
    """A log's item from its task file (None: the task never finished)."""
    if data is None:
        return BatchItem(entry.log, folder, None, f"{entry.log}: no result", 0.0)
    row, doc = data["row"], data.get("document")
    seconds = float(row.get("total_s") or 0.0)
    if row.get("status") != "ok" or not isinstance(doc, dict):
        return BatchItem(entry.log, folder, None, str(row.get("error") or "failed"), seconds)
    doc = dict(doc)
    export = doc.pop("export", None) or {}
    result = ExportResult(
        log=entry.log,
        route=Path(str(entry.route)),
        out_dir=folder,
        files=tuple(Path(f) for f in data.get("files", ())),
        metrics=doc,
        frames=int(export.get("frames", 0)),
    )
    return BatchItem(entry.log, folder, result, None, seconds)


class _CallbackProgress:
    """The engine's progress as ``progress(i, n, log, stage, fraction)`` calls."""

    def __init__(self, callback: LegacyProgress) -> None:
        self.callback = callback
        self.total = self.done = 0

    def start(self, *, total: int, done: int, failed: int, dashboard: str | None) -> None:
        self.total, self.done = total, done

    def advance(self, row: Mapping[str, Any]) -> None:
        stage = "done" if row.get("status") == "ok" else "failed"
        self.callback(self.done, self.total, Path(str(row["log"])), stage, 1.0)
        self.done += 1

    def note(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass
