"""Measurement updates of the error-state EKF (the update half), each written as its equations:
``S = H P H^T + R``, ``K = P H^T S^-1``, ``dx = K y``, ``P <- P - K H P``, then ``x <- x (+) dx``
(the error state is injected at once, so it is zero between updates).

The body-velocity (wheel speed + non-holonomic), ZUPT, route pseudo-position and heading
updates live here; the GNSS update with its robustness tests in :mod:`estimator.filter.gnss`."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from estimator.filter.compiled import kernel
from estimator.filter.layout import (
    A_GYRO_N,
    A_GYRO_SUM,
    A_INFLATE,
    A_MAP_AT,
    A_ROT,
    A_ROT_EST,
    A_ROT_SHIFT,
    A_ROUTE,
    A_ROUTE_EST,
    C_AID_DT,
    C_ARW2,
    C_GSF_BLIND,
    C_GSF_EST,
    C_NHC_TILT2,
    C_NHC_VAR,
    C_SCALE_ON,
    C_WHEEL_VAR,
    C_WIE,
    C_ZUPT_VAR,
    E_ATT,
    E_BA,
    E_BG,
    E_GSF,
    E_GW,
    E_LANE,
    E_MAP,
    E_POS,
    E_ROT,
    E_SCALE,
    E_VEL,
    NE,
    X_BA,
    X_BG,
    X_GSF,
    X_GW,
    X_POS,
    X_QUAT,
    X_SCALE,
    X_VEL,
)
from estimator.filter.propagation import flush_covariance
from estimator.filter.quaternion import dcm_to_euler, qmul, quat_to_dcm, rotvec_quat, set_quat

F64 = NDArray[np.float64]

WHEEL_GATE = 25.0
"""Chi-square (1 dof) gate of the wheel-speed row: a slipping or locked wheel disagrees with the
mechanised forward velocity by metres per second, and the position-velocity correlation of a
long outage would turn that into tens of metres of position error per update; the wheel row is
then dropped and the non-holonomic rows still apply."""


@kernel
def _inv_small(S: F64, m: int, Si: F64) -> None:
    """``Si`` <- the inverse of the leading m x m block of ``S`` (m <= 3), in closed form."""
    if m == 1:
        Si[0, 0] = 1.0 / S[0, 0]
        return
    if m == 2:
        d = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        Si[0, 0] = S[1, 1] / d
        Si[1, 1] = S[0, 0] / d
        Si[0, 1] = -S[0, 1] / d
        Si[1, 0] = -S[1, 0] / d
        return
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 0], S[1, 1], S[1, 2]
    g, h, k = S[2, 0], S[2, 1], S[2, 2]
    A = e * k - f * h
    B = -(d * k - f * g)
    Cc = d * h - e * g
    det = a * A + b * B + c * Cc
    Si[0, 0] = A / det
    Si[1, 0] = B / det
    Si[2, 0] = Cc / det
    Si[0, 1] = -(b * k - c * h) / det
    Si[1, 1] = (a * k - c * g) / det
    Si[2, 1] = -(a * h - b * g) / det
    Si[0, 2] = (b * f - c * e) / det
    Si[1, 2] = -(a * f - c * d) / det
    Si[2, 2] = (a * e - b * d) / det


@kernel
def innovation_cov(P: F64, H: F64, R: F64, m: int, PHt: F64, S: F64, Si: F64) -> None:
    """``PHt`` <- P H^T, ``S`` <- H P H^T + R, ``Si`` <- S^-1 for the first ``m`` rows of H
    (skipping H's zeros: an update touches a few states)."""
    for i in range(NE):
        for a in range(m):
            acc = 0.0
            for j in range(NE):
                h = H[a, j]
                if h != 0.0:
                    acc += P[i, j] * h
            PHt[i, a] = acc  # P H^T
    for a in range(m):
        for b in range(m):
            acc = R[a, b]
            for j in range(NE):
                h = H[a, j]
                if h != 0.0:
                    acc += h * PHt[j, b]
            S[a, b] = acc  # S = H P H^T + R
    _inv_small(S, m, Si)


@kernel
def nis(y: F64, Si: F64, m: int) -> float:
    """The normalised innovation squared y^T S^-1 y."""
    acc = 0.0
    for a in range(m):
        for b in range(m):
            acc += y[a] * Si[a, b] * y[b]
    return acc


@kernel
def apply_update(x: F64, P: F64, y: F64, m: int, PHt: F64, Si: F64, cfg: F64) -> None:
    """x <- x (+) K y, P <- P - K H P, with K = P H^T S^-1 (the error state is injected into
    the nominal state at once, so it is zero between updates)."""
    K = np.empty((NE, 3))
    dx = np.empty(NE)
    _apply_gain(x, P, y, m, PHt, Si, cfg, K, dx, NE, False, 1.0, 0.0, 0.0)


@kernel
def _considered(i: int, last_considered: int, rot_est: bool, gsf_est: bool) -> bool:
    if i == E_ROT:
        return not rot_est
    if i == E_GSF:
        return not gsf_est
    return E_LANE <= i < last_considered


@kernel
def _zero_considered_gain(
    K: F64, m: int, last_considered: int, rot_est: bool, gsf_est: bool
) -> None:
    """A considered (Schmidt) state gets no gain."""
    for i in range(NE):
        if _considered(i, last_considered, rot_est, gsf_est):
            for a in range(m):
                K[i, a] = 0.0


@kernel
def _inject_gain(x: F64, y: F64, m: int, cfg: F64, K: F64, dx: F64) -> None:
    """dx = K y (the wheel scale's share dropped unless it is a state), x <- x (+) dx."""
    for i in range(NE):
        acc = 0.0
        for a in range(m):
            acc += K[i, a] * y[a]
        dx[i] = acc  # dx = K y
    if not cfg[C_SCALE_ON] > 0:
        dx[E_SCALE] = 0.0
    inject(x, dx)  # x <- x (+) dx


@kernel
def _share_route_gain(K: F64, m: int, share: float, c0: float, c1: float) -> None:
    """A partial update of the route-error states (lane offset, map bias, map rotation): the
    part of their gain that acts on the innovation's component along the unit vector
    (``c0``, ``c1``), the route's normal, times ``share``
    (``extensions.route_errors_overlap_share``); the covariance is then updated in Joseph
    form, so that it stays the covariance of the error this gain makes."""
    if m != 2:
        return
    for i in (E_LANE, E_MAP, E_MAP + 1, E_ROT):
        c = (1.0 - share) * (K[i, 0] * c0 + K[i, 1] * c1)
        K[i, 0] -= c * c0
        K[i, 1] -= c * c1


@kernel
def _joseph(x: F64, P: F64, y: F64, m: int, PHt: F64, Si: F64, cfg: F64, K: F64, dx: F64) -> None:
    """P <- (I - K H) P (I - K H)^T + K R K^T for any gain K, then x <- x (+) K y."""
    S = np.empty((3, 3))
    _inv_small(Si, m, S)
    KS = np.empty((NE, 3))
    for i in range(NE):
        for a in range(m):
            acc = 0.0
            for b in range(m):
                acc += K[i, b] * S[b, a]
            KS[i, a] = acc
    for i in range(NE):
        for j in range(i, NE):
            acc = 0.0
            for a in range(m):
                acc += K[i, a] * PHt[j, a] + PHt[i, a] * K[j, a] - KS[i, a] * K[j, a]
            v = P[i, j] - acc
            P[i, j] = v
            P[j, i] = v
    _inject_gain(x, y, m, cfg, K, dx)


@kernel
def _apply_gain(
    x: F64,
    P: F64,
    y: F64,
    m: int,
    PHt: F64,
    Si: F64,
    cfg: F64,
    K: F64,
    dx: F64,
    last_considered: int,
    rot_est: bool,
    share: float,
    c0: float,
    c1: float,
) -> None:
    # the states from E_LANE up to last_considered (the lane-offset and map-bias errors, but
    # for the map bias where a route pseudo-position estimates it) are considered, not
    # estimated (Schmidt): their gain is zero, and the symmetric update below then leaves
    # their covariance as it was; the map's rotation error E_ROT is considered unless
    # rot_est (a route pseudo-position with extensions.map_turn_estimate); the z gyro's
    # scale-factor error E_GSF is unless C_GSF_EST (extensions.gyro_scale_state)
    gsf_est = cfg[C_GSF_EST] > 0
    if cfg[C_GSF_BLIND] > 0 and not gsf_est and P[E_GSF, E_GSF] > 0.0:
        _apply_blind_gain(x, P, y, m, PHt, Si, cfg, K, dx, last_considered, rot_est, share, c0, c1)
        return
    for i in range(NE):
        for a in range(m):
            acc = 0.0
            for b in range(m):
                acc += PHt[i, b] * Si[b, a]
            K[i, a] = acc  # K = P H^T S^-1
    _zero_considered_gain(K, m, last_considered, rot_est, gsf_est)
    if share != 1.0:
        _share_route_gain(K, m, share, c0, c1)
        _joseph(x, P, y, m, PHt, Si, cfg, K, dx)
        return
    for i in range(NE):
        considered = _considered(i, last_considered, rot_est, gsf_est)
        for j in range(i, NE):
            acc = 0.0
            for a in range(m):
                if considered:
                    acc += PHt[i, a] * K[j, a]  # P <- P - P H^T K^T for a considered row
                else:
                    acc += K[i, a] * PHt[j, a]
            v = P[i, j] - acc  # P <- P - K (P H^T)^T = P - K H P
            P[i, j] = v
            P[j, i] = v
    _inject_gain(x, y, m, cfg, K, dx)


@kernel
def _apply_blind_gain(
    x: F64,
    P: F64,
    y: F64,
    m: int,
    PHt: F64,
    Si: F64,
    cfg: F64,
    K: F64,
    dx: F64,
    last_considered: int,
    rot_est: bool,
    share: float,
    c0: float,
    c1: float,
) -> None:
    """:func:`_apply_gain` with the gain of the filter that does not know the considered z gyro
    scale factor (``extensions.gyro_scale_blind_gain``), and the covariance updated for that
    gain (Joseph form), so that it stays the covariance of the error this filter makes.

    With ``s`` the scale error (variance ``ss``) and ``c = P[:, E_GSF]``, the error is
    ``e0 + c s / ss`` with ``e0`` independent of ``s``; ``P0 = P - c c^T / ss`` is the
    covariance the filter without the scale carries (its rows and column of ``E_GSF`` zero),
    and the gain from it is that filter's gain, whatever the scale's share of ``P``: the
    estimate follows the filter that ignores the scale, while ``P`` (gates, sigmas) also
    covers the heading and position error the scale makes. Estimating the scale (or weighting
    updates by its variance) makes dead reckoning worse where its error cancels others
    (docs/integrity.md); this keeps that estimate and only tells how wrong it can be."""
    ss = P[E_GSF, E_GSF]
    h = np.empty(3)
    for a in range(m):
        h[a] = PHt[E_GSF, a]  # H c
    S = np.empty((3, 3))
    _inv_small(Si, m, S)
    S0 = np.empty((3, 3))
    for a in range(m):
        for b in range(m):
            S0[a, b] = S[a, b] - h[a] * h[b] / ss
    Si0 = np.empty((3, 3))
    _inv_small(S0, m, Si0)
    gsf_est = False
    for i in range(NE):
        ci = P[i, E_GSF] / ss
        for a in range(m):
            acc = 0.0
            for b in range(m):
                acc += (PHt[i, b] - ci * h[b]) * Si0[b, a]
            K[i, a] = acc  # K = P0 H^T (H P0 H^T + R)^-1
    _zero_considered_gain(K, m, last_considered, rot_est, gsf_est)
    if share != 1.0:
        _share_route_gain(K, m, share, c0, c1)
    _joseph(x, P, y, m, PHt, Si, cfg, K, dx)


@kernel
def inject(x: F64, dx: F64) -> None:
    """Add an error-state estimate to the nominal state."""
    for i in range(3):
        x[X_POS + i] += dx[E_POS + i]
        x[X_VEL + i] += dx[E_VEL + i]
        x[X_BG + i] += dx[E_BG + i]
        x[X_BA + i] += dx[E_BA + i]
    x[X_SCALE] += dx[E_SCALE]
    x[X_GSF] += dx[E_GSF]
    for i in range(3):
        x[X_GW + i] += dx[E_GW + i]
    d = rotvec_quat(dx[0], dx[1], dx[2])
    q = qmul(d[0], d[1], d[2], d[3], x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3])
    set_quat(x, q[0], q[1], q[2], q[3])


