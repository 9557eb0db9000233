"""The playback controls above the tabs: status, progress, time slider, frame and attempt
stepping, play / pause and speed, the camera buttons, and the hotkeys that do the same."""

from __future__ import annotations

import contextlib
import traceback
from collections.abc import Callable, Coroutine
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from estimator.errors import RoutefuseError
from estimator.evaluation import run_notes
from estimator.results import Run
from inspector.app.widgets import Event, markdown_text, show_value, wrapping_anywhere
from inspector.controller import Session, format_outages
from inspector.timeline import PLAY_SPEEDS, parse_speed

if TYPE_CHECKING:
    from inspector.app.view import ClientView

STEP_BUTTONS = {"« 10": -10, "‹ prev": -1, "next ›": 1, "10 »": 10}
"""the frame step buttons and how many output frames each moves"""
MATCH_BUTTONS = {
    "‹ attempt": "previous",
    "attempt ›": "next",
    "‹ rejected": "previous rejected",
    "rejected ›": "rejected",
}
"""the match navigation buttons and the :meth:`ClientView.jump` each makes"""
NOTHING_LOADED = "**routefuse inspector** · nothing loaded (open a log in Files)"


def status_markdown(s: Session) -> str:
    """The status line of a session: files, length, attempts, and the off-route summary."""
    tl = s.timeline
    text = (
        f"{wrapping_anywhere(f'**{markdown_text(s.log_name)}**')} · route "
        f"{wrapping_anywhere(f'**{markdown_text(s.route_name)}**')} · "
        f"{tl.duration:.0f} s, "
        f"{tl.n_frames} frames, {len(tl.match_t)} match attempts "
        f"({int((~tl.match_accepted).sum())} rejected)"
    )
    if s.outages:
        text += f" · GNSS removed {format_outages(s.outages)} s"
    off = s.off_route.summary() if s.off_route is not None else ""
    text = f"{text} · {off}" if off else text
    return text + notes_markdown(s.proposed) + warnings_markdown(s.proposed.warnings)


MAX_NOTES_SHOWN = 10


def notes_markdown(run: Run) -> str:
    """What the run did at its outages (:func:`~estimator.evaluation.run_notes`, escaped):
    where it found the route drawn off the road driven, so that an "off the route" summary of
    a corrected run is not read as a failure; the fixes its portal re-runs left out, so that an
    outage entered away from the last fixes shown is not a mystery; the outages too short for
    any attempt."""
    return "".join(f"\n\n{markdown_text(n)}" for n in run_notes(run)[:MAX_NOTES_SHOWN])


MAX_WARNINGS_SHOWN = 5
MAX_WARNING_CHARS = 300


def warnings_markdown(warnings: tuple[str, ...]) -> str:
    """The log's warnings below the status line (what was repaired or looks wrong), escaped
    and bounded; empty without any."""
    if not warnings:
        return ""
    unique = tuple(dict.fromkeys(warnings))
    lines = [f"- {markdown_text(w[:MAX_WARNING_CHARS])}" for w in unique[:MAX_WARNINGS_SHOWN]]
    if len(unique) > MAX_WARNINGS_SHOWN:
        lines.append(f"- and {len(unique) - MAX_WARNINGS_SHOWN} more (`routefuse info` lists all)")
    plural = "s" if len(unique) > 1 else ""
    head = f"\n\n⚠ **{len(unique)} warning{plural} about this log and its run**"
    return head + " (what was repaired, looks wrong or was undone):\n\n" + "\n".join(lines)


def _report_failure(done: Future[None]) -> None:
    """Print what a click's action raised (it runs on a worker thread nobody waits on)."""
    exc = None if done.cancelled() else done.exception()
    if exc is not None:
        traceback.print_exception(exc)


def _ignoring_event(action: Callable[[], None]) -> Callable[[viser.CommandEvent], None]:
    def trigger(_: viser.CommandEvent) -> None:
        action()

    return trigger


