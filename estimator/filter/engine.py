"""The filter as a Python object: the kernel's state arrays, the output rows, and the stepping
of the compiled loop (:func:`estimator.filter.kernel.run_until`) to a stop time, growing the
output buffer and reporting progress on the way."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError
from estimator.filter.kernel import run_until, write_row
from estimator.filter.layout import (
    A_DIST,
    A_INFLATE,
    A_NEXT_OUT,
    A_REJECT_SINCE,
    A_TIME,
    A_TRUST_T,
    A_USED_DIST,
    C_OUT_DT,
    E_ATT,
    E_POS,
    I_IMU,
    I_OUT,
    NO,
    O_COV_EN,
    O_GNSS,
    O_POS,
    O_RPY,
    O_SIG_POS,
    O_SIG_YAW,
    O_T,
    O_VEL,
    STATUS_DIVERGED,
    STATUS_FULL,
    X_POS,
    X_QUAT,
    X_VEL,
)
from estimator.filter.propagation import flush_covariance
from estimator.filter.setup import FilterInputs, Realignment
from estimator.results import Epochs

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
ProgressFn = Callable[[float], None]
FilterState = tuple[F64, F64, F64, I64]
"""(x, P, aux, idx): everything the kernel carries between two calls"""
GnssArrays = tuple[F64, F64, F64]
"""(times, ENU positions, variances) of the fixes the kernel uses"""

CHUNK_S = 30.0
"""log seconds per kernel call when progress is reported"""


class Filter:
    """The state (``x``, ``P``, ``aux``, ``idx``) and output rows (``out``) of one run over
    ``inputs``. ``source`` and ``t_start`` name the log and its start in error messages."""

    def __init__(
        self,
        inputs: FilterInputs,
        *,
        source: str,
        t_start: float,
        progress: ProgressFn | None = None,
    ) -> None:
        self.inp = inputs
        self.source = source
        self.t_start = t_start
        self.progress = progress
        self.x, self.P, self.aux, self.idx = self.snapshot_of(
            (inputs.x0, inputs.P0, inputs.aux0, inputs.idx0)
        )
        self.out: F64 = np.zeros((0, NO))

    @staticmethod
    def snapshot_of(state: FilterState) -> FilterState:
        x, P, aux, idx = state
        return x.copy(), P.copy(), aux.copy(), idx.copy()

    def snapshot(self) -> FilterState:
        """A copy of the state (a checkpoint)."""
        return self.snapshot_of((self.x, self.P, self.aux, self.idx))

    def set_state(self, state: FilterState) -> None:
        self.x, self.P, self.aux, self.idx = self.snapshot_of(state)

    @property
    def n_out(self) -> int:
        """Output rows written so far."""
        return int(self.idx[I_OUT])

    @property
    def t_first(self) -> float:
        """Time of the first IMU sample the filter processes (the aligning one)."""
        return float(self.inp.imu_t[self.inp.idx0[I_IMU] - 1])

    def alloc(self, n_rows: int) -> None:
        self.out = np.zeros((n_rows, NO))

    def start(self, n_rows: int) -> None:
        """From the initial state: room for ``n_rows`` output rows, the first written and the
        next one due an output interval later."""
        self.set_state((self.inp.x0, self.inp.P0, self.inp.aux0, self.inp.idx0))
        self.alloc(n_rows)
        self.write_row()
        self.aux[A_NEXT_OUT] = self.aux[A_TIME] + self.inp.cfg[C_OUT_DT]

    def grow(self) -> None:
        self.out = np.vstack([self.out, np.zeros((len(self.out) // 2 + 16, NO))])

    def write_row(self) -> int:
        """Write the current state as an output row; returns its index."""
        if self.idx[I_OUT] >= len(self.out) - 1:
            self.grow()
        write_row(self.x, self.P, self.aux, self.idx, self.out)
        return int(self.idx[I_OUT]) - 1

    def advance(self, t_stop: float, gnss: GnssArrays | None = None) -> None:
        """Run the filter to ``t_stop``; ``gnss`` replaces the log's fixes (the portal re-run)."""
        inp = self.inp
        gnss_t, gnss_pos, gnss_var = (
            (inp.gnss_t, inp.gnss_pos, inp.gnss_var) if gnss is None else gnss
        )
        t_end = float(inp.imu_t[-1])
        t_first = self.t_first
        while True:
            t_now = self.aux[A_TIME]
            target = t_stop
            if self.progress is not None:
                # from the next IMU sample: a gap longer than a chunk must not stall the loop
                k = int(self.idx[I_IMU])
                t_next = float(inp.imu_t[k]) if k < len(inp.imu_t) else t_now
                target = min(t_stop, max(t_now, t_next) + CHUNK_S)
            realign = next((r for r in inp.realignments if t_now < r.t <= target), None)
            if realign is not None:
                target = realign.t
            status = run_until(
                target,
                self.x,
                self.P,
                self.aux,
                self.idx,
                inp.imu_t,
                inp.gyro,
                inp.accel,
                inp.still,
                inp.wheel_t,
                inp.wheel_v,
                gnss_t,
                gnss_pos,
                gnss_var,
                inp.cfg,
                self.out,
            )
            if status == STATUS_FULL:
                self.grow()
                continue
            if status == STATUS_DIVERGED:
                raise LogError(
                    self.source,
                    "the filter diverged (non-finite state) at "
                    f"t = {self.aux[A_TIME] - self.t_start:.2f} s",
                )
            if realign is not None and self.aux[A_TIME] >= realign.t:
                self._realign(realign)
            if self.progress is not None:
                span = max(t_end - t_first, 1e-9)
                self.progress(min(1.0, (self.aux[A_TIME] - t_first) / span))
            if target >= t_stop or self.idx[I_IMU] >= len(inp.imu_t):
                return

    def _realign(self, r: Realignment) -> None:
        """Replace the navigation state carried across an IMU gap by the fresh alignment after
        it: attitude, velocity and position with their covariance, uncorrelated with the rest
        (the biases and the GNSS wander go on); fixes right after it are trusted."""
        flush_covariance(self.P, self.aux, self.inp.cfg)
        nav = slice(E_ATT, E_POS + 3)
        self.x[X_POS : X_POS + 3] = r.x[X_POS : X_POS + 3]
        self.x[X_VEL : X_VEL + 3] = r.x[X_VEL : X_VEL + 3]
        self.x[X_QUAT : X_QUAT + 4] = r.x[X_QUAT : X_QUAT + 4]
        self.P[nav, :] = 0.0
        self.P[:, nav] = 0.0
        self.P[nav, nav] = r.P[nav, nav]
        self.aux[A_REJECT_SINCE] = -1.0
        self.aux[A_INFLATE] = 0.0
        self.aux[A_TRUST_T] = r.t
        self.aux[A_USED_DIST] = self.aux[A_DIST]


