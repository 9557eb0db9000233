"""``extensions.map_turn_estimate``: the rotation corrections a route pseudo-position makes at
the vehicle are summed by the filter as a turn about the origin and a shift, which
:func:`turned_back` turns into the shift at the bias's pivot and the turn about it. Checked
against the displacement field the corrections add one by one."""

from __future__ import annotations

import numpy as np

from estimator.filter.layout import (
    A_MAP_AT,
    A_ROT,
    A_ROT_EST,
    A_ROT_SHIFT,
    A_ROUTE,
    A_ROUTE_EST,
    E_ROT,
    NA,
    NC,
    NE,
    NX,
    X_POS,
    X_QUAT,
)
from estimator.filter.updates import pseudo_position_update
from estimator.matching.map_bias import turned_back, xy_moved_back


def _field(offset: np.ndarray, rotation: float, pivot: np.ndarray, q: np.ndarray) -> np.ndarray:
    d = q - pivot
    out: np.ndarray = offset + rotation * np.column_stack([-d[:, 1], d[:, 0]])
    return out


def _setup(rot_est: bool, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(NE, NE))
    P = a @ a.T + NE * np.eye(NE)
    P[E_ROT, :] *= 1e-3
    P[:, E_ROT] *= 1e-3  # a rotation error of a few mrad against metres elsewhere
    x = np.zeros(NX)
    x[X_QUAT] = 1.0
    aux = np.zeros(NA)
    aux[A_ROUTE_EST] = 1.0
    aux[A_ROT_EST] = 1.0 if rot_est else 0.0
    cfg = np.zeros(NC)
    return P, x, aux, cfg


def test_summed_rotation_corrections_are_the_field_they_add_up_to() -> None:
    rng = np.random.default_rng(7)
    P, x, aux, cfg = _setup(True, 1)
    offset0, rotation0 = np.array([6.0, -3.0]), 0.004
    pivot = np.array([1200.0, -800.0])
    q = rng.uniform(-3000.0, 3000.0, size=(20, 2))
    want = _field(offset0, rotation0, pivot, q)
    for _ in range(6):
        at = rng.uniform(-2500.0, 2500.0, size=2)
        x[X_POS : X_POS + 2] = at + rng.normal(size=2)
        aux[A_MAP_AT : A_MAP_AT + 2] = at
        before = aux.copy()
        z = x[X_POS : X_POS + 2] + rng.normal(scale=3.0, size=2)
        pseudo_position_update(x, P, aux, cfg, z, np.eye(2), np.array([0.0, 1.0]), 1.0, np.zeros(2))
        dm = aux[A_ROUTE + 1 : A_ROUTE + 3] - before[A_ROUTE + 1 : A_ROUTE + 3]
        dr = aux[A_ROT] - before[A_ROT]
        assert dr != 0.0  # the rotation error has a gain
        want = want + dm + dr * np.column_stack([-(q[:, 1] - at[1]), q[:, 0] - at[0]])
    offset, rotation = turned_back(
        offset0 + aux[A_ROUTE + 1 : A_ROUTE + 3],
        rotation0,
        pivot,
        turn=float(aux[A_ROT]),
        shift=aux[A_ROT_SHIFT : A_ROT_SHIFT + 2],
    )
    assert rotation == rotation0 + aux[A_ROT]
    np.testing.assert_allclose(_field(offset, rotation, pivot, q), want, rtol=0, atol=1e-9)
    # the route moved back by it is the one moved back by each correction in turn
    np.testing.assert_allclose(xy_moved_back(q, offset, rotation, pivot), q - want, atol=1e-9)


def test_without_the_switch_the_rotation_error_stays_considered() -> None:
    P, x, aux, cfg = _setup(False, 2)
    rot_row = P[E_ROT].copy()
    x[X_POS : X_POS + 2] = [300.0, 40.0]
    aux[A_MAP_AT : A_MAP_AT + 2] = [300.0, 40.0]
    z = np.array([302.0, 37.0])
    pseudo_position_update(x, P, aux, cfg, z, np.eye(2), np.array([0.0, 1.0]), 1.0, np.zeros(2))
    assert aux[A_ROT] == 0.0 and not np.any(aux[A_ROT_SHIFT : A_ROT_SHIFT + 2])
    assert P[E_ROT, E_ROT] == rot_row[E_ROT]
    P2, x2, aux2, cfg2 = _setup(True, 2)
    pseudo_position_update(x2, P2, aux2, cfg2, z, np.eye(2), np.array([0.0, 1.0]), 1.0, np.zeros(2))
    assert P2[E_ROT, E_ROT] < rot_row[E_ROT]
