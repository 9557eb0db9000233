"""Where the mission route lies relative to the road actually driven.

An SD-map route is not the road: it is offset across (the lane, and the map's own error) and
along (a junction or a portal drawn metres early), and often slightly rotated. Matching the
dead-reckoned window to such a route hands the filter a position on the map, so an uncorrected
bias drags the estimate along the map while the route-relative deviation looks excellent.

Before each outage the GNSS-good track of the last ``offset.map_bias_track_m`` is registered to
the route with the same rigid fit as a match (:func:`estimator.matching.match.match_geometry`).
Where the fitted route position of the vehicle differs from the GNSS position, the difference is
the map's bias there, measured with the fit's covariance: across-track well, along-track only
where the road curves within the track (on a straight approach the fit's along-track sigma is
100 m and the bias stays at its prior). The estimate is the posterior of that measurement with
a zero-mean prior of ``offset.map_bias_prior_sigma_m``:

    K   = S0 (S0 + R)^-1           S0 = prior covariance, R = fit covariance + GNSS covariance
    b   = K (z_route - p_gnss)     the bias estimate
    S_b = (I - K) S0               its covariance

During the outage every pseudo-position is taken from the route moved back by ``b``. The error
of ``b`` is one error shared by all of the outage's matches, so the filter carries it as a
considered state with covariance ``S_b`` (:func:`estimator.filter.updates.set_map_bias`), grown
as a random walk with the distance driven (a map's error changes along the road,
``offset.map_bias_walk_m_per_sqrt_km``).
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
    """The route's bias learned before an outage: route position minus true position."""

    offset: F64
    """(2,) E, N: the route lies ``offset`` from the road driven, m"""
    cov: F64
    """(2, 2) its covariance where it was learned, m^2"""
    measured: F64
    """(2,) the fit's raw measurement of the offset, before the prior, m"""
    along_observed: bool
    """the track's shape fixed the along-track bias (else it is the prior's)"""


def prior_bias(params: Params) -> MapBias:
    """Nothing learned: zero offset with the prior covariance."""
    s0 = params.offset.map_bias_prior_sigma_m
    return MapBias(
        offset=np.zeros(2),
        cov=s0**2 * np.eye(2),
        measured=np.full(2, np.nan),
        along_observed=False,
    )


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
    covariance at the end; ``s_guess`` the route arc length of the end. A fit that does not
    follow the road (residual above ``offset.map_bias_max_residual_m``) learns nothing."""
    op = params.offset
    prior = prior_bias(params)
    if len(track_xy) < 2:
        return prior
    end = np.asarray(track_xy[-1], np.float64)
    geometry = match_geometry(
        track_xy,
        end,
        track_cov,
        route,
        s_guess=s_guess,
        lane_offset=lane_offset,
        params=params,
    )
    fit = geometry.fit
    if fit is None or not np.isfinite(fit.residual) or fit.residual > op.map_bias_max_residual_m:
        return prior
    measured = fit.z - end
    t = fit.tangent
    r = float(t @ (fit.obs_cov + track_cov) @ t)
    b = float(t @ measured)
    s0 = op.map_bias_prior_sigma_m**2
    k = s0 / (s0 + r)  # K = S0 (S0 + R)^-1
    var = (1.0 - k) * s0  # S_b = (1 - K) S0
    along = k * b if abs(b) >= op.map_bias_min_sigmas * math.sqrt(r) else 0.0  # b = K (z - p)
    return MapBias(
        offset=along * t,
        cov=var * np.outer(t, t) + op.map_bias_cross_sigma_m**2 * np.outer(fit.normal, fit.normal),
        measured=measured,
        along_observed=bool(fit.along_observed),
    )
