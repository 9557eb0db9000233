"""A level turn for covariance tests of the gyro's scale factor."""

from __future__ import annotations

import math

import numpy as np

from estimator.filter import layout, propagation


def quiet_cfg() -> np.ndarray:
    """Run constants with no process noise worth the name (correlation times of 1e9 s)."""
    cfg = np.zeros(layout.NC)
    cfg[layout.C_TAU_G] = cfg[layout.C_TAU_A] = cfg[layout.C_TAU_W] = 1e9
    return cfg


def turned(
    P: np.ndarray,
    angle: float,
    *,
    cfg: np.ndarray | None = None,
    steps: int = 400,
    rate: float = 0.2,
) -> np.ndarray:
    """Propagate ``P`` through a level turn of ``angle`` rad at ``rate`` rad/s (``cfg``: the run
    constants, :func:`quiet_cfg` by default); returns the aux array it was propagated with."""
    cfg = quiet_cfg() if cfg is None else cfg
    aux = np.zeros(layout.NA)
    dt = angle / rate / steps
    yaw = 0.0
    for _ in range(steps):
        yaw += rate * dt
        c, s = math.cos(yaw), math.sin(yaw)
        C = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        propagation.accumulate(aux, C, 0.0, 0.0, 9.81, rate, dt)
        propagation.flush_covariance(P, aux, cfg)
    return aux
