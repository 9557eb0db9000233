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
map) share it out, with the covariance saying that the share is unknown. A least-squares fit
with those priors gives ``u = [l, b]`` and its covariance.

The errors ``e_i`` have two parts. The estimate's own error at the end of the track (the
receiver's slow wander) is common to the whole track; it enters ``u`` through a gain ``G``
(3, 2), and since every pseudo-position of the outage is made from ``u``, the filter carries the
lane-offset and map-bias errors as considered states cloned through ``G`` from its position
error at the outage start (:func:`estimator.filter.updates.clone_route_errors`): the
pseudo-positions then hold the estimate to the road without claiming to know it better than
GNSS did. The rest (map shape, lane keeping) is noise of ``pseudo.shape_noise_m`` per
``window.length_m`` of track, independent of the state.

The bias is used only when a chi-square test of ``b`` against zero, with its full covariance,
exceeds ``offset.map_bias_min_sigmas`` squared: a right map then keeps the lane offset learned
near the portal and no bias, and the filter only carries ``offset.map_bias_null_sigma_m`` of
map error (a map no test can tell from right is not known to be right). Otherwise the route is
moved back by ``b`` for every match of the outage and ``l`` is its lane offset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimator.matching.match import match_geometry
from estimator.params import Params
from estimator.route import Route

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class MapBias:
    """The route's bias learned before an outage: route position minus road position."""

    offset: F64
    """(2,) E, N: the route lies ``offset`` from the road driven, m (zero unless significant)"""
    lane: float
    """the lane offset to keep with it (positive = vehicle left of the road), m"""
    gain: F64
    """(3, 2) how the estimate's E/N position error at the outage start enters the lane-offset
    and the map-bias (E, N) errors"""
    cov: F64
    """(3, 3) covariance of the lane-offset and map-bias (E, N) errors beyond ``gain``'s part"""
    measured: F64
    """(2,) the fit's estimate of the map's bias before the significance test, m (NaN when
    nothing was learned)"""
    measured_cov: F64
    """(2, 2) its covariance, the part shared with the position error included, m^2"""
    chi2: float
    """``measured`` against zero (NaN when nothing was learned)"""
    along_observed: bool
    """the track's turns fixed the along-track bias to better than half its prior"""

    @property
    def significant(self) -> bool:
        """The bias was applied (it differs from zero by more than the test allows)."""
        return bool(np.any(self.offset != 0.0))

    @property
    def bias_cov(self) -> F64:
        """(2, 2) the map-bias error's covariance at the outage start, for a position error of
        zero (the part not shared with it), m^2."""
        out: F64 = self.cov[1:, 1:]
        return out


def prior_bias(params: Params, *, lane: float, normal: F64) -> MapBias:
    """Nothing learned: the lane offset ``lane`` learned near the portal (its error the position
    error across ``normal``), zero bias with the prior covariance."""
    op = params.offset
    t = np.array([normal[1], -normal[0]])
    cov = np.zeros((3, 3))
    cov[1:, 1:] = op.map_bias_prior_sigma_m**2 * np.outer(t, t)
    cov[1:, 1:] += op.map_bias_cross_sigma_m**2 * np.outer(normal, normal)
    gain = np.zeros((3, 2))
    gain[0] = normal
    return MapBias(
        offset=np.zeros(2),
        lane=lane,
        gain=gain,
        cov=cov,
        measured=np.full(2, np.nan),
        measured_cov=np.full((2, 2), np.nan),
        chi2=math.nan,
        along_observed=False,
    )


def _thin(xy: F64, spacing: float) -> F64:
    """The points of ``xy`` at least ``spacing`` apart along it, the last kept."""
    step = np.hypot(*np.diff(xy, axis=0).T)
    back = np.concatenate([np.cumsum(step[::-1])[::-1], [0.0]])
    keep = np.unique(np.floor(back / spacing), return_index=True)[1]
    out: F64 = xy[np.sort(keep)]
    if not np.array_equal(out[-1], xy[-1]):
        out = np.vstack([out, xy[-1:]])
    return out


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