def row_position_cov(rows: F64) -> F64:
    """The E/N position covariance output rows hold (their sigmas and the E-N term): (2, 2)
    for one row, (N, 2, 2) for rows. The ellipse's tilt is in the E-N term; the sigmas
    alone would test an error along a diagonal road against the wrong axes."""
    var_e, var_n, cov_en = (
        rows[..., O_SIG_POS] ** 2,
        rows[..., O_SIG_POS + 1] ** 2,
        rows[..., O_COV_EN],
    )
    cov: F64 = np.stack([np.stack([var_e, cov_en], -1), np.stack([cov_en, var_n], -1)], -2)
    return cov


def epochs_of(out: F64, n: int, degraded: tuple[tuple[float, float], ...]) -> Epochs:
    """The public per-epoch results of the first ``n`` output rows."""
    o = out[:n]
    t = o[:, O_T].copy()
    starts = np.array([a for a, _ in degraded])
    ends = np.array([b for _, b in degraded])
    if len(starts):
        j = np.searchsorted(starts, t, side="right") - 1
        inside = (j >= 0) & (t <= ends[np.clip(j, 0, None)])
    else:
        inside = np.zeros(n, bool)
    return Epochs(
        t=t,
        position=np.ascontiguousarray(o[:, O_POS : O_POS + 3]),
        velocity=np.ascontiguousarray(o[:, O_VEL : O_VEL + 3]),
        attitude=np.ascontiguousarray(o[:, O_RPY : O_RPY + 3]),
        position_sigma=np.ascontiguousarray(o[:, O_SIG_POS : O_SIG_POS + 3]),
        position_cov_en=np.ascontiguousarray(o[:, O_COV_EN]),
        yaw_sigma=o[:, O_SIG_YAW].copy(),
        gnss_used=o[:, O_GNSS] > 0,
        degraded=inside,
    )
