"""Where the mission route lies relative to the road actually driven.

An SD-map route is not the road: it is offset across (the lane, and the map's own error) and
along (a junction or a portal drawn metres early), and often slightly rotated. Matching the
dead-reckoned window to such a route hands the filter a position on the map, so an uncorrected
bias drags the estimate along the map while the route-relative deviation looks excellent.

Before each outage the GNSS-good track of the last ``offset.map_bias_track_m`` is registered to
the route. Each track point ``i`` lies a distance ``d_i`` to the left of the route, where the
route's left normal is ``n_i``. A vehicle keeping the lane offset ``l`` on a road that the route
draws ``b`` (E, N) away sees

    d_i = l - n_i . b + e_i

The lane follows the road's normal, the map's shift does not: where the track turns, the
cross-track distances tell them apart and fix ``b`` along the road too; on a straight approach
only ``l - n . b`` is seen, and the priors (``offset.map_bias_lane_sigma_m`` for the lane,
``offset.map_bias_prior_sigma_m`` along and ``offset.map_bias_cross_sigma_m`` across for the
map) share it out, with the covariance saying that the share is unknown. A map drawn rotated by
a small angle ``a`` about the end of the track ``x_e`` is shifted by ``b + a J (x - x_e)``
(``J`` a quarter turn), which a straight approach sees as a route at an angle to the track:
with the prior ``offset.map_bias_rotation_sigma_deg`` it is a fourth unknown. The shape's own
along-track registration (the matcher's rigid fit) adds ``t . b`` where the track turns. A
least-squares fit with those priors gives ``u = [l, b, a]`` and its covariance. The shift's
prior is a map's local error, which holds where a turned map is right, not at ``x_e``: a map
turned about a point kilometres ahead is tens of metres off at ``x_e``, and the prior's pull on
the intercept there turns the fitted rotation and moves the lane (drive 32 of the stress corpus:
0.735 deg on the truth track against 0.559). With ``offset.map_bias_turn_prior`` a bias applied
with its rotation takes its values from the fit whose shift prior adds the rotation's share
(:func:`_turn_spread`).

The errors ``e_i`` have two parts. The estimate's own error at the end of the track (the
receiver's slow wander) is common to the whole track; it enters ``u`` through a gain ``G``
(3, 2), and since every pseudo-position of the outage is made from ``u``, the filter carries the
lane-offset and map-bias errors as considered states cloned through ``G`` from its position
error at the outage start (:func:`estimator.filter.updates.clone_route_errors`): the
pseudo-positions then hold the estimate to the road without claiming to know it better than
GNSS did. The rest (map shape, lane keeping) is noise of ``pseudo.shape_noise_m`` per
``window.length_m`` of track, independent of the state. The receiver's wander is common only
over its correlation time (a minute, ``noise.gnss_wander_tau_s``): on an approach longer than
that, ``offset.map_bias_wander_rows`` takes a point's error as the share of the end's error
the wander keeps over the time between them plus the rest, correlated along the track
(:func:`_wander_rows`).

The bias is used only when a chi-square test of ``b`` (or of ``a``) against zero, with its full
covariance, exceeds ``offset.map_bias_min_sigmas`` squared: a right map then keeps the lane
offset learned near the portal and no bias, and the filter only carries
``offset.map_bias_null_sigma_m`` of map error. Otherwise the route is moved back by the bias
for every match of the outage and ``l`` is its lane offset; the rotation's remaining
uncertainty grows the map-bias error with the distance from ``x_e``; a rotation fitted but
not applied is considered in the outage as what the fit shows beyond its noise
(:func:`_unapplied_turn_var`). A bias further from zero
than ``offset.map_bias_max_prior_sigmas`` of its prior all along the road ahead (a map drawn
turned is right somewhere, perhaps in the tunnel, and off most far from there) is not a map's
error but another road (a parallel carriageway): nothing is learned, and the matcher's gates
judge the route as it is. So is a lane further than ``offset.max_offset_m`` from the
centreline.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimator.matching.match import match_geometry
from estimator.params import Params
from estimator.results import MapBiasRefusal
from estimator.route import Route

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class MapBias:
    """The route's bias learned before an outage: route position minus road position, at
    ``pivot`` plus the rotation ``rotation`` about it."""

    offset: F64
    """(2,) E, N: the route lies ``offset`` from the road driven at ``pivot``, m (zero unless
    significant)"""
    rotation: float
    """the route is drawn turned by this about ``pivot`` (counter-clockwise), rad"""
    rotation_sigma: float
    """its 1-sigma, rad"""
    pivot: F64
    """(2,) E, N: the end of the track it was learned from"""
    lane: float
    """the lane offset to keep with it (positive = vehicle left of the road), m"""
    gain: F64
    """(3, 2) how the estimate's E/N position error at the outage start enters the lane-offset
    and the map-bias (E, N) errors"""
    cov: F64
    """(3, 3) covariance of the lane-offset and map-bias (E, N) errors beyond ``gain``'s part"""
    measured: F64
    """(2,) the fit's estimate of the map's bias at ``pivot`` before the significance test, m
    (NaN when nothing was learned)"""
    measured_cov: F64
    """(2, 2) its covariance, the part shared with the position error included, m^2"""
    chi2: float
    """``measured`` against zero (NaN when nothing was learned)"""
    along_observed: bool
    """the track fixed the along-track bias to better than half its prior"""
    turn_var: float = 0.0
    """variance of the map's rotation error, rad^2: the applied rotation's, or the second
    moment of one fitted but not applied (its square less its own variance; plus it where the
    bias is applied and ``offset.map_turn_honest_prior``); the outage's pseudo-positions carry
    it as a considered state (``extensions.map_turn_consider``) or estimate it"""
    turn_second_moment: float = 0.0
    """the honest second moment of the map's rotation error, rad^2: for a rotation fitted but
    not applied, its square plus its variance (the error of taking it as zero); else
    ``turn_var``. A method-of-moments ``turn_var`` of zero claims the map exactly unturned,
    which a fit within its noise does not show (``extensions.map_turn_honest_consider``)"""
    refused: MapBiasRefusal | None = None
    """why ``measured`` was not applied whatever its significance: too large for a map's
    error, or with a lane too far from the route (another road); None otherwise"""
    tied: bool = False
    """not applied, its lane (the offset seen near the portal, lane and map together) is tied
    to the considered map error (``extensions.unapplied_bias_lane_tie``); the outage's
    pseudo-positions estimate both with ``extensions.unapplied_bias_estimate``"""

    @property
    def significant(self) -> bool:
        """The bias was applied (it differs from zero by more than the test allows)."""
        return bool(np.any(self.offset != 0.0) or self.rotation != 0.0)

    def moved_back(self, xy: F64, offset: F64) -> F64:
        """Route vertices ``xy`` (N, 2) moved back onto the road: by ``offset`` (the bias at
        ``pivot``, as the outage's matches have corrected it) and the rotation about it."""
        return xy_moved_back(xy, offset, self.rotation, self.pivot)


