"""The parameter tree's leaves as specs, and their conversion from CLI strings, TOML values and GUI
widgets: every value that enters :class:`~estimator.params.Params` is checked here against the
type, bounds and choices its declaration gives."""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import stat
import sys
from collections.abc import Iterator
from dataclasses import dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, get_args, get_type_hints

from estimator.errors import ConfigError
from estimator.params.declarations import Params


@dataclass(frozen=True)
class ParamSpec:
    """One leaf parameter: its dotted name, type, default and presentation metadata."""

    name: str
    group: str
    type: Any
    default: Any
    doc: str
    unit: str
    lo: float | None
    hi: float | None
    step: float | None
    choices: tuple[str, ...] | None


def param_specs(cls: type = Params, prefix: str = "") -> Iterator[ParamSpec]:
    """Every leaf parameter of the tree, in declaration order."""
    hints = get_type_hints(cls)
    for f in fields(cls):
        tp = hints[f.name]
        if isinstance(tp, type) and is_dataclass(tp):
            yield from param_specs(tp, f"{prefix}{f.name}.")
            continue
        default = f.default
        if default is dataclasses.MISSING and f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        m = f.metadata
        yield ParamSpec(
            name=f"{prefix}{f.name}",
            group=prefix.rstrip(".") or "general",
            type=tp,
            default=default,
            doc=m.get("doc", ""),
            unit=m.get("unit", ""),
            lo=m.get("lo"),
            hi=m.get("hi"),
            step=m.get("step"),
            choices=m.get("choices") or _literal(tp),
        )


def _literal(tp: Any) -> tuple[str, ...] | None:
    args = get_args(tp)
    return tuple(args) if args and all(isinstance(a, str) for a in args) else None


def get_param(params: Params, name: str) -> Any:
    obj: Any = params
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def _spec(name: str) -> ParamSpec:
    for s in param_specs():
        if s.name == name:
            return s
    close = difflib.get_close_matches(name, [s.name for s in param_specs()], n=3)
    hint = f"did you mean {', '.join(close)}?" if close else "see routefuse run --help"
    raise ConfigError(None, f"unknown parameter {_short(repr(name))} ({hint})")