@kernel
def body_velocity_update(
    x: F64,
    P: F64,
    cfg: F64,
    w_speed: float,
    use_wheel: bool,
    C: F64,
    H: F64,
    y: F64,
    R: F64,
    PHt: F64,
    S: F64,
    Si: F64,
) -> None:
    """Wheel speed (forward = scale * wheel) and the non-holonomic constraint (no lateral or
    vertical body velocity) as one observation of the body-frame velocity C^T v; the wheel row
    is left out when :data:`WHEEL_GATE` rejects it."""
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    v0, v1, v2 = x[X_VEL], x[X_VEL + 1], x[X_VEL + 2]
    # vb = C^T v
    vb0 = C[0, 0] * v0 + C[1, 0] * v1 + C[2, 0] * v2
    vb1 = C[0, 1] * v0 + C[1, 1] * v1 + C[2, 1] * v2
    vb2 = C[0, 2] * v0 + C[1, 2] * v1 + C[2, 2] * v2
    if use_wheel:
        # the wheel row alone: h = (c_0 x v, c_0, -w at the scale), innovation variance h P h'
        h = np.zeros(NE)
        c0, c1, c2 = C[0, 0], C[1, 0], C[2, 0]
        h[0] = c1 * v2 - c2 * v1
        h[1] = c2 * v0 - c0 * v2
        h[2] = c0 * v1 - c1 * v0
        h[3], h[4], h[5] = c0, c1, c2
        h[E_SCALE] = -w_speed
        s00 = cfg[C_WHEEL_VAR]
        for i in range(NE):
            if h[i] != 0.0:
                for j in range(NE):
                    s00 += h[i] * P[i, j] * h[j]
        y0 = x[X_SCALE] * w_speed - vb0
        if y0 * y0 > WHEEL_GATE * s00:
            use_wheel = False
    off = 0 if use_wheel else 1
    m = 3 - off
    # R_nhc = sigma^2 + |v|^2 sigma_mount^2: a body axis turned by an unknown angle from the
    # vehicle's sees speed x angle where the constraint says zero (noise.nhc_mount_sigma_deg)
    nhc_var = cfg[C_NHC_VAR] + cfg[C_NHC_TILT2] * (v0 * v0 + v1 * v1 + v2 * v2)
    for a in range(3):
        for j in range(NE):
            H[a, j] = 0.0
        for b in range(3):
            R[a, b] = 0.0
    for a in range(m):
        r = a + off  # body axis
        # d(C^T v) / dphi = C^T [v x]: row r is (c_r x v) with c_r the r-th column of C
        c0, c1, c2 = C[0, r], C[1, r], C[2, r]
        H[a, 0] = c1 * v2 - c2 * v1
        H[a, 1] = c2 * v0 - c0 * v2
        H[a, 2] = c0 * v1 - c1 * v0
        H[a, 3] = c0
        H[a, 4] = c1
        H[a, 5] = c2
        R[a, a] = nhc_var
    if use_wheel:
        H[0, E_SCALE] = -w_speed
        R[0, 0] = cfg[C_WHEEL_VAR]
        y[0] = x[X_SCALE] * w_speed - vb0
        y[1] = -vb1
        y[2] = -vb2
    else:
        y[0] = -vb1
        y[1] = -vb2
    innovation_cov(P, H, R, m, PHt, S, Si)
    apply_update(x, P, y, m, PHt, Si, cfg)


