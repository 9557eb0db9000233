"""One browser tab: its panels, its scene layers, its own playhead and camera.

Each tab keeps its own time, playback, camera and layer toggles (on ``client.gui`` /
``client.scene``), so several tabs never disturb each other. What is shared - the loaded files,
the parameters and the runs - lives in the controller; a tab changes it only through requests,
and every tab redraws when a new session is published. Scrubbing and stepping only index into
the session's precomputed arrays.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from estimator.errors import RoutefuseError
from inspector.app.compare import ComparePanel
from inspector.app.files import FilesPanel
from inspector.app.match import MatchPanel
from inspector.app.parameters import ParametersPanel
from inspector.app.playback import PlaybackPanel
from inspector.app.plots import PlotsPanel
from inspector.app.widgets import Event
from inspector.controller import Playhead, Session
from inspector.layers import LAYER_TYPES, SceneLayers, legend_entries, legend_html
from inspector.scene_data import SceneData

if TYPE_CHECKING:
    from inspector.app.application import InspectorApp

PANEL_PX = 400.0
"""width of viser's control panel (large), which hides the right of the 3D view"""
NO_MORE = {
    "previous": "no earlier match attempt",
    "next": "no later match attempt",
    "rejected": "no later rejected attempt",
    "previous rejected": "no earlier rejected attempt",
}
"""what a jump says when there is no attempt to go to"""
FOCUS_HEIGHT_M = 600.0
"""camera height over the attempt a tab opens at: the window and its route segment in view"""
MAX_NOTE = 300
"""characters of a notification (a refused value may be any size)"""


