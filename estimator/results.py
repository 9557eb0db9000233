"""What a run returns: immutable per-epoch results and one record per match attempt, kept so the
inspector can draw any instant without re-running the filter."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from estimator.nav.frames import LocalFrame
from estimator.params import Method, Params

if TYPE_CHECKING:
    from estimator.pipeline.reuse import ReuseState

F64 = NDArray[np.float64]

Comparison = Literal["<=", ">="]


class Rival(Enum):
    """A road the matched window could also belong to: the route shifted sideways by
    ``gates.alternative_shift_m`` (a parallel carriageway) or driven the other way."""

    LEFT = "left"
    RIGHT = "right"
    REVERSED = "reversed"


class Gate(Enum):
    """Every gate a match attempt can hold, in the order the matcher evaluates them."""

    MIN_PAIRS = "min_pairs"
    HEADING = "heading"
    RESIDUAL = "residual"
    ROTATION = "rotation"
    MAHALANOBIS = "mahalanobis"
    LANE_CONTINUITY = "lane_continuity"
    ALTERNATIVE_LEFT = "alternative_left"
    ALTERNATIVE_RIGHT = "alternative_right"
    ALTERNATIVE_REVERSED = "alternative_reversed"
    CORRECTION_CAP = "correction_cap"
    ROTATION_CONSISTENCY = "rotation_consistency"
    """the fitted rotation against the filter's heading covariance
    (``extensions.rotation_consistency``)"""
    DR_SEPARATION = "dr_separation"
    """the filter's, after the update: how far the outage's route updates moved the position
    from dead reckoning (``extensions.dr_separation``)"""

    @property
    def rival(self) -> Rival | None:
        """The rival an ``ALTERNATIVE_*`` gate compares the candidate with (else None)."""
        return _GATE_RIVALS.get(self)

    @property
    def refuses_off_route(self) -> bool:
        """A failure means the road is ambiguous (a rival fits as well) or the vehicle moved
        across the route away from its lane: the attempt is refused as off-route."""
        return self is Gate.LANE_CONTINUITY or self.rival is not None

    @classmethod
    def alternative(cls, rival: Rival) -> Gate:
        return cls("alternative_" + rival.value)


_GATE_RIVALS = {Gate.alternative(r): r for r in Rival}


@dataclass(frozen=True)
class GateDecision:
    """One gate of one match attempt: ``passed`` is ``value <comparison> threshold``.

    An ``ALTERNATIVE_*`` gate's value is the rival's cost minus the candidate's; it is +inf
    (``no_rival``) when the rival fails the shape gates, so there is nothing to confuse the
    candidate with."""

    gate: Gate
    value: float
    threshold: float
    comparison: Comparison
    passed: bool
    note: str = ""

    @property
    def name(self) -> str:
        return self.gate.value

    @property
    def no_rival(self) -> bool:
        return self.gate.rival is not None and self.value == float("inf")


@dataclass(frozen=True)
class FitSummary:
    """What the registration of a window found beyond its pose: along-track observability,
    the route direction at the pseudo-position, and the innovation in route axes."""

    along_offset_m: float
    """along-track shift of the route pairs the search chose, m"""
    along_curvature: float
    """curvature of the mean squared residual over the along-track shift at its minimum"""
    along_sigma_m: float
    """1-sigma of the along-track shift (``pseudo.along_sigma_max_m`` when unobserved)"""
    along_observed: bool
    """route shape observes along-track here; when False, the along-track axis of the
    observation carries no information and is applied as unobserved"""
    cross_sigma_m: float
    lane_path: bool
    """the window was matched to the lane line (the route shifted by the lane offset)"""
    innovation_along_m: float
    innovation_cross_m: float
    normal: F64
    """(2,) unit route normal at the pseudo-position, pointing LEFT of the route direction"""
    heading_sigma_rad: float
    """1-sigma of the fitted rotation read as a heading correction"""

    def diagnostics(self) -> dict[str, float]:
        return {
            "along_offset_m": self.along_offset_m,
            "along_curvature": self.along_curvature,
            "along_sigma_m": self.along_sigma_m,
            "along_observed": float(self.along_observed),
            "cross_sigma_m": self.cross_sigma_m,
            "lane_path": float(self.lane_path),
            "innovation_along_m": self.innovation_along_m,
            "innovation_cross_m": self.innovation_cross_m,
            "normal_e": float(self.normal[0]),
            "normal_n": float(self.normal[1]),
            "heading_sigma_rad": self.heading_sigma_rad,
        }


@dataclass(frozen=True)
class LongWindow:
    """An accepted match that left along-track unobserved, replaced by the match of a longer
    window that observed it (``extensions.long_window``)."""

    turn_deg: float
    """largest turn of the long window over a standard window's length"""
    short_window_length_m: float