@kernel
def zupt_update(
    x: F64, P: F64, aux: F64, cfg: F64, H: F64, y: F64, R: F64, PHt: F64, S: F64, Si: F64
) -> None:
    """Zero velocity, and zero angular rate (the mean gyro while still measures its bias plus
    the Earth rate)."""
    for a in range(3):
        for j in range(NE):
            H[a, j] = 0.0
        for b in range(3):
            R[a, b] = 0.0
        H[a, E_VEL + a] = 1.0  # z = v + dv
        R[a, a] = cfg[C_ZUPT_VAR]
        y[a] = -x[X_VEL + a]  # y = 0 - v
    innovation_cov(P, H, R, 3, PHt, S, Si)
    apply_update(x, P, y, 3, PHt, Si, cfg)
    n = aux[A_GYRO_N]
    if n >= 2:
        C = np.empty((3, 3))
        quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
        w = cfg[C_WIE : C_WIE + 3]
        var = cfg[C_ARW2] / max(cfg[C_AID_DT], 1e-3) + (1e-5) ** 2
        for a in range(3):
            for j in range(NE):
                H[a, j] = 0.0
            for b in range(3):
                R[a, b] = 0.0
            H[a, E_BG + a] = 1.0  # z = mean gyro = bg + dbg + C^T w_ie
            R[a, a] = var
            wb = C[0, a] * w[0] + C[1, a] * w[1] + C[2, a] * w[2]
            y[a] = aux[A_GYRO_SUM + a] / n - x[X_BG + a] - wb  # y = z - bg - C^T w_ie
        innovation_cov(P, H, R, 3, PHt, S, Si)
        apply_update(x, P, y, 3, PHt, Si, cfg)
    aux[A_GYRO_N] = 0.0
    for a in range(3):
        aux[A_GYRO_SUM + a] = 0.0


