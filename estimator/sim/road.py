"""Road geometry: a centreline of straights, circular arcs and clothoids, with speed and grade.

Every road is a sequence of :class:`Piece` s whose curvature varies linearly along the piece
(a straight: zero, an arc: constant, a clothoid: linear). Curvature must be continuous from
piece to piece, so the heading is C1 and the lateral acceleration, and with it the roll, has
no jumps. A polyline (a map route) becomes a chain of short clothoid pieces fitted to its
smoothed curvature (:func:`pieces_from_polyline`).

Heading is exact (piecewise quadratic in arc length); positions are integrated with
Gauss-Legendre quadrature on cells of at most one metre, to 1e-12 m per cell.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.sparse.linalg import spsolve

from estimator.errors import ConfigError

F64 = NDArray[np.float64]
CurvatureShape = Literal["linear", "cosine"]
"""how a piece's curvature goes from its start value to its end value"""

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True)
class Piece:
    """A stretch of road whose curvature goes linearly from ``curvature_start`` to
    ``curvature_end`` (1/m, positive = turning left)."""

    length_m: float
    curvature_start: float = 0.0
    curvature_end: float = 0.0
    speed_m_s: float | None = None
    """target lane speed on this piece; None keeps the previous piece's"""
    grade: float | None = None
    """target grade (rise over run); None keeps the previous piece's"""
    tunnel: bool = False
    scalable: bool = True
    """whether ``duration_scale`` stretches this piece (straights yes, turns no)"""
    shape: CurvatureShape = "linear"
    """how curvature changes: ``linear`` (a clothoid) or ``cosine`` (a half-cosine, so the
    curvature rate, and with it the yaw acceleration and roll rate, is continuous too)"""


def straight(
    length_m: float,
    *,
    speed_m_s: float | None = None,
    grade: float | None = None,
    tunnel: bool = False,
) -> tuple[Piece, ...]:
    return (Piece(length_m, 0.0, 0.0, speed_m_s, grade, tunnel, True),)


def turn(
    angle_deg: float,
    radius_m: float,
    *,
    transition_m: float = 60.0,
    transition: Literal["clothoid", "cosine"] = "cosine",
    speed_m_s: float | None = None,
    grade: float | None = None,
    tunnel: bool = False,
) -> tuple[Piece, ...]:
    """A transition-arc-transition turn through ``angle_deg`` (positive = left) at ``radius_m``.

    Each transition takes half its length's worth of the angle; if the angle is too small for
    full transitions they are shortened and the arc vanishes. ``cosine`` transitions (the
    default) are clothoids with rounded ends: a car's roll follows its lateral acceleration
    smoothly, and a strapdown integrator does not meet a step in the body rate (with
    clothoids, 100 Hz RK4 integration of the ideal IMU is off by decimetres after a minute of
    turns; with cosine transitions by a fraction of a millimetre).
    """
    if radius_m <= 0:
        raise ConfigError(None, f"turn radius must be positive, got {radius_m}")
    k = np.sign(angle_deg) / radius_m
    total = abs(np.radians(angle_deg)) * radius_m
    tr = min(transition_m, total)
    arc_len = total - tr
    shape: CurvatureShape = "linear" if transition == "clothoid" else "cosine"

    def piece(length: float, k0: float, k1: float, piece_shape: CurvatureShape) -> Piece:
        return Piece(length, k0, k1, speed_m_s, grade, tunnel, scalable=False, shape=piece_shape)

    pieces = [piece(tr, 0.0, k, shape)]
    if arc_len > 1e-9:
        pieces.append(piece(arc_len, k, k, "linear"))
    pieces.append(piece(tr, k, 0.0, shape))
    return tuple(pieces)


def scale_pieces(pieces: Sequence[Piece], scale: float) -> tuple[Piece, ...]:
    """Stretch the scalable pieces (straights) by ``scale``; turns keep their angle."""
    if not scale > 0:
        raise ConfigError(None, f"duration scale must be positive, got {scale}")
    return tuple(replace(p, length_m=p.length_m * scale) if p.scalable else p for p in pieces)


