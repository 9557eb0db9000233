"""Tunnel scenario simulator: truth, MEMS IMU, wheel speed, GNSS with tunnel outages, and the
SD-map route, written as a ROS 2 bag plus GeoJSON.

The navigation model (frames, gravity, Earth rate, specific force) is in
:mod:`estimator.nav.earth`; the estimator's mechanisation must match it. Typical use::

    sim = simulate("long_tunnel", seed=0)               # or perfect=True for ideal sensors
    log, route = sim.log(), sim.route()
    sim.write("out/")                                   # out/long_tunnel.mcap + .route.geojson
"""

from estimator.sim.road import Piece, Road, pieces_from_polyline, straight, turn
from estimator.sim.scenario import GnssOutage, Scenario
from estimator.sim.scenarios import SCENARIOS, get_scenario, long_drive, polyline_scenario
from estimator.sim.sdmap import RouteModel
from estimator.sim.sensors import GnssErrorModel, ImuErrorModel, ImuErrors, WheelErrorModel
from estimator.sim.simulation import Simulation, simulate
from estimator.sim.trajectory import Kinematics, Trajectory

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
