"""The viser app: one :class:`ClientView` per browser tab over one shared :class:`Controller`.

Each tab keeps its own time, playback, camera and layer toggles (on ``client.gui`` /
``client.scene``), so several tabs never disturb each other. What is shared - the loaded files,
the parameters and the runs - lives in the controller; a tab changes it only through requests,
and every tab redraws when a new session is published. Scrubbing and stepping only index into
the session's precomputed arrays.
"""

from __future__ import annotations

import contextlib
import threading
import time
import traceback
from collections.abc import Awaitable, Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np
import viser
from viser import _messages

from estimator.errors import RoutefuseError
from estimator.params import ParamSpec, get_param, param_specs, params_to_toml
from estimator.results import GateDecision, MatchRecord
from inspector.controller import Controller, Playhead, Session, format_outages, parse_outages
from inspector.layers import LAYER_TYPES, SceneLayers
from inspector.plots import metrics_markdown

STEP_BUTTONS = {"« 10": -10, "‹ prev": -1, "next ›": 1, "10 »": 10}
"""the frame step buttons and how many output frames each moves"""
MATCH_BUTTONS = {
    "‹ attempt": "previous",
    "attempt ›": "next",
    "‹ rejected": "previous rejected",
    "rejected ›": "rejected",
}
"""the match navigation buttons and the :meth:`ClientView.jump` each makes"""
SPEEDS = ("0.25x", "0.5x", "1x", "2x", "5x", "10x", "20x", "50x")
PLAY_RATE_HZ = 15.0
PANEL_PX = 400.0
"""width of viser's control panel (large), which hides the right of the 3D view"""
GROUP_TITLES = {
    "trigger": "trigger",
    "window": "window",
    "gates": "gates",
    "pseudo": "pseudo-observation",
    "offset": "offset compensation",
    "extensions": "extensions",
    "noise": "noise",
    "sensors": "sensors",
    "general": "general",
}
_NONE = "(none)"
OUTAGE_LABEL = "GNSS outages (s)"
OUTAGE_EDIT_QUIET_S = 1.0
"""the outage field applies its text once typing has rested this long: viser sends every
keystroke, and '3', '30', '30:' on the way to '30:60' are not outages the user meant"""


def _fmt(v: Any, digits: int = 3) -> str:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not np.isfinite(f):
        return "–"
    return f"{f:.{digits}f}" if abs(f) < 1e5 else f"{f:.3g}"


def _gate_value(g: GateDecision) -> str:
    """The matcher caps an alternative's margin at 1e9 when no rival fits the shape gates:
    that means 'no rival', not a number to read."""
    if g.name.startswith("alternative_") and g.value >= 1e9:
        return "no rival"
    return _fmt(g.value)


def _vec(v: Any, digits: int = 2) -> str:
    a = np.asarray(v, np.float64).reshape(-1)
    if a.size == 0 or not np.all(np.isfinite(a)):
        return "–"
    return "(" + ", ".join(f"{x:.{digits}f}" for x in a) + ")"


