"""Ctrl+C for a test that runs ``routefuse serve`` (:func:`inspector.cli.serve.execute`) in its
own main thread, as a user stops it."""

from __future__ import annotations

import _thread
import signal
import threading
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager


@contextmanager
def ctrl_c_when_served(
    port: int, *, then: Callable[[], None] = lambda: None, settle_s: float = 2.0
) -> Iterator[None]:
    """Within the block: once the server on ``port`` answers, run ``then``, wait ``settle_s``
    (for the first load to report), then press Ctrl+C every 2 s until the block ends (on a
    loaded machine one may land before the serve loop). Python's default SIGINT handler is
    installed for the block: a process started from a background job of a non-interactive
    shell inherits SIGINT ignored, and ``_thread.interrupt_main`` then does nothing."""
    done = threading.Event()

    def interrupt_when_served() -> None:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2).read(100)
                break
            except OSError:
                time.sleep(0.2)
        then()
        time.sleep(settle_s)
        while not done.is_set():
            _thread.interrupt_main()
            done.wait(2.0)

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Thread(target=interrupt_when_served, daemon=True).start()
    try:
        yield
    finally:
        done.set()
        signal.signal(signal.SIGINT, previous)
