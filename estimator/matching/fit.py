"""THE rigid fit: a window registered to one road (the candidate or a rival).

The window's pairs are placed along the road where the along-track search puts them
(:func:`~estimator.matching.kernels.along_track_pairs`), registered with a proper rigid 2-D
transform (Kabsch), and the current DR position mapped by it, moved by the lane offset, is the
pseudo-position; its covariance follows the road's direction. The candidate and the rivals go
through the same code, so a change to the fit is made once. The Kabsch step is numpy's: the
filter's results were made with its roundings (a match the filter is updated with feeds later
windows, and the along-track search amplifies a 1e-16 change into 1e-8 m over an outage).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.matching.geometry import Polyline
from estimator.matching.kernels import along_track_pairs, rms_residual
from estimator.params import Params

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class FitSettings:
    """The parameters the fit depends on, read once per parameter set."""

    spacing_m: float
    along_search: bool
    """``extensions.along_track_search``: scan the pairs' start along the road"""
    geometry_covariance: bool
    """``extensions.geometry_covariance``: the covariance follows the road's direction"""
    step_m: float
    deltas: F64
    """along-track offsets the scan tries, m"""
    grid_ratio: int
    """the window spacing in search steps when the offsets are a grid the pairs can share
    (:func:`~estimator.matching.kernels._scan_grid`), else 0"""
    shape_noise_m: float
    along_sigma_max_m: float
    along_sigma_min_m: float
    cross_sigma_m: float
    cross_residual_factor: float
    sigma_m: float
    """isotropic 1-sigma without ``geometry_covariance``"""
    plausible_place: bool = False
    """``extensions.covariance_search``: an unobserved window is paired where the shape allows"""
    curvature_covariance: bool = False
    """``extensions.curvature_covariance``: the road's bend over the along-track uncertainty
    is cross-track noise (with ``geometry_covariance``)"""
    weak_along_track: bool = False
    """``extensions.weak_along_track``: along-track weaker than the filter's is not used"""
    weak_along_disagreement: float = 0.0
    """``pseudo.weak_along_disagreement``: ... and disagreeing with the filter's along-track
    position by more than this many of its sigmas (0: always)"""
    weak_along_max_chi2: float = float("inf")
    """``pseudo.weak_along_max_chi2``: ... but within this chi-square of the fit's and the
    filter's along-track sigmas together"""
    window_scale_sigma_m: float = 0.0
    """``extensions.window_scale_covariance``: 1-sigma of the attempt's window length error
    (the filter's along-track velocity sigma times the window's duration), added to an
    observed along-track sigma; set per attempt (:meth:`with_window_scale`)"""

    @classmethod
    def of(cls, params: Params) -> FitSettings:
        return _settings(params)

    @classmethod
    def searching(cls, params: Params, half_width_m: float) -> FitSettings:
        """:meth:`of`, with the along-track search ``half_width_m`` wide when that is wider
        than ``window.along_search_m`` (``extensions.covariance_search``), in whole steps."""
        step = params.window.along_search_step_m
        k_half = int(np.ceil(half_width_m / step))
        if k_half <= max(int(np.ceil(params.window.along_search_m / step)), 1):
            return _settings(params)
        return _widened(params, k_half)

    def with_window_scale(self, sigma_m: float) -> FitSettings:
        """These settings for a window whose length is uncertain by ``sigma_m`` (1-sigma)."""
        if not (np.isfinite(sigma_m) and sigma_m > 0.0):
            return self
        return dataclasses.replace(self, window_scale_sigma_m=float(sigma_m))


