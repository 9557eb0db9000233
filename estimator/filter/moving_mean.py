"""The centred moving mean of the stationarity test, compiled.

It adds the same numbers in the same order as ``scipy.ndimage.uniform_filter1d(x, size,
mode="nearest")`` (a running sum over the edge-extended line, divided by ``size`` at each
sample), so the results are the same to the bit (checked against scipy in the tests), without
importing ``scipy.ndimage``, which alone took a quarter of a second of every ``routefuse run``."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def _moving_mean_line(x: F64, size: int, out: F64) -> None:
    n = len(x)
    left = size // 2
    total = 0.0
    for k in range(size):
        total += x[min(max(k - left, 0), n - 1)]
    out[0] = total / size
    for i in range(1, n):
        entering = x[min(max(i + size - 1 - left, 0), n - 1)]
        leaving = x[min(max(i - 1 - left, 0), n - 1)]
        total += entering - leaving
        out[i] = total / size


_compiled_line: Any = numba.njit(cache=True)(_moving_mean_line)


def moving_mean(values: F64, size: int) -> F64:
    """Mean over ``size`` samples centred on each sample (the window's extra sample, for an even
    ``size``, is on the left), along the first axis; the ends repeat the first and last sample."""
    x = np.asarray(values, np.float64)
    out = np.empty_like(x)
    if len(x) == 0:
        return out
    if x.ndim == 1:
        _compiled_line(np.ascontiguousarray(x), int(size), out)
        return out
    for c in range(x.shape[1]):
        column = np.empty(len(x))
        _compiled_line(np.ascontiguousarray(x[:, c]), int(size), column)
        out[:, c] = column
    return out
