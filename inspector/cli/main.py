"""The ``routefuse`` command: one parser, a subcommand per module."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys
import textwrap
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import NoReturn, TextIO, cast

from estimator.errors import RoutefuseError
from inspector.cli.exit_codes import ExitCode, exit_codes_epilog
from inspector.cli.terminal import PrintableStream, one_line

COMMANDS = (
    "inspector.cli.info",
    "inspector.cli.run",
    "inspector.cli.simulate",
    "inspector.cli.serve",
    "inspector.cli.export",
    "inspector.cli.sweep",
    "inspector.cli.bench",
)


def _modules(command: str | None = None) -> list[ModuleType]:
    """Every command's module, or only ``command``'s when it names one."""
    chosen = f"inspector.cli.{command}"
    return [
        importlib.import_module(name) for name in ((chosen,) if chosen in COMMANDS else COMMANDS)
    ]


def _command_of(argv: Sequence[str]) -> str | None:
    """The command a command line names: its first word that is not an option (the top-level
    options, ``--debug`` and ``--version``, take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def version() -> str:
    """The installed distribution's version; ``unknown (not installed)`` when the code runs from
    a source tree that was never installed."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("routefuse")
    except PackageNotFoundError:
        return "unknown (not installed)"


class _VersionAction(argparse.Action):
    """``--version``: ``routefuse X.Y.Z`` on stdout, exit 0 (the version looked up only when
    asked, so building the parser stays light)."""

    def __init__(self, option_strings: Sequence[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        print(f"routefuse {version()}")
        parser.exit(0)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``routefuse`` parser; with ``command``, one that knows only that command, so that a
    command line naming it imports no other command's module nor builds its options (0.02 s of
    every ``routefuse run``). Without it, or for an unknown name, every command (the top-level
    help, the invalid-choice error)."""
    parser = argparse.ArgumentParser(
        prog="routefuse",
        description=textwrap.fill(
            "Keep a ground vehicle localised through GNSS outages by matching the shape of its "
            "dead-reckoned track to the mission route, and inspect every match in a browser.",
            width=78,
        ),
        epilog=exit_codes_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--debug", action="store_true", help="show the full traceback on unexpected errors"
    )
    parser.add_argument(
        "--version", action=_VersionAction, help="print routefuse's version and exit"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for mod in _modules(command):
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_execute=mod.execute)
    return parser


QUICK_EXIT_COMMANDS = frozenset({"run", "info"})
"""Commands whose process ends without the interpreter's teardown (:func:`console`)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; its exit code (:class:`ExitCode`; a usage error raises argparse's
    ``SystemExit(2)``)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    with printable_output():
        return _execute(build_parser(_command_of(argv)).parse_args(argv))


@contextlib.contextmanager
def printable_output() -> Iterator[None]:
    """stdout and stderr through :class:`~inspector.cli.terminal.PrintableStream` (argparse's
    usage errors, which quote what was typed, included)."""
    out = cast(TextIO, PrintableStream(sys.stdout))
    err = cast(TextIO, PrintableStream(sys.stderr))
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        yield


def console() -> NoReturn:
    """The ``routefuse`` console script.

    After ``run`` or ``info`` (every file written and closed, stdout and stderr flushed) the
    process ends at once: the interpreter's teardown of numba's and LLVM's objects took
    0.3-0.4 s measured (a 5-minute drive, 2-core machine), longer than the estimation itself,
    and those commands leave nothing for it to do. Every other command exits normally."""
    argv = sys.argv[1:]
    with printable_output():
        args = build_parser(_command_of(argv)).parse_args(argv)
        code = _execute(args)
    if args.command in QUICK_EXIT_COMMANDS:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


def _execute(args: argparse.Namespace) -> int:
    try:
        return int(args._execute(args) or 0)
    except RoutefuseError as exc:
        print(f"routefuse: error: {one_line(str(exc))}", file=sys.stderr)
        return ExitCode.REFUSED
    except KeyboardInterrupt:
        print("routefuse: interrupted", file=sys.stderr)
        return ExitCode.INTERRUPTED
    except Exception as exc:
        if args.debug or os.environ.get("ROUTEFUSE_DEBUG"):
            raise
        print(
            f"routefuse: internal error: {type(exc).__name__}: {one_line(str(exc))} "
            "(run with --debug for the traceback)",
            file=sys.stderr,
        )
        return ExitCode.INTERNAL_ERROR


if __name__ == "__main__":
    console()
