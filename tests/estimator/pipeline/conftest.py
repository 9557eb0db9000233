"""Shared fixtures of the pipeline tests: a simulated tunnel drive and its proposed run."""

from __future__ import annotations

import pytest

from estimator.params import Params
from estimator.pipeline import run
from estimator.sim import simulate


@pytest.fixture(scope="session")
def tunnel():
    sim = simulate("short_tunnel", seed=1)
    return sim.log(), sim.route(), sim.frame


@pytest.fixture(scope="session")
def tunnel_proposed(tunnel):
    log, route, frame = tunnel
    return run(log, route, Params(), method="proposed", frame=frame)
