"""The error-state EKF: state layout (:mod:`.layout`), mechanisation, covariance propagation,
measurement updates and the compiled loop (:mod:`.kernel`); the inputs it reads
(:mod:`.setup`, :mod:`.alignment`); the filter object that steps it (:mod:`.engine`); the portal
re-run (:mod:`.portal`) and the route update (:mod:`.route_update`).

Kernels compile on first use (cached on disk), so the face imports them lazily."""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimator._lazy import lazy_getattr

if TYPE_CHECKING:
    from estimator.filter.engine import Filter, FilterState, epochs_of
    from estimator.filter.portal import advance_to_outage, disagreeing_fixes
    from estimator.filter.route_update import (
        UNOBSERVED_VAR,
        applied_obs_cov,
        apply_route_match,
        heading_observation,
    )
    from estimator.filter.setup import FilterInputs, kernel_config, prepare_inputs

_HOMES = {
    "Filter": "estimator.filter.engine",
    "FilterState": "estimator.filter.engine",
    "epochs_of": "estimator.filter.engine",
    "advance_to_outage": "estimator.filter.portal",
    "disagreeing_fixes": "estimator.filter.portal",
    "UNOBSERVED_VAR": "estimator.filter.route_update",
    "applied_obs_cov": "estimator.filter.route_update",
    "apply_route_match": "estimator.filter.route_update",
    "heading_observation": "estimator.filter.route_update",
    "FilterInputs": "estimator.filter.setup",
    "kernel_config": "estimator.filter.setup",
    "prepare_inputs": "estimator.filter.setup",
}

__all__ = [
    "UNOBSERVED_VAR",
    "Filter",
    "FilterInputs",
    "FilterState",
    "advance_to_outage",
    "applied_obs_cov",
    "apply_route_match",
    "disagreeing_fixes",
    "epochs_of",
    "heading_observation",
    "kernel_config",
    "prepare_inputs",
]


__getattr__ = lazy_getattr(__name__, _HOMES)
