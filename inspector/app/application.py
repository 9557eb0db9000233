"""The viser app: one :class:`ClientView` per browser tab over one shared :class:`Controller`,
the player clock that advances every playing tab, and the controller's news sent to every tab."""

from __future__ import annotations

import threading
import time

import viser

from estimator.errors import RoutefuseError, RouteLineError
from inspector.app.view import ClientView
from inspector.controller import Controller, Session

PLAY_RATE_HZ = 15.0


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
            if isinstance(exc, RouteLineError):  # offer the lines the file holds now
                view.files.show_route_lines_again()
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
