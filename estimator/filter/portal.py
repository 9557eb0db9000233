"""The fixed-lag re-run at a tunnel portal (``extensions.portal_rerun``).

At a portal, fixes jump by metres while still claiming metre-level sigmas, and a filter that
accepted some of them enters the tunnel from a corrupted position it then carries through the
whole outage. So the state ``noise.gnss_rerun_lag_s`` before the gap is saved, the fixes since
then are tested against where the filter would have dead-reckoned without them
(:func:`disagreeing_fixes`), and if any disagrees the last seconds are processed again from the
saved state without those fixes. The state saved is at least the lag after the filter's last
alignment (``extensions.portal_rerun_after_alignment``): before that its velocity and heading
are still the alignment's guess, and dead reckoning from them disagrees with good fixes."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from estimator.filter.engine import Filter, FilterState, row_position_cov
from estimator.filter.kernel import run_until, write_row
from estimator.filter.layout import (
    A_NEXT_OUT,
    A_TIME,
    C_GNSS_GATE,
    C_LEVER,
    C_OUT_DT,
    C_QW_H,
    C_TAU_W,
    C_WHITE_VAR,
    E_ATT,
    E_GW,
    E_POS,
    E_SCALE,
    I_GNSS,
    I_OUT,
    NO,
    O_DIST,
    O_POS,
    O_RPY,
    O_T,
    STATUS_DONE,
    X_GW,
)
from estimator.filter.quaternion import euler_to_quat, quat_to_dcm
from estimator.filter.setup import FilterInputs
from estimator.params import Params

F64 = NDArray[np.float64]


def advance_to_outage(filt: Filter, t_a: float, p: Params) -> list[float]:
    """Run ``filt`` to the start of a degraded interval (``t_a``, the last fix before the gap),
    leaving out the portal fixes that disagree with dead reckoning; returns their times."""
    lag = p.noise.gnss_rerun_lag_s
    if not (p.extensions.portal_rerun and lag > 0):
        filt.advance(t_a)
        return []
    t_save = t_a - lag
    if p.extensions.portal_rerun_after_alignment:
        t_save = max(t_save, last_alignment(filt, t_a) + lag)
    if t_save >= t_a:
        filt.advance(t_a)
        return []
    filt.advance(t_save)
    saved = filt.snapshot()
    filt.advance(t_a)
    inp = filt.inp
    g0, g1 = int(saved[3][I_GNSS]), int(filt.idx[I_GNSS])
    if g1 <= g0:
        return []
    drop = disagreeing_fixes(saved, t_a, inp, range(g0, g1))
    if not drop:
        return []
    keep = np.ones(len(inp.gnss_t), bool)
    keep[drop] = False
    filt.set_state(saved)
    filt.advance(t_a, (inp.gnss_t[keep], inp.gnss_pos[keep], inp.gnss_var[keep]))
    # every fix up to t_a is behind the filter, in the log's own indexing as well
    filt.idx[I_GNSS] = g1
    return [float(inp.gnss_t[g]) for g in drop]


def last_alignment(filt: Filter, t: float) -> float:
    """The time of the filter's last alignment up to ``t``: its start, or a fresh alignment
    after an IMU gap."""
    return max([filt.t_first, *(r.t for r in filt.inp.realignments if r.t <= t)])


def _dead_reckoned_rows(saved: FilterState, t_stop: float, inp: FilterInputs) -> F64 | None:
    """Output rows of the filter run from ``saved`` to ``t_stop`` without any fix (None if the
    kernel did not finish)."""
    x, P, aux, idx = Filter.snapshot_of(saved)
    cfg = inp.cfg
    t_save = float(aux[A_TIME])
    n_rows = int((t_stop - t_save) / cfg[C_OUT_DT]) + 64
    rows = np.zeros((n_rows, NO))
    idx[I_OUT] = 0
    write_row(x, P, aux, idx, rows)
    aux[A_NEXT_OUT] = t_save + cfg[C_OUT_DT]
    no_t, no_xyz = np.empty(0), np.empty((0, 3))
    status = run_until(
        t_stop, x, P, aux, idx, inp.imu_t, inp.gyro, inp.accel, inp.still, inp.wheel_t,
        inp.wheel_v, no_t, no_xyz, no_xyz, cfg, rows,
    )  # fmt: skip
    if status != STATUS_DONE:
        return None
    write_row(x, P, aux, idx, rows)
    return rows[: int(idx[I_OUT])]


def disagreeing_fixes(
    saved: FilterState, t_stop: float, inp: FilterInputs, fixes: range
) -> list[int]:
    """The fixes (indices into ``inp.gnss_*``) that disagree with the filter dead-reckoned
    from the ``saved`` state (x, P, aux, idx) to ``t_stop`` without GNSS.

    Each fix's offset from the dead-reckoned antenna position (plus the GNSS wander state) is
    tested twice, with the chi-square (2 dof) gate ``noise.gnss_chi2_gate``. Against the
    filter: the saved E/N covariance of position + wander, the growth of the position covariance
    while dead-reckoning (its E-N term too: along a diagonal road the growth is an ellipse
    along the road), and the log's *typical* white fix variance (not the one the fix
    reports: portal fixes claim metre-level sigmas for jumps of 5-15 m). Against the other
    fixes: over a few seconds dead reckoning drifts by centimetres, so good fixes share one
    offset (the filter's error) up to their white noise and the wander's change, and a jump
    the wheels did not drive stands out from the largest set of fixes that agree with each
    other, if that set holds more than half of them. The second test still works when the
    saved state is loose (a portal shortly after another outage)."""
    r = _dead_reckoned_rows(saved, t_stop, inp)
    if r is None or len(fixes) == 0:
        return []
    cfg = inp.cfg
    t_save = float(saved[2][A_TIME])
    t_r = r[:, O_T]
    g = np.asarray(fixes)
    tf = inp.gnss_t[g]
    pos = np.column_stack([np.interp(tf, t_r, r[:, O_POS + i]) for i in range(2)])
    rpy = np.column_stack([np.interp(tf, t_r, np.unwrap(r[:, O_RPY + i])) for i in range(3)])
    lever = cfg[C_LEVER : C_LEVER + 3]
    C = np.empty((3, 3))
    lever_en = np.empty((len(g), 2))
    for k in range(len(g)):
        quat_to_dcm(euler_to_quat(rpy[k, 0], rpy[k, 1], rpy[k, 2]), C)
        lever_en[k] = (C @ lever)[:2]
    gw0 = saved[0][X_GW : X_GW + 2]
    gw = gw0[None, :] * np.exp(-(tf - t_save) / cfg[C_TAU_W])[:, None]
    d = inp.gnss_pos[g, :2] - (pos + lever_en + gw)
    cov_r = row_position_cov(r).reshape(-1, 4)
    cov_f = np.column_stack([np.interp(tf, t_r, cov_r[:, i]) for i in range(4)])
    w, v = np.linalg.eigh((cov_f - cov_r[0]).reshape(-1, 2, 2))
    growth = v @ (np.maximum(w, 0.0)[..., None] * np.swapaxes(v, -1, -2))  # grown, never shrunk
    white = cfg[C_WHITE_VAR]
    gate = cfg[C_GNSS_GATE]
    pe, pw = slice(E_POS, E_POS + 2), slice(E_GW, E_GW + 2)
    P0 = saved[1]
    S0 = P0[pe, pe] + P0[pw, pw] + P0[pe, pw] + P0[pw, pe]
    bad = np.zeros(len(g), bool)
    for k in range(len(g)):
        S = S0 + growth[k] + white * np.eye(2)
        bad[k] = float(d[k] @ np.linalg.solve(S, d[k])) > gate
    # the fixes among themselves: two white noises, the wander's change over the lag, and
    # what a heading or odometer-scale error turns the distance driven into
    driven = float(r[-1, O_DIST] - r[0, O_DIST])
    drift2 = (P0[E_ATT + 2, E_ATT + 2] + P0[E_SCALE, E_SCALE]) * driven**2
    var_pair = 2.0 * white + cfg[C_QW_H] * (t_stop - t_save) + drift2
    d2 = np.sum((d[:, None, :] - d[None, :, :]) ** 2, axis=2) / var_pair
    support = d2 <= gate
    best = int(np.argmax(support.sum(axis=1)))
    agree = support[best]
    if 2 * int(agree.sum()) > len(g):
        centre = d[agree].mean(axis=0)
        bad |= np.sum((d - centre) ** 2, axis=1) / var_pair > gate
    return [int(i) for i in g[bad]]