def coerce_value(spec: ParamSpec, value: Any, source: str | None = None) -> Any:
    """Convert and check one value (from TOML, a CLI string or a GUI widget)."""
    where = source
    tp = spec.type
    try:
        if tp is bool:
            if isinstance(value, str):
                if value.lower() not in ("true", "false", "1", "0", "yes", "no", "on", "off"):
                    raise ValueError(value)
                value = value.lower() in ("true", "1", "yes", "on")
            elif not isinstance(value, bool) and value not in (0, 1):
                raise ValueError("true or false is required")
            return bool(value)
        if tp is int:
            if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                raise ValueError("a whole number is required")
            out: Any = int(value)
        elif tp is float or tp == (float | None):
            if value is None or (isinstance(value, str) and value.lower() in ("none", "")):
                if tp is float:
                    raise ValueError("a number is required")
                return None
            out = float(value)
        elif str(tp).startswith("tuple"):
            items = value.split(",") if isinstance(value, str) else list(value)
            out = tuple(float(v) for v in items)
            if len(out) != len(spec.default):
                raise ValueError(f"expected {len(spec.default)} numbers")
            for item in out:
                _check_number(spec, item, where)
            return out
        else:
            out = str(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(
            where, f"{spec.name}: invalid value {_short(repr(value))} ({_short(str(exc))})"
        ) from None
    if spec.choices and out not in spec.choices:
        raise ConfigError(where, f"{spec.name}: {_short(repr(out))} is not one of {spec.choices}")
    if isinstance(out, int | float) and not isinstance(out, bool):
        _check_number(spec, out, where)
    return out


MAX_MAGNITUDE = 1e9
"""Bound of a number without declared bounds (a tuple's items: a lever arm in metres)."""


def _check_number(spec: ParamSpec, value: float, where: str | None) -> None:
    """A one-line :class:`ConfigError` for a value that is not finite or out of bounds. An
    ``int`` is compared as it is: it may be too large to convert to a float."""
    if isinstance(value, float) and value != value:
        raise ConfigError(where, f"{spec.name}: NaN is not a valid value (not a finite number)")
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(where, f"{spec.name}: {value} is not a finite number")
    lo = spec.lo if spec.lo is not None else (-MAX_MAGNITUDE if spec.type is not int else None)
    hi = spec.hi if spec.hi is not None else (MAX_MAGNITUDE if spec.type is not int else None)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigError(where, f"{spec.name}={_short(str(value))} is outside [{lo}, {hi}]")


def _short(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def with_values(params: Params, values: dict[str, Any], source: str | None = None) -> Params:
    """A copy of ``params`` with dotted-name values replaced (checked and converted)."""
    for name, raw in values.items():
        spec = _spec(name)
        params = _replace_path(params, name.split("."), coerce_value(spec, raw, source))
    return params


def _replace_path(obj: Any, path: list[str], value: Any) -> Any:
    if len(path) == 1:
        return replace(obj, **{path[0]: value})
    return replace(obj, **{path[0]: _replace_path(getattr(obj, path[0]), path[1:], value)})


def parse_assignments(items: list[str]) -> dict[str, str]:
    """``["gates.max_residual_m=2.5", ...]`` from ``--set`` into a dict."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(None, f"--set expects NAME=VALUE, got {item!r}")
        out[name.strip()] = value.strip()
    return out


MAX_CONFIG_BYTES = 1_000_000
"""A parameter file is a few kB; nothing larger (or not a regular file: a fifo, /dev/zero) is
read."""
MAX_KEY_PARTS = 32
"""Parts of a dotted TOML key (``[a.b.c]``, ``a.b.c = 1``) a config may have. A parameter's name
has two (``gates.min_pairs``); tomllib's time grows with the square of a key's parts (a
100 000-part table header took 17 s, a 1 MB one would take minutes), so a deeper key is refused
before it is parsed."""

_TOML_KEY_PART = r"""(?:[A-Za-z0-9_-]++|"(?:[^"\\\n]|\\.)*+"|'[^'\n]*+')"""
_DEEP_TOML_KEY = re.compile(
    rf"(?<![A-Za-z0-9_\-\"'\\]){_TOML_KEY_PART}"
    rf"(?:[ \t]*+\.[ \t]*+{_TOML_KEY_PART}){{{MAX_KEY_PARTS}}}"
)
"""More than :data:`MAX_KEY_PARTS` bare or quoted key parts joined by dots, anywhere in the text
(a string or a comment of 33 dotted words is refused too: no parameter value is one). Started
only where a part can start, with possessive repeats, so the search is linear in the text."""


def load_params(path: str | Path, base: Params | None = None) -> Params:
    """Parameters from a TOML file (tables named like the groups; unknown keys are errors)."""
    import tomllib  # here, not above: a run without a config file does not need it

    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(path, "not a regular file; a config is a TOML file")
        if info.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(path, f"config is {info.st_size} bytes; over {MAX_CONFIG_BYTES}")
        text = path.read_text(encoding="utf-8")
        if _DEEP_TOML_KEY.search(text):
            raise ConfigError(
                path,
                f"a key of more than {MAX_KEY_PARTS} dotted parts; parameter names have two "
                "(gates.min_pairs)",
            )
        data = tomllib.loads(text)
    except OSError as exc:
        raise ConfigError(path, f"cannot read config: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(path, f"not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(path, "not a config: arrays or tables nested too deeply") from None
    except ValueError:  # tomllib's int(): more digits than Python converts
        raise ConfigError(
            path,
            f"not valid TOML: an integer of more than {sys.get_int_max_str_digits()} digits",
        ) from None
    flat: dict[str, Any] = {}
    tables: list[tuple[str, Iterator[tuple[str, Any]]]] = [("", iter(data.items()))]
    while tables:
        prefix, items = tables[-1]
        for k, v in items:
            if isinstance(v, dict):
                tables.append((f"{prefix}{k}.", iter(v.items())))
                break
            flat[f"{prefix}{k}"] = v
        else:
            tables.pop()
    known = {s.name for s in param_specs()}
    for name in flat:
        if name not in known:
            raise ConfigError(path, f"unknown parameter {_short(repr(name))}")
    return with_values(base or Params(), flat, str(path))


def params_to_toml(params: Params) -> str:
    """TOML text that :func:`load_params` reads back to an equal ``Params``."""
    tree: dict[str, Any] = {}
    for spec in param_specs():
        value = get_param(params, spec.name)
        if value is None:
            continue
        *groups, leaf = spec.name.split(".")
        node = tree
        for g in groups:
            node = node.setdefault(g, {})
        node[leaf] = list(value) if isinstance(value, tuple) else value
    head = "# routefuse estimator parameters (routefuse run --config FILE)\n"
    import tomli_w

    return head + tomli_w.dumps(tree)


def save_params(params: Params, path: str | Path) -> None:
    Path(path).write_text(params_to_toml(params), encoding="utf-8")