def xy_moved_back(xy: F64, offset: F64, rotation: float, pivot: F64) -> F64:
    """Route vertices ``xy`` (N, 2) of a map shifted by ``offset`` at ``pivot`` and turned by
    ``rotation`` (rad, small) about it, moved back onto the road."""
    d = xy - pivot
    out: F64 = xy - offset - rotation * np.column_stack([-d[:, 1], d[:, 0]])
    return out


def turned_back(
    offset: F64, rotation: float, pivot: F64, *, turn: float, shift: F64
) -> tuple[F64, float]:
    """The bias ``offset`` at ``pivot`` and ``rotation`` about it after an outage's matches
    turned the map back by ``turn`` about the origin and shifted it by ``shift``
    (``extensions.map_turn_estimate``): each correction ``dr`` of the rotation error at the
    vehicle's position ``a`` moves the map by ``dr J (q - a)``, which the filter sums as a turn
    about the origin and a shift ``-dr J a``; as a shift at the pivot and a turn about it, the
    same field is ``offset + shift + turn J pivot`` and ``rotation + turn``."""
    moved: F64 = offset + shift + turn * np.array([-pivot[1], pivot[0]])
    return moved, rotation + turn


def _result(
    lane: float,
    normal: F64,
    map_cov: F64,
    *,
    measured: F64 | None = None,
    measured_cov: F64 | None = None,
    chi2: float = math.nan,
    along_observed: bool = False,
    pivot: F64 | None = None,
    turn_var: float = 0.0,
    refused: MapBiasRefusal | None = None,
) -> MapBias:
    """No bias applied: the lane offset ``lane`` learned near the portal (its error the
    position error across ``normal``), the map-bias error of covariance ``map_cov``."""
    cov = np.zeros((3, 3))
    cov[1:, 1:] = map_cov
    gain = np.zeros((3, 2))
    gain[0] = normal
    return MapBias(
        offset=np.zeros(2),
        rotation=0.0,
        rotation_sigma=0.0,
        pivot=np.zeros(2) if pivot is None else pivot,
        lane=lane,
        gain=gain,
        cov=cov,
        measured=np.full(2, np.nan) if measured is None else measured,
        measured_cov=np.full((2, 2), np.nan) if measured_cov is None else measured_cov,
        chi2=chi2,
        along_observed=along_observed,
        turn_var=turn_var,
        refused=refused,
    )


def _prior_cov(params: Params, normal: F64) -> F64:
    """(2, 2) the map bias's prior covariance where the road's left normal is ``normal``."""
    op = params.offset
    t = np.array([normal[1], -normal[0]])
    out: F64 = op.map_bias_prior_sigma_m**2 * np.outer(t, t)
    out += op.map_bias_cross_sigma_m**2 * np.outer(normal, normal)
    return out


def prior_bias(params: Params, *, lane: float, normal: F64) -> MapBias:
    """Nothing learned (too little GNSS-good driving before the outage, or a track that does
    not follow the route): the lane offset ``lane`` learned near the portal (``normal``: the
    route's left normal there), and the map taken as right, as without ``extensions.map_bias``
    (``offset.map_bias_null_sigma_m``). Carrying the prior's 10 m along the road instead makes
    every pseudo-position of a short-approach outage say nothing along-track, on the many maps
    that are right."""
    return _result(lane, normal, params.offset.map_bias_null_sigma_m**2 * np.eye(2))


def unbiased(params: Params, *, lane: float, normal: F64, learned: MapBias) -> MapBias:
    """The previous outage's finding that the map is right (``learned``), carried to the next
    one with the lane offset ``lane`` learned near its portal (``normal``: the route's left
    normal there)."""
    null = params.offset.map_bias_null_sigma_m**2 * np.eye(2)
    return _result(
        lane,
        normal,
        null,
        measured=learned.measured,
        measured_cov=learned.measured_cov,
        chi2=learned.chi2,
        along_observed=learned.along_observed,
        pivot=learned.pivot,
        refused=learned.refused,
    )


@dataclass(frozen=True)
class _LateralRows:
    """The approach's cross-track distances to a route, the rows of the bias fits."""

    points: F64
    """(K, 2) the track's points (thinned to the window spacing) that project inside the route"""
    d: F64
    """(K,) their cross-track distances"""
    normal: F64
    """(K, 2) the route's normals where they project"""
    weights: F64
    """(K,) 1 / variance of each distance, or (K, K) the inverse of their covariance where
    the GNSS wander is correlated along the track (``offset.map_bias_wander_rows``)"""
    span: float
    """distance along the thinned track, m"""
    common: F64
    """(K,) how much of the track's common error (the estimate's at the end) each distance
    holds: 1, or the wander's correlation with the end (``offset.map_bias_wander_rows``)"""


