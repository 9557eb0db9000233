"""``MatchRecord.filter_cov``: the filter's position covariance at a match attempt, before its
update, as the Mahalanobis gate used it. The gate's chi-square is recomputed from the record
alone (S = filter_cov + obs_cov), so the Match tab's split of S into the filter's part and the
fit's is the split the gate made."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.params import Params
from estimator.pipeline import open_inputs, run_methods
from estimator.results import Gate, MatchRecord, Run

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"


def _proposed(log: str, route: str) -> Run:
    inp = open_inputs(SAMPLES / f"{log}.mcap", SAMPLES / f"{route}.route.geojson")
    return run_methods(inp, Params(), methods=("proposed",))["proposed"]


@pytest.fixture(scope="module")
def trap() -> Run:
    """The long tunnel on its trap route (1.2 km drawn along the parallel bore): accepted
    attempts and attempts refused by the Mahalanobis gate, no map-bias variance."""
    return _proposed("long_tunnel", "long_tunnel_parallel_bore")


@pytest.fixture(scope="module")
def biased() -> Run:
    """The spiral tunnel, whose outage carries a map bias with a variance: the gate's S holds
    the map-bias error's covariance too."""
    return _proposed("spiral_tunnel", "spiral_tunnel")


def _gate(m: MatchRecord) -> float | None:
    return next((g.value for g in m.gates if g.gate is Gate.MAHALANOBIS), None)


def _posterior(run: Run, k: int) -> np.ndarray:
    e = run.epochs
    c = float(e.position_cov_en[k])
    return np.array([[e.position_sigma[k, 0] ** 2, c], [c, e.position_sigma[k, 1] ** 2]])


@pytest.mark.parametrize("which", ["trap", "biased"])
def test_the_gate_chi_square_is_the_innovation_over_filter_and_fit_covariance(which, request):
    """nu^T (filter_cov + obs_cov)^-1 nu with the record's innovation: the gate's value to
    rounding, refused or accepted, with a map bias carried or not (the record's obs_cov is the
    gate's R_k unless ``extensions.overlap_inflation``, off here, widens it after the gates)."""
    run: Run = request.getfixturevalue(which)
    assert not run.params.extensions.overlap_inflation
    gated = [m for m in run.matches if _gate(m) is not None]
    assert len(gated) > 100
    for m in gated:
        nu = np.asarray(m.innovation)
        d2 = float(nu @ np.linalg.solve(m.filter_cov + m.obs_cov, nu))
        assert d2 == pytest.approx(_gate(m), rel=1e-9, abs=1e-12), m.index
        assert m.extra["mahalanobis_d2"] == _gate(m)
    refused = [m for m in gated if m.verdict == "rejected: mahalanobis"]
    if which == "trap":
        assert len(refused) >= 10 and any(m.accepted for m in gated)
    else:
        # the map-bias term is in play: its covariance is part of what the gate added
        assert all(m.map_bias is not None and np.trace(m.map_bias.cov) > 0 for m in gated)


@pytest.mark.parametrize("which", ["trap", "biased"])
def test_filter_cov_is_symmetric_positive_definite(which, request):
    run: Run = request.getfixturevalue(which)
    for m in run.matches:
        c = m.filter_cov
        assert c.shape == (2, 2) and np.all(np.isfinite(c))
        assert np.array_equal(c, c.T)
        assert np.linalg.eigvalsh(c)[0] > 0.0, m.index


def test_an_accepted_update_shrinks_the_position_covariance_along_what_it_observed(trap):
    """The epoch row at an accepted attempt is written after its update: across the route
    (always observed) and, where the fit observed it, along the route, its covariance is below
    the attempt's filter_cov. Without map-bias variance filter_cov is the position's own."""
    accepted = [m for m in trap.matches if m.accepted]
    assert len(accepted) > 100
    along = 0
    for m in accepted:
        assert m.map_bias is None or not np.any(m.map_bias.cov)
        post = _posterior(trap, m.epoch)
        n, t = m.normal, m.tangent
        assert n @ post @ n < n @ m.filter_cov @ n, m.index
        if m.along_observed:
            along += 1
            assert t @ post @ t < t @ m.filter_cov @ t, m.index
    assert along >= 10


def test_diagnostics_give_the_filter_sigma_along_and_across_the_route(trap):
    """The export's extra_filter_* columns and the Match tab read these."""
    m = next(m for m in trap.matches if m.verdict == "rejected: mahalanobis")
    d = m.diagnostics()
    t, n = m.tangent, m.normal
    assert d["filter_along_sigma_m"] == pytest.approx(np.sqrt(t @ m.filter_cov @ t), rel=1e-12)
    assert d["filter_cross_sigma_m"] == pytest.approx(np.sqrt(n @ m.filter_cov @ n), rel=1e-12)
    assert t @ n == pytest.approx(0.0, abs=1e-12) and n @ n == pytest.approx(1.0)
    # the fit's own pair, from the same axes
    assert m.route_sigmas(m.obs_cov)[1] == pytest.approx(d["cross_sigma_m"], rel=1e-9)
