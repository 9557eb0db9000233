"""The gates of a match attempt as data: one entry per :class:`~estimator.results.Gate` (what it
compares, against which threshold, why), and the table of decisions built from them in one
place (:func:`gate_table`). A new gate is a :class:`Gate` member, a :class:`GateSpec` here and
the value that feeds it."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from estimator.matching.fit import Fit
from estimator.params import GateParams, Params
from estimator.results import Comparison, Gate, GateDecision, Rival


class ShapeValues(NamedTuple):
    """What the shape gates test of a fit."""

    n_pairs: float
    heading_cos: float
    residual_m: float
    rotation_deg: float

    @classmethod
    def of(cls, fit: Fit) -> ShapeValues:
        return cls(fit.n_pairs, fit.heading_cos, fit.residual, float(np.degrees(abs(fit.angle))))


@dataclass(frozen=True)
class GateSpec:
    """One gate: ``value <comparison> threshold(params.gates)`` passes."""

    gate: Gate
    comparison: Comparison
    threshold: Callable[[GateParams], float]
    note: str

    def passes(self, value: float, g: GateParams) -> bool:
        threshold = float(self.threshold(g))
        v = float(value)
        return v <= threshold if self.comparison == "<=" else v >= threshold

    def decide(self, value: float, g: GateParams, *, note: str | None = None) -> GateDecision:
        return GateDecision(
            self.gate,
            float(value),
            float(self.threshold(g)),
            self.comparison,
            self.passes(value, g),
            self.note if note is None else note,
        )


@functools.lru_cache(maxsize=64)
def _cos_deg(angle_deg: float) -> float:
    return float(np.cos(np.radians(angle_deg)))


SHAPE_GATES = (
    GateSpec(Gate.MIN_PAIRS, ">=", lambda g: g.min_pairs, "valid window/route point pairs"),
    GateSpec(
        Gate.HEADING,
        ">=",
        lambda g: _cos_deg(g.max_heading_diff_deg),
        "signed cosine between DR and route end directions",
    ),
    GateSpec(Gate.RESIDUAL, "<=", lambda g: g.max_residual_m, "RMS of the rigid fit, m"),
    GateSpec(Gate.ROTATION, "<=", lambda g: g.max_rotation_deg, "fitted rotation, deg"),
)
"""in the order of :class:`ShapeValues`"""

UNPAIRED = GateSpec(
    Gate.MIN_PAIRS, ">=", lambda g: g.min_pairs, "window or route too short to pair"
)
"""the only gate of an attempt without a fit"""

MAHALANOBIS = GateSpec(
    Gate.MAHALANOBIS,
    "<=",
    lambda g: g.mahalanobis_chi2,
    "innovation chi-square, S = P_EN + R_k (P_EN with the map-bias error where carried)",
)
"""S = H P H^T + R_k with H = [I, I] over the position and map-bias error states: the record's
``filter_cov`` plus its ``obs_cov`` (:func:`~estimator.matching.fit.mahalanobis2`)"""
LANE_CONTINUITY = GateSpec(
    Gate.LANE_CONTINUITY,
    "<=",
    lambda g: g.max_lateral_jump_m,
    "move across the route away from the learned lane, m",
)
ALTERNATIVES = {
    r: GateSpec(Gate.alternative(r), ">=", lambda g: g.alternative_margin, "") for r in Rival
}
CORRECTION_CAP = GateSpec(Gate.CORRECTION_CAP, "<=", lambda g: g.max_correction_m, "|z - p_dr|, m")
ROTATION_CONSISTENCY = GateSpec(
    Gate.ROTATION_CONSISTENCY,
    "<=",
    lambda g: g.rotation_chi2,
    "chi-square of the fitted rotation, S = yaw variance + map rotation variance + the fit's "
    "heading variance",
)
"""judged with the filter's covariance at the attempt (``extensions.rotation_consistency``)"""
DR_SEPARATION = GateSpec(
    Gate.DR_SEPARATION,
    "<=",
    lambda g: g.dr_separation_chi2,
    "chi-square of the move from dead reckoning over the outage after the update, "
    "S = P_dr - P; failed: the outage's route updates undone",
)
"""not the matcher's but the filter's, tested after the update (``extensions.dr_separation``)"""


