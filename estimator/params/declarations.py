"""The parameter tree: every estimator parameter declared once, with the doc, unit, bounds and step
that the CLI help, the TOML comments and the GUI sliders show."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal

Method = Literal["baseline", "proposed", "paper"]
"""``baseline``: GNSS/INS/ODO, plain DR in outages. ``proposed``: routefuse (the paper's method
plus every extension switched on in :class:`ExtensionParams`). ``paper``: the published method
only, every extension off."""


def param(
    default: Any,
    doc: str,
    *,
    unit: str = "",
    lo: float | None = None,
    hi: float | None = None,
    step: float | None = None,
    choices: tuple[str, ...] | None = None,
) -> Any:
    """A dataclass field carrying what the CLI, TOML and GUI need to present it."""
    meta = {"doc": doc, "unit": unit, "lo": lo, "hi": hi, "step": step, "choices": choices}
    if isinstance(default, tuple):
        return field(default_factory=lambda: default, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class TriggerParams:
    """When a route match is attempted (the paper's trigger control)."""

    min_outage_s: float = param(
        4.0,
        "GNSS must be absent this long before the first match",
        unit="s",
        lo=0,
        hi=120,
        step=0.5,
    )
    min_outage_distance_m: float = param(
        40.0,
        "DR distance driven inside the outage before the first match",
        unit="m",
        lo=0,
        hi=1000,
        step=5,
    )
    interval_s: float = param(
        1.0, "time between two match attempts (low-rate updates)", unit="s", lo=0.1, hi=30, step=0.1
    )
    min_approach_m: float = param(
        100.0,
        "driving with GNSS since the filter started that an outage needs before it takes route "
        "updates (extensions.calibrated_approach): fixes a metre apart fix the heading to about "
        "a degree only over 100 m, and a cross-track update on a heading, tilt and "
        "accelerometer bias that are not yet told apart turns the along-track velocity",
        unit="m",
        lo=0,
        hi=2000,
        step=10,
    )


@dataclass(frozen=True)
class WindowParams:
    """The DR window and the local route segment it is matched to."""

    length_m: float = param(
        250.0, "arc length of the DR window matched to the route", unit="m", lo=20, hi=3000, step=10
    )
    spacing_m: float = param(
        5.0,
        "spatial resampling interval of window and route segment",
        unit="m",
        lo=0.5,
        hi=50,
        step=0.5,
    )
    route_search_m: float = param(
        60.0,
        "arc-length search radius around the previous route projection",
        unit="m",
        lo=5,
        hi=2000,
        step=5,
    )
    along_search_m: float = param(
        30.0,
        "half-width of the along-track offset search of the route segment",
        unit="m",
        lo=1,
        hi=300,
        step=1,
    )
    along_search_max_m: float = param(
        300.0,
        "with extensions.covariance_search, the widest half-width the along-track search "
        "grows to (3 sigma of the filter's along-track position)",
        unit="m",
        lo=1,
        hi=2000,
        step=10,
    )
    along_search_step_m: float = param(
        1.0,
        "grid step of the along-track offset search (refined by a parabola)",
        unit="m",
        lo=0.1,
        hi=10,
        step=0.1,
    )
    long_length_m: float = param(
        1000.0,
        "arc length of the longer window tried when the standard one leaves along-track "
        "unobserved (extensions.long_window): a gentle bend is seen whole",
        unit="m",
        lo=20,
        hi=5000,
        step=50,
    )
    long_max_turn_deg: float = param(
        10.0,
        "the longer window is only tried where no window.length_m stretch of it turns more "
        "than this (sharper bends the standard window observes itself)",
        unit="deg",
        lo=0,
        hi=180,
        step=1,
    )


@dataclass(frozen=True)
class GateParams:
    """Quality gates: a failed gate skips the pseudo-position update."""

    min_pairs: int = param(20, "minimum number of valid point pairs", lo=3, hi=500, step=1)
    max_heading_diff_deg: float = param(
        10.0,
        "terminal heading gate: angle between DR and route end directions (signed cos)",
        unit="deg",
        lo=0.5,
        hi=90,
        step=0.5,
    )
    max_residual_m: float = param(
        3.0, "RMS registration residual after the rigid fit", unit="m", lo=0.1, hi=50, step=0.1
    )
    max_correction_m: float = param(
        30.0, "cap on a single correction |z - p_dr|", unit="m", lo=0.5, hi=500, step=0.5
    )
    max_rotation_deg: float = param(
        15.0, "largest fitted rotation accepted", unit="deg", lo=0.5, hi=180, step=0.5
    )
    mahalanobis_chi2: float = param(
        13.8,
        "chi-square gate on the match innovation, S = P_EN + R_k (P_EN with the map-bias error "
        "where carried; 2 dof; 13.8 = 99.9 %)",
        lo=1,
        hi=1000,
        step=0.5,
    )
    rotation_chi2: float = param(
        10.8,
        "chi-square gate on the fitted rotation read as a heading correction, against the "
        "filter's yaw variance plus the map's rotation variance plus the fit's own heading "
        "variance (1 dof; 10.8 = 99.9 %, the Mahalanobis gate's confidence; "
        "extensions.rotation_consistency)",
        lo=1,
        hi=1000,
        step=0.5,
    )
    max_lateral_jump_m: float = param(
        5.0,
        "largest move of the vehicle across the route away from its learned lane offset",
        unit="m",
        lo=0.5,
        hi=100,
        step=0.5,
    )
    alternative_shift_m: float = param(
        25.0,
        "lateral shift of the rival route segments (a parallel road or bore)",
        unit="m",
        lo=2,
        hi=200,
        step=1,
    )
    alternative_margin: float = param(
        2.0,
        "how much worse (chi-square units) every rival must fit than the candidate",
        lo=0,
        hi=100,
        step=0.5,
    )
    reanchor_after: int = param(
        5,
        "consecutive shape-valid matches refused only for disagreeing with the filter before "
        "the filter is re-anchored to the route (extensions.reanchor)",
        lo=2,
        hi=100,
        step=1,
    )
    dr_separation_chi2: float = param(
        13.8,
        "chi-square bound on how far the outage's route updates may move the position from "
        "its dead-reckoning twin, against P_dr - P (2 dof; extensions.dr_separation)",
        lo=1,
        hi=1000,
        step=0.5,
    )
    dr_separation_floor_m: float = param(
        1.0,
        "smallest sigma of the separation from dead reckoning (extensions.dr_separation): "
        "where the route added almost nothing, P_dr - P is near zero",
        unit="m",
        lo=0.01,
        hi=100,
        step=0.1,
    )
    reanchor_gyro_bias_deg_s: float = param(
        0.25,
        "largest unmodelled gyro bias a re-anchor may blame: an innovation larger than the "
        "drift it gives since GNSS was lost (theta = b t, off-track about theta * D / 2) is a "
        "wrong road, not drift",
        unit="deg/s",
        lo=0,
        hi=5,
        step=0.01,
    )


@dataclass(frozen=True)
class PseudoObsParams:
    """The E/N pseudo-position observation."""

    sigma_m: float = param(
        2.0,
        "1-sigma of the pseudo-position (the paper's conservative, isotropic R)",
        unit="m",
        lo=0.05,
        hi=100,
        step=0.05,
    )
    cross_sigma_m: float = param(
        0.3,
        "smallest cross-track 1-sigma when R follows route geometry",
        unit="m",
        lo=0.05,
        hi=100,
        step=0.05,
    )
    cross_residual_factor: float = param(
        8.0,
        "cross-track 1-sigma is at least this many registration residuals: a window the route "
        "fits to centimetres holds the estimate to the route, one it fits loosely (a coarse "
        "map cutting a curve) only softly",
        lo=0,
        hi=100,
        step=0.5,
    )
    along_sigma_min_m: float = param(
        0.5,
        "smallest along-track 1-sigma derived from route shape",
        unit="m",
        lo=0.01,
        hi=100,
        step=0.05,
    )
    along_sigma_max_m: float = param(
        100.0,
        "along-track 1-sigma where route shape does not observe it (straight road)",
        unit="m",
        lo=1,
        hi=10000,
        step=1,
    )
    shape_noise_m: float = param(
        1.0,
        "per-point noise of DR and route shape (map error, corner cutting) assumed when "
        "deriving the along-track sigma and comparing rivals",
        unit="m",
        lo=0.01,
        hi=20,
        step=0.05,
    )
    gap_bridge_heading_sigma_deg: float = param(
        1.0,
        "1-sigma of the road's heading as the vehicle's after an IMU gap bridged along the route "
        "(extensions.gap_route_bridge): the map's polyline against the curve, and the vehicle's "
        "own angle to its lane; the map's rotation uncertainty is added to it",
        unit="deg",
        lo=0.05,
        hi=20,
        step=0.05,
    )
    weak_along_disagreement: float = param(
        5.0,
        "extensions.weak_along_track refuses a fit's along-track only when it also disagrees "
        "with the filter's along-track position by more than this many of the filter's "
        "along-track sigmas (0: whenever the fit is the weaker)",
        unit="sigma",
        lo=0,
        hi=100,
        step=0.5,
    )
    weak_along_max_chi2: float = param(
        13.8,
        "extensions.weak_along_track applies a fit across the road only while its along-track "
        "innovation is within this chi-square of the fit's and the filter's along-track sigmas "
        "together (1 dof); a fit farther off is wrong, not weak, and goes to the gates whole",
        lo=1,
        hi=1000,
        step=0.5,
    )


@dataclass(frozen=True)
class OffsetParams:
    """Route offset compensation: keep the lane offset the vehicle had under good GNSS."""

    enabled: bool = param(True, "add the learned lateral lane offset to the pseudo-position")
    time_constant_s: float = param(
        20.0, "averaging time constant of the learned offset", unit="s", lo=0.5, hi=600, step=0.5
    )
    max_offset_m: float = param(
        8.0, "offsets larger than this are not learned (off-route)", unit="m", lo=0, hi=50, step=0.5
    )
    map_bias_track_m: float = param(
        1600.0,
        "GNSS-good driving before an outage registered to the route to learn the map's bias "
        "(extensions.map_bias; with offset.map_turn_lower_sigmas, since a long approach's "
        "rotation sigma is small enough for the method of moments to make a rotation of a "
        "one-sigma draw)",
        unit="m",
        lo=50,
        hi=3000,
        step=50,
    )
    map_bias_portal_cut_s: float = param(
        8.0,
        "with extensions.map_bias_portal_cut, the map-bias fit's approach ends this long "
        "before the outage starts",
        unit="s",
        lo=0,
        hi=60,
        step=1,
    )
    map_bias_prior_sigma_m: float = param(
        10.0,
        "1-sigma of the map's bias before it is learned (what an unobserved direction keeps)",
        unit="m",
        lo=0.1,
        hi=100,
        step=0.5,
    )
    map_bias_walk_m_per_sqrt_km: float = param(
        0.5,
        "random walk of the map's bias along the road: its 1-sigma grows by this after 1 km",
        unit="m/sqrt(km)",
        lo=0,
        hi=1000,
        step=0.5,
    )
    map_bias_cross_sigma_m: float = param(
        5.0,
        "1-sigma of the map's bias across the road before it is learned: a straight approach "
        "cannot tell the lane from a map shifted sideways, and this prior with "
        "offset.map_bias_lane_sigma_m shares the offset seen out between them",
        unit="m",
        lo=0.1,
        hi=100,
        step=0.1,
    )
    map_bias_lane_prior_m: float = param(
        -1.75,
        "the vehicle's lane offset from the road's centreline expected before it is learned "
        "(positive = left): half a 3.5 m lane to the right in right-hand traffic",
        unit="m",
        lo=-10,
        hi=10,
        step=0.05,
    )
    map_bias_lane_sigma_m: float = param(
        2.0,
        "1-sigma of the vehicle's lane offset from the road's centreline (the prior that keeps "
        "a sideways map shift from being taken for a lane the vehicle keeps through bends)",
        unit="m",
        lo=0.1,
        hi=20,
        step=0.1,
    )
    map_bias_rotation_sigma_deg: float = param(
        1.0,
        "1-sigma of the map's rotation before it is learned (a map drawn turned about the "
        "portal is shifted more the further into the tunnel)",
        unit="deg",
        lo=0.01,
        hi=20,
        step=0.1,
    )
    map_bias_max_prior_sigmas: float = param(
        3.0,
        "a bias further from zero than this many of its prior sigmas is not a map's error but "
        "another road: nothing is learned",
        lo=0.5,
        hi=20,
        step=0.1,
    )
    map_bias_null_sigma_m: float = param(
        0.0,
        "1-sigma of the map-bias error carried when the learned bias is not significant and "
        "is not applied",
        unit="m",
        lo=0,
        hi=20,
        step=0.1,
    )
    map_bias_min_sigmas: float = param(
        3.0,
        "a bias whose chi-square against zero (2 dof, its full covariance) is below this "
        "squared is not applied",
        lo=0,
        hi=10,
        step=0.1,
    )
    map_turn_two_places_min_sigmas: float = param(
        2.0,
        "the rotation learned from two places (extensions.map_turn_two_places) is applied "
        "where it differs from zero by this many sigmas (its prior is the honest second "
        "moment of the rotation the approach fitted, so a right map's stays near zero)",
        lo=0,
        hi=10,
        step=0.1,
    )
    map_bias_estimated: bool = param(
        True,
        "the route pseudo-positions of an outage also estimate the learned lane offset's and "
        "map bias's errors (a bend tells a sideways map shift from a lane; else they are only "
        "considered)",
    )
    map_bias_refine: bool = param(
        True,
        "where the GNSS-good driving since the previous outage is too short to learn the map's "
        "bias afresh, refine the previous outage's bias with it (a stretch that turns fixes the "
        "along-track bias the outage's matches cannot) instead of carrying it unchanged",
    )
    map_bias_turn_walk: bool = param(
        True,
        "an applied rotation's uncertainty also grows the map-bias error as a random walk, "
        "beside extensions.map_turn_consider (the walk lets the outage's matches re-estimate "
        "the bias where the road turns; off, the considered rotation alone carries it)",
    )
    map_bias_walk_turned_only: bool = param(
        False,
        "an applied bias's error grows by offset.map_bias_walk_m_per_sqrt_km in the outage only "
        "where the approach fitted a rotation beyond its noise (a map turned away from the "
        "bias learned at the portal); else the learned bias stays correlated with the position "
        "error it was cloned from, and the tunnel's bends refine it instead of taking the "
        "dead-reckoned drift for a change of the map",
    )
    map_bias_turned_rescue: bool = param(
        True,
        "a bias that the test for another road (offset.map_bias_max_prior_sigmas) refuses as a "
        "shift but passes with the fitted rotation, two sigmas from zero if not three, is applied "
        "with that rotation and its sigma (a map drawn turned about a point far into a long "
        "tunnel is metres off at the portal)",
    )
    map_bias_far_turned: bool = param(
        True,
        "an approach that fits the route only with a shift beyond the map's local prior "
        "(offset.map_bias_cross_sigma_m) is fitted again with the shift's prior widened by the "
        "rotation's share, as offset.map_bias_turn_prior does, and the bias is applied when its "
        "rotation is significant and passes the test for another road (a map drawn turned about "
        "a point kilometres into a long tunnel is tens of metres off at the portal)",
    )
    map_bias_wander_rows: bool = param(
        False,
        "the map-bias fit takes the approach's error as the filter's GNSS wander (a "
        "Gauss-Markov process of noise.gnss_wander_tau_s, correlated along the track) rather "
        "than one error common to the whole approach: the far part of a long approach, whose "
        "wander the outage start shares only in part, weighs less and passes less of the "
        "position error on to the lane and map-bias errors the outage clones (the fit learned "
        "afresh before an outage; a carried bias's refinement keeps one common error)",
    )
    map_bias_far_turned_passes: int = param(
        3,
        "Gauss-Newton passes of offset.map_bias_far_turned's fit, each against the route moved "
        "back by the fit so far",
        lo=1,
        hi=10,
        step=1,
    )
    map_bias_turn_prior: bool = param(
        True,
        "a map bias applied with its rotation takes its values from a fit whose prior on the "
        "shift at the approach's end includes what the map's rotation "
        "(offset.map_bias_rotation_sigma_deg) about an unknown point within "
        "offset.map_bias_track_m times ten of route puts there (the decisions stay those of the "
        "fit without it); without it a map turned about a point far from the portal, tens of "
        "metres off there, has its shift held at offset.map_bias_cross_sigma_m and the fitted "
        "lane and rotation take the rest",
    )
    map_turn_honest_prior: bool = param(
        True,
        "with extensions.map_turn_estimate, an applied bias whose fitted rotation is not "
        "applied starts the outage's rotation error from its honest second moment (the "
        "rotation's square plus its variance) instead of the method of moments (its square "
        "less its variance, often zero): the matches cannot tell the map's rotation from the "
        "dead-reckoned heading's drift, so on a right map they then turn the map instead of "
        "the heading",
    )
    map_turn_lower_sigmas: float = param(
        2.0,
        "a map rotation fitted on the approach but not applied is considered in the outage "
        "as the least rotation the fit shows at this many of its sigmas, (|a| - k sigma)^2, "
        "instead of the method of moments (a^2 less its variance, positive for any draw beyond "
        "one sigma on a right map) (0: the method of moments; goes with "
        "offset.map_bias_track_m 1600: at 800 m it loses turned maps)",
        unit="sigma",
        lo=0.0,
        hi=3.0,
        step=0.1,
    )
    map_turn_min_heading_ratio: float = param(
        1.2,
        "with extensions.map_turn_estimate, a rotation fitted on the approach but not applied "
        "is estimated in the outage only where its prior sigma (method of moments) is at "
        "least this many times the filter's heading sigma at the outage start: a map turned "
        "about the portal and a heading error there move the pseudo-positions alike, so a "
        "rotation prior no larger than the heading's lets the matches take the heading's "
        "error for the map's rotation (0: always)",
        lo=0.0,
        hi=10.0,
        step=0.1,
    )
    map_bias_max_residual_m: float = param(
        3.0,
        "a GNSS track fitting the route worse than this (RMS) teaches no bias (another road)",
        unit="m",
        lo=0.1,
        hi=50,
        step=0.1,
    )


@dataclass(frozen=True)
class ExtensionParams:
    """routefuse's additions beyond the paper; each can be switched off (``--method paper``)."""

    geometry_covariance: bool = param(
        True, "observation covariance follows route geometry (along-track weak on straights)"
    )
    candidate_validation: bool = param(
        True,
        "reject candidates that fit worse than shifted/reversed alternatives, or whose "
        "innovation is improbable (Mahalanobis)",
    )
    along_track_search: bool = param(
        True, "search the route arc-length offset that minimises the residual"
    )
    lane_path_matching: bool = param(
        True,
        "register the window to the route shifted by the learned lane offset (the lane's "
        "own arc length on curves) instead of adding the offset after the fit",
    )
    long_window: bool = param(
        True,
        "where the standard window sees too little of the road's shape to fix along-track "
        "position (a straight, or a bend gentler than the window), also try a "
        "window.long_length_m window and use it if it passes every gate and observes along-track",
    )
    heading_observation: bool = param(False, "feed the fitted rotation as a heading observation")
    lane_offset_state: bool = param(
        True,
        "carry the learned lane offset's error (shared by all of an outage's matches) as a "
        "filter state cloned from the cross-track position error at the outage start, so the "
        "position covariance in a tunnel stays honest",
    )
    robust_gnss: bool = param(
        True,
        "test each fix against the filter with the typical fix variance and inflate the "
        "disagreeing ones; after a gap, use fixes only once they agree with each other",
    )
    portal_rerun: bool = param(
        True,
        "when GNSS drops out, re-process the last noise.gnss_rerun_lag_s without the fixes "
        "that disagree with dead reckoning (fixed-lag re-run from a saved state)",
    )
    portal_rerun_after_alignment: bool = param(
        True,
        "the portal re-run keeps noise.gnss_rerun_lag_s between an alignment (the start, or "
        "after an IMU gap) and the state it saves: a filter still calibrating its velocity "
        "and heading dead-reckons away from every good fix (comma2k19 without wheel speed, "
        "an outage 10 s after the start: every fix from 3.8 s dropped, the filter 17 m off "
        "as the outage began)",
    )
    align_track_accel: bool = param(
        True,
        "an alignment in motion without wheel speed takes the car's acceleration from the "
        "GNSS track (a parabola through the aligning chord's fixes, weighed against a 1 m/s^2 "
        "prior; none where they cannot tell it) when it levels the accelerometer, and widens "
        "the tilt's sigma by what it leaves unknown: comma2k19 starts accelerating 1.4 m/s^2, "
        "levelled 9 deg nose-up under a 1.5 deg sigma without it",
    )
    align_track_accel_ahead: bool = param(
        True,
        "with align_track_accel, where the aligning chord holds too few fixes for the parabola "
        "(a 1-2 Hz receiver: two or three), the fixes after the aligning one are added until "
        "six, within 5 s of the chord's start: comma2k19 thinned to 2 Hz was levelled 6.6 deg "
        "nose-up without them",
    )
    wheel_scale_state: bool = param(True, "estimate the wheel-speed scale factor as a state")
    gyro_scale_consider: bool = param(
        True,
        "carry the z gyro's scale-factor error (noise.gyro_scale_sigma_ppm) as a considered "
        "state: the heading error it makes grows with the angle turned, not with time, and "
        "is one quantity over the drive, so bias and white-noise terms cannot cover it (a "
        "spiral tunnel turns the heading by its full error many times)",
    )
    gyro_scale_blind_gain: bool = param(
        True,
        "with gyro_scale_consider: no update's gain uses the considered scale factor (the "
        "estimate is the one of the filter without it) and the covariance is updated for "
        "that gain, so the gates, the separation test and the reported sigma cover the "
        "error the scale makes while the dead reckoning stays the defaults'",
    )
    gyro_scale_state: bool = param(
        False,
        "estimate the z gyro's scale factor as a state (prior noise.gyro_scale_sigma_ppm), "
        "applied in the mechanisation and calibrated wherever GNSS sees the heading after a "
        "turn; supersedes gyro_scale_consider",
    )
    overlap_inflation: bool = param(
        False,
        "count the along-track evidence of overlapping windows once: an accepted match's "
        "along-track variance is multiplied by the window length over the distance since the "
        "previous accepted match",
    )
    route_errors_overlap_share: bool = param(
        True,
        "where an outage considers the map's rotation without estimating it, the estimated "
        "route errors (lane offset, map bias) take an accepted match's cross-track evidence in "
        "proportion to the road its window adds to the previous accepted match's (the "
        "distance since over the window length, at most 1; a partial update, the covariance in "
        "Joseph form); the position keeps the whole gain. The considered rotation regrows the "
        "map bias's variance with the distance driven, so it is re-learned match by match, and "
        "consecutive windows share most of their road and dead-reckoned shape: counted each "
        "second, their one cross-track error walks the map bias, and the pseudo-positions "
        "taken from the map it moves walk along",
    )
    weak_along_track: bool = param(
        True,
        "a match whose along-track sigma is larger than the filter's own along-track sigma and "
        "whose along-track innovation exceeds pseudo.weak_along_disagreement of the filter's "
        "sigmas is applied across the road only, at the dead-reckoned along-track position: it "
        "would add little along the road but carry the window's shape error there (a gentle "
        "bend under a gyro drift fits metres to tens of metres off, the same way attempt after "
        "attempt); off without wheel speed under no_wheel_caution",
    )
    rotation_consistency: bool = param(
        False,
        "refuse a match whose fitted rotation, read as a heading correction, the filter's yaw "
        "covariance (with the map's rotation and the fit's heading sigma) cannot support "
        "(gates.rotation_chi2): the Mahalanobis gate tests only the position, whose "
        "covariance is stretched along the direction of travel; a window turned far beyond "
        "the heading's sigma means the route is drawn wrong there or the filter's heading "
        "is, and either way the position update spreads the cross-track innovation along "
        "the filter's own track. Off: the fit's heading sigma leaves out the route's own "
        "direction error, and on a route drawn from the robot's own fixes (the Husky lot with "
        "wheel speed) it refuses good matches",
    )
    reanchor: bool = param(
        False,
        "when consecutive shape-valid matches with no better-shaped rival keep being refused "
        "only for disagreeing with the filter, by no more than a plausible dead-reckoning drift, "
        "widen the filter's position and heading covariance to the innovation and accept",
    )
    gap_reacquire: bool = param(
        True,
        "after an IMU gap in an outage, whose heading the wheels carried straight across it, "
        "re-anchor to the route (as extensions.reanchor) once gates.reanchor_after consecutive "
        "windows wholly after the gap fit it turned by at most 45 deg and placed within what the "
        "gap explains, refused only for disagreeing with the filter's heading and place",
    )
    gap_route_bridge: bool = param(
        True,
        "after an IMU gap in an outage, where the route placed the vehicle up to a window "
        "before it, place it where the wheels' distance along the route puts it and turn its "
        "heading to the road's there (pseudo.gap_bridge_heading_sigma_deg): the gap carried "
        "it straight along the old heading, off the road wherever the road turned inside it",
    )
    curvature_covariance: bool = param(
        False,
        "a pseudo-position's cross-track variance includes how far the road bends away from "
        "its tangent over the along-track uncertainty of the match (the filter's, or the fit's "
        "where the shape observes it): a road 150 m further round a bend is 5 m off the "
        "tangent, and the cross-track direction turning along a bend otherwise claims "
        "along-track position nobody observed",
    )
    covariance_search: bool = param(
        False,
        "widen the along-track search to 3 sigma of the filter's own along-track position "
        "(up to window.along_search_max_m) when that exceeds window.along_search_m, and pair a "
        "window whose along-track stays unobserved at the nearest place its shape allows: "
        "without wheel speed the dead-reckoned position slides hundreds of metres along the "
        "road, and a bend searched only +-30 m around it is paired with the wrong stretch",
    )
    window_scale_covariance: bool = param(
        False,
        "a fit's along-track variance includes the window's own length error: the filter's "
        "velocity sigma along the track times the window's duration. Dead-reckoned without "
        "wheel speed, the window is stretched or shrunk by the velocity error, and a bend "
        "fitted with a stretched window is placed that much off along the road, the same way "
        "attempt after attempt",
    )
    cross_track_heading_widen: bool = param(
        False,
        "the first fix after an outage widens the heading's variance by the heading error that "
        "explains only its innovation across the travel, not along it (a heading error moves "
        "the vehicle sideways; the along-track part is a speed error, which taken for heading "
        "error lets that fix and the next turn the velocity); on through no_wheel_caution",
    )
    calibrated_approach: bool = param(
        False,
        "an outage takes route updates only after trigger.min_approach_m of driving with GNSS "
        "since the filter started; before that the outage is dead-reckoned, with a warning "
        "naming it. Without wheel speed a filter that has barely moved under GNSS cannot vouch "
        "for the updates: its heading, tilt, mounting and accelerometer bias are one blur, and "
        "every cross-track update moves the along-track velocity through them; on through "
        "no_wheel_caution",
    )
    along_drift_evidence: bool = param(
        False,
        "where an outage's updates (route pseudo-positions, the non-holonomic constraint in a "
        "bend) correct the position along the travel over 10 s by more than the along-track "
        "sigma the filter claimed before, the excess is along-track drift "
        "the model does not have (an accelerometer scale or mounting error, no odometer to bound "
        "it): estimate it as a velocity random walk along the travel (the excess variance over "
        "the time it grew in, covariance matching) and add it to the filter for the rest of the "
        "outage, so the covariance after a bend's along-track correction covers the regrowth; "
        "on through no_wheel_caution",
    )
    exit_adapt: bool = param(
        True,
        "where a dead-reckoned outage (no route update applied in it, the IMU running) ended "
        "farther from the fixes after it than its sigmas allow (the exit check, chi-square "
        "over 13.8), each later outage's horizontal position takes a random walk (until a fix "
        "is accepted after it): the least that would have put that exit within the 95 % bound "
        "over the time it ran, the walks of several such exits added. Dead reckoning shown to "
        "drift beyond its model is not trusted to the same sigmas again; only the covariance "
        "widens (no dead-reckoned estimate moves inside the outage), so route updates weigh "
        "more and pass their gates more readily; a run whose exits all pass is unchanged",
    )
    search_correction_cap: bool = param(
        False,
        "with covariance_search, a match's correction |z - p_dr| is capped at the half-width "
        "the along-track search was widened to (3 sigma of the filter's own along-track "
        "position, up to window.along_search_max_m) where that exceeds gates.max_correction_m: "
        "a correction the search was widened to find, and the Mahalanobis gate lets through, "
        "is no blunder; refused by a fixed 30 m cap, a filter that dead reckoning left 70 m "
        "off along the road cannot be put back by the bend that shows it; on through "
        "no_wheel_caution",
    )
    no_wheel_caution: bool = param(
        True,
        "on a log without wheel speed, switch on covariance_search, curvature_covariance, "
        "overlap_inflation, window_scale_covariance, cross_track_heading_widen, "
        "calibrated_approach, along_drift_evidence and search_correction_cap (the "
        "dead-reckoned along-track position is then uncertain by tens to hundreds of metres, "
        "which is what they are for) and "
        "offset.map_turn_honest_prior "
        "(the weak heading is otherwise turned by a map rotation the approach could not tell "
        "from zero), and switch off weak_along_track and dr_separation (the filter's own "
        "covariance is then no yardstick); a log with wheel speed is matched as the other "
        "switches say",
    )
    map_bias: bool = param(
        True,
        "learn where the route lies relative to the road driven (along and across) from the "
        "GNSS-good track before each outage, take pseudo-positions from the route moved back by "
        "it, and carry its uncertainty, shared by all of an outage's matches, in their covariance",
    )
    unapplied_bias_consider: bool = param(
        True,
        "when the map bias learned before an outage is not applied (not significant, or too "
        "large for a map's error), its pseudo-positions still carry the bias seen as a "
        "considered map error shared by all of the outage's matches (the measured bias's "
        "second moment less its own covariance): a test that fails to reject zero is no "
        "evidence that the map is exact",
    )
    unapplied_bias_lane_tie: bool = param(
        True,
        "with extensions.unapplied_bias_consider, the lane offset kept with a bias not applied "
        "(the cross-track offset seen near the portal, lane and map together) is tied to the "
        "considered map error (a map shifted by b leaves that lane off by n . b, n the "
        "portal's normal): the pseudo-positions' covariance grows across where the road turns "
        "away from the portal's direction, instead of holding the map's shift as a lane",
    )
    unapplied_bias_estimate: bool = param(
        False,
        "with extensions.unapplied_bias_lane_tie, the outage's pseudo-positions also estimate "
        "the tied lane and map errors of a bias not applied (offset.map_bias_estimated): a "
        "bend tells the map's shift from the lane",
    )
    map_bias_keep_applied: bool = param(
        True,
        "a map bias applied in the previous outage is carried to the next (refined by the "
        "GNSS-good driving in between) unless the bias learned afresh from that driving is "
        "significant itself: a short stretch that cannot tell the map's bias from zero is no "
        "evidence against the one a longer approach established, and the applied-or-not "
        "decision would otherwise flip on small changes of the stretch",
    )
    map_bias_carry_turned: bool = param(
        True,
        "a map bias applied in the previous outage is also carried to the next (as with "
        "extensions.map_bias_keep_applied) when the one learned afresh is refused as too large "
        "for a map's error but is the shift the carried bias, turned by its rotation over the "
        "kilometres between, predicts there (within offset.map_bias_max_prior_sigmas of the "
        "two covariances): a map turned a degree is tens of metres off one tunnel further on, "
        "which the generic prior calls another road",
    )
    map_bias_portal_cut: bool = param(
        False,
        "the map-bias fit's approach (and its refinement) ends offset.map_bias_portal_cut_s "
        "before the outage starts: receivers degrade near portals (multipath jumps, a slowly "
        "growing bias reported as white), and the fixes there the filter still used would "
        "otherwise pull the fitted lane, shift and rotation. Off: the robust GNSS test "
        "already leaves most of them out, and the stretch also carries the approach's last "
        "geometry (scripts/portal_fit.py; docs/integrity.md)",
    )
    dr_separation: bool = param(
        True,
        "run a dead-reckoning twin of the filter through each outage (no route updates) and, "
        "when the route updates have moved the position further from it than P_dr - P allows "
        "(gates.dr_separation_chi2), go back to the twin's state and take no more route "
        "updates in that outage: a map that pulls the estimate away from dead reckoning "
        "beyond its own confidence is wrong, and so is a filter that believes it",
    )
    dr_separation_gyro_scale: bool = param(
        True,
        "the dead-reckoning twin considers the z gyro's scale-factor error "
        "(noise.gyro_scale_sigma_ppm) even where the filter does not: dead reckoning's heading "
        "error grows with the angle turned, and a twin that leaves it out takes a right route "
        "through a spiral for a wrong one (the filter's own estimate is untouched)",
    )
    map_turn_consider: bool = param(
        True,
        "carry the map's rotation error (the applied rotation's variance, or the second "
        "moment of one fitted on the approach but not applied) as a considered state of the "
        "outage's pseudo-positions: the map's error grows with the distance from where the bias "
        "was learned as one quantity shared by all of the outage's matches, beside the random "
        "walk (which repeated matches average away while they turn the heading to the map's, "
        "but which lets them re-estimate an applied bias where the road turns)",
    )
    map_turn_honest_consider: bool = param(
        False,
        "where an applied bias's fitted rotation is neither applied nor estimated in the "
        "outage, its pseudo-positions consider the rotation with its honest second moment "
        "(its square plus its variance), as does a bias carried to the next outage, instead "
        "of the method of moments (its square less its variance, often zero): a fit within its "
        "noise does not show the map unturned, and kilometres from where it was learned a "
        "tenth of a degree is metres the pseudo-positions must not claim to know",
    )
    map_turn_release: bool = param(
        True,
        "at the end of an outage whose route updates followed an applied bias, add to the "
        "heading, velocity and position the map's rotation error they took from it unaccounted "
        "(its honest second moment less the variance the outage carried), fully correlated as "
        "a turned map moves them (the position turned about the bias's pivot): a heading held "
        "to the map's is only as good as the map's rotation is known, and the first fixes "
        "then correct it together with the position it explains",
    )
    map_turn_two_places: bool = param(
        True,
        "where a bias is carried to the next outage and refined by the GNSS-good driving in "
        "between, learn the map's rotation from the two places: the carried shift grows "
        "across the line between them with the rotation's honest second moment (not the "
        "method of moments' zero), and the refine fits the rotation about its own place with "
        "that prior, applied (with its sigma, the pivot moved there) when significant. One "
        "approach cannot tell a map's turn from the heading's drift; two GNSS-measured shifts "
        "kilometres apart can",
    )
    map_turn_two_places_applied: bool = param(
        True,
        "where the carried bias applies a rotation, the rotation learned from two places "
        "(extensions.map_turn_two_places) corrects it whatever its significance: its prior is "
        "the applied rotation's own variance, so the fit is that rotation's posterior, and "
        "the test against zero (offset.map_turn_two_places_min_sigmas) is for whether to "
        "apply a rotation at all; refused, the plain refine keeps the rotation the previous "
        "outage's matches left and extrapolates it from the first pivot",
    )
    map_turn_estimate: bool = param(
        True,
        "estimate the map's rotation error in the outage instead of only considering it, "
        "where the outage's pseudo-positions estimate the map's bias (an applied bias), match "
        "to the route turned back by what they learned and carry it to the next outage; where "
        "the bias is not applied it stays considered (the matches cannot tell the map's "
        "rotation from the heading's drift, which on a right map they would take for it)",
    )


@dataclass(frozen=True)
class NoiseParams:
    """Sensor noise and filter tuning (SI units except where the unit says otherwise)."""

    gyro_arw_deg_sqrt_h: float = param(
        0.3, "gyro angle random walk", unit="deg/sqrt(h)", lo=0.001, hi=100, step=0.01
    )
    accel_vrw_m_s_sqrt_h: float = param(
        0.2, "accelerometer velocity random walk", unit="m/s/sqrt(h)", lo=0.001, hi=100, step=0.01
    )
    gyro_bias_sigma_deg_h: float = param(
        10.0, "gyro bias instability (Gauss-Markov sigma)", unit="deg/h", lo=0.01, hi=1000, step=0.5
    )
    gyro_bias_tau_s: float = param(
        3600.0, "gyro bias correlation time", unit="s", lo=1, hi=100000, step=10
    )
    accel_bias_sigma_mg: float = param(
        2.0,
        "accelerometer bias instability (Gauss-Markov sigma)",
        unit="mg",
        lo=0.001,
        hi=100,
        step=0.1,
    )
    along_drift_share: float = param(
        0.1,
        "with extensions.along_drift_evidence, the share of the along-track velocity random "
        "walk the outage's corrections show (covariance matching) that is added: one stretch's "
        "excess is a single chi-square sample, and a bend's correction also carries the "
        "attitude and the window's shape errors; 1 takes it whole (on the 42 IMU-only cases "
        "1 and 0.2 lose the long-tunnel sim 20, 0.05 no longer wins sim 12)",
        lo=0.0,
        hi=10.0,
        step=0.01,
    )
    exit_walk_max_m2_s: float = param(
        100.0,
        "with extensions.exit_adapt, the largest random walk of the horizontal position the "
        "exits of a run add up to (100 m^2/s: a 100 m sigma after 100 s): fixes worse than "
        "they claim (a receiver's wander at walking speed) can flag every outage, and the "
        "walks must not then grow without end; the IMU-only sims' largest is 12.7",
        unit="m^2/s",
        lo=0.0,
        hi=10000.0,
        step=1.0,
    )
    accel_bias_tau_s: float = param(
        3600.0, "accelerometer bias correlation time", unit="s", lo=1, hi=100000, step=10
    )
    wheel_speed_sigma_m_s: float = param(
        0.1, "wheel speed observation 1-sigma", unit="m/s", lo=0.001, hi=5, step=0.01
    )
    nhc_sigma_m_s: float = param(
        0.1,
        "non-holonomic constraint 1-sigma (lateral and vertical body velocity)",
        unit="m/s",
        lo=0.001,
        hi=5,
        step=0.01,
    )
    nhc_mount_sigma_deg: float = param(
        0.0,
        "1-sigma of the IMU's misalignment with the vehicle's axes that the non-holonomic "
        "constraint assumes away, added to its variance as (speed x angle)^2: an IMU turned "
        "by an angle the config does not give sees speed x sin(angle) across and up, and a "
        "constraint that calls that zero within noise.nhc_sigma_m_s holds the pitch on its "
        "own flight path while the accelerometer bias takes the gravity, confident and wrong "
        "in the outages after (comma2k19 without its 3.8 deg mount, no wheels, 20-50 s: 33 m "
        "RMS off, NEES 17; with 2 deg here 15 m, NEES 1.3). 0: off, as the simulated drives need "
        "it (their gyros, 300-700 deg/h off, are held by the tight constraint: with 2 deg "
        "the IMU-only sims' dead reckoning is worse on 22 of 29); set it for a real vehicle "
        "whose mount is not given (the accelerometer-bias warning)",
        unit="deg",
        lo=0.0,
        hi=10.0,
        step=0.1,
    )
    gnss_sigma_floor_m: float = param(
        0.5,
        "smallest GNSS horizontal 1-sigma trusted, whatever the message claims",
        unit="m",
        lo=0.01,
        hi=50,
        step=0.05,
    )
    gnss_chi2_gate: float = param(
        16.0,
        "chi-square gate on the GNSS innovation, tested on horizontal (2 dof) and "
        "vertical (1 dof) separately",
        lo=1,
        hi=1000,
        step=0.5,
    )
    gnss_sigma_default_m: float = param(
        3.0,
        "GNSS horizontal 1-sigma assumed when the message carries no covariance "
        "(vertical: twice this)",
        unit="m",
        lo=0.05,
        hi=100,
        step=0.1,
    )
    gnss_reset_after_s: float = param(
        5.0,
        "after fixes have been rejected this long in a row, the position covariance is "
        "widened so GNSS is trusted again",
        unit="s",
        lo=0.5,
        hi=600,
        step=0.5,
    )
    gnss_rerun_lag_s: float = param(
        10.0,
        "how far back the fixed-lag re-run at the start of an outage goes "
        "(extensions.portal_rerun)",
        unit="s",
        lo=0,
        hi=120,
        step=1,
    )
    gnss_wander_fraction: float = param(
        0.8,
        "fraction of the typical fix variance that wanders slowly (a Gauss-Markov state "
        "of the filter); the rest of each fix's variance is white",
        lo=0,
        hi=0.99,
        step=0.05,
    )
    gnss_wander_tau_s: float = param(
        60.0, "correlation time of the GNSS wander", unit="s", lo=1, hi=3600, step=5
    )
    wheel_scale_sigma: float = param(
        0.01, "initial 1-sigma of the wheel-speed scale factor error", lo=0, hi=0.2, step=0.001
    )
    gyro_bias_init_sigma_deg_h: float = param(
        100.0,
        "initial 1-sigma of the gyro bias (turn-on bias of automotive MEMS)",
        unit="deg/h",
        lo=0.01,
        hi=10000,
        step=1,
    )
    gyro_scale_sigma_ppm: float = param(
        1500.0,
        "1-sigma of the gyro's scale-factor error (a MEMS gyro's datasheet figure; "
        "extensions.gyro_scale_consider)",
        unit="ppm",
        lo=0,
        hi=50000,
        step=100,
    )
    accel_bias_init_sigma_mg: float = param(
        10.0, "initial 1-sigma of the accelerometer bias", unit="mg", lo=0.001, hi=500, step=0.5
    )
    velocity_init_sigma_m_s: float = param(
        0.5, "initial 1-sigma of the velocity", unit="m/s", lo=0.001, hi=20, step=0.05
    )
    zupt_speed_m_s: float = param(
        0.05,
        "wheel speed below which the vehicle counts as stopped",
        unit="m/s",
        lo=0,
        hi=2,
        step=0.01,
    )
    zupt_gyro_deg_s: float = param(
        1.0,
        "mean |gyro| over 0.5 s below which the vehicle may count as stopped",
        unit="deg/s",
        lo=0,
        hi=20,
        step=0.1,
    )
    zupt_accel_std_m_s2: float = param(
        0.05,
        "std of |accel| over 0.5 s below which a log without wheel speed counts as stopped",
        unit="m/s^2",
        lo=0,
        hi=5,
        step=0.01,
    )
    zupt_sigma_m_s: float = param(
        0.02, "zero-velocity update 1-sigma", unit="m/s", lo=0.001, hi=1, step=0.005
    )
    aid_rate_hz: float = param(
        10.0,
        "rate of the wheel-speed, non-holonomic and zero-velocity updates",
        unit="Hz",
        lo=0.5,
        hi=200,
        step=0.5,
    )
    propagation_interval_s: float = param(
        0.02,
        "covariance propagation interval (the state is propagated at every IMU sample)",
        unit="s",
        lo=0.0,
        hi=0.2,
        step=0.005,
    )


@dataclass(frozen=True)
class SensorParams:
    """Mounting and timing: what a real log needs to be configured with."""

    imu_roll_deg: float = param(
        0.0, "IMU-to-body rotation: roll", unit="deg", lo=-180, hi=180, step=0.1
    )
    imu_pitch_deg: float = param(
        0.0, "IMU-to-body rotation: pitch", unit="deg", lo=-90, hi=90, step=0.1
    )
    imu_yaw_deg: float = param(
        0.0, "IMU-to-body rotation: yaw", unit="deg", lo=-180, hi=180, step=0.1
    )
    gnss_lever_arm_m: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), "GNSS antenna position in the body frame (forward, left, up)", unit="m"
    )
    gnss_time_offset_s: float = param(
        0.0,
        "added to GNSS stamps to put them on the IMU clock (up to a minute: GPS time against "
        "UTC is 18 s; the log's loading measures it from the turns)",
        unit="s",
        lo=-60,
        hi=60,
        step=0.01,
    )
    wheel_time_offset_s: float = param(
        0.0,
        "added to wheel-speed stamps to put them on the IMU clock (up to a minute)",
        unit="s",
        lo=-60,
        hi=60,
        step=0.01,
    )
    truth_time_offset_s: float = param(
        0.0,
        "added to ground-truth stamps to put them on the IMU clock (evaluation only: "
        "truth errors and plots; the filter never reads truth)",
        unit="s",
        lo=-2,
        hi=2,
        step=0.01,
    )
    initial_heading_deg: float | None = param(
        None,
        "initial heading (ENU yaw, counter-clockwise from East); None = from GNSS motion",
        unit="deg",
    )
    align_distance_m: float = param(
        10.0,
        "GNSS fixes at least this far apart give the initial heading",
        unit="m",
        lo=1,
        hi=200,
        step=1,
    )
    gnss_gap_s: float = param(
        1.0,
        "no valid fix for longer than this is a GNSS-degraded interval",
        unit="s",
        lo=0.1,
        hi=60,
        step=0.1,
    )


