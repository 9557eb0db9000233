"""The Files tab: the logs and routes under the data folders, open, and uploads (their
accepted suffixes are the log-format registry's, :mod:`estimator.io`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import viser
from viser import _messages

from estimator.errors import RoutefuseError, RouteLineError
from estimator.io import LOG_SUFFIXES_TEXT, ROUTE_SUFFIXES_TEXT
from estimator.io.routefile import choose_line, line_label
from inspector.app.widgets import Event, markdown_text, show_value, wrapping_anywhere
from inspector.controller import (
    ROUTE_LINE_FIELD,
    Kind,
    RouteFeature,
    Session,
    format_outages,
)

if TYPE_CHECKING:
    from inspector.app.view import ClientView

NONE = "(none)"
"""the dropdown entry when there is nothing to choose"""
CHOOSE_LINE = "(choose a line)"
"""the route line dropdown's entry before a line is chosen (opening it says to choose one)"""


MAX_NOTES = 8
"""listing warnings shown in the Files tab (the rest are counted)"""


def listing_notes(warnings: tuple[str, ...]) -> str:
    """What the walk of the data folders skipped, as escaped markdown ('' when nothing)."""
    if not warnings:
        return ""
    lines = [f"- {markdown_text(w[:300])}" for w in warnings[:MAX_NOTES]]
    if len(warnings) > MAX_NOTES:
        lines.append(f"- and {len(warnings) - MAX_NOTES} more")
    return "**Not listed:**\n" + "\n".join(lines)


def _transfers(*guis: viser.GuiApi) -> list[tuple[str, dict[str, Any]]]:
    """The uploads viser is receiving through these tabs' controls (each declared size is a
    bound on what it holds: a transfer that sends more is dropped)."""
    seen: dict[int, dict[str, Any]] = {}
    for gui in guis:
        states = getattr(gui, "_current_file_upload_states", None)
        if isinstance(states, dict):
            seen[id(states)] = states
    return [item for states in seen.values() for item in list(states.items())]


def not_a_line(line: str, route: str) -> RoutefuseError:
    """The refusal of a route line that the route file ``route`` does not offer, one wording
    wherever the tab checks it (choosing the line, and again on 'open'): the browser may send
    any text, so it is shown quoted and cut to 60 characters."""
    return RoutefuseError(ROUTE_LINE_FIELD, f"{line[:60]!r} is not a line of {route}")


PATH_STYLE = "; font-size: 0.85em; opacity: 0.75"
"""the full path's line beneath a file's name: smaller and paler than the name"""


def loaded_markdown(session: Session) -> str:
    """What is loaded: each file's name (and the route's line, when one was chosen among
    several) and, on a smaller line beneath it, its full path, all wrapping within the panel
    however long; escaped."""
    line = ""
    feature = session.route_feature
    if feature is not None:
        route = session.inputs.route
        name = route.name if route is not None else str(feature)
        shown = line_label(feature, name) if isinstance(feature, int) else name
        line = f" · line **{markdown_text(shown)}**"
    return (
        "**Loaded:**\n\n"
        f"- log {_file_markdown(session.log_name, session.log_path)}\n"
        f"- route {_file_markdown(session.route_name, session.route_path, line)}"
    )


def _file_markdown(name: str, path: object, after: str = "") -> str:
    return (
        wrapping_anywhere(f"**{markdown_text(name)}**{after}")
        + "<br>"
        + wrapping_anywhere(markdown_text(str(path)), style=PATH_STYLE)
    )