def _lateral_rows(
    xy: F64,
    route: Route,
    end_s: float,
    track_var: F64 | None,
    track_cov: F64,
    params: Params,
    track_t: F64 | None = None,
) -> _LateralRows | None:
    """The approach ``xy`` (ending at arc length ``end_s``) against ``route``; None with fewer
    than 5 points on it. The map's shape and the lane keeping err together over a window's
    length, so the distances count as many independent ones as windows fit in the span;
    ``track_var`` adds each point's own variance beyond the track's common error. With
    ``track_t`` (the points' times) and ``offset.map_bias_wander_rows`` the track's error is
    the filter's GNSS wander (:func:`_wander_rows`), not one error common to the whole track."""
    keep = _thin(xy, params.window.spacing_m)
    pts = xy[keep]
    step = np.hypot(*np.diff(pts, axis=0).T)
    back = np.concatenate([np.cumsum(step[::-1])[::-1], [0.0]])
    proj = route.project(pts, end_s - back, params.window.route_search_m)
    inside = (proj.s > 1e-6) & (proj.s < route.length - 1e-6)
    if np.count_nonzero(inside) < 5:
        return None
    span = float(back[0])
    d = proj.lateral[inside]
    n_eff = max(span / params.window.length_m, 1.0)
    var = np.full(len(d), len(d) * params.pseudo.shape_noise_m**2 / n_eff)
    if track_var is not None:
        v = np.asarray(track_var, np.float64)[keep][inside]
        var += np.maximum(v - 0.5 * float(np.trace(track_cov)), 0.0)
    normal = route.normal_at(proj.s[inside])
    weights: F64 = 1.0 / var
    common = np.ones(len(d))
    if track_t is not None and params.offset.map_bias_wander_rows:
        t = np.asarray(track_t, np.float64)[keep][inside]
        weights, common = _wander_rows(var, normal, t, track_cov, params)
    return _LateralRows(
        points=pts[inside],
        d=d,
        normal=normal,
        weights=weights,
        span=span,
        common=common,
    )


def _wander_rows(var: F64, normal: F64, t: F64, track_cov: F64, params: Params) -> tuple[F64, F64]:
    """The weight matrix of cross-track distances (independent variances ``var``, route
    normals ``normal``, times ``t``) whose estimate errs by the GNSS wander, a Gauss-Markov
    process of correlation time ``noise.gnss_wander_tau_s`` and covariance ``track_cov`` (the
    estimate's at the end), and the share ``rho`` of the end's error each distance holds.
    Given the end's error (carried through the fit's gain), a point ``dt`` before it errs by
    ``rho = exp(-dt / tau)`` of it plus a part of covariance ``(exp(-|t_i - t_j| / tau) -
    rho_i rho_j) track_cov``: zero at the end, growing back along the track. Counted as one
    common error, the wander of a minute's approach, a drift of the cross-track error with
    the distance from the end, is taken for a rotation of the map with a sigma too small."""
    tau = params.noise.gnss_wander_tau_s
    rho = np.exp(-(t[-1] - t) / tau)
    corr = np.exp(-np.abs(t[:, None] - t[None, :]) / tau) - np.outer(rho, rho)
    cov = corr * np.einsum("ia,ab,jb->ij", normal, track_cov, normal)
    cov[np.diag_indices_from(cov)] += var
    weights: F64 = np.linalg.inv(cov)
    return weights, rho


def _thin(xy: F64, spacing: float) -> NDArray[np.intp]:
    """Indices of the points of ``xy`` at least ``spacing`` apart along it, the last kept."""
    step = np.hypot(*np.diff(xy, axis=0).T)
    back = np.concatenate([np.cumsum(step[::-1])[::-1], [0.0]])
    keep = np.sort(np.unique(np.floor(back / spacing), return_index=True)[1])
    if keep[-1] != len(xy) - 1:
        keep = np.append(keep, len(xy) - 1)
    return keep


def _with_shape_row(
    A: F64,
    d: F64,
    nrm: F64,
    weights: F64,
    xy: F64,
    track_cov: F64,
    moved: Route,
    end_s: float,
    first: F64,
    params: Params,
) -> tuple[F64, F64, F64, F64]:
    """The fit's rows (``A``, ``d``, ``nrm``, ``weights``; unknowns lane, shift E, N, ...)
    with, where the approach's shape fixes it, its along-track registration to ``moved`` (the
    route moved back by the first solve ``first``, so that a wrong lane on a bend does not skew
    the arc length) as one more row: t . b = t . b1 + y."""
    end = xy[-1]
    s_moved = float(moved.project(end[None, :], end_s, params.window.route_search_m).s[0])
    along = _along_by_shape(
        xy, track_cov, moved, s_guess=s_moved, lane=float(first[0]), params=params
    )
    if along is None:
        return A, d, nrm, weights
    y, tangent, along_var = along
    row = np.zeros(A.shape[1])
    row[1:3] = tangent
    if weights.ndim == 1:
        weighted: F64 = np.append(weights, 1.0 / along_var)
    else:
        weighted = np.zeros((len(d) + 1, len(d) + 1))
        weighted[:-1, :-1] = weights
        weighted[-1, -1] = 1.0 / along_var
    return (
        np.vstack([A, row]),
        np.append(d, y + float(tangent @ first[1:3])),
        np.vstack([nrm, -tangent]),
        weighted,
    )


def _along_observed(normal: F64, shift_cov: F64, params: Params) -> bool:
    """Whether a fit pinned the map's shift along the road at the track's end (the route's left
    normal there ``normal``): its sigma along the road under half the prior's."""
    t = np.array([normal[1], -normal[0]])
    return math.sqrt(float(t @ shift_cov @ t)) < 0.5 * params.offset.map_bias_prior_sigma_m


