"""Errors that reach the user as one line: the file (or parameter) and what is wrong with it."""

from __future__ import annotations

from pathlib import Path


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


CHOOSE_LINE_BY_FLAG = "with --route-feature NAME_OR_INDEX"
"""Where a command-line user chooses the line of a route file holding several."""


class RouteLineError(RouteError):
    """A route file holding several lines opened without choosing one, or with a choice that
    names none of them. ``lines`` are the file's line names (in order); the message ends with
    where to choose one, ``how`` (the command line's flag unless the caller, such as the
    inspector, names its own control)."""

    def __init__(
        self,
        source: str | Path | None,
        problem: str,
        *,
        lines: tuple[str, ...],
        how: str = CHOOSE_LINE_BY_FLAG,
    ) -> None:
        self.lines = lines
        super().__init__(source, f"{problem}; choose one {how}")


CHOOSE_TOPIC_BY_FLAG = "with --{kind}-topic TOPIC"
"""Where a command-line user chooses the topic of a kind (``{kind}``: imu, gnss, wheel, truth)
that a log holds several of."""


class TopicError(LogError):
    """A log holding several topics of a kind (``kind``: imu, gnss, wheel, truth) opened
    without choosing one. ``found`` are the candidates; the message says where to choose one,
    ``how`` (the command line's flag unless the caller, such as the inspector, names its own
    way), as :class:`RouteLineError` does for a route file's lines, and then lists every topic
    of the log, ``topics`` (last: a notification cut short loses the listing, not the way
    out)."""

    def __init__(
        self,
        source: str | Path | None,
        problem: str,
        *,
        kind: str,
        found: tuple[str, ...],
        topics: str = "",
        how: str = CHOOSE_TOPIC_BY_FLAG,
    ) -> None:
        self.kind = kind
        self.found = found
        self.topics = topics
        self.bare_problem = problem
        listing = f" (topics: {topics})" if topics else ""
        super().__init__(source, f"{problem}; choose one {how.format(kind=kind)}{listing}")

    def choose(self, how: str) -> TopicError:
        """The same error, saying ``how`` to choose one instead."""
        return TopicError(
            self.source,
            self.bare_problem,
            kind=self.kind,
            found=self.found,
            topics=self.topics,
            how=how,
        )
