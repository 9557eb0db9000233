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
BLAMES_THE_GAP = BLAMES_THE_FILTER | {Gate.HEADING, Gate.ROTATION, Gate.CORRECTION_CAP}
"""after an IMU gap in the outage (``extensions.gap_reacquire``) the filter's heading and place
are the gap's guesses, so the gates comparing the window's heading and the correction with
them blame the filter too"""
GAP_TURN_RAD = math.pi / 4
"""the largest turn of the road an IMU gap may hide from the heading (the kernel's yaw sigma
across a gap): a window turned further is another road or the reversed route"""


def drift_bound_m(seconds: float, metres: float, params: Params) -> float:
    """How far off a drift of ``gates.reanchor_gyro_bias_deg_s`` puts the vehicle after
    ``seconds`` and ``metres`` without GNSS."""
    b = math.radians(params.gates.reanchor_gyro_bias_deg_s)
    return 0.5 * b * max(seconds, 0.0) * max(metres, 0.0)


def blames_the_filter(rec: MatchRecord, params: Params, *, after_gap: bool = False) -> bool:
    """A refused match that is sound in itself: it failed only gates that compare it with the
    filter (``after_gap``: also its heading and the correction's size, the window turned by
    no more than :data:`GAP_TURN_RAD`), and a rival road it lost to fits no better in shape
    (same or larger residual)."""
    if rec.accepted or rec.fit is None or not math.isfinite(rec.residual_m):
        return False
    if after_gap and not abs(rec.rotation_rad) <= GAP_TURN_RAD:
        return False
    blamed = BLAMES_THE_GAP if after_gap else BLAMES_THE_FILTER
    for g in rec.failed_gates:
        rival = g.gate.rival
        if rival is None:
            if g.gate not in blamed:
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
    gap_m: float = 0.0,
) -> bool:
    """The innovation is no larger than the drift bound plus three sigmas of
    ``innovation_cov`` in its own direction (a direction the match does not observe has a
    large sigma there, and is not what failed the gates), plus ``gap_m`` (what an IMU gap
    left unknown: :func:`gap_bound_m`)."""
    size = float(np.hypot(*innovation))
    if size == 0.0:
        return True
    u = innovation / size
    sigma = math.sqrt(max(float(u @ innovation_cov @ u), 0.0))
    return size <= drift_bound_m(seconds, metres, params) + gap_m + 3.0 * sigma


def gap_bound_m(bridged_m: float, since_m: float) -> float:
    """How far off an IMU gap can leave the vehicle ``since_m`` metres after it: half the
    ``bridged_m`` the wheels carried it along the last heading (a road turning anywhere in the
    gap), then the heading up to :data:`GAP_TURN_RAD` off over the distance since."""
    return 0.5 * bridged_m + math.sin(GAP_TURN_RAD) * since_m


def should_reanchor(
    run: Sequence[tuple[MatchRecord, bool]], params: Params, *, after_gap: bool = False
) -> bool:
    """Whether to re-anchor at the last attempt of ``run``: the attempts since the last accepted
    one in this outage, oldest first, each with whether it was :func:`within_drift`. There
    must be at least ``gates.reanchor_after`` of them, and every one must blame the filter
    and be within the drift at its own time: a wrong road is off from its first attempt on,
    before any drift could explain it, and that taints the whole run."""
    if len(run) < params.gates.reanchor_after:
        return False
    return all(ok and blames_the_filter(r, params, after_gap=after_gap) for r, ok in run)
