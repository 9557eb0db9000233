"""Running the estimator over a log: open the inputs (:func:`open_inputs`), run a session of
methods with re-run reuse (:func:`run_methods`, what every caller uses), or one method
(:func:`run`).

Names are imported on first use, so a caller that only opens inputs (or builds a CLI parser)
does not compile the filter."""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimator._lazy import lazy_getattr

if TYPE_CHECKING:
    from estimator.pipeline.driver import run
    from estimator.pipeline.inputs import Inputs, frame_of, open_inputs, route_distances
    from estimator.pipeline.session import (
        MethodProgress,
        MethodRunner,
        MethodRuns,
        checked_outages,
        run_method,
        run_methods,
    )

_HOMES = {
    "run": "estimator.pipeline.driver",
    "Inputs": "estimator.pipeline.inputs",
    "frame_of": "estimator.pipeline.inputs",
    "open_inputs": "estimator.pipeline.inputs",
    "route_distances": "estimator.pipeline.inputs",
    "MethodProgress": "estimator.pipeline.session",
    "MethodRunner": "estimator.pipeline.session",
    "MethodRuns": "estimator.pipeline.session",
    "checked_outages": "estimator.pipeline.session",
    "run_method": "estimator.pipeline.session",
    "run_methods": "estimator.pipeline.session",
}

__all__ = [
    "Inputs",
    "MethodProgress",
    "MethodRunner",
    "MethodRuns",
    "checked_outages",
    "frame_of",
    "open_inputs",
    "route_distances",
    "run",
    "run_method",
    "run_methods",
]


__getattr__ = lazy_getattr(__name__, _HOMES)
