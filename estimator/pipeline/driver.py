"""Drive the EKF over a log and, in GNSS-degraded intervals, the route matcher.

The compiled loop runs from one stop time to the next; the driver steps in only at the start of
each degraded interval and at each match attempt, where it saves a checkpoint (for re-run
reuse, :mod:`estimator.pipeline.reuse`), builds the DR window, matches it
(:func:`estimator.matching.match_geometry`, then
:func:`~estimator.matching.judge_match`) and, if the match is accepted, applies the route
update (:mod:`estimator.filter.route_update`).

When GNSS returns after pseudo-position updates, the first fix widens the E/N position variance
just enough to cover its own innovation (:func:`estimator.filter.gnss.widen_position`) before it
is tested: the route observations are correlated with each other and with the DR drift, so the
filter's position covariance after them is optimistic, and without the widening the chi-square
gate would reject the returning fixes for seconds and then let one through as a late, large
jump. Attitude, velocity and biases keep their covariances, so the returning fix corrects them
through the cross-covariances exactly as in normal fusion.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError, RoutefuseError, named_and_summed
from estimator.evaluation.exits import exit_warnings, outage_exits
from estimator.evaluation.metrics import NEES_95_2DOF, interval_mask
from estimator.filter.alignment import MG
from estimator.filter.engine import Filter, epochs_of, row_position_cov
from estimator.filter.gnss import widen_heading
from estimator.filter.kernel import GAP_VEL_VAR, IMU_GAP_S, finite_state, wheel_distance
from estimator.filter.layout import (
    A_DIST,
    A_DR,
    A_EXIT_WALK,
    A_INFLATE,
    A_POS_WALK,
    A_ROT,
    A_ROT_EST,
    A_ROT_SHIFT,
    A_ROUTE,
    A_TIME,
    A_USED_DIST,
    A_WALK_FROM,
    E_ATT,
    E_BA,
    E_GSF,
    E_MAP,
    E_POS,
    E_ROT,
    E_SCALE,
    E_VEL,
    I_IMU,
    O_DIST,
    O_DR,
    O_GNSS,
    O_POS,
    O_SIG_POS,
    O_T,
    O_VEL,
    X_BA,
    X_POS,
    X_QUAT,
    X_VEL,
)
from estimator.filter.portal import advance_to_outage
from estimator.filter.propagation import flush_covariance
from estimator.filter.route_update import applied_obs_cov, apply_route_match, turn_about_up
from estimator.filter.setup import (
    FilterInputs,
    fix_wander_var,
    prepare_inputs,
    route_errors_estimated,
)
from estimator.filter.twin import DeadReckoningTwin, Undone
from estimator.filter.updates import (
    clone_lane_offset,
    clone_map_turn,
    clone_route_errors,
    grow_map_bias,
    heading_update,
    pseudo_position_update,
    turn_map_bias,
)
from estimator.io.plausibility import GRAVITY, configured_clock_warnings
from estimator.log import Log
from estimator.matching import (
    MatchGeometry,
    geometry_params,
    judge_match,
    learn_lane_offset,
    match_geometry,
    route_arc_length,
)
from estimator.matching.gates import DR_SEPARATION, ROTATION_CONSISTENCY, undone_gate
from estimator.matching.kernels import max_turn_deg, search_right, track_window
from estimator.matching.map_bias import (
    MapBias,
    carried_bias,
    carried_explains,
    learn_map_bias,
    prior_bias,
    refined_bias,
    turned_back,
    unbiased,
    xy_moved_back,
)
from estimator.matching.reanchor import gap_bound_m, should_reanchor, within_drift
from estimator.nav.frames import LocalFrame
from estimator.nav.rotation import yaw_from_quaternion
from estimator.params import Method, Params, for_method, get_param, matching_params
from estimator.pipeline.inputs import frame_of
from estimator.pipeline.reuse import (
    Checkpoint,
    Memo,
    ReuseState,
    filter_key,
    log_key,
    resume,
    reusable_state,
)
from estimator.results import (
    Epochs,
    Gate,
    LongWindow,
    MapBiasUse,
    MatchRecord,
    OutageExit,
    Run,
)
from estimator.route import Route

F64 = NDArray[np.float64]
ProgressFn = Callable[[float], None]


def run(
    log: Log,
    route: Route | None,
    params: Params,
    *,
    method: Method = "proposed",
    frame: LocalFrame | None = None,
    outages: Sequence[tuple[float, float]] = (),
    progress: ProgressFn | None = None,
    reuse: Run | None = None,
) -> Run:
    """Run one method over a log.

    ``outages``: (start, end) seconds after the log start where GNSS is removed. ``frame``: the
    session's local frame (default: at the log's first valid fix). ``progress``: called with the
    fraction done. ``reuse``: a previous run on the same log, route and outages; if only matching
    parameters differ, the filter resumes from the first match attempt whose outcome changes.
    """
    p = for_method(params, method)
    matching = method != "baseline"
    if matching and route is None:
        raise RoutefuseError(None, f"method {method!r} needs a route")
    outages_t = tuple((float(a), float(b)) for a, b in outages)
    for a, b in outages_t:
        if not (math.isfinite(a) and math.isfinite(b)) or b <= a:
            raise RoutefuseError(None, f"outage {a:g}:{b:g}: END must be after START")
    if frame is None:
        frame = _frame_of(log)
    key = filter_key(p)
    old = reusable_state(reuse, log, route, frame, outages_t, key)
    inputs = old.inputs if old is not None else prepare_inputs(log, p, frame, outages_t)
    memo = Memo(None if old is None else old.memo)
    driver = Driver(log, route, p, matching, inputs, progress, memo)
    if old is not None and reuse is not None:
        resume(driver, old, reuse.params, reuse_matching=reuse.method != "baseline")
    else:
        driver.start()
    # a baseline after a baseline is the previous run: share its (immutable) epochs, so what
    # was computed from them can be recognised (metrics.deviation_series)
    epochs = reuse.epochs if driver.copied_whole_run and reuse is not None else driver.epochs()
    if progress is not None:
        progress(1.0)
    state = ReuseState(
        log=log_key(log),
        route=route,
        frame=frame,
        outages=outages_t,
        filter_key=key,
        inputs=inputs,
        out=driver.filt.out,
        n_out=driver.filt.n_out,
        checkpoints=tuple(driver.checkpoints),
        records=tuple(driver.records),
        memo=driver.memo.own,
        dropped_fixes=tuple(driver.dropped_fixes),
    )
    exits = run_exits(epochs, inputs.degraded, inputs, p)
    routed = [driver.route_updated(x.start, x.end) for x in exits]
    return Run(
        method=method,
        params=p,
        frame=frame,
        epochs=epochs,
        matches=tuple(driver.records),
        degraded_intervals=inputs.degraded,
        t0=log.t_start,
        dropped_fix_times=tuple(driver.dropped_fixes),
        exits=exits,
        warnings=configured_clock_warnings(
            log, {o.setting: float(get_param(p, o.setting)) for o in log.clock_offsets}
        )
        + inputs.warnings
        + (route.warnings if route is not None else ())
        + gnss_acceptance_warnings(log, epochs, inputs.degraded)
        + separation_warnings(driver.records, log.t_start, p)
        + refused_outage_warnings(method, driver.records, inputs.degraded, log.t_start)
        + reacquire_warnings(driver.records, log.t_start)
        + gap_bridge_warnings(driver.records, log.t_start)
        + approach_warnings(driver.checkpoints, driver.inp.degraded, log.t_start, p)
        + accel_bias_warnings(driver.checkpoints, driver.inp.degraded, log.t_start, p)
        + unplaced_along_warnings(epochs, driver.records, inputs.degraded, log.t_start)
        + (
            far_route_warnings(epochs, route, driver.records, inputs.degraded, log.t_start, p)
            if matching and route is not None
            else ()
        )
        + exit_warnings(method, exits, routed, log.t_start),
        _reuse=state,
    )


def run_exits(
    epochs: Epochs, degraded: Sequence[tuple[float, float]], inputs: FilterInputs, p: Params
) -> tuple[OutageExit, ...]:
    """The exit check of ``degraded``'s outages (absolute times) against the run's fixes."""
    return outage_exits(
        epochs,
        degraded,
        inputs.gnss_t,
        inputs.gnss_pos,
        inputs.gnss_var + fix_wander_var(inputs.cfg),
        p.sensors.gnss_lever_arm_m,
    )


MIN_GNSS_ACCEPTANCE = 0.5


def gnss_acceptance_warnings(
    log: Log, epochs: Epochs, degraded: Sequence[tuple[float, float]]
) -> tuple[str, ...]:
    """A filter that uses few of the fixes it is given outside the outages disagrees with its
    own GNSS: fix variances that lie, a wrong lever arm or IMU mounting, clocks apart, a bad
    start. Counted per output row (a fix used since the previous row), against the rows or the
    valid fixes there, whichever is fewer."""
    g = log.gnss
    outside = ~interval_mask(g.t, degraded) & (g.t >= epochs.t[0]) & (g.t <= epochs.t[-1])
    fixes = int(np.count_nonzero(g.valid & outside))
    rows = ~interval_mask(epochs.t, degraded)
    expected = min(fixes, int(np.count_nonzero(rows)))
    if expected < 20:
        return ()
    used = int(np.count_nonzero(epochs.gnss_used & rows))
    if used >= MIN_GNSS_ACCEPTANCE * expected:
        return ()
    return (
        f"GNSS: the filter used only {100 * used / expected:.0f} % of the fixes outside the "
        f"outages ({fixes} valid): the fixes disagree with the IMU and the wheel speed (fix "
        "variances that lie, a wrong lever arm or IMU mounting, IMU and GNSS clocks apart, or a "
        "bad start)",
    )


def separation_warnings(
    records: Sequence[MatchRecord], t_start: float, p: Params
) -> tuple[str, ...]:
    """One line per outage whose route updates were undone for moving the position too far
    from dead reckoning (``extensions.dr_separation``)."""
    lines = []
    for r in records:
        if "dr_separation_m" not in r.extra:
            continue
        chi2 = next(g.value for g in r.gates if g.gate is Gate.DR_SEPARATION)
        lines.append(
            f"route updates undone at {r.t - t_start:.1f} s: they had moved the position "
            f"{r.extra['dr_separation_m']:.1f} m from dead reckoning (chi-square {chi2:.1f} > "
            f"{p.gates.dr_separation_chi2:g} against what they added to it); the rest of the "
            "outage is dead-reckoned: the route there is off the road, or the filter trusted it "
            "too much"
        )
    return tuple(lines)


REFUSED_OUTAGE_MIN_ATTEMPTS = 5
"""an outage with this many match attempts, every one refused, is named in a warning"""


def refused_outage_warnings(
    method: str,
    records: Sequence[MatchRecord],
    degraded: Sequence[tuple[float, float]],
    t_start: float,
) -> tuple[str, ...]:
    """One line per outage whose match attempts were all refused: the method ran as dead
    reckoning there, which its figures alone would not tell apart from a route that helped
    nothing. The gates that refused them say why: a route drawn against the travel
    (heading), another road (lane continuity, rivals), a route far from the vehicle."""
    lines = []
    for a, b in degraded:
        tried = [r for r in records if a <= r.t <= b]
        if len(tried) < REFUSED_OUTAGE_MIN_ATTEMPTS or any(r.accepted for r in tried):
            continue
        gates = Counter(r.failed_gates[0].name if r.failed_gates else "other" for r in tried)
        lines.append(
            f"{method} run: all {len(tried)} match attempts in the outage at "
            f"{a - t_start:.1f}-{b - t_start:.1f} s were refused "
            f"({', '.join(f'{g} {n}' for g, n in gates.most_common())}): it was dead-reckoned "
            "there; check that the route is the road driven, drawn the way it was driven"
        )
    named, summed = named_and_summed(lines)
    if summed:
        more = f"... and {len(summed)} more outages whose match attempts were all refused"
        return (*named, f"{method} run: {more}")
    return tuple(named)


def reacquire_warnings(records: Sequence[MatchRecord], t_start: float) -> tuple[str, ...]:
    """One line per IMU gap whose heading the route re-acquired (``extensions.gap_reacquire``),
    at its first re-anchor."""
    by_gap: dict[float, list[MatchRecord]] = {}
    for r in records:
        if "gap_end_s" in r.extra:
            by_gap.setdefault(r.extra["gap_end_s"], []).append(r)
    lines = []
    for end, (first, *more) in by_gap.items():
        again = f" ({len(more)} more re-anchors after it)" if more else ""
        lines.append(
            f"heading re-acquired from the route at {first.t - t_start:.1f} s, after the IMU gap "
            f"that ended at {end:.1f} s: the windows after it fitted the route turned by "
            f"{math.degrees(first.rotation_rad):+.1f} deg, a turn of the road inside the gap "
            f"that the wheels could not see; heading and position re-anchored there{again}"
        )
    return tuple(lines)


def gap_bridge_warnings(records: Sequence[MatchRecord], t_start: float) -> tuple[str, ...]:
    """One line per IMU gap bridged along the route (``extensions.gap_route_bridge``); beyond
    :data:`~estimator.errors.WARNING_LINES_NAMED` of them the rest are summed up in one line,
    as the gaps' own lines are."""
    named, rest = named_and_summed([r.extra for r in records if "gap_bridge_end_s" in r.extra])
    lines = [
        f"IMU gap that ended at {e['gap_bridge_end_s']:.1f} s bridged along the route there: "
        f"the wheels' {e['gap_bridge_along_m']:.0f} m along the road moved the position "
        f"{e['gap_bridge_moved_m']:.1f} m from the straight line the gap left it on and "
        f"turned its heading {e['gap_bridge_turn_deg']:+.1f} deg to the road's"
        for e in named
    ]
    if rest:
        lines.append(
            f"... and {len(rest)} more IMU gaps bridged along the route, ending between "
            f"{rest[0]['gap_bridge_end_s']:.1f} and {rest[-1]['gap_bridge_end_s']:.1f} s (the "
            f"position moved {max(e['gap_bridge_moved_m'] for e in rest):.1f} m at most, the "
            f"heading turned {max(abs(e['gap_bridge_turn_deg']) for e in rest):.1f} deg at most)"
        )
    return tuple(lines)


