"""The route matcher: a dead-reckoned window registered to the mission route.

- :mod:`~estimator.matching.match`: one attempt, :func:`match_geometry` (the fits) then
  :func:`judge_match` (the gates), or both in :func:`match_window`;
- :mod:`~estimator.matching.fit`: THE rigid fit, used by the candidate and the rivals;
- :mod:`~estimator.matching.gates`: the gates as data and the table built from them;
- :mod:`~estimator.matching.rivals`: the shifted and reversed roads a candidate must beat;
- :mod:`~estimator.matching.geometry`: resampling, local route pieces, projections, the lane
  offset;
- :mod:`~estimator.matching.kernels`, :mod:`~estimator.matching.route_kernels`: the compiled
  inner loops.

Names are imported on first use, so importing the package does not load the compiled kernels.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimator._lazy import lazy_getattr

if TYPE_CHECKING:
    from estimator.matching.fit import Fit, FitSettings, fit_window, kabsch_2d
    from estimator.matching.gates import SHAPE_GATES, GateSpec, ShapeValues, gate_table
    from estimator.matching.geometry import (
        Polyline,
        learn_lane_offset,
        project_on_route,
        resample_polyline,
        route_arc_length,
        shifted_route,
        track_on_route,
    )
    from estimator.matching.match import (
        MatchGeometry,
        geometry_params,
        judge_match,
        match_geometry,
        match_window,
    )
    from estimator.matching.rivals import RivalFit, fit_rivals, rival_pieces

_HOMES = {
    "Fit": "estimator.matching.fit",
    "FitSettings": "estimator.matching.fit",
    "fit_window": "estimator.matching.fit",
    "kabsch_2d": "estimator.matching.fit",
    "SHAPE_GATES": "estimator.matching.gates",
    "GateSpec": "estimator.matching.gates",
    "ShapeValues": "estimator.matching.gates",
    "gate_table": "estimator.matching.gates",
    "Polyline": "estimator.matching.geometry",
    "learn_lane_offset": "estimator.matching.geometry",
    "project_on_route": "estimator.matching.geometry",
    "resample_polyline": "estimator.matching.geometry",
    "route_arc_length": "estimator.matching.geometry",
    "shifted_route": "estimator.matching.geometry",
    "track_on_route": "estimator.matching.geometry",
    "MatchGeometry": "estimator.matching.match",
    "geometry_params": "estimator.matching.match",
    "judge_match": "estimator.matching.match",
    "match_geometry": "estimator.matching.match",
    "match_window": "estimator.matching.match",
    "RivalFit": "estimator.matching.rivals",
    "fit_rivals": "estimator.matching.rivals",
    "rival_pieces": "estimator.matching.rivals",
}

__all__ = [
    "SHAPE_GATES",
    "Fit",
    "FitSettings",
    "GateSpec",
    "MatchGeometry",
    "Polyline",
    "RivalFit",
    "ShapeValues",
    "fit_rivals",
    "fit_window",
    "gate_table",
    "geometry_params",
    "judge_match",
    "kabsch_2d",
    "learn_lane_offset",
    "match_geometry",
    "match_window",
    "project_on_route",
    "resample_polyline",
    "rival_pieces",
    "route_arc_length",
    "shifted_route",
    "track_on_route",
]


__getattr__ = lazy_getattr(__name__, _HOMES)
