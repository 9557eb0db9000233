"""Errors that reach the user as one line: the file (or parameter) and what is wrong with it;
and the rule by which a warning of many like it stays a few lines."""

from __future__ import annotations

import abc
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Self, TypeVar

T = TypeVar("T")


class RoutefuseError(Exception):
    """Base class: an error the CLI prints as one line and exits 3 on, and the UI notifies."""

    def __init__(self, source: str | Path | None, problem: str) -> None:
        self.source = None if source is None else str(source)
        self.problem = problem
        super().__init__(f"{self.source}: {problem}" if self.source else problem)


class LogError(RoutefuseError):
    """A log file that cannot be read, or lacks what the estimator needs."""


class RouteError(RoutefuseError):
    """A route file that cannot be parsed or is unusable (too short, far away, ...)."""


class ConfigError(RoutefuseError):
    """A parameter file or a parameter value that is invalid."""


@dataclass(frozen=True)
class WhereToChoose:
    """Where the user chooses among what a file holds several of, as the end of a
    :class:`ChoiceError`'s message says it (``...; choose one <where>``): the command line's
    flags by default; a caller with controls of its own (the inspector) names them."""

    route_line: str = "with --route-feature NAME_OR_INDEX"
    topic: str = "with --{kind}-topic TOPIC"
    """a template: ``{kind}`` is imu, gnss, wheel or truth"""


ON_THE_COMMAND_LINE = WhereToChoose()


class ChoiceError(RoutefuseError, abc.ABC):
    """A file holding several of something (a route file's lines, a log's topics of a kind)
    opened without choosing one, or with a choice naming none of them. It is raised where the
    file is read, saying where to choose on the command line; a caller with other controls
    says its own with :meth:`choose`. The message is the problem, where to choose, then
    ``listing`` (last: a notification cut short loses the listing, not the way out).

    Abstract: each kind of thing chosen says its own :meth:`way` and :meth:`choose`. It is
    caught by its class (``except ChoiceError`` in :func:`choices_said`), so an ABC and not a
    Protocol; and because an exception is made by ``BaseException.__new__``, which does not
    refuse an abstract class as ``object.__new__`` does, :meth:`__new__` refuses it here."""

    def __new__(cls, *args: object, **kwargs: object) -> Self:
        if cls.__abstractmethods__:
            missing = ", ".join(repr(name) for name in sorted(cls.__abstractmethods__))
            raise TypeError(
                f"Can't instantiate abstract class {cls.__name__} without an implementation "
                f"for abstract methods {missing}"
            )
        return super().__new__(cls, *args, **kwargs)

    def __init__(
        self,
        source: str | Path | None,
        problem: str,
        *,
        where: WhereToChoose = ON_THE_COMMAND_LINE,
        listing: str = "",
    ) -> None:
        self.bare_problem = problem
        self.where = where
        self.listing = listing
        super().__init__(source, f"{problem}; choose one {self.way(where)}{listing}")

    @abc.abstractmethod
    def way(self, where: WhereToChoose) -> str:
        """Where to choose this error's kind of thing."""

    @abc.abstractmethod
    def choose(self, where: WhereToChoose) -> ChoiceError:
        """The same error, saying where to choose as ``where`` does."""


class RouteLineError(RouteError, ChoiceError):
    """A route file holding several lines opened without choosing one, or with a choice that
    names none of them. ``lines`` are the file's line names (in order)."""

    def __init__(
        self,
        source: str | Path | None,
        problem: str,
        *,
        lines: tuple[str, ...],
        where: WhereToChoose = ON_THE_COMMAND_LINE,
    ) -> None:
        self.lines = lines
        super().__init__(source, problem, where=where)

    def way(self, where: WhereToChoose) -> str:
        return where.route_line

    def choose(self, where: WhereToChoose) -> RouteLineError:
        return RouteLineError(self.source, self.bare_problem, lines=self.lines, where=where)


class TopicError(LogError, ChoiceError):
    """A log holding several topics of a kind (``kind``: imu, gnss, wheel, truth) opened
    without choosing one. ``found`` are the candidates; the message lists every topic of the
    log, ``topics``, after where to choose."""

    def __init__(
        self,
        source: str | Path | None,
        problem: str,
        *,
        kind: str,
        found: tuple[str, ...],
        topics: str = "",
        where: WhereToChoose = ON_THE_COMMAND_LINE,
    ) -> None:
        self.kind = kind
        self.found = found
        self.topics = topics
        listing = f" (topics: {topics})" if topics else ""
        super().__init__(source, problem, where=where, listing=listing)

    def way(self, where: WhereToChoose) -> str:
        return where.topic.format(kind=self.kind)

    def choose(self, where: WhereToChoose) -> TopicError:
        return TopicError(
            self.source,
            self.bare_problem,
            kind=self.kind,
            found=self.found,
            topics=self.topics,
            where=where,
        )


@contextmanager
def choices_said(where: WhereToChoose) -> Iterator[None]:
    """A :class:`ChoiceError` raised inside says where to choose as ``where`` does."""
    try:
        yield
    except ChoiceError as exc:
        if where == ON_THE_COMMAND_LINE:
            raise
        raise exc.choose(where) from None


WARNING_LINES_NAMED = 5
"""A warning about more items of one kind than this (IMU gaps, outages) names the first
``WARNING_LINES_NAMED - 1`` and sums the rest up in one line: a log cut into thousands of gaps
gets a few warning lines, not thousands."""


def named_and_summed(items: Sequence[T]) -> tuple[Sequence[T], Sequence[T]]:
    """The items a warning gives a line each, and the rest its last line sums up: all of them
    when there are at most :data:`WARNING_LINES_NAMED`, else all but the summary's line."""
    named = len(items) if len(items) <= WARNING_LINES_NAMED else WARNING_LINES_NAMED - 1
    return items[:named], items[named:]