def match_markdown(
    m: MatchRecord | None, *, t_rel: float | None = None, age_s: float = 0.0, total: int = 0
) -> str:
    """The match panel: every gate with value, threshold and verdict, then the fit."""
    if m is None:
        return "*No match attempt before this time.*"
    head = "ACCEPTED" if m.accepted else "REJECTED"
    when = f" at t = {t_rel:.2f} s" if t_rel is not None else ""
    age = f" ({age_s:.2f} s ago)" if age_s > 0.005 else ""
    lines = [
        f"**Attempt #{m.index} of {total}{when}{age}: {head}**",
        "",
        "| gate | value | limit | verdict |",
        "|---|---:|---:|---|",
    ]
    notes = []
    for g in m.gates:
        verdict = "✓ passed" if g.passed else "✗ **FAILED**"
        lines.append(
            f"| {g.name} | {_gate_value(g)} | {g.comparison} {_fmt(g.threshold)} | {verdict} |"
        )
        if g.note:
            notes.append(f"*{g.name}*: {g.note}")
    corr = np.asarray(m.correction, np.float64).reshape(-1)
    corr_norm = float(np.hypot(*corr)) if corr.size == 2 and np.all(np.isfinite(corr)) else np.nan
    cov = np.asarray(m.obs_cov, np.float64)
    sig = np.sqrt(np.clip(np.diag(cov), 0, None)) if cov.shape == (2, 2) else np.full(2, np.nan)
    lines += [
        "",
        "| fit | |",
        "|---|---:|",
        f"| rotation | {_fmt(np.degrees(m.rotation_rad))} deg |",
        f"| translation E, N | {_vec(m.translation)} m |",
        f"| residual (RMS) | {_fmt(m.residual_m)} m |",
        f"| pairs | {m.n_pairs} |",
        f"| heading cos | {_fmt(m.heading_cos, 4)} |",
        f"| route arc length | {_fmt(m.route_s[0], 1)} – {_fmt(m.route_s[1], 1)} m |",
        f"| lane offset | {_fmt(m.lane_offset_m, 2)} m |",
        f"| p_dr → z | {_vec(m.p_dr)} → {_vec(m.pseudo_position)} |",
        f"| innovation E, N | {_vec(m.innovation)} m |",
        f"| correction E, N | {_vec(m.correction)} m (\\|c\\| = {_fmt(corr_norm, 2)} m) |",
        f"| obs. 1-sigma E, N | {_vec(sig)} m |",
    ]
    lines += [f"| {k} | {_fmt(v)} |" for k, v in sorted(m.extra.items())]
    if notes:
        lines += ["", "<small>" + "; ".join(notes) + "</small>"]
    return "\n".join(lines)


def status_markdown(s: Session) -> str:
    """The status line of a session: files, length, attempts, and the off-route summary."""
    tl = s.timeline
    text = (
        f"**{s.log_name}** · route **{s.route_name}** · {tl.duration:.0f} s, "
        f"{tl.n_frames} frames, {len(tl.match_t)} match attempts "
        f"({int((~tl.match_accepted).sum())} rejected)"
    )
    if s.outages:
        text += f" · GNSS removed {format_outages(s.outages)} s"
    off = s.off_route.summary() if s.off_route is not None else ""
    return f"{text} · {off}" if off else text


def _report_failure(done: Future[None]) -> None:
    """Print what a click's action raised (it runs on a worker thread nobody waits on)."""
    exc = None if done.cancelled() else done.exception()
    if exc is not None:
        traceback.print_exception(exc)


