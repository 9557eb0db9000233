#!/usr/bin/env python3
"""What the portal's degraded fixes put into the map-bias fit (issue 17).

    python scripts/portal_fit.py 32 2 3 40 [param=value ...]

For each stress-corpus drive given, runs routefuse with its defaults and catches every
approach the map-bias fit (:func:`estimator.matching.map_bias.learn_map_bias`) is given, then
refits it with the same parameters on variants of the approach: the filter's GNSS-aided
estimate as run, without its last 8 s before the tunnel entry (the simulator's degraded
fixes: multipath jumps and a portal bias reported at 2.5 m), the raw fixes over the same
span (their reported variances as the points' own), with and without that stretch, and the
truth (the floor: what the fit gets wrong with a perfect track). Each line gives the fitted
rotation, the error of the bias at the pivot along and across the road against
:meth:`estimator.sim.stress.Drive.map_bias_at`, and the RMS and last value of the error of
the fitted bias field across the road over the truth inside the tunnel that follows (what
the pseudo-positions inherit before the outage's matches correct any of it).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import estimator.pipeline.driver as driver  # noqa: E402
from estimator.filter.layout import O_GNSS, O_POS, O_T  # noqa: E402
from estimator.matching.map_bias import MapBias  # noqa: E402
from estimator.params import Params, with_values  # noqa: E402
from estimator.pipeline import run_methods  # noqa: E402
from estimator.sim.sensors import GnssErrorModel  # noqa: E402
from estimator.sim.stress import Drive, build, drive_spec  # noqa: E402

DEGRADED_S = GnssErrorModel().degraded_before_s
"""the simulator's degraded stretch before each tunnel entry"""


def _caught(drive: Drive, params: Params) -> list[tuple[np.ndarray, dict[str, Any]]]:
    """Every (track rows, learn_map_bias arguments) of a routefuse run on ``drive``."""
    calls: list[dict[str, Any]] = []
    tracks: list[np.ndarray] = []
    learn, bias_track = driver.learn_map_bias, driver.Driver._bias_track

    def spy_learn(xy: np.ndarray, cov: np.ndarray, route: Any, **kw: Any) -> MapBias:
        calls.append({"cov": np.array(cov), "route": route, **kw})
        return learn(xy, cov, route, **kw)

    def spy_track(self: Any, rows: np.ndarray, last: np.ndarray) -> np.ndarray | None:
        track = bias_track(self, rows, last)
        if track is not None:
            tracks.append(track.copy())
        return track

    driver.learn_map_bias = spy_learn  # type: ignore[assignment]
    driver.Driver._bias_track = spy_track  # type: ignore[method-assign]
    try:
        run_methods(drive.inputs, params, methods=("proposed",))
    finally:
        driver.learn_map_bias = learn
        driver.Driver._bias_track = bias_track  # type: ignore[method-assign]
    return list(zip(tracks, calls, strict=True))


def _line(tag: str, mb: MapBias, drive: Drive, tunnel_xy: np.ndarray, lane_end: float) -> str:
    """One variant's fit against the truth: ``tunnel_xy`` the truth in the tunnel ahead,
    ``lane_end`` the truth's offset from the road at the approach's end. The pseudo-positions
    put the vehicle at the route moved back by the fitted bias plus the lane: their error
    across the road is the lane's error less the bias field's error across."""
    if not np.isfinite(mb.measured[0]):
        return f"  {tag:24s} nothing learned"
    road = drive.road
    n_p = road.normal_at(road.project(mb.pivot[None]).s)[0]
    e = mb.offset - drive.map_bias_at(mb.pivot[None])[0]
    d = tunnel_xy - mb.pivot
    fitted = mb.offset + mb.rotation * np.column_stack([-d[:, 1], d[:, 0]])
    n_t = road.normal_at(road.project(tunnel_xy).s)
    field = np.sum((fitted - drive.map_bias_at(tunnel_xy)) * n_t, axis=1)
    across = mb.lane - road.project(tunnel_xy).lateral - field
    rms = math.sqrt(float(np.mean(across**2)))
    along = float(e @ np.array([n_p[1], -n_p[0]]))
    pseudo = mb.lane - lane_end - float(e @ n_p)
    rot = math.degrees(mb.rotation)
    return (
        f"  {tag:24s} applied={mb.significant!s:5s} rotation {rot:+.3f} +- "
        f"{math.degrees(mb.rotation_sigma):.3f} deg, lane {mb.lane:+.2f} m; pseudo-position "
        f"error at the pivot along {along:+6.2f} across {pseudo:+6.2f} m, across in the "
        f"tunnel RMS {rms:6.2f} end {across[-1]:+7.2f} m"
    )