@kernel
def pseudo_position_update(
    x: F64,
    P: F64,
    aux: F64,
    cfg: F64,
    z: F64,
    R2: F64,
    normal: F64,
    share: float,
    cross: F64,
) -> F64:
    """The route pseudo-observation of E, N position with covariance ``R2``. Returns
    [innovation E, N, correction E, N]. Also asks the next GNSS fix to widen the position
    covariance (see :func:`estimator.filter.gnss.widen_position`).

    The truth is ``z + normal * (lane-offset error) - (map-bias error) + noise`` (``normal``:
    the route's left normal at the match; zero leaves the lane-offset error out; the map-bias
    error is zero unless :func:`clone_route_errors` gave it a covariance). ``share``: the
    route-error states' part of the gain on the innovation across ``cross`` (the route's unit
    normal; 1: all of it, see :func:`_share_route_gain`)."""
    flush_covariance(P, aux, cfg)
    H = np.zeros((3, NE))
    R = np.zeros((3, 3))
    y = np.zeros(3)
    PHt = np.empty((NE, 3))
    S = np.empty((3, 3))
    Si = np.empty((3, 3))
    for a in range(2):
        H[a, E_POS + a] = 1.0  # z = p + dp - normal * d_lane + d_map
        H[a, E_LANE] = -normal[a]
        H[a, E_MAP + a] = 1.0
        y[a] = z[a] - x[X_POS + a]  # y = z - p (the lane error has no nominal value)
        for b in range(2):
            R[a, b] = R2[a, b]
    p0, p1 = x[X_POS], x[X_POS + 1]
    innovation_cov(P, H, R, 2, PHt, S, Si)
    K = np.empty((NE, 3))
    dx = np.empty(NE)
    estimate = aux[A_ROUTE_EST] > 0
    rot_est = aux[A_ROT_EST] > 0
    last = E_LANE if estimate else NE
    _apply_gain(x, P, y, 2, PHt, Si, cfg, K, dx, last, rot_est, share, cross[0], cross[1])
    if estimate:
        for k in range(3):
            aux[A_ROUTE + k] += dx[E_LANE + k]
    if rot_est:
        # E_MAP is the map's error at A_MAP_AT: a rotation correction dr there moves the map
        # by dr J (q - a), i.e. turns it by dr about the origin and shifts it by -dr J a
        dr = dx[E_ROT]
        aux[A_ROT] += dr
        aux[A_ROT_SHIFT] += dr * aux[A_MAP_AT + 1]
        aux[A_ROT_SHIFT + 1] -= dr * aux[A_MAP_AT]
    aux[A_INFLATE] = 1.0
    return np.array([y[0], y[1], x[X_POS] - p0, x[X_POS + 1] - p1])


