"""Scene layers drawn into a real (browser-less) viser server: what a frame step changes."""

from __future__ import annotations

import numpy as np
from fake_runs import T0, make_route, make_run

from inspector.layers import SceneLayers
from inspector.scene_data import SceneData


def _drifting_layers(viser_server, root: str) -> SceneLayers:
    """The layers of a proposed run and a baseline 30 m off it, their data set."""
    data = SceneData.build(
        baseline=make_run(drift=30, method="baseline"),
        proposed=make_run(),
        route=make_route(),
        log=None,
    )
    layers = SceneLayers(viser_server.scene, root=root)
    layers.set_data(data)
    return layers


def test_draw_moves_the_vehicle_and_switches_the_match(viser_server):
    layers = _drifting_layers(viser_server, "/test1")
    pose = layers.layers["proposed"]._handles["pose"]
    match = layers.layers["match"]
    layers.draw(T0 + 10)
    p10 = np.array(pose.position)
    assert not match._handles  # no attempt yet: nothing drawn
    layers.draw(T0 + 10.05)
    assert np.linalg.norm(np.array(pose.position) - p10) > 0.1
    layers.draw(T0 + 45)
    label = match._handles["label"]
    assert label.text == "#1 accepted" and label.visible
    window = match._handles["window"].points.copy()
    layers.draw(T0 + 50)
    assert label.text == "#2 rejected: residual"
    assert not np.allclose(match._handles["window"].points, window)
    layers.draw(T0 + 70)  # 10 s after the last attempt: the match layer hides
    assert not label.visible and not match._handles["window"].visible
    layers.remove()


def test_toggling_a_layer_hides_its_nodes(viser_server):
    data = SceneData.build(
        baseline=make_run(method="baseline"), proposed=make_run(), route=make_route(), log=None
    )
    layers = SceneLayers(viser_server.scene, root="/test2")
    layers.set_data(data)
    layers.draw(T0 + 45)
    layers.set_visible("match", False)
    assert all(not h.visible for h in layers.layers["match"]._handles.values())
    layers.draw(T0 + 50)
    assert all(not h.visible for h in layers.layers["match"]._handles.values())
    layers.set_visible("match", True)
    assert layers.layers["match"]._handles["label"].visible
    layers.set_visible("baseline", False)
    assert not layers.layers["baseline"]._handles["line"].visible
    layers.remove()


def _map_bias_layers(viser_server, bias, root):
    """The layers of a run whose attempt shown at ``T0 + 45`` was matched with ``bias``."""
    import dataclasses

    run = make_run()
    k = next(i for i, m in enumerate(run.matches) if m.index == 1)  # on screen at T0 + 45
    matches = tuple(
        dataclasses.replace(m, map_bias=bias) if i == k else m for i, m in enumerate(run.matches)
    )
    data = SceneData.build(
        baseline=make_run(method="baseline"),
        proposed=dataclasses.replace(run, matches=matches),
        route=make_route(),
        log=None,
    )
    layers = SceneLayers(viser_server.scene, root=root)
    layers.set_data(data)
    layers.draw(T0 + 45)
    return layers


def test_a_match_with_a_map_bias_draws_the_segment_where_the_map_has_it(viser_server):
    """With ``extensions.map_bias`` the window is matched to the route moved back by the
    learned bias; the map's own segment is drawn beside it, ``offset`` away, and hidden for a
    match without a bias."""
    from estimator.results import MapBiasUse

    offset = np.array([6.0, -2.5])
    bias = MapBiasUse(offset=offset, cov=np.eye(2), along_observed=True)
    layers = _map_bias_layers(viser_server, bias, "/test3")
    match = layers.layers["match"]
    matched, on_map = match._handles["segment"].points, match._handles["map_segment"].points
    assert match._handles["map_segment"].visible and on_map.shape == matched.shape
    assert np.allclose(on_map[..., :2] - matched[..., :2], offset, atol=1e-4)
    layers.draw(T0 + 50)
    assert not match._handles["map_segment"].visible
    layers.remove()


def test_a_turned_map_bias_draws_the_segment_turned_about_where_it_was_learned(viser_server):
    """A map turned about a point far into a long tunnel lies tens of metres more off at the
    vehicle than at the portal where the bias was learned: the map's segment is drawn where
    the turned bias puts it at the vehicle, not ``offset`` (the bias at the pivot) away."""
    from estimator.results import MapBiasUse

    offset, pivot, rotation = np.array([6.0, -2.5]), np.array([-3000.0, 400.0]), 0.03
    bias = MapBiasUse(
        offset=offset, cov=np.eye(2), along_observed=True, rotation_rad=rotation, pivot=pivot
    )
    layers = _map_bias_layers(viser_server, bias, "/test4")
    match = layers.layers["match"]
    matched = match._handles["segment"].points[..., :2]
    on_map = match._handles["map_segment"].points[..., :2]
    d = matched - pivot
    expected = offset + rotation * np.stack([-d[..., 1], d[..., 0]], axis=-1)
    assert np.allclose(on_map - matched, expected, atol=1e-3)
    assert np.min(np.hypot(*(on_map - matched - offset).reshape(-1, 2).T)) > 50.0
    layers.remove()


def test_a_runs_vehicle_carries_the_ring_of_its_own_covariance(viser_server):
    """The proposed and baseline vehicles are ringed by the 95 % ellipse of their filter's
    horizontal covariance (the fake runs claim 1 m in E and N, uncorrelated: a circle of
    2.45 m); the truth has none."""
    layers = _drifting_layers(viser_server, "/ring")
    ring = layers.layers["proposed"]._handles["ring"]
    assert not ring.visible  # placed by the first frame
    layers.draw(T0 + 10)
    pose = layers.layers["proposed"]._handles["pose"]
    assert ring.visible
    np.testing.assert_allclose(np.array(ring.position)[:2], np.array(pose.position)[:2])
    np.testing.assert_allclose(np.array(ring.scale)[:2], np.sqrt(5.991), rtol=1e-6)
    assert "ring" in layers.layers["baseline"]._handles
    assert "ring" not in layers.layers["truth"]._handles
    layers.set_visible("proposed", False)
    assert not ring.visible
    layers.remove()
