"""``extensions.route_errors_overlap_share``: the route-error states take a share of a route
pseudo-position's cross-track evidence (a partial update), the position all of it, and the
covariance stays the one of the gain applied (Joseph form), with or without the blind gain of
the considered gyro scale factor."""

from __future__ import annotations

import numpy as np

from estimator.filter import layout, updates


def _setup(seed: int, blind: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((layout.NE, layout.NE))
    P = (a @ a.T + layout.NE * np.eye(layout.NE)) * 0.1
    x = np.zeros(layout.NX)
    x[layout.X_QUAT] = 1.0
    x[layout.X_SCALE] = 1.0
    aux = np.zeros(layout.NA)
    aux[layout.A_ROUTE_EST] = 1.0
    cfg = np.zeros(layout.NC)
    cfg[layout.C_SCALE_ON] = 1.0
    cfg[layout.C_GSF_BLIND] = 1.0 if blind else 0.0
    return x, P, aux, cfg


def _expected(P: np.ndarray, R: np.ndarray, n: np.ndarray, normal: np.ndarray, share: float):
    H = np.zeros((2, layout.NE))
    H[0, layout.E_POS] = H[1, layout.E_POS + 1] = 1.0
    H[:, layout.E_LANE] = -n
    H[:, layout.E_MAP : layout.E_MAP + 2] = np.eye(2)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    K[layout.E_ROT] = 0.0
    K[layout.E_GSF] = 0.0
    route = [layout.E_LANE, layout.E_MAP, layout.E_MAP + 1]
    K[route] = K[route] @ (np.eye(2) - (1.0 - share) * np.outer(normal, normal))
    I_KH = np.eye(layout.NE) - K @ H
    return K, I_KH @ P @ I_KH.T + K @ R @ K.T


def test_the_route_errors_take_a_share_of_the_cross_track_evidence_only() -> None:
    x, P, aux, cfg = _setup(3, blind=False)
    z = np.array([1.5, -0.5])
    R = np.array([[2.0, 0.3], [0.3, 0.5]])
    n = np.array([0.6, 0.8])
    share = 0.1
    K, P_exp = _expected(P, R, n, n, share)
    full, _ = _expected(P, R, n, n, 1.0)
    y = z - x[:2]
    res = updates.pseudo_position_update(x, P, aux, cfg, z, R, n, share, n)
    np.testing.assert_allclose(P, P_exp, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res[2:], (full @ y)[layout.E_POS : layout.E_POS + 2], rtol=1e-12)
    moved = aux[layout.A_ROUTE + 1 : layout.A_ROUTE + 3]
    np.testing.assert_allclose(moved, (K @ y)[layout.E_MAP : layout.E_MAP + 2], rtol=1e-12)
    assert not np.allclose(moved, (full @ y)[layout.E_MAP : layout.E_MAP + 2])


def _route_moved(z: np.ndarray, n: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    x, P, aux, cfg = _setup(5, blind=True)
    R = np.array([[1.0, -0.2], [-0.2, 0.7]])
    updates.pseudo_position_update(x, P, aux, cfg, z, R, n, share, n)
    return aux[layout.A_ROUTE + 1 : layout.A_ROUTE + 3].copy(), P


def test_with_the_blind_gain_an_along_track_innovation_moves_the_map_as_before() -> None:
    n = np.array([-0.8, 0.6])
    t = np.array([n[1], -n[0]])
    whole_along, P1 = _route_moved(2.0 * t, n, 1.0)
    shared_along, P = _route_moved(2.0 * t, n, 0.25)
    np.testing.assert_allclose(shared_along, whole_along, rtol=1e-12)
    whole_cross, _ = _route_moved(2.0 * n, n, 1.0)
    shared_cross, _ = _route_moved(2.0 * n, n, 0.25)
    np.testing.assert_allclose(shared_cross, 0.25 * whole_cross, rtol=1e-12)
    # less gain on the route errors leaves more of their variance than the whole update
    i = layout.E_MAP
    assert n @ P[i : i + 2, i : i + 2] @ n > n @ P1[i : i + 2, i : i + 2] @ n


def test_a_share_of_one_is_the_whole_update() -> None:
    R = np.array([[1.0, -0.2], [-0.2, 0.7]])
    n = np.array([-0.8, 0.6])
    z = np.array([-0.7, 2.0])
    x1, P1, aux1, cfg1 = _setup(5, blind=True)
    updates.pseudo_position_update(x1, P1, aux1, cfg1, z, R, n, 1.0, n)
    x2, P2, aux2, cfg2 = _setup(5, blind=True)
    updates.pseudo_position_update(x2, P2, aux2, cfg2, z, R, n, 1.0, np.zeros(2))
    np.testing.assert_array_equal(P2, P1)
    np.testing.assert_array_equal(x2, x1)