MapBiasRefusal = Literal["too large", "lane too far"]
"""Why a map bias the approach measured was taken for another road and not applied: ``"too
large"`` for a map's error all along the road ahead (``offset.map_bias_max_prior_sigmas`` of
its prior), or the lane it implies ``"lane too far"`` from the route (``offset.max_offset_m``)."""


@dataclass(frozen=True)
class MapBiasUse:
    """The map bias an attempt was matched with (``extensions.map_bias``): its pseudo-position
    comes from the route moved back by ``offset``, whose error (covariance ``cov`` at the
    attempt) the filter carries as a state shared by all of the outage's matches."""

    offset: F64
    """(2,) E, N, m: where the route lies relative to the road driven"""
    cov: F64
    """(2, 2) m^2"""
    along_observed: bool
    """the approach's shape fixed the along-track bias"""
    learned: F64 = field(default_factory=lambda: np.full(2, np.nan))
    """(2,) E, N, m: the bias the approach measured before the test against zero (``offset``
    is zero plus the outage's corrections when the test found it insignificant)"""
    chi2: float = float("nan")
    """``learned`` against zero with its covariance (2 dof; applied above
    ``offset.map_bias_min_sigmas`` squared)"""
    rotation_rad: float = 0.0
    """the route is drawn turned by this about where the bias was learned (0 unless
    significant)"""
    rotation_sigma_rad: float = 0.0
    applied: bool = False
    """the bias was applied (the route moved back by it); else the route was taken as right"""
    refused: MapBiasRefusal | None = None
    """why it was not applied when that was not its significance: taken for another road, the
    matcher's gates judging the route as it is (None when applied or not significant)"""
    pivot: F64 = field(default_factory=lambda: np.full(2, np.nan))
    """(2,) E, N, m: where the bias was learned (the approach's end), which ``offset`` is at
    and ``rotation_rad`` turns about"""

    def at(self, xy: F64) -> F64:
        """The bias at points ``xy`` ((2,) or (N, 2)): ``offset`` turned by ``rotation_rad``
        about ``pivot``. A map drawn turned about a point far into a long tunnel is off by
        tens of metres more at the vehicle than at the portal, or by nothing."""
        p = np.asarray(xy, np.float64)
        if self.rotation_rad == 0.0 or not np.all(np.isfinite(self.pivot)):
            return np.broadcast_to(self.offset, p.shape).astype(np.float64)
        d = p - self.pivot
        turned = np.stack([-d[..., 1], d[..., 0]], axis=-1)
        out: F64 = self.offset + self.rotation_rad * turned
        return out


@dataclass(frozen=True)
class HeadingObservation:
    """The yaw observation an accepted match's fitted rotation was applied as
    (``extensions.heading_observation``)."""

    yaw_rad: float
    """innovation: the fitted rotation"""
    sigma_rad: float
    correction_rad: float
    """yaw change the update applied"""


