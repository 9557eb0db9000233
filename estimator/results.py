"""What a run returns: immutable per-epoch results and one record per match attempt, kept so the
inspector can draw any instant without re-running the filter."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from estimator.nav.frames import LocalFrame
from estimator.params import Method, Params

F64 = NDArray[np.float64]

Comparison = Literal["<=", ">="]


@dataclass(frozen=True)
class GateDecision:
    """One gate of one match attempt: ``passed`` is ``value <comparison> threshold``."""

    name: str
    value: float
    threshold: float
    comparison: Comparison
    passed: bool
    note: str = ""


@dataclass(frozen=True)
class MatchRecord:
    """One match attempt with every intermediate, accepted or not.

    Arrays are EN metres in the run's local frame. Fields that a failed early gate never
    computed are NaN (scalars) or empty arrays.
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
    matched to the lane line (the route shifted by the lane offset, ``extra["lane_path"] = 1``)"""
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
    """(2, 2) observation covariance R_k"""
    innovation: F64
    """(2,) z - H x before the update"""
    correction: F64
    """(2,) position change the update applied (zeros when rejected)"""
    extra: dict[str, float] = field(default_factory=dict)
    """method-specific scalars (along-track search, alternatives' residuals, ...)"""

    @property
    def failed_gates(self) -> tuple[GateDecision, ...]:
        return tuple(g for g in self.gates if not g.passed)

    @property
    def verdict(self) -> str:
        """'accepted' or 'rejected: <first failed gate>'."""
        if self.accepted:
            return "accepted"
        failed = self.failed_gates
        return f"rejected: {failed[0].name}" if failed else "rejected"


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
    resume: object = field(default=None, repr=False, compare=False)
    """opaque checkpoints that let ``runner.run(..., reuse=this_run)`` restart at the first
    match attempt a parameter change affects; None when the run kept none"""