@kernel
def clone_lane_offset(P: F64, aux: F64, cfg: F64, normal: F64) -> None:
    """Start an outage's lane-offset error as a clone of the cross-track position error.

    The lane offset every pseudo-position of an outage keeps was learned from the estimate while
    GNSS was good, so it is wrong by the estimate's own cross-track error then (mostly the
    receiver's slow wander), and all the outage's matches share that error. Treated as
    independent noise it must either get a metre-level sigma, with which the estimate lags the
    route, or it makes the position covariance shrink far below the real error. Carried as a
    state correlated one-to-one with the position error at the outage start, consecutive
    matches hold the estimate to the route while the absolute cross-track variance stays what
    GNSS left. ``normal``: the route's left normal at the vehicle."""
    flush_covariance(P, aux, cfg)
    for j in range(NE):
        v = normal[0] * P[E_POS, j] + normal[1] * P[E_POS + 1, j]
        P[E_LANE, j] = v
        P[j, E_LANE] = v
    P[E_LANE, E_LANE] = normal[0] * P[E_LANE, E_POS] + normal[1] * P[E_LANE, E_POS + 1]


@kernel
def clone_route_errors(P: F64, aux: F64, cfg: F64, gain: F64, cov: F64, estimate: bool) -> None:
    """Start an outage's lane-offset and map-bias errors (``E_LANE``, ``E_MAP``) as ``gain``
    (3, 2) times the E/N position error plus an independent part of covariance ``cov`` (3, 3).

    The lane offset and the map's bias are learned from the GNSS-good estimate before the
    outage (:mod:`estimator.matching.map_bias`), so they are wrong by that estimate's own error
    (the receiver's slow wander) through the fit's gain, and every pseudo-position of the outage
    shares it: cloned from the position error, consecutive matches hold the estimate to the road
    while its absolute variance stays what GNSS left (:func:`clone_lane_offset` is the case of
    a lane offset alone). ``estimate``: the outage's pseudo-positions estimate these errors
    (where the road turns, the dead-reckoned shape tells a map shifted sideways from a lane
    kept), accumulated in ``aux[A_ROUTE:]``; else they are only considered."""
    flush_covariance(P, aux, cfg)
    for k in range(3):
        aux[A_ROUTE + k] = 0.0
    aux[A_ROUTE_EST] = 1.0 if estimate else 0.0
    rows = np.empty((3, NE))
    for k in range(3):
        for j in range(NE):
            rows[k, j] = gain[k, 0] * P[E_POS, j] + gain[k, 1] * P[E_POS + 1, j]
    for k in range(3):
        for j in range(NE):
            if j < E_LANE or j == E_GSF:
                P[E_LANE + k, j] = rows[k, j]
                P[j, E_LANE + k] = rows[k, j]
    for k in range(3):
        for m in range(k, 3):
            v = gain[m, 0] * rows[k, E_POS] + gain[m, 1] * rows[k, E_POS + 1] + cov[k, m]
            P[E_LANE + k, E_LANE + m] = v
            P[E_LANE + m, E_LANE + k] = v


