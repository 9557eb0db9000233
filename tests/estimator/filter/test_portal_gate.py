"""The portal's test of each fix against the filter dead-reckoned without it
(``estimator.filter.portal.disagreeing_fixes``) uses the whole E-N covariance the dead
reckoning grew, its tilt included: along a diagonal road the growth is a thin ellipse along
the road, and the E and N sigmas alone would pass a fix metres off across it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from estimator.filter import layout as ly
from estimator.filter import portal
from estimator.filter.engine import row_position_cov

ALONG = np.array([1.0, 1.0]) / np.sqrt(2.0)
ACROSS = np.array([1.0, -1.0]) / np.sqrt(2.0)


def _rows(t: np.ndarray, var_along: np.ndarray, var_across: float) -> np.ndarray:
    rows = np.zeros((len(t), ly.NO))
    rows[:, ly.O_T] = t
    cov = var_along[:, None, None] * np.outer(ALONG, ALONG) + var_across * np.outer(ACROSS, ACROSS)
    rows[:, ly.O_SIG_POS] = np.sqrt(cov[:, 0, 0])
    rows[:, ly.O_SIG_POS + 1] = np.sqrt(cov[:, 1, 1])
    rows[:, ly.O_COV_EN] = cov[:, 0, 1]
    return rows


def test_row_position_cov_reads_one_row_or_many() -> None:
    rows = _rows(np.arange(3.0), np.array([1.0, 4.0, 9.0]), 0.25)
    many = row_position_cov(rows)
    assert many.shape == (3, 2, 2)
    np.testing.assert_allclose(row_position_cov(rows[2]), many[2])
    np.testing.assert_allclose(many[2] @ ALONG, 9.0 * ALONG)
    np.testing.assert_allclose(many[2] @ ACROSS, 0.25 * ACROSS)


def _disagreeing(
    monkeypatch: pytest.MonkeyPatch, var_along: np.ndarray, offsets: list[np.ndarray]
) -> list[int]:
    """The fixes at 2 s ``offsets`` (E, N) from the dead-reckoned position that the portal's
    test drops, dead reckoning from a state known exactly (zero covariance, white fixes of
    0.01 m^2) having grown ``var_along`` along the north-east road over 0-2 s and 0.05 m^2
    across it."""
    t = np.linspace(0.0, 2.0, len(var_along))
    rows = _rows(t, var_along, 0.05)
    monkeypatch.setattr(portal, "_dead_reckoned_rows", lambda saved, t_stop, inp: rows)
    cfg = np.zeros(ly.NC)
    cfg[ly.C_TAU_W] = 100.0
    cfg[ly.C_WHITE_VAR] = 0.01
    cfg[ly.C_GNSS_GATE] = 13.8
    fix_pos = np.zeros((len(offsets), 3))
    fix_pos[:, :2] = offsets
    inp = SimpleNamespace(cfg=cfg, gnss_t=np.full(len(offsets), 2.0), gnss_pos=fix_pos)
    saved = (np.zeros(ly.NX), np.zeros((ly.NE, ly.NE)), np.zeros(ly.NA), np.zeros(ly.NI, np.int64))
    return portal.disagreeing_fixes(saved, 2.0, inp, range(len(offsets)))  # type: ignore[arg-type]


def test_a_fix_off_across_a_diagonal_road_disagrees_and_one_along_it_does_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Dead reckoning grew 50 m^2 along a road heading north-east and almost nothing across:
    a fix 1.5 m off across it is 15 sigmas off, one 5 m off along it under one. With only the
    E and N variances (25 m^2 each) both looked fine."""
    grown = np.linspace(0.0, 50.0, 21)
    assert _disagreeing(monkeypatch, grown, [5.0 * ALONG, 1.5 * ACROSS]) == [1]


def test_a_covariance_the_dead_reckoning_shrank_is_not_taken_off_the_fixes_noise(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Dead reckoning's non-holonomic and wheel updates can shrink the position variance a
    little through its correlations. Taken off the saved covariance, such shrinking can cancel
    the fixes' white noise and leave the test a matrix that is singular or not positive, under
    which a fix 1 m off passes; the growth counts as grown or nothing, so the fix is judged
    against its noise (the E and N variances alone were clipped at zero the same way)."""
    shrunk = np.linspace(0.06, 0.05, 21)
    assert _disagreeing(monkeypatch, shrunk, [1.0 * ALONG]) == [0]