def approach_warnings(
    checkpoints: Sequence[Checkpoint],
    degraded: Sequence[tuple[float, float]],
    t_start: float,
    p: Params,
) -> tuple[str, ...]:
    """One line per outage left to dead reckoning for too short a GNSS-aided approach
    (``extensions.calibrated_approach``)."""
    lines = []
    for c in checkpoints:
        if c.kind != "outage" or c.uncalibrated_m is None:
            continue
        a, b = degraded[c.interval]
        lines.append(
            f"no route updates in the outage {a - t_start:.1f}-{b - t_start:.1f} s: only "
            f"{c.uncalibrated_m:.0f} m of driving with GNSS before it (< "
            f"trigger.min_approach_m {p.trigger.min_approach_m:g} m without wheel speed), too "
            "little to calibrate the heading and the accelerometer for them; the outage is "
            "dead-reckoned"
        )
    return tuple(lines)


ACCEL_BIAS_PRIOR_SIGMAS = 4.0
"""an accelerometer bias estimated beyond this many of its prior's sigmas
(``noise.accel_bias_init_sigma_mg``) is named: a MEMS unit's turn-on bias is within its
datasheet's figure, and several times it is most often gravity seen through an IMU mounted
tilted, which the non-holonomic constraint holds level and the bias state absorbs"""


def accel_bias_warnings(
    checkpoints: Sequence[Checkpoint],
    degraded: Sequence[tuple[float, float]],
    t_start: float,
    p: Params,
) -> tuple[str, ...]:
    """One line for the first outage whose start finds the accelerometer's forward or lateral
    bias estimated beyond :data:`ACCEL_BIAS_PRIOR_SIGMAS` of its prior (and beyond three of
    its own sigma). On comma2k19's real IMU, mounted 3.8 deg nose-down and run without that
    mount, the forward bias comes out at -64 mg against a 10 mg prior (the mount's gravity is
    66 mg), and the outage's error reaches 78 m while the filter claims a fraction of it:
    without this line that run is confident and wrong in silence. The tilt named is the one
    whose gravity is the bias (``asin(b / g)``). The line also names
    ``noise.nhc_mount_sigma_deg``: where the mount is not known, giving it a sigma is what
    makes such a run honest (2 deg there: 14.6 m RMS against 33.4 m, NEES 1.3 against 17;
    docs/integrity.md, "An IMU mounted tilted" and "Levelled through the car's
    acceleration"). The inspector shows 300 characters of a warning; at the default prior this
    line stays within them for any bias up to 1 g and outages before 100 000 s."""
    prior = p.noise.accel_bias_init_sigma_mg * MG
    for c in checkpoints:
        if c.kind != "outage":
            continue
        x, P = c.state[0], c.state[1]
        for axis, name, tilt, minus, plus in (
            (0, "forward", "sensors.imu_pitch_deg", "nose-down", "nose-up"),
            (1, "lateral", "sensors.imu_roll_deg", "rolled left", "rolled right"),
        ):
            b = float(x[X_BA + axis])
            sigma = math.sqrt(max(float(P[E_BA + axis, E_BA + axis]), 0.0))
            if abs(b) <= ACCEL_BIAS_PRIOR_SIGMAS * prior or abs(b) <= 3.0 * sigma:
                continue
            a, _ = degraded[c.interval]
            deg = math.degrees(math.asin(min(abs(b) / GRAVITY, 1.0)))
            return (
                f"the accelerometer's {name} bias is estimated at {b / MG:+.0f} mg, "
                f"{abs(b) / prior:.0f} times its {p.noise.accel_bias_init_sigma_mg:g} mg prior "
                f"sigma, at the outage at {a - t_start:.1f} s: gravity through an IMU mounted "
                f"{deg:.1f} deg {minus if b < 0 else plus}? The outages drift with it; give the "
                f"mount ({tilt}) or, if unknown, a sigma for it (noise.nhc_mount_sigma_deg)",
            )
    return ()


def far_route_warnings(
    epochs: Epochs,
    route: Route,
    records: Sequence[MatchRecord],
    degraded: Sequence[tuple[float, float]],
    t_start: float,
    p: Params,
) -> tuple[str, ...]:
    """One line when the route is farther from the vehicle at the start of an outage (its last
    GNSS-aided position) than a route update may move it (``gates.max_correction_m``): no match
    can be accepted there, and the outage is dead-reckoned. A route within the few kilometres
    :func:`~estimator.pipeline.inputs.open_inputs` lets through may still be the wrong one,
    or drawn elsewhere; without this line the run would read as a right route that matched
    nothing. Where the outage's matches moved the route back by a map bias the approach
    learned (``extensions.map_bias``), the distance is to the route so moved: that is the one
    they are made against, and a map drawn a hundred metres off but learned is not a wrong
    route."""
    cap = p.gates.max_correction_m
    far: list[tuple[float, float]] = []
    for a, b in degraded:
        k = min(max(int(np.searchsorted(epochs.t, a, side="right")) - 1, 0), len(epochs.t) - 1)
        here = epochs.position[k, :2]
        bias = next(
            (
                r.map_bias
                for r in records
                if a <= r.t <= b and r.map_bias is not None and r.map_bias.applied
            ),
            None,
        )
        on_map = here + bias.at(here) if bias is not None else here
        d = float(route.project(on_map[None, :]).distance[0])
        if d > cap:
            far.append((a, d))
    if not far:
        return ()
    (a, d), rest = far[0], far[1:]
    more = f" (and of {len(rest)} more, up to {max(x for _, x in rest):.0f} m)" if rest else ""
    return (
        f"the route is {d:.0f} m from the vehicle at the start of the outage at "
        f"{a - t_start:.1f} s{more}, farther than a route update may move it "
        f"(gates.max_correction_m {cap:g} m): no match can be accepted, the outage is "
        "dead-reckoned. The wrong route for this drive?",
    )


UNPLACED_SIGMA_M = 20.0
"""the position's horizontal 1-sigma above which a route-held outage is reported: several
car lengths, more than the spacing of the junctions and exits a user reads a trace against"""


def unplaced_along_warnings(
    epochs: Epochs,
    records: Sequence[MatchRecord],
    degraded: Sequence[tuple[float, float]],
    t_start: float,
) -> tuple[str, ...]:
    """One line per outage whose position the filter itself did not know to
    ``UNPLACED_SIGMA_M`` while it accepted route updates. The updates hold the position across
    the road, so the trace sits on the route and every attempt reads "accepted"; but where the
    road runs straight they cannot tell where along it the vehicle is, and there the run is
    dead reckoning's (without wheel speed its along-track error grows with the square of the
    time). The route-relative deviation cannot show this; the filter's own sigma does. The
    rows from the end of an IMU gap to its bridge along the route
    (``extensions.gap_route_bridge``) are left out: the gap's sigma there is the gap's, which
    its own line names, and the bridge placed the vehicle along the road."""
    sigma = np.hypot(epochs.position_sigma[:, 0], epochs.position_sigma[:, 1])
    bridging = np.zeros(len(epochs.t), bool)
    for r in records:
        if "gap_bridge_end_s" in r.extra:
            bridging |= (epochs.t >= t_start + r.extra["gap_bridge_end_s"]) & (epochs.t < r.t)
    lines = []
    for a, b in degraded:
        accepted = sum(1 for r in records if r.accepted and a <= r.t <= b)
        inside = np.flatnonzero((epochs.t >= a) & (epochs.t <= b) & ~bridging)
        over = inside[sigma[inside] > UNPLACED_SIGMA_M]
        if accepted == 0 or len(over) == 0:
            continue
        peak = over[np.argmax(sigma[over])]
        lasting = float(np.diff(epochs.t[inside])[sigma[inside[1:]] > UNPLACED_SIGMA_M].sum())
        lines.append(
            f"outage {a - t_start:.1f}-{b - t_start:.1f} s: {accepted} route updates "
            f"accepted, yet the position's 1-sigma passed {UNPLACED_SIGMA_M:g} m at "
            f"{epochs.t[over[0]] - t_start:.1f} s and reached {sigma[peak]:.0f} m at "
            f"{epochs.t[peak] - t_start:.1f} s ({lasting:.0f} s over {UNPLACED_SIGMA_M:g} m): "
            "the route holds it across the road; on a straight road only dead reckoning places "
            "it along, so the trace sits on the route unknown along it"
        )
    return tuple(lines)