@functools.lru_cache(maxsize=64)
def _settings(params: Params) -> FitSettings:
    ext, w, po = params.extensions, params.window, params.pseudo
    step = w.along_search_step_m
    if ext.along_track_search:
        k_half = max(int(np.ceil(w.along_search_m / step)), 1)
        deltas = step * np.arange(-k_half, k_half + 1, dtype=np.float64)
    elif ext.geometry_covariance:
        deltas = np.array([-step, 0.0, step])
    else:
        deltas = np.zeros(1)
    deltas.setflags(write=False)
    h = w.spacing_m
    ratio = int(np.rint(h / step))
    grid = (
        ext.along_track_search
        and len(deltas) > 1
        and ratio >= 1
        and abs(ratio * step - h) <= 1e-12 * h
        and abs(deltas[1] - deltas[0] - step) <= 1e-12 * step
    )
    return FitSettings(
        spacing_m=w.spacing_m,
        along_search=ext.along_track_search,
        geometry_covariance=ext.geometry_covariance,
        step_m=step,
        deltas=deltas,
        grid_ratio=ratio if grid else 0,
        shape_noise_m=po.shape_noise_m,
        along_sigma_max_m=po.along_sigma_max_m,
        along_sigma_min_m=po.along_sigma_min_m,
        cross_sigma_m=po.cross_sigma_m,
        cross_residual_factor=po.cross_residual_factor,
        sigma_m=po.sigma_m,
        curvature_covariance=ext.curvature_covariance and ext.geometry_covariance,
        plausible_place=ext.covariance_search and ext.along_track_search,
        weak_along_track=ext.weak_along_track and ext.geometry_covariance,
        weak_along_disagreement=po.weak_along_disagreement,
        weak_along_max_chi2=po.weak_along_max_chi2,
    )


@functools.lru_cache(maxsize=64)
def _widened(params: Params, k_half: int) -> FitSettings:
    base = _settings(params)
    if not base.along_search:
        return base
    deltas = base.step_m * np.arange(-k_half, k_half + 1, dtype=np.float64)
    deltas.setflags(write=False)
    return dataclasses.replace(base, deltas=deltas)


@dataclass(frozen=True)
class Fit:
    """A window registered to one road."""

    s_first: float
    """arc length (on the road) of the first pair"""
    valid: NDArray[np.bool_]
    route_points: F64
    rotation: F64
    translation: F64
    residual: float
    n_pairs: int
    heading_cos: float
    along_offset: float
    along_curvature: float
    along_sigma: float
    along_observed: bool
    p_ref: F64
    s_ref: float
    tangent: F64
    normal: F64
    z: F64
    obs_cov: F64

    @property
    def angle(self) -> float:
        return float(np.arctan2(self.rotation[1, 0], self.rotation[0, 0]))


def fit_window(
    win: F64,
    p_dr: F64,
    road: Polyline,
    s_anchor: float,
    lane_offset: float,
    settings: FitSettings,
    *,
    pointwise_residual: bool = False,
    grid_scan: bool = False,
    pos_cov2: F64 | None = None,
) -> Fit | None:
    """Register the window (resampled, (N, 2)) to ``road``, its first point at about arc
    length ``s_anchor``; the pseudo-position is moved ``lane_offset`` to the left of the road.
    None when fewer than 2 pairs fall on the road.

    ``pointwise_residual``: the residual summed pair by pair
    (:func:`~estimator.matching.kernels.rms_residual`), exact to the last digits a table
    prints, instead of from the Kabsch sums, whose rounding the candidate's results (its
    covariance, the filter) were made with; the rivals, scored only, use it.

    ``grid_scan``: the along-track search on a grid the pairs share
    (``FitSettings.grid_ratio``), half the direct scan's time (23 vs 45 us) and equal to it to
    rounding; the rivals, scored only, use it, as the compiled rival score did.

    ``pos_cov2``: the filter's E/N covariance, for ``curvature_covariance``."""
    n = len(win)
    s = np.empty(n)
    valid = np.empty(n, np.bool_)
    q = np.empty((n, 2))
    offset, curvature, sigma, observed = along_track_pairs(
        win,
        road.xy,
        road.s,
        road.unit,
        float(s_anchor),
        settings.deltas,
        settings.along_search,
        settings.step_m,
        settings.spacing_m,
        settings.shape_noise_m,
        settings.along_sigma_max_m,
        settings.along_sigma_min_m,
        settings.grid_ratio if grid_scan else 0,
        s,
        valid,
        q,
        settings.plausible_place,
    )
    if observed and settings.window_scale_sigma_m > 0.0:
        sigma = float(np.hypot(sigma, settings.window_scale_sigma_m))
        if sigma >= settings.along_sigma_max_m:
            observed, sigma = False, settings.along_sigma_max_m
    idx = np.flatnonzero(valid)
    n_pairs = len(idx)
    if n_pairs < 2:
        return None
    rot, trans, ms = _kabsch(win, q, valid.astype(np.float64), with_residual=not pointwise_residual)
    residual = rms_residual(win, q, valid, rot) if pointwise_residual else float(np.sqrt(ms))
    i1, i0 = idx[-1], idx[-2]
    d_s = win[i1] - win[i0]
    d_t = q[i1] - q[i0]
    norm = float(np.hypot(*d_s) * np.hypot(*d_t))
    heading_cos = float(np.dot(d_s, d_t) / norm) if norm > 0 else -1.0

    p_ref = rot @ p_dr + trans
    s_end = float(s[i1])
    s_ref = s_end + float((p_ref - q[i1]) @ road.tangent(s_end))
    tangent = road.tangent(s_ref)
    normal = np.array([-tangent[1], tangent[0]])
    z = p_ref + lane_offset * normal
    along = float((p_ref - p_dr) @ tangent)
    if (
        observed
        and settings.weak_along_track
        and _weaker_than_filter(
            sigma,
            along,
            tangent,
            pos_cov2,
            settings.weak_along_disagreement,
            settings.weak_along_max_chi2,
        )
    ):
        p_ref = p_ref - along * tangent
        s_ref -= along
        z = z - along * tangent
        observed, sigma = False, settings.along_sigma_max_m
    return Fit(
        s_first=float(s[idx[0]]),
        valid=valid,
        route_points=q,
        rotation=rot,
        translation=trans,
        residual=residual,
        n_pairs=n_pairs,
        heading_cos=heading_cos,
        along_offset=float(offset),
        along_curvature=float(curvature),
        along_sigma=float(sigma),
        along_observed=bool(observed),
        p_ref=p_ref,
        s_ref=s_ref,
        tangent=tangent,
        normal=normal,
        z=z,
        obs_cov=_observation_cov(
            tangent,
            normal,
            sigma,
            residual,
            settings,
            bend_var=_bend_variance(road, s_ref, tangent, normal, pos_cov2, sigma, observed)
            if settings.curvature_covariance and pos_cov2 is not None
            else 0.0,
        ),
    )