def learn_map_bias(
    track_xy: F64,
    track_cov: F64,
    route: Route,
    *,
    s_guess: float | None,
    lane_offset: float,
    params: Params,
) -> MapBias:
    """The map bias from ``track_xy`` (N, 2), the GNSS-good estimate over the last
    ``offset.map_bias_track_m`` in time order, ending at the vehicle; ``track_cov`` its E/N
    covariance at the end; ``s_guess`` the route arc length of the end; ``lane_offset`` the
    lane offset learned near the end (kept when the bias is not significant). A track that
    does not follow the route (residual above ``offset.map_bias_max_residual_m``) learns
    nothing."""
    op = params.offset
    xy = np.asarray(track_xy, np.float64)[:, :2]
    end_s = route.project(xy[-1:]).s[0] if s_guess is None else float(s_guess)
    normal_end = route.normal_at(np.array([end_s]))[0]
    prior = prior_bias(params, lane=lane_offset, normal=normal_end)
    if len(xy) < 2:
        return prior
    pts = _thin(xy, params.window.spacing_m)
    step = np.hypot(*np.diff(pts, axis=0).T)
    back = np.concatenate([np.cumsum(step[::-1])[::-1], [0.0]])
    proj = route.project(pts, end_s - back, params.window.route_search_m)
    inside = (proj.s > 1e-6) & (proj.s < route.length - 1e-6)
    span = float(back[0])
    if np.count_nonzero(inside) < 5 or span < params.window.length_m:
        return prior
    d = proj.lateral[inside]
    nrm = route.normal_at(proj.s[inside])
    A = np.column_stack([np.ones(len(d)), -nrm])
    # the map's shape and the lane keeping err together over a window's length
    n_eff = max(span / params.window.length_m, 1.0)
    weights = np.full(len(d), n_eff / (len(d) * params.pseudo.shape_noise_m**2))
    along = _along_by_shape(xy, track_cov, route, s_guess=end_s, lane=lane_offset, params=params)
    if along is not None:
        # the shape's along-track registration: t . b = y, the track's common error entering
        # as -t . eps
        y, tangent, var = along
        A = np.vstack([A, np.concatenate([[0.0], tangent])])
        d = np.append(d, y)
        nrm = np.vstack([nrm, -tangent])
        weights = np.append(weights, 1.0 / var)
    t_end = np.array([normal_end[1], -normal_end[0]])
    P0 = np.zeros((3, 3))
    P0[0, 0] = op.map_bias_lane_sigma_m**2
    P0[1:, 1:] = op.map_bias_prior_sigma_m**2 * np.outer(t_end, t_end)
    P0[1:, 1:] += op.map_bias_cross_sigma_m**2 * np.outer(normal_end, normal_end)
    info = A.T @ (weights[:, None] * A) + np.linalg.inv(P0)
    C = np.linalg.inv(info)  # posterior covariance with the independent noise
    K = C @ (A * weights[:, None]).T  # u = K d (zero prior mean)
    u = K @ d
    lateral = A[: len(inside.nonzero()[0])]
    residual = float(np.sqrt(np.mean((d[: len(lateral)] - lateral @ u) ** 2)))
    if not np.isfinite(residual) or residual > op.map_bias_max_residual_m:
        return prior
    # d_i holds n_i . (estimate - truth): u's error is K N eps; the state is the negative of
    # u's error, and the position error state is truth - estimate, hence G = K N
    G = K @ nrm
    b, Cb = u[1:], C[1:, 1:] + G[1:] @ track_cov @ G[1:].T
    chi2 = float(b @ np.linalg.solve(Cb, b))
    along_sigma = math.sqrt(float(t_end @ C[1:, 1:] @ t_end))
    along_observed = along_sigma < 0.5 * op.map_bias_prior_sigma_m
    if chi2 < op.map_bias_min_sigmas**2:
        null = np.zeros((3, 3))
        null[1:, 1:] = op.map_bias_null_sigma_m**2 * np.eye(2)
        gain = np.zeros((3, 2))
        gain[0] = normal_end
        return MapBias(
            offset=np.zeros(2),
            lane=lane_offset,
            gain=gain,
            cov=null,
            measured=b,
            measured_cov=Cb,
            chi2=chi2,
            along_observed=along_observed,
        )
    return MapBias(
        offset=b,
        lane=float(u[0]),
        gain=G,
        cov=C,
        measured=b,
        measured_cov=Cb,
        chi2=chi2,
        along_observed=along_observed,
    )
