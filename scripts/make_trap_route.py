#!/usr/bin/env python3
"""Write the bundled trap route: the long-tunnel sample's route with a stretch in the middle of
its tunnel drawn along the parallel bore, 25 m to the side (as a map that routes through the
other tube). ``routefuse serve`` opens the sample with it, so the first view shows refused
attempts (the rejection workflow) beside accepted ones.

    python scripts/make_trap_route.py

(writes sample_logs/long_tunnel_parallel_bore.route.geojson)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from estimator.pipeline import open_inputs  # noqa: E402
from estimator.sim.sdmap import parallel_bore  # noqa: E402

SAMPLE = REPO / "sample_logs" / "long_tunnel.mcap"
ROUTE = REPO / "sample_logs" / "long_tunnel.route.geojson"
OUT = REPO / "sample_logs" / "long_tunnel_parallel_bore.route.geojson"
SHIFT_M = 25.0
STRETCH = (0.45, 0.6)
"""the part of the tunnel (fractions of its length) drawn along the other bore"""


def main() -> int:
    inputs = open_inputs(SAMPLE, ROUTE)
    log, route, frame = inputs.log, inputs.route, inputs.frame
    assert route is not None and log.truth is not None
    g = log.gnss
    t = g.t[g.valid]
    gap = int(np.argmax(np.diff(t)))
    a, b = float(t[gap]), float(t[gap + 1])
    truth = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
    ends = [a + f * (b - a) for f in STRETCH]
    xy = np.array([[np.interp(x, log.truth.t, truth[:, i]) for i in range(2)] for x in ends])
    s0, s1 = route.project(xy).s
    moved = parallel_bore(route, float(s0), float(s1), SHIFT_M)
    geo = frame.to_geodetic(np.column_stack([moved.xy, np.zeros(len(moved.xy))]))
    doc = json.loads(ROUTE.read_text(encoding="utf-8"))
    feature = doc["features"][0]
    feature["geometry"]["coordinates"] = [[round(lon, 8), round(lat, 8)] for lat, lon in geo[:, :2]]
    feature["properties"]["name"] = "long tunnel, the middle of the tunnel along the parallel bore"
    feature["properties"]["trap"] = (
        f"{s1 - s0:.0f} m of the tunnel ({s0:.0f}-{s1:.0f} m along the route) drawn "
        f"{SHIFT_M:.0f} m to the left, along the parallel bore"
    )
    OUT.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {OUT} ({feature['properties']['trap']})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