def aided_approach_m(rows: F64, t_a: float, degraded: Sequence[tuple[float, float]]) -> float:
    """The distance the filter has travelled with GNSS offered (outside ``degraded``) up to
    ``t_a``: how long a GNSS-aided approach an outage starting there had."""
    r = rows[rows[:, O_T] <= t_a]
    if len(r) < 2:
        return 0.0
    offered = ~interval_mask(r[1:, O_T], degraded)
    return float(np.diff(r[:, O_DIST])[offered].sum())


def _frame_of(log: Log) -> LocalFrame:
    """The session's frame (:func:`~estimator.pipeline.inputs.frame_of`), which the filter
    places at a fix: a log without one is refused here, not framed at its truth."""
    if not log.gnss.valid.any():
        raise LogError(log.path, "no valid GNSS fix: the filter cannot be initialised")
    return frame_of(log)


@dataclass
class _Track:
    """Where on the route the vehicle is, and the lane offset of the current interval."""

    lane: float = 0.0
    s: float | None = None
    s_dist: float = 0.0
    t_start: float = -math.inf
    """start of the current interval"""
    bias: MapBias | None = None
    """the map bias of the current interval (``extensions.map_bias``)"""
    biased_route: Route | None = None
    """the route moved back by ``bias``: where the road driven is"""
    biased_key: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """the offset and rotation ``biased_route`` was moved back by"""
    pivot_dist: float = 0.0
    """distance travelled at the end of the track the bias was learned from"""
    bridged_gap_end: float = -math.inf
    """the end of the last IMU gap :meth:`Driver._bridged_on_route` looked at"""
    placed_dist: float = -math.inf
    """distance travelled when the vehicle was last known on the route: an accepted match, a
    bridged gap, or an outage's start whose approach found the route the road driven
    (:meth:`Driver._portal_on_route`)"""


