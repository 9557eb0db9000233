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
        lines = str(message).strip().splitlines()
        text = f"{category.__name__}: {lines[0] if lines else '(no message)'}"
        if text not in told:
            told.add(text)
            print(f"routefuse {command}: warning: {text}", file=sys.stderr, flush=True)

    with warnings.catch_warnings():
        warnings.showwarning = tell
        yield