@dataclass(frozen=True)
class CosineSteps:
    """``base`` plus a sum of raised-cosine steps: C1, with closed-form derivative and integral.

    Step ``j`` rises by ``delta[j]`` over ``[start[j], start[j] + length[j]]``. Evaluation is
    O(N log M): finished steps come from prefix sums, only the few active ones are summed.
    """

    base: float
    start: F64
    length: F64
    delta: F64
    _s: F64 = field(init=False, repr=False, compare=False)
    """step starts, in order"""
    _l: F64 = field(init=False, repr=False, compare=False)
    _d: F64 = field(init=False, repr=False, compare=False)
    _e: F64 = field(init=False, repr=False, compare=False)
    """step ends, in the order of the starts"""
    _end_sorted: F64 = field(init=False, repr=False, compare=False)
    _cum_d: F64 = field(init=False, repr=False, compare=False)
    """rise of the steps finished by each sorted end (prefix sums, 0 first)"""
    _cum_dm: F64 = field(init=False, repr=False, compare=False)
    """prefix sums of rise times mid-point: the integral of the finished steps"""
    _lmax: float = field(init=False, repr=False, compare=False)
    _width: int = field(init=False, repr=False, compare=False)
    """most steps that can be active at one x: the window the evaluation loops over"""

    def __post_init__(self) -> None:
        order = np.argsort(self.start, kind="stable")
        start, length, delta = self.start[order], self.length[order], self.delta[order]
        end = start + length
        by_end = np.argsort(end, kind="stable")
        object.__setattr__(self, "_s", start)
        object.__setattr__(self, "_l", length)
        object.__setattr__(self, "_d", delta)
        object.__setattr__(self, "_e", end)
        object.__setattr__(self, "_end_sorted", end[by_end])
        object.__setattr__(self, "_cum_d", np.r_[0.0, np.cumsum(delta[by_end])])
        mid = (start + 0.5 * length)[by_end]
        object.__setattr__(self, "_cum_dm", np.r_[0.0, np.cumsum(delta[by_end] * mid)])
        lmax = float(length.max()) if len(length) else 0.0
        object.__setattr__(self, "_lmax", lmax)
        if len(start):
            lo = np.searchsorted(start, start - lmax, side="left")
            width = int(np.max(np.arange(len(start)) - lo)) + 1
        else:
            width = 0
        object.__setattr__(self, "_width", width)

    def _eval(self, x: F64, kind: Literal["value", "derivative", "integral"]) -> F64:
        """Sum over steps of delta times (ramp value | slope | antiderivative) at x."""
        out = np.zeros(len(x))
        if not len(self._d):
            return out
        done = np.searchsorted(self._end_sorted, x, side="right")
        if kind == "value":
            out += self._cum_d[done]
        elif kind == "integral":
            out += x * self._cum_d[done] - self._cum_dm[done]
        hi = np.searchsorted(self._s, x, side="left")
        lo = np.searchsorted(self._s, x - self._lmax, side="left")
        for o in range(self._width):
            j = np.minimum(lo + o, len(self._s) - 1)
            act = (lo + o < hi) & (x > self._s[j]) & (x < self._e[j])
            if not act.any():
                continue
            length = self._l[j]
            u = np.where(act, (x - self._s[j]) / length, 0.0)
            if kind == "value":
                r = 0.5 - 0.5 * np.cos(np.pi * u)
            elif kind == "derivative":
                r = 0.5 * np.pi * np.sin(np.pi * u) / length
            else:
                r = 0.5 * u * length - length / (2 * np.pi) * np.sin(np.pi * u)
            out += np.where(act, self._d[j] * r, 0.0)
        return out

    def value(self, x: ArrayLike) -> F64:
        xa = np.atleast_1d(np.asarray(x, np.float64))
        return self.base + self._eval(xa, "value")

    def derivative(self, x: ArrayLike) -> F64:
        return self._eval(np.atleast_1d(np.asarray(x, np.float64)), "derivative")

    def integral(self, x: ArrayLike) -> F64:
        """Integral from 0 to x."""
        xa = np.atleast_1d(np.asarray(x, np.float64))
        return self.base * xa + self._eval(xa, "integral") - self._eval(np.zeros(1), "integral")


