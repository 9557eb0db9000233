"""Session 11's map-bias fit (the 800 m approach, the method of moments for an unapplied
rotation) and session 12's prior for an unapplied rotation, for tests of mechanisms that
today's fit (the 1600 m approach, an unapplied rotation estimated from its honest second
moment) no longer exercises on their corpus drive: drive 5's matches pulling the estimate away
from dead reckoning (undone by ``dr_separation``), drive 10's first tunnel undone on the road
as driven, and the like."""

from __future__ import annotations

from estimator.params import Params, with_values

MOMENTS_PRIOR = {
    "offset.map_turn_honest_prior": False,
    "extensions.route_errors_overlap_share": False,
}
"""an unapplied rotation's prior in the outage as it was up to session 12 (the method of
moments, or its least value at ``offset.map_turn_lower_sigmas``), before the honest second
moment and the overlap share became the defaults in session 13"""

SESSION_11_FIT = {
    "offset.map_bias_track_m": 800.0,
    "offset.map_turn_lower_sigmas": 0.0,
    **MOMENTS_PRIOR,
}
"""the map-bias fit with the 800 m approach and the method of moments for an unapplied
rotation"""

UNDOING_VALUES = {**SESSION_11_FIT, "extensions.unapplied_bias_lane_tie": False}
"""the parameter values with which drive 5 trips ``dr_separation``"""


def undoing_params(**values: object) -> Params:
    """The defaults with :data:`UNDOING_VALUES` and any further ``values`` (dotted names)."""
    return with_values(Params(), {**UNDOING_VALUES, **values})
