"""Fleet scale: sweeps of parameter sets over many logs, run as Dask tasks on a laptop
(LocalCluster) or a cluster (a running ``dask scheduler``), with one tidy table and a report.

Python API (see :mod:`inspector.fleet.engine` for what it does and writes)::

    from inspector.fleet import SweepPlan, build_sets, collect_logs, run_sweep

    plan = SweepPlan(collect_logs(["drives/", "more/*.mcap", "manifest.csv"]),
                     build_sets([("config", "a.toml"), ("grid", "grid.toml")]))
    result = run_sweep(plan, "out/", workers=4)      # or scheduler="tcp://head:8786"

Importing this package is light (no Dask, no pyarrow, no matplotlib until a sweep runs)."""

from estimator._lazy import lazy_getattr
from inspector.fleet.plan import (
    LogEntry,
    ParamSet,
    SweepPlan,
    Task,
    build_sets,
    collect_logs,
    differing_values,
    expand_grid,
    find_logs,
)

_LAZY = {
    "SweepResult": "inspector.fleet.engine",
    "TerminalProgress": "inspector.fleet.engine",
    "QuietProgress": "inspector.fleet.engine",
    "run_sweep": "inspector.fleet.engine",
}

__getattr__ = lazy_getattr(__name__, _LAZY)

__all__ = [
    "LogEntry",
    "ParamSet",
    "QuietProgress",
    "SweepPlan",
    "SweepResult",
    "Task",
    "TerminalProgress",
    "build_sets",
    "collect_logs",
    "differing_values",
    "expand_grid",
    "find_logs",
    "run_sweep",
]