def _weaker_than_filter(
    along_sigma: float,
    along: float,
    tangent: F64,
    pos_cov2: F64 | None,
    disagreement: float,
    max_chi2: float,
) -> bool:
    """The fit's along-track sigma exceeds the filter's own along the road, its along-track
    innovation ``along`` exceeds ``disagreement`` of the filter's along-track sigmas, and is
    within ``max_chi2`` of both sigmas together:
    along^2 / (sigma_fit^2 + t' P t) <= max_chi2.

    Why the second test: the fits of overlapping windows carry one shape error, attempt after
    attempt, so a weak fit far outside the filter's own along-track uncertainty is more likely
    that error than news; one within it is the along-track evidence a long tunnel lives on.
    Why the third: a fit that is off by many of its own sigmas too is not weak but wrong (paired
    with another stretch of the route); applied across the road it would pass the innovation
    gate that refuses it whole (the Husky's parking lot: 25 m off at 3.2 m, chi-square 60)."""
    if pos_cov2 is None:
        return False
    var_p = float(tangent @ pos_cov2 @ tangent)
    return bool(
        np.isfinite(var_p)
        and along_sigma**2 > var_p
        and along * along > disagreement**2 * var_p
        and along * along <= max_chi2 * (along_sigma**2 + var_p)
    )


_BEND_NODES, _BEND_WEIGHTS = np.polynomial.hermite_e.hermegauss(9)
_BEND_WEIGHTS = _BEND_WEIGHTS / _BEND_WEIGHTS.sum()


def _bend_variance(
    road: Polyline,
    s_ref: float,
    tangent: F64,
    normal: F64,
    pos_cov2: F64,
    along_sigma: float,
    observed: bool,
) -> float:
    """E[d^2]: d the distance of the road from its tangent at ``s_ref``, at an arc-length error
    drawn from the match's along-track uncertainty (the filter's along-track sigma, combined
    with the fit's where the shape observed it).

    The pseudo-position says "on the road's tangent line at s_ref"; where s_ref is uncertain by
    sigma on a bend of curvature k, the vehicle is about k sigma^2 / 2 off that line, and the
    line's direction, turning along the bend, makes a cross-track update inform along-track.
    With wheel speed sigma is metres and this is nothing; dead-reckoned by an IMU alone it is
    tens to hundreds of metres, and a matched bend then pulls the estimate to the wrong place
    with a confident covariance. (Gauss-Hermite over 9 nodes, on the polyline.)"""
    var_p = float(tangent @ pos_cov2 @ tangent)
    if not np.isfinite(var_p) or var_p <= 0.0:
        return 0.0
    var = 1.0 / (1.0 / var_p + 1.0 / along_sigma**2) if observed else var_p
    s = s_ref + np.sqrt(var) * _BEND_NODES
    i = np.clip(np.searchsorted(road.s, s, side="right") - 1, 0, len(road.unit) - 1)
    pts = road.xy[i] + (s - road.s[i])[:, None] * road.unit[i]
    j = min(max(int(np.searchsorted(road.s, s_ref, side="right")) - 1, 0), len(road.unit) - 1)
    ref = road.xy[j] + (s_ref - road.s[j]) * road.unit[j]
    d = (pts - ref) @ normal
    return float(_BEND_WEIGHTS @ (d * d))


