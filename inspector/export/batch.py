"""Exports of many logs: find them, pair each with the route beside it, export each into its
own folder and keep going past a bad one, then write one summary table."""

from __future__ import annotations

import glob
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from estimator.errors import RoutefuseError
from estimator.io import AUTO_TOPICS, LOG_FORMATS_TEXT, TopicChoice, is_log_path, is_route_path
from estimator.io import route_beside as find_route_beside
from estimator.params import Method, Params
from inspector.export import tables as export_tables
from inspector.export.replay import ExportResult, ReplayOptions, export_log, make_dir

"""how the route beside a log is named: ``<stem>.route.geojson``"""
DEFAULT_REPLAY = ReplayOptions()


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


def find_logs(spec: str | Path) -> list[Path]:
    """The logs a batch covers: what the log-format registry recognises directly in a folder,
    or whatever a glob pattern matches."""
    p = Path(spec).expanduser()
    if p.is_dir():
        found = [c for c in sorted(p.iterdir()) if is_log_path(c)]
    else:
        found = [Path(m) for m in sorted(glob.glob(str(p)))]
        found = [m for m in found if not is_route_path(m)]
    if not found:
        raise RoutefuseError(
            spec, f"no logs found (expected a folder holding {LOG_FORMATS_TEXT}, or a glob)"
        )
    return found


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
    progress: Callable[[int, int, Path, str, float], None] | None = None,
) -> BatchResult:
    """Export each log into ``out_dir/<stem>/`` and write ``out_dir/summary.csv``. A log that
    fails (no route beside it, unreadable, ...) is recorded with its one-line error and the
    batch goes on. ``progress(i, n, log, stage, fraction)``."""
    out = Path(out_dir)
    make_dir(out)
    items: list[BatchItem] = []
    used: set[str] = set()
    for i, log in enumerate(logs):
        name = log.name.split(".")[0] or "log"
        folder, k = name, 2
        while folder in used:
            folder, k = f"{name}-{k}", k + 1
        used.add(folder)
        target = out / folder
        started = time.perf_counter()

        def report(stage: str, fraction: float, i: int = i, log: Path = log) -> None:
            if progress is not None:
                progress(i, len(logs), log, stage, fraction)

        result, error = None, None
        try:
            result = export_log(
                log,
                route_beside(log),
                target,
                params=params,
                method=method,
                outages=outages,
                topics=topics,
                replay=replay,
                progress=report,
            )
        except RoutefuseError as exc:
            error = str(exc)
        except Exception as exc:  # one broken log must not stop the batch
            error = f"{log}: internal error: {type(exc).__name__}: {exc}"
        items.append(BatchItem(log, target, result, error, time.perf_counter() - started))
        report("failed" if error else "done", 1.0)
    summary = export_tables.write_summary(out / "summary.csv", items)
    return BatchResult(tuple(items), summary)