def _steps(
    pieces: Sequence[Piece],
    attr: Literal["speed_m_s", "grade"],
    s0: F64,
    default: float,
    ramp_len: Callable[[float, float], float],
) -> CosineSteps:
    first: float | None = getattr(pieces[0], attr)
    cur = default if first is None else first
    base = cur
    starts: list[float] = []
    lengths: list[float] = []
    deltas: list[float] = []
    prev_end = -np.inf
    for i, p in enumerate(pieces):
        v: float | None = getattr(p, attr)
        if v is None or i == 0 or v == cur:
            continue
        length = ramp_len(cur, v)
        # slow down before the piece, speed up after its start; grades change centred
        if attr == "grade":
            start = s0[i] - 0.5 * length
        else:
            start = s0[i] - length if v < cur else s0[i]
            # one speed change at a time (the acceleration stays bounded), none before 0:
            # a change that does not fit before its piece finishes inside it
            start = max(start, prev_end, 0.0)
        prev_end = start + length
        starts.append(start)
        lengths.append(length)
        deltas.append(v - cur)
        cur = v
    return CosineSteps(base, np.array(starts), np.array(lengths), np.array(deltas))


@dataclass(frozen=True)
class Road:
    """The centreline of a sequence of pieces, placed at ``start_xy`` heading ``heading0``.

    ``sigma`` (m) is the centreline arc length from the start.
    """

    pieces: tuple[Piece, ...]
    start_xy: tuple[float, float] = (0.0, 0.0)
    heading0: float = 0.0
    """rad, ENU yaw of the start tangent"""
    max_accel_m_s2: float = 1.0
    """longitudinal acceleration used to size the speed ramps (peak of a cosine ramp)"""
    vertical_curve_m: float = 200.0
    """length of the transition between two grades"""
    speed: CosineSteps = field(init=False, repr=False)
    """lane speed (m/s) as a function of sigma"""
    grade: CosineSteps = field(init=False, repr=False)
    """centreline grade dh/dsigma as a function of sigma (height = its integral)"""
    _s0: F64 = field(init=False, repr=False, compare=False)
    _ka: F64 = field(init=False, repr=False, compare=False)
    _dk: F64 = field(init=False, repr=False, compare=False)
    """curvature change per metre of each piece (its mean rate for a cosine piece)"""
    _len: F64 = field(init=False, repr=False, compare=False)
    _cos: NDArray[np.bool_] = field(init=False, repr=False, compare=False)
    _psi0: F64 = field(init=False, repr=False, compare=False)
    _grid: F64 = field(init=False, repr=False, compare=False)
    _grid_xy: F64 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        p = self.pieces
        if not p:
            raise ConfigError(None, "a road needs at least one piece")
        if any(not (q.length_m > 0) for q in p):
            raise ConfigError(None, "every road piece needs a positive length")
        ka = np.array([q.curvature_start for q in p])
        kb = np.array([q.curvature_end for q in p])
        jumps = np.abs(ka[1:] - kb[:-1])
        if len(jumps) and jumps.max() > 1e-9:
            i = int(np.argmax(jumps))
            raise ConfigError(
                None,
                f"curvature jumps between road pieces {i} and {i + 1}; "
                "join arcs to straights with clothoids (turn())",
            )
        length = np.array([q.length_m for q in p])
        s0 = np.r_[0.0, np.cumsum(length)]
        cosine = np.array([q.shape == "cosine" for q in p])
        dk = (kb - ka) / length
        psi0 = self.heading0 + np.r_[0.0, np.cumsum(length * (ka + kb) / 2)]
        object.__setattr__(self, "_s0", s0)
        object.__setattr__(self, "_ka", ka)
        object.__setattr__(self, "_dk", dk)
        object.__setattr__(self, "_len", length)
        object.__setattr__(self, "_cos", cosine)
        object.__setattr__(self, "_psi0", psi0)
        # integration grid: cells of <= 1 m that never straddle a piece boundary
        nodes = [
            np.linspace(s0[i], s0[i + 1], max(int(np.ceil(length[i])), 1) + 1)[:-1]
            for i in range(len(p))
        ]
        grid = np.r_[np.concatenate(nodes), s0[-1]]
        object.__setattr__(self, "_grid", grid)
        cell_xy = self._integrate_xy(grid[:-1], grid[1:])
        xy = np.vstack([[0.0, 0.0], np.cumsum(cell_xy, axis=0)]) + np.asarray(self.start_xy)
        object.__setattr__(self, "_grid_xy", xy)
        amax = self.max_accel_m_s2

        def speed_ramp(a: float, b: float) -> float:
            return max(np.pi * abs(b - a) * max(a, b) / (2 * amax), 1.0)

        object.__setattr__(self, "speed", _steps(p, "speed_m_s", s0, 15.0, speed_ramp))
        vc = self.vertical_curve_m
        object.__setattr__(self, "grade", _steps(p, "grade", s0, 0.0, lambda a, b: vc))
        if np.any(self.speed.value(grid) <= 0.5):
            raise ConfigError(None, "road speed profile must stay above 0.5 m/s")

    @property
    def length(self) -> float:
        return float(self._s0[-1])

    @property
    def piece_bounds(self) -> F64:
        """(P + 1,) sigma where each piece starts, then the road's end."""
        return self._s0

    @property
    def cell_bounds(self) -> F64:
        """Sigma of the integration cells' bounds: cells of at most one metre that never
        straddle a piece boundary, so quadrature over a cell meets no kink."""
        return self._grid

    def piece_index(self, sigma: ArrayLike) -> NDArray[np.intp]:
        s = np.atleast_1d(np.asarray(sigma, np.float64))
        index: NDArray[np.intp] = np.searchsorted(self._s0, s, side="right") - 1
        return np.clip(index, 0, len(self.pieces) - 1)

    def _local(self, sigma: ArrayLike) -> tuple[NDArray[np.intp], F64, F64]:
        s = np.atleast_1d(np.asarray(sigma, np.float64))
        i = self.piece_index(s)
        x = s - self._s0[i]
        return i, x, np.where(self._cos[i], np.pi * x / self._len[i], 0.0)

    def curvature(self, sigma: ArrayLike) -> F64:
        i, x, ph = self._local(sigma)
        lin = self._dk[i] * x
        cos = self._dk[i] * self._len[i] * 0.5 * (1.0 - np.cos(ph))
        kappa: F64 = self._ka[i] + np.where(self._cos[i], cos, lin)
        return kappa

    def curvature_rate(self, sigma: ArrayLike) -> F64:
        """d(curvature)/d(sigma), 1/m^2."""
        i, _, ph = self._local(sigma)
        rate: F64 = self._dk[i] * np.where(self._cos[i], 0.5 * np.pi * np.sin(ph), 1.0)
        return rate

    def heading(self, sigma: ArrayLike) -> F64:
        i, x, ph = self._local(sigma)
        lin = 0.5 * self._dk[i] * x * x
        length = self._len[i]
        cos = self._dk[i] * length * 0.5 * (x - length / np.pi * np.sin(ph))
        psi: F64 = self._psi0[i] + self._ka[i] * x + np.where(self._cos[i], cos, lin)
        return psi

    def _integrate_xy(self, a: F64, b: F64) -> F64:
        """(N, 2) integral of the unit tangent from a to b (within one piece each)."""
        half = 0.5 * (b - a)
        x = (0.5 * (a + b))[:, None] + half[:, None] * _GL_X[None, :]
        psi = self.heading(x.ravel()).reshape(x.shape)
        return np.column_stack([(np.cos(psi) @ _GL_W) * half, (np.sin(psi) @ _GL_W) * half])

    def xy(self, sigma: ArrayLike) -> F64:
        """(N, 2) centreline points; beyond the ends the end tangents are extended."""
        s = np.atleast_1d(np.asarray(sigma, np.float64))
        sc = np.clip(s, 0.0, self.length)
        k = np.clip(np.searchsorted(self._grid, sc, side="right") - 1, 0, len(self._grid) - 2)
        out: F64 = self._grid_xy[k] + self._integrate_xy(self._grid[k], sc)
        over = s - sc
        if np.any(over != 0.0):
            psi = self.heading(sc)
            out = out + over[:, None] * np.column_stack([np.cos(psi), np.sin(psi)])
        return out

    def height(self, sigma: ArrayLike) -> F64:
        """Centreline height above the start, m."""
        return self.grade.integral(sigma)

    def tunnel_intervals(self) -> list[tuple[float, float]]:
        """Merged sigma intervals of the tunnel pieces."""
        out: list[tuple[float, float]] = []
        for i, p in enumerate(self.pieces):
            if not p.tunnel:
                continue
            a, b = float(self._s0[i]), float(self._s0[i + 1])
            if out and abs(out[-1][1] - a) < 1e-9:
                out[-1] = (out[-1][0], b)
            else:
                out.append((a, b))
        return out


