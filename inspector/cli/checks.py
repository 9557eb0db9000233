"""Checks of the paths a command is given, made before any work: each problem is one
:class:`RoutefuseError` naming the path, raised before the estimator runs (the log's own problem
first, then the route's, then the output files')."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from estimator.errors import RoutefuseError

GLOB_CHARACTERS = frozenset("*?[")
"""A log argument holding one of these is a glob pattern, not a path that must exist."""


def check_log(log: str | Path) -> Path:
    """``log`` as a path, once the log-format registry recognises it as a log it can open
    (:func:`estimator.io.open_log_path`: it exists, is a file or a ROS 2 bag folder of a known
    format, and starts as that format does); its problem otherwise, as a :class:`LogError`."""
    from estimator.io import open_log_path

    path = Path(log).expanduser()
    open_log_path(path)
    return path


def check_route(route: str | Path) -> Path:
    """``route`` as a path, once it is an existing file (a folder is named as one, instead of
    as an unknown route format); its format and content are the route reader's to check."""
    from estimator.io.routefile import route_file_stat

    path = Path(route).expanduser()
    route_file_stat(path)
    return path


NO_ROUTE = "no route given and none beside the log (<name>.route.*): give one with --route"


def route_for(log: Path, route: str | Path | None) -> Path:
    """The route given (checked by :func:`check_route`), else the one named after the log beside
    it (:func:`estimator.io.route_beside`, as ``serve`` and ``sweep`` find it), else a one-line
    error. Call it after :func:`check_log`: a bad log is reported as such, not as a log
    without a route."""
    from estimator.io import route_beside

    if route is not None:
        return check_route(route)
    found = route_beside(log)
    if found is None:
        raise RoutefuseError(log, NO_ROUTE)
    return found


def check_output_file(path: Path) -> None:
    """A file to be written after the run: its folder must exist and it must not be a folder,
    so that a typo fails at once instead of after the whole estimation."""
    folder = path.parent
    if path.is_dir():
        raise RoutefuseError(path, "cannot write: is a folder")
    if not folder.exists():
        raise RoutefuseError(path, f"cannot write: no folder {folder}")
    if not folder.is_dir():
        raise RoutefuseError(path, f"cannot write: {folder} is not a folder")


def check_log_specs(specs: Iterable[str]) -> None:
    """Log arguments that are plain paths (not glob patterns) must exist: a missing one is
    named as missing, not as a folder or glob that matched no log. One that exists but cannot
    be looked at (no permission) is left to the sweep, whose row for it names the problem
    while the other logs run."""
    for spec in specs:
        if GLOB_CHARACTERS.isdisjoint(spec):
            try:
                Path(spec).expanduser().stat()
            except FileNotFoundError:
                raise RoutefuseError(spec, "no such file or folder") from None
            except OSError:
                pass
