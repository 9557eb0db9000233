"""Re-anchoring: which refused attempts blame the filter, and the drift that may explain them
(:mod:`estimator.matching.reanchor`); the covariance widening it comes with."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.matching.reanchor import (
    GAP_TURN_RAD,
    blames_the_filter,
    drift_bound_m,
    gap_bound_m,
    should_reanchor,
    within_drift,
)
from estimator.params import Params
from estimator.pipeline.driver import widen_to_innovation
from estimator.results import FitSummary, Gate, GateDecision, MatchRecord, Rival

P = Params()


def _record(
    failed: tuple[Gate, ...],
    *,
    residual: float = 1.0,
    rival_residual: float = 1.0,
    rotation_deg: float = 0.0,
):
    gates = tuple(GateDecision(g, 1.0, 0.0, "<=", g not in failed, "") for g in Gate)
    fit = FitSummary(
        along_offset_m=0.0,
        along_curvature=0.0,
        along_sigma_m=1.0,
        along_observed=True,
        cross_sigma_m=1.0,
        lane_path=False,
        innovation_along_m=0.0,
        innovation_cross_m=8.0,
        normal=np.array([0.0, 1.0]),
        heading_sigma_rad=0.01,
    )
    nan2 = np.full(2, np.nan)
    return MatchRecord(
        index=0,
        t=0.0,
        epoch=0,
        accepted=not failed,
        gates=gates,
        window_dr=np.zeros((0, 2)),
        route_points=np.zeros((0, 2)),
        route_segment=np.zeros((0, 2)),
        route_s=(0.0, 0.0),
        n_pairs=40,
        rotation_rad=math.radians(rotation_deg),
        translation=np.zeros(2),
        residual_m=residual,
        heading_cos=1.0,
        p_dr=np.zeros(2),
        p_ref=nan2,
        lane_offset_m=0.0,
        pseudo_position=np.array([0.0, 8.0]),
        obs_cov=np.eye(2),
        innovation=np.array([0.0, 8.0]),
        correction=np.zeros(2),
        anchor_s=0.0,
        window_length_m=250.0,
        fit=fit,
        extra={f"residual_{r.value}_m": rival_residual for r in Rival},
    )


def test_refusals_for_disagreeing_with_the_filter_blame_it() -> None:
    assert blames_the_filter(_record((Gate.MAHALANOBIS, Gate.LANE_CONTINUITY)), P)
    assert blames_the_filter(_record((Gate.ALTERNATIVE_LEFT,), rival_residual=1.0), P)


@pytest.mark.parametrize(
    "record",
    [
        _record((Gate.RESIDUAL,)),
        _record((Gate.CORRECTION_CAP, Gate.MAHALANOBIS)),
        _record((Gate.ALTERNATIVE_REVERSED,)),
        _record((Gate.ALTERNATIVE_LEFT,), rival_residual=0.5),
        _record(()),
    ],
    ids=["bad shape", "over the cap", "reversed", "better-shaped rival", "accepted"],
)
def test_a_doubtful_match_does_not_blame_the_filter(record: MatchRecord) -> None:
    assert not blames_the_filter(record, P)


def test_the_drift_bound_is_half_the_heading_error_times_the_distance() -> None:
    b = math.radians(P.gates.reanchor_gyro_bias_deg_s)
    assert drift_bound_m(20.0, 300.0, P) == pytest.approx(0.5 * b * 20.0 * 300.0)
    assert drift_bound_m(-1.0, 300.0, P) == 0.0


def test_only_innovations_a_drift_explains_are_within_it() -> None:
    y = np.array([0.0, 8.0])
    assert within_drift(y, np.eye(2), seconds=20.0, metres=300.0, params=P)  # bound 13 m
    assert not within_drift(y, np.eye(2), seconds=3.0, metres=45.0, params=P)  # 0.3 m + 3
    # a direction the match does not observe does not widen the test across the road
    along_blind = np.diag([1e4, 1.0])
    assert not within_drift(y, along_blind, seconds=3.0, metres=45.0, params=P)


def test_a_run_is_re_anchored_only_whole_and_long_enough() -> None:
    sound = _record((Gate.MAHALANOBIS,))
    k = P.gates.reanchor_after
    assert should_reanchor([(sound, True)] * k, P)
    assert not should_reanchor([(sound, True)] * (k - 1), P)
    # a wrong road is off from the first attempt on: that taints the run
    assert not should_reanchor([(sound, False)] + [(sound, True)] * k, P)
    assert not should_reanchor([(_record((Gate.RESIDUAL,)), True)] + [(sound, True)] * k, P)


def test_widening_makes_the_innovation_one_sigma_in_its_direction() -> None:
    P6 = np.eye(22) * 0.5
    s = np.array([[1e4, 0.0], [0.0, 1.0]])  # along-track unobserved
    y = np.array([3.0, 8.0])
    widen_to_innovation(P6, y, s)
    added = P6[6:8, 6:8] - 0.5 * np.eye(2)
    assert y @ np.linalg.solve(s + added, y) == pytest.approx(1.0)
    assert np.linalg.eigvalsh(P6).min() > 0
    before = P6.copy()
    widen_to_innovation(P6, np.array([0.0, 0.1]), np.eye(2))  # already within: unchanged
    np.testing.assert_array_equal(P6, before)


def test_after_an_imu_gap_the_heading_and_the_correction_blame_the_filter() -> None:
    turned = _record((Gate.HEADING, Gate.ROTATION, Gate.CORRECTION_CAP), rotation_deg=18.0)
    assert not blames_the_filter(turned, P)
    assert blames_the_filter(turned, P, after_gap=True)
    k = P.gates.reanchor_after
    assert should_reanchor([(turned, True)] * k, P, after_gap=True)
    assert not should_reanchor([(turned, True)] * k, P)


@pytest.mark.parametrize(
    "record",
    [
        _record((Gate.ROTATION,), rotation_deg=math.degrees(GAP_TURN_RAD) + 1.0),
        _record((Gate.HEADING, Gate.ALTERNATIVE_REVERSED), rotation_deg=10.0),
        _record((Gate.RESIDUAL, Gate.HEADING), rotation_deg=10.0),
    ],
    ids=["turned beyond the gap's bound", "reversed", "bad shape"],
)
def test_a_gap_does_not_excuse_a_doubtful_match(record: MatchRecord) -> None:
    assert not blames_the_filter(record, P, after_gap=True)


def test_the_gap_bound_is_half_the_bridge_then_the_gap_turn_over_the_distance() -> None:
    assert gap_bound_m(400.0, 0.0) == pytest.approx(200.0)
    assert gap_bound_m(400.0, 300.0) == pytest.approx(200.0 + math.sin(GAP_TURN_RAD) * 300.0)
    y = np.array([0.0, 300.0])
    assert not within_drift(y, np.eye(2), seconds=20.0, metres=300.0, params=P)
    assert within_drift(
        y, np.eye(2), seconds=20.0, metres=300.0, params=P, gap_m=gap_bound_m(400.0, 300.0)
    )
