"""Headless export of runs: one log (:func:`export_log`: replay, figures, tables) or many
(:func:`export_batch`, with a summary table). This is the package's public face."""

from inspector.export.batch import BatchItem, BatchResult, export_batch, find_logs, route_beside
from inspector.export.replay import (
    ExportResult,
    ReplayOptions,
    export_log,
    headless_server,
    replay_times,
    write_replay,
)
from inspector.export.tables import format_summary

__all__ = [
    "BatchItem",
    "BatchResult",
    "ExportResult",
    "ReplayOptions",
    "export_batch",
    "export_log",
    "find_logs",
    "format_summary",
    "headless_server",
    "replay_times",
    "route_beside",
    "write_replay",
]