def gaussian_smooth(xy: F64, sigma_pts: float) -> F64:
    """Gaussian smoothing of an evenly spaced polyline; odd reflection at the ends keeps
    straight ends straight."""
    if sigma_pts <= 0:
        return xy.copy()
    r = int(np.ceil(4 * sigma_pts))
    r = min(r, len(xy) - 1)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_pts) ** 2)
    k /= k.sum()
    out = np.empty_like(xy)
    for c in range(xy.shape[1]):
        v = xy[:, c]
        vv = np.r_[2 * v[0] - v[r:0:-1], v, 2 * v[-1] - v[-2 : -r - 2 : -1]]
        out[:, c] = np.convolve(vv, k, mode="valid")
    return out


def resample_polyline(xy: ArrayLike, step: float) -> F64:
    """Evenly spaced points (spacing close to ``step``) along a polyline, ends included."""
    p = np.asarray(xy, np.float64)[:, :2]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
    n = max(int(np.round(s[-1] / step)), 1)
    si = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(si, s, p[:, 0]), np.interp(si, s, p[:, 1])])


def pieces_from_polyline(
    xy: ArrayLike,
    *,
    smoothing_m: float = 20.0,
    knot_spacing_m: float = 4.0,
    speed_m_s: float | None = None,
    grade: float | None = None,
    tunnel_intervals: Sequence[tuple[float, float]] = (),
) -> tuple[tuple[Piece, ...], tuple[float, float], float]:
    """A drivable road along a polyline: resample to 1 m, Gaussian-smooth (``smoothing_m``
    sigma), differentiate the heading into a curvature, smooth it again and cut it into
    clothoid pieces of ``knot_spacing_m``.

    ``tunnel_intervals`` are arc-length intervals of the input polyline. Returns
    ``(pieces, start_xy, heading0)``; the road follows the smoothed polyline to centimetres.
    """
    p = np.asarray(xy, np.float64)
    if p.ndim != 2 or len(p) < 2:
        raise ConfigError(None, "a road polyline needs at least two points")
    s_in = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p[:, :2], axis=0).T))]
    dense = resample_polyline(p, 1.0)
    ds = s_in[-1] / (len(dense) - 1)
    sm = gaussian_smooth(dense, smoothing_m / ds)
    seg = np.diff(sm, axis=0)
    s_sm = np.r_[0.0, np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))]
    psi_seg = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    s_mid = 0.5 * (s_sm[1:] + s_sm[:-1])
    n_knots = max(int(np.round(s_sm[-1] / knot_spacing_m)), 1)
    knots = np.linspace(0.0, s_sm[-1], n_knots + 1)
    # heading at the knots, then curvature at the knots such that the clothoid chain
    # reproduces the heading change of every knot interval on average
    psi_k = np.interp(knots, s_mid, psi_seg)
    kappa = _fit_curvature(np.diff(knots), psi_k - psi_k[0])
    # the input parameter of the tunnels -> the smoothed arc length (same fraction)
    frac = s_sm[-1] / s_in[-1]
    tunnel = [(a * frac, b * frac) for a, b in tunnel_intervals]
    pieces = []
    for j in range(n_knots):
        mid = 0.5 * (knots[j] + knots[j + 1])
        in_tunnel = any(a <= mid < b for a, b in tunnel)
        pieces.append(
            Piece(
                float(knots[j + 1] - knots[j]),
                float(kappa[j]),
                float(kappa[j + 1]),
                speed_m_s if j == 0 else None,
                grade if j == 0 else None,
                in_tunnel,
                False,
            )
        )
    heading0 = float(psi_k[0])
    return tuple(pieces), (float(sm[0, 0]), float(sm[0, 1])), heading0