class Driver:
    """One run's estimation loop: the filter between stops, the route part at the stops."""

    def __init__(
        self,
        log: Log,
        route: Route | None,
        p: Params,
        matching: bool,
        inputs: FilterInputs,
        progress: ProgressFn | None,
        memo: Memo,
    ) -> None:
        self.log = log
        self._route = route
        self.p = matching_params(p, have_wheel=len(inputs.wheel_t) > 0)
        """the parameters as the matcher runs with them (:func:`matching_params`)"""
        self.matching = matching
        self.inp = inputs
        self.filt = Filter(inputs, source=log.path, t_start=log.t_start, progress=progress)
        self.memo = memo
        self.checkpoints: list[Checkpoint] = []
        self.records: list[MatchRecord] = []
        self.track = _Track()
        self.dropped_fixes: list[float] = []
        """times of the fixes the fixed-lag re-runs left out"""
        imu_t = inputs.imu_t
        self.gap_ends: F64 = imu_t[1:][np.diff(imu_t) > IMU_GAP_S]
        """the first IMU sample after each IMU gap the filter bridged"""
        self.copied_whole_run = False
        """the run is the reused one (a baseline after a baseline)"""
        self.twin: DeadReckoningTwin | None = None
        """the current outage's dead-reckoning twin (``extensions.dr_separation``)"""
        self.pending_bridge: dict[str, float] = {}
        """an IMU gap bridged along the route since the last attempt, for its record"""

    @property
    def route(self) -> Route:
        if self._route is None:
            raise RoutefuseError(None, "matching needs a route")
        return self._route

    def start(self) -> None:
        self.filt.start(self._rows_needed())
        self.loop(0, None)

    def _rows_needed(self) -> int:
        """Room for the output rows the run will most likely write: one per output interval,
        but no more than the IMU samples (the kernel writes a row only as a sample arrives),
        and one per match attempt, no more than the distance the outage's IMU samples can
        travel allows. Counted from the data, not the span: a clock that jumps years forward
        would otherwise ask for rows for every output interval of those years. A run that
        writes more grows the buffer (:meth:`Filter.grow`)."""
        inp = self.inp
        k0 = int(inp.idx0[I_IMU]) - 1
        span = float(inp.imu_t[-1] - inp.imu_t[k0])
        n = min(int(span * self.p.output_rate_hz), len(inp.imu_t) - k0) + 16
        if self.matching:
            tr = self.p.trigger
            for a, b in inp.degraded:
                samples = int(np.searchsorted(inp.imu_t, b) - np.searchsorted(inp.imu_t, a))
                n += min(int((b - a) / tr.interval_s), samples) + 2
        return n

    def loop(self, i0: int, at: Checkpoint | None) -> None:
        """Run live from the start of interval ``i0``, or from the attempt checkpoint ``at``
        (whose attempt is redone)."""
        tr = self.p.trigger
        spacing = self.p.window.spacing_m
        f = self.filt
        for i in range(i0, len(self.inp.degraded)):
            a, b = self.inp.degraded[i]
            if at is not None and i == at.interval:
                k, dist_a, dist_last = at.k, at.dist_a, at.dist_last
            else:
                self.twin = None
                self.dropped_fixes.extend(advance_to_outage(f, a, self.p))
                if self.p.extensions.exit_adapt:
                    self._walk_by_exits(i)
                dist_a = float(f.aux[A_DIST])
                dist_last = -math.inf
                k = 0
                self._checkpoint("outage", i, 0, dist_a, dist_last)
                if not self.matching:
                    continue
                approach = aided_approach_m(f.out[: f.n_out], a, self.inp.degraded)
                if (
                    self.p.extensions.calibrated_approach
                    and approach < self.p.trigger.min_approach_m
                ):
                    cp = dataclasses.replace(self.checkpoints[-1], uncalibrated_m=approach)
                    self.checkpoints[-1] = cp
                    continue
                self.begin_interval(a, f.out, f.n_out, f.x, f.aux)
                self.clone_route_errors(f.x, f.P, f.aux)
                cloned = (f.P.copy(), f.aux.copy())
                self.checkpoints[-1] = dataclasses.replace(self.checkpoints[-1], cloned=cloned)
                if self.p.extensions.dr_separation:
                    self.twin = self._twin(a)
            while True:
                t_try = a + tr.min_outage_s + k * tr.interval_s
                if t_try >= b or t_try > self.inp.imu_t[-1]:
                    break
                redo = at is not None and i == at.interval and k == at.k
                if at is not None and redo:
                    self.pending_bridge = dict(at.bridged)
                else:
                    if self.matching and self.p.extensions.gap_route_bridge:
                        self._bridge_gaps_until(t_try)
                    f.advance(t_try)
                    growth = 0.0
                    if self.p.extensions.along_drift_evidence:
                        q = along_drift_psd(f.out[: f.n_out], a, t_try)
                        growth = self.p.noise.along_drift_share * q * tr.interval_s
                        grow_along_velocity(f.P, f.x, growth)
                    if skipped := self._attempts_in_imu_gap(a, k, t_try):
                        grow_along_velocity(f.P, f.x, growth * skipped)
                        k += skipped
                d = float(f.aux[A_DIST])
                if d - dist_a >= tr.min_outage_distance_m and d - dist_last >= spacing:
                    if not redo:
                        if self.track.bias is not None and self.track.bias.significant:
                            grow_map_bias(f.P, self._bias_growth(d, dist_last, dist_a))
                        if self.p.extensions.map_turn_consider:
                            turn_map_bias(f.P, f.aux, f.x)
                        self._checkpoint("attempt", i, k, dist_a, dist_last)
                    self._attempt_live()
                    dist_last = d
                k += 1
            if self.p.extensions.map_turn_release:
                self._release_turn(i, a, b)
            at = None
        f.advance(math.inf)

    def _attempts_in_imu_gap(self, a: float, k: int, t_try: float) -> int:
        """How many attempt times after attempt ``k`` (at ``t_try``, in the outage starting at
        ``a``) to pass over at once: those inside an IMU gap holding more than
        :data:`ATTEMPTS_WALKED` of them (a clock that jumped days or years forward), but the
        last. Inside a gap nothing moves and no attempt is made; only the along-track growth
        (``extensions.along_drift_evidence``) goes on, the same at each once the output rows
        are a drift window behind, and the caller adds it for all of them at once. Walked,
        the attempts would take a loop iteration per interval of the gap."""
        f = self.filt
        i = int(f.idx[I_IMU])
        imu_t = self.inp.imu_t
        if i >= len(imu_t) or f.n_out == 0:
            return 0
        if t_try < float(f.out[f.n_out - 1, O_T]) + DRIFT_WINDOW_S:
            return 0
        tr = self.p.trigger
        last = math.floor((float(imu_t[i]) - a - tr.min_outage_s) / tr.interval_s)
        skipped = last - k - 1
        return skipped if skipped > ATTEMPTS_WALKED else 0

    def route_updated(self, a: float, b: float) -> bool:
        """Whether a route update was applied from ``a`` to ``b`` (absolute times)."""
        return any(r.accepted and a <= r.t <= b for r in self.records)

    def _walk_by_exits(self, i: int) -> None:
        """At outage ``i``'s start (``extensions.exit_adapt``): if the previous outage, dead
        reckoned (no route update applied in it), ended beyond its sigmas, add to the run's
        random walk of the horizontal position the least one that would have put that exit
        within the 95 % bound over the time it ran (from the outage's start to the fix it was
        judged by), and start this outage with it. The previous exit was judged with the walk
        it had, so the walks add up (to ``noise.exit_walk_max_m2_s`` at most); the fixes after
        an outage end the kernel's walk (``A_POS_WALK``), not the run's (``A_EXIT_WALK``,
        carried in the filter's state through checkpoints). A walk of the position alone
        moves no dead-reckoned estimate inside the outage (no other state is correlated with
        it, so no velocity or attitude update takes a gain from it): it widens the covariance
        the route updates, their gates and the returning fixes are weighed against. An outage
        whose route updates pulled it off is left out: that is the route's error, and a wider
        dead-reckoning covariance would let the next outage's route updates pull harder (with
        the map's bias not learned, on the stress corpus, drives 14 and 46 went 4.87 -> 8.31
        and 4.38 -> 6.93 m). So is one the IMU fell silent in: its position was carried along
        the wheels, not dead-reckoned, and the filter is aligned afresh after it (60 s without
        IMU in open sky on the long tunnel ended 60963 chi-square off, and the walk it gave
        took the tunnel after it 2.7 -> 72 m)."""
        f = self.filt
        if i > 0:
            degraded = self.inp.degraded[i - 1 : i + 1]
            rows = f.out[: f.n_out]
            k0 = max(int(np.searchsorted(rows[:, O_T], degraded[0][0])) - 1, 0)
            epochs = epochs_of(rows[k0:], len(rows) - k0, degraded)
            for x in run_exits(epochs, degraded[:1], self.inp, self.p):
                gapped = (self.gap_ends > x.start) & (self.gap_ends <= x.fix_t[1])
                if x.overconfident and not self.route_updated(x.start, x.end) and not gapped.any():
                    excess = isotropic_excess(x.error, x.estimate_cov + x.fix_cov, NEES_95_2DOF)
                    walk = f.aux[A_EXIT_WALK] + excess / max(x.fix_t[0] - x.start, 1.0)
                    f.aux[A_EXIT_WALK] = min(walk, self.p.noise.exit_walk_max_m2_s)
        f.aux[A_POS_WALK] = f.aux[A_EXIT_WALK]
        f.aux[A_WALK_FROM] = self.inp.degraded[i][0]

    def _release_turn(self, i: int, a: float, b: float) -> None:
        """At the end of outage ``i`` (``a`` to ``b``), give the navigation state back the
        map's rotation error its route updates put into it unaccounted
        (``extensions.map_turn_release``): what the rotation's honest second moment exceeds
        the variance the outage carried for it (often a method-of-moments zero), along the
        direction a turned map moves the state: position turned about the bias's pivot,
        heading and velocity turned alike. A heading held to the map's for a tunnel is only
        as good as the map's rotation is known; with that correlation the first fix after
        the outage corrects the heading with the position it explains, as dead reckoning's
        own correlations would, instead of a heading left confidently on the map's turn."""
        bias = self.track.bias
        if bias is None or not bias.significant:
            return
        if self.twin is not None and self.twin.undone is not None:
            return  # back on dead reckoning, whose covariance is its own
        if not any(r.accepted and a <= r.t <= b for r in self.records):
            return
        starts = [c for c in self.checkpoints if c.kind == "outage" and c.interval == i]
        cloned = starts[-1].cloned if starts else None
        if cloned is None:
            return
        extra = bias.turn_second_moment - float(cloned[0][E_ROT, E_ROT])
        if extra <= 0.0:
            return
        f = self.filt
        f.advance(b)
        flush_covariance(f.P, f.aux, self.inp.cfg)
        release_turn(f.x, f.P, bias.pivot, extra)
        f.aux[A_INFLATE] = 0.0  # the next fix is tested against that, not widened to it

    def clone_route_errors(self, x: F64, P: F64, aux: F64) -> None:
        """At an outage's start (after :meth:`begin_interval`): the lane-offset, map-bias and
        map-rotation errors the outage's pseudo-positions share, cloned into the filter."""
        bias = self.track.bias
        if bias is not None:
            gain, cov = bias.gain.copy(), bias.cov.copy()
            if not self.p.extensions.lane_offset_state:
                gain[0], cov[0], cov[:, 0] = 0.0, 0.0, 0.0
            tied_estimated = bias.tied and self.p.extensions.unapplied_bias_estimate
            estimate = (bias.significant or tied_estimated) and route_errors_estimated(self.p)
            clone_route_errors(P, aux, self.inp.cfg, gain, cov, estimate)
        elif self.p.extensions.lane_offset_state and self.track.s is not None:
            t = self.route.tangent_at(self.track.s)[0]
            clone_lane_offset(P, aux, self.inp.cfg, np.array([-t[1], t[0]]))
        ext = self.p.extensions
        turn = ext.map_turn_consider
        var = bias.turn_var if bias is not None and turn else 0.0
        estimate = turn and ext.map_turn_estimate and self._turn_estimated(bias, var)
        if turn and not estimate and ext.map_turn_honest_consider:
            var = honest_turn_consider(bias, var)
        clone_map_turn(P, aux, x, var, estimate)

    def _bias_growth(self, d: float, dist_last: float, dist_a: float) -> float:
        """Variance (m^2, per axis) an applied map bias's error gains from the previous attempt
        (or the outage start) to travelled distance ``d``: the map's error wandering along the
        road (``offset.map_bias_walk_m_per_sqrt_km``), and the learned rotation's uncertainty
        carried further from where it was learned. A bias tested insignificant keeps
        ``offset.map_bias_null_sigma_m``. With ``offset.map_bias_walk_turned_only`` the walk
        is left out where the approach saw no rotation (``turn_var`` zero)."""
        bias = self.track.bias
        assert bias is not None
        before = dist_last if dist_last > -math.inf else dist_a
        walk = self.p.offset.map_bias_walk_m_per_sqrt_km
        if self.p.offset.map_bias_walk_turned_only and bias.turn_var <= 0.0:
            walk = 0.0
        far, near = d - self.track.pivot_dist, before - self.track.pivot_dist
        turn = bias.rotation_sigma**2 * (far * far - near * near)
        if self.p.extensions.map_turn_consider and not self.p.offset.map_bias_turn_walk:
            turn = 0.0  # carried by E_ROT alone (turn_map_bias)
        return float(walk**2 * (d - before) / 1000.0 + max(turn, 0.0))

    def _checkpoint(
        self,
        kind: Literal["outage", "attempt"],
        interval: int,
        k: int,
        dist_a: float,
        dist_last: float,
    ) -> None:
        self.checkpoints.append(
            Checkpoint(
                kind=kind,
                interval=interval,
                k=k,
                state=self.filt.snapshot(),
                n_records=len(self.records),
                dist_a=dist_a,
                dist_last=dist_last,
                twin=None if self.twin is None else self.twin.copy(),
                bridged=dict(self.pending_bridge),
            )
        )

    def _predicted_s(self, aux: F64) -> float | None:
        tr = self.track
        return None if tr.s is None else tr.s + (aux[A_DIST] - tr.s_dist)

    def begin_interval(self, t_a: float, out: F64, n_out: int, x: F64, aux: F64) -> None:
        """Place the vehicle on the route and learn the lane offset at an interval's start."""
        rows = out[:n_out]
        tr = self.track
        tr.s = route_arc_length(
            self.route,
            x[:2],
            s_guess=self._predicted_s(aux),
            params=self.p,
            heading_xy=x[X_VEL : X_VEL + 2],
        )
        tr.s_dist = float(aux[A_DIST])
        used = rows[:, O_GNSS] > 0
        # the offset is learned around the last epoch a fix was used in, which may lie well
        # before t_a (fixes rejected or left out at the portal): a search window centred on
        # the vehicle would clip the older epochs onto its end, with metres of false offset
        last = np.flatnonzero(used & (rows[:, O_T] <= t_a))
        s_last = tr.s
        if len(last):
            s_last = tr.s - (float(aux[A_DIST]) - float(rows[last[-1], O_DIST]))
        tr.lane = self._offset_near_portal(
            rows, used, t_a, s_last, max_offset_m=self.p.offset.max_offset_m
        )
        tr.t_start = t_a
        previous = None
        if tr.bias is not None and np.isfinite(tr.bias.chi2):
            turned = dataclasses.replace(tr.bias, rotation=self._route_turn(aux))
            previous = (turned, self._route_estimate(aux)[0], tr.pivot_dist)
        tr.bias, tr.biased_route = None, None
        if self.p.extensions.map_bias:
            s_bias, cut = s_last, self.p.offset.map_bias_portal_cut_s
            if self.p.extensions.map_bias_portal_cut and len(last):
                # the portal's degraded fixes the filter used: not the road driven
                kept = np.flatnonzero(used & (rows[:, O_T] <= t_a - cut))
                if len(kept):
                    s_bias -= float(rows[last[-1], O_DIST]) - float(rows[kept[-1], O_DIST])
                last = kept
            track = self._bias_track(rows, last)
            tr.bias = self._learn_bias(track, s_bias)
            carried = None
            if previous is not None and previous[0].significant:
                bias, offset, pivot_dist = previous
                carried = carried_bias(
                    bias,
                    offset,
                    position=x[:2].copy(),
                    lane_seen=self._offset_near_portal(rows, used, t_a, s_last),
                    normal=self.route.normal_at(np.array([tr.s]))[0],
                    metres=float(aux[A_DIST]) - pivot_dist,
                    params=self.p,
                )
            if previous is not None and (
                not np.isfinite(tr.bias.chi2)
                or (self.p.extensions.map_bias_keep_applied and keeps_carried(previous[0], tr.bias))
                or (
                    self.p.extensions.map_bias_carry_turned
                    and carried is not None
                    and carried_explains(carried, tr.bias, self.p)
                )
            ):
                # too little driving since the previous outage to learn, or too little to
                # overturn the bias it applied, or a bias it predicts: its bias still holds
                bias, _, pivot_dist = previous
                if carried is not None:
                    tr.pivot_dist = pivot_dist
                    tr.bias = carried
                    if self.p.offset.map_bias_refine and track is not None:
                        if self.p.extensions.map_turn_two_places:
                            # fixes refused after an outage leave the estimate where dead
                            # reckoning put it (metres off across), which the fit of a second
                            # place would take for the map's turn
                            track = track[int(np.flatnonzero(track[:, O_GNSS] > 0)[0]) :]
                        tr.bias = refined_bias(
                            track[:, O_POS : O_POS + 2],
                            _track_cov(track),
                            self.route,
                            carried=carried,
                            s_guess=s_bias,
                            params=self.p,
                            track_var=_track_var(track),
                            metres=float(track[-1, O_DIST]) - pivot_dist,
                        )
                        if tr.bias.pivot is not carried.pivot:
                            # the rotation learned from the two places turns about the new one
                            tr.pivot_dist = float(track[-1, O_DIST])
                else:
                    normal = self.route.normal_at(np.array([tr.s]))[0]
                    tr.bias = unbiased(self.p, lane=tr.lane, normal=normal, learned=bias)
            tr.lane = tr.bias.lane
            if self.p.extensions.unapplied_bias_consider:
                tr.bias = unapplied_considered(
                    tr.bias, tied=self.p.extensions.unapplied_bias_lane_tie
                )
        if self._portal_on_route(rows, used, t_a, s_last):
            tr.placed_dist = float(aux[A_DIST])

    def _portal_on_route(
        self, rows: F64, used: NDArray[np.bool_], t_a: float, s_last: float
    ) -> bool:
        """The GNSS-aided approach found the road driven where the route (moved back by the map
        bias) draws it: a map bias learned and not refused as another road, or, with none
        learned, the offset from the route near the portal within ``offset.max_offset_m``."""
        bias = self.track.bias
        if bias is not None and np.isfinite(bias.chi2):
            return bias.refused is None
        lane = self._offset_near_portal(rows, used, t_a, s_last)
        return math.isfinite(lane) and abs(lane) <= self.p.offset.max_offset_m

    def _offset_near_portal(
        self,
        rows: F64,
        used: NDArray[np.bool_],
        t_a: float,
        s_last: float,
        *,
        max_offset_m: float = math.inf,
    ) -> float:
        """The cross-track offset from the route learned near the portal up to ``t_a``
        (:func:`learn_lane_offset`), lane and map together, 0 beyond ``max_offset_m``: by
        default however large, since a map shifted sideways puts it beyond
        ``offset.max_offset_m``, where the lane offset is taken as 0."""
        op = dataclasses.replace(self.p.offset, max_offset_m=max_offset_m)
        return learn_lane_offset(
            rows[:, O_T],
            rows[:, O_POS : O_POS + 2],
            used,
            self.route,
            t_end=t_a,
            params=dataclasses.replace(self.p, offset=op),
            s_guess=s_last,
        )

    def _learn_bias(self, track: F64 | None, s_last: float) -> MapBias:
        """The map bias from the estimate over ``track`` (:meth:`_bias_track`;
        :func:`learn_map_bias`), the prior without one."""
        lane = self.track.lane
        prior = prior_bias(self.p, lane=lane, normal=self.route.normal_at(np.array([s_last]))[0])
        if track is None:
            return prior
        self.track.pivot_dist = float(track[-1, O_DIST])
        return learn_map_bias(
            track[:, O_POS : O_POS + 2],
            _track_cov(track),
            self.route,
            s_guess=s_last,
            lane_offset=self.track.lane,
            params=self.p,
            track_var=_track_var(track),
            track_t=track[:, O_T],
        )

    def _bias_track(self, rows: F64, last: NDArray[np.intp]) -> F64 | None:
        """The output rows of the GNSS-good driving the map bias is learned from: the last
        ``offset.map_bias_track_m`` of travel up to the last epoch a fix was used in, after
        the estimate settled from the previous outage; None with under five fixes."""
        if not len(last):
            return None
        end = int(last[-1])
        d = rows[: end + 1, O_DIST]
        i0 = int(search_right(d, float(d[end]) - self.p.offset.map_bias_track_m))
        # only driving under GNSS, once the estimate has settled on it again: the previous
        # outage's dead reckoning, and the pull back from it, are not the road
        ends = [b for _, b in self.inp.degraded if b <= rows[end, O_T]]
        if ends:
            settled = ends[-1] + self.p.noise.gnss_rerun_lag_s
            i0 = max(i0, int(np.searchsorted(rows[: end + 1, O_T], settled, side="right")))
        track = rows[i0 : end + 1]
        if np.count_nonzero(track[:, O_GNSS] > 0) < 5:
            return None
        return track

    def _window(self, out: F64, n_out: int, x: F64, aux: F64, length_m: float) -> F64:
        """:func:`dr_window` over the last ``length_m`` of travel. With
        ``extensions.gap_route_bridge`` it starts no earlier than the end of an IMU gap in the
        outage: across the gap the track is a straight line the wheels' distance long, a shape
        nobody measured (too short a window then fails ``gates.min_pairs``)."""
        if self.p.extensions.gap_route_bridge:
            ends = self.gaps_ended(float(aux[A_TIME]))
            if len(ends):
                rows = out[:n_out]
                k = row_after_gap(rows, float(ends[-1]))
                length_m = min(length_m, float(aux[A_DIST]) - float(rows[k, O_DIST]))
        return dr_window(out, n_out, x, aux, length_m)

    def match(self, out: F64, n_out: int, x: F64, P: F64, aux: F64) -> MatchRecord:
        """One attempt's match (P must be propagated to the attempt time), its along-track
        covariance widened for the windows it shares with the previous accepted match
        (:meth:`_overlap`)."""
        rec = self._match_window(out, n_out, x, P, aux)
        if self.p.extensions.overlap_inflation and rec.accepted and rec.along_observed:
            rec = self._overlap(rec, out, float(aux[A_DIST]))
        if self.p.extensions.rotation_consistency:
            rec = rotation_checked(rec, P, self.p)
        return rec

    def _new_road_m(self, out: F64, dist: float) -> float | None:
        """The road driven since this outage's previous accepted match (at least
        ``window.spacing_m``; None: none yet), at travelled distance ``dist``: what a window
        adds to the previous accepted one's."""
        for r in reversed(self.records):
            if r.t < self.track.t_start:
                break
            if r.accepted:
                return max(dist - float(out[r.epoch, O_DIST]), self.p.window.spacing_m)
        return None

    def _route_share(self, rec: MatchRecord, out: F64, dist: float) -> float:
        """The part of an accepted match's gain on the cross-track innovation that the
        route-error states take (``extensions.route_errors_overlap_share``): the road its
        window adds to the previous accepted match's, over its length, where the outage
        considers a map rotation (variance above zero) without estimating it; else 1.

        A considered rotation turns the map-bias error at the vehicle by its lever arm
        (:func:`estimator.filter.updates.turn_map_bias`): its variance grows with the square
        of the distance driven and no match ever shrinks the rotation's part, so the map's
        bias is a random walk the matches re-learn at every step. Consecutive windows share
        most of their road and dead-reckoned shape, so their cross-track errors are one error
        for as long as they overlap; a random walk fed them once a second follows that error
        (on the long sample's moved map, 6 m across over 7 km). Counted once per window
        length it does not, while the position keeps the whole gain. Where the rotation is
        estimated, the bias at the vehicle is the bias at the portal plus one rotation that
        the trend of the matches refines: sharing its gain only slows that (held-out drives
        7 and 27). Along the road the overlapping windows' evidence is
        ``extensions.overlap_inflation``'s."""
        f = self.filt
        if not (
            self.p.extensions.route_errors_overlap_share
            and f.aux[A_ROT_EST] <= 0
            and f.P[E_ROT, E_ROT] > 0.0
        ):
            return 1.0
        new_road = self._new_road_m(out, dist)
        length = rec.window_length_m
        if new_road is None or not length > 0.0:
            return 1.0
        return min(1.0, new_road / length)

    def _overlap(self, rec: MatchRecord, out: F64, dist: float) -> MatchRecord:
        """Consecutive windows share most of their track: one attempt a second with a 250 m
        window at 15 m/s re-measures 235 m of the previous one's road and DR shape, so their
        along-track estimates are nearly one measurement, not independent ones. The along-track
        variance is multiplied by the window length over the distance since the previous
        accepted match (at least 1), so a stretch of road counts once however often it is
        matched."""
        new_road = self._new_road_m(out, dist)
        if new_road is None:
            return rec
        factor = rec.window_length_m / new_road
        if factor <= 1.0 or rec.fit is None:
            return rec
        t = rec.tangent
        along_var = float(t @ rec.obs_cov @ t)
        cov = rec.obs_cov + (factor - 1.0) * along_var * np.outer(t, t)
        return dataclasses.replace(rec, obs_cov=cov)

    def _match_window(self, out: F64, n_out: int, x: F64, P: F64, aux: F64) -> MatchRecord:
        """:meth:`match` before the overlap widening.

        A bend much gentler than the window (an expressway's 12 deg over 500 m) has no shape
        inside a 250 m window: sliding along an arc is a rotation, which the rigid fit absorbs,
        so along-track stays unobserved however long the tunnel. Seen whole in a longer window
        the bend is a corner, whose place along the road the fit finds. The longer window only
        replaces an accepted standard match that left along-track unobserved, only where the
        road is gentle (no standard-length stretch of it turns more than
        ``window.long_max_turn_deg``: sharper bends the standard window observes itself, and
        over a long window they make the fit depend on how well the map's arc length matches
        the lane's), and only if it passes every gate itself (``extensions.long_window``)."""
        pred = self._predicted_s(aux)
        w = self.p.window

        def attempt(window_xy: F64, params: Params, length_m: float) -> MatchRecord:
            scale = (
                window_scale_sigma(out, n_out, x, P, aux, length_m)
                if params.extensions.window_scale_covariance
                else 0.0
            )
            geometry = self._geometry(
                window_xy, x[:2].copy(), position_on_map_cov(P), pred, params, aux, scale
            )
            rec = judge_match(
                geometry, params, index=len(self.records), t=float(aux[A_TIME]), epoch=n_out
            )
            bias = self.track.bias
            if bias is None:
                return rec
            offset, _ = self._route_estimate(aux)
            used = MapBiasUse(
                offset,
                P[E_MAP : E_MAP + 2, E_MAP : E_MAP + 2].copy(),
                bias.along_observed,
                learned=bias.measured,
                chi2=bias.chi2,
                rotation_rad=self._route_turn(aux),
                rotation_sigma_rad=bias.rotation_sigma,
                applied=bias.significant,
                refused=bias.refused,
                pivot=np.asarray(bias.pivot, np.float64).copy(),
            )
            return dataclasses.replace(rec, map_bias=used)

        rec = attempt(self._window(out, n_out, x, aux, w.length_m), self.p, w.length_m)
        if not (
            self.p.extensions.long_window
            and w.long_length_m > w.length_m
            and rec.accepted
            and not rec.along_observed
        ):
            return rec
        long_xy = self._window(out, n_out, x, aux, w.long_length_m)
        turn = self.memo.get(
            ("turn", w.length_m, w.spacing_m),
            (long_xy,),
            lambda: max_turn(long_xy, w.length_m, w.spacing_m),
        )
        if turn > w.long_max_turn_deg:
            return rec
        # map and DR shape errors are correlated over tens of metres: the long window's points
        # count as many as the standard window's, not as independent extra information
        po = self.p.pseudo
        noise = po.shape_noise_m * math.sqrt(w.long_length_m / w.length_m)
        long = attempt(
            long_xy,
            dataclasses.replace(self.p, pseudo=dataclasses.replace(po, shape_noise_m=noise)),
            w.long_length_m,
        )
        if not (long.accepted and long.along_observed):
            return rec
        return dataclasses.replace(long, long_window=LongWindow(turn, rec.window_length_m))

    def _geometry(
        self,
        window_xy: F64,
        p_dr: F64,
        cov: F64,
        pred: float | None,
        params: Params,
        aux: F64,
        window_scale_sigma_m: float = 0.0,
    ) -> MatchGeometry:
        """:func:`match_geometry` of an attempt, or the previous run's for the same inputs
        (window, position, covariance, route guess, lane offset, map bias and the parameters
        the geometry depends on): after a gate change the attempts before the first changed
        outcome are only re-judged, not fitted again.

        With a map bias the window is matched to the route moved back by it, and to the lane
        it learned, both as the outage's matches have corrected them (:meth:`_route_estimate`)."""
        route, lane, bias_key = self._road(aux)
        return self.memo.get(
            ("geometry", pred, lane, bias_key, geometry_params(params), window_scale_sigma_m),
            (window_xy, p_dr, cov),
            lambda: match_geometry(
                window_xy,
                p_dr,
                cov,
                route,
                s_guess=pred,
                lane_offset=lane,
                params=params,
                window_scale_sigma_m=window_scale_sigma_m,
            ),
        )

    def _road(self, aux: F64) -> tuple[Route, float, tuple[float, ...]]:
        """The road driven as the current interval knows it: the route moved back by the map
        bias (as the outage's matches have corrected it), the lane offset, and the key of the
        bias moved back by (empty without one)."""
        tr = self.track
        if tr.bias is None:
            return self.route, tr.lane, ()
        offset, lane = self._route_estimate(aux)
        turn = self._route_turn(aux)
        key = (float(offset[0]), float(offset[1]), turn)
        if tr.biased_route is None or tr.biased_key != key:
            tr.biased_route = Route(
                xy_moved_back(self.route.xy, offset, turn, tr.bias.pivot),
                name=self.route.name,
                source=self.route.source,
            )
            tr.biased_key = key
        return tr.biased_route, lane, key

    def _route_estimate(self, aux: F64) -> tuple[F64, float]:
        """The map bias and the lane offset of the current interval: as learned before the
        outage plus what its matches estimated of their errors since (the filter's
        ``A_ROUTE``, ``offset.map_bias_estimated``)."""
        bias = self.track.bias
        assert bias is not None
        offset: F64 = bias.offset + aux[A_ROUTE + 1 : A_ROUTE + 3]
        if aux[A_ROT_EST] > 0:
            shift = aux[A_ROT_SHIFT : A_ROT_SHIFT + 2]
            offset = turned_back(
                offset, bias.rotation, bias.pivot, turn=float(aux[A_ROT]), shift=shift
            )[0]
        return offset, bias.lane + float(aux[A_ROUTE])

    def _route_turn(self, aux: F64) -> float:
        """The map's rotation about the bias's pivot: as learned before the outage plus what
        its matches estimated of its error since (``extensions.map_turn_estimate``)."""
        bias = self.track.bias
        assert bias is not None
        return bias.rotation + (float(aux[A_ROT]) if aux[A_ROT_EST] > 0 else 0.0)

    def _turn_estimated(self, bias: MapBias | None, var: float) -> bool:
        """The outage's pseudo-positions estimate the map's rotation error (prior variance
        ``var``): where they estimate its bias (an applied bias), and, for a rotation fitted
        but not applied (a method-of-moments prior, as often spurious as not on a right map),
        where the prior stands out against the heading's (``offset.map_turn_min_heading_ratio``);
        an applied rotation's prior is the fit's own posterior."""
        if bias is None or not bias.significant or not route_errors_estimated(self.p):
            return False
        if bias.rotation != 0.0:
            return True
        ratio = self.p.offset.map_turn_min_heading_ratio
        return var >= ratio * ratio * float(self.filt.P[E_ATT + 2, E_ATT + 2])

    def after_match(self, rec: MatchRecord, x_after: F64, aux: F64) -> None:
        """Follow the vehicle along the route after an accepted match."""
        if rec.accepted:
            self._placed_on_route(x_after, aux)

    def _placed_on_route(self, x: F64, aux: F64) -> None:
        """Where on the route the vehicle is, after a route update placed it there."""
        tr = self.track
        pred = self._predicted_s(aux)
        tr.s = route_arc_length(self.route, x[:2], s_guess=pred, params=self.p)
        tr.s_dist = tr.placed_dist = float(aux[A_DIST])

    def _attempt_live(self) -> None:
        f = self.filt
        flush_covariance(f.P, f.aux, self.inp.cfg)
        bridged, self.pending_bridge = self.pending_bridge, {}
        n_out = f.n_out
        rec = self.match(f.out, n_out, f.x, f.P, f.aux)
        if not rec.accepted and self.p.extensions.reanchor:
            rec = self._reanchored(rec)
        if not rec.accepted and self.p.extensions.gap_reacquire:
            rec = self._reacquired(rec)
        twin = self.twin
        if twin is not None:
            if twin.undone is None:
                twin.advance(float(f.aux[A_TIME]), self.log.path)
            elif not rec.reanchored:
                u = twin.undone
                gate = undone_gate(u.separation.chi2, u.t - self.log.t_start, self.p.gates)
                rec = dataclasses.replace(rec, accepted=False, gates=(*rec.gates, gate))
        innovation, correction = rec.innovation, np.zeros(2)
        if rec.accepted:
            share = self._route_share(rec, f.out, float(f.aux[A_DIST]))
            innovation, correction, rec = apply_route_match(f, rec, self.p, route_share=share)
            if twin is not None and rec.reanchored:
                # the filter's covariance was found not to cover its drift: dead reckoning
                # starts afresh from the re-anchored state
                self.twin = self._twin(float(f.aux[A_TIME]))
            elif twin is not None:
                rec = self._separation_checked(rec, twin)
                if not rec.accepted:
                    correction = np.zeros(2)
            if not finite_state(f.x, f.P):
                raise LogError(
                    self.log.path,
                    "the filter diverged (non-finite state) after "
                    f"the route update at t = {rec.t - self.log.t_start:.2f} s",
                )
        epoch = f.write_row()
        rec = dataclasses.replace(rec, epoch=epoch, innovation=innovation, correction=correction)
        if bridged:
            rec = dataclasses.replace(rec, extra={**rec.extra, **bridged})
        self.records.append(rec)
        self.after_match(rec, f.x, f.aux)

    def _twin(self, since: float) -> DeadReckoningTwin:
        """The filter's dead-reckoning twin from now (fixes up to ``since`` are the filter's)."""
        scale = self.p.noise.gyro_scale_sigma_ppm * 1e-6
        return DeadReckoningTwin(
            self.filt.snapshot(),
            self.inp,
            fixes_until=since,
            gyro_scale_var=scale * scale if self.p.extensions.dr_separation_gyro_scale else 0.0,
        )

    def _separation_checked(self, rec: MatchRecord, twin: DeadReckoningTwin) -> MatchRecord:
        """``rec`` (just applied) with its dead-reckoning separation gate; when it fails, the
        outage's route updates are undone: the filter goes back to its twin, which took none
        of them, and takes no more in this outage (:mod:`estimator.filter.twin`)."""
        f, g = self.filt, self.p.gates
        sep = twin.separation(f.x, f.P, floor_m=g.dr_separation_floor_m)
        gate = DR_SEPARATION.decide(sep.chi2, g)
        rec = dataclasses.replace(rec, gates=(*rec.gates, gate))
        if gate.passed:
            return rec
        twin.undone = Undone(rec.t, sep)
        f.x[:] = twin.x
        f.P[:] = twin.P
        if twin.considers_scale:
            f.P[E_GSF, :] = 0.0
            f.P[:, E_GSF] = 0.0
        # what the outage's matches estimated of the route's errors, and where, goes back too
        estimated = slice(A_ROUTE, A_ROT_SHIFT + 2)
        f.aux[estimated] = twin.aux[estimated]
        # and so does the mark that route updates were taken: the next fix is tested against
        # dead reckoning's own covariance, not widened to its innovation
        f.aux[A_INFLATE] = twin.aux[A_INFLATE]
        extra = {**rec.extra, "dr_separation_m": sep.metres}
        return dataclasses.replace(rec, accepted=False, extra=extra)

    def _reanchored(self, rec: MatchRecord) -> MatchRecord:
        """``rec`` accepted as a re-anchor (:mod:`estimator.matching.reanchor`) after widening
        the filter's heading and position covariance to its innovation, or ``rec`` itself."""
        f = self.filt
        run = self._refusal_run(rec, since_t=self.track.t_start)
        if not should_reanchor(run, self.p):
            return rec
        y = np.ascontiguousarray(rec.innovation, np.float64)
        widen_heading(f.x, f.P, y, f.aux, self.p.extensions.cross_track_heading_widen)
        widen_to_innovation(f.P, y, position_on_map_cov(f.P) + applied_obs_cov(rec, self.p))
        return dataclasses.replace(rec, accepted=True, reanchored=True)

    def gaps_ended(self, t: float) -> F64:
        """The ends of the IMU gaps that ended in the current outage by ``t``."""
        ends = self.gap_ends
        lo = np.searchsorted(ends, self.track.t_start, side="right")
        return ends[lo : np.searchsorted(ends, t, side="right")]

    def _reacquired(self, rec: MatchRecord) -> MatchRecord:
        """``rec`` accepted as a re-anchor after an IMU gap in this outage
        (``extensions.gap_reacquire``), or ``rec`` itself. The wheels carried the position
        across the gap along the last heading, so where the road turned inside it the heading
        after it is off by that turn; the wheel-speed and non-holonomic updates cannot see it
        (they measure the body velocity, which turning heading and velocity together leaves
        as it is), yet the filter's yaw sigma shrinks back to tenths of a degree within
        seconds, and every match is then refused for its heading, its rotation and the size of
        its correction. Once ``gates.reanchor_after`` consecutive attempts whose windows lie
        wholly after the gap are sound and within what the gap can explain
        (:func:`~estimator.matching.reanchor.gap_bound_m`), heading and velocity are turned by
        the fitted rotation (:func:`~estimator.filter.route_update.turn_about_up`), the heading
        variance is widened by it, the position covariance to the innovation, and the match is
        applied, its heading observation then with no innovation left."""
        f = self.filt
        t_now = float(f.aux[A_TIME])
        ends = self.gaps_ended(t_now)
        if len(ends) == 0:
            return rec
        n = f.n_out
        rows = f.out[:n]
        j = row_after_gap(rows, float(ends[-1]))
        gap_dist = float(rows[j, O_DIST])
        bridged = gap_dist - float(rows[max(j - 1, 0), O_DIST])
        clean = gap_dist + self.p.window.length_m
        if float(f.aux[A_DIST]) < clean:
            return rec
        run = self._refusal_run(
            rec,
            since_t=float(ends[-1]),
            since_dist=clean,
            gap=lambda d: gap_bound_m(bridged, d - gap_dist),
        )
        if not should_reanchor(run, self.p, after_gap=True):
            return rec
        turn_about_up(f.x, f.P, rec.rotation_rad)
        turn_heading(f.x, f.P, rec.rotation_rad**2)
        y = np.ascontiguousarray(rec.innovation, np.float64)
        widen_to_innovation(f.P, y, position_on_map_cov(f.P) + applied_obs_cov(rec, self.p))
        extra = {**rec.extra, "gap_end_s": float(ends[-1]) - self.log.t_start}
        return dataclasses.replace(rec, accepted=True, reanchored=True, extra=extra)

    def _bridge_gaps_until(self, t: float) -> None:
        """Run the filter to the end of each IMU gap of the outage that ends by ``t`` and bridge
        it there along the route (:meth:`_bridged_on_route`), the output row at the gap's end
        then showing the bridged state: the route and the wheels' distance are known the moment
        the IMU comes back, not only at the next attempt."""
        f = self.filt
        for end in self.gaps_ended(t):
            if end <= f.aux[A_TIME]:
                continue
            f.advance(float(end))
            bridged = self._bridged_on_route()
            if bridged:
                f.write_row()
                self.pending_bridge = bridged

    def _bridged_on_route(self) -> dict[str, float]:
        """Bridge the IMU gap that has just ended along the route
        (``extensions.gap_route_bridge``); returns what the next attempt's record keeps of it,
        empty where nothing was bridged.

        The wheels carried the position across the gap by the distance they measured, but along
        the heading before it: wherever the road turned inside the gap the state comes out of
        it off the road and turned from it, with a covariance of half the gap's travel each way
        (:func:`~estimator.filter.kernel._bridge`). Where the route placed the vehicle up to a
        window before the gap, the same distance along the road (moved back by the map bias)
        says where it is: the position is updated to that point and the heading to the road's
        there. Along the road the point is as uncertain as the position was before the gap plus
        the wheel scale's uncertainty over the distance (without wheel speed, the last speed's
        over the gap's time, as the kernel carried it); across, as a match
        (``pseudo.cross_sigma_m``); the heading by ``pseudo.gap_bridge_heading_sigma_deg`` and
        the map's rotation uncertainty."""
        f = self.filt
        tr = self.track
        ends = self.gaps_ended(float(f.aux[A_TIME]))
        if not len(ends) or float(ends[-1]) <= tr.bridged_gap_end or tr.s is None:
            return {}
        end = float(ends[-1])
        tr.bridged_gap_end = end
        rows = f.out[: f.n_out]
        k = row_after_gap(rows, end)
        if k == 0:
            return {}
        before = rows[k - 1]
        dist_before = float(before[O_DIST])
        if dist_before - tr.placed_dist > self.p.window.length_m:
            return {}  # nothing placed the vehicle on the route up to a window before the gap
        wheels = self.inp.wheel_t
        span = float(rows[k, O_T] - before[O_T])
        if (
            len(wheels)
            and wheel_distance(float(before[O_T]), float(rows[k, O_T]), wheels, self.inp.wheel_v)[0]
            < 0.0
        ):
            return {}  # the wheels fell silent with the IMU: a paused recording, held
        road, lane, _ = self._road(f.aux)
        s0 = route_arc_length(
            road,
            before[O_POS : O_POS + 2],
            s_guess=tr.s + (dist_before - tr.s_dist),
            params=self.p,
        )
        travelled = float(f.aux[A_DIST]) - dist_before
        forward = float(road.tangent_at(s0)[0] @ before[O_VEL : O_VEL + 2]) >= 0.0
        if not (self.p.offset.enabled and math.isfinite(lane)):
            lane = 0.0
        s1 = s0 + travelled if forward else s0 - travelled
        if forward and lane != 0.0 and 0.0 <= s1 <= road.length:
            # a lane to the left of the route is shorter round a left turn: driven = ds - lane dpsi
            s1 += lane * road_turn(road, s0, s1, self.p.window.spacing_m)
        if not 0.0 <= s1 <= road.length:
            return {}
        u0, u, normal = road.tangent_at(s0)[0], road.tangent_at(s1)[0], road.normal_at(s1)[0]
        z = road.point_at(s1)[0] + lane * normal
        along_var = float(u0 @ row_position_cov(before) @ u0) + (
            float(f.P[E_SCALE, E_SCALE]) * travelled**2 if len(wheels) else GAP_VEL_VAR * span**2
        )
        cross_var = self.p.pseudo.cross_sigma_m**2
        cov = along_var * np.outer(u, u) + cross_var * np.outer(normal, normal)
        road_yaw = float(road.smooth_heading_at(s1)[0]) + (0.0 if forward else math.pi)
        q = f.x[X_QUAT : X_QUAT + 4]
        d = road_yaw - float(yaw_from_quaternion(q[0], q[1], q[2], q[3]))
        dyaw = math.atan2(math.sin(d), math.cos(d))
        yaw_var = math.radians(self.p.pseudo.gap_bridge_heading_sigma_deg) ** 2
        if tr.bias is not None:
            yaw_var += tr.bias.turn_var
        cfg = self.inp.cfg
        turn_about_up(f.x, f.P, dyaw)
        turned = dyaw + heading_update(f.x, f.P, f.aux, cfg, 0.0, yaw_var)
        moved = pseudo_position_update(
            f.x,
            f.P,
            f.aux,
            cfg,
            z,
            cov,
            normal * float(self.p.extensions.lane_offset_state),
            1.0,
            normal,
        )
        if not finite_state(f.x, f.P):
            raise LogError(
                self.log.path,
                "the filter diverged (non-finite state) bridging the IMU gap that ended at "
                f"{end - self.log.t_start:.2f} s along the route",
            )
        if self.twin is not None:
            self.twin = self._twin(float(f.aux[A_TIME]))
        self._placed_on_route(f.x, f.aux)
        return {
            "gap_bridge_end_s": end - self.log.t_start,
            "gap_bridge_along_m": travelled,
            "gap_bridge_turn_deg": math.degrees(turned),
            "gap_bridge_moved_m": float(np.hypot(moved[2], moved[3])),
        }

    def _refusal_run(
        self,
        rec: MatchRecord,
        *,
        since_t: float,
        since_dist: float = -math.inf,
        gap: Callable[[float], float] | None = None,
    ) -> list[tuple[MatchRecord, bool]]:
        """The attempts refused since the last accepted one, ``since_t`` and ``since_dist`` (the
        distance travelled), oldest first, then ``rec``, each with whether its innovation is
        within the drift (:func:`~estimator.matching.reanchor.within_drift`, plus ``gap`` of
        the distance travelled)."""
        f = self.filt
        used_dist = float(f.aux[A_USED_DIST])
        t_start = self.track.t_start

        def checked(r: MatchRecord, cov: F64, dist: float) -> tuple[MatchRecord, bool]:
            ok = within_drift(
                r.innovation,
                cov + applied_obs_cov(r, self.p),
                seconds=r.t - t_start,
                metres=dist - used_dist,
                params=self.p,
                gap_m=0.0 if gap is None else gap(dist),
            )
            return r, ok

        run: list[tuple[MatchRecord, bool]] = []
        for r in reversed(self.records):
            dist = float(f.out[r.epoch, O_DIST])
            if r.t < since_t or dist < since_dist or r.accepted:
                break
            run.append(checked(r, row_position_cov(f.out[r.epoch]), dist))
        run.reverse()
        run.append(checked(rec, position_on_map_cov(f.P), float(f.aux[A_DIST])))
        return run

    def epochs(self) -> Epochs:
        return epochs_of(self.filt.out, self.filt.n_out, self.inp.degraded)