def _fit_with_shape(
    A: F64,
    d: F64,
    nrm: F64,
    weights: F64,
    P0: F64,
    mean: F64,
    xy: F64,
    track_cov: F64,
    route: Route,
    end_s: float,
    params: Params,
    *,
    max_residual_m: float | None = None,
) -> tuple[F64, F64, F64, tuple[F64, F64, F64, F64]] | None:
    """The bias fit in two passes: the cross-track rows (``A``, ``d``, ``nrm``, ``weights``;
    unknowns lane, shift E, N and, with a fourth column, a rotation about the track's end)
    solved once, then again with the shape's along-track row against ``route`` moved back by
    that first solve (:func:`_with_shape_row`). Returns (u, C, G) of the second solve and the
    rows it used, or None when the cross-track residual exceeds ``max_residual_m`` (by default
    ``offset.map_bias_max_residual_m``: a track that does not follow the route)."""
    n_lateral = len(d)
    first = _solve(A, d, weights, P0, nrm, mean)[0]
    rotation = float(first[3]) if len(first) > 3 else 0.0
    moved = Route(xy_moved_back(route.xy, first[1:3], rotation, xy[-1]))
    rows = _with_shape_row(A, d, nrm, weights, xy, track_cov, moved, end_s, first, params)
    A, d, nrm, weights = rows
    u, C, G = _solve(A, d, weights, P0, nrm, mean)
    residual = float(np.sqrt(np.mean((d[:n_lateral] - A[:n_lateral] @ u) ** 2)))
    if max_residual_m is None:
        max_residual_m = params.offset.map_bias_max_residual_m
    if not np.isfinite(residual) or residual > max_residual_m:
        return None
    return u, C, G, rows


def _along_by_shape(
    xy: F64, track_cov: F64, route: Route, *, s_guess: float, lane: float, params: Params
) -> tuple[float, F64, float] | None:
    """The along-track part of the bias from registering the track's shape to the route with
    the matcher's rigid fit (:func:`estimator.matching.match.match_geometry`): the along-track
    difference between the fitted route position of the end and the end, the direction and
    its variance; None where the shape does not fix it."""
    geometry = match_geometry(
        xy, xy[-1], track_cov, route, s_guess=s_guess, lane_offset=lane, params=params
    )
    fit = geometry.fit
    if fit is None or not fit.along_observed or not np.isfinite(fit.residual):
        return None
    if fit.residual > params.offset.map_bias_max_residual_m:
        return None
    t = np.asarray(fit.tangent, np.float64)
    return float(t @ (fit.z - xy[-1])), t, float(t @ fit.obs_cov @ t)


def _solve(A: F64, d: F64, weights: F64, P0: F64, nrm: F64, prior: F64) -> tuple[F64, F64, F64]:
    """The weighted least-squares ``u = prior + K (d - A prior)`` with the prior ``prior``,
    ``P0``, its covariance with the independent noise, and the gain ``G = K N`` of the track's
    common error: ``d`` holds ``n_i . (estimate - truth)``, so u's error is ``K N eps``; the
    filter's states are the negative of u's error and its position error is truth -
    estimate, hence ``G``. ``weights``: (K,) the rows' inverse variances, or (K, K) the
    inverse of their covariance."""
    WA = weights[:, None] * A if weights.ndim == 1 else weights @ A
    C = np.linalg.inv(A.T @ WA + np.linalg.inv(P0))
    K = C @ WA.T
    return prior + K @ (d - A @ prior), C, K @ nrm


def _turn_spread(route: Route, s_end: float, end: F64, params: Params) -> F64:
    """(2, 2) the mean of ``J (end - q) (J (end - q))^T`` over the route points ``q`` within
    ``offset.map_bias_track_m`` times ten of arc length ``s_end`` (``offset.map_bias_turn_prior``).
    A map drawn turned by ``a`` about a point ``c`` is shifted by ``b0 + a J (end - c)`` at
    ``end``: the prior of the map's shift (``offset.map_bias_cross_sigma_m``, a map's local
    error) holds at ``c``, not at the approach's end, and with ``c`` unknown (anywhere a
    turned map may be right, as :func:`_least_bias_ahead` takes it) the shift at the end has
    the rotation's variance times this more. Held at the local prior instead, a map turned
    about a point kilometres away, tens of metres off at the portal, is shrunk to its prior
    and the fitted rotation and lane take up the difference (biased on a perfect track)."""
    reach = 10.0 * params.offset.map_bias_track_m
    s = np.arange(max(s_end - reach, 0.0), min(s_end + reach, route.length), 50.0)
    if len(s) == 0:
        return np.zeros((2, 2))
    d = end - route.point_at(s)
    jd = np.column_stack([-d[:, 1], d[:, 0]])
    out: F64 = jd.T @ jd / len(s)
    return out


def _least_bias_ahead(
    route: Route, s_end: float, end: F64, offset: F64, rotation: float, params: Params
) -> float:
    """The smallest the bias ``offset`` at ``end`` (route arc length ``s_end``), turned by
    ``rotation`` about it, gets on the next ``offset.map_bias_track_m`` times ten of route, in
    prior sigmas. A map drawn turned is off most far from where it is right, which may lie
    in the tunnel ahead; a parallel road is off by as much everywhere."""
    ahead = np.arange(s_end, min(s_end + 10.0 * params.offset.map_bias_track_m, route.length), 50.0)
    if len(ahead) == 0:
        ahead = np.array([s_end])
    xy = route.point_at(ahead)
    d = xy - end
    bias = offset + rotation * np.column_stack([-d[:, 1], d[:, 0]])
    # the prior where the bias was learned: a shift across the road there is one across the
    # road wherever the route ahead turns
    inv = np.linalg.inv(_prior_cov(params, route.normal_at(np.array([s_end]))[0]))
    return math.sqrt(float(np.min(np.einsum("ki,ij,kj->k", bias, inv, bias))))


