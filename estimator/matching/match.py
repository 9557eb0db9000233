"""The route match of one window: the paper's shape registration plus routefuse's validation.

The last ``window.length_m`` of dead-reckoned travel is resampled at a fixed spacing, paired by
arc length with the route segment that starts where the window's first point projects, and
registered to it with a rigid 2-D transform (:mod:`~estimator.matching.fit`). The current DR
position mapped by that transform, shifted by the learned lane offset, is the pseudo-position
the filter is updated with.

Beyond the paper (each switchable in :class:`~estimator.params.ExtensionParams`): the route
segment's arc-length offset is searched, so route shape can correct along-track drift where the
road bends; the observation covariance follows the route geometry, so a straight road says
"along-track unknown" instead of pretending; and a candidate is validated against the filter's
own covariance, the lane the vehicle was in, and laterally shifted and reversed rivals
(:mod:`~estimator.matching.rivals`), because a parallel carriageway has the same shape and would
pass every shape gate.

An attempt is computed in two steps: :func:`match_geometry` (the fits, independent of the gate
thresholds) and :func:`judge_match` (the gate table, :mod:`~estimator.matching.gates`), so the
pipeline can re-judge an attempt after a threshold change without fitting it again. Every
intermediate and every gate goes into a :class:`~estimator.results.MatchRecord`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.errors import RoutefuseError
from estimator.matching.fit import Fit, FitSettings, fit_cost, fit_window, mahalanobis2
from estimator.matching.gates import ShapeValues, Validation, gate_table, unpaired_table
from estimator.matching.geometry import (
    Polyline,
    local_piece,
    project_near,
    project_on_route,
    resample_polyline,
)
from estimator.matching.kernels import rotation_sigma
from estimator.matching.rivals import fit_rivals
from estimator.params import Params
from estimator.results import FitSummary, MatchRecord
from estimator.route import Route

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Scores:
    """The values the gates test and the record's summary of a fitted attempt; they depend on
    the geometry and the pseudo-observation parameters, not on the thresholds."""

    nu: F64
    p_ref: F64
    shape: ShapeValues
    summary: FitSummary
    validation: Validation | None
    """None without ``extensions.candidate_validation``"""
    extra: dict[str, float]
    """the validation's chi-square and costs, for display"""
    correction: float
    search_m: float
    """half-width of the along-track search the fit was made in, m"""


@dataclass(frozen=True)
class MatchGeometry:
    """What a match attempt computes before any quality gate: the resampled window, where it
    anchors on the route, the candidate's fit and the rivals' fits.

    It depends on the attempt's inputs and on :func:`geometry_params` only, not on the gate
    thresholds, so after a gate change the pipeline re-judges the attempts it shares with the
    previous run (:func:`judge_match`) instead of fitting them again."""

    win: F64
    p_dr: F64
    cov: F64
    """(2, 2) the filter's position covariance the attempt was made with, symmetrised: what
    the Mahalanobis gate adds to the fit's observation covariance"""
    lane: float
    lane_path: bool
    s_anchor: float
    span: float
    fit: Fit | None
    route_s: tuple[float, float]
    route_segment: F64
    scores: Scores | None = None
    """the values the gates test (None without a fit)"""


def geometry_params(params: Params) -> tuple[object, ...]:
    """The parameters a :class:`MatchGeometry` depends on: all matching parameters except the
    gate thresholds (the rivals' lateral shift is geometry)."""
    return (
        params.window,
        params.pseudo,
        params.offset,
        params.extensions,
        params.gates.alternative_shift_m,
    )


def match_window(
    window_xy: ArrayLike,
    p_dr: ArrayLike,
    pos_cov2: ArrayLike,
    route: Route,
    *,
    s_guess: float | None,
    lane_offset: float,
    params: Params,
    index: int,
    t: float,
    epoch: int,
) -> MatchRecord:
    """Match the DR window ending at ``p_dr`` to the route; every gate is recorded.

    ``window_xy``: (N, 2) DR positions in time order covering the last ``window.length_m`` of
    travel, free of correction jumps. ``pos_cov2``: the filter's E/N covariance before the
    update. ``s_guess``: the vehicle's previous route arc length (None: search the whole route).
    ``lane_offset``: learned lateral offset, positive = vehicle left of the route. The record's
    ``innovation`` is z - p_dr and ``correction`` is zero: the caller fills in what it applied.
    """
    geometry = match_geometry(
        window_xy, p_dr, pos_cov2, route, s_guess=s_guess, lane_offset=lane_offset, params=params
    )
    return judge_match(geometry, params, index=index, t=t, epoch=epoch)


