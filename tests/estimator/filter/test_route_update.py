"""What an accepted route match does to the filter (the covariance it is applied with)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimator.filter import UNOBSERVED_VAR, applied_obs_cov
from estimator.params import Params, with_values


def test_a_match_that_does_not_observe_along_track_updates_cross_track_only():
    tangent = np.array([np.cos(0.3), np.sin(0.3)])
    normal = np.array([-tangent[1], tangent[0]])
    basis = np.column_stack([tangent, normal])
    cov = basis @ np.diag([100.0**2, 1.0]) @ basis.T
    rec = dataclasses.make_dataclass("Rec", ["obs_cov", "along_observed"])(cov, False)
    applied = applied_obs_cov(rec, Params())
    assert tangent @ applied @ tangent == pytest.approx(UNOBSERVED_VAR)
    assert normal @ applied @ normal == pytest.approx(1.0)
    assert tangent @ applied @ normal == pytest.approx(0.0, abs=1e-6)
    observed = dataclasses.replace(rec, along_observed=True)
    assert np.array_equal(applied_obs_cov(observed, Params()), cov)
    paper = with_values(Params(), {"extensions.geometry_covariance": False})
    assert np.array_equal(applied_obs_cov(rec, paper), cov)