def road_turn(road: Route, s0: float, s1: float, spacing_m: float) -> float:
    """How far the road turns (rad, left positive) from arc length ``s0`` to ``s1``."""
    n = math.ceil(abs(s1 - s0) / max(spacing_m, 1e-3)) + 2
    heading = np.unwrap(road.smooth_heading_at(np.linspace(s0, s1, n)))
    return float(heading[-1] - heading[0])


def row_after_gap(rows: F64, end: float) -> int:
    """The first of the output ``rows`` at or after an IMU gap's ``end`` (the first IMU sample
    after it, where the kernel has bridged it and writes a row); the row before it is the last
    before the gap. The last row if none is."""
    return min(search_right(rows[:, O_T], float(np.nextafter(end, -np.inf))), len(rows) - 1)


def rotation_checked(rec: MatchRecord, P: F64, params: Params) -> MatchRecord:
    """``rec`` with its rotation-consistency gate (``extensions.rotation_consistency``): the
    fitted rotation is the heading correction the window's shape asks for, and under the
    filter's belief it is zero with the variance of the yaw error, the map's rotation error
    (``E_ROT``) and the fit's own heading sigma (their correlation left out). The Mahalanobis
    gate tests only the position, whose covariance without an odometer is stretched along the
    filter's own direction of travel: a window turned far beyond that heading sigma passes it
    while the update, across a route at that angle to the track, moves the position along the
    track instead of across the road (the Husky lot without wheels, 311.6 s: 15.8 deg against
    3.0 deg, the position moved 6.8 m the wrong way along). Either the route is drawn wrong
    there or the filter's heading is, and either way the update is not to be trusted. Off by
    default: the fit's heading sigma leaves out the route's own direction error, and with wheel
    speed on the same lot (a route made of the robot's fixes, windows turned 8-15 deg from it
    under a 2 deg yaw sigma) it refused good matches, 20-260 s 4.59 -> 9.45 m. An attempt
    without a fit is left as it is."""
    fit = rec.fit
    if fit is None or not math.isfinite(rec.rotation_rad):
        return rec
    var = (
        float(P[E_ATT + 2, E_ATT + 2]) + float(P[E_ROT, E_ROT]) + float(fit.heading_sigma_rad) ** 2
    )
    chi2 = rec.rotation_rad**2 / var if var > 0.0 else math.inf
    gate = ROTATION_CONSISTENCY.decide(chi2, params.gates)
    return dataclasses.replace(rec, accepted=rec.accepted and gate.passed, gates=(*rec.gates, gate))


