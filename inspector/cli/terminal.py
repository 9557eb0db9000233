"""What the commands print reaches a terminal as text, never as its control sequences.

File names, route line names, topic names and values typed on the command line come from the
disk or the user, and end up in errors, warnings and tables. Printed raw, an escape sequence
in one retitles, clears or recolours the terminal (or hides text), and a newline splits the
one-line error a script greps for in two. Every command's stdout and stderr go through
:class:`PrintableStream`; one-line messages (errors, warnings) also through :func:`one_line`.
"""

from __future__ import annotations

import re
from typing import Any, TextIO

ERASE_LINE = "\x1b[K"
"""the one control sequence the commands print themselves (a progress line rewritten in place)"""
_CONTROL = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")
"""C0 controls but tab, newline and carriage return; DEL; C1 controls; the bidirectional
overrides and isolates (which reorder what a terminal shows)"""
_LINE_BREAKS = re.compile("[\n\r\u2028\u2029]")


def _escaped(match: re.Match[str]) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def printable(text: str) -> str:
    """``text`` with every control character shown as its escape (``\\x1b``), line breaks and
    tabs kept."""
    return _CONTROL.sub(_escaped, text)


def one_line(text: str) -> str:
    """``text`` as one printable line: line breaks shown as their escapes too."""
    return printable(_LINE_BREAKS.sub(_escaped, text))


class PrintableStream:
    """A text stream that writes what it is given through :func:`printable` (keeping the
    commands' own :data:`ERASE_LINE`); everything else is the wrapped stream's."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        self._stream.write(ERASE_LINE.join(printable(part) for part in text.split(ERASE_LINE)))
        return len(text)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)
