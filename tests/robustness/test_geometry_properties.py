"""Property-based tests of the geometry that complement tests/estimator (which already cover
``resample_polyline`` with the end anchor, exact Kabsch recovery of noise-free transforms, the
ENU round trip at |lat| <= 80 deg and the global projection): ``Route.resample``, repeated
vertices, the start anchor, Kabsch optimality and properness on arbitrary (noisy, weighted,
mirrored, degenerate) point sets, the ENU frame near the poles and the antimeridian and its
rigidity, and the windowed projection."""

from __future__ import annotations

import math

import numpy as np
import pyproj
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from estimator.matching import kabsch_2d, resample_polyline
from estimator.nav.frames import LocalFrame
from estimator.route import Route

SEEDS = st.integers(0, 2**32 - 1)
FAST = settings(max_examples=40, deadline=None)


def _polyline(rng: np.random.Generator, n: int, step: float = 40.0) -> np.ndarray:
    return np.cumsum(rng.uniform(-step, step, (n, 2)), axis=0)


def _distance_to_polyline(xy: np.ndarray, p: np.ndarray) -> float:
    a, b = xy[:-1], xy[1:]
    ab = b - a
    f = np.clip(
        np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1
    )
    return float(np.min(np.hypot(*(a + f[:, None] * ab - p).T)))


def _arc(xy: np.ndarray) -> np.ndarray:
    return np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]


# --- resampling ------------------------------------------------------------------------------


@FAST
@given(
    seed=SEEDS,
    n=st.integers(2, 25),
    spacing=st.floats(0.5, 60.0),
    a=st.floats(0, 1),
    b=st.floats(0, 1),
)
def test_route_resample_keeps_arc_length_and_spacing(seed, n, spacing, a, b) -> None:
    rng = np.random.default_rng(seed)
    route = Route(_polyline(rng, n))
    s0, s1 = sorted((a * route.length, b * route.length))
    pts = route.resample(spacing, s0, s1)
    k = len(pts)
    # as many points as whole spacings fit in [s0, s1], the first at s0
    assert k == math.floor((s1 - s0) / spacing + 1e-9) + 1
    assert (k - 1) * spacing <= s1 - s0 + 1e-6 < k * spacing + 1e-6
    # every point on the polyline, at its arc length s0 + i * spacing
    s_expected = s0 + spacing * np.arange(k)
    np.testing.assert_allclose(pts, route.point_at(s_expected), atol=1e-9)
    for p in pts:
        assert _distance_to_polyline(route.xy, p) < 1e-6
    # chords never exceed the spacing; on one segment they equal it
    chord = np.hypot(*np.diff(pts, axis=0).T)
    assert np.all(chord <= spacing + 1e-9)
    seg = np.searchsorted(route.s, s_expected, side="right")
    same = seg[1:] == seg[:-1]
    np.testing.assert_allclose(chord[same], spacing, rtol=1e-9, atol=1e-9)


@FAST
@given(seed=SEEDS, n=st.integers(2, 20), spacing=st.floats(0.5, 30.0), reps=st.integers(1, 4))
def test_resampling_ignores_repeated_vertices(seed, n, spacing, reps) -> None:
    """A polyline with every other vertex repeated resamples to the same points (both anchors),
    and the start-anchored points sit at whole spacings from the start."""
    rng = np.random.default_rng(seed)
    xy = _polyline(rng, n)
    doubled = np.repeat(xy, np.where(np.arange(n) % 2 == 0, reps + 1, 1), axis=0)
    for anchor in ("start", "end"):
        ref = resample_polyline(xy, spacing, anchor=anchor)
        out = resample_polyline(doubled, spacing, anchor=anchor)
        assert np.all(np.isfinite(out))
        np.testing.assert_allclose(out, ref, atol=1e-9)
    start = resample_polyline(xy, spacing, anchor="start")
    np.testing.assert_allclose(start[0], xy[0], atol=1e-12)
    c = _arc(xy)
    at = spacing * np.arange(len(start))
    ref = np.column_stack([np.interp(at, c, xy[:, 0]), np.interp(at, c, xy[:, 1])])
    np.testing.assert_allclose(start, ref, atol=1e-9)
    assert at[-1] <= c[-1] + 1e-6 < at[-1] + spacing


