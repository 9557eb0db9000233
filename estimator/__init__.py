"""routefuse estimator: log and route I/O, the local ENU frame, the error-state EKF with
route-constrained pseudo-position updates, metrics and the tunnel simulator.

Pure computation; never imports the inspector or viser.
"""

from .errors import ConfigError, LogError, RouteError, RoutefuseError
from .geo import LocalFrame
from .log import GnssData, ImuData, Log, TopicInfo, TruthData, WheelData
from .params import Params, load_params, params_to_toml, save_params
from .results import Epochs, GateDecision, MatchRecord, Run
from .route import Projection, Route

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
