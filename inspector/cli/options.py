"""Options shared by subcommands: estimator parameters (generated from :class:`Params`) and
log-loading options."""

from __future__ import annotations

import argparse
import math
from typing import Any

from estimator.errors import ConfigError
from estimator.params import Params, load_params, param_specs, parse_assignments, with_values


def _flag(name: str) -> str:
    return "--" + name.replace(".", "-").replace("_", "-")


def add_param_options(parser: argparse.ArgumentParser) -> None:
    """``--config FILE``, ``--set NAME=VALUE`` and one flag per parameter (declared once in
    :mod:`estimator.params`)."""
    g = parser.add_argument_group(
        "estimator parameters",
        "precedence: defaults < --config FILE < --set NAME=VALUE < the per-parameter flags",
    )
    g.add_argument("--config", metavar="FILE.toml", help="parameters from a TOML file")
    g.add_argument(
        "--set",
        metavar="NAME=VALUE",
        action="append",
        default=[],
        help="set a parameter by dotted name, e.g. gates.max_residual_m=2.5",
    )
    for spec in param_specs():
        unit = f" [{spec.unit}]" if spec.unit else ""
        g.add_argument(
            _flag(spec.name),
            dest=f"param:{spec.name}",
            metavar="V",
            default=None,
            help=f"{spec.doc}{unit} (default {spec.default})".replace("%", "%%"),
        )


def params_from_args(args: argparse.Namespace) -> Params:
    params = load_params(args.config) if getattr(args, "config", None) else Params()
    params = with_values(params, parse_assignments(getattr(args, "set", []) or []), "--set")
    flags: dict[str, Any] = {
        k.removeprefix("param:"): v
        for k, v in vars(args).items()
        if k.startswith("param:") and v is not None
    }
    return with_values(params, flags, "command line")


def add_topic_options(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("topics", "needed only when a message type has several topics")
    for kind in ("imu", "gnss", "wheel", "truth"):
        g.add_argument(
            f"--{kind}-topic",
            metavar="TOPIC",
            default=None,
            help=f"topic to read the {kind} stream from",
        )
    g.add_argument(
        "--no-wheel",
        action="store_true",
        help="leave the wheel speed out (IMU + GNSS only) even when the log has a wheel topic",
    )


def add_route_feature_option(parser: argparse.ArgumentParser) -> None:
    """``--route-feature NAME_OR_INDEX``: the line of a route file holding several (the one
    declaration of run, export, info and serve; :func:`estimator.io.routefile.choose_line`
    reads it)."""
    parser.add_argument(
        "--route-feature",
        metavar="NAME_OR_INDEX",
        default=None,
        help="which line of a route file that holds several (its name, or its index from 0)",
    )


def add_outage_option(parser: argparse.ArgumentParser) -> None:
    """``--outage START:END`` (repeatable), read with :func:`parse_outage`."""
    parser.add_argument(
        "--outage",
        metavar="START:END",
        action="append",
        default=[],
        help="remove GNSS between START and END seconds after the log start (repeatable)",
    )


def parse_outage(text: str) -> tuple[float, float]:
    """``START:END`` in seconds after the log start (a bad value is a one-line
    :class:`ConfigError`, so the CLI and the inspector report it alike)."""
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        raise ConfigError("--outage", f"{text[:60]!r} is not START:END in seconds") from None
    shown = text if len(text) <= 60 else text[:57] + "..."
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ConfigError("--outage", f"{shown!r}: START and END must be finite numbers")
    if a < 0 or b < 0:
        raise ConfigError("--outage", f"{shown!r}: negative times; seconds after the log start")
    if not b > a:
        raise ConfigError("--outage", f"{shown!r}: END must be after START")
    return a, b
