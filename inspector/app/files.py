"""The Files tab: the logs and routes under the data folders, open, and uploads (their
accepted suffixes are the log-format registry's, :mod:`estimator.io`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal

import viser
from viser import _messages

from estimator.errors import RoutefuseError
from estimator.io import LOG_SUFFIXES_TEXT, ROUTE_SUFFIXES_TEXT
from inspector.app.widgets import Event, markdown_text, show_value
from inspector.controller import Session, format_outages

if TYPE_CHECKING:
    from inspector.app.view import ClientView

NONE = "(none)"
"""the dropdown entry when there is nothing to choose"""


class FilesPanel:
    """Choose a log and its route from the listing, open them, upload more."""

    def __init__(self, view: ClientView, gui: viser.GuiApi) -> None:
        self.view = view
        self.client = view.client
        self.controller = view.app.controller
        listing = self.controller.folders.listing()
        logs = tuple(listing.logs) or (NONE,)
        routes = tuple(listing.routes) or (NONE,)
        self.log_choice = gui.add_dropdown("log", logs, initial_value=logs[0])
        self.log_choice.on_update(self._on_log_choice)
        self.route_choice = gui.add_dropdown("route file", routes, initial_value=routes[0])
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
            self._refuse_large_uploads(gui, uploads.max_bytes)
        folders = "\n".join(f"- {markdown_text(r)}" for r in self.controller.folders.roots)
        gui.add_markdown(f"Files are listed from:\n{folders}")

    def _refuse_large_uploads(self, gui: viser.GuiApi, max_bytes: int) -> None:
        """Drop an oversized upload when it starts, before its parts are buffered in memory.

        viser has no public size limit; its transfer state for this tab is dropped right after
        viser creates it, so the parts that follow are ignored."""
        states = getattr(gui, "_current_file_upload_states", None)
        interface = getattr(gui, "_websock_interface", None)
        uploads = self.controller.uploads
        if states is None or interface is None or uploads is None:
            return

        def check(_client_id: Any, message: _messages.FileTransferStartUpload) -> None:
            if message.size_bytes > max_bytes:
                states.pop(message.transfer_uuid, None)
                try:
                    uploads.check_size(message.filename, message.size_bytes)
                except RoutefuseError as exc:
                    self.view.notify_error(exc, "Upload rejected")

        interface.register_handler(_messages.FileTransferStartUpload, check)

    def _on_log_choice(self, event: Event) -> None:
        if event.client is None:
            return
        route = self.controller.folders.default_route(self.log_choice.value)
        if route is not None and route in self.route_choice.options:
            show_value(self.route_choice, route)

    def _on_open(self, event: Event) -> None:
        log, route = self.log_choice.value, self.route_choice.value
        if NONE in (log, route):
            self.view.notify_error(RoutefuseError(None, "choose a log and a route first"))
            return
        controller = self.controller
        before = controller.outages
        self.view.guard(lambda: controller.open_named(log, route))
        if before and not controller.outages:
            self.client.add_notification(
                "GNSS outages not carried over",
                f"{log} opens without {format_outages(before)} s: those were times in the "
                "previous log",
                auto_close_seconds=6.0,
            )

    def _uploader(self, kind: Literal["log", "route"]) -> Callable[[Event], None]:
        def on_upload(event: Event) -> None:
            handle = self.upload_log if kind == "log" else self.upload_route
            up = handle.value
            try:
                name = self.controller.save_upload(up.name, up.content)
            except RoutefuseError as exc:
                self.view.notify_error(exc, "Upload rejected")
                return
            self.view.app.refresh_files()
            choice = self.log_choice if kind == "log" else self.route_choice
            if name in choice.options:
                show_value(choice, name)
            self.client.add_notification(
                "Uploaded", f"{name}: press 'open' to load it", auto_close_seconds=6.0
            )

        return on_upload

    def show_session(self, session: Session) -> None:
        """Select the files a new session was opened from."""
        if session.log_name in self.log_choice.options:
            show_value(self.log_choice, session.log_name)
        if session.route_name in self.route_choice.options:
            show_value(self.route_choice, session.route_name)

    def refresh(self) -> None:
        listing = self.controller.folders.listing()
        for choice, names in (
            (self.log_choice, tuple(listing.logs)),
            (self.route_choice, tuple(listing.routes)),
        ):
            keep = choice.value
            choice.options = names or (NONE,)
            if keep in names:
                show_value(choice, keep)
