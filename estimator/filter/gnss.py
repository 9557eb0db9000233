"""The GNSS fix update: lever arm, the fix moved to the state time, robustness against portal
jumps (fixes chained by dead-reckoned motion, probation after an outage), chi-square gates, and
the widening of the position covariance after route pseudo-observations."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from estimator.filter.compiled import kernel
from estimator.filter.layout import (
    A_CHAIN_DR,
    A_CHAIN_POS,
    A_CHAIN_T,
    A_CHAIN_T0,
    A_DIST,
    A_DR,
    A_INFLATE,
    A_REJECT_SINCE,
    A_TRUST_T,
    A_USED_DIST,
    C_CROSS_WIDEN,
    C_GNSS_GATE,
    C_LEVER,
    C_RESET_S,
    C_ROBUST,
    C_WHITE_VAR,
    E_ATT,
    E_GW,
    E_POS,
    E_VEL,
    NE,
    X_GW,
    X_POS,
    X_QUAT,
    X_VEL,
)
from estimator.filter.quaternion import quat_to_dcm
from estimator.filter.updates import apply_update, innovation_cov, nis

F64 = NDArray[np.float64]

PROBATION_GAP_S = 2.0
"""After this long without a trusted fix, new fixes are on probation (see robust_check)."""
AGREE_S = 3.0
"""Fixes on probation are used once they have agreed with each other for this long."""
CHAIN_GAP_S = 1.0
CHAIN_GATE = 9.0
"""Chi-square (2 dof) of the motion between consecutive fixes against the DR motion."""


@kernel
def widen_position(P: F64, y: F64, S: F64) -> None:
    """Add diag(max(0, y_i^2 - S_ii)) to the E/N position variance: the fix then agrees with
    the filter to about one sigma and is accepted, and P stays positive definite."""
    for a in range(2):
        d = y[a] * y[a] - S[a, a]
        if d > 0.0:
            P[E_POS + a, E_POS + a] += d


@kernel
def widen_heading(x: F64, P: F64, y: F64, aux: F64, cross_only: bool) -> None:
    """Widen yaw and horizontal velocity variance by the heading error that explains the fix's
    horizontal innovation over the distance driven since the last fix used (a heading error
    grown linearly over D puts the vehicle about theta * D / 2 off). Widening only the position
    would leave a filter that claims a tenth of a degree of yaw with a heading ten degrees off:
    each later fix then pulls the position back and the heading drags it away again.

    ``cross_only`` (``extensions.cross_track_heading_widen``): a heading error moves the
    vehicle across its travel, so only the innovation's part across the velocity is taken as
    one; the part along it is a speed error (without wheel speed, tens of metres after an
    outage), which taken as heading error corrupts the velocity the next fixes correct."""
    dist = aux[A_DIST] - aux[A_USED_DIST]
    if dist < 1.0:
        return
    off = math.hypot(y[0], y[1])
    speed = math.hypot(x[X_VEL], x[X_VEL + 1])
    if cross_only and speed > 1.0:
        off = abs(y[0] * x[X_VEL + 1] - y[1] * x[X_VEL]) / speed
    theta = min(2.0 * off / dist, math.pi / 4)
    var_yaw = theta * theta
    if var_yaw <= P[E_ATT + 2, E_ATT + 2]:
        return
    P[E_ATT + 2, E_ATT + 2] += var_yaw
    speed2 = x[X_VEL] * x[X_VEL] + x[X_VEL + 1] * x[X_VEL + 1]
    for a in range(2):
        P[E_VEL + a, E_VEL + a] += speed2 * var_yaw


@kernel
def robust_check(
    aux: F64,
    cfg: F64,
    t_fix: float,
    e: float,
    n: float,
    dr_e: float,
    dr_n: float,
    nis_typical: float,
) -> int:
    """Robust GNSS: is a fix trusted? Returns 0 (use it as it is), 1 (it disagrees with the
    filter: inflate its covariance by its innovation) or -1 (on probation: do not use it).

    ``nis_typical`` is the horizontal innovation tested against the filter's covariance plus
    the *typical* white variance of the log's fixes, not the variance the fix reports: at tunnel
    portals receivers report metre-level sigmas for jumps of 5-15 m. Fixes are also chained by
    the distance dead reckoning drove between consecutive fixes (good to centimetres over a
    fraction of a second, and blind to the heading error DR may have gathered in a long outage,
    which would otherwise make every returning fix 'disagree'): after a gap of more than
    PROBATION_GAP_S (an outage) fixes are not used until they have agreed with each other for
    AGREE_S, and a chain that agrees that long is trusted even if it disagrees with the filter
    (then the filter was wrong)."""
    ct = aux[A_CHAIN_T]
    chain_ok = False
    if ct > 0 and t_fix - ct <= CHAIN_GAP_S:
        step_fix = math.hypot(e - aux[A_CHAIN_POS], n - aux[A_CHAIN_POS + 1])
        step_dr = math.hypot(dr_e - aux[A_CHAIN_DR], dr_n - aux[A_CHAIN_DR + 1])
        d = step_fix - step_dr
        chain_ok = d * d / (2.0 * cfg[C_WHITE_VAR]) <= CHAIN_GATE
    if not chain_ok:
        aux[A_CHAIN_T0] = t_fix
    aux[A_CHAIN_T] = t_fix
    aux[A_CHAIN_POS], aux[A_CHAIN_POS + 1] = e, n
    aux[A_CHAIN_DR], aux[A_CHAIN_DR + 1] = dr_e, dr_n
    chain_long = t_fix - aux[A_CHAIN_T0] >= AGREE_S
    probation = t_fix - aux[A_TRUST_T] > PROBATION_GAP_S
    if chain_long or (not probation and nis_typical <= cfg[C_GNSS_GATE]):
        aux[A_TRUST_T] = t_fix
        return 0
    return -1 if probation else 1


@kernel
def gnss_update(
    x: F64,
    P: F64,
    aux: F64,
    cfg: F64,
    t: float,
    t_fix: float,
    pos: F64,
    var: F64,
    C: F64,
    H: F64,
    y: F64,
    R: F64,
    PHt: F64,
    S: F64,
    Si: F64,
) -> int:
    """One fix: antenna lever arm, the fix moved to the state time with the velocity, the
    motion check (robust GNSS), separate chi-square gates on horizontal and vertical
    innovations. Returns 1 if the fix was used."""
    dtf = t - t_fix
    quat_to_dcm(x[X_QUAT : X_QUAT + 4], C)
    lv = cfg[C_LEVER : C_LEVER + 3]
    la = np.empty(3)
    for i in range(3):
        la[i] = C[i, 0] * lv[0] + C[i, 1] * lv[1] + C[i, 2] * lv[2]
    for a in range(3):
        for j in range(NE):
            H[a, j] = 0.0
        for b in range(3):
            R[a, b] = 0.0
        H[a, E_POS + a] = 1.0  # z = p + dp + C l + gw + dgw (at the fix time)
        H[a, E_GW + a] = 1.0
        R[a, a] = var[a]
        y[a] = pos[a] - (x[X_POS + a] - x[X_VEL + a] * dtf + la[a] + x[X_GW + a])  # y = z - h(x)
    # d(C l)/dphi = -[C l x]
    H[0, 1] = la[2]
    H[0, 2] = -la[1]
    H[1, 0] = -la[2]
    H[1, 2] = la[0]
    H[2, 0] = la[1]
    H[2, 1] = -la[0]
    if cfg[C_ROBUST] > 0:
        R[0, 0] = R[1, 1] = cfg[C_WHITE_VAR]
        innovation_cov(P, H, R, 2, PHt, S, Si)
        nis_typical = nis(y, Si, 2)
        R[0, 0], R[1, 1] = var[0], var[1]
        # the antenna on the DR track at the fix time
        dr_e = aux[A_DR] - x[X_VEL] * dtf + la[0]
        dr_n = aux[A_DR + 1] - x[X_VEL + 1] * dtf + la[1]
        verdict = robust_check(aux, cfg, t_fix, pos[0], pos[1], dr_e, dr_n, nis_typical)
        if verdict < 0:
            return 0
        if verdict > 0:
            R[0, 0] += y[0] * y[0]
            R[1, 1] += y[1] * y[1]
    innovation_cov(P, H, R, 3, PHt, S, Si)
    gate = cfg[C_GNSS_GATE]
    widen = aux[A_INFLATE] > 0
    if not widen and aux[A_REJECT_SINCE] >= 0 and t - aux[A_REJECT_SINCE] > cfg[C_RESET_S]:
        widen = True
    if widen:
        widen_heading(x, P, y, aux, cfg[C_CROSS_WIDEN] > 0)
        widen_position(P, y, S)
        innovation_cov(P, H, R, 3, PHt, S, Si)
        aux[A_INFLATE] = 0.0
    d = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    nis_h = (S[1, 1] * y[0] * y[0] - 2 * S[0, 1] * y[0] * y[1] + S[0, 0] * y[1] * y[1]) / d
    if nis_h > gate:
        if aux[A_REJECT_SINCE] < 0:
            aux[A_REJECT_SINCE] = t
        return 0
    aux[A_REJECT_SINCE] = -1.0
    m = 3
    if y[2] * y[2] / S[2, 2] > gate:
        m = 2
        innovation_cov(P, H, R, 2, PHt, S, Si)
    apply_update(x, P, y, m, PHt, Si, cfg)
    aux[A_USED_DIST] = aux[A_DIST]
    return 1
