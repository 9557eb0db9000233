"""Time in the inspector: a session's frames and match attempts on the relative clock, one tab's
playhead over them, and the injected GNSS outages as the user types them."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimator.errors import ConfigError
from estimator.results import Run
from inspector.cli.options import parse_outage

F64 = NDArray[np.float64]

Outages = tuple[tuple[float, float], ...]
"""injected GNSS outages: (start, end) seconds after the log start, as ``--outage START:END``"""
MAX_OUTAGES = 100
"""outages one request may inject (each costs both runs a little)"""
MAX_OUTAGE_TEXT = 4000
"""characters the outage field may hold (a hundred outages fit with room)"""
PLAY_SPEEDS = ("0.25x", "0.5x", "1x", "2x", "5x", "10x", "20x", "50x")
"""the playback speeds a tab offers (the only ones it accepts)"""


@dataclass(frozen=True)
class Timeline:
    """Frames and match attempts of a session on the relative clock (seconds after the log
    start), with the navigation a person uses: step, next/previous attempt, next rejection."""

    t: F64
    """(N,) frame times, s after start"""
    match_t: F64
    """(A,) attempt times, s after start"""
    match_accepted: NDArray[np.bool_]

    @classmethod
    def of_run(cls, run: Run) -> Timeline:
        return cls(
            t=np.asarray(run.epochs.t, np.float64) - run.t0,
            match_t=np.array([m.t - run.t0 for m in run.matches], np.float64),
            match_accepted=np.array([m.accepted for m in run.matches], bool),
        )

    @property
    def n_frames(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    def clamp(self, t: float) -> float:
        return float(np.clip(t, self.t[0], self.t[-1])) if len(self.t) else 0.0

    def checked_time(self, t: float | str) -> float:
        """``t`` (a slider's value from the browser) when it is a time of this timeline, to the
        slider's rounding; anything else is refused."""
        try:
            value = float(t)
        except (TypeError, ValueError):
            value = math.nan
        end = max(self.duration, 0.0)
        if not (math.isfinite(value) and -0.01 <= value <= end + 0.01 * max(1.0, end)):
            raise ConfigError("time", f"{str(t)[:40]} s is not a time in this log (0 to {end:g} s)")
        return self.clamp(value)

    def frame_at(self, t: float) -> int:
        """The last frame at or before ``t`` (clamped)."""
        i = np.searchsorted(self.t, t + 1e-9, side="right") - 1
        return int(np.clip(i, 0, len(self.t) - 1))

    def step(self, t: float, frames: int) -> float:
        """The time ``frames`` frames away from the frame shown at ``t``."""
        return float(self.t[int(np.clip(self.frame_at(t) + frames, 0, len(self.t) - 1))])

    def match_at(self, t: float) -> int | None:
        """The last attempt at or before ``t``."""
        i = int(np.searchsorted(self.match_t, t + 1e-9, side="right")) - 1
        return i if i >= 0 else None

    def next_match(self, t: float, *, rejected_only: bool = False) -> int | None:
        """The first attempt strictly after ``t``."""
        idx = np.flatnonzero(self.match_t > t + 1e-9)
        if rejected_only:
            idx = idx[~self.match_accepted[idx]]
        return int(idx[0]) if len(idx) else None

    def previous_match(self, t: float, *, rejected_only: bool = False) -> int | None:
        """The last attempt strictly before ``t``."""
        idx = np.flatnonzero(self.match_t < t - 1e-9)
        if rejected_only:
            idx = idx[~self.match_accepted[idx]]
        return int(idx[-1]) if len(idx) else None


@dataclass
class Playhead:
    """One tab's position in time and playback state (kept per browser tab)."""

    t: float = 0.0
    playing: bool = False
    speed: float = 1.0

    def advance(self, timeline: Timeline, wall_dt: float) -> None:
        """Move by ``wall_dt`` seconds of wall time at the chosen speed; stop at the end."""
        if not self.playing:
            return
        t = self.t + wall_dt * self.speed
        if t >= timeline.duration:
            t, self.playing = timeline.duration, False
        self.t = timeline.clamp(t)


def parse_speed(label: object) -> float:
    """The playback speed of one of :data:`PLAY_SPEEDS` (a browser may send anything)."""
    if label not in PLAY_SPEEDS:
        raise ConfigError("speed", f"{str(label)[:40]!r} is not one of {', '.join(PLAY_SPEEDS)}")
    return float(str(label).rstrip("x"))


def parse_outages(text: str) -> Outages:
    """Outages typed as ``30:60, 90:120`` (each part read by the ``--outage`` parser, so the
    command line and the UI accept the same values); empty text means none. At most
    :data:`MAX_OUTAGE_TEXT` characters and :data:`MAX_OUTAGES` outages."""
    if len(text) > MAX_OUTAGE_TEXT:
        raise ConfigError(
            "GNSS outages", f"{len(text)} characters: at most {MAX_OUTAGE_TEXT} are read"
        )
    parts = [p.strip() for p in text.split(",")]
    try:
        return normalise_outages(parse_outage(p) for p in parts if p)
    except ConfigError as exc:
        raise ConfigError("GNSS outages", exc.problem) from None


def normalise_outages(outages: Iterable[tuple[float, float]]) -> Outages:
    """Sorted float pairs, checked: the same outages typed in another order are the same
    request, so they do not re-run."""
    out: list[tuple[float, float]] = []
    for a, b in outages:
        if len(out) == MAX_OUTAGES:
            raise ConfigError("GNSS outages", f"more than {MAX_OUTAGES} outages")
        a, b = float(a), float(b)
        if not (np.isfinite(a) and np.isfinite(b)) or not b > a:
            raise ConfigError("GNSS outages", f"{a:g}:{b:g}: END must be after START")
        out.append((a, b))
    return tuple(sorted(set(out)))


def format_outages(outages: Outages) -> str:
    """The text :func:`parse_outages` reads back (``30:60, 90:120``)."""
    return ", ".join(f"{a:g}:{b:g}" for a, b in outages)