class PlaybackPanel:
    """The controls every tab shows above its tab group. Clicks go to this tab's one worker
    thread (:meth:`_pressed`), so they are applied once each, in order."""

    def __init__(self, view: ClientView, gui: viser.GuiApi) -> None:
        self.view = view
        self.clicks = ThreadPoolExecutor(1, thread_name_prefix="routefuse-clicks")
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
                {label: partial(view.step, n) for label, n in STEP_BUTTONS.items()},
            )
        )
        self.match_buttons = gui.add_button_group("match", tuple(MATCH_BUTTONS))
        self.match_buttons.on_click(
            self._pressed(
                self.match_buttons,
                {label: partial(view.jump, w) for label, w in MATCH_BUTTONS.items()},
            )
        )
        self.play_button = gui.add_button("play", hint="play / pause (space)")
        self.play_button.on_click(lambda _: view.toggle_play())
        self.speed = gui.add_dropdown("speed", PLAY_SPEEDS, initial_value="5x")
        self.speed.on_update(self._on_speed)
        view.playhead.speed = 5.0
        self.follow_box = gui.add_checkbox("follow vehicle", False)
        self.follow_box.on_update(self._on_follow)
        self.view_button = gui.add_button("top-down view")
        self.view_button.on_click(lambda _: view.place_camera())
        gui.add_markdown(
            "<small>keys: ← → frame · ↑ ↓ ten frames · space play · N / P next / previous "
            "attempt · R / E next / previous rejected</small>"
        )
        self._enable(False)

    def _enable(self, on: bool) -> None:
        """Nothing to step before the first session: the controls are disabled (a button group
        cannot be, so it is hidden) until one is shown."""
        for control in (
            self.time_slider,
            self.play_button,
            self.speed,
            self.follow_box,
            self.view_button,
        ):
            control.disabled = not on
        self.step_buttons.visible = on
        self.match_buttons.visible = on

    def add_hotkeys(self, gui: viser.GuiApi) -> None:
        """The keyboard twins of the buttons (after the tabs, as viser lists commands)."""
        view = self.view
        binds: list[tuple[str, Any, Callable[[], None]]] = [
            ("next frame", "arrowright", partial(view.step, 1)),
            ("previous frame", "arrowleft", partial(view.step, -1)),
            ("forward 10 frames", "arrowup", partial(view.step, 10)),
            ("back 10 frames", "arrowdown", partial(view.step, -10)),
            ("play / pause", "space", view.toggle_play),
            ("next match attempt", "N", partial(view.jump, "next")),
            ("previous match attempt", "P", partial(view.jump, "previous")),
            ("next rejected attempt", "R", partial(view.jump, "rejected")),
            ("previous rejected attempt", "E", partial(view.jump, "previous rejected")),
        ]
        for label, key, fn in binds:
            cmd = gui.add_command(label, hotkey=key)
            cmd.on_trigger(_ignoring_event(fn))

    def _on_slider(self, event: Event) -> None:
        if event.client is None:
            return
        view = self.view
        session = view.session
        if session is None:
            return
        try:
            t = session.timeline.checked_time(self.time_slider.value)
        except RoutefuseError as exc:
            view.notify_error(exc, "Refused")
            show_value(
                self.time_slider, float(np.clip(round(view.playhead.t, 3), 0, self.time_slider.max))
            )
            return
        view.seek(t)

    def _pressed(
        self, group: viser.GuiButtonGroupHandle, actions: dict[str, Callable[[], None]]
    ) -> Callable[[Event], Coroutine[Any, Any, None]]:
        """A button group's click handler that reads which button was pressed as the click
        arrives.

        viser stores the pressed label on the shared handle, then runs plain callbacks on its
        thread pool: two quick clicks ("next ›", "10 »") could both be read as the second. A
        coroutine runs on the event loop before the next message is handled; the action itself
        goes to this tab's one worker thread, so clicks are applied once each, in order.
        """

        async def on_click(event: Event) -> None:
            action = actions.get(group.value)
            if action is None:  # a label no button has: only a misbehaving client sends one
                self.view.notify_error(
                    RoutefuseError(None, f"no button {str(group.value)[:40]!r}"), "Refused"
                )
                return
            with contextlib.suppress(RuntimeError):  # raised once the tab has closed
                self.clicks.submit(action).add_done_callback(_report_failure)

        return on_click

    def _on_speed(self, event: Event) -> None:
        try:
            self.view.playhead.speed = parse_speed(self.speed.value)
        except RoutefuseError as exc:
            self.view.notify_error(exc, "Refused")
            show_value(self.speed, f"{self.view.playhead.speed:g}x")

    def _on_follow(self, event: Event) -> None:
        self.view.follow = bool(self.follow_box.value)
        if self.view.follow:
            self.view.place_camera()

    def show_session(self, session: Session) -> None:
        """Fit the slider to a new session's frames and show its status line."""
        tl = session.timeline
        dt = float(np.median(np.diff(tl.t))) if tl.n_frames > 1 else 0.05
        self.time_slider.max = max(tl.duration, dt)
        self.time_slider.step = round(max(dt, 1e-3), 3)
        self.status.content = status_markdown(session)
        self._enable(True)

    def show_time(self, s: Session, t: float) -> None:
        """The frame line and the slider at time ``t``."""
        tl = s.timeline
        frame = tl.frame_at(t)
        gnss = "missing" if s.proposed.epochs.degraded[frame] else "ok"
        off = s.off_route.frame_text(t) if s.off_route is not None else ""
        self.frame_label.content = (
            f"**frame {frame + 1} / {tl.n_frames}** · t = {tl.t[frame]:.2f} s · GNSS {gnss}"
            + (f" · {off}" if off else "")
        )
        show_value(self.time_slider, float(np.clip(round(t, 3), 0, self.time_slider.max)))

    def show_playing(self, playing: bool) -> None:
        self.play_button.label = "pause" if playing else "play"

    def set_progress(self, fraction: float, message: str, session: Session | None) -> None:
        done = fraction >= 1.0
        self.progress.visible = not done
        show_value(self.progress, float(np.clip(fraction * 100, 0, 100)))
        if not done:
            self.status.content = f"*{markdown_text(message)}* ({fraction * 100:.0f} %)"
        elif session is not None:
            self.status.content = status_markdown(session)
        else:
            self.status.content = NOTHING_LOADED

    def close(self) -> None:
        self.clicks.shutdown(wait=False, cancel_futures=True)