class ClientView:
    """One browser tab: the panels it composes, its scene layers and its playhead."""

    def __init__(self, app: InspectorApp, client: viser.ClientHandle) -> None:
        self.app = app
        self.client = client
        self.playhead = Playhead()
        self.session: Session | None = None
        self.follow = False
        self._lock = threading.RLock()
        self._camera_placed = False
        self.layers = SceneLayers(client.scene)
        self._camera_pending = False
        self._focus: tuple[np.ndarray, float] | None = None
        """where the camera first looks (the first refused attempt), else the whole drive"""
        client.camera.on_update(self._on_camera)
        self._build()

    def _build(self) -> None:
        gui = self.client.gui
        gui.configure_theme(control_width="large", show_share_button=False)
        self.playback = PlaybackPanel(self, gui)
        with gui.add_folder("Legend", expand_by_default=True):
            self.legend = gui.add_markdown(
                f"<small>{legend_html(legend_entries(), separator=' &nbsp; ')}</small>"
            )
        tabs = gui.add_tab_group()
        with tabs.add_tab("Match"):
            self.match = MatchPanel(gui)
        self.plots = PlotsPanel(gui, tabs.add_tab("Plots"))
        with tabs.add_tab("Compare"):
            self.compare = ComparePanel(self, gui)
        with tabs.add_tab("Layers"):
            self.layer_boxes: dict[str, viser.GuiCheckboxHandle] = {}
            for cls in LAYER_TYPES:
                box = gui.add_checkbox(cls.label, True)
                box.on_update(self._layer_toggler(cls.key))
                self.layer_boxes[cls.key] = box
                gui.add_markdown(f"<small>{legend_html(cls.legend, separator='<br>')}</small>")
        with tabs.add_tab("Parameters"):
            self.parameters = ParametersPanel(self, gui, lock=self._lock)
        with tabs.add_tab("Files"):
            self.files = FilesPanel(self, gui)
        self.playback.add_hotkeys(gui)

    @property
    def log_choice(self) -> viser.GuiDropdownHandle[str]:
        return self.files.log_choice

    @property
    def route_choice(self) -> viser.GuiDropdownHandle[str]:
        return self.files.route_choice

    # -- callbacks (thread pool) ----------------------------------------------------------

    def notify_error(self, exc: Exception, title: str = "Error") -> None:
        text = str(exc)
        text = text if len(text) <= MAX_NOTE else text[: MAX_NOTE - 1] + "…"
        self.client.add_notification(title, text, color="red", auto_close_seconds=12.0)

    def guard(self, fn: Callable[[], Any]) -> None:
        """Run a request; a refused one is shown, and the panels show what is in effect."""
        try:
            fn()
        except RoutefuseError as exc:
            self.notify_error(exc)
            self.sync_params()

    def _on_camera(self, _: viser.CameraHandle) -> None:
        if self._camera_pending:
            with self._lock:
                self.place_camera()

    def _layer_toggler(self, key: str) -> Callable[[Event], None]:
        def toggle(event: Event) -> None:
            with self._lock:
                self.layers.set_visible(key, bool(self.layer_boxes[key].value))

        return toggle

    # -- actions --------------------------------------------------------------------------

    def seek(self, t: float) -> None:
        with self._lock:
            if self.session is None:
                return
            self.playhead.t = self.session.timeline.clamp(t)
            self.render()

    def step(self, frames: int) -> None:
        with self._lock:
            if self.session is None:
                return
            self.playhead.playing = False
            self.playhead.t = self.session.timeline.step(self.playhead.t, frames)
            self.render()

    def jump(self, which: str) -> None:
        """Go to the previous / next match attempt, or the previous / next rejected one."""
        with self._lock:
            s = self.session
            if s is None:
                return
            tl = s.timeline
            if which.startswith("previous"):
                i = tl.previous_match(self.playhead.t, rejected_only=which.endswith("rejected"))
            else:
                i = tl.next_match(self.playhead.t, rejected_only=which == "rejected")
            if i is None:
                self.client.add_notification(
                    "Nothing there", NO_MORE[which], auto_close_seconds=4.0
                )
                return
            self.playhead.playing = False
            self.playhead.t = float(tl.match_t[i])
            self.render()

    def toggle_play(self) -> None:
        with self._lock:
            if self.session is None:
                return
            ph = self.playhead
            if not ph.playing and ph.t >= self.session.timeline.duration:
                ph.t = 0.0
            ph.playing = not ph.playing
            self.playback.show_playing(ph.playing)

    def tick(self, wall_dt: float) -> None:
        with self._lock:
            if self.session is None or not self.playhead.playing:
                return
            self.playhead.advance(self.session.timeline, wall_dt)
            if not self.playhead.playing:
                self.playback.show_playing(False)
            self.render()

    # -- camera ---------------------------------------------------------------------------

    def place_camera(self) -> None:
        """Top-down over the whole drive (or over the vehicle when following); the first
        placement of a tab looks at the attempt it opened at (:meth:`_open_at_the_story`), once:
        **top-down view** afterwards shows the whole drive, also of a log opened later."""
        s = self.session
        if s is None:
            return
        data = s.scene
        cam = self.client.camera
        if self.follow:
            xy, _ = data.proposed.pose_at(self.playhead.t + data.t0)
            center, height = np.asarray(xy, float), 250.0
        elif self._focus is not None:
            center, height = self._focus
        else:
            center = data.center
            height = data.extent_m * 0.6
        if cam.update_timestamp == 0.0:
            self._camera_pending = True  # the browser has not reported its camera yet
            return
        self._camera_pending = False
        focused, self._focus = self._focus is not None, None
        # The control panel covers the right of the view: fit the drive into the rest and
        # shift the view east so it is centred there (top-down, north up: screen x = east).
        aspect, free, half_h = self._view_geometry()
        if not self.follow and not focused:
            # the drive's extent across the free width, and up the view's height (a drive
            # running north-south ran off the top and bottom of a wide window)
            across = data.extent_m * 0.55 / (half_h * aspect * free)
            height = max(height, across, data.extent_m * 0.55 / half_h)
        center = np.asarray(center, float) + self._panel_shift(height)[:2]
        cam.far = max(10 * height, 1000.0)
        cam.near = max(height / 100, 0.05)  # depth precision for layers 5 cm apart
        cam.up_direction = (0.0, 0.0, 1.0)
        # position first: assigning it drags look_at along, so look_at is set after.
        cam.position = (float(center[0]), float(center[1]) - 0.001 * height, float(height))
        cam.look_at = (float(center[0]), float(center[1]), 0.0)

    def _view_geometry(self) -> tuple[float, float, float]:
        """Aspect ratio, fraction of the width not under the panel, tan(fov / 2)."""
        cam = self.client.camera
        aspect = float(cam.aspect) if np.isfinite(cam.aspect) and cam.aspect > 0 else 1.5
        width_px = float(cam.image_width) or 1400.0
        return aspect, max(1.0 - PANEL_PX / width_px, 0.4), float(np.tan(cam.fov / 2))

    def _panel_shift(self, height: float) -> np.ndarray:
        """How far east to look so what is below the camera sits mid-way in the free part."""
        aspect, free, half_h = self._view_geometry()
        return np.array([height * half_h * aspect * (1.0 - free), 0.0, 0.0])

    # -- drawing --------------------------------------------------------------------------

    def _follow(self, data: SceneData, t: float) -> None:
        xy, _ = data.proposed.pose_at(t + data.t0)
        cam = self.client.camera
        offset = np.asarray(cam.position) - np.asarray(cam.look_at)
        target = np.array([xy[0], xy[1], 0.0]) + self._panel_shift(float(np.linalg.norm(offset)))
        # position first: assigning it drags look_at along by the same move.
        cam.position = tuple(target + offset)
        cam.look_at = tuple(target)

    # -- drawing --------------------------------------------------------------------------

    def set_session(self, session: Session) -> None:
        """A new session: redraw everything, keeping this tab's time and camera; a session of
        another log (opened from the Files tab) opens as the first does, at its first refused
        attempt with the camera on it (the previous drive's time and view mean nothing in it:
        the map was left blank, looking where the previous drive was)."""
        with self._lock:
            first = self.session is None or self.session.log_path != session.log_path
            self.session = session
            with self.client.atomic():
                self.layers.set_data(session.scene)
                self.playback.show_session(session)
                self.plots.show_session(session, self.playhead.t)
                self.parameters.sync()
                self.files.show_session(session)
            self.playhead.t = session.timeline.clamp(self.playhead.t)
            if first:
                self._open_at_the_story(session)
            self.match.forget()
            if first or not self._camera_placed:
                self.place_camera()
                self._camera_placed = True
            self.render()

    def _open_at_the_story(self, session: Session) -> None:
        """A tab's first session opens at its first refused attempt (else its first attempt),
        zoomed to it with the Match tab filled: where a user debugging matches starts."""
        tl = session.timeline
        i = tl.next_match(-math.inf, rejected_only=True)
        if i is None:
            i = tl.next_match(-math.inf)
        if i is None:
            return
        self.playhead.t = float(tl.match_t[i])
        xy = np.asarray(session.scene.match_xy[i], float)
        if np.all(np.isfinite(xy)):
            self._focus = (xy, FOCUS_HEIGHT_M)

    def sync_params(self) -> None:
        """Show the controller's parameters (after another tab changed them, or a failure)."""
        self.parameters.sync()

    def render(self) -> None:
        """Draw the current time: layers, labels, panel, plot markers, camera."""
        s = self.session
        if s is None:
            return
        t = self.playhead.t
        with self.client.atomic():
            self.layers.draw(t + s.scene.t0)
            self.playback.show_time(s, t)
            self.match.show(s, t)
            self.plots.show_time(s, t)
            self.compare.show(s, t)
            if self.follow:
                self._follow(s.scene, t)

    def set_progress(self, fraction: float, message: str) -> None:
        self.playback.set_progress(fraction, message, self.session)

    def refresh_files(self) -> None:
        self.files.refresh()

    def close(self) -> None:
        self.playback.close()
        with self._lock:
            self.playhead.playing = False
        self.parameters.close()