def _check_inputs(
    window_xy: ArrayLike, p_dr: ArrayLike, pos_cov2: ArrayLike
) -> tuple[F64, F64, F64]:
    w = np.asarray(window_xy, np.float64)
    if w.ndim != 2 or w.shape[1] < 2 or len(w) < 1:
        raise RoutefuseError(None, f"route match: window must be (N, 2) positions, got {w.shape}")
    w = w[:, :2]
    p = np.asarray(p_dr, np.float64).reshape(-1)[:2]
    cov = np.asarray(pos_cov2, np.float64)
    if cov.shape != (2, 2):
        raise RoutefuseError(None, f"route match: position covariance must be 2x2, got {cov.shape}")
    if not (np.isfinite(w).all() and np.isfinite(p).all() and np.isfinite(cov).all()):
        raise RoutefuseError(None, "route match: window, position or covariance is not finite")
    return w, p, 0.5 * (cov + cov.T)


def match_geometry(
    window_xy: ArrayLike,
    p_dr: ArrayLike,
    pos_cov2: ArrayLike,
    route: Route,
    *,
    s_guess: float | None,
    lane_offset: float,
    params: Params,
    window_scale_sigma_m: float = 0.0,
) -> MatchGeometry:
    """The fits of :func:`match_window` (same arguments), before its gates.

    ``window_scale_sigma_m``: 1-sigma of the window's length error, with
    ``extensions.window_scale_covariance`` added to the along-track sigma of the candidate's
    and the rivals' fits (the caller knows the window's duration and velocity covariance)."""
    win_raw, p, cov = _check_inputs(window_xy, p_dr, pos_cov2)
    enabled = params.offset.enabled and np.isfinite(lane_offset)
    lane = float(lane_offset) if enabled else 0.0
    h = params.window.spacing_m
    win = resample_polyline(win_raw, h, anchor="end")
    span = (len(win) - 1) * h
    road = Polyline.of(route)
    if s_guess is None or not np.isfinite(s_guess):
        s_anchor = float(project_on_route(route, win[0])[0][0])
    else:
        search = params.window.route_search_m
        s_anchor = float(project_near(road, win[0], s_guess - span, search)[0][0])
    lane_path = params.extensions.lane_path_matching and abs(lane) > 1e-3
    search = search_half_width(road, s_anchor + span, cov, params)
    pad = search + 2.0 * h
    settings = FitSettings.searching(params, search)
    if params.extensions.window_scale_covariance:
        settings = settings.with_window_scale(window_scale_sigma_m)
    fit = None
    if lane_path:
        cand = local_piece(road, lane, s_anchor - pad, s_anchor + span + pad)
        if cand is not None and len(win) >= 2:
            fit = fit_window(win, p, cand, cand.arc_of(win[0]), 0.0, settings, pos_cov2=cov)
    elif len(win) >= 2:
        fit = fit_window(win, p, road, s_anchor, lane, settings, pos_cov2=cov)
    if fit is None:
        return MatchGeometry(
            win=win,
            p_dr=p,
            cov=cov,
            lane=lane,
            lane_path=lane_path,
            s_anchor=s_anchor,
            span=span,
            fit=None,
            route_s=(s_anchor, s_anchor),
            route_segment=np.empty((0, 2)),
        )
    if lane_path:
        ends = fit.route_points[np.flatnonzero(fit.valid)[[0, -1]]] - lane * fit.normal
        guess = s_anchor + fit.along_offset + np.array([0.0, span])
        route_s = project_near(road, ends, guess, pad + 10.0)[0]
        s0, s1 = float(route_s[0]), float(route_s[1])
    else:
        s0, s1 = fit.s_first, fit.s_first + (fit.n_pairs - 1) * h
    return MatchGeometry(
        win=win,
        p_dr=p,
        cov=cov,
        lane=lane,
        lane_path=lane_path,
        s_anchor=s_anchor,
        span=span,
        fit=fit,
        route_s=(s0, s1),
        route_segment=road.segment(s0, s1),
        scores=_scores(win, p, cov, road, s_anchor, lane, lane_path, fit, params, settings, search),
    )


def search_half_width(road: Polyline, s_now: float, pos_cov2: F64, params: Params) -> float:
    """Half-width of the along-track search: ``window.along_search_m``, or with
    ``extensions.covariance_search`` 3 sigma of the filter's position along the road at the
    vehicle where that is wider (up to ``window.along_search_max_m``).

    The window is anchored where its dead-reckoned start projects; with wheel speed that is
    metres from the truth and +-30 m covers it, but an IMU alone lets it slide hundreds of
    metres along a straight, and a bend searched too narrowly is paired with the wrong stretch
    of road (which then corrupts cross-track too). The filter's own covariance says how far to
    look; the search's likelihood interval still decides whether along-track is observed."""
    base = params.window.along_search_m
    if not (params.extensions.covariance_search and params.extensions.along_track_search):
        return base
    t = road.tangent(s_now)
    var = float(t @ pos_cov2 @ t)
    if not np.isfinite(var) or var <= 0.0:
        return base
    return float(min(max(base, 3.0 * np.sqrt(var)), max(base, params.window.along_search_max_m)))