def dr_window(out: F64, n_out: int, x: F64, aux: F64, length_m: float) -> F64:
    """The DR track over the last ``length_m`` of travel, integrated from the mechanised
    velocity only (no correction jumps), translated to end at the estimate."""
    dist = out[:n_out, O_DIST]
    d_now = float(aux[A_DIST])
    i0 = max(search_right(dist, d_now - length_m) - 1, 0)
    window: F64 = track_window(
        out[:n_out, O_DR : O_DR + 2],
        dist,
        aux[A_DR : A_DR + 2],
        d_now,
        i0,
        x[:2] - aux[A_DR : A_DR + 2],
    )
    return window


def _track_cov(track: F64) -> F64:
    """The E/N covariance of the error a bias track's points share: the filter's at its end."""
    return row_position_cov(track[-1])


def _track_var(track: F64) -> F64:
    """Each point's own horizontal variance per axis (the mean of E and N)."""
    var: F64 = 0.5 * np.sum(track[:, O_SIG_POS : O_SIG_POS + 2] ** 2, axis=1)
    return var


def keeps_carried(previous: MapBias, fresh: MapBias) -> bool:
    """Whether the bias ``previous`` applied in the last outage is carried to this one (and
    refined by the driving since) rather than replaced by ``fresh``, learned from that driving
    alone (``extensions.map_bias_keep_applied``). A ``fresh`` bias that fails the significance
    test only fails to tell the map's bias from zero on a stretch often far shorter than the
    approach the previous one was learned on: no evidence against that bias, which the refine
    weighs against the same stretch. Replacing it would make the applied-or-not decision of
    every later outage flip with small changes of that stretch. A ``fresh`` bias refused as
    another road's (or with a lane beyond the road) stands."""
    return previous.significant and not fresh.significant and fresh.refused is None