@dataclass(frozen=True)
class Params:
    """The whole estimator configuration."""

    trigger: TriggerParams = field(default_factory=TriggerParams)
    window: WindowParams = field(default_factory=WindowParams)
    gates: GateParams = field(default_factory=GateParams)
    pseudo: PseudoObsParams = field(default_factory=PseudoObsParams)
    offset: OffsetParams = field(default_factory=OffsetParams)
    extensions: ExtensionParams = field(default_factory=ExtensionParams)
    noise: NoiseParams = field(default_factory=NoiseParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    output_rate_hz: float = param(
        20.0, "rate of the per-epoch results kept for inspection", unit="Hz", lo=1, hi=200, step=1
    )


def matching_params(params: Params, *, have_wheel: bool) -> Params:
    """The parameters the route matcher runs with on a log with or without wheel speed: with
    ``extensions.no_wheel_caution`` and no wheel speed, the switches for a dead-reckoned
    along-track position that is uncertain by tens to hundreds of metres are on (and
    ``calibrated_approach``: an outage after too little GNSS-aided driving is dead-reckoned;
    ``along_drift_evidence``: an along-track drift the model lacks, shown by a correction
    beyond the filter's sigma, is carried as a velocity random walk for the rest of the outage;
    ``search_correction_cap``: a correction as far as the widened search looked is not refused
    by the fixed cap),
    ``weak_along_track`` and ``dr_separation`` are off (the filter's along-track is then no
    yardstick for a fit, and dead reckoning's covariance none for the route updates: on the
    real comma2k19 log without its wheels it undid updates that beat dead reckoning), and
    ``offset.map_turn_honest_prior`` is on: without wheel speed the heading drifts fastest, so
    the matches take a map rotation the approach's fit could not tell from zero (method of
    moments: no rotation at all) for the heading's error, and turn the heading by it."""
    ext = params.extensions
    if have_wheel or not ext.no_wheel_caution:
        return params
    cautious = replace(
        ext,
        covariance_search=True,
        curvature_covariance=True,
        overlap_inflation=True,
        window_scale_covariance=True,
        weak_along_track=False,
        dr_separation=False,
        cross_track_heading_widen=True,
        calibrated_approach=True,
        along_drift_evidence=True,
        search_correction_cap=True,
    )
    offset = replace(params.offset, map_turn_honest_prior=True)
    if cautious == ext and offset == params.offset:
        return params
    return replace(params, extensions=cautious, offset=offset)


def for_method(params: Params, method: Method) -> Params:
    """The parameters a method runs with: ``paper`` switches every extension off."""
    if method == "paper":
        off = {f.name: False for f in fields(ExtensionParams)}
        return replace(params, extensions=ExtensionParams(**off))
    return params
