"""The navigation model routefuse computes in: the local ENU frame of a session
(:class:`LocalFrame`, exact geodetic <-> ENU), the Earth's gravity and rotation, and one rotation
convention (body forward-left-up to ENU, quaternions scalar-first). This is the package's public
face; names are imported on first use, so that reading a rotation does not import pyproj."""

from __future__ import annotations

from typing import TYPE_CHECKING

from estimator._lazy import lazy_getattr

if TYPE_CHECKING:
    from estimator.nav.earth import OMEGA_IE, earth_rate_n, gravity_n, normal_gravity
    from estimator.nav.frames import LocalFrame
    from estimator.nav.rotation import (
        body_rate_from_euler_rates,
        dcm_from_euler,
        dcm_from_quaternion,
        euler_from_dcm,
        quaternion_from_ros,
        yaw_from_quaternion,
    )

_HOME = {
    "OMEGA_IE": "estimator.nav.earth",
    "earth_rate_n": "estimator.nav.earth",
    "gravity_n": "estimator.nav.earth",
    "normal_gravity": "estimator.nav.earth",
    "LocalFrame": "estimator.nav.frames",
    "body_rate_from_euler_rates": "estimator.nav.rotation",
    "dcm_from_euler": "estimator.nav.rotation",
    "dcm_from_quaternion": "estimator.nav.rotation",
    "euler_from_dcm": "estimator.nav.rotation",
    "quaternion_from_ros": "estimator.nav.rotation",
    "yaw_from_quaternion": "estimator.nav.rotation",
}

__all__ = [
    "OMEGA_IE",
    "LocalFrame",
    "body_rate_from_euler_rates",
    "dcm_from_euler",
    "dcm_from_quaternion",
    "earth_rate_n",
    "euler_from_dcm",
    "gravity_n",
    "normal_gravity",
    "quaternion_from_ros",
    "yaw_from_quaternion",
]


__getattr__ = lazy_getattr(__name__, _HOME)