def _turned_rows(
    xy: F64,
    route: Route,
    end_s: float,
    track_var: F64 | None,
    track_cov: F64,
    params: Params,
    track_t: F64 | None = None,
) -> tuple[F64, F64, F64, F64] | None:
    """The cross-track rows of the fit (``A``, ``d``, ``nrm``, ``weights``; unknowns lane,
    shift E, N at the approach's end and a rotation about it) of the approach ``xy`` against
    ``route``; None where it is too short (:func:`_lateral_rows`). ``nrm`` holds the share of
    the track's common error each row carries."""
    rows = _lateral_rows(xy, route, end_s, track_var, track_cov, params, track_t)
    if rows is None or rows.span < params.window.length_m:
        return None
    rel = rows.points - xy[-1]
    turned = np.column_stack([-rel[:, 1], rel[:, 0]])  # J (x - x_e)
    nrm = rows.normal
    A = np.column_stack([np.ones(len(rows.d)), -nrm, -np.sum(nrm * turned, axis=1)])
    return A, rows.d, nrm * rows.common[:, None], rows.weights


def _relinearised_fit(
    xy: F64,
    route: Route,
    end_s: float,
    rows: tuple[F64, F64, F64, F64],
    track_var: F64 | None,
    track_cov: F64,
    P0: F64,
    mean: F64,
    params: Params,
    *,
    passes: int,
    track_t: F64 | None = None,
) -> tuple[F64, F64, F64, tuple[F64, F64, F64, F64]] | None:
    """:func:`_fit_with_shape` on the approach's ``rows`` against ``route``
    (:func:`_turned_rows`), then ``passes - 1`` times more on its rows against the route moved
    back by the fit so far (Gauss-Newton: the increment's prior is the prior less what is
    moved back, and the bias field being linear in shift and rotation about the end, the
    increments add). Distances to a route tens of
    metres off are not linear in the shift where the route bends, so only the last pass's
    residual tells whether the track follows the route."""
    moved_by = np.zeros(4)
    moved, s_moved = route, end_s
    fit = None
    for k in range(passes):
        if fit is not None:
            moved = Route(xy_moved_back(route.xy, moved_by[1:3], float(moved_by[3]), xy[-1]))
            s_moved = float(moved.project(xy[-1:], end_s, params.window.route_search_m).s[0])
            moved_rows = _turned_rows(xy, moved, s_moved, track_var, track_cov, params, track_t)
            if moved_rows is None:
                return None
            rows = moved_rows
        step = _fit_with_shape(
            *rows,
            P0,
            mean - moved_by,
            xy,
            track_cov,
            moved,
            s_moved,
            params,
            max_residual_m=None if k == passes - 1 else math.inf,
        )
        if step is None:
            return None
        u, C, G, used = step
        fit = (u + moved_by, C, G, used)
        moved_by = np.concatenate([[0.0], fit[0][1:]])
    return fit


def _far_turned_fit(
    xy: F64,
    route: Route,
    end_s: float,
    rows: tuple[F64, F64, F64, F64],
    track_var: F64 | None,
    track_cov: F64,
    P0: F64,
    mean: F64,
    params: Params,
    track_t: F64 | None = None,
) -> tuple[F64, F64, F64, tuple[F64, F64, F64, F64]] | None:
    """The fit with the shift's prior widened by the rotation's share (:func:`_turn_spread`)
    for an approach the fit held at the map's local prior cannot follow
    (``offset.map_bias_far_turned``): a map drawn turned about a point kilometres ahead lies
    tens of metres off at the portal, more than the local prior lets the shift take. Fitted
    in ``offset.map_bias_far_turned_passes`` passes (:func:`_relinearised_fit`), kept only when
    the rotation is significant and makes the shift one the map may have somewhere ahead
    (:func:`_least_bias_ahead`); a parallel road, off by as much everywhere, stays refused."""
    op = params.offset
    wide = P0.copy()
    wide[1:3, 1:3] += wide[3, 3] * _turn_spread(route, end_s, xy[-1], params)
    fit = _relinearised_fit(
        xy,
        route,
        end_s,
        rows,
        track_var,
        track_cov,
        wide,
        mean,
        params,
        passes=op.map_bias_far_turned_passes,
        track_t=track_t,
    )
    if fit is None:
        return None
    u, C, G, _ = fit
    total = C + G @ track_cov @ G.T
    if u[3] ** 2 / total[3, 3] < op.map_bias_min_sigmas**2 or abs(u[0]) > op.max_offset_m:
        return None
    if _least_bias_ahead(route, end_s, xy[-1], u[1:3], float(u[3]), params) > (
        op.map_bias_max_prior_sigmas
    ):
        return None
    return fit


def _unapplied_turn_var(rotation: float, var: float, params: Params) -> float:
    """The variance of the map's rotation error considered for a rotation fitted (``rotation``,
    variance ``var``) but not applied. By default the method of moments, its square less its
    variance: from one fit that is positive on a third of right maps (any draw beyond one
    sigma), and a long approach's fit with a sigma of hundredths of a degree makes such a
    draw a rotation that grows the pseudo-positions' error kilometres into a tunnel. With
    ``offset.map_turn_lower_sigmas`` ``k`` it is the square of the least rotation the fit
    shows at ``k`` sigmas, ``(|rotation| - k sigma)^2`` where positive: a draw within ``k``
    sigmas claims nothing, one at the significance test nearly all it shows."""
    k = params.offset.map_turn_lower_sigmas
    if k <= 0.0:
        return max(rotation**2 - var, 0.0)
    return max(abs(rotation) - k * math.sqrt(var), 0.0) ** 2


