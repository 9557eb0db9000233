"""The Match tab's route-axes table in headless Chromium: at an attempt the Mahalanobis gate
refused, the innovation, the filter's 1-sigma before the update and the observation's 1-sigma,
along and across the route, with the record's numbers. The long tunnel on its trap route (the
``routefuse serve`` default), where the parallel bore's attempts are refused. With
ROUTEFUSE_UPDATE_SCREENSHOT=1 its screenshot replaces docs/match_sigmas.png."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from _browser import panel_screenshot, served, session_page, wait_until

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "long_tunnel.mcap"
TRAP = REPO / "sample_logs" / "long_tunnel_parallel_bore.route.geojson"
VIEWPORT = {"width": 1400, "height": 1250}


def _row(label: str, along: float, across: float) -> re.Pattern[str]:
    """A table row as the page's text has it: the cells apart by white space."""
    return re.compile(rf"{re.escape(label)}\s+{along:.2f}\s+{across:.2f}\b")


def test_a_refused_attempt_shows_the_filter_sigma_beside_the_observation_sigma(browser, tmp_path):
    with served(LOG, TRAP) as (server, controller, app):
        session = controller.session
        matches = session.proposed.matches
        i = next(k for k, m in enumerate(matches) if m.verdict == "rejected: mahalanobis")
        m = matches[i]
        t, n = m.tangent, m.normal
        nu = np.asarray(m.innovation)
        gate = next(g for g in m.gates if g.name == "mahalanobis")
        # the numbers on the page are the split of the gate's own S
        s = m.filter_cov + m.obs_cov
        assert float(nu @ np.linalg.solve(s, nu)) == pytest.approx(gate.value, rel=1e-9)

        page, view = session_page(browser, server, app, VIEWPORT)
        page.get_by_role("tab", name="Match").click()
        view.seek(float(session.timeline.match_t[i]) + 0.01)
        wait_until(lambda: f"Attempt #{i} (" in page.inner_text("body"), 20, "the attempt")
        text = page.inner_text("body")
        assert "REJECTED by mahalanobis" in text
        assert re.search(rf"mahalanobis\s+{gate.value:.3f}\s+<= 13.800\s+✗ FAILED", text)
        assert re.search(r"route axes, m\s+along\s+across \(\+ left\)", text), text[:3000]
        f, r = m.filter_cov, m.obs_cov
        rows = {
            "innovation": (t @ nu, n @ nu),
            "filter 1-sigma, before the update": (np.sqrt(t @ f @ t), np.sqrt(n @ f @ n)),
            "observation 1-sigma": (np.sqrt(t @ r @ t), np.sqrt(n @ r @ n)),
        }
        for label, (along, across) in rows.items():
            assert _row(label, along, across).search(text), (label, along, across, text[:3000])
        # the filter was sure across the road, the innovation was not
        assert abs(n @ nu) > 5 * np.sqrt(n @ f @ n + n @ r @ n)
        shot = tmp_path / "match_sigmas.png"
        panel_screenshot(page, shot)
        page.close()
    if os.environ.get("ROUTEFUSE_UPDATE_SCREENSHOT") == "1":
        shutil.move(shot, REPO / "docs" / "match_sigmas.png")