def honest_turn_consider(bias: MapBias | None, var: float) -> float:
    """The variance of the map's rotation error an outage considers (not estimated) under
    ``extensions.map_turn_honest_consider``: for an applied bias, at least its fitted
    rotation's honest second moment. A map found right keeps ``var``: its rotation is part
    of the null hypothesis the significance test accepted."""
    if bias is None or not bias.significant:
        return var
    return max(var, bias.turn_second_moment)


def unapplied_considered(bias: MapBias, *, tied: bool = False) -> MapBias:
    """``bias`` with, when it was learned but not applied, the bias seen added to the
    map-bias error the outage's pseudo-positions carry (``extensions.unapplied_bias_consider``).

    Not applying a bias that the significance test (or the test for another road) did not
    accept takes the map as right, and with ``offset.map_bias_null_sigma_m`` as exact: every
    pseudo-position then claims the shape noise alone, while the road may lie where the
    approach showed it. The map's error is estimated by the method of moments: the second
    moment of what was measured, ``m m^T``, less what the measurement's own covariance ``C``
    explains (negative directions dropped), so a right map whose bias is within its noise
    gains nothing. As a considered state (never estimated) it is shared by all of the
    outage's matches, so repeating them does not average it away.

    ``tied`` (``extensions.unapplied_bias_lane_tie``): the lane kept with a bias not applied is
    the cross-track offset seen near the portal, ``l - n . b`` with ``n`` the route's left
    normal there, so a map shifted by ``b`` leaves it off by ``n . b``: the lane's error is
    tied to the map's, and at the portal the two cancel across the road (the offset seen is
    right there) while where the road turns they do not, and the pseudo-positions' covariance
    says so; without it the lane held through a spiral carries the map's shift as a lane
    across every later normal with the shape noise's sigma. Not for a bias refused as another
    road. With ``extensions.unapplied_bias_estimate`` the outage's matches estimate both."""
    m, c = bias.measured, bias.measured_cov
    if bias.significant or not (np.all(np.isfinite(m)) and np.all(np.isfinite(c))):
        return bias
    w, v = np.linalg.eigh(np.outer(m, m) - 0.5 * (c + c.T))
    seen = (v * np.maximum(w, 0.0)) @ v.T
    cov = bias.cov.copy()
    cov[1:, 1:] += seen
    if not (tied and bias.refused is None and np.any(w > 0.0)):
        return dataclasses.replace(bias, cov=cov)
    normal = bias.gain[0]
    # d_lane = n . d_map: the pseudo-position's error d_map - n d_lane is the map's shift along
    # the portal's road there, and grows across as the road turns away from it
    cov[0, 0] += float(normal @ seen @ normal)
    cov[0, 1:] += normal @ seen
    cov[1:, 0] += seen @ normal
    return dataclasses.replace(bias, cov=cov, tied=True)