@dataclass(frozen=True)
class MatchRecord:
    """One match attempt with every intermediate, accepted or not.

    Arrays are EN metres in the run's local frame. Fields that a failed early gate never
    computed are NaN (scalars), empty arrays or None.
    """

    index: int
    t: float
    epoch: int
    """index into :class:`Epochs` of the epoch at (or just before) ``t``"""
    accepted: bool
    gates: tuple[GateDecision, ...]
    window_dr: F64
    """(N, 2) DR window resampled at the spatial interval: s_i"""
    route_points: F64
    """(N, 2) route points paired with ``window_dr``: t_i (same index = a pair)"""
    route_segment: F64
    """(K, 2) the local route polyline (with its vertices) the window was matched to"""
    route_s: tuple[float, float]
    """arc-length interval of the local route segment, m"""
    n_pairs: int
    rotation_rad: float
    translation: F64
    """(2,) t of the fit R s_i + t ~ route_points; R p_dr + t is p_ref, or z when the window was
    matched to the lane line (``fit.lane_path``)"""
    residual_m: float
    """RMS of |R s_i + t - t_i|"""
    heading_cos: float
    p_dr: F64
    """(2,) DR position at t before the update"""
    p_ref: F64
    """(2,) route-referenced position R p_dr + t"""
    lane_offset_m: float
    """learned lateral offset added (positive = vehicle left of the route)"""
    pseudo_position: F64
    """(2,) z = p_ref + offset"""
    obs_cov: F64
    """(2, 2) observation covariance R_k (of an accepted attempt, as applied: widened along the
    road by ``extensions.overlap_inflation`` after the gates)"""
    innovation: F64
    """(2,) z - H x before the update"""
    correction: F64
    """(2,) position change the update applied (zeros when rejected)"""
    anchor_s: float = float("nan")
    """route arc length where the window's first point projects, m"""
    window_length_m: float = float("nan")
    """arc length of the resampled DR window, m"""
    fit: FitSummary | None = None
    """None when the window could not be registered (too short, off the route)"""
    long_window: LongWindow | None = None
    heading_observation: HeadingObservation | None = None
    map_bias: MapBiasUse | None = None
    reanchored: bool = False
    """accepted although gates failed: the last of a run of consistent, shape-valid matches the
    filter kept refusing because its covariance did not cover its own drift
    (``extensions.reanchor``); the filter's covariance was widened to the innovation first"""
    extra: dict[str, float] = field(default_factory=dict)
    """free-form scalars for display (candidate validation's chi-square and costs, ...)"""
    filter_cov: F64 = field(default_factory=lambda: np.full((2, 2), np.nan))
    """(2, 2) m^2: the filter's E-N covariance of the position relative to the route at the
    attempt, before the update: H P H^T with H = [I, I] over the position and map-bias error
    states (the position's own E-N block where the run carries no map bias). It is what the
    Mahalanobis gate adds to ``obs_cov``, S = filter_cov + R_k, so a refusal can be told apart
    as an overconfident filter or an overconfident fit; the :class:`Epochs` row at ``epoch`` is
    written after the update (the posterior where accepted). A re-anchored attempt's filter was
    widened after this, before its update. NaN where nothing filled it in (records built
    outside the pipeline)"""

    @property
    def failed_gates(self) -> tuple[GateDecision, ...]:
        return tuple(g for g in self.gates if not g.passed)

    @property
    def verdict(self) -> str:
        """'accepted', 'accepted: re-anchored' or 'rejected: <first failed gate>'."""
        if self.accepted:
            return "accepted: re-anchored" if self.reanchored else "accepted"
        failed = self.failed_gates
        return f"rejected: {failed[0].name}" if failed else "rejected"

    @property
    def along_observed(self) -> bool:
        """The fit observed along-track (False without a fit)."""
        return self.fit is not None and self.fit.along_observed

    @property
    def normal(self) -> F64:
        """(2,) unit route normal at the pseudo-position (NaN without a fit)."""
        return np.full(2, np.nan) if self.fit is None else self.fit.normal

    @property
    def tangent(self) -> F64:
        """(2,) unit route direction at the pseudo-position, the normal turned right (NaN
        without a fit)."""
        n = self.normal
        return np.array([n[1], -n[0]])

    def route_sigmas(self, cov: F64) -> F64:
        """(2,) 1-sigma along and across the route (:attr:`tangent`, :attr:`normal`) of an E-N
        covariance such as ``obs_cov`` or ``filter_cov``, m (NaN without a fit): the axes the
        fit observes differently, where E and N mix them wherever the road runs diagonally."""
        c = np.asarray(cov, np.float64)
        axes = np.stack([self.tangent, self.normal])
        sigmas: F64 = np.sqrt(np.einsum("ai,ij,aj->a", axes, c, axes))
        return sigmas

    def diagnostics(self) -> dict[str, float]:
        """Every scalar of the attempt beyond the fixed fields, by name, in a stable order
        (the export's ``extra_*`` columns, the match panel's rows); unknown (NaN) anchor and
        window length are left out, as is the filter's sigma where no fit gives it axes or
        nothing filled in ``filter_cov``."""
        out = {
            k: v
            for k, v in (("anchor_s", self.anchor_s), ("window_length_m", self.window_length_m))
            if not np.isnan(v)
        }
        if self.fit is not None:
            out.update(self.fit.diagnostics())
            if np.all(np.isfinite(self.filter_cov)):
                along, cross = self.route_sigmas(self.filter_cov)
                out["filter_along_sigma_m"] = float(along)
                out["filter_cross_sigma_m"] = float(cross)
        out.update(self.extra)
        if self.long_window is not None:
            out["long_window"] = 1.0
            out["long_window_turn_deg"] = self.long_window.turn_deg
            out["short_window_length_m"] = self.long_window.short_window_length_m
        if self.heading_observation is not None:
            out["heading_obs_rad"] = self.heading_observation.yaw_rad
            out["heading_obs_sigma_rad"] = self.heading_observation.sigma_rad
            out["heading_correction_rad"] = self.heading_observation.correction_rad
        if self.map_bias is not None and self.fit is not None:
            here = self.map_bias.offset
            if np.all(np.isfinite(self.p_ref)):
                here = self.map_bias.at(self.p_ref)
            along_sigma, cross_sigma = self.route_sigmas(self.map_bias.cov)
            out["map_bias_along_m"] = float(self.tangent @ here)
            out["map_bias_along_sigma_m"] = float(along_sigma)
            out["map_bias_cross_m"] = float(self.normal @ here)
            out["map_bias_cross_sigma_m"] = float(cross_sigma)
            if np.isfinite(self.map_bias.chi2):
                out["map_bias_chi2"] = self.map_bias.chi2
            if self.map_bias.rotation_rad != 0.0:
                out["map_bias_rotation_deg"] = float(np.degrees(self.map_bias.rotation_rad))
                out["map_bias_rotation_sigma_deg"] = float(
                    np.degrees(self.map_bias.rotation_sigma_rad)
                )
        return out


