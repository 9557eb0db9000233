"""The true motion of a vehicle driving a lane of a :class:`~.road.Road`, in closed form.

The vehicle keeps a constant lateral offset ``d`` from the centreline (positive = left), so at
centreline arc length ``sigma`` it is at ``c(sigma) + d n(sigma)`` and its own arc length grows
by ``J = 1 - d kappa`` per metre of centreline. Its lane speed ``u(sigma)`` is the road's speed
profile, so time is ``t(sigma) = integral J / u`` (Gauss-Legendre per metre) and a time is
mapped back to ``sigma`` by Newton's method. Everything else is differentiated analytically:

* heading = the centreline heading (no side slip), yaw rate ``kappa u / J``;
* velocity ``u (cos psi, sin psi, G)`` with the lane grade ``G = h'(sigma) / J``;
* pitch ``atan(G)`` (body x along the velocity, so the body velocity is ``(|v|, 0, 0)``);
* roll = a constant cross-fall plus ``roll_per_lateral_accel`` times the lateral acceleration
  ``u^2 kappa / J`` (body roll to the outside of a turn).

The ideal IMU follows from :mod:`.model`. Nothing is integrated from noisy data: any time can
be evaluated independently, which is what lets sensors of different rates share one truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimator.errors import ConfigError
from estimator.nav.earth import earth_rate_n, gravity_n
from estimator.nav.rotation import body_rate_from_euler_rates, dcm_from_euler
from estimator.sim.road import _GL_W, _GL_X, Road

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Kinematics:
    """The true state at a set of times, in the local ENU frame (see :mod:`.model`)."""

    t: F64
    """(N,) s: after the start of the drive from :meth:`Trajectory.at`, log time (Unix s) in
    :attr:`Simulation.truth`"""
    sigma: F64
    """(N,) centreline arc length, m"""
    position: F64
    """(N, 3) ENU, m"""
    velocity: F64
    """(N, 3) ENU, m/s"""
    acceleration: F64
    """(N, 3) ENU, m/s^2 (relative to the Earth-fixed frame)"""
    rpy: F64
    """(N, 3) roll, pitch, yaw, rad (``C_nb = Rz(yaw) Ry(-pitch) Rx(roll)``)"""
    rpy_rate: F64
    """(N, 3) time derivatives of roll, pitch, yaw, rad/s"""
    speed: F64
    """(N,) forward body speed = |velocity|, m/s"""

    @property
    def heading(self) -> F64:
        return self.rpy[:, 2]

    def c_nb(self) -> F64:
        return dcm_from_euler(self.rpy[:, 0], self.rpy[:, 1], self.rpy[:, 2])


@dataclass(frozen=True)
class Trajectory:
    """A drive along ``road`` in a lane ``lane_offset_m`` left of the centreline
    (negative = right), with the origin latitude and height that fix gravity and Earth rate."""

    road: Road
    lane_offset_m: float = -1.75
    lat0_deg: float = 45.0
    h0_m: float = 0.0
    crossfall_rad: float = 0.02
    """roll on a straight (right side down: a cambered right-hand lane)"""
    roll_per_lateral_accel: float = 0.006
    """body roll per m/s^2 of lateral acceleration, rad (about 3.4 deg/g)"""
    _t_grid: F64 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        road = self.road
        grid = road.cell_bounds
        j = 1.0 - self.lane_offset_m * road.curvature(grid)
        if np.any(j <= 0.05):
            raise ConfigError(
                None, f"lane offset {self.lane_offset_m} m is beyond a curve's centre of curvature"
            )
        dt = self._integrate_dt(grid[:-1], grid[1:])
        object.__setattr__(self, "_t_grid", np.r_[0.0, np.cumsum(dt)])

    @property
    def duration_s(self) -> float:
        return float(self._t_grid[-1])

    def _jacobian(self, sigma: F64) -> F64:
        return 1.0 - self.lane_offset_m * self.road.curvature(sigma)

    def _integrate_dt(self, a: F64, b: F64) -> F64:
        half = 0.5 * (b - a)
        x = (0.5 * (a + b))[:, None] + half[:, None] * _GL_X[None, :]
        xf = x.ravel()
        f = (self._jacobian(xf) / self.road.speed.value(xf)).reshape(x.shape)
        return (f @ _GL_W) * half

    def time_at(self, sigma: ArrayLike) -> F64:
        s = np.clip(np.atleast_1d(np.asarray(sigma, np.float64)), 0.0, self.road.length)
        g = self.road.cell_bounds
        k = np.clip(np.searchsorted(g, s, side="right") - 1, 0, len(g) - 2)
        return self._t_grid[k] + self._integrate_dt(g[k], s)

    def sigma_at(self, t: ArrayLike) -> F64:
        """Centreline arc length reached at times ``t`` (Newton on ``t(sigma)``)."""
        ta = np.atleast_1d(np.asarray(t, np.float64))
        if np.any((ta < -1e-9) | (ta > self.duration_s + 1e-9)):
            raise ConfigError(None, f"times outside the drive [0, {self.duration_s:.3f}] s")
        s = np.interp(ta, self._t_grid, self.road.cell_bounds)
        for _ in range(4):
            rate = self.road.speed.value(s) / self._jacobian(s)
            s = np.clip(s - (self.time_at(s) - ta) * rate, 0.0, self.road.length)
        return s

    def at(self, t: ArrayLike) -> Kinematics:
        """The true state at times ``t`` (s after the start, within the drive)."""
        ta = np.atleast_1d(np.asarray(t, np.float64))
        road = self.road
        d = self.lane_offset_m
        s = self.sigma_at(ta)
        kappa = road.curvature(s)
        dkappa = road.curvature_rate(s)
        psi = road.heading(s)
        jac = 1.0 - d * kappa
        djac = -d * dkappa
        u = road.speed.value(s)
        du = road.speed.derivative(s)
        g_c = road.grade.value(s)
        dg_c = road.grade.derivative(s)
        sdot = u / jac
        udot = du * sdot
        grade = g_c / jac
        grade_dot = sdot * (dg_c * jac - g_c * djac) / jac**2
        yaw_rate = kappa * sdot
        yaw_acc = sdot * (dkappa * u / jac + kappa * du / jac - kappa * u * djac / jac**2)
        cpsi, spsi = np.cos(psi), np.sin(psi)
        xy = road.xy(s) + d * np.column_stack([-spsi, cpsi])
        position = np.column_stack([xy, road.height(s)])
        velocity = u[:, None] * np.column_stack([cpsi, spsi, grade])
        acceleration = udot[:, None] * np.column_stack([cpsi, spsi, grade]) + u[
            :, None
        ] * np.column_stack([-spsi * yaw_rate, cpsi * yaw_rate, grade_dot])
        pitch = np.arctan(grade)
        pitch_rate = grade_dot / (1.0 + grade**2)
        lat_acc = u * yaw_rate
        roll = self.crossfall_rad + self.roll_per_lateral_accel * lat_acc
        roll_rate = self.roll_per_lateral_accel * (udot * yaw_rate + u * yaw_acc)
        return Kinematics(
            t=ta,
            sigma=s,
            position=position,
            velocity=velocity,
            acceleration=acceleration,
            rpy=np.column_stack([roll, pitch, psi]),
            rpy_rate=np.column_stack([roll_rate, pitch_rate, yaw_rate]),
            speed=u * np.sqrt(1.0 + grade**2),
        )

    def ideal_imu(self, k: Kinematics) -> tuple[F64, F64]:
        """Exact specific force and body rate ``(f_b, w_ib_b)``, each (N, 3), for the states."""
        c_nb = k.c_nb()
        omega = earth_rate_n(self.lat0_deg)
        g = gravity_n(self.lat0_deg, self.h0_m)
        f_n = k.acceleration + 2.0 * np.cross(omega, k.velocity) - g
        f_b = np.einsum("nji,nj->ni", c_nb, f_n)
        w_nb = body_rate_from_euler_rates(
            k.rpy[:, 0], k.rpy[:, 1], k.rpy_rate[:, 0], k.rpy_rate[:, 1], k.rpy_rate[:, 2]
        )
        w_ib = w_nb + np.einsum("nji,j->ni", c_nb, omega)
        return f_b, w_ib
