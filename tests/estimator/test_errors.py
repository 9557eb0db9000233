"""One way of saying where to choose among what a file holds several of: a route file's lines
and a log's topics are both :class:`ChoiceError` s raised with the command line's flags and
re-worded for another place (the inspector) by :func:`choices_said`."""

from __future__ import annotations

import pytest

from estimator.errors import (
    ON_THE_COMMAND_LINE,
    ChoiceError,
    LogError,
    RouteError,
    RouteLineError,
    TopicError,
    WhereToChoose,
    choices_said,
)

ELSEWHERE = WhereToChoose(route_line="in the line picker", topic="in the {kind} picker")


def _errors() -> tuple[RouteLineError, TopicError]:
    return (
        RouteLineError("r.geojson", "the file has 2 lines (0: a, 1: b)", lines=("a", "b")),
        TopicError(
            "x.bag",
            "several imu topics: /a, /b",
            kind="imu",
            found=("/a", "/b"),
            topics="/a (Imu), /b (Imu)",
        ),
    )


def test_both_say_where_to_choose_on_the_command_line_by_default():
    line, topic = _errors()
    assert str(line) == (
        "r.geojson: the file has 2 lines (0: a, 1: b); choose one with --route-feature "
        "NAME_OR_INDEX"
    )
    assert str(topic) == (
        "x.bag: several imu topics: /a, /b; choose one with --imu-topic TOPIC "
        "(topics: /a (Imu), /b (Imu))"
    )
    assert isinstance(line, RouteError) and isinstance(topic, LogError)


@pytest.mark.parametrize("index", [0, 1])
def test_choices_said_rewords_either_keeping_what_it_carries(index):
    raised = _errors()[index]
    with pytest.raises(ChoiceError) as caught, choices_said(ELSEWHERE):
        raise raised
    said = caught.value
    assert type(said) is type(raised) and said.source == raised.source
    assert said.bare_problem == raised.bare_problem and said.where == ELSEWHERE
    assert str(said) == {
        0: "r.geojson: the file has 2 lines (0: a, 1: b); choose one in the line picker",
        1: "x.bag: several imu topics: /a, /b; choose one in the imu picker "
        "(topics: /a (Imu), /b (Imu))",
    }[index]
    with pytest.raises(ChoiceError) as kept, choices_said(ON_THE_COMMAND_LINE):
        raise raised
    assert kept.value is raised


def test_other_errors_pass_through_unchanged():
    other = RouteError("r.geojson", "no line geometry found")
    with pytest.raises(RouteError) as caught, choices_said(ELSEWHERE):
        raise other
    assert caught.value is other


def test_a_choice_error_that_does_not_say_where_to_choose_cannot_be_made():
    """``way`` and ``choose`` are abstract: an exception's ``BaseException.__new__`` does not
    refuse an abstract class by itself, ``ChoiceError.__new__`` does."""

    class WayOnly(ChoiceError):
        def way(self, where: WhereToChoose) -> str:
            return where.route_line

    with pytest.raises(TypeError, match=r"abstract class WayOnly .* 'choose'$"):
        WayOnly("r.geojson", "the file has 2 lines")
    with pytest.raises(TypeError, match=r"abstract class ChoiceError .* 'choose', 'way'$"):
        ChoiceError("r.geojson", "the file has 2 lines")  # type: ignore[abstract]
    assert not RouteLineError.__abstractmethods__ and not TopicError.__abstractmethods__