def undone_gate(chi2: float, at_s: float, g: GateParams) -> GateDecision:
    """The attempt after the outage's route updates were undone at ``at_s`` (seconds into the
    log) with separation chi-square ``chi2``: refused with that value."""
    note = f"the outage's route updates were undone at {at_s:.1f} s: none taken since"
    return DR_SEPARATION.decide(chi2, g, note=note)


def shape_gates(values: ShapeValues, g: GateParams) -> list[GateDecision]:
    return [spec.decide(v, g) for spec, v in zip(SHAPE_GATES, values, strict=True)]


def shape_passes(values: ShapeValues, g: GateParams) -> bool:
    """Every shape gate passes (a rival that fails one is no road to confuse the
    candidate with)."""
    return all(spec.passes(v, g) for spec, v in zip(SHAPE_GATES, values, strict=True))


@dataclass(frozen=True)
class Validation:
    """The values the candidate-validation gates test (``extensions.candidate_validation``)."""

    d2: float
    """innovation chi-square"""
    jump: float
    """move across the route, m"""
    cost: float
    """the candidate's cost (:func:`~estimator.matching.fit.fit_cost`)"""
    rivals: tuple[tuple[Rival, ShapeValues, float], ...]
    """(rival, shape values, cost) of each rival that could be fitted"""


def alternative_gate(
    rival: Rival, shape: ShapeValues, rival_cost: float, cost: float, g: GateParams
) -> GateDecision:
    """Rival cost minus candidate cost; +inf (no rival) when the rival fails a shape gate."""
    plausible = shape_passes(shape, g)
    margin = rival_cost - cost if plausible else float("inf")
    note = (
        f"rival cost minus candidate cost ({rival.value} "
        + (f"shift {g.alternative_shift_m:g} m)" if rival is not Rival.REVERSED else "direction)")
        + ("" if plausible else "; rival fails the shape gates")
    )
    return ALTERNATIVES[rival].decide(margin, g, note=note)


def gate_table(
    shape: ShapeValues,
    validation: Validation | None,
    correction_m: float,
    params: Params,
    *,
    search_m: float = 0.0,
) -> tuple[GateDecision, ...]:
    """Every gate of a fitted attempt, in :class:`Gate` order; ``search_m``: the half-width of
    the along-track search the fit was made in (the correction cap with
    ``extensions.search_correction_cap``)."""
    g = params.gates
    table = shape_gates(shape, g)
    if validation is not None:
        table.append(MAHALANOBIS.decide(validation.d2, g))
        table.append(LANE_CONTINUITY.decide(validation.jump, g))
        table += [
            alternative_gate(rival, values, rival_cost, validation.cost, g)
            for rival, values, rival_cost in validation.rivals
        ]
    table.append(correction_cap(correction_m, params, search_m))
    return tuple(table)


def correction_cap(correction_m: float, params: Params, search_m: float) -> GateDecision:
    """``gates.max_correction_m``, or with ``extensions.search_correction_cap`` and
    ``covariance_search`` the along-track search's half-width where that is wider: the search
    was widened to 3 sigma of the filter's own along-track position because the filter may be
    that far off, so a correction that far is what it was looking for, not a blunder."""
    ext, g = params.extensions, params.gates
    if not (ext.search_correction_cap and ext.covariance_search) or search_m <= g.max_correction_m:
        return CORRECTION_CAP.decide(correction_m, g)
    return CORRECTION_CAP.decide(
        correction_m,
        replace(g, max_correction_m=search_m),
        note="|z - p_dr|, m (cap: the along-track search's half-width)",
    )


def unpaired_table(window_points: int, params: Params) -> tuple[GateDecision, ...]:
    """The gate of an attempt that could not be fitted."""
    return (UNPAIRED.decide(0 if window_points < 2 else 1, params.gates),)
