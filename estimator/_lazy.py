"""Package faces that import their names on first use.

A package's ``__init__`` lists where each public name lives; the module holding it is imported
when the name is first read, so importing one light module of a package (the CLI's parser needs
``estimator.errors`` and ``estimator.io``'s wording) does not import numpy, numba or pyproj."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_getattr(package: str, homes: Mapping[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: a name of ``homes`` (name -> module) is
    imported from its module, kept in the package's namespace, and returned."""
    namespace = sys.modules[package].__dict__

    def __getattr__(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(home), name)
        namespace[name] = value
        return value

    return __getattr__
