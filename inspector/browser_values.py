"""What a browser may send, checked before the controller uses it: a tab's values arrive as
anything viser can cast to the control's type, and one tab's bad value must never reach the
state every tab shares."""

from __future__ import annotations

import math
from typing import Any, Literal

from estimator.errors import ConfigError, RoutefuseError
from estimator.params import Params, get_param, with_values

ProposedMethod = Literal["proposed", "paper"]
PROPOSED_METHODS: tuple[ProposedMethod, ...] = ("proposed", "paper")
"""the methods a session compares with the baseline (the 'method' dropdown's choices)"""


def checked_method(value: object) -> ProposedMethod:
    """``value`` when it is one of :data:`PROPOSED_METHODS` (a browser may send anything)."""
    for method in PROPOSED_METHODS:
        if value == method:
            return method
    raise RoutefuseError(
        "method", f"{str(value)[:80]!r} is not one of {', '.join(PROPOSED_METHODS)}"
    )


def with_param(params: Params, name: str, value: Any) -> Params:
    """``params`` with one parameter set from a browser's value: checked against its
    declaration (:func:`estimator.params.with_values`) and, as no run can use them, refused
    when not finite."""
    try:
        changed = with_values(params, {name: value}, "parameter panel")
    except (OverflowError, RecursionError) as exc:
        raise ConfigError("parameter panel", f"{name}: invalid value ({exc})") from None
    new = get_param(changed, name)
    numbers = new if isinstance(new, tuple) else (new,)
    if any(isinstance(v, float) and not math.isfinite(v) for v in numbers):
        raise ConfigError("parameter panel", f"{name}: {str(value)[:80]} is not a finite number")
    return changed