# --- Kabsch ----------------------------------------------------------------------------------


def _rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def _cost(r: np.ndarray, t: np.ndarray, src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> float:
    return float(np.sum(w * np.sum((src @ r.T + t - dst) ** 2, axis=1)))


def _best_t(r: np.ndarray, src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> np.ndarray:
    return (w @ (dst - src @ r.T)) / w.sum()


@settings(max_examples=40, deadline=None)
@given(
    seed=SEEDS,
    n=st.integers(2, 40),
    angle=st.floats(-math.pi, math.pi),
    noise=st.floats(0.0, 20.0),
    zero_weights=st.integers(0, 5),
)
def test_kabsch_is_the_least_squares_proper_rotation(seed, n, angle, noise, zero_weights) -> None:
    """With noise and weights (some zero), the fit is a proper rotation whose cost is no more
    than that of the true transform or of any rotation on a fine grid."""
    rng = np.random.default_rng(seed)
    src = rng.normal(scale=50.0, size=(n, 2))
    t_true = rng.uniform(-500, 500, 2)
    dst = src @ _rot(angle).T + t_true + rng.normal(scale=noise + 1e-12, size=(n, 2))
    w = rng.uniform(0.1, 2.0, n)
    w[rng.choice(n, size=min(zero_weights, n - 2), replace=False)] = 0.0
    r, t = kabsch_2d(src, dst, w)
    assert np.all(np.isfinite(r)) and np.all(np.isfinite(t))
    np.testing.assert_allclose(r.T @ r, np.eye(2), atol=1e-9)
    assert abs(np.linalg.det(r) - 1.0) < 1e-9
    best = _cost(r, t, src, dst, w)
    scale = 1e-9 * (1.0 + best + float(np.sum(w * np.sum(dst**2, axis=1))) * 1e-6)
    assert best <= _cost(_rot(angle), _best_t(_rot(angle), src, dst, w), src, dst, w) + scale
    angles = np.linspace(-math.pi, math.pi, 1441)
    grid = np.stack(
        [
            np.column_stack([np.cos(angles), -np.sin(angles)]),
            np.column_stack([np.sin(angles), np.cos(angles)]),
        ],
        axis=1,
    )  # (k, 2, 2)
    moved = np.einsum("kij,nj->kni", grid, src)
    t_grid = np.einsum("n,kni->ki", w, dst[None] - moved) / w.sum()
    costs = np.einsum("n,kn->k", w, np.sum((moved + t_grid[:, None] - dst) ** 2, axis=2))
    assert best <= costs.min() + scale


point_sets = st.sampled_from(["mirrored", "collinear", "coincident", "random", "two points"])


@settings(max_examples=60, deadline=None)
@given(seed=SEEDS, kind=point_sets, n=st.integers(2, 30))
def test_kabsch_never_returns_a_reflection(seed, kind, n) -> None:
    """Mirror images, collinear and coincident points: always a finite rotation, det +1."""
    rng = np.random.default_rng(seed)
    src = rng.normal(scale=30.0, size=(n, 2))
    if kind == "mirrored":
        dst = src * np.array([1.0, -1.0]) + rng.uniform(-100, 100, 2)
    elif kind == "collinear":
        src = np.outer(rng.uniform(-50, 50, n), rng.normal(size=2))
        dst = np.outer(rng.uniform(-50, 50, n), rng.normal(size=2))
    elif kind == "coincident":
        src = np.tile(rng.normal(size=2), (n, 1))
        dst = np.tile(rng.normal(size=2), (n, 1))
    elif kind == "two points":
        src, dst = src[:2], rng.normal(scale=30.0, size=(2, 2))
    else:
        dst = rng.normal(scale=30.0, size=(n, 2))
    r, t = kabsch_2d(src, dst)
    assert np.all(np.isfinite(r)) and np.all(np.isfinite(t))
    assert abs(np.linalg.det(r) - 1.0) < 1e-9
    np.testing.assert_allclose(r.T @ r, np.eye(2), atol=1e-9)
    # the translation maps the weighted centroids onto each other
    np.testing.assert_allclose(src.mean(0) @ r.T + t, dst.mean(0), atol=1e-6)


# --- the ENU frame ---------------------------------------------------------------------------

_ECEF = pyproj.Transformer.from_pipeline(
    "+proj=pipeline +step +proj=axisswap +order=2,1 "
    "+step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=cart +ellps=WGS84"
)


@settings(max_examples=40, deadline=None)
@given(
    lat0=st.one_of(st.floats(-89.99, -85.0), st.floats(85.0, 89.99), st.floats(-90.0, 90.0)),
    lon0=st.one_of(st.floats(179.0, 180.0), st.floats(-180.0, -179.0), st.floats(-180, 180)),
    h0=st.floats(-500.0, 9000.0),
    seed=SEEDS,
)
def test_enu_round_trip_and_rigidity_near_poles_and_antimeridian(lat0, lon0, h0, seed) -> None:
    """Geodetic -> ENU -> geodetic returns the point (longitude modulo 360), and ENU is a rigid
    image of ECEF: 3-D distances between points are kept to a micrometre."""
    assume(abs(lat0) < 90.0)
    frame = LocalFrame(lat0, lon0, h0)
    rng = np.random.default_rng(seed)
    enu = np.column_stack([rng.uniform(-20_000, 20_000, (50, 2)), rng.uniform(-300, 300, 50)])
    geo = frame.to_geodetic(enu)
    assert np.all(np.isfinite(geo))
    back = frame.to_enu(*geo.T)
    assert np.max(np.abs(back - enu)) < 1e-6
    geo2 = frame.to_geodetic(back)
    dlon = (geo2[:, 1] - geo[:, 1] + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(geo2[:, 0] - geo[:, 0])) < 1e-9 and np.max(np.abs(dlon)) < 1e-7
    ecef = np.column_stack(_ECEF.transform(geo[:, 0], geo[:, 1], geo[:, 2]))
    i, j = rng.integers(0, 50, (2, 200))
    d_enu = np.linalg.norm(enu[i] - enu[j], axis=1)
    d_ecef = np.linalg.norm(ecef[i] - ecef[j], axis=1)
    assert np.max(np.abs(d_enu - d_ecef)) < 1e-6


# --- windowed projection ---------------------------------------------------------------------


@FAST
@given(seed=SEEDS, n=st.integers(2, 40), search=st.floats(5.0, 300.0), g=st.floats(0, 1))
def test_windowed_projection_is_the_nearest_point_of_the_window(seed, n, search, g) -> None:
    """With ``s_guess``/``search_m`` the foot is the nearest point of the stretch of route
    within [guess - search, guess + search] (clipped inside long segments): never outside it,
    never farther than its nearest point, never nearer than the global nearest."""
    rng = np.random.default_rng(seed)
    route = Route(_polyline(rng, n))
    guess = g * route.length
    pts = rng.uniform(route.xy.min(0) - 30, route.xy.max(0) + 30, (15, 2))
    proj = route.project(pts, np.full(len(pts), guess), search)
    glob = route.project(pts)
    s_lo, s_hi = max(guess - search, 0.0), min(guess + search, route.length)
    window = route.segment(s_lo, s_hi)
    assert np.all(proj.s >= s_lo - 1e-9) and np.all(proj.s <= s_hi + 1e-9)
    for p, d, dg in zip(pts, proj.distance, glob.distance, strict=True):
        assert abs(d - _distance_to_polyline(window, p)) < 1e-6
        assert d >= dg - 1e-9
