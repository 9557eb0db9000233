"""How the inspector, its exports and the command line print a difference of two figures."""

from __future__ import annotations


def signed(value: float, digits: int = 3) -> str:
    """A difference with its sign, ``+0.012`` / ``-0.012``; one that rounds to zero (-0.0, or
    -0.0004 at 3 digits) is ``0.000``, without a sign, so that a comparison of two equal runs
    does not read as a change."""
    text = f"{value:+.{digits}f}"
    return text[1:] if float(text) == 0.0 else text