@kernel
def grow_map_bias(P: F64, var: float) -> None:
    """The map's bias changes along the road: add ``var`` (m^2) to each axis of its error."""
    for i in range(2):
        P[E_MAP + i, E_MAP + i] += var


@kernel
def clone_map_turn(P: F64, aux: F64, x: F64, var: float, estimate: bool) -> None:
    """Start an outage's map-rotation error (``E_ROT``, rad) with variance ``var``,
    independent of every other state, and make the map-bias error ``E_MAP`` the one at the
    vehicle's position (:func:`turn_map_bias` carries it along). ``estimate``: the outage's
    pseudo-positions estimate it (``extensions.map_turn_estimate``), accumulated in
    ``aux[A_ROT]`` and ``aux[A_ROT_SHIFT:]`` (the map turned back by ``A_ROT`` about the
    origin and shifted back by ``A_ROT_SHIFT``, on top of ``A_ROUTE``'s shift)."""
    for j in range(NE):
        P[E_ROT, j] = 0.0
        P[j, E_ROT] = 0.0
    P[E_ROT, E_ROT] = var
    aux[A_ROT_EST] = 1.0 if estimate else 0.0
    aux[A_ROT] = 0.0
    aux[A_ROT_SHIFT] = 0.0
    aux[A_ROT_SHIFT + 1] = 0.0
    aux[A_MAP_AT] = x[X_POS]
    aux[A_MAP_AT + 1] = x[X_POS + 1]


