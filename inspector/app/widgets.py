"""What the panels share about viser's controls."""

from __future__ import annotations

import html
import re
from typing import Any

import viser
from viser._gui_handles import GuiProgressBarHandle  # viser does not export it

Event = viser.GuiEvent[Any]
"""a control's update or click, as its callbacks receive it"""


def show_value(control: viser.GuiInputHandle[Any] | GuiProgressBarHandle, value: Any) -> None:
    """Set what a control shows (viser sends it to the browser and runs its update callbacks)."""
    # viser's control classes inherit a `value` field from their props dataclass beside the
    # `value` property with its setter, which mypy takes for a read-only property
    control.value = value  # type: ignore[misc]  # a settable property, see above


_MARKDOWN_PUNCTUATION = re.compile(r"([\\`*_{}\[\]()#+\-.!|~])")


def markdown_text(text: object) -> str:
    """``text`` (a file name, a path, anything a file or the user chose) as literal text in
    viser's markdown, which renders raw HTML unsanitised: markdown punctuation backslash-escaped,
    then HTML's special characters as entities (the standard library's ``html.escape``)."""
    return html.escape(_MARKDOWN_PUNCTUATION.sub(r"\\\1", str(text)))


def wrapping_anywhere(markdown: str, *, style: str = "") -> str:
    """``markdown`` (already escaped) in a span whose text may break anywhere: a file name or a
    path has no space to wrap at and ran off the panel. ``style`` adds CSS of our own, never
    anything a file or the user chose."""
    return f'<span style="overflow-wrap: anywhere{style}">{markdown}</span>'
