"""The dead-reckoning twin of an outage: the filter cloned at the outage start and run on without
any route update, for solution separation (``extensions.dr_separation``).

A route update only adds information to dead reckoning, so between the filter that took the
outage's pseudo-positions and its twin that took none, the separation ``x_f - x_d`` has the
covariance ``P_d - P_f`` when both covariances are honest: the solution-separation test of
receiver autonomous integrity monitoring, with the route in place of a satellite. A route that
pulls the estimate further from dead reckoning than that allows is a wrong map, or the filter
believes the route more than it should: either way the pulled estimate is not to be trusted,
and the twin's is the one that took nothing from it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimator.errors import LogError
from estimator.filter.engine import FilterState
from estimator.filter.kernel import run_until
from estimator.filter.layout import (
    E_GSF,
    E_POS,
    I_OUT,
    NO,
    STATUS_DIVERGED,
    STATUS_FULL,
    X_POS,
)
from estimator.filter.propagation import flush_covariance
from estimator.filter.setup import FilterInputs

F64 = NDArray[np.float64]

ROWS = 64
"""output rows the twin writes into before starting over (nobody reads them)"""


@dataclass(frozen=True)
class Separation:
    """The filter's horizontal position against its dead-reckoning twin's."""

    offset: F64
    """(2,) E, N: filter minus twin, m"""
    cov: F64
    """(2, 2) ``P_d - P_f``, its eigenvalues floored at the floor's square"""
    chi2: float
    """``offset^T cov^-1 offset``"""

    @property
    def metres(self) -> float:
        return float(math.hypot(*self.offset))


@dataclass(frozen=True)
class Undone:
    """The attempt at which an outage's route updates were undone."""

    t: float
    """its time (log clock), s"""
    separation: Separation


class DeadReckoningTwin:
    """The filter's state at an outage start (``state``), run on without route updates;
    ``undone`` once the outage's route updates were given up for it."""

    def __init__(
        self,
        state: FilterState,
        inputs: FilterInputs,
        *,
        fixes_until: float,
        gyro_scale_var: float = 0.0,
        rows: F64 | None = None,
    ) -> None:
        x, P, aux, idx = state
        self.x, self.P, self.aux, self.idx = x.copy(), P.copy(), aux.copy(), idx.copy()
        self.considers_scale = gyro_scale_var > self.P[E_GSF, E_GSF]
        """the twin considers the gyro's scale factor where the filter did not
        (``extensions.dr_separation_gyro_scale``): its covariance is not the filter's to take"""
        if self.considers_scale:
            self.P[E_GSF, E_GSF] = gyro_scale_var
        self.idx[I_OUT] = 0
        self.inp = inputs
        self.fixes_until = fixes_until
        """the outage's start: the fixes up to it are the filter's too (the last one, at the
        start itself, comes with the IMU sample after it)"""
        k = int(np.searchsorted(inputs.gnss_t, fixes_until, side="right"))
        self.fixes = (inputs.gnss_t[:k], inputs.gnss_pos[:k], inputs.gnss_var[:k])
        self.rows: F64 = np.zeros((ROWS, NO)) if rows is None else rows
        """scratch for the kernel's output rows, shared by copies"""
        self.undone: Undone | None = None

    def copy(self) -> DeadReckoningTwin:
        """A copy of the state (a checkpoint's)."""
        twin = DeadReckoningTwin(
            (self.x, self.P, self.aux, self.idx),
            self.inp,
            fixes_until=self.fixes_until,
            rows=self.rows,
        )
        twin.considers_scale = self.considers_scale
        twin.undone = self.undone
        return twin

    def advance(self, t_stop: float, source: str) -> None:
        """Dead-reckon to ``t_stop`` (no fix after the outage's start: the twin lives inside
        the outage) and propagate the covariance to it."""
        inp = self.inp
        gnss_t, gnss_pos, gnss_var = self.fixes
        while True:
            status = run_until(
                t_stop, self.x, self.P, self.aux, self.idx, inp.imu_t, inp.gyro, inp.accel,
                inp.still, inp.wheel_t, inp.wheel_v, gnss_t, gnss_pos, gnss_var, inp.cfg,
                self.rows,
            )  # fmt: skip
            if status == STATUS_FULL:
                self.idx[I_OUT] = 0
                continue
            if status == STATUS_DIVERGED:
                raise LogError(source, "the dead-reckoning twin diverged (non-finite state)")
            break
        flush_covariance(self.P, self.aux, inp.cfg)

    def separation(self, x: F64, P: F64, *, floor_m: float) -> Separation:
        """How far the filter (``x``, ``P``, at the twin's time) has moved from dead reckoning
        (:func:`separation`)."""
        return separation(x, P, self.x, self.P, floor_m=floor_m)


def separation(x: F64, P: F64, x_dr: F64, P_dr: F64, *, floor_m: float) -> Separation:
    """How far the filter (``x``, ``P``) has moved from dead reckoning (``x_dr``, ``P_dr``),
    against how far the information it gained allows: ``P_dr - P``, whose sigmas are floored at
    ``floor_m`` (where the route added next to nothing it is near zero)."""
    pos = slice(E_POS, E_POS + 2)
    offset: F64 = x[X_POS : X_POS + 2] - x_dr[X_POS : X_POS + 2]
    diff = P_dr[pos, pos] - P[pos, pos]
    w, v = np.linalg.eigh(0.5 * (diff + diff.T))
    w = np.maximum(w, floor_m * floor_m)
    cov: F64 = (v * w) @ v.T
    along_axes = v.T @ offset
    return Separation(offset, cov, float(np.sum(along_axes * along_axes / w)))