def _scores(
    win: F64,
    p: F64,
    cov: F64,
    road: Polyline,
    s_anchor: float,
    lane: float,
    lane_path: bool,
    fit: Fit,
    params: Params,
    settings: FitSettings,
    search: float,
) -> Scores:
    nu = fit.z - p
    summary = FitSummary(
        along_offset_m=fit.along_offset,
        along_curvature=fit.along_curvature,
        along_sigma_m=fit.along_sigma,
        along_observed=fit.along_observed,
        cross_sigma_m=float(np.sqrt(fit.normal @ fit.obs_cov @ fit.normal)),
        lane_path=lane_path,
        innovation_along_m=float(nu @ fit.tangent),
        innovation_cross_m=float(nu @ fit.normal),
        normal=fit.normal,
        heading_sigma_rad=_rotation_sigma(win, fit, cov, params),
    )
    validation = None
    extra: dict[str, float] = {}
    if params.extensions.candidate_validation:
        d2 = mahalanobis2(nu, cov + fit.obs_cov)
        cost = fit_cost(fit, p, cov, settings)
        extra = {"mahalanobis_d2": d2, "cost": cost}
        rivals = fit_rivals(
            win, p, cov, road, s_anchor, lane, lane_path, params, settings, search_m=search
        )
        for r in rivals:
            extra[f"cost_{r.rival.value}"] = r.cost
            extra[f"residual_{r.rival.value}_m"] = r.residual_m
        validation = Validation(
            d2=d2,
            jump=abs(float(nu @ fit.normal)),
            cost=cost,
            rivals=tuple((r.rival, r.shape, r.cost) for r in rivals),
        )
    return Scores(
        nu=nu,
        p_ref=fit.z - lane * fit.normal,
        shape=ShapeValues.of(fit),
        summary=summary,
        validation=validation,
        extra=extra,
        correction=float(np.hypot(*nu)),
        search_m=float(search),
    )


def _rotation_sigma(win: F64, fit: Fit, pos_cov2: F64, params: Params) -> float:
    """1-sigma of the fitted rotation read as a heading correction (yaw + rotation_rad): the
    shape noise over the window's spread, plus what an along-track error the fit could not
    see turns into on a bend (sliding along a curve of curvature k is a rotation of k ds)."""
    return float(
        rotation_sigma(
            np.ascontiguousarray(win, np.float64),
            fit.valid,
            fit.route_points,
            float(fit.residual),
            float(params.pseudo.shape_noise_m),
            float(fit.along_sigma),
            np.ascontiguousarray(fit.tangent, np.float64),
            np.ascontiguousarray(pos_cov2, np.float64),
        )
    )


def judge_match(
    geometry: MatchGeometry, params: Params, *, index: int, t: float, epoch: int
) -> MatchRecord:
    """The gates of one attempt on its geometry (computed with the same
    :func:`geometry_params`): the record :func:`match_window` returns. Its ``filter_cov`` is
    the position covariance the geometry was computed with, the one the Mahalanobis gate adds
    to the fit's ``obs_cov``."""
    win, p, lane = geometry.win, geometry.p_dr, geometry.lane
    fit, sc = geometry.fit, geometry.scores
    if fit is None or sc is None:
        nan2 = np.full(2, np.nan)
        return MatchRecord(
            index=index,
            t=t,
            epoch=epoch,
            accepted=False,
            gates=unpaired_table(len(win), params),
            window_dr=win,
            route_points=np.empty((0, 2)),
            route_segment=np.empty((0, 2)),
            route_s=geometry.route_s,
            n_pairs=0,
            rotation_rad=float("nan"),
            translation=nan2,
            residual_m=float("nan"),
            heading_cos=float("nan"),
            p_dr=p,
            p_ref=nan2.copy(),
            lane_offset_m=lane,
            pseudo_position=nan2.copy(),
            obs_cov=np.full((2, 2), np.nan),
            innovation=nan2.copy(),
            correction=np.zeros(2),
            anchor_s=geometry.s_anchor,
            window_length_m=geometry.span,
            filter_cov=geometry.cov,
        )
    gates = gate_table(sc.shape, sc.validation, sc.correction, params, search_m=sc.search_m)
    return MatchRecord(
        index=index,
        t=t,
        epoch=epoch,
        accepted=all(d.passed for d in gates),
        gates=gates,
        window_dr=win[fit.valid],
        route_points=fit.route_points[fit.valid],
        route_segment=geometry.route_segment,
        route_s=geometry.route_s,
        n_pairs=fit.n_pairs,
        rotation_rad=fit.angle,
        translation=fit.translation,
        residual_m=fit.residual,
        heading_cos=fit.heading_cos,
        p_dr=p,
        p_ref=sc.p_ref,
        lane_offset_m=lane,
        pseudo_position=fit.z,
        obs_cov=fit.obs_cov,
        innovation=sc.nu,
        correction=np.zeros(2),
        anchor_s=geometry.s_anchor,
        window_length_m=geometry.span,
        fit=sc.summary,
        extra=dict(sc.extra),
        filter_cov=geometry.cov,
    )
