"""What ``routefuse bench`` measures: the items, the drives they run on and their targets.

Only names and numbers here (no numpy, nothing of routefuse beyond its errors), so that the
command's help and its argument checks stay light."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

IMU_RATE_HZ = 200.0
SEED = 0


@dataclass(frozen=True)
class Drive:
    """A bench log: a simulator scenario, cut to ``duration_s`` (None: the whole drive)."""

    scenario: str
    duration_s: float | None = None


@dataclass(frozen=True)
class BenchLog:
    """A simulated bench log on disk."""

    key: str
    bag: Path
    route: Path


LOGS: dict[str, Drive] = {
    "5min": Drive("long_drive_10min", 300.0),
    "10min": Drive("long_drive_10min"),
    "60min": Drive("long_drive_60min"),
}
"""bench log key -> drive"""
QUICK_LOGS = ("5min", "10min")
"""the logs of ``--quick``"""

MATCHING_CHANGE = ("gates.max_residual_m", 0.1)
"""a gate slider moved (then back to the default: each request is a change); on the bench logs
it rejects attempts from late in the drive on (the figures say where: first_changed)"""
EARLY_CHANGE = ("gates.max_correction_m", 2.0)
"""a gate change that rejects attempts from the first tunnel on: nearly a whole re-run"""
WINDOW_CHANGE = ("window.length_m", 300.0)
"""a window-length change: every match attempt's inputs change"""
NOISE_CHANGE = ("noise.gyro_arw_deg_sqrt_h", 0.2)
"""a filter-noise change: the whole log is re-run"""

Figures = dict[str, float]


@dataclass(frozen=True)
class Target:
    """A figure's goal (from issue 7): ``figure <op> value``."""

    figure: str
    op: str
    value: float
    text: str

    def met(self, figures: Figures) -> bool | None:
        v = figures.get(self.figure)
        if v is None or not math.isfinite(v):
            return None
        return v <= self.value if self.op == "<=" else v >= self.value


@dataclass(frozen=True)
class Item:
    name: str
    what: str
    logs: tuple[str, ...]
    targets: dict[str, tuple[Target, ...]]
    """per log key"""


def _t(figure: str, op: str, value: float, text: str) -> tuple[Target, ...]:
    return (Target(figure, op, value, text),)


ITEMS: tuple[Item, ...] = (
    Item(
        "startup_help",
        "routefuse --help, wall time of the command (start-up: parser, no estimator)",
        ("5min",),
        {"5min": _t("wall_s", "<=", 0.3, "<= 0.3 s")},
    ),
    Item(
        "startup_run",
        "routefuse run LOG --route ROUTE, wall time of the command, warm caches",
        ("5min",),
        {"5min": _t("wall_s", "<=", 1.0, "<= 1.0 s")},
    ),
    Item("load_first", "bag -> arrays, first load (empty cache)", ("10min", "60min"), {}),
    Item(
        "load_cached",
        "bag -> arrays, cached reload",
        ("10min", "60min"),
        {"60min": _t("wall_s", "<=", 0.5, "<= 0.5 s")},
    ),
    Item("baseline", "baseline run (IMU + wheel + GNSS)", ("10min", "60min"), {}),
    Item(
        "proposed",
        "proposed run (with route matching)",
        ("10min", "60min"),
        {
            "10min": _t("x_realtime", ">=", 1000.0, ">= 1000x real time"),
            "60min": _t("x_realtime", ">=", 1000.0, ">= 1000x real time"),
        },
    ),
    Item(
        "rerun_matching",
        f"inspector: {MATCHING_CHANGE[0]} changed -> new session (both runs, views)",
        ("10min", "60min"),
        {"10min": _t("cpu_s", "<=", 0.5, "<= 0.5 s"), "60min": _t("cpu_s", "<=", 2.0, "<= 2 s")},
    ),
    Item(
        "rerun_early",
        f"inspector: {EARLY_CHANGE[0]} changed -> new session (changes the first tunnel)",
        ("10min", "60min"),
        {},
    ),
    Item(
        "rerun_window",
        f"inspector: {WINDOW_CHANGE[0]} changed -> new session",
        ("10min", "60min"),
        {},
    ),
    Item(
        "rerun_noise",
        f"inspector: {NOISE_CHANGE[0]} changed -> new session",
        ("10min", "60min"),
        {},
    ),
    Item(
        "inspector",
        "inspector server side: one frame step, one scrub jump; serve peak memory",
        ("10min", "60min"),
        {
            "60min": (
                Target("step_p95_ms", "<=", 30.0, "<= 30 ms"),
                Target("peak_rss_mb", "<=", 1024.0, "<= 1 GB"),
            )
        },
    ),
    Item("export", "routefuse export (all files)", ("10min",), {}),
    Item(
        "route_parse",
        "route files at the caps (benchmarks/route_parse_memory.py): peak RSS of reading each "
        "in a fresh process (the 5min log is not used)",
        ("5min",),
        {
            "5min": (
                Target("worst_peak_rss_mb", "<=", 450.0, "every file <= 450 MB"),
                Target("xml_csv_route_peak_rss_mb", "<=", 250.0, "GPX/KML/CSV route <= 250 MB"),
            )
        },
    ),
)
ITEM_NAMES = tuple(i.name for i in ITEMS)


def select_items(only: Sequence[str] = ()) -> tuple[Item, ...]:
    """Items named in ``only`` (a name, or a prefix such as ``load`` or ``rerun``); all if
    empty."""
    if not only:
        return ITEMS
    chosen = [i for i in ITEMS if any(i.name == o or i.name.startswith(o) for o in only)]
    unknown = [o for o in only if not any(i.name.startswith(o) for i in ITEMS)]
    if unknown:
        from estimator.errors import ConfigError

        raise ConfigError(
            "--only", f"unknown item {', '.join(unknown)} (items: {', '.join(ITEM_NAMES)})"
        )
    return tuple(chosen)