def report(index: int, params: Params) -> None:
    drive = build(drive_spec(index))
    log, frame = drive.inputs.log, drive.inputs.frame
    assert log.truth is not None
    t0 = log.t_start
    truth = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)[:, :2]

    def truth_at(t: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, log.truth.t, truth[:, i]) for i in range(2)])

    g = log.gnss
    ok = g.valid
    fix_xy = frame.to_enu(g.lat[ok], g.lon[ok], g.alt[ok])[:, :2]
    fix_t, fix_var = g.t[ok], g.cov_enu[ok, :2].mean(axis=1)
    s = drive.spec
    print(
        f"drive {index} ({s.base}, {s.fault}): map {s.bias_along_m:+.1f} m along "
        f"{s.bias_across_m:+.1f} m across, turned {s.bias_rotation_deg:+.3f} deg"
    )
    for rows, kw in _caught(drive, params):
        t = rows[:, O_T]
        ahead = [(a, b) for a, b in drive.tunnels if a >= t[-1] - 1.0]
        if not ahead:
            continue
        entry, leave = ahead[0]
        inside = (log.truth.t >= entry) & (log.truth.t <= leave)
        tunnel_xy = truth[inside]
        degraded = t > entry - DEGRADED_S
        print(
            f" approach {t[0] - t0:.1f}-{t[-1] - t0:.1f} s, tunnel {entry - t0:.0f}-"
            f"{leave - t0:.0f} s; rows in the last {DEGRADED_S:g} s: {int(degraded.sum())}, "
            f"with a fix used {int(np.sum(rows[degraded, O_GNSS] > 0))}"
        )

        def fit(xy: np.ndarray, var: np.ndarray, kw: dict[str, Any] = kw) -> MapBias | None:
            if len(xy) < 5:
                return None
            route, cov = kw["route"], kw["cov"]
            rest = {k: v for k, v in kw.items() if k not in ("cov", "route")}
            rest.update(track_var=var, s_guess=float(route.project(xy[-1:]).s[0]))
            return driver.learn_map_bias(xy, cov, route, **rest)

        keep = t <= entry - DEGRADED_S
        span = (fix_t >= t[0]) & (fix_t <= t[-1])
        est = rows[:, O_POS : O_POS + 2]
        variants = {
            "estimate (as run)": (est, kw["track_var"]),
            "estimate, cut 8 s": (est[keep], kw["track_var"][keep]),
            "raw fixes": (fix_xy[span], fix_var[span]),
            "raw fixes, cut 8 s": (
                fix_xy[span & (fix_t <= entry - DEGRADED_S)],
                fix_var[span & (fix_t <= entry - DEGRADED_S)],
            ),
            "truth": (truth_at(t), kw["track_var"]),
            "truth, cut 8 s": (truth_at(t[keep]), kw["track_var"][keep]),
        }
        lane_end = float(drive.road.project(truth_at(t[-1:])).lateral[0])
        for tag, (xy, var) in variants.items():
            mb = fit(xy, var)
            if mb is None:
                print(f"  {tag:24s} too short")
            else:
                print(_line(tag, mb, drive, tunnel_xy, lane_end))


def main(argv: list[str]) -> int:
    drives = [int(a) for a in argv if "=" not in a]
    values = dict(a.split("=", 1) for a in argv if "=" in a)
    params = with_values(
        Params(),
        {k: (v == "True") if v in ("True", "False") else float(v) for k, v in values.items()},
    )
    for index in drives:
        report(index, params)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