def learn_map_bias(
    track_xy: F64,
    track_cov: F64,
    route: Route,
    *,
    s_guess: float | None,
    lane_offset: float,
    params: Params,
    track_var: F64 | None = None,
    track_t: F64 | None = None,
) -> MapBias:
    """The map bias from ``track_xy`` (N, 2), the GNSS-good estimate over the last
    ``offset.map_bias_track_m`` in time order, ending at the vehicle; ``track_cov`` its E/N
    covariance at the end; ``track_var`` (N,) the estimate's horizontal variance per point
    (a point less certain than the end weighs less); ``track_t`` (N,) the points' times (for
    ``offset.map_bias_wander_rows``); ``s_guess`` the route arc length of the
    end; ``lane_offset`` the lane offset learned near the end (kept when the bias is not
    significant). A track that does not follow the route (residual above
    ``offset.map_bias_max_residual_m``) learns nothing."""
    op = params.offset
    xy = np.asarray(track_xy, np.float64)[:, :2]
    end_s = route.project(xy[-1:]).s[0] if s_guess is None else float(s_guess)
    normal_end = route.normal_at(np.array([end_s]))[0]
    prior = prior_bias(params, lane=lane_offset, normal=normal_end)
    if len(xy) < 2:
        return prior
    rows = _turned_rows(xy, route, end_s, track_var, track_cov, params, track_t)
    if rows is None:
        return prior
    end = xy[-1]
    A, d, nrm, weights = lateral = rows
    P0 = np.zeros((4, 4))
    P0[0, 0] = op.map_bias_lane_sigma_m**2
    P0[1:3, 1:3] = _prior_cov(params, normal_end)
    P0[3, 3] = math.radians(op.map_bias_rotation_sigma_deg) ** 2
    # the shape's along-track registration, to the route moved back by the cross-track fit's
    # bias and lane (matched to a wrong lane, a bend's arc length is off): t . b = t . b1 + y,
    # the track's common error entering as -t . eps
    mean = np.array([op.map_bias_lane_prior_m, 0.0, 0.0, 0.0])
    fit = _fit_with_shape(A, d, nrm, weights, P0, mean, xy, track_cov, route, end_s, params)
    far = None
    if op.map_bias_far_turned and (fit is None or abs(fit[0][0]) > op.max_offset_m):
        far = _far_turned_fit(
            xy, route, end_s, lateral, track_var, track_cov, P0, mean, params, track_t
        )
        fit = fit if far is None else far
    if fit is None:
        return prior
    u, C, G, (A, d, nrm, weights) = fit
    total = C + G @ track_cov @ G.T
    rotated = u[3] ** 2 / total[3, 3] >= op.map_bias_min_sigmas**2
    full = (u, C, G, total)
    turn_var = float(C[3, 3])
    honest_turn_var = turn_var
    second_moment = turn_var
    if not rotated:
        second_moment = float(u[3] ** 2 + total[3, 3])
        # a rotation not applied leaves the map turned by what the fit saw, less what its own
        # noise explains (a right map within its noise gains nothing)
        turn_var = _unapplied_turn_var(float(u[3]), float(total[3, 3]), params)
        honest_turn_var = turn_var
        if params.extensions.map_turn_estimate and op.map_turn_honest_prior:
            # with the bias applied the outage's matches estimate the rotation error, which can
            # then start from its honest second moment (taking it as zero given N(u3, total33))
            honest_turn_var = float(u[3] ** 2 + total[3, 3])
        # a rotation no test tells from zero is not applied, nor does its sigma, extrapolated
        # from the approach into a long tunnel, swamp the bias learned at the portal
        u3, C3, G3 = _solve(A[:, :3], d, weights, P0[:3, :3], nrm, mean[:3])
        u, C, G = np.append(u3, 0.0), np.zeros((4, 4)), np.zeros((4, 2))
        C[:3, :3], G[:3] = C3, G3
        total = C + G @ track_cov @ G.T
        if (
            op.map_bias_turned_rescue
            and _least_bias_ahead(route, end_s, end, u[1:3], 0.0, params)
            > op.map_bias_max_prior_sigmas
            and _least_bias_ahead(route, end_s, end, full[0][1:3], float(full[0][3]), params)
            <= op.map_bias_max_prior_sigmas
            and abs(full[0][0]) <= op.max_offset_m
            and full[0][3] ** 2 / full[3][3, 3] >= 4.0
        ):
            # a shift too large for a map's unless the map is turned, and the rotation, at
            # two sigmas if not three, is what makes it one: a map drawn turned about a point
            # far into the tunnel is metres off at the portal, a parallel road everywhere
            u, C, G, total = full
            rotated = True
            turn_var = float(C[3, 3])
            honest_turn_var = turn_var
            second_moment = turn_var
    b, Cb = u[1:3], total[1:3, 1:3]
    chi2 = float(b @ np.linalg.solve(Cb, b))
    along_observed = _along_observed(normal_end, C[1:3, 1:3], params)
    refused: MapBiasRefusal | None = None
    if abs(u[0]) > op.max_offset_m:
        refused = "lane too far"
    elif (
        _least_bias_ahead(route, end_s, end, b, float(u[3]), params) > op.map_bias_max_prior_sigmas
    ):
        refused = "too large"
    if refused is not None:
        map_cov = np.zeros((2, 2))
    elif chi2 < op.map_bias_min_sigmas**2 and not rotated:
        map_cov = op.map_bias_null_sigma_m**2 * np.eye(2)
    else:
        map_cov = None
    if map_cov is not None:
        return _result(
            lane_offset,
            normal_end,
            map_cov,
            measured=b,
            measured_cov=Cb,
            chi2=chi2,
            along_observed=along_observed,
            pivot=end,
            turn_var=turn_var,
            refused=refused,
        )
    if rotated and op.map_bias_turn_prior and far is None:
        # decided with the map's shift held at its local prior (the tests for another road
        # and for significance as without the switch), the turned bias's values from the fit
        # whose shift prior includes the rotation's share (:func:`_turn_spread`)
        P0[1:3, 1:3] += P0[3, 3] * _turn_spread(route, end_s, end, params)
        spread = _fit_with_shape(*lateral, P0, mean, xy, track_cov, route, end_s, params)
        if spread is not None:
            u, C, G, _ = spread
            total = C + G @ track_cov @ G.T
            b, Cb = u[1:3], total[1:3, 1:3]
            chi2 = float(b @ np.linalg.solve(Cb, b))
            along_observed = _along_observed(normal_end, C[1:3, 1:3], params)
            honest_turn_var = second_moment = float(C[3, 3])
    return MapBias(
        offset=b,
        rotation=float(u[3]),
        rotation_sigma=math.sqrt(float(C[3, 3])),
        pivot=end,
        lane=float(u[0]),
        gain=G[:3],
        cov=C[:3, :3],
        measured=b,
        measured_cov=Cb,
        chi2=chi2,
        along_observed=along_observed,
        turn_var=honest_turn_var,
        turn_second_moment=second_moment,
    )


