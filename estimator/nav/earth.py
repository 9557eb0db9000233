"""The navigation model shared by the simulator and the estimator's strapdown mechanisation.

The EKF integrates in a fixed local-level ENU frame ``n`` whose origin is the log's local
frame origin (lat0, lon0, h0); the simulator produces its IMU data in exactly the same model,
so a perfect IMU integrated with these equations reproduces the truth:

* The frame ``n`` is Earth-fixed (the ENU axes at the origin, not re-levelled along the way).
  It rotates with the Earth at ``omega_ie_n = omega_ie * (0, cos(lat0), sin(lat0))``.
* Gravity is constant: normal gravity (Somigliana, with the free-air height term) at the
  origin latitude and height, along -U: ``g_n = (0, 0, -g0)``.
* Body axes are forward-left-up. The body-to-navigation rotation is
  ``C_nb = Rz(yaw) @ Ry(-pitch) @ Rx(roll)``: yaw is the ENU yaw of the body x axis
  (counter-clockwise from East), pitch is positive nose up, roll is positive right side down.
* Specific force and body rate, as an ideal IMU measures them:
  ``f_b = C_bn (a_n + 2 omega_ie_n x v_n - g_n)`` and ``w_ib_b = w_nb_b + C_bn omega_ie_n``,
  where ``a_n`` and ``v_n`` are the acceleration and velocity relative to the frame ``n``.
  The centripetal term ``omega x (omega x r)`` is left out (as is the change of the plumb
  line across the drive): it is below 3e-4 m/s^2 anywhere within 10 km and the estimator's
  model leaves it out too.
* The mechanisation that inverts it: ``dp/dt = v_n``,
  ``dv_n/dt = C_nb f_b + g_n - 2 omega_ie_n x v_n``,
  ``dC_nb/dt = C_nb [w_ib_b - C_bn omega_ie_n]x``.
* IMU samples are instantaneous values at their time stamps (not interval averages).
* The IMU, the GNSS antenna and the wheel-speed reference are all at the body origin (no lever
  arms); the wheel speed is the forward body speed ``|v_n|``: the body x axis is along the
  velocity (no side slip), so the non-holonomic constraint holds exactly.

Truth positions live in the same frame; ``LocalFrame.to_geodetic`` turns them into latitude,
longitude and ellipsoidal height (the tangent plane rises above the ellipsoid by
``d^2 / (2 R)``: 8 cm at 1 km, 2 m at 5 km).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

OMEGA_IE = 7.292115e-5
"""Earth rotation rate, rad/s (WGS84)."""

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius (IUGG), m: a sphere for distances that need no ellipsoid."""

_GE = 9.7803253359
_K = 0.00193185265241
_E2 = 0.00669437999013


def normal_gravity(lat_deg: float, h_m: float = 0.0) -> float:
    """Magnitude of normal gravity, m/s^2: Somigliana on WGS84 plus the free-air gradient."""
    s2 = np.sin(np.radians(lat_deg)) ** 2
    g = _GE * (1.0 + _K * s2) / np.sqrt(1.0 - _E2 * s2)
    return float(g - 3.086e-6 * h_m)


def gravity_n(lat_deg: float, h_m: float = 0.0) -> F64:
    """Gravity vector in the local ENU frame at the origin: ``(0, 0, -g0)``."""
    return np.array([0.0, 0.0, -normal_gravity(lat_deg, h_m)])


def earth_rate_n(lat_deg: float) -> F64:
    """Earth rotation expressed in the local ENU frame at the origin, rad/s."""
    lat = np.radians(lat_deg)
    return OMEGA_IE * np.array([0.0, np.cos(lat), np.sin(lat)])


def great_circle_m(lat0: ArrayLike, lon0: ArrayLike, lat1: ArrayLike, lon1: ArrayLike) -> F64:
    """Haversine distance, m, on a sphere of :data:`EARTH_RADIUS_M` (within 0.5 % of the
    ellipsoid's: enough to tell a road's segment from a joined region's, or a fix from the
    other side of the world)."""
    phi0, phi1 = np.radians(lat0), np.radians(lat1)
    half_dphi = (phi1 - phi0) / 2
    half_dlam = np.radians(np.subtract(lon1, lon0)) / 2
    h = np.sin(half_dphi) ** 2 + np.cos(phi0) * np.cos(phi1) * np.sin(half_dlam) ** 2
    distance: F64 = 2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.clip(h, 0.0, 1.0)))
    return distance
