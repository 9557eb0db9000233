"""What an accepted route match does to the filter: the E/N pseudo-position update with the
covariance it is applied with, and (``extensions.heading_observation``) a yaw observation from
the fitted rotation. The compiled updates are in :mod:`estimator.filter.updates`."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from estimator.filter.engine import Filter
from estimator.filter.layout import E_ATT, E_VEL, X_QUAT, X_VEL
from estimator.filter.quaternion import qmul, set_quat
from estimator.filter.updates import heading_update, pseudo_position_update
from estimator.params import Params
from estimator.results import HeadingObservation, MatchRecord

F64 = NDArray[np.float64]

UNOBSERVED_VAR = 1e8
"""m^2: the along-track variance a match that does not observe along-track is applied with."""


def apply_route_match(
    filt: Filter, rec: MatchRecord, p: Params, *, route_share: float = 1.0
) -> tuple[F64, F64, MatchRecord]:
    """Update ``filt`` with the accepted match ``rec``; returns the innovation and the
    correction of the position update (E, N) and the record with the heading observation
    it was applied with. ``route_share``: the part of the gain on the cross-track innovation
    the route-error states (lane offset, map bias and rotation) take
    (``extensions.route_errors_overlap_share``)."""
    res = pseudo_position_update(
        filt.x,
        filt.P,
        filt.aux,
        filt.inp.cfg,
        np.asarray(rec.pseudo_position, float),
        applied_obs_cov(rec, p),
        rec.normal * float(p.extensions.lane_offset_state),
        route_share,
        np.asarray(rec.normal, float),
    )
    innovation, correction = res[:2].copy(), res[2:].copy()
    heading = heading_observation(rec, p)
    if heading is not None:
        applied = heading_update(
            filt.x, filt.P, filt.aux, filt.inp.cfg, heading[0], heading[1] ** 2
        )
        observed = HeadingObservation(heading[0], heading[1], applied)
        rec = dataclasses.replace(rec, heading_observation=observed)
    return innovation, correction, rec


def applied_obs_cov(rec: MatchRecord, p: Params) -> F64:
    """The covariance an accepted match updates the filter with.

    Where route shape leaves along-track unobserved, the record says so with
    ``pseudo.along_sigma_max_m`` (100 m). Applied as it is, once a second, that would still be
    information: 350 such updates in a straight tunnel claim along-track to 100 / sqrt(350) = 5 m
    when nothing was observed, which without wheel speed (along-track drifting by hundreds of
    metres) makes the filter confident of a position it never measured and then reject the
    bends that do observe it. So the along-track axis is applied as unobserved (cross-track
    only). Only with ``extensions.geometry_covariance``; the paper's isotropic R is kept."""
    cov = np.asarray(rec.obs_cov, float)
    if not (p.extensions.geometry_covariance and not rec.along_observed):
        return cov
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    w[-1] = max(w[-1], UNOBSERVED_VAR)
    result: F64 = (v * w) @ v.T
    return result


def heading_observation(rec: MatchRecord, p: Params) -> tuple[float, float] | None:
    """(yaw innovation, 1-sigma) from an accepted match's fitted rotation, or None.

    The rotation that maps the DR window onto the route is the heading error the window was
    dead-reckoned with. Its sigma is that of a rigid fit of ``n_pairs`` points spread over the
    window's length with the registration residual as point noise (sqrt(12 / N) / L), floored
    at 0.1 deg; the window's own heading drift is part of the residual. A re-anchor after an
    IMU gap (``extensions.gap_reacquire``) always observes the heading: the gap's turn is what it
    corrects, turned exactly before the update (:func:`turn_about_up`), which then only narrows
    the heading's variance to the fit's."""
    after_gap = "gap_end_s" in rec.extra
    observed = p.extensions.heading_observation or after_gap
    if not (observed and rec.accepted and rec.n_pairs >= 3):
        return None
    # a re-anchor after an IMU gap has turned the heading by the rotation already
    dyaw = 0.0 if after_gap else float(rec.rotation_rad)
    length = (rec.n_pairs - 1) * p.window.spacing_m
    if not (math.isfinite(dyaw) and length > 0):
        return None
    noise = max(float(rec.residual_m), 0.5) if math.isfinite(rec.residual_m) else 0.5
    sigma = max(noise * math.sqrt(12.0 / rec.n_pairs) / length, math.radians(0.1))
    return dyaw, sigma


def turn_about_up(x: F64, P: F64, angle: float) -> None:
    """Turn the navigation state by ``angle`` (rad) about the local vertical: the attitude and
    the velocity exactly, and their errors' covariance by the same rotation (the attitude error
    is a rotation of the ENU frame, so it turns with it). A heading error of tens of degrees
    (a road's turn inside an IMU gap) corrected through the linear gain would turn the velocity
    by its tangent instead of the angle and stretch it (by 41 % at 45 deg); the body-velocity
    updates after it then split that mismatch between heading and velocity and walk the heading
    off by degrees a second."""
    c, s = math.cos(angle), math.sin(angle)
    h = 0.5 * angle
    q = x[X_QUAT : X_QUAT + 4]
    set_quat(x, *qmul(math.cos(h), 0.0, 0.0, math.sin(h), q[0], q[1], q[2], q[3]))
    ve, vn = float(x[X_VEL]), float(x[X_VEL + 1])
    x[X_VEL], x[X_VEL + 1] = c * ve - s * vn, s * ve + c * vn
    turn = np.eye(P.shape[0])
    for block in (E_ATT, E_VEL):
        turn[block : block + 2, block : block + 2] = [[c, -s], [s, c]]
    P[:] = turn @ P @ turn.T
