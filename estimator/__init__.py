"""routefuse estimator: log and route I/O, the local ENU frame, the error-state EKF with
route-constrained pseudo-position updates, metrics and the tunnel simulator.

Pure computation; never imports the inspector or viser.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimator._lazy import lazy_getattr

if TYPE_CHECKING:
    from estimator.errors import ConfigError, LogError, RouteError, RoutefuseError
    from estimator.log import GnssData, ImuData, Log, TopicInfo, TruthData, WheelData
    from estimator.nav.frames import LocalFrame
    from estimator.params import Params, load_params, params_to_toml, save_params
    from estimator.results import (
        Epochs,
        FitSummary,
        Gate,
        GateDecision,
        HeadingObservation,
        LongWindow,
        MatchRecord,
        Rival,
        Run,
    )
    from estimator.route import Projection, Route

_HOME = {
    "ConfigError": "estimator.errors",
    "LogError": "estimator.errors",
    "RouteError": "estimator.errors",
    "RoutefuseError": "estimator.errors",
    "GnssData": "estimator.log",
    "ImuData": "estimator.log",
    "Log": "estimator.log",
    "TopicInfo": "estimator.log",
    "TruthData": "estimator.log",
    "WheelData": "estimator.log",
    "LocalFrame": "estimator.nav.frames",
    "Params": "estimator.params",
    "load_params": "estimator.params",
    "params_to_toml": "estimator.params",
    "save_params": "estimator.params",
    "Epochs": "estimator.results",
    "FitSummary": "estimator.results",
    "Gate": "estimator.results",
    "GateDecision": "estimator.results",
    "HeadingObservation": "estimator.results",
    "LongWindow": "estimator.results",
    "MatchRecord": "estimator.results",
    "Rival": "estimator.results",
    "Run": "estimator.results",
    "Projection": "estimator.route",
    "Route": "estimator.route",
}
"""Where each public name lives: imported on first use, so that importing one light module
(``estimator.errors`` for the CLI's parser) does not import numpy, pyproj and the rest."""


__getattr__ = lazy_getattr(__name__, _HOME)


__all__ = [
    "ConfigError",
    "Epochs",
    "FitSummary",
    "Gate",
    "GateDecision",
    "GnssData",
    "HeadingObservation",
    "ImuData",
    "LocalFrame",
    "Log",
    "LogError",
    "LongWindow",
    "MatchRecord",
    "Params",
    "Projection",
    "Rival",
    "Route",
    "RouteError",
    "RoutefuseError",
    "Run",
    "TopicInfo",
    "TruthData",
    "WheelData",
    "load_params",
    "params_to_toml",
    "save_params",
]