def _carried_turn_var(previous: MapBias) -> float:
    """The variance of the map's rotation error a carried bias is refined with
    (``extensions.map_turn_two_places``): the applied rotation's, else the honest second moment
    of one fitted but not applied, never less than the method of moments'."""
    return max(previous.rotation_sigma**2, previous.turn_var, previous.turn_second_moment)


def carried_bias(
    previous: MapBias,
    offset: F64,
    *,
    position: F64,
    lane_seen: float,
    normal: F64,
    metres: float,
    params: Params,
) -> MapBias:
    """The bias of the previous outage, ``offset`` at its pivot as that outage's matches left
    it, carried to the next outage ``metres`` further along where the driving in between was
    too short to learn one: the map's bias there is the same one, wandered and turned a little
    further (``offset.map_bias_walk_m_per_sqrt_km``; the rotation's uncertainty, which for a
    rotation seen but not applied is ``turn_var``, not the zero sigma of the rotation not
    applied). ``lane_seen``: the cross-track offset from the route learned near the portal
    (lane and map together), at ``position`` where the route's left normal is ``normal``. The
    bias's error is no longer the position's (GNSS has since corrected the position), so it
    is carried independent."""
    op = params.offset
    d = position - previous.pivot
    here = offset + previous.rotation * np.array([-d[1], d[0]])
    grow = op.map_bias_walk_m_per_sqrt_km**2 * metres / 1000.0
    turn = max(previous.rotation_sigma**2, previous.turn_var)
    if params.extensions.map_turn_honest_consider:
        turn = max(turn, previous.turn_second_moment)
    grow += turn * float(d @ d)
    cov = np.zeros((3, 3))
    cov[1:, 1:] = previous.measured_cov + grow * np.eye(2)
    gain = np.zeros((3, 2))
    gain[0] = normal
    return dataclasses.replace(
        previous,
        offset=offset,
        lane=float(lane_seen + normal @ here),
        gain=gain,
        cov=cov,
    )


def carried_explains(carried: MapBias, fresh: MapBias, params: Params) -> bool:
    """Whether ``fresh``, learned afresh before this outage and refused as too large for a
    map's error, is the bias ``carried`` (:func:`carried_bias`, from the previous outage)
    predicts at ``fresh``'s pivot (``extensions.map_bias_carry_turned``): its shift turned by
    its rotation about its own pivot, within ``offset.map_bias_max_prior_sigmas`` of the two
    covariances together. The test for another road holds a fresh bias against the generic
    prior of a map's error; after a map's rotation was learned, the map's own field is the
    better prior, and a parallel road does not follow it."""
    if fresh.refused != "too large" or not carried.significant:
        return False
    if not (np.all(np.isfinite(fresh.measured)) and np.all(np.isfinite(fresh.pivot))):
        return False
    d = fresh.pivot - carried.pivot
    predicted = carried.offset + carried.rotation * np.array([-d[1], d[0]])
    r = fresh.measured - predicted
    chi2 = float(r @ np.linalg.solve(carried.cov[1:, 1:] + fresh.measured_cov, r))
    return chi2 <= params.offset.map_bias_max_prior_sigmas**2


