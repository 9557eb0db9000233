"""When the filter, not the match, is wrong: re-anchoring to the route (``extensions.reanchor``).

Under a drift the filter does not model (a gyro bias that appeared in the tunnel, an
uncalibrated MEMS IMU), its covariance shrinks while the dead-reckoned position runs away: good
matches are then refused for disagreeing with it (the Mahalanobis and lane-continuity gates),
and every later one disagrees more, so the method stays with dead reckoning for the rest of the
outage. A run of such refusals is evidence against the filter when each match is sound in
itself (every shape gate passes, the correction is under the cap, no rival road is better
shaped, only worse placed relative to the drifted estimate) and the disagreement is one a
plausible drift explains: a heading error growing as ``theta = b t`` over ``t`` seconds without
GNSS puts the vehicle about ``theta D / 2`` off after ``D`` metres, with ``b`` the largest
unmodelled gyro bias allowed (``gates.reanchor_gyro_bias_deg_s``). A parallel road the route
does not take shows up at once, far beyond that bound, and is still refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from estimator.params import Params
from estimator.results import Gate, MatchRecord

BLAMES_THE_FILTER = frozenset({Gate.MAHALANOBIS, Gate.LANE_CONTINUITY, Gate.DR_SEPARATION})
"""gates that fail when the filter, not the road, is off (a route update that moved the
estimate away from a drifting dead reckoning too)"""


def drift_bound_m(seconds: float, metres: float, params: Params) -> float:
    """How far off a drift of ``gates.reanchor_gyro_bias_deg_s`` puts the vehicle after
    ``seconds`` and ``metres`` without GNSS."""
    b = math.radians(params.gates.reanchor_gyro_bias_deg_s)
    return 0.5 * b * max(seconds, 0.0) * max(metres, 0.0)


def blames_the_filter(rec: MatchRecord, params: Params) -> bool:
    """A refused match that is sound in itself: it failed only gates that compare it with the
    filter, and a rival road it lost to fits no better in shape (same or larger residual)."""
    if rec.accepted or rec.fit is None or not math.isfinite(rec.residual_m):
        return False
    for g in rec.failed_gates:
        rival = g.gate.rival
        if rival is None:
            if g.gate not in BLAMES_THE_FILTER:
                return False
            continue
        if rival.value == "reversed":
            return False
        rival_residual = rec.extra.get(f"residual_{rival.value}_m", math.nan)
        if not rival_residual >= rec.residual_m:
            return False
    return True


def within_drift(
    innovation: np.ndarray,
    innovation_cov: np.ndarray,
    *,
    seconds: float,
    metres: float,
    params: Params,
) -> bool:
    """The innovation is no larger than the drift bound plus three sigmas of
    ``innovation_cov`` in its own direction (a direction the match does not observe has a
    large sigma there, and is not what failed the gates)."""
    size = float(np.hypot(*innovation))
    if size == 0.0:
        return True
    u = innovation / size
    sigma = math.sqrt(max(float(u @ innovation_cov @ u), 0.0))
    return size <= drift_bound_m(seconds, metres, params) + 3.0 * sigma


def should_reanchor(run: Sequence[tuple[MatchRecord, bool]], params: Params) -> bool:
    """Whether to re-anchor at the last attempt of ``run``: the attempts since the last accepted
    one in this outage, oldest first, each with whether it was :func:`within_drift`. There
    must be at least ``gates.reanchor_after`` of them, and every one must blame the filter
    and be within the drift at its own time: a wrong road is off from its first attempt on,
    before any drift could explain it, and that taints the whole run."""
    if len(run) < params.gates.reanchor_after:
        return False
    return all(ok and blames_the_filter(r, params) for r, ok in run)