def release_turn(x: F64, P: F64, pivot: F64, var: float) -> None:
    """Add ``var`` (rad^2) of a turn about ``pivot`` (E, N) to the navigation state: yaw,
    the horizontal velocity turned with it (``e_up x v``) and the position turned about the
    pivot (``e_up x (p - pivot)``), fully correlated, as a map turned by that much moves a
    state its route updates held to it (``extensions.map_turn_release``)."""
    j = np.zeros(P.shape[0])
    j[E_ATT + 2] = 1.0
    j[E_VEL] = -x[X_VEL + 1]
    j[E_VEL + 1] = x[X_VEL]
    j[E_POS] = -(x[X_POS + 1] - pivot[1])
    j[E_POS + 1] = x[X_POS] - pivot[0]
    P += var * np.outer(j, j)


def turn_heading(x: F64, P: F64, var: float) -> None:
    """Add ``var`` (rad^2) of yaw turning the horizontal velocity with it (``dv / dpsi = e_up x
    v``): a heading error that the body-velocity updates cannot see, which a heading
    observation then corrects together with the velocity's direction."""
    j = np.zeros(P.shape[0])
    j[E_ATT + 2] = 1.0
    j[E_VEL] = -x[X_VEL + 1]
    j[E_VEL + 1] = x[X_VEL]
    P += var * np.outer(j, j)


def widen_to_innovation(P: F64, y: F64, s: F64) -> None:
    """Add ``c u u^T`` to the E/N position covariance, ``u`` the innovation's direction, so
    that the innovation ``y`` becomes one sigma of ``s + c u u^T`` (``s`` its covariance):
    with ``a = u^T s^-1 u``, Sherman-Morrison gives ``y^T (s + c u u^T)^-1 y = |y|^2 a /
    (1 + c a)``, so ``c = |y|^2 - 1 / a``. Widening the diagonal instead would be lost in a
    covariance whose along-track part is large and projects onto both axes."""
    size = float(np.hypot(*y))
    if size == 0.0:
        return
    u = y / size
    a = float(u @ np.linalg.solve(s, u))
    c = size * size - 1.0 / a if a > 0 else 0.0
    if c > 0.0:
        P[E_POS : E_POS + 2, E_POS : E_POS + 2] += c * np.outer(u, u)


ATTEMPTS_WALKED = 100_000
"""Attempt times inside one IMU gap that the outage loop steps through one by one (28 h at
the default 1 s); a gap holding more is crossed at once (:meth:`Driver._attempts_in_imu_gap`)."""
DRIFT_WINDOW_S = 10.0
"""s: the stretch over which a correction along the travel is compared with the along-track
sigma the filter claimed before it (``extensions.along_drift_evidence``)"""


def along_drift_psd(rows: F64, t_a: float, t: float) -> float:
    """The along-track velocity random walk (PSD, (m/s)^2/s) that the corrections inside the
    outage starting at ``t_a`` show the model lacks (``extensions.along_drift_evidence``).

    Over each ``DRIFT_WINDOW_S`` stretch ending on a whole second up to ``t``, the updates
    (route pseudo-positions, the non-holonomic constraint in a bend) moved the position along
    the travel by ``c`` beyond the dead-reckoned motion, where the filter claimed ``s`` (its
    along-track sigma at the stretch's start). An excess ``c^2 - s^2`` grown over the ``tau``
    seconds since the outage started is what a velocity random walk of PSD
    ``3 (c^2 - s^2) / tau^3`` adds (covariance matching); the largest over the stretches is
    returned, 0 where every correction is within its sigma (an honest along-track covariance)."""
    w = DRIFT_WINDOW_S
    tt = rows[:, O_T]
    if not len(tt):
        return 0.0
    # a stretch ending more than a window after the last row holds no row: left out before
    # it is made (an IMU gap of years would otherwise ask for a stretch per second of it)
    ends = np.arange(t_a + 2.0 * w, min(t, float(tt[-1]) + w) + 1e-9, 1.0)
    if ends.size == 0:
        return 0.0
    i1 = np.minimum(np.searchsorted(tt, ends, side="right") - 1, len(rows) - 1)
    i0 = np.searchsorted(tt, ends - w, side="right") - 1
    ok = (i0 >= 0) & (i1 > i0)
    i0, i1 = i0[ok], i1[ok]
    if i0.size == 0:
        return 0.0
    before = rows[i0]
    v = before[:, O_VEL : O_VEL + 2]
    speed = np.hypot(v[:, 0], v[:, 1])
    u = v / np.maximum(speed, 1e-9)[:, None]
    moved = rows[i1, O_POS : O_POS + 2] - before[:, O_POS : O_POS + 2]
    dr = rows[i1, O_DR : O_DR + 2] - before[:, O_DR : O_DR + 2]
    c = np.sum((moved - dr) * u, axis=1)
    s2 = np.einsum("ni,nij,nj->n", u, row_position_cov(before), u)  # u' P u along the travel
    tau = before[:, O_T] - t_a
    q = 3.0 * np.maximum(c * c - s2, 0.0) / np.maximum(tau, w) ** 3
    q[speed <= 1.0] = 0.0
    return float(np.max(q))


def grow_along_velocity(P: F64, x: F64, var: float) -> None:
    """Add ``var`` ((m/s)^2) to the velocity error's variance along the horizontal travel."""
    v = x[X_VEL : X_VEL + 2]
    speed = math.hypot(float(v[0]), float(v[1]))
    if var <= 0.0 or speed <= 1.0:
        return
    u = v / speed
    P[E_VEL : E_VEL + 2, E_VEL : E_VEL + 2] += var * np.outer(u, u)


def window_scale_sigma(out: F64, n_out: int, x: F64, P: F64, aux: F64, length_m: float) -> float:
    """1-sigma of the length error of the window over the last ``length_m`` of travel: the
    filter's velocity sigma along the direction of travel times the window's duration
    (``extensions.window_scale_covariance``).

    Dead-reckoned without wheel speed the window's length is the integral of a velocity that
    is wrong by that sigma; a bend matched with a window stretched by ``dv T`` is placed up to
    ``dv T`` off along the road, and the next attempts, sharing the window, the same way."""
    dist = out[:n_out, O_DIST]
    i0 = max(search_right(dist, float(aux[A_DIST]) - length_m) - 1, 0)
    duration = float(aux[A_TIME]) - float(out[i0, O_T]) if n_out > 0 else 0.0
    v = x[X_VEL : X_VEL + 2]
    speed = float(np.hypot(v[0], v[1]))
    if not (duration > 0.0 and speed > 0.0):
        return 0.0
    u = v / speed
    var = float(u @ P[E_VEL : E_VEL + 2, E_VEL : E_VEL + 2] @ u)
    return math.sqrt(max(var, 0.0)) * duration


def position_on_map_cov(P: F64) -> F64:
    """E/N covariance of the position relative to the road the route stands for: the
    position's, the map-bias error's (zero without ``extensions.map_bias``) and their
    cross-covariances (H P H^T with H = [I, I])."""
    pos, bias = slice(E_POS, E_POS + 2), slice(E_MAP, E_MAP + 2)
    cov: F64 = P[pos, pos] + P[bias, bias] + P[pos, bias] + P[bias, pos]
    return cov


def isotropic_excess(e: F64, C: F64, bound: float) -> float:
    """The least ``d`` >= 0 with ``e' (C + d I)^-1 e <= bound`` (2-D): the variance, equal in
    every direction, a covariance ``C`` lacked to hold the error ``e`` within the bound. The
    equation is the quadratic ``bound (det(C) + d tr(C) + d^2) = e' adj(C) e + d |e|^2``."""
    c11, c12, c22 = float(C[0, 0]), float(C[0, 1]), float(C[1, 1])
    e1, e2 = float(e[0]), float(e[1])
    det = c11 * c22 - c12 * c12
    adj = e1 * e1 * c22 - 2.0 * e1 * e2 * c12 + e2 * e2 * c11
    b = bound * (c11 + c22) - (e1 * e1 + e2 * e2)
    c = bound * det - adj
    if c >= 0.0:
        return 0.0
    return float((-b + math.sqrt(b * b - 4.0 * bound * c)) / (2.0 * bound))


def max_turn(xy: F64, stretch_m: float, spacing_m: float) -> float:
    """The largest heading change over any ``stretch_m`` of a polyline, in degrees (the
    polyline resampled every ``spacing_m`` from its end; compiled:
    :func:`estimator.matching.kernels.max_turn_deg`)."""
    pts = np.ascontiguousarray(np.asarray(xy, np.float64)[:, :2])
    return float(max_turn_deg(pts, float(stretch_m), float(spacing_m)))
