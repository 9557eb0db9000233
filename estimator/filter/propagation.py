"""Covariance propagation of the error state (the predict half of the EKF):
``P <- Phi P Phi^T + Q`` with ``Phi = I + F T``, accumulated between updates so the 20x20
product runs at ``noise.propagation_interval_s``, not at the IMU rate."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from estimator.filter.compiled import kernel
from estimator.filter.layout import (
    A_COV_C,
    A_COV_F,
    A_COV_T,
    A_COV_W,
    A_POS_WALK,
    C_ARW2,
    C_QBA,
    C_QBG,
    C_QW_H,
    C_QW_V,
    C_TAU_A,
    C_TAU_G,
    C_TAU_W,
    C_VRW2,
    C_WIE,
    E_ATT,
    E_BA,
    E_BG,
    E_GSF,
    E_GW,
    E_LANE,
    E_POS,
    E_VEL,
    NE,
)

F64 = NDArray[np.float64]


@kernel
def _f_times(
    M: F64,
    Cb: F64,
    fn: F64,
    w: F64,
    cw0: float,
    cw1: float,
    cw2: float,
    inv_tau_g: float,
    inv_tau_a: float,
    inv_tau_w: float,
    out: F64,
) -> None:
    """out = F M for the error-state F, using its block sparsity (~50 products per column
    instead of 361). ``cw``: the mean of C_bn e_z w_z, the z gyro's scale-factor error's column."""
    for c in range(NE):
        a0, a1, a2 = M[0, c], M[1, c], M[2, c]
        s = M[E_GSF, c]
        v0, v1, v2 = M[3, c], M[4, c], M[5, c]
        g0, g1, g2 = M[9, c], M[10, c], M[11, c]
        b0, b1, b2 = M[12, c], M[13, c], M[14, c]
        # attitude: -w x phi - C dbg
        out[0, c] = (
            -(w[1] * a2 - w[2] * a1) - (Cb[0, 0] * g0 + Cb[0, 1] * g1 + Cb[0, 2] * g2) - cw0 * s
        )
        out[1, c] = (
            -(w[2] * a0 - w[0] * a2) - (Cb[1, 0] * g0 + Cb[1, 1] * g1 + Cb[1, 2] * g2) - cw1 * s
        )
        out[2, c] = (
            -(w[0] * a1 - w[1] * a0) - (Cb[2, 0] * g0 + Cb[2, 1] * g1 + Cb[2, 2] * g2) - cw2 * s
        )
        # velocity: -fn x phi - 2 w x dv - C dba
        out[3, c] = (
            -(fn[1] * a2 - fn[2] * a1)
            - 2 * (w[1] * v2 - w[2] * v1)
            - (Cb[0, 0] * b0 + Cb[0, 1] * b1 + Cb[0, 2] * b2)
        )
        out[4, c] = (
            -(fn[2] * a0 - fn[0] * a2)
            - 2 * (w[2] * v0 - w[0] * v2)
            - (Cb[1, 0] * b0 + Cb[1, 1] * b1 + Cb[1, 2] * b2)
        )
        out[5, c] = (
            -(fn[0] * a1 - fn[1] * a0)
            - 2 * (w[0] * v1 - w[1] * v0)
            - (Cb[2, 0] * b0 + Cb[2, 1] * b1 + Cb[2, 2] * b2)
        )
        out[6, c] = v0
        out[7, c] = v1
        out[8, c] = v2
        out[9, c] = -inv_tau_g * g0
        out[10, c] = -inv_tau_g * g1
        out[11, c] = -inv_tau_g * g2
        out[12, c] = -inv_tau_a * b0
        out[13, c] = -inv_tau_a * b1
        out[14, c] = -inv_tau_a * b2
        out[15, c] = 0.0
        out[16, c] = -inv_tau_w * M[16, c]
        out[17, c] = -inv_tau_w * M[17, c]
        out[18, c] = -inv_tau_w * M[18, c]
        for k in range(E_LANE, NE):
            out[k, c] = 0.0  # considered states are constant


@kernel
def flush_covariance(P: F64, aux: F64, cfg: F64) -> None:
    """P <- Phi P Phi^T + Q over the time accumulated since the last call, with
    Phi = I + F T and F built from the interval's mean attitude and specific force."""
    flush_into(P, aux, cfg, np.empty((NE, NE)), np.empty((NE, NE)), np.empty((3, 3)), np.empty(3))


@kernel
def flush_into(P: F64, aux: F64, cfg: F64, A: F64, B: F64, Cb: F64, fn: F64) -> None:
    """:func:`flush_covariance` with its work arrays given (the kernel loop allocates them once)."""
    T = aux[A_COV_T]
    if T <= 0.0:
        return
    for i in range(3):
        for j in range(3):
            Cb[i, j] = aux[A_COV_C + 3 * i + j] / T
    for i in range(3):
        fn[i] = aux[A_COV_F + i] / T
    w = cfg[C_WIE : C_WIE + 3]
    cw0, cw1, cw2 = aux[A_COV_W] / T, aux[A_COV_W + 1] / T, aux[A_COV_W + 2] / T
    itg = 1.0 / cfg[C_TAU_G]
    ita = 1.0 / cfg[C_TAU_A]
    itw = 1.0 / cfg[C_TAU_W]
    _f_times(P, Cb, fn, w, cw0, cw1, cw2, itg, ita, itw, A)  # A = F P
    _f_times(A.T, Cb, fn, w, cw0, cw1, cw2, itg, ita, itw, B)  # B = F P F^T
    TT = T * T
    for i in range(NE):
        for j in range(i, NE):
            v = P[i, j] + T * (A[i, j] + A[j, i]) + TT * 0.5 * (B[i, j] + B[j, i])
            P[i, j] = v
            P[j, i] = v
    for i in range(2):
        P[E_POS + i, E_POS + i] += aux[A_POS_WALK] * T
    for i in range(3):
        P[E_ATT + i, E_ATT + i] += cfg[C_ARW2] * T
        P[E_VEL + i, E_VEL + i] += cfg[C_VRW2] * T
        P[E_BG + i, E_BG + i] += cfg[C_QBG] * T
        P[E_BA + i, E_BA + i] += cfg[C_QBA] * T
        P[E_GW + i, E_GW + i] += (cfg[C_QW_H] if i < 2 else cfg[C_QW_V]) * T
    aux[A_COV_T] = 0.0
    for i in range(12):
        aux[A_COV_C + i] = 0.0
    for i in range(3):
        aux[A_COV_W + i] = 0.0


@kernel
def accumulate(aux: F64, C: F64, fn0: float, fn1: float, fn2: float, wz: float, dt: float) -> None:
    """Add one IMU interval (attitude ``C``, specific force ``fn`` in ENU, body z rate
    ``wz``) to the pending propagation: the next flush uses their means over the accumulated
    time."""
    aux[A_COV_T] += dt
    for i in range(3):
        aux[A_COV_W + i] += C[i, 2] * wz * dt
    for i in range(3):
        for j in range(3):
            aux[A_COV_C + 3 * i + j] += C[i, j] * dt
    aux[A_COV_F] += fn0 * dt
    aux[A_COV_F + 1] += fn1 * dt
    aux[A_COV_F + 2] += fn2 * dt
