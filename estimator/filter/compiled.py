"""The one way the filter compiles a kernel: numba nopython, cached on disk, numpy's error model
(a division by zero gives inf/NaN, which the divergence check then catches, instead of raising).

The decorator keeps the function's own signature for the type checker (numba's are untyped)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

from numba import njit

Fn = TypeVar("Fn", bound=Callable[..., Any])


def kernel(fn: Fn) -> Fn:
    """``fn`` compiled with ``njit(cache=True, error_model="numpy")``."""
    return cast(Fn, njit(cache=True, error_model="numpy")(fn))
