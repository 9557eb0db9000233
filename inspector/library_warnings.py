"""Python warnings from the libraries a command drives (matplotlib, numpy, rosbags), told as
routefuse's own one-line warnings: Python's default prints the library's source file and line
under the message, which reads as a crash to a user and says nothing they can act on."""

from __future__ import annotations

import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO


@contextmanager
def library_warnings_as_lines(command: str) -> Iterator[None]:
    """Inside, a Python warning that the filters let through is printed once on stderr as
    ``routefuse <command>: warning: <Category>: <first line of the message>``, with no source
    line. The filters are left as they are (a warning ignored stays ignored); the previous
    ``warnings.showwarning`` is restored on leaving."""
    told: set[str] = set()

    def tell(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        text = warning_line(message, category)
        if text not in told:
            told.add(text)
            print(f"routefuse {command}: warning: {text}", file=sys.stderr, flush=True)

    with warnings.catch_warnings():
        warnings.showwarning = tell
        yield


def warning_line(message: Warning | str, category: type[Warning]) -> str:
    """``<Category>: <first line of the message>``."""
    lines = str(message).strip().splitlines()
    return f"{category.__name__}: {lines[0] if lines else '(no message)'}"


@contextmanager
def library_warnings_recorded() -> Iterator[list[str]]:
    """Inside, the Python warnings the filters let through are kept (each once, as
    :func:`warning_line`) in the list yielded, not printed: a sweep's worker process has no
    terminal of its own, so they go into the log's results, as its warnings."""
    kept: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        yield kept
    kept.extend(dict.fromkeys(warning_line(w.message, w.category) for w in caught))
