"""The compiled moving mean of the stationarity test equals scipy's ``uniform_filter1d`` with
``mode="nearest"`` to the bit (scipy is the oracle here; production does not import it)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from estimator.filter.moving_mean import moving_mean


@pytest.mark.parametrize("seed", range(40))
def test_bit_identical_to_scipy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, size = int(rng.integers(1, 2000)), int(rng.integers(1, 300))
    x = rng.normal(size=(n, 3)) * rng.uniform(1e-3, 1e3) + (1e6 if seed % 3 == 0 else 0.0)
    np.testing.assert_array_equal(
        moving_mean(x, size), uniform_filter1d(x, size, axis=0, mode="nearest")
    )
    norm = np.linalg.norm(x, axis=1)
    np.testing.assert_array_equal(
        moving_mean(norm, size), uniform_filter1d(norm, size, mode="nearest")
    )


def test_non_finite_values_spread_as_in_scipy() -> None:
    x = np.arange(20.0)
    x[7], x[12] = np.nan, np.inf
    np.testing.assert_array_equal(moving_mean(x, 4), uniform_filter1d(x, 4, mode="nearest"))
    assert moving_mean(np.zeros((0, 3)), 5).shape == (0, 3)