def _observation_cov(
    tangent: F64,
    normal: F64,
    along_sigma: float,
    residual: float,
    settings: FitSettings,
    *,
    bend_var: float = 0.0,
) -> F64:
    """R_k: along-track as the search observed it, cross-track from the registration
    residual plus ``bend_var`` (``geometry_covariance``); else isotropic."""
    if settings.geometry_covariance:
        cross = max(settings.cross_sigma_m, settings.cross_residual_factor * residual)
        basis = np.array([[tangent[0], normal[0]], [tangent[1], normal[1]]])
        scale = np.array([[along_sigma**2, 0.0], [0.0, cross**2 + bend_var]])
        cov: F64 = basis @ scale @ basis.T
        return cov
    return settings.sigma_m**2 * np.eye(2)


def fit_cost(fit: Fit, p_dr: F64, pos_cov2: F64, settings: FitSettings) -> float:
    """How badly a road explains the window: innovation chi-square plus fit quality."""
    nu = fit.z - p_dr
    return mahalanobis2(nu, pos_cov2 + fit.obs_cov) + (fit.residual / settings.shape_noise_m) ** 2


def mahalanobis2(nu: F64, cov: F64) -> float:
    """nu^T cov^-1 nu of a 2-vector (inf when cov is singular); the 2x2 inverse written out,
    which is np.linalg.solve's result to rounding at a fraction of its call overhead."""
    a, b = float(cov[0, 0]), float(cov[0, 1])
    c, d = float(cov[1, 0]), float(cov[1, 1])
    det = a * d - b * c
    if det == 0.0:
        return float("inf")
    n0, n1 = float(nu[0]), float(nu[1])
    return (n0 * (d * n0 - b * n1) + n1 * (a * n1 - c * n0)) / det


def kabsch_2d(src: ArrayLike, dst: ArrayLike, weights: ArrayLike | None = None) -> tuple[F64, F64]:
    """The proper rotation R (2, 2) and translation t (2,) minimising
    sum w_i |R src_i + t - dst_i|^2 over (n, 2) point sets.

    SVD of the cross-covariance C = U S V^T, R = V diag(1, det(V U^T)) U^T: the guard refuses
    reflections, so a mirrored shape is fitted by the best rotation, with its residual."""
    s = np.asarray(src, np.float64)
    d = np.asarray(dst, np.float64)
    w = np.ones(len(d)) if weights is None else np.asarray(weights, np.float64)
    rot, trans, _ = _kabsch(s, d, w)
    return rot, trans


def _kabsch(src: F64, dst: F64, w: F64, *, with_residual: bool = True) -> tuple[F64, F64, float]:
    """Weighted Kabsch of one (n, 2) pair of point sets: R, t and the weighted mean squared
    residual (from sum w |R a - b|^2 = sum w |a|^2 + sum w |b|^2 - 2 tr(R C)); NaN without
    ``with_residual`` (a caller that sums the residual pair by pair)."""
    wsum = max(float(w.sum()), 1e-300)
    w2 = w[:, None]
    cs = (w2 * src).sum(axis=0) / wsum
    ct = (w2 * dst).sum(axis=0) / wsum
    a = src - cs
    b = dst - ct
    aw = w2 * a
    cov = aw.T @ b
    u, _, vt = np.linalg.svd(cov)
    v = vt.T.copy()
    r = v @ u.T
    if r[0, 0] * r[1, 1] - r[0, 1] * r[1, 0] < 0.0:
        v[:, 1] *= -1.0
        r = v @ u.T
    trans = ct - r @ cs
    if not with_residual:
        return r, trans, float("nan")
    sq = float((aw * a).sum() + (w2 * b * b).sum())
    tr = float(np.einsum("ij,ji->", r, cov))
    return r, trans, max(sq - 2.0 * tr, 0.0) / wsum
