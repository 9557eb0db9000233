"""The inspector's browser UI: :class:`InspectorApp` wires a viser server to a controller and
gives every tab a :class:`ClientView`, composed of panels (playback, match, plots, parameters,
files) that each own their controls and callbacks."""

from inspector.app.application import PLAY_RATE_HZ, InspectorApp
from inspector.app.match import MatchPanel, match_markdown
from inspector.app.playback import PlaybackPanel, status_markdown
from inspector.app.view import ClientView

__all__ = [
    "PLAY_RATE_HZ",
    "ClientView",
    "InspectorApp",
    "MatchPanel",
    "PlaybackPanel",
    "match_markdown",
    "status_markdown",
]