class ClientView:
    """One browser tab: its GUI, its scene layers and its own playhead."""

    def __init__(self, app: InspectorApp, client: viser.ClientHandle) -> None:
        self.app = app
        self.client = client
        self.playhead = Playhead()
        self.session: Session | None = None
        self.follow = False
        self._lock = threading.RLock()
        self._shown_match: tuple[int, int | None] | None = None
        self._plot_t: float | None = None
        self._param_widgets: dict[str, viser.GuiInputHandle[Any]] = {}
        self._outage_edits = 0
        self._outage_timer: threading.Timer | None = None
        self._camera_placed = False
        self.layers = SceneLayers(client.scene)
        self._camera_pending = False
        self._clicks = ThreadPoolExecutor(1, thread_name_prefix="routefuse-clicks")
        client.camera.on_update(self._on_camera)
        self._build()

    # -- GUI ------------------------------------------------------------------------------

    def _build(self) -> None:
        gui = self.client.gui
        gui.configure_theme(control_width="large", show_share_button=False)
        self.status = gui.add_markdown("**routefuse inspector** · nothing loaded yet")
        self.progress = gui.add_progress_bar(0.0, visible=False, animated=True)
        self.frame_label = gui.add_markdown("frame – / –")
        self.time_slider = gui.add_slider(
            "time [s]", min=0.0, max=1.0, step=0.05, initial_value=0.0
        )
        self.time_slider.on_update(self._on_slider)
        self.step_buttons = gui.add_button_group("frame", tuple(STEP_BUTTONS))
        self.step_buttons.on_click(
            self._pressed(
                self.step_buttons,
                {label: (lambda n=n: self.step(n)) for label, n in STEP_BUTTONS.items()},
            )
        )
        self.match_buttons = gui.add_button_group("match", tuple(MATCH_BUTTONS))
        self.match_buttons.on_click(
            self._pressed(
                self.match_buttons,
                {label: (lambda w=w: self.jump(w)) for label, w in MATCH_BUTTONS.items()},
            )
        )
        self.play_button = gui.add_button("play", hint="play / pause (space)")
        self.play_button.on_click(lambda _: self.toggle_play())
        self.speed = gui.add_dropdown("speed", SPEEDS, initial_value="5x")
        self.speed.on_update(self._on_speed)
        self.playhead.speed = 5.0
        self.follow_box = gui.add_checkbox("follow vehicle", False)
        self.follow_box.on_update(self._on_follow)
        self.view_button = gui.add_button("top-down view")
        self.view_button.on_click(lambda _: self.place_camera())
        gui.add_markdown(
            "<small>keys: ← → frame · ↑ ↓ ten frames · space play · N / P next / previous "
            "attempt · R / E next / previous rejected</small>"
        )

        tabs = gui.add_tab_group()
        with tabs.add_tab("Match"):
            self.match_panel = gui.add_markdown(match_markdown(None))
        self.plots_tab = tabs.add_tab("Plots")
        self.plots: dict[str, viser.GuiUplotHandle] = {}  # added with the first session
        with self.plots_tab:
            self.metrics = gui.add_markdown("")
        with tabs.add_tab("Layers"):
            self.layer_boxes = {}
            for cls in LAYER_TYPES:
                box = gui.add_checkbox(cls.label, True)
                box.on_update(self._layer_toggler(cls.key))
                self.layer_boxes[cls.key] = box
        with tabs.add_tab("Parameters"):
            self.method = gui.add_dropdown(
                "method", ("proposed", "paper"), initial_value=self.app.controller.method
            )
            self.method.on_update(self._on_method)
            self.outage_field = gui.add_text(
                OUTAGE_LABEL,
                format_outages(self.app.controller.outages),
                hint="remove GNSS between START and END seconds after the log start, as "
                "'routefuse run --outage START:END': e.g. 30:60, 90:120 (empty: none). "
                "Applied when you stop typing; opening another log clears them.",
            )
            self.outage_field.on_update(self._on_outages)
            reset = gui.add_button("reset to defaults")
            reset.on_click(lambda e: self._guard(self.app.controller.reset_params))
            save = gui.add_button("save parameters")
            save.on_click(self._on_save)
            self._build_params()
        with tabs.add_tab("Files"):
            self._build_files()
        self._build_commands()

    def _build_params(self) -> None:
        gui = self.client.gui
        groups: dict[str, list[ParamSpec]] = {}
        for spec in param_specs():
            groups.setdefault(spec.group, []).append(spec)
        params = self.app.controller.params
        for group, specs in groups.items():
            with gui.add_folder(
                GROUP_TITLES.get(group, group),
                expand_by_default=group in ("trigger", "window", "gates"),
            ):
                for spec in specs:
                    widget = self._param_widget(spec, get_param(params, spec.name))
                    widget.on_update(self._param_setter(spec.name))
                    self._param_widgets[spec.name] = widget

    def _param_widget(self, spec: ParamSpec, value: Any) -> viser.GuiInputHandle[Any]:
        gui = self.client.gui
        label = spec.name.rsplit(".", 1)[-1]
        hint = spec.doc + (f" [{spec.unit}]" if spec.unit else "")
        if spec.type is bool:
            return gui.add_checkbox(label, bool(value), hint=hint)
        if spec.choices:
            return gui.add_dropdown(label, spec.choices, initial_value=value, hint=hint)
        if str(spec.type).startswith("tuple"):
            return gui.add_vector3(label, tuple(value), step=0.01, hint=hint)
        if spec.type in (int, float) and spec.lo is not None and spec.hi is not None:
            step = spec.step or (1 if spec.type is int else (spec.hi - spec.lo) / 100)
            if (spec.hi - spec.lo) / step <= 2000:
                if spec.type is int:
                    return gui.add_slider(
                        label, int(spec.lo), int(spec.hi), int(step), int(value), hint=hint
                    )
                return gui.add_slider(
                    label, float(spec.lo), float(spec.hi), float(step), float(value), hint=hint
                )
            return gui.add_number(label, value, min=spec.lo, max=spec.hi, step=step, hint=hint)
        return gui.add_text(label, "" if value is None else str(value), hint=hint)

    def _build_files(self) -> None:
        gui = self.client.gui
        listing = self.app.controller.folders.listing()
        logs = tuple(listing.logs) or (_NONE,)
        routes = tuple(listing.routes) or (_NONE,)
        self.log_choice = gui.add_dropdown("log", logs, initial_value=logs[0])
        self.log_choice.on_update(self._on_log_choice)
        self.route_choice = gui.add_dropdown("route file", routes, initial_value=routes[0])
        self.open_button = gui.add_button("open", hint="load the chosen log and route")
        self.open_button.on_click(self._on_open)
        refresh = gui.add_button("refresh list")
        refresh.on_click(lambda _: self.refresh_files())
        uploads = self.app.controller.uploads
        if uploads is not None:
            limit = f"up to {uploads.max_bytes / 1e6:.0f} MB"
            self.upload_log = gui.add_upload_button("upload log", hint=f".mcap or .bag, {limit}")
            self.upload_log.on_upload(self._uploader("log"))
            self.upload_route = gui.add_upload_button(
                "upload route", hint=f".geojson, .gpx, .kml or .csv, {limit}"
            )
            self.upload_route.on_upload(self._uploader("route"))
            self._refuse_large_uploads(uploads.max_bytes)
        folders = "\n".join(f"- `{r}`" for r in self.app.controller.folders.roots)
        gui.add_markdown(f"Files are listed from:\n{folders}")

    def _refuse_large_uploads(self, max_bytes: int) -> None:
        """Drop an oversized upload when it starts, before its parts are buffered in memory.

        viser has no public size limit; its transfer state for this tab is dropped right after
        viser creates it, so the parts that follow are ignored."""
        gui = self.client.gui
        states = getattr(gui, "_current_file_upload_states", None)
        interface = getattr(gui, "_websock_interface", None)
        if states is None or interface is None:
            return

        def check(_client_id: Any, message: _messages.FileTransferStartUpload) -> None:
            if message.size_bytes > max_bytes:
                states.pop(message.transfer_uuid, None)
                try:
                    self.app.controller.uploads.check_size(message.filename, message.size_bytes)
                except RoutefuseError as exc:
                    self.notify_error(exc, "Upload rejected")

        interface.register_handler(_messages.FileTransferStartUpload, check)

    def _build_commands(self) -> None:
        gui = self.client.gui
        binds: list[tuple[str, Any, Callable[[], None]]] = [
            ("next frame", "arrowright", lambda: self.step(1)),
            ("previous frame", "arrowleft", lambda: self.step(-1)),
            ("forward 10 frames", "arrowup", lambda: self.step(10)),
            ("back 10 frames", "arrowdown", lambda: self.step(-10)),
            ("play / pause", "space", self.toggle_play),
            ("next match attempt", "N", lambda: self.jump("next")),
            ("previous match attempt", "P", lambda: self.jump("previous")),
            ("next rejected attempt", "R", lambda: self.jump("rejected")),
            ("previous rejected attempt", "E", lambda: self.jump("previous rejected")),
        ]
        for label, key, fn in binds:
            cmd = gui.add_command(label, hotkey=key)
            cmd.on_trigger(lambda _e, fn=fn: fn())

    # -- callbacks (thread pool) ----------------------------------------------------------

    def notify_error(self, exc: Exception, title: str = "Error") -> None:
        self.client.add_notification(title, str(exc), color="red", auto_close_seconds=12.0)

    def _guard(self, fn: Callable[[], Any]) -> None:
        try:
            fn()
        except RoutefuseError as exc:
            self.notify_error(exc)
            self.sync_params()

    def _on_slider(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.seek(float(self.time_slider.value))

    def _pressed(
        self, group: viser.GuiButtonGroupHandle, actions: dict[str, Callable[[], None]]
    ) -> Callable[[viser.GuiEvent], Awaitable[None]]:
        """A button group's click handler that reads which button was pressed as the click
        arrives.

        viser stores the pressed label on the shared handle, then runs plain callbacks on its
        thread pool: two quick clicks ("next ›", "10 »") could both be read as the second. A
        coroutine runs on the event loop before the next message is handled; the action itself
        goes to this tab's one worker thread, so clicks are applied once each, in order.
        """

        async def on_click(event: viser.GuiEvent) -> None:
            action = actions.get(group.value)
            if action is None:
                return
            with contextlib.suppress(RuntimeError):  # raised once the tab has closed
                self._clicks.submit(action).add_done_callback(_report_failure)

        return on_click

    def _on_speed(self, event: viser.GuiEvent) -> None:
        self.playhead.speed = float(self.speed.value.rstrip("x"))

    def _on_follow(self, event: viser.GuiEvent) -> None:
        self.follow = bool(self.follow_box.value)
        if self.follow:
            self.place_camera()

    def _on_camera(self, _: viser.CameraHandle) -> None:
        if self._camera_pending:
            with self._lock:
                self.place_camera()

    def _layer_toggler(self, key: str) -> Callable[[viser.GuiEvent], None]:
        def toggle(event: viser.GuiEvent) -> None:
            with self._lock:
                self.layers.set_visible(key, bool(self.layer_boxes[key].value))

        return toggle

    def _param_setter(self, name: str) -> Callable[[viser.GuiEvent], None]:
        def set_value(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            widget = self._param_widgets[name]
            self._guard(lambda: self.app.controller.set_param(name, widget.value))

        return set_value

    def _on_method(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self._guard(lambda: self.app.controller.set_method(self.method.value))

    def _on_outages(self, event: viser.GuiEvent) -> None:
        """Restart the quiet-period timer: the text is applied once the typing rests."""
        if event.client is None:
            return
        with self._lock:
            self._outage_edits += 1
            if self._outage_timer is not None:
                self._outage_timer.cancel()
            timer = threading.Timer(
                OUTAGE_EDIT_QUIET_S, self._commit_outages, args=(self._outage_edits,)
            )
            timer.daemon = True
            self._outage_timer = timer
        timer.start()

    def _commit_outages(self, edit: int) -> None:
        with self._lock:
            if edit != self._outage_edits:
                return  # typed again since
            self._outage_timer = None
            text = str(self.outage_field.value)
        try:
            self.app.controller.set_outages(parse_outages(text))
        except RoutefuseError as exc:
            kept = format_outages(self.app.controller.outages) or "none"
            self.client.add_notification(
                "GNSS outages not changed",
                f"{exc} (kept: {kept})",
                color="red",
                auto_close_seconds=12.0,
            )

    def _on_save(self, event: viser.GuiEvent) -> None:
        text = params_to_toml(self.app.controller.params)
        self.client.send_file_download(
            "routefuse-params.toml", text.encode("utf-8"), save_immediately=True
        )

    def _on_log_choice(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        route = self.app.controller.folders.default_route(self.log_choice.value)
        if route is not None and route in self.route_choice.options:
            self.route_choice.value = route

    def _on_open(self, event: viser.GuiEvent) -> None:
        log, route = self.log_choice.value, self.route_choice.value
        if _NONE in (log, route):
            self.notify_error(RoutefuseError(None, "choose a log and a route first"))
            return
        controller = self.app.controller
        before = controller.outages
        self._guard(lambda: controller.open_named(log, route))
        if before and not controller.outages:
            self.client.add_notification(
                "GNSS outages not carried over",
                f"{log} opens without {format_outages(before)} s: those were times in the "
                "previous log",
                auto_close_seconds=6.0,
            )

    def _uploader(self, kind: str) -> Callable[[viser.GuiEvent], None]:
        def on_upload(event: viser.GuiEvent) -> None:
            handle = self.upload_log if kind == "log" else self.upload_route
            up = handle.value
            try:
                name = self.app.controller.save_upload(up.name, up.content)
            except RoutefuseError as exc:
                self.notify_error(exc, "Upload rejected")
                return
            self.app.refresh_files()
            choice = self.log_choice if kind == "log" else self.route_choice
            if name in choice.options:
                choice.value = name
            self.client.add_notification(
                "Uploaded", f"{name}: press 'open' to load it", auto_close_seconds=6.0
            )

        return on_upload

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
                what = {
                    "previous": "no earlier match attempt",
                    "next": "no later match attempt",
                    "rejected": "no later rejected attempt",
                    "previous rejected": "no earlier rejected attempt",
                }[which]
                self.client.add_notification("Nothing there", what, auto_close_seconds=4.0)
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
            self.play_button.label = "pause" if ph.playing else "play"

    def tick(self, wall_dt: float) -> None:
        with self._lock:
            if self.session is None or not self.playhead.playing:
                return
            self.playhead.advance(self.session.timeline, wall_dt)
            if not self.playhead.playing:
                self.play_button.label = "play"
            self.render()

    def place_camera(self) -> None:
        """Top-down over the whole drive (or over the vehicle when following)."""
        s = self.session
        if s is None:
            return
        data = s.scene
        cam = self.client.camera
        if self.follow:
            xy, _ = data.proposed.pose_at(self.playhead.t + data.t0)
            center, height = np.asarray(xy, float), 250.0
        else:
            center = data.center
            height = data.extent_m * 0.6
        if cam.update_timestamp == 0.0:
            self._camera_pending = True  # the browser has not reported its camera yet
            return
        self._camera_pending = False
        # The control panel covers the right of the view: fit the drive into the rest and
        # shift the view east so it is centred there (top-down, north up: screen x = east).
        aspect, free, half_h = self._view_geometry()
        if not self.follow:
            height = max(height, data.extent_m * 0.55 / (half_h * aspect * free))
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

    def set_session(self, session: Session) -> None:
        """A new session: redraw everything, keeping this tab's time."""
        with self._lock:
            first = self.session is None
            self.session = session
            tl = session.timeline
            dt = float(np.median(np.diff(tl.t))) if tl.n_frames > 1 else 0.05
            with self.client.atomic():
                self.layers.set_data(session.scene)
                self.time_slider.max = max(tl.duration, dt)
                self.time_slider.step = round(max(dt, 1e-3), 3)
                self.status.content = status_markdown(session)
                self.metrics.content = metrics_markdown(session.metrics, session.method)
                self._set_plots(session)
                self.sync_params()
                if session.log_name in self.log_choice.options:
                    self.log_choice.value = session.log_name
                if session.route_name in self.route_choice.options:
                    self.route_choice.value = session.route_name
            self.playhead.t = tl.clamp(self.playhead.t)
            self._shown_match = None
            self._plot_t = None
            if first or not self._camera_placed:
                self.place_camera()
                self._camera_placed = True
            self.render()

    def _set_plots(self, session: Session) -> None:
        dev = session.deviation
        kinds = dev.kinds
        for k, which in enumerate(("position", "heading", "truth")):
            h = self.plots.get(which)
            if which not in kinds:
                if h is not None:
                    h.visible = False
                continue
            kw = dev.uplot(which, self.playhead.t)
            if h is None:
                with self.plots_tab:
                    self.plots[which] = self.client.gui.add_uplot(
                        kw["data"],
                        kw["series"],
                        scales=kw["scales"],
                        title=kw["title"],
                        aspect=1.6,
                        order=self.metrics.order - 1.0 + 0.25 * k,
                    )
            else:
                h.data = kw["data"]
                h.visible = True
        self._set_off_route_plot(session)

    def _set_off_route_plot(self, session: Session) -> None:
        """The vehicle's distance from the route with the off-route spans shaded."""
        h = self.plots.get("off_route")
        if session.off_route is None:
            if h is not None:
                h.visible = False
            return
        kw = session.off_route.uplot(self.playhead.t)
        if h is None:
            with self.plots_tab:
                self.plots["off_route"] = self.client.gui.add_uplot(
                    kw["data"],
                    kw["series"],
                    scales=kw["scales"],
                    title=kw["title"],
                    aspect=2.2,
                    order=self.metrics.order - 0.25,
                )
        else:
            h.data = kw["data"]
            h.visible = True

    def sync_params(self) -> None:
        """Show the controller's parameters (after another tab changed them, or a failure)."""
        params = self.app.controller.params
        for name, widget in self._param_widgets.items():
            value = get_param(params, name)
            if isinstance(value, tuple):
                value = tuple(float(v) for v in value)
            elif value is None:
                value = ""
            try:
                if widget.value != value:
                    widget.value = value
            except (TypeError, ValueError):
                pass
        if self.method.value != self.app.controller.method:
            self.method.value = self.app.controller.method
        self.sync_outages()

    def sync_outages(self) -> None:
        """Show the outages in effect, unless this tab is typing in the field (its text is
        applied, or refused, when the typing rests)."""
        if self._outage_timer is not None:
            return
        wanted = self.app.controller.outages
        try:
            shown = parse_outages(str(self.outage_field.value))
        except RoutefuseError:
            shown = None
        if shown != wanted:
            self.outage_field.value = format_outages(wanted)

    def render(self) -> None:
        """Draw the current time: layers, labels, panel, plot markers, camera."""
        s = self.session
        if s is None:
            return
        t = self.playhead.t
        tl = s.timeline
        data = s.scene
        with self.client.atomic():
            self.layers.draw(t + data.t0)
            frame = tl.frame_at(t)
            gnss = "missing" if s.proposed.epochs.degraded[frame] else "ok"
            off = s.off_route.frame_text(t) if s.off_route is not None else ""
            self.frame_label.content = (
                f"**frame {frame + 1} / {tl.n_frames}** · t = {tl.t[frame]:.2f} s · GNSS {gnss}"
                + (f" · {off}" if off else "")
            )
            self.time_slider.value = float(np.clip(round(t, 3), 0, self.time_slider.max))
            i = tl.match_at(t)
            off_head = s.off_route.panel_text(t, i) if s.off_route is not None else ""
            key = (s.version, i, off_head)
            if key != self._shown_match:
                self._shown_match = key
                m = s.proposed.matches[i] if i is not None else None
                panel = match_markdown(
                    m,
                    t_rel=None if i is None else float(tl.match_t[i]),
                    age_s=0.0 if i is None else t - float(tl.match_t[i]),
                    total=len(tl.match_t),
                )
                self.match_panel.content = f"{off_head}\n\n{panel}" if off_head else panel
            if self._plot_t is None or abs(self._plot_t - t) > tl.duration / 800:
                self._plot_t = t
                for which, h in self.plots.items():
                    if which in s.deviation.kinds:
                        h.data = s.deviation.uplot(which, t)["data"]
                    elif which == "off_route" and s.off_route is not None:
                        h.data = s.off_route.uplot(t)["data"]
            if self.follow:
                self._follow(data, t)

    def _follow(self, data: Any, t: float) -> None:
        xy, _ = data.proposed.pose_at(t + data.t0)
        cam = self.client.camera
        offset = np.asarray(cam.position) - np.asarray(cam.look_at)
        target = np.array([xy[0], xy[1], 0.0]) + self._panel_shift(float(np.linalg.norm(offset)))
        # position first: assigning it drags look_at along by the same move.
        cam.position = tuple(target + offset)
        cam.look_at = tuple(target)

    def set_progress(self, fraction: float, message: str) -> None:
        done = fraction >= 1.0
        self.progress.visible = not done
        self.progress.value = float(np.clip(fraction * 100, 0, 100))
        if not done:
            self.status.content = f"*{message}* ({fraction * 100:.0f} %)"
        elif self.session is not None:
            self.set_status()
        else:
            self.status.content = "**routefuse inspector** · nothing loaded (open a log in Files)"

    def set_status(self) -> None:
        s = self.session
        if s is None:
            return
        self.status.content = status_markdown(s)

    def refresh_files(self) -> None:
        listing = self.app.controller.folders.listing()
        for choice, names in (
            (self.log_choice, tuple(listing.logs)),
            (self.route_choice, tuple(listing.routes)),
        ):
            keep = choice.value
            choice.options = names or (_NONE,)
            if keep in names:
                choice.value = keep

    def close(self) -> None:
        self._clicks.shutdown(wait=False, cancel_futures=True)
        with self._lock:
            self.playhead.playing = False
            if self._outage_timer is not None:
                self._outage_timer.cancel()
                self._outage_timer = None


class InspectorApp:
    """Wires a viser server to a controller: a view per tab, the player clock, notifications."""

    def __init__(self, server: viser.ViserServer, controller: Controller) -> None:
        self.server = server
        self.controller = controller
        self._views: dict[int, ClientView] = {}
        self._views_lock = threading.Lock()
        self._last_progress = 0.0
        self._stop = threading.Event()
        server.scene.set_up_direction("+z")
        server.on_client_connect(self._connect)
        server.on_client_disconnect(self._disconnect)
        self._unsubscribe = controller.subscribe(
            on_progress=self._on_progress, on_session=self._on_session, on_error=self._on_error
        )
        self._player = threading.Thread(
            target=self._play_loop, name="routefuse-player", daemon=True
        )
        self._player.start()

    def views(self) -> list[ClientView]:
        with self._views_lock:
            return list(self._views.values())

    def _connect(self, client: viser.ClientHandle) -> None:
        view = ClientView(self, client)
        with self._views_lock:
            self._views[client.client_id] = view
        session = self.controller.session
        if session is not None:
            view.set_session(session)
        elif self.controller.busy:
            view.set_progress(0.0, "loading")

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._views_lock:
            view = self._views.pop(client.client_id, None)
        if view is not None:
            view.close()

    def _on_progress(self, fraction: float, message: str) -> None:
        now = time.monotonic()
        if fraction < 1.0 and now - self._last_progress < 0.1:
            return
        self._last_progress = now
        for view in self.views():
            view.set_progress(fraction, message)

    def _on_session(self, session: Session) -> None:
        for view in self.views():
            try:
                view.set_session(session)
            except Exception as exc:  # one broken tab must not starve the others
                view.notify_error(exc, "Display error")

    def _on_error(self, exc: RoutefuseError) -> None:
        for view in self.views():
            view.set_progress(1.0, "")
            view.notify_error(
                exc,
                "Could not load"
                if self.controller.session is None
                else "Kept the previous session",
            )
            view.sync_params()

    def refresh_files(self) -> None:
        for view in self.views():
            view.refresh_files()

    def _play_loop(self) -> None:
        period = 1.0 / PLAY_RATE_HZ
        last = time.monotonic()
        while not self._stop.wait(period):
            now = time.monotonic()
            dt, last = now - last, now
            for view in self.views():
                try:
                    view.tick(dt)
                except Exception:
                    view.playhead.playing = False

    def close(self) -> None:
        self._stop.set()
        self._unsubscribe()
