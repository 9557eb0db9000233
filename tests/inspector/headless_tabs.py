"""Browser tabs without a browser, for the issue-16 server tests: a tab whose notifications are
recorded, and messages handed to viser's own message handlers as its websocket would."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from typing import Any

from benchmarks.measures import HeadlessTab


class RecordingTab(HeadlessTab):
    """A :class:`HeadlessTab` with its own id that keeps the notifications it was sent."""

    def __init__(self, server: Any, client_id: int) -> None:
        super().__init__(server)
        self.client_id = client_id
        self.notes: list[tuple[str, str]] = []

    def add_notification(self, title: str, body: str = "", *args: Any, **kwargs: Any) -> None:
        self.notes.append((title, body))


def deliver(server: Any, client_id: int, *messages: Any) -> None:
    """Hand messages to every handler viser registered for their type (viser's own first),
    in order, on an event loop of their own, then wait for the callbacks they queued."""
    interface = server.gui._websock_interface

    async def send() -> None:
        for message in messages:
            # viser runs each message as its own task: one that fails is logged, not raised
            with contextlib.suppress(Exception):
                await interface._handle_incoming_message(client_id, message)

    runner = threading.Thread(target=asyncio.run, args=(send(),))
    runner.start()  # its own event loop: the browser tests may leave one running here
    runner.join(30)
    settle(server)


def settle(server: Any) -> None:
    """Wait until the callbacks viser queued on its thread pool so far have run: one task per
    worker that all meet at a barrier, so every worker has finished what it took before."""
    pool = server.gui._thread_executor
    barrier = threading.Barrier(pool._max_workers)
    meetings = [pool.submit(barrier.wait, 30) for _ in range(pool._max_workers)]
    for meeting in meetings:
        meeting.result(timeout=60)
