"""The ``routefuse`` command's exit codes: one table, read by the commands and by ``--help``, so
that a script can tell a refused command from a sweep that ran with failures."""

from __future__ import annotations

import textwrap
from enum import IntEnum


class ExitCode(IntEnum):
    OK = 0
    INTERNAL_ERROR = 1
    USAGE = 2
    REFUSED = 3
    SOME_FAILED = 4
    EXIT_CHECK_FAILED = 5
    INTERRUPTED = 130


MEANINGS: dict[ExitCode, str] = {
    ExitCode.OK: "success",
    ExitCode.INTERNAL_ERROR: "internal error, a bug (--debug shows the traceback)",
    ExitCode.USAGE: "usage error from the argument parser: unknown option, missing or "
    "mistyped argument (the usage is printed)",
    ExitCode.REFUSED: "refused, nothing done: one line 'routefuse: error: <file or flag>: "
    "<problem>' (an unreadable log or route, an ambiguous topic or route line, a bad value)",
    ExitCode.SOME_FAILED: "ran to the end, but some logs or items failed (sweep, export "
    "--batch, bench): the table or summary is written and names them",
    ExitCode.EXIT_CHECK_FAILED: "run --check-exits: routefuse ended an outage farther from the "
    "fixes after it than its sigmas allow (a warning names it); the results are written",
    ExitCode.INTERRUPTED: "interrupted (Ctrl-C)",
}


def exit_codes_epilog() -> str:
    """The exit codes as ``routefuse --help`` lists them."""
    entries = [
        textwrap.fill(
            MEANINGS[code],
            width=78,
            initial_indent=f"  {code.value:<4} ",
            subsequent_indent=" " * 7,
        )
        for code in ExitCode
    ]
    return "\n".join(["exit codes:", *entries])