@kernel
def turn_map_bias(P: F64, aux: F64, x: F64) -> None:
    """Make the map-bias error ``E_MAP`` the one at the vehicle's position: a map turned by
    ``E_ROT`` about any point is off by ``E_ROT J d`` more ``d`` further along (``J`` a
    quarter turn), so ``E_MAP <- E_MAP + J d E_ROT`` with ``d`` the move since the last call
    (``P <- T P T^T``). Unlike a random walk of the map-bias error, the growth is one
    quantity shared by all of the outage's matches: repeating them does not average it away,
    and a heading turned to the map's stays as uncertain as the map's rotation."""
    d0 = x[X_POS] - aux[A_MAP_AT]
    d1 = x[X_POS + 1] - aux[A_MAP_AT + 1]
    v0, v1 = -d1, d0  # J d
    for j in range(NE):
        P[E_MAP, j] += v0 * P[E_ROT, j]
        P[E_MAP + 1, j] += v1 * P[E_ROT, j]
    for j in range(NE):
        P[j, E_MAP] += v0 * P[j, E_ROT]
        P[j, E_MAP + 1] += v1 * P[j, E_ROT]
    aux[A_MAP_AT] = x[X_POS]
    aux[A_MAP_AT + 1] = x[X_POS + 1]


@kernel
def heading_update(x: F64, P: F64, aux: F64, cfg: F64, dyaw: float, var: float) -> float:
    """A yaw observation: the true yaw is the estimate plus ``dyaw`` (rad) with variance
    ``var``. Returns the yaw change applied."""
    flush_covariance(P, aux, cfg)
    H = np.zeros((3, NE))
    R = np.zeros((3, 3))
    y = np.zeros(3)
    PHt = np.empty((NE, 3))
    S = np.empty((3, 3))
    Si = np.empty((3, 3))
    H[0, E_ATT + 2] = 1.0  # z = yaw + d_yaw
    R[0, 0] = var
    y[0] = dyaw  # y = z - yaw
    C = np.empty((3, 3))
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    yaw0 = dcm_to_euler(C)[2]
    innovation_cov(P, H, R, 1, PHt, S, Si)
    apply_update(x, P, y, 1, PHt, Si, cfg)
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    d = dcm_to_euler(C)[2] - yaw0
    return math.atan2(math.sin(d), math.cos(d))
