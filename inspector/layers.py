"""Scene layers: small objects that draw one aspect of a session into a viser scene.

``set_data(data)`` sends what does not change with time (route, trajectories, verdict markers);
``draw(data, t)`` updates what does (vehicle poses, the current match attempt), touching only
the handles whose content changed. A layer only knows a :class:`viser.SceneApi` and a
:class:`SceneData`, so the live UI (a tab's ``client.scene``) and the headless export (the
server's scene under a serializer) draw the same thing.

Everything is drawn in the local EN plane (z = small per-layer offsets so lines do not fight),
polylines as line segments with screen-space thickness.
"""

from __future__ import annotations

import html
import math
from typing import ClassVar, Literal, TypeVar

import numpy as np
import viser

from estimator.results import MatchRecord
from inspector.scene_data import F64, SceneData, Track, polyline_segments

RGB = tuple[int, int, int]
PointShape = Literal["square", "diamond", "circle", "rounded", "sparkle"]
H = TypeVar("H", bound=viser.SceneNodeHandle)

ROUTE = (120, 120, 120)
SEGMENT = (255, 200, 0)
MAP_SEGMENT = (150, 110, 40)
BASELINE = (232, 113, 10)
PROPOSED = (26, 115, 232)
TRUTH = (30, 150, 60)
GNSS = (40, 180, 90)
NO_GNSS = (255, 170, 170)
DR_WINDOW = (150, 70, 200)
ALIGNED = (0, 190, 200)
PAIRS = (170, 170, 170)
PSEUDO = (220, 30, 140)
ACCEPTED = (30, 170, 60)
REJECTED = (220, 40, 40)
EXIT_WITHIN = (40, 40, 40)
EXIT_BEYOND = (140, 0, 0)


RING_POINTS = 72
"""segments of a vehicle's covariance ring"""

MATCH_MAX_AGE_S = 5.0
"""The current attempt stays drawn this long after its time (then the frame has no match)."""

_EMPTY_SEG = np.zeros((1, 2, 3), np.float32)


def _yaw_wxyz(yaw: float) -> tuple[float, float, float, float]:
    return (float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2)))


def _segments_or_empty(seg: np.ndarray) -> np.ndarray:
    return seg if len(seg) else _EMPTY_SEG


def _points3(xy: F64, z: float) -> np.ndarray:
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return np.zeros((1, 3), np.float32)
    return np.column_stack([xy, np.full(len(xy), z)]).astype(np.float32)


