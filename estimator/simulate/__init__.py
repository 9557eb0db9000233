"""Tunnel scenario simulator: truth, MEMS IMU, wheel speed, GNSS with tunnel outages, and the
SD-map route, written as a ROS 2 bag plus GeoJSON.

The navigation model (frames, gravity, Earth rate, specific force) is in :mod:`.model`; the
estimator's mechanisation must match it. Typical use::

    sim = simulate("long_tunnel", seed=0)               # or perfect=True for ideal sensors
    log, route = sim.log(), sim.route()
    sim.write("out/")                                   # out/long_tunnel.mcap + .route.geojson
"""

from .road import Piece, Road, pieces_from_polyline, straight, turn
from .scenario import GnssOutage, Scenario
from .scenarios import SCENARIOS, get_scenario, long_drive, polyline_scenario
from .sdmap import RouteModel
from .sensors import GnssErrorModel, ImuErrorModel, ImuErrors, WheelErrorModel
from .simulation import Simulation, simulate
from .trajectory import Kinematics, Trajectory

__all__ = [
    "SCENARIOS",
    "GnssErrorModel",
    "GnssOutage",
    "ImuErrorModel",
    "ImuErrors",
    "Kinematics",
    "Piece",
    "Road",
    "RouteModel",
    "Scenario",
    "Simulation",
    "Trajectory",
    "WheelErrorModel",
    "get_scenario",
    "long_drive",
    "pieces_from_polyline",
    "polyline_scenario",
    "simulate",
    "straight",
    "turn",
]
