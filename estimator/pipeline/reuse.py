"""Re-run reuse (a UI speed feature): a run keeps checkpoints of the filter at every stop, and
the match geometries it computed by their inputs, so a later run on the same log, route and
outages with other matching parameters resumes from the first checkpoint whose outcome
changes instead of from the log start. The attempts before it are only re-judged (the
previous run's geometries are kept by their inputs, and a gate threshold does not change
them), and a baseline after a baseline is the previous run.

None of this is public: it travels in :class:`estimator.results.Run`'s private ``_reuse``."""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from estimator.filter.engine import FilterState
from estimator.filter.layout import A_TIME, I_OUT, O_POS
from estimator.filter.propagation import flush_covariance
from estimator.filter.setup import FilterInputs
from estimator.filter.twin import DeadReckoningTwin
from estimator.log import Log
from estimator.matching.reanchor import blames_the_filter
from estimator.nav.frames import LocalFrame
from estimator.params import Params, matching_params
from estimator.results import Gate, MatchRecord, Run
from estimator.route import Route

if TYPE_CHECKING:
    from estimator.pipeline.driver import Driver

F64 = NDArray[np.float64]
T = TypeVar("T")
Key = tuple[Hashable, ...]


@dataclass(frozen=True)
class Checkpoint:
    """The filter at a stop, before anything the driver does there."""

    kind: Literal["outage", "attempt"]
    """the start of a degraded interval, or a match attempt"""
    interval: int
    k: int
    """attempt counter inside the interval: t = a + min_outage_s + k * interval_s"""
    state: FilterState
    n_records: int
    dist_a: float
    dist_last: float
    twin: DeadReckoningTwin | None = None
    """the outage's dead-reckoning twin as it was then (``extensions.dr_separation``)"""
    bridged: dict[str, float] = field(default_factory=dict)
    """an IMU gap bridged along the route since the previous attempt, for this attempt's record
    (``extensions.gap_route_bridge``)"""
    uncalibrated_m: float | None = None
    """an outage left to dead reckoning (``extensions.calibrated_approach``): the driving with
    GNSS before it, m"""
    cloned: tuple[F64, F64] | None = None
    """an outage's P and aux once the route's errors were cloned into them at its start (what
    the map bias, the lane and the map's rotation learned before it gave)"""

    @property
    def n_out(self) -> int:
        return int(self.state[3][I_OUT])


class Memo:
    """Values computed from arrays (match geometries, long-window turns) by their inputs: this
    run's, and the previous run's when this one reuses it."""

    def __init__(self, known: dict[Key, object] | None = None) -> None:
        self.known: dict[Key, object] = known if known is not None else {}
        self.own: dict[Key, object] = {}

    def get(self, key: Key, arrays: tuple[F64, ...], compute: Callable[[], T]) -> T:
        """``compute()``, or the value this run or the previous one computed for the same key
        and array contents."""
        digest = hashlib.blake2b(digest_size=16)
        for a in arrays:
            a = np.ascontiguousarray(a, np.float64)
            digest.update(repr(a.shape).encode())
            digest.update(a.tobytes())
        full = (*key, digest.digest())
        value = self.known.get(full, self.own.get(full))
        if value is None:
            value = compute()
        self.own[full] = value
        return cast(T, value)


@dataclass(frozen=True)
class ReuseState:
    """What a later run needs to resume from this one."""

    log: Key
    """fingerprint of the log (:func:`log_key`); a Run stays picklable"""
    route: Route | None
    frame: LocalFrame
    outages: tuple[tuple[float, float], ...]
    filter_key: Key
    inputs: FilterInputs
    out: F64
    n_out: int
    checkpoints: tuple[Checkpoint, ...]
    records: tuple[MatchRecord, ...]
    memo: dict[Key, object] = field(default_factory=dict)
    dropped_fixes: tuple[float, ...] = ()


