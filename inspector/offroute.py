"""The "off-route" state of a session: where the vehicle is farther from the route than the
route can explain, and which match attempts were refused because their candidate was ambiguous
or off the route. Computed once per run (vectorised, on the controller's worker thread); a frame
step only looks it up.

The vehicle is the ground truth when the log has it (what really happened), else the proposed
estimate. Its distance from the route comes from :func:`estimator.matching.track_on_route`
(followed along the route, so a loop or a parallel carriageway does not capture it). It is
off-route where that distance exceeds ``params.offset.max_offset_m``: the largest lateral offset
the estimator still learns as "a lane of this road" (beyond it the vehicle is not on this road),
so the UI and the estimator agree on what "on the route" means.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from estimator.matching import project_on_route, track_on_route
from estimator.params import Params
from estimator.results import MapBiasUse, MatchRecord
from estimator.route import Route

F64 = NDArray[np.float64]

MAX_PLOT_POINTS = 1500
OFF_FILL = "rgba(150, 60, 200, 0.18)"
DIST_COLOR = "#6a3d9a"
LIMIT_COLOR = "#888888"
NOW_COLOR = "#d62728"


def off_route_threshold(params: Params) -> float:
    """Distance from the route beyond which the vehicle counts as off-route, m."""
    return float(params.offset.max_offset_m)


def refused_off_route(m: MatchRecord) -> str | None:
    """The gate that refused an attempt as ambiguous / off-route (its first failed gate, the
    attempt's verdict, is a candidate-validation gate that ``refuses_off_route``), or None."""
    if m.accepted:
        return None
    failed = m.failed_gates
    if failed and failed[0].gate.refuses_off_route:
        return failed[0].name
    return None


REACQUIRE_MARGIN_M = 3.0
"""the followed track is re-acquired where the route's nearest point is this much closer"""
MAX_REACQUIRE = 50
"""times the followed track may be re-acquired in one run (each costs one more follow)"""


def followed_distance(route: Route, xy: F64) -> F64:
    """Distance of each point from the route, followed along it
    (:func:`estimator.matching.track_on_route`, so a crossing or a return leg does not capture
    the vehicle), re-acquired from the nearest point of the whole route wherever that is
    :data:`REACQUIRE_MARGIN_M` closer than the followed one: at a figure-eight's crossing the
    local search may slide onto the other leg and then follow it away from the vehicle for
    ever."""
    n = len(xy)
    dist = np.empty(n)
    _, foot = _nearest(route, xy)
    nearest = np.hypot(*(xy - foot).T)
    start = 0
    for _ in range(MAX_REACQUIRE):
        s, _ = track_on_route(route, xy[start:])
        # the distance to the foot point: also right past either end of the route
        dist[start:] = np.hypot(*(xy[start:] - route.point_at(s)).T)
        lost = np.flatnonzero(dist[start:] > nearest[start:] + REACQUIRE_MARGIN_M)
        if not len(lost):
            break
        start += int(lost[0])
    return dist


def _nearest(route: Route, xy: F64) -> tuple[F64, F64]:
    """Arc length and foot point of each point's nearest point on the whole route."""
    s, _ = project_on_route(route, xy)
    return s, route.point_at(s)


def _moved_distance(m: MatchRecord, route: Route, t: F64, xy: F64, t0: float) -> float:
    """The distance of the vehicle (``xy`` at ``t`` s after the start) at attempt ``m`` from
    the route moved back by the map bias the attempt applied, NaN without one. The whole route,
    not the segment the attempt matched: a vehicle the filter has lost along the road (no
    odometer on a straight) is far from that segment yet on the road the route moved back
    draws. Measured as the point the moving back takes onto the vehicle, from the route as
    drawn (the moving back is a shift and a small turn, which keep distances to within the
    turn's square): one projection onto the route, not a moved copy of it per attempt."""
    if m.map_bias is None or not m.map_bias.applied or len(route.xy) < 2 or not len(t):
        return float("nan")
    at = m.t - t0
    if at < t[0] or at > t[-1]:
        return float("nan")
    p = np.array([np.interp(at, t, xy[:, 0]), np.interp(at, t, xy[:, 1])])
    drawn = _moved_back_from(m.map_bias, p)
    if not np.all(np.isfinite(drawn)):
        return float("nan")
    _, foot = _nearest(route, drawn[None, :])
    return float(np.hypot(*(drawn - foot[0])))


def _moved_back_from(bias: MapBiasUse, y: F64) -> F64:
    """The point of the route as drawn that the map bias moves back onto ``y``: the inverse of
    :func:`estimator.matching.map_bias.xy_moved_back`, ``y = x - offset - r J (x - pivot)``."""
    r = bias.rotation_rad
    if r == 0.0 or not np.all(np.isfinite(bias.pivot)):
        out: F64 = y + bias.offset
        return out
    turn = np.array([[1.0, r], [-r, 1.0]])  # I - r J, J the quarter turn to the left
    out = bias.pivot + np.linalg.solve(turn, y - bias.pivot + bias.offset)
    return out


def _spans(t: F64, mask: NDArray[np.bool_]) -> tuple[tuple[float, float], ...]:
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return tuple(
        (float(t[a]), float(t[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)
    )


@dataclass(frozen=True)
class OffRoute:
    """Distance of the vehicle from the route over time, the off-route spans and the refused
    attempts. Times are seconds after the log start."""

    source: Literal["truth", "proposed"]
    threshold_m: float
    t: F64
    """(N,) s after start"""
    distance_m: F64
    """(N,) distance from the route, m (NaN where unknown)"""
    off: NDArray[np.bool_]
    """(N,) distance_m > threshold_m"""
    spans: tuple[tuple[float, float], ...]
    """off-route intervals, s after start"""
    refused: tuple[str | None, ...]
    """per match attempt: the off-route gate that refused it, or None"""
    moved_distance_m: tuple[float, ...] = ()
    """per match attempt: the vehicle's distance from the route moved back by the map bias the
    attempt applied (``extensions.map_bias``) from where the map draws it; NaN for an attempt
    without an applied bias"""

    @classmethod
    def build(cls, scene: Any, route: Route, params: Params) -> OffRoute:
        """From a :class:`inspector.scene_data.SceneData` (its truth and proposed tracks, its
        attempts) and the route."""
        track = scene.truth if scene.truth is not None else scene.proposed
        source: Literal["truth", "proposed"] = "truth" if scene.truth is not None else "proposed"
        t = np.asarray(track.t, np.float64) - scene.t0
        xy = np.asarray(track.xy, np.float64)
        dist = np.full(len(t), np.nan)
        ok = np.all(np.isfinite(xy), axis=1)
        threshold = off_route_threshold(params)
        if ok.sum() >= 1 and len(route.xy) >= 2:
            dist[ok] = followed_distance(route, xy[ok])
        off = np.nan_to_num(dist, nan=0.0) > threshold
        return cls(
            source=source,
            threshold_m=threshold,
            t=t,
            distance_m=dist,
            off=off,
            spans=_spans(t, off),
            refused=tuple(refused_off_route(m) for m in scene.matches),
            moved_distance_m=tuple(
                _moved_distance(m, route, t[ok], xy[ok], scene.t0) for m in scene.matches
            ),
        )

    # -- lookups (per frame) --------------------------------------------------------------

    def index_at(self, t_rel: float) -> int | None:
        if not len(self.t) or t_rel < self.t[0] - 1.0 or t_rel > self.t[-1] + 1.0:
            return None
        return int(np.clip(np.searchsorted(self.t, t_rel, side="right") - 1, 0, len(self.t) - 1))

    def at(self, t_rel: float) -> tuple[bool, float]:
        """Whether the vehicle is off-route at ``t_rel`` and its distance from the route."""
        i = self.index_at(t_rel)
        if i is None:
            return False, float("nan")
        return bool(self.off[i]), float(self.distance_m[i])

    @property
    def total_s(self) -> float:
        return float(sum(b - a for a, b in self.spans))

    @property
    def n_refused(self) -> int:
        return sum(r is not None for r in self.refused)

    # -- text -----------------------------------------------------------------------------

    def summary(self) -> str:
        """For the status line: '' when the whole drive stays on the route."""
        parts = []
        if self.spans:
            n = len(self.spans)
            parts.append(
                f"**OFF-ROUTE** {self.total_s:.0f} s in {n} span{'s' if n > 1 else ''} "
                f"({self.source} > {self.threshold_m:g} m from the route)"
            )
        if self.n_refused:
            n = self.n_refused
            parts.append(f"{n} attempt{'s' if n > 1 else ''} refused as ambiguous / off-route")
        return " · ".join(parts)

    def frame_text(self, t_rel: float) -> str:
        """For the frame label: '' when on the route."""
        off, d = self.at(t_rel)
        if not off:
            return ""
        return f"**OFF-ROUTE** ({self.source} {d:.1f} m from the route)"

    def panel_text(self, t_rel: float, match_index: int | None) -> str:
        """Lines heading the match panel: the off-route state now, and why the attempt shown
        was refused when it was refused as off-route. Where the attempt shown was matched to
        the route moved back by an applied map bias, the vehicle's distance from the moved
        route says whether a match was to be expected, not its distance from the map's."""
        lines = []
        off, d = self.at(t_rel)
        moved = float("nan")
        if match_index is not None and 0 <= match_index < len(self.moved_distance_m):
            moved = self.moved_distance_m[match_index]
        if off and math.isfinite(moved):
            expected = (
                "a match onto it is expected"
                if moved <= self.threshold_m
                else "no match onto it is expected either"
            )
            lines.append(
                f"**OFF-ROUTE as the map draws it**: the vehicle ({self.source}) is {d:.1f} m "
                f"from the route as drawn and {moved:.1f} m from it moved back by the map "
                f"bias this attempt used (limit {self.threshold_m:g} m, offset.max_offset_m); "
                f"{expected}."
            )
        elif off:
            lines.append(
                f"**OFF-ROUTE**: the vehicle ({self.source}) is {d:.1f} m from the route "
                f"(limit {self.threshold_m:g} m, offset.max_offset_m); no match onto the "
                "route is expected here."
            )
        if match_index is not None and 0 <= match_index < len(self.refused):
            gate = self.refused[match_index]
            if gate is not None:
                lines.append(
                    f"**Refused as off-route**: the candidate is ambiguous or off the route "
                    f"(gate `{gate}`)."
                )
        return "\n\n".join(lines)

    # -- plot -----------------------------------------------------------------------------

    def uplot(self, t_now: float) -> dict[str, Any]:
        """Keyword arguments for ``gui.add_uplot``: distance from the route, the limit, the
        off-route spans shaded and the current time marked."""
        t, d = self.t, self.distance_m
        if len(t) > MAX_PLOT_POINTS:
            # thin by taking the largest distance of each bin: a short excursion still shows
            edges = np.linspace(0, len(t), MAX_PLOT_POINTS + 1).astype(np.intp)
            dd = np.nan_to_num(d, nan=-np.inf)
            d = np.maximum.reduceat(dd, edges[:-1])
            d[~np.isfinite(d)] = np.nan
            t = t[edges[:-1]]
        if not len(t):
            t, d = np.zeros(1), np.full(1, np.nan)
        k = int(np.searchsorted(t, t_now))
        dn = float(np.interp(t_now, t, np.nan_to_num(d))) if len(t) else 0.0
        xs = np.insert(t, k, [t_now] * 3)
        ys = np.insert(d, k, [dn] * 3)
        band = np.zeros(len(xs))
        for a, b in self.spans:
            band[(xs >= a) & (xs <= b)] = 1.0
        now = np.full(len(xs), -1.0)
        now[k + 1] = 2.0
        limit = np.full(len(xs), self.threshold_m)
        return {
            "data": (xs, ys, limit, band, now),
            "series": (
                {"label": "t [s]"},
                {"label": f"{self.source} from route [m]", "stroke": DIST_COLOR, "width": 1.5},
                {"label": "off-route limit [m]", "stroke": LIMIT_COLOR, "width": 1, "dash": [4, 4]},
                {
                    "label": "off-route",
                    "scale": "band",
                    "stroke": "rgba(0,0,0,0)",
                    "fill": OFF_FILL,
                    "width": 0,
                    "points": {"show": False},
                },
                {
                    "label": "now",
                    "scale": "band",
                    "stroke": NOW_COLOR,
                    "width": 1.5,
                    "points": {"show": False},
                },
            ),
            "scales": {"x": {"time": False}, "band": {"auto": False, "range": (0.0, 1.0)}},
            "title": "distance from the route (off-route shaded)",
        }