def _fit_curvature(lengths: F64, dpsi: F64) -> F64:
    """Knot curvatures of a clothoid chain whose heading at every knot (``dpsi``, relative to
    the first) matches in the least-squares sense, with a small curvature-smoothness term and
    zero curvature at both ends (so the chain joins straights). Matching knot headings, not
    local curvatures, keeps the chain from drifting sideways.

    Unknowns are the knot headings and curvatures; the chain's heading increments are tied to
    the curvatures by heavily weighted equations, so the system stays banded (O(n))."""
    n = len(lengths)
    rows: list[NDArray[np.intp]] = []
    cols: list[NDArray[np.intp]] = []
    vals: list[F64] = []
    rhs: list[F64] = []
    m = np.arange(n)
    tie = 1e3
    # unknowns: h_1..h_n (h_0 = 0) at columns 0..n-1, kappa_1..kappa_{n-1} at n..2n-2

    def h(i: int) -> int:
        return i - 1

    def k(i: int) -> int:
        return n + i - 1

    r = 0
    # 1. headings match the data: h_1..h_n are columns 0..n-1
    rows.append(r + m)
    cols.append(m)
    vals.append(np.ones(n))
    rhs.append(dpsi[1:])
    r += n
    # 2. h_{i+1} - h_i - (kappa_i + kappa_{i+1}) L_i / 2 = 0, kappa_0 = kappa_n = 0, h_0 = 0
    for i in range(n):
        entries: list[tuple[int, float]] = [(h(i + 1), tie)]
        if i > 0:
            entries += [(h(i), -tie), (k(i), -tie * 0.5 * lengths[i])]
        if i + 1 < n:
            entries.append((k(i + 1), -tie * 0.5 * lengths[i]))
        rows.append(np.full(len(entries), r))
        cols.append(np.array([c for c, _ in entries]))
        vals.append(np.array([v for _, v in entries]))
        r += 1
    rhs.append(np.zeros(n))
    # 3. smooth curvature: w (kappa_{i+1} - kappa_i) = 0 for i = 0..n-1
    weight = 0.1 * float(np.mean(lengths))
    for i in range(n):
        entries = []
        if i + 1 < n:
            entries.append((k(i + 1), weight))
        if i > 0:
            entries.append((k(i), -weight))
        if entries:
            rows.append(np.full(len(entries), r))
            cols.append(np.array([c for c, _ in entries]))
            vals.append(np.array([v for _, v in entries]))
        r += 1
    rhs.append(np.zeros(n))
    a = sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(r, 2 * n - 1),
    )
    x = spsolve((a.T @ a).tocsc(), a.T @ np.concatenate(rhs))
    kappa: F64 = np.r_[0.0, x[n:], 0.0]
    return kappa
