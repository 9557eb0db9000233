"""The rivals of a candidate: the same window fitted (with the same fit) to the route shifted
left and right by ``gates.alternative_shift_m`` and to the route driven backwards. A parallel
carriageway has the same shape as the road and would pass every shape gate; a candidate is
only trusted if it explains the window clearly better than these. Rivals are scored, never
applied."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from estimator.matching.fit import FitSettings, fit_cost, fit_window
from estimator.matching.gates import ShapeValues
from estimator.matching.geometry import Polyline, local_piece
from estimator.params import Params
from estimator.results import Rival

F64 = NDArray[np.float64]


class RivalPiece(NamedTuple):
    """Where a rival road lies: the route between ``lo`` and ``hi`` shifted ``lateral_m`` to
    the left, driven backwards if ``reverse``."""

    rival: Rival
    lateral_m: float
    lo: float
    hi: float
    reverse: bool


@dataclass(frozen=True)
class RivalFit:
    """A rival that could be fitted: what its shape gates test, its cost and its residual."""

    rival: Rival
    shape: ShapeValues
    cost: float
    residual_m: float


def rival_pieces(
    n_window: int,
    s_anchor: float,
    lane: float,
    lane_path: bool,
    params: Params,
    *,
    search_m: float | None = None,
) -> tuple[RivalPiece, ...]:
    """The route pieces the rivals of a window of ``n_window`` points anchored at arc length
    ``s_anchor`` are fitted to (``search_m``: the candidate's along-track search half-width,
    ``window.along_search_m`` unless widened)."""
    h = params.window.spacing_m
    span = (n_window - 1) * h
    search = params.window.along_search_m if search_m is None else search_m
    pad = search + 2.0 * h
    shift = params.gates.alternative_shift_m
    base = lane if lane_path else 0.0
    ahead = (s_anchor - pad, s_anchor + span + pad)
    return (
        RivalPiece(Rival.LEFT, base + shift, *ahead, False),
        RivalPiece(Rival.RIGHT, base - shift, *ahead, False),
        # driven the other way, the lane lies on the other side of the centreline
        RivalPiece(Rival.REVERSED, -base, s_anchor - span - pad, s_anchor + pad, True),
    )


def fit_rivals(
    win: F64,
    p_dr: F64,
    cov: F64,
    road: Polyline,
    s_anchor: float,
    lane: float,
    lane_path: bool,
    params: Params,
    settings: FitSettings,
    *,
    search_m: float | None = None,
) -> tuple[RivalFit, ...]:
    """Each rival of the window that can be built and fitted (``settings``: of ``params``).
    ``lane_path``: the candidate was the lane line, so the rivals are shifted lane lines and
    carry no further lane offset."""
    z_lane = 0.0 if lane_path else lane
    out = []
    for rp in rival_pieces(len(win), s_anchor, lane, lane_path, params, search_m=search_m):
        piece = local_piece(road, rp.lateral_m, rp.lo, rp.hi, reverse=rp.reverse)
        if piece is None:
            continue
        anchor = piece.arc_of(win[0])
        fit = fit_window(
            win,
            p_dr,
            piece,
            anchor,
            z_lane,
            settings,
            pointwise_residual=True,
            grid_scan=True,
            pos_cov2=cov,
        )
        if fit is None:
            continue
        cost = fit_cost(fit, p_dr, cov, settings)
        out.append(RivalFit(rp.rival, ShapeValues.of(fit), cost, fit.residual))
    return tuple(out)