def log_key(log: Log) -> Key:
    """Identifies a log's content cheaply: sizes, spans and sums over a sample of values."""
    imu, g = log.imu, log.gnss
    step = max(1, len(imu.t) // 4096)
    wheel = () if log.wheel is None else (len(log.wheel.t), float(np.nansum(log.wheel.speed)))
    return (
        log.path,
        len(imu.t),
        float(imu.t[0]) if len(imu.t) else 0.0,
        float(imu.t[-1]) if len(imu.t) else 0.0,
        float(np.nansum(imu.gyro[::step])),
        float(np.nansum(imu.accel[::step])),
        len(g.t),
        float(np.nansum(g.lat)),
        float(np.nansum(g.lon)),
        wheel,
    )


def filter_key(p: Params) -> Key:
    """Everything the filter itself (not the matcher) depends on."""
    ext = p.extensions
    return (
        p.noise,
        p.sensors,
        ext.wheel_scale_state,
        ext.gyro_scale_consider,
        ext.gyro_scale_blind_gain,
        ext.gyro_scale_state,
        ext.robust_gnss,
        ext.portal_rerun,
        ext.portal_rerun_after_alignment,
        ext.align_track_accel,
        ext.align_track_accel_ahead,
        ext.cross_track_heading_widen,
        ext.no_wheel_caution,
        ext.exit_adapt,
        p.output_rate_hz,
    )


def reusable_state(
    reuse: Run | None,
    log: Log,
    route: Route | None,
    frame: LocalFrame,
    outages: tuple[tuple[float, float], ...],
    key: Key,
) -> ReuseState | None:
    """``reuse``'s state if it was run on the same log, frame, outages, route and filter."""
    old = reuse._reuse if reuse is not None else None
    if old is None:
        return None
    same = (
        old.log == log_key(log)
        and old.frame == frame
        and old.outages == outages
        and old.filter_key == key
        and (
            route is None
            or old.route is route
            or (old.route is not None and np.array_equal(old.route.xy, route.xy))
        )
    )
    return old if same else None


def same_outcome(new: MatchRecord, old: MatchRecord) -> bool:
    """Whether a re-evaluated attempt leaves the filter exactly as the old one did."""
    if new.accepted != old.accepted:
        return False
    if not new.accepted:
        return True
    return bool(
        np.array_equal(new.pseudo_position, old.pseudo_position)
        and np.array_equal(new.obs_cov, old.obs_cov)
        and new.rotation_rad == old.rotation_rad
        and new.n_pairs == old.n_pairs
        and new.residual_m == old.residual_m
        and new.along_observed == old.along_observed
    )


MATCHING_EXTENSIONS = (
    "heading_observation",
    "lane_offset_state",
    "map_bias",
    "unapplied_bias_consider",
    "unapplied_bias_lane_tie",
    "unapplied_bias_estimate",
    "map_bias_keep_applied",
    "map_bias_carry_turned",
    "map_turn_consider",
    "map_turn_estimate",
    "map_turn_two_places",
    "map_turn_two_places_applied",
    "map_turn_honest_consider",
    "map_turn_release",
    "route_errors_overlap_share",
    "geometry_covariance",
    "weak_along_track",
    "reanchor",
    "gap_reacquire",
    "gap_route_bridge",
    "calibrated_approach",
    "along_drift_evidence",
    "dr_separation",
)
"""The extensions that decide where an outage's attempts fall or what they carry: changed, a
re-run replays from the first outage instead of attempt by attempt."""


def resume(d: Driver, old: ReuseState, old_params: Params, *, reuse_matching: bool) -> None:
    """Replay the old run's checkpoints with ``d``'s matching parameters until one gives a
    different outcome, then run live from there."""
    p = d.p
    old_params = matching_params(old_params, have_wheel=len(d.inp.wheel_t) > 0)
    d.filt.out = old.out
    outage_cps = [c for c in old.checkpoints if c.kind == "outage"]
    same_trigger = (
        p.trigger == old_params.trigger
        and p.window.spacing_m == old_params.window.spacing_m
        and all(
            getattr(p.extensions, name) == getattr(old_params.extensions, name)
            for name in MATCHING_EXTENSIONS
        )
        and p.pseudo.weak_along_disagreement == old_params.pseudo.weak_along_disagreement
        and p.pseudo.weak_along_max_chi2 == old_params.pseudo.weak_along_max_chi2
        and (
            not p.extensions.dr_separation
            or (
                p.gates.dr_separation_chi2,
                p.gates.dr_separation_floor_m,
                p.extensions.dr_separation_gyro_scale,
                p.noise.gyro_scale_sigma_ppm,
            )
            == (
                old_params.gates.dr_separation_chi2,
                old_params.gates.dr_separation_floor_m,
                old_params.extensions.dr_separation_gyro_scale,
                old_params.noise.gyro_scale_sigma_ppm,
            )
        )
        and (
            not (p.extensions.reanchor or p.extensions.gap_reacquire)
            or (p.gates.reanchor_after, p.gates.reanchor_gyro_bias_deg_s)
            == (old_params.gates.reanchor_after, old_params.gates.reanchor_gyro_bias_deg_s)
        )
        and (not p.extensions.map_bias or p.offset == old_params.offset)
        and (
            # the states after a gap bridged along the route hold what it was bridged with
            not (p.extensions.gap_route_bridge and len(d.gap_ends))
            or (p.pseudo, p.window) == (old_params.pseudo, old_params.window)
        )
    )
    if not d.matching and not reuse_matching:
        # baseline after baseline: the filter and its inputs are the same, so is the run
        _copy_old(d, old, len(old.checkpoints), old.n_out)
        d.copied_whole_run = True
        return
    if not d.matching or not reuse_matching or not same_trigger:
        if not outage_cps:
            _copy_old(d, old, len(old.checkpoints), old.n_out)
            return
        first = outage_cps[0]
        _restart(d, old, first, old.checkpoints.index(first), [])
        d.loop(first.interval, None)
        return
    _replay_attempts(d, old)


def _replay_attempts(d: Driver, old: ReuseState) -> None:
    """Re-judge the old attempts in order; at the first changed outcome run live from it."""
    records: list[MatchRecord] = []
    for n_cp, cp in enumerate(old.checkpoints):
        x, P0, aux0, _ = cp.state
        if cp.kind == "outage":
            if cp.uncalibrated_m is None:
                track = dataclasses.replace(d.track)
                a = d.inp.degraded[cp.interval][0]
                d.begin_interval(a, old.out, cp.n_out, x, aux0)
                P, aux = P0.copy(), aux0.copy()
                d.clone_route_errors(x.copy(), P, aux)
                if cp.cloned is not None and not (
                    np.array_equal(P, cp.cloned[0]) and np.array_equal(aux, cp.cloned[1])
                ):
                    # what was learned before the outage changed (the map bias's fit reads
                    # the window and shape parameters too): the outage runs live from its start
                    d.track = track
                    _restart(d, old, cp, n_cp, records)
                    d.loop(cp.interval, None)
                    return
            continue
        P = P0.copy()
        aux = aux0.copy()
        flush_covariance(P, aux, d.inp.cfg)
        d.records = records
        rec = d.match(old.out, cp.n_out, x, P, aux)
        prev = old.records[cp.n_records]
        # whether a refusal re-anchors depends on the live filter: judged live from there
        may_reanchor = (d.p.extensions.reanchor and blames_the_filter(rec, d.p)) or (
            d.p.extensions.gap_reacquire
            and len(d.gaps_ended(rec.t)) > 0
            and blames_the_filter(rec, d.p, after_gap=True)
        )
        separation = [g for g in prev.gates if g.gate is Gate.DR_SEPARATION]
        # an update the twin's gate undid, or one after it, was judged on the live filter
        if not same_outcome(rec, prev) or may_reanchor or not all(g.passed for g in separation):
            _restart(d, old, cp, n_cp + 1, records)
            d.loop(cp.interval, cp)
            return
        rec = dataclasses.replace(
            rec,
            gates=(*rec.gates, *separation),
            extra={**rec.extra, **cp.bridged},
            epoch=prev.epoch,
            innovation=prev.innovation,
            correction=prev.correction,
            heading_observation=prev.heading_observation,
        )
        records.append(rec)
        x_after = old.out[prev.epoch, O_POS : O_POS + 3]
        d.after_match(rec, x_after, aux)
    _copy_old(d, old, len(old.checkpoints), old.n_out)
    d.records = records


def _copy_old(d: Driver, old: ReuseState, n_checkpoints: int, n_out: int) -> None:
    d.dropped_fixes = list(old.dropped_fixes)
    d.filt.out = old.out
    d.checkpoints = list(old.checkpoints[:n_checkpoints])
    d.records = []
    d.filt.idx = np.zeros_like(d.filt.idx)
    d.filt.idx[I_OUT] = n_out


def _restart(
    d: Driver, old: ReuseState, cp: Checkpoint, n_keep: int, records: list[MatchRecord]
) -> None:
    d.checkpoints = list(old.checkpoints[:n_keep])
    d.records = list(records)
    d.dropped_fixes = [t for t in old.dropped_fixes if t <= cp.state[2][A_TIME]]
    d.filt.set_state(cp.state)
    d.twin = None if cp.twin is None else cp.twin.copy()
    d.filt.out = old.out.copy()