class Layer:
    """Base: a named group of scene handles that can be shown or hidden together."""

    key: ClassVar[str] = ""
    label: ClassVar[str] = ""
    legend: ClassVar[tuple[tuple[RGB, str], ...]] = ()
    """(colour, what it marks) of everything the layer draws: the Layers tab, the compact
    legend and the export's legend are made from it"""

    def __init__(self, scene: viser.SceneApi, *, root: str = "/routefuse") -> None:
        self.scene = scene
        self.root = f"{root}/{self.key}"
        self._handles: dict[str, viser.SceneNodeHandle] = {}
        """every part by name, shown, hidden and removed together"""
        self._segments: dict[str, viser.LineSegmentsHandle] = {}
        self._clouds: dict[str, viser.PointCloudHandle] = {}
        self._meshes: dict[str, viser.MeshHandle] = {}
        self._labels: dict[str, viser.LabelHandle] = {}
        self._wanted: dict[str, bool] = {}
        """whether a part has something to show (drawn only while the layer is visible)"""
        self._visible = True

    @property
    def visible(self) -> bool:
        return self._visible

    @visible.setter
    def visible(self, on: bool) -> None:
        self._visible = bool(on)
        for name, h in self._handles.items():
            h.visible = self._visible and self._wanted.get(name, True)

    def _show(self, name: str, on: bool) -> None:
        self._wanted[name] = on
        self._handles[name].visible = on and self._visible

    def _keep(self, name: str, handle: H, kind: dict[str, H]) -> H:
        """Register a new part under ``name``, in ``kind`` (its typed table) and among all."""
        kind[name] = handle
        self._handles[name] = handle
        return handle

    def _lines(self, name: str, seg: np.ndarray, color: RGB, px: float) -> None:
        seg = _segments_or_empty(np.asarray(seg, np.float32))
        h = self._segments.get(name)
        if h is None:
            self._keep(
                name,
                self.scene.add_line_segments(
                    f"{self.root}/{name}",
                    seg,
                    color,
                    thickness=px,
                    thickness_units="screen",
                    visible=self._visible,
                ),
                self._segments,
            )
        else:
            h.points = seg

    def _cloud(
        self,
        name: str,
        pts: np.ndarray,
        colors: RGB | np.ndarray,
        size: float,
        shape: PointShape = "circle",
    ) -> None:
        h = self._clouds.get(name)
        colors_arr = np.asarray(colors, np.uint8)
        if colors_arr.ndim == 2 and len(colors_arr) != len(pts):
            colors_arr = np.broadcast_to(colors_arr[:1], (len(pts), 3)).copy()
        if h is None or (colors_arr.ndim == 2 and h.colors.shape != colors_arr.shape):
            if h is not None:
                h.remove()
            self._keep(
                name,
                self.scene.add_point_cloud(
                    f"{self.root}/{name}",
                    pts,
                    colors_arr,
                    point_size=size,
                    point_shape=shape,
                    precision="float32",
                    point_shading="flat",
                    visible=self._visible,
                ),
                self._clouds,
            )
        else:
            h.points = pts
            if colors_arr.ndim == 2:
                h.colors = colors_arr

    def _dots(self, name: str, xy: F64, colors: np.ndarray, px: float, z: float) -> None:
        """Markers that keep their size on screen at any zoom: tiny segments drawn with a
        thickness in pixels (a point cloud's points have a size in metres)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        d = np.array([0.01, 0.0])
        seg = (
            np.stack([_points3(xy - d, z), _points3(xy + d, z)], axis=1)
            if len(xy)
            else (_EMPTY_SEG)
        )
        cols = np.asarray(colors, np.uint8).reshape(-1, 3)
        cols = (
            np.repeat(cols[:, None, :], 2, axis=1)
            if len(cols) == len(seg)
            else np.zeros((len(seg), 2, 3), np.uint8)
        )
        h = self._segments.get(name)
        if h is not None and h.points.shape == seg.shape:
            h.points = seg
            h.colors = cols
            return
        if h is not None:
            h.remove()
        self._keep(
            name,
            self.scene.add_line_segments(
                f"{self.root}/{name}",
                seg,
                cols,
                thickness=px,
                thickness_units="screen",
                visible=self._visible,
            ),
            self._segments,
        )

    def set_data(self, data: SceneData) -> None:
        """Draw what does not depend on time."""

    def draw(self, data: SceneData, t: float) -> None:
        """Update what depends on the time ``t`` (absolute, the run's clock)."""

    def remove(self) -> None:
        for h in self._handles.values():
            h.remove()
        for table in (self._handles, self._segments, self._clouds, self._meshes, self._labels):
            table.clear()
        self._wanted.clear()


class RouteLayer(Layer):
    key = "route"
    label = "route"
    legend = ((ROUTE, "mission route"),)

    def set_data(self, data: SceneData) -> None:
        self._lines("line", polyline_segments(data.route_line, 0.0), ROUTE, 3.0)


class GnssLayer(Layer):
    key = "gnss"
    label = "GNSS fixes and outages"
    legend = ((GNSS, "GNSS fix"), (NO_GNSS, "GNSS outage (no fix)"))

    def set_data(self, data: SceneData) -> None:
        self._lines("missing", data.degraded_segments, NO_GNSS, 14.0)
        self._segments["missing"].position = (0.0, 0.0, -0.05)  # beneath everything
        self._cloud("fixes", _points3(data.gnss_fixes, 0.05), GNSS, 1.2)
        self._show("fixes", len(data.gnss_fixes) > 0)
        self._show("missing", len(data.degraded_segments) > 0)


class TrackLayer(Layer):
    """One trajectory (baseline, proposed or truth) and its vehicle pose at ``t``."""

    z: ClassVar[float] = 0.1
    color: ClassVar[RGB] = PROPOSED
    length_m: ClassVar[float] = 6.0
    ring: ClassVar[bool] = False
    """draw the 95 % ellipse of the run's own covariance around its vehicle: where the truth
    falls outside it, the filter claims more than it knows"""

    def _track(self, data: SceneData) -> Track | None:
        raise NotImplementedError

    def set_data(self, data: SceneData) -> None:
        track = self._track(data)
        line = track.line if track is not None else np.zeros((0, 2))
        self._lines("line", polyline_segments(line, self.z), self.color, 2.0)
        if "pose" not in self._meshes:
            L = self.length_m
            verts = np.array(
                [[L * 0.6, 0, 0], [-L * 0.4, L * 0.3, 0], [-L * 0.4, -L * 0.3, 0]], np.float32
            )
            self._keep(
                "pose",
                self.scene.add_mesh_simple(
                    f"{self.root}/pose",
                    verts,
                    np.array([[0, 1, 2]], np.uint32),
                    color=self.color,
                    side="double",
                    flat_shading=True,
                    cast_shadow=False,
                    receive_shadow=False,
                    visible=self._visible,
                ),
                self._meshes,
            )
        if "marker" not in self._segments:
            # the pose seen from far away: a dot of constant size on screen
            self._keep(
                "marker",
                self.scene.add_line_segments(
                    f"{self.root}/marker",
                    np.array([[[-0.01, 0, 0], [0.01, 0, 0]]], np.float32),
                    self.color,
                    thickness=9.0,
                    thickness_units="screen",
                    visible=self._visible,
                ),
                self._segments,
            )
        if self.ring:
            a = np.linspace(0.0, 2.0 * np.pi, RING_POINTS + 1)
            circle = np.column_stack([np.cos(a), np.sin(a)])
            self._lines("ring", polyline_segments(circle, 0.0), self.color, 1.5)
            self._show("ring", False)  # placed and shown by draw
        self._show("line", track is not None)
        self._show("pose", track is not None)
        self._show("marker", track is not None)

    def set_pose_scale(self, scale: float) -> None:
        """Enlarge the vehicle marker: seen from high above a whole drive, a car-sized marker
        is a dot (the export's overview replay)."""
        h = self._meshes.get("pose")
        if h is not None:
            h.scale = float(scale)

    def draw(self, data: SceneData, t: float) -> None:
        track = self._track(data)
        if track is None:
            return
        xy, yaw = track.pose_at(t)
        h = self._meshes["pose"]
        h.position = (float(xy[0]), float(xy[1]), self.z + 0.3)
        h.wxyz = _yaw_wxyz(yaw)
        self._segments["marker"].position = (float(xy[0]), float(xy[1]), self.z + 0.25)
        if self.ring:
            axes = track.ring_at(t)
            if axes is not None:
                ring = self._segments["ring"]
                ring.position = (float(xy[0]), float(xy[1]), self.z + 0.2)
                ring.wxyz = _yaw_wxyz(axes[2])
                ring.scale = (axes[0], axes[1], 1.0)
            self._show("ring", axes is not None)


class BaselineLayer(TrackLayer):
    key = "baseline"
    label = "baseline trajectory"
    color = BASELINE
    legend = ((BASELINE, "baseline: GNSS/INS/odometer, dead reckoning in outages"),)
    z = 0.1
    ring = True

    def _track(self, data: SceneData) -> Track | None:
        return data.baseline


class ProposedLayer(TrackLayer):
    key = "proposed"
    label = "proposed trajectory"
    color = PROPOSED
    legend = (
        (PROPOSED, "proposed: with the route matches"),
        (PROPOSED, "ring round a vehicle: 95 % of where its run says it is"),
    )
    z = 0.2
    ring = True

    def _track(self, data: SceneData) -> Track | None:
        return data.proposed


class TruthLayer(TrackLayer):
    key = "truth"
    label = "ground truth"
    color = TRUTH
    legend = ((TRUTH, "ground truth (when the log has it)"),)
    z = 0.15
    length_m = 5.0

    def _track(self, data: SceneData) -> Track | None:
        return data.truth


class VerdictLayer(Layer):
    """Every match attempt marked at its DR position, green accepted, red rejected."""

    key = "verdicts"
    label = "match verdicts"
    legend = ((ACCEPTED, "match accepted"), (REJECTED, "match refused"))

    def set_data(self, data: SceneData) -> None:
        ok = np.all(np.isfinite(data.match_xy), axis=1) if len(data.match_xy) else np.zeros(0, bool)
        colors = np.where(data.match_accepted[ok, None], ACCEPTED, REJECTED).astype(np.uint8)
        self._dots("markers", data.match_xy[ok], colors, 5.0, z=0.45)
        self._show("markers", bool(ok.any()))


class MatchLayer(Layer):
    """The current attempt: local route segment, DR window, aligned window R s + t, point
    pairs, p_dr -> pseudo-position, and a label with its verdict."""

    key = "match"
    label = "current match attempt"
    legend = (
        (SEGMENT, "route segment matched"),
        (MAP_SEGMENT, "that segment where the map draws it (with extensions.map_bias)"),
        (DR_WINDOW, "DR window (dead-reckoned track)"),
        (ALIGNED, "DR window aligned onto the route"),
        (PAIRS, "point pairs"),
        (PSEUDO, "DR position -> pseudo-position"),
    )
    _parts = (
        "segment",
        "map_segment",
        "window",
        "aligned",
        "pairs",
        "route_points",
        "correction",
        "pseudo",
        "label",
    )

    def __init__(self, scene: viser.SceneApi, *, root: str = "/routefuse") -> None:
        super().__init__(scene, root=root)
        self._shown: int | None = -1
        self._data_id: int | None = None

    def set_data(self, data: SceneData) -> None:
        self._shown = -1
        self._data_id = id(data)

    def draw(self, data: SceneData, t: float) -> None:
        i = data.match_index_at(t, max_age_s=MATCH_MAX_AGE_S)
        if i == self._shown and self._data_id == id(data):
            return
        self._shown, self._data_id = i, id(data)
        if i is None:
            for name in self._handles:
                self._show(name, False)
            return
        self.draw_match(data.matches[i])

    def draw_match(self, m: MatchRecord) -> None:
        win = np.asarray(m.window_dr, np.float64).reshape(-1, 2)
        route_pts = np.asarray(m.route_points, np.float64).reshape(-1, 2)
        seg = np.asarray(m.route_segment, np.float64).reshape(-1, 2)
        self._lines("segment", polyline_segments(seg, 0.02), SEGMENT, 7.0)
        map_seg = np.zeros((0, 2))
        if m.map_bias is not None and np.all(np.isfinite(m.map_bias.offset)) and len(seg):
            map_seg = seg + m.map_bias.at(seg)
        self._lines("map_segment", polyline_segments(map_seg, 0.01), MAP_SEGMENT, 3.0)
        self._lines("window", polyline_segments(win, 0.3), DR_WINDOW, 3.0)
        aligned = np.zeros((0, 2))
        c, s = np.cos(m.rotation_rad), np.sin(m.rotation_rad)
        tr = np.asarray(m.translation, np.float64).reshape(-1)
        if (
            len(win)
            and np.isfinite(m.rotation_rad)
            and tr.shape == (2,)
            and np.all(np.isfinite(tr))
        ):
            aligned = win @ np.array([[c, s], [-s, c]]) + tr
        self._lines("aligned", polyline_segments(aligned, 0.35), ALIGNED, 3.0)
        n = min(len(win), len(route_pts))
        pair_seg = np.zeros((0, 2, 3), np.float32)
        if n:
            a = _points3(win[:n], 0.25)
            b = _points3(route_pts[:n], 0.25)
            ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
            pair_seg = np.stack([a[ok], b[ok]], axis=1)
        self._lines("pairs", pair_seg, PAIRS, 1.0)
        self._cloud("route_points", _points3(route_pts, 0.3), SEGMENT, 0.8)
        p_dr = np.asarray(m.p_dr, np.float64).reshape(-1)
        z = np.asarray(m.pseudo_position, np.float64).reshape(-1)
        has_z = z.shape == (2,) and np.all(np.isfinite(z)) and np.all(np.isfinite(p_dr))
        corr = (
            np.array([[[p_dr[0], p_dr[1], 0.5], [z[0], z[1], 0.5]]], np.float32)
            if has_z
            else np.zeros((0, 2, 3), np.float32)
        )
        self._lines("correction", corr, PSEUDO, 3.0)
        self._cloud("pseudo", _points3(z if has_z else np.zeros((0, 2)), 0.5), PSEUDO, 2.0)
        anchor = p_dr if np.all(np.isfinite(p_dr)) else (win[-1] if len(win) else np.zeros(2))
        text = f"#{m.index} {m.verdict}"
        position = (float(anchor[0]), float(anchor[1]), 1.0)
        h = self._labels.get("label")
        if h is None:
            self._keep(
                "label",
                self.scene.add_label(
                    f"{self.root}/label",
                    text,
                    position=position,
                    anchor="bottom-left",
                    visible=self._visible,
                ),
                self._labels,
            )
        else:
            h.text = text
            h.position = position
        shown = {
            "segment": len(seg) > 1,
            "map_segment": len(map_seg) > 1,
            "window": len(win) > 1,
            "aligned": len(aligned) > 1,
            "pairs": len(pair_seg) > 0,
            "route_points": len(route_pts) > 0,
            "correction": bool(has_z),
            "pseudo": bool(has_z),
            "label": True,
        }
        for name, on in shown.items():
            self._show(name, on)


class ExitLayer(Layer):
    """Where each outage's estimate ended against the fixes that came back after it (the exit
    check): at the first fix compared, a line from where the estimate had the vehicle to where
    the fixes put it (their median offset), dark within the sigmas the estimate claimed and red
    beyond them, the red ones labelled with their distance and sigmas."""

    key = "exits"
    label = "outage exits"
    legend = (
        (EXIT_WITHIN, "outage exit: the estimate -> the fixes after it"),
        (EXIT_BEYOND, "outage exit beyond the sigmas the estimate claimed"),
    )
    z: ClassVar[float] = 0.5

    def set_data(self, data: SceneData) -> None:
        for flagged, color in ((False, EXIT_WITHIN), (True, EXIT_BEYOND)):
            exits = [x for x in data.exits if x.overconfident == flagged]
            name = "beyond" if flagged else "within"
            ends = np.array([[x.estimate_at, x.estimate_at - x.error] for x in exits])
            ends = ends.reshape(-1, 2, 2)
            seg = np.concatenate([ends, np.full((len(ends), 2, 1), self.z)], axis=2)
            self._lines(name, seg, color, 5.0)
            self._dots(f"{name}_fixes", ends[:, 1], np.tile(color, (len(ends), 1)), 9.0, self.z)
            self._show(name, len(exits) > 0)
            self._show(f"{name}_fixes", len(exits) > 0)
        for name in [n for n in self._labels if n.startswith("exit_")]:
            self._labels.pop(name).remove()
            del self._handles[name]
            self._wanted.pop(name, None)
        for i, x in enumerate(e for e in data.exits if e.overconfident):
            name = f"exit_{i}"
            text = f"exit {x.distance_m:.1f} m, {math.sqrt(x.chi2):.1f} sigma"
            position = (*(x.estimate_at - x.error / 2), self.z)
            label = self.scene.add_label(
                f"{self.root}/{name}", text, position=position, visible=self._visible
            )
            self._keep(name, label, self._labels)


LAYER_TYPES: tuple[type[Layer], ...] = (
    RouteLayer,
    GnssLayer,
    TruthLayer,
    BaselineLayer,
    ProposedLayer,
    VerdictLayer,
    ExitLayer,
    MatchLayer,
)


def legend_entries() -> tuple[tuple[RGB, str], ...]:
    """Every colour on the map and what it marks, in the layers' order."""
    return tuple(entry for cls in LAYER_TYPES for entry in cls.legend)


def legend_html(entries: tuple[tuple[RGB, str], ...], *, separator: str = " ") -> str:
    """Colour swatches with their meaning as inline HTML (viser's markdown renders it; the
    export's pages embed it), every label escaped."""
    return separator.join(
        f'<span style="white-space:nowrap"><span style="color:rgb{rgb}">&#9632;</span> '
        f"{html.escape(text)}</span>"
        for rgb, text in entries
    )


class SceneLayers:
    """All layers of one scene, drawn together."""

    def __init__(self, scene: viser.SceneApi, *, root: str = "/routefuse") -> None:
        self.layers: dict[str, Layer] = {cls.key: cls(scene, root=root) for cls in LAYER_TYPES}
        self.data: SceneData | None = None

    def set_data(self, data: SceneData) -> None:
        self.data = data
        for layer in self.layers.values():
            layer.set_data(data)

    def draw(self, t: float) -> None:
        if self.data is None:
            return
        for layer in self.layers.values():
            layer.draw(self.data, t)

    def set_visible(self, key: str, on: bool) -> None:
        self.layers[key].visible = on

    def remove(self) -> None:
        for layer in self.layers.values():
            layer.remove()