class FilesPanel:
    """Choose a log and its route from the listing, open them, upload more."""

    def __init__(self, view: ClientView, gui: viser.GuiApi) -> None:
        self.view = view
        self.client = view.client
        self.controller = view.app.controller
        listing = self.controller.folders.listing()
        logs = tuple(listing.logs) or (NONE,)
        routes = tuple(listing.routes) or (NONE,)
        self.loaded = gui.add_markdown("**Loaded:** nothing yet")
        self.log_choice = gui.add_dropdown("log", logs, initial_value=logs[0])
        self.log_choice.on_update(self._on_log_choice)
        self.route_choice = gui.add_dropdown("route file", routes, initial_value=routes[0])
        self.route_choice.on_update(self._on_route_choice)
        self.route_line = gui.add_dropdown(
            ROUTE_LINE_FIELD,
            (CHOOSE_LINE,),
            initial_value=CHOOSE_LINE,
            visible=False,
            hint="the line of this route file to open (it holds several)",
        )
        self.route_line.on_update(self._on_route_line)
        self._lines: dict[str, int] = {}
        """the route line dropdown's entries and the index of the line each names"""
        self._accepted: dict[Kind, str] = {"log": logs[0], "route": routes[0]}
        """the last choice of each dropdown that was in the listing (shown again on a refusal)"""
        self._accepted_line = CHOOSE_LINE
        self._show_lines(routes[0])
        self.open_button = gui.add_button("open", hint="load the chosen log and route")
        self.open_button.on_click(self._on_open)
        refresh = gui.add_button("refresh list")
        refresh.on_click(lambda _: self.refresh())
        uploads = self.controller.uploads
        if uploads is not None:
            limit = f"up to {uploads.max_bytes / 1e6:.0f} MB"
            self.upload_log = gui.add_upload_button(
                "upload log", hint=f"{LOG_SUFFIXES_TEXT}, {limit}"
            )
            self.upload_log.on_upload(self._uploader("log"))
            self.upload_route = gui.add_upload_button(
                "upload route", hint=f"{ROUTE_SUFFIXES_TEXT}, {limit}"
            )
            self.upload_route.on_upload(self._uploader("route"))
            self._bound_uploads(gui)
        folders = "\n".join(f"- {markdown_text(r)}" for r in self.controller.folders.roots)
        gui.add_markdown(f"Files are listed from:\n{folders}")
        self.notes = gui.add_markdown(listing_notes(listing.warnings))

    def _bound_uploads(self, gui: viser.GuiApi) -> None:
        """Bound every upload by the bytes it really sends, not by what it declares.

        viser has no size limit of its own: it buffers a transfer's parts in memory until as
        many as declared have come. Two handlers beside viser's own (its websocket interface's
        public ``register_handler``; viser's run first) drop the transfer state that viser
        keeps for this tab, so the parts that follow are ignored: at the start when the declared
        size is over the limit or the upload folder, with what every tab has in flight, would
        be full; after each part once more bytes came than the declared size or the limit."""
        states = getattr(gui, "_current_file_upload_states", None)
        interface = getattr(gui, "_websock_interface", None)
        uploads = self.controller.uploads
        if states is None or interface is None or uploads is None:
            return

        def drop(transfer_uuid: str, exc: RoutefuseError) -> None:
            states.pop(transfer_uuid, None)
            self.view.notify_error(exc, "Upload rejected")

        def on_start(_client_id: Any, message: _messages.FileTransferStartUpload) -> None:
            if message.transfer_uuid not in states:
                return
            in_flight = sum(
                int(state["total_bytes"])
                for uuid, state in _transfers(gui, *(v.client.gui for v in self.view.app.views()))
                if uuid != message.transfer_uuid
            )
            try:
                uploads.check_size(message.filename, message.size_bytes)
                uploads.check_room(message.filename, in_flight + max(message.size_bytes, 0))
            except RoutefuseError as exc:
                drop(message.transfer_uuid, exc)

        def on_part(_client_id: Any, message: _messages.FileTransferPart) -> None:
            state = states.get(message.transfer_uuid)
            if state is None:
                return
            try:
                uploads.check_received(
                    str(state["filename"]),
                    int(state["total_bytes"]),
                    int(state["transferred_bytes"]),
                )
            except RoutefuseError as exc:
                drop(message.transfer_uuid, exc)

        interface.register_handler(_messages.FileTransferStartUpload, on_start)
        interface.register_handler(_messages.FileTransferPart, on_part)

    def _choice(self, kind: Kind) -> viser.GuiDropdownHandle[str]:
        return self.log_choice if kind == "log" else self.route_choice

    def _accept(self, kind: Kind) -> bool:
        """Whether the dropdown of ``kind`` shows a listed file (the browser may send any
        text); a refused one is reported to this tab and the last accepted choice shown."""
        choice = self._choice(kind)
        value = choice.value
        if value == self._accepted[kind]:
            return True
        try:
            self.controller.check_choice(value, kind)
        except RoutefuseError as exc:
            self.view.notify_error(exc, "Refused")
            show_value(choice, self._accepted[kind])
            return False
        self._accepted[kind] = value
        return True

    def _on_route_choice(self, event: Event) -> None:
        if event.client is not None and self._accept("route"):
            self._show_lines(self.route_choice.value)

    def _on_route_line(self, event: Event) -> None:
        """Accept a line of the dropdown's own (the browser may send any text)."""
        if event.client is None:
            return
        value = self.route_line.value
        if value == CHOOSE_LINE or value in self._lines:
            self._accepted_line = value
            return
        self.view.notify_error(not_a_line(value, self.route_choice.value), "Refused")
        show_value(self.route_line, self._accepted_line)

    def _show_lines(self, route_name: str, chosen: RouteFeature | str = CHOOSE_LINE) -> None:
        """Offer the lines of the route file ``route_name`` when it holds several (the control
        is hidden otherwise), showing ``chosen`` (an index, a name, or an entry of the
        dropdown's own) or else :data:`CHOOSE_LINE`."""
        names = () if route_name == NONE else self.controller.route_lines(route_name)
        if len(names) < 2:
            self._lines = {}
            self.route_line.options = (CHOOSE_LINE,)
            self.route_line.visible = False
            self._accepted_line = CHOOSE_LINE
            return
        self._lines = {line_label(i, name): i for i, name in enumerate(names)}
        options = (CHOOSE_LINE, *self._lines)
        if tuple(self.route_line.options) != options:
            self.route_line.options = options
        shown = CHOOSE_LINE
        if isinstance(chosen, str) and chosen in options:
            shown = chosen
        elif chosen is not None and chosen != CHOOSE_LINE:
            try:
                index = choose_line(route_name, names, chosen)
            except RouteLineError:
                pass
            else:
                shown = options[1 + index]
        self._accepted_line = shown
        show_value(self.route_line, shown)
        self.route_line.visible = True

    def _on_log_choice(self, event: Event) -> None:
        if event.client is None or not self._accept("log"):
            return
        route = self.controller.folders.default_route(self.log_choice.value)
        if (
            route is not None
            and route in self.route_choice.options
            and route != self.route_choice.value
        ):
            self._show("route", route)
            self._show_lines(route)

    def _on_open(self, event: Event) -> None:
        log, route = self.log_choice.value, self.route_choice.value
        if NONE in (log, route):
            self.view.notify_error(RoutefuseError(None, "choose a log and a route first"))
            return
        line = self.route_line.value if self._lines else CHOOSE_LINE
        if line != CHOOSE_LINE and line not in self._lines:
            self.view.notify_error(not_a_line(line, route), "Refused")
            return
        feature = self._lines.get(line)  # None before a line is chosen: opening says to
        controller = self.controller
        before = controller.outages
        self.view.guard(lambda: controller.open_named(log, route, route_feature=feature))
        if before and not controller.outages:
            self.client.add_notification(
                "GNSS outages not carried over",
                f"{log} opens without {format_outages(before)} s: those were times in the "
                "previous log",
                auto_close_seconds=6.0,
            )

    def _uploader(self, kind: Kind) -> Callable[[Event], None]:
        def on_upload(event: Event) -> None:
            handle = self.upload_log if kind == "log" else self.upload_route
            up = handle.value
            try:
                name = self.controller.save_upload(up.name, up.content)
            except RoutefuseError as exc:
                self.view.notify_error(exc, "Upload rejected")
                return
            self.view.app.refresh_files()
            if name in self._choice(kind).options:
                self._show(kind, name)
                if kind == "route":
                    self._show_lines(name)
            self.client.add_notification(
                "Uploaded", f"{name}: press 'open' to load it", auto_close_seconds=6.0
            )

        return on_upload

    def show_session(self, session: Session) -> None:
        """Name the files a new session was opened from (also when they are not in the listing:
        given on the command line outside the data folders) and select them where listed.
        The "Loaded" line is written last: once it names the session, the dropdowns show it."""
        if session.log_name in self.log_choice.options:
            self._show("log", session.log_name)
        if session.route_name in self.route_choice.options:
            self._show("route", session.route_name)
            self._show_lines(session.route_name, session.route_feature)
        self.loaded.content = loaded_markdown(session)

    def show_route_lines_again(self) -> None:
        """Read the chosen route file's lines again, keeping the line shown if it is still
        there (after a route line was refused: the file may have changed)."""
        self._show_lines(self.route_choice.value, self.route_line.value)

    def _show(self, kind: Kind, name: str) -> None:
        """Show a listed file in the dropdown of ``kind`` (the server's own choice)."""
        self._accepted[kind] = name
        show_value(self._choice(kind), name)

    def refresh(self) -> None:
        listing = self.controller.folders.listing()
        self.notes.content = listing_notes(listing.warnings)
        kinds: tuple[tuple[Kind, tuple[str, ...]], ...] = (
            ("log", tuple(listing.logs)),
            ("route", tuple(listing.routes)),
        )
        for kind, names in kinds:
            choice = self._choice(kind)
            keep = self._accepted[kind]
            choice.options = names or (NONE,)
            if keep in names:
                self._show(kind, keep)
            else:
                self._accepted[kind] = choice.value
        self.show_route_lines_again()