def refined_bias(
    track_xy: F64,
    track_cov: F64,
    route: Route,
    *,
    carried: MapBias,
    s_guess: float,
    params: Params,
    track_var: F64 | None = None,
    metres: float = 0.0,
) -> MapBias:
    """The bias ``carried`` from the previous outage (:func:`carried_bias`), refined by the
    GNSS-good driving since (``track_xy`` (N, 2), ending at the vehicle; ``track_cov``,
    ``track_var`` and ``s_guess`` as for :func:`learn_map_bias`) when it is too short to learn
    the bias afresh. Every GNSS-good stretch between tunnels measures the map's bias anew,
    with the receiver's wander of its own time, not the approach's: where the stretch turns,
    its cross-track distances and its shape fix the along-track bias, which the outage's
    matches cannot (they see the position and the map's error only together). The carried
    bias is the prior of the same least-squares fit, with the route moved back by it; its
    rotation is kept. A stretch that does not follow the moved-back route (residual above
    ``offset.map_bias_max_residual_m``, or a lane beyond ``offset.max_offset_m``) leaves
    ``carried`` as it is. With ``extensions.map_turn_two_places`` the map's rotation is fitted
    too (:func:`_refined_turn`; ``metres``: the distance driven since ``carried``'s pivot)."""
    op = params.offset
    xy = np.asarray(track_xy, np.float64)[:, :2]
    if not carried.significant or len(xy) < 2:
        return carried
    moved = Route(carried.moved_back(route.xy, carried.offset))
    end = xy[-1]
    end_s = float(moved.project(end[None, :], s_guess, params.window.route_search_m).s[0])
    rows = _lateral_rows(xy, moved, end_s, track_var, track_cov, params)
    if rows is None:
        return carried
    if params.extensions.map_turn_two_places:
        turned = _refined_turn(xy, track_cov, moved, end_s, rows, carried, metres, params)
        if turned is not None:
            return turned
    d, nrm, weights = rows.d, rows.normal, rows.weights
    A = np.column_stack([np.ones(len(d)), -nrm])
    P0 = np.zeros((3, 3))
    P0[0, 0] = op.map_bias_lane_sigma_m**2
    P0[1:, 1:] = carried.cov[1:, 1:]
    mean = np.array([op.map_bias_lane_prior_m, 0.0, 0.0])
    fit = _fit_with_shape(A, d, nrm, weights, P0, mean, xy, track_cov, moved, end_s, params)
    if fit is None:
        return carried
    u, C, G, _ = fit
    if abs(u[0]) > op.max_offset_m:
        return carried
    offset = carried.offset + u[1:]
    total = C + G @ track_cov @ G.T
    b_total = total[1:, 1:]
    return dataclasses.replace(
        carried,
        offset=offset,
        lane=float(u[0]),
        gain=G,
        cov=C,
        measured=offset,
        measured_cov=b_total,
        chi2=float(offset @ np.linalg.solve(b_total, offset)),
        along_observed=_along_observed(moved.normal_at(np.array([end_s]))[0], C[1:, 1:], params),
    )


def _refined_turn(
    xy: F64,
    track_cov: F64,
    moved: Route,
    end_s: float,
    rows: _LateralRows,
    carried: MapBias,
    metres: float,
    params: Params,
) -> MapBias | None:
    """The map's rotation learned from two places (``extensions.map_turn_two_places``): the
    bias at ``carried``'s pivot and the GNSS-good stretch ``xy`` a distance ``D`` from it,
    its cross-track ``rows`` against the route ``moved`` back by ``carried``. A rotation error
    ``r`` about the pivot shifts the map at the stretch by ``r J D``, so the fit's unknowns are
    the lane, the shift at the stretch's end and ``r`` (about that end), with the prior the
    carried bias implies: the shift's covariance the pivot's (its measured covariance and the
    wander since) plus ``s^2 (J D)(J D)^T``, its covariance with ``r`` ``s^2 J D``, where
    ``s^2`` is the rotation's honest variance (:func:`_carried_turn_var`). GNSS measures the
    shift at the stretch, so the stretch's cross-track offset tells ``r`` kilometres from the
    pivot, which one approach cannot tell from the heading's drift. Where ``r`` passes the
    significance test (``offset.map_turn_two_places_min_sigmas``) the bias is moved to the
    stretch's end (the new pivot) with the rotation ``carried.rotation + r`` and its sigma;
    otherwise None (the plain refine follows). Where ``carried`` applies a rotation and
    ``extensions.map_turn_two_places_applied``, ``r`` corrects it whatever its significance:
    with the applied rotation's own variance as its prior the fit is its posterior."""
    op = params.offset
    end = xy[-1]
    D = end - carried.pivot
    jd = np.array([-D[1], D[0]])
    s2 = _carried_turn_var(carried)
    if s2 <= 0.0:
        return None
    d, nrm, weights = rows.d, rows.normal, rows.weights
    rel = rows.points - end
    turned = np.column_stack([-rel[:, 1], rel[:, 0]])
    A = np.column_stack([np.ones(len(d)), -nrm, -np.sum(nrm * turned, axis=1)])
    P0 = np.zeros((4, 4))
    P0[0, 0] = op.map_bias_lane_sigma_m**2
    walk = op.map_bias_walk_m_per_sqrt_km**2 * max(metres, 0.0) / 1000.0
    P0[1:3, 1:3] = carried.measured_cov + walk * np.eye(2) + s2 * np.outer(jd, jd)
    P0[1:3, 3] = P0[3, 1:3] = s2 * jd
    P0[3, 3] = s2
    mean = np.array([op.map_bias_lane_prior_m, 0.0, 0.0, 0.0])
    fit = _fit_with_shape(A, d, nrm, weights, P0, mean, xy, track_cov, moved, end_s, params)
    if fit is None:
        return None
    u, C, G, _ = fit
    total = C + G @ track_cov @ G.T
    # a rotation already applied is corrected by its posterior; the test decides whether to
    # apply one at all
    corrects = params.extensions.map_turn_two_places_applied and carried.rotation != 0.0
    if abs(u[0]) > op.max_offset_m or (
        not corrects and u[3] ** 2 / total[3, 3] < op.map_turn_two_places_min_sigmas**2
    ):
        return None
    here = carried.offset + carried.rotation * jd
    offset = here + u[1:3]
    b_total = total[1:3, 1:3]
    turn_var = float(C[3, 3])
    return dataclasses.replace(
        carried,
        offset=offset,
        rotation=carried.rotation + float(u[3]),
        rotation_sigma=math.sqrt(turn_var),
        pivot=end.copy(),
        lane=float(u[0]),
        gain=G[:3],
        cov=C[:3, :3],
        measured=offset,
        measured_cov=b_total,
        chi2=float(offset @ np.linalg.solve(b_total, offset)),
        along_observed=_along_observed(moved.normal_at(np.array([end_s]))[0], C[1:3, 1:3], params),
        turn_var=turn_var,
        turn_second_moment=turn_var,
    )
