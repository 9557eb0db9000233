"""The bundled sample logs are exactly what their documented command regenerates."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.io import load_log
from estimator.sim import simulate
from inspector.cli.main import main
from inspector.cli.summary import gnss_outages

SAMPLE_LOGS = Path(__file__).resolve().parents[3] / "sample_logs"
NAMES = ("long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel")


@pytest.fixture
def sample_logs() -> Path:
    if not (SAMPLE_LOGS / "README.md").is_file():
        pytest.skip(f"sample logs not found at {SAMPLE_LOGS}")
    return SAMPLE_LOGS


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_regenerates_bit_for_bit(name, sample_logs, tmp_path) -> None:
    command = f"routefuse simulate {name} --out sample_logs --force"
    assert command in (sample_logs / "README.md").read_text()
    assert main(["simulate", name, "--out", str(tmp_path)]) == 0
    for suffix in (".mcap", ".route.geojson"):
        bundled = (sample_logs / f"{name}{suffix}").read_bytes()
        assert (tmp_path / f"{name}{suffix}").read_bytes() == bundled, f"{name}{suffix} differs"


@pytest.mark.parametrize("name", NAMES)
def test_info_outages_are_the_tunnels(name, sample_logs, tmp_path) -> None:
    sim = simulate(name)
    log = load_log(sample_logs / f"{name}.mcap", cache_dir=tmp_path)
    outages, _ = gnss_outages(log)
    tunnels = [(a - sim.t0, b - sim.t0) for a, b in sim.tunnels]
    assert len(outages) == len(tunnels)
    gap = 1.0 / sim.scenario.gnss.rate_hz
    for (o0, o1), (a, b) in zip(outages, tunnels, strict=True):
        assert o0 == pytest.approx(a, abs=gap + 1e-6)
        assert o1 == pytest.approx(b + sim.scenario.gnss.reacquisition_s, abs=gap + 1e-6)
    assert (sample_logs / "ATTRIBUTION").is_file() or name != "monaco_tunnel"
    assert np.all(np.diff(log.imu.t) > 0)