@dataclass(frozen=True)
class Epochs:
    """Filter output at ``output_rate_hz`` (and at every match attempt)."""

    t: F64
    position: F64
    """(N, 3) ENU m"""
    velocity: F64
    """(N, 3) ENU m/s"""
    attitude: F64
    """(N, 3) roll, pitch, yaw (ENU yaw, counter-clockwise from East), rad"""
    position_sigma: F64
    """(N, 3) 1-sigma E, N, U, m"""
    position_cov_en: F64
    """(N,) covariance of the E and N errors, m^2. With ``position_sigma`` it is the horizontal
    ellipse, long along the road in an outage: the sigmas alone cannot draw it where the road
    runs diagonally"""
    yaw_sigma: F64
    """(N,) rad"""
    gnss_used: NDArray[np.bool_]
    """(N,) a GNSS fix was accepted since the previous epoch"""
    degraded: NDArray[np.bool_]
    """(N,) inside a GNSS-degraded interval (no valid fix, or an injected outage)"""

    def __len__(self) -> int:
        return len(self.t)

    def index_at(self, t: float) -> int:
        """Index of the last epoch at or before ``t`` (clamped)."""
        return int(np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 1))


@dataclass(frozen=True)
class OutageExit:
    """How far a GNSS outage's estimate ended from the fixes that came back after it: the one
    check of an outage a log without ground truth still allows, and the one that catches an
    estimate that was wrong while it claimed to be right (route updates following a wrong map,
    dead reckoning beyond its noise model). Built by
    :func:`estimator.evaluation.exits.outage_exits`."""

    start: float
    end: float
    """the outage (absolute time, as ``Run.degraded_intervals``)"""
    fix_t: tuple[float, float]
    """first and last fix compared (absolute time)"""
    n_fixes: int
    error: F64
    """(2,) E, N m: the estimate carried on from the outage's end by its own velocity, minus
    the fixes (their median)"""
    estimate_at: F64
    """(2,) E, N m: where the estimate, carried on from the outage's end by its own velocity,
    had the antenna at the first fix compared, and ``estimate_at - error`` where the fixes put
    it. It is on the run's track there unless something besides fixes moved the track after
    the outage (the non-holonomic constraint in a turn, telling a velocity error)"""
    estimate_cov: F64
    """(2, 2) m^2: the E-N covariance the estimate claimed at the outage's end"""
    fix_cov: F64
    """(2, 2) m^2: the fixes' (the median of their variances, the wander included)"""

    @property
    def distance_m(self) -> float:
        return float(np.hypot(*self.error))

    @property
    def chi2(self) -> float:
        """e' (P + R)^-1 e, 2 degrees of freedom: 13.8 or more once in a thousand outages whose
        estimate and fixes are as good as they claim."""
        s = self.estimate_cov + self.fix_cov
        return float(self.error @ np.linalg.solve(s, self.error))

    @property
    def estimate_sigma_m(self) -> float:
        """the estimate's claimed 1-sigma in the direction of the error (its whole horizontal
        sigma, sqrt(trace P), when the error is zero)"""
        d = self.distance_m
        if d == 0.0:
            return float(np.sqrt(np.trace(self.estimate_cov)))
        u = self.error / d
        return float(np.sqrt(u @ self.estimate_cov @ u))

    @property
    def overconfident(self) -> bool:
        """the estimate ended farther from the fixes than it and they claim, at 99.9 %"""
        return self.chi2 > EXIT_CHI2_2DOF


EXIT_CHI2_2DOF = 13.816
"""chi-square of 2 degrees of freedom at 99.9 %: an outage's exit error beyond it is not a
draw of honest errors (one outage in a thousand)"""


@dataclass(frozen=True)
class Run:
    """One estimator run over one log."""

    method: Method
    params: Params
    frame: LocalFrame
    epochs: Epochs
    matches: tuple[MatchRecord, ...]
    degraded_intervals: tuple[tuple[float, float], ...]
    """absolute times (same clock as ``epochs.t``)"""
    t0: float
    """log start, s (so times can be shown relative to it)"""
    warnings: tuple[str, ...] = ()
    dropped_fix_times: tuple[float, ...] = ()
    """fixes the fixed-lag re-run at the start of an outage left out (they disagreed with
    dead reckoning; ``extensions.portal_rerun``)"""
    exits: tuple[OutageExit, ...] = ()
    """one per degraded interval after which the filter took fixes again"""
    _reuse: ReuseState | None = field(default=None, repr=False, compare=False)
    """private to :mod:`estimator.pipeline`: the checkpoints that let ``run(..., reuse=this_run)``
    restart at the first match attempt a parameter change affects (None: the run kept none)"""
