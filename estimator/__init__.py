"""routefuse estimator: log and route I/O, the local ENU frame, the error-state EKF with
route-constrained pseudo-position updates, metrics and the tunnel simulator.

Pure computation; never imports the inspector or viser.
"""

from estimator.errors import ConfigError, LogError, RouteError, RoutefuseError
from estimator.log import GnssData, ImuData, Log, TopicInfo, TruthData, WheelData
from estimator.nav.frames import LocalFrame
from estimator.params import Params, load_params, params_to_toml, save_params
from estimator.results import Epochs, GateDecision, MatchRecord, Run
from estimator.route import Projection, Route

__all__ = [
    "ConfigError",
    "Epochs",
    "GateDecision",
    "GnssData",
    "ImuData",
    "LocalFrame",
    "Log",
    "LogError",
    "MatchRecord",
    "Params",
    "Projection",
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
