"""Time in the inspector: navigation over frames and attempts, a tab's playhead, and the
outages as typed."""

from __future__ import annotations

import pytest
from fake_runs import T0, make_run

from estimator.errors import ConfigError
from inspector.timeline import Playhead, Timeline, format_outages, parse_outages


def test_timeline_navigation():
    tl = Timeline.of_run(make_run(rejected=(2, 4)))
    assert tl.n_frames == 2000 and tl.duration == pytest.approx(99.95)
    assert tl.step(0.0, 1) == pytest.approx(0.05)
    assert tl.step(0.0, -1) == 0.0
    assert tl.step(99.0, 1000) == pytest.approx(99.95)
    # attempts at 40, 45, 50, 55, 60 s; 50 and 60 rejected
    assert tl.next_match(0.0) == 0
    assert tl.next_match(40.0) == 1
    assert tl.previous_match(45.0) == 0
    assert tl.previous_match(40.0) is None
    assert tl.next_match(0.0, rejected_only=True) == 2
    assert tl.next_match(50.0, rejected_only=True) == 4
    assert tl.next_match(60.0, rejected_only=True) is None
    assert tl.match_at(47.0) == 1 and tl.match_at(39.0) is None


def test_playhead_plays_at_speed_and_stops_at_the_end():
    tl = Timeline.of_run(make_run())
    ph = Playhead(t=10.0, playing=True, speed=5.0)
    ph.advance(tl, 0.5)
    assert ph.t == pytest.approx(12.5)
    ph.advance(tl, 100.0)
    assert not ph.playing and ph.t == pytest.approx(tl.duration)


def test_time_is_relative_to_the_log_start():
    tl = Timeline.of_run(make_run())
    assert tl.t[0] == 0.0
    assert tl.match_t[0] == pytest.approx(40.0)
    assert make_run().t0 == T0


def test_outage_text_reads_like_the_outage_option_and_writes_back():
    assert parse_outages("") == parse_outages("  ,  ") == ()
    assert parse_outages("90:120, 30:60") == ((30.0, 60.0), (90.0, 120.0))  # sorted
    assert parse_outages("30:60,30:60, 12.5:20") == ((12.5, 20.0), (30.0, 60.0))
    assert format_outages(((12.5, 20.0), (30.0, 60.0))) == "12.5:20, 30:60"
    assert parse_outages(format_outages(((12.5, 20.0), (30.0, 60.0)))) == (
        (12.5, 20.0),
        (30.0, 60.0),
    )
    for bad, why in (
        ("30", "is not START:END"),
        ("30:", "is not START:END"),
        ("30-60", "is not START:END"),
        ("30:60, 90", "is not START:END"),
        ("60:30", "END must be after START"),
        ("30:30", "END must be after START"),
        ("30:nan", "must be finite numbers"),
        ("30:inf", "must be finite numbers"),
        ("-100:-50", "negative times"),
    ):
        with pytest.raises(ConfigError, match=why) as info:
            parse_outages(bad)
        assert str(info.value).startswith("GNSS outages: ") and "\n" not in str(info.value)
