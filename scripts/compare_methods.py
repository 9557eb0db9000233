#!/usr/bin/env python3
"""Paper vs routefuse vs baseline on every bundled sample log; writes the measured tables of
``docs/method.md`` and the README's "Results" section.

    python scripts/compare_methods.py           # print the tables (about 2-4 minutes on 2 cores)
    python scripts/compare_methods.py --write   # also replace them in docs/method.md and README.md

It runs what ``routefuse run LOG --route ROUTE --method baseline proposed paper
--subtract-lane-offset`` runs (:func:`estimator.pipeline.run_methods`,
:func:`estimator.evaluation.method_metrics` over the GNSS-degraded intervals, route
deviations measured from the learned lane) with the default parameters, plus:

- ``routefuse + heading obs.``: ``extensions.heading_observation = true``;
- ``no wheel``: the same log with its wheel-speed topic dropped (IMU + GNSS only);
- one row per extension switched from its default alone (the ablation table);
- the entry error at each tunnel portal with and without the fixed-lag re-run;
- a biased map: the route moved rigidly 10 m along the road's overall direction and 3.5 m
  across it (as SD-map routes are), with the extensions that address it switched on and off.

Every number in those tables comes from this script; rerun it after changing the estimator.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from _doc_blocks import replace_block  # noqa: E402

from estimator.evaluation.metrics import (  # noqa: E402
    MethodMetrics,
    RouteDeviation,
    deviation_series,
    format_table,
    match_summary,
    method_metrics,
)
from estimator.log import Log  # noqa: E402
from estimator.params import ExtensionParams, Params, with_values  # noqa: E402
from estimator.pipeline import open_inputs, run_methods  # noqa: E402
from estimator.pipeline.inputs import Inputs  # noqa: E402
from estimator.results import Run  # noqa: E402
from estimator.route import Route  # noqa: E402
from estimator.sim.stress import moved_route  # noqa: E402

SAMPLES = ("long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel")
PAPER_SCENARIO = {
    "long_tunnel": "Long tunnel",
    "spiral_tunnel": "Curved tunnel",
    "multi_tunnel": "Multi-segment",
    "monaco_tunnel": "Curved tunnel",
}
PUBLISHED = {
    # the paper's rows (../shared/method.md): max, mean, RMSE pos. dev., mean, RMSE heading dev.
    ("Long tunnel", "Baseline"): (386.3, 142.909, 186.821, 2.073, 3.524),
    ("Long tunnel", "Proposed"): (22.7, 0.745, 1.672, 0.048, 1.257),
    ("Curved tunnel", "Baseline"): (32.6, 7.908, 10.376, -0.216, 0.793),
    ("Curved tunnel", "Proposed"): (27.5, 1.431, 1.889, -0.179, 0.946),
    ("Multi-segment", "Baseline"): (23.3, 3.576, 6.502, 0.011, 1.839),
    ("Multi-segment", "Proposed"): (8.5, 1.755, 2.351, 0.018, 1.332),
}
MARK = "<!-- compare_methods.py: {} -->"
ENTRY_HEAD = "| log | outage start [s] | re-run off [m] | re-run on [m] |"
MATCH_HEAD = "| log | paper: accepted / attempted | routefuse: accepted / attempted |"


def _published(scenario: str, method: str) -> MethodMetrics:
    return MethodMetrics(RouteDeviation(*PUBLISHED[(scenario, method)]), None, 0)


def _metrics(r: Run, route: Route, log: Log) -> MethodMetrics:
    return method_metrics(r, route, log, subtract_lane_offset=True, params=r.params)


def _entry_errors(r: Run, route: Route, log: Log) -> list[float]:
    """Horizontal error against truth at the start of each degraded interval, m."""
    ts = deviation_series(r, route, log).truth
    assert ts is not None
    return [float(np.interp(a, ts.t, ts.h_err_m)) for a, _ in r.degraded_intervals]


BIASED_RUNS = {
    "baseline": ("baseline", {}),
    "routefuse": ("proposed", {}),
    "routefuse, `map_bias` off": ("proposed", {"extensions.map_bias": False}),
    "routefuse, `offset.map_bias_refine` off": ("proposed", {"offset.map_bias_refine": False}),
    "routefuse, `map_turn_estimate` off": ("proposed", {"extensions.map_turn_estimate": False}),
    "routefuse, `route_errors_overlap_share` off": (
        "proposed",
        {"extensions.route_errors_overlap_share": False},
    ),
    "routefuse, `offset.map_turn_honest_prior` and `route_errors_overlap_share` off": (
        "proposed",
        {"offset.map_turn_honest_prior": False, "extensions.route_errors_overlap_share": False},
    ),
    "routefuse, `offset.map_bias_turn_prior` off": (
        "proposed",
        {"offset.map_bias_turn_prior": False},
    ),
    "routefuse, `offset.map_bias_far_turned` off": (
        "proposed",
        {"offset.map_bias_far_turned": False},
    ),
    "routefuse + `map_turn_honest_consider`": (
        "proposed",
        {"extensions.map_turn_honest_consider": True},
    ),
    "routefuse, `offset.map_turn_min_heading_ratio` 0": (
        "proposed",
        {"offset.map_turn_min_heading_ratio": 0.0},
    ),
    "routefuse, `map_turn_release` off": (
        "proposed",
        {"extensions.map_turn_release": False},
    ),
    "routefuse, `map_turn_two_places` off": (
        "proposed",
        {"extensions.map_turn_two_places": False},
    ),
    "routefuse + `map_bias_portal_cut`": (
        "proposed",
        {"extensions.map_bias_portal_cut": True},
    ),
    "routefuse + `offset.map_bias_walk_turned_only`": (
        "proposed",
        {"offset.map_bias_walk_turned_only": True},
    ),
    "routefuse, `offset.map_bias_walk_m_per_sqrt_km` 0": (
        "proposed",
        {"offset.map_bias_walk_m_per_sqrt_km": 0.0},
    ),
    "routefuse, `offset.map_turn_lower_sigmas` 0": (
        "proposed",
        {"offset.map_turn_lower_sigmas": 0.0},
    ),
    "routefuse, `offset.map_bias_track_m` 800, `offset.map_turn_lower_sigmas` 0": (
        "proposed",
        {"offset.map_bias_track_m": 800.0, "offset.map_turn_lower_sigmas": 0.0},
    ),
    "routefuse + `offset.map_bias_wander_rows`": (
        "proposed",
        {"offset.map_bias_wander_rows": True},
    ),
    "routefuse, `gyro_scale_consider` off": (
        "proposed",
        {"extensions.gyro_scale_consider": False},
    ),
    "routefuse, `gyro_scale_blind_gain` off": (
        "proposed",
        {"extensions.gyro_scale_blind_gain": False},
    ),
    "routefuse + `reanchor`": ("proposed", {"extensions.reanchor": True}),
    "routefuse + `reanchor`, `map_bias` off": (
        "proposed",
        {"extensions.map_bias": False, "extensions.reanchor": True},
    ),
}
"""label: (method, parameters) of the runs on the biased map"""


def _biased_map(inp: Inputs) -> dict[str, tuple[float, float]]:
    """Truth RMSE / route deviation RMSE of each of :data:`BIASED_RUNS` on the biased map."""
    assert inp.route is not None
    moved = dataclasses.replace(inp, route=moved_route(inp.route))
    out = {}
    for label, (method, values) in BIASED_RUNS.items():
        r = run_methods(moved, with_values(Params(), values), methods=(method,))[method]
        mm = _metrics(r, moved.route, moved.log)  # type: ignore[arg-type]
        assert mm.truth is not None
        out[label] = (mm.truth.rmse_h_err_m or 0.0, mm.route.rmse_pos_dev_m or 0.0)
    return out


def measure() -> dict[str, str]:
    """Every table, as markdown, by name."""
    main_rows, wheel_rows, readme_rows = [], [], []
    ablation: dict[str, dict[str, tuple[float, float]]] = {}
    biased: dict[str, dict[str, tuple[float, float]]] = {}
    entry_lines = []
    matches = []
    heading_on = with_values(Params(), {"extensions.heading_observation": True})
    defaults = ExtensionParams()
    switches = [f.name for f in dataclasses.fields(ExtensionParams)]
    for name in SAMPLES:
        t_start = time.perf_counter()
        inp = open_inputs(
            REPO / "sample_logs" / f"{name}.mcap", REPO / "sample_logs" / f"{name}.route.geojson"
        )
        log, route = inp.log, inp.route
        assert route is not None
        paper_name = PAPER_SCENARIO[name]
        session = run_methods(inp, Params(), methods=("baseline", "paper", "proposed"))
        base, paper, prop = session["baseline"], session["paper"], session["proposed"]
        head = run_methods(inp, heading_on, methods=("proposed",), reuse=session)["proposed"]
        runs = {"baseline": base, "paper": paper, "proposed": prop, "heading": head}
        m = {k: _metrics(r, route, log) for k, r in runs.items()}
        main_rows += [
            (name, "baseline", m["baseline"]),
            (name, "paper", m["paper"]),
            (name, "routefuse", m["proposed"]),
            (name, "routefuse + heading obs.", m["heading"]),
        ]
        readme_rows += [
            (f"{name} ({paper_name})", "paper, published", _published(paper_name, "Proposed")),
            (name, "paper, our implementation", m["paper"]),
            (name, "routefuse", m["proposed"]),
        ]
        s, sp = match_summary(prop), match_summary(paper)
        cells = [f"{x['accepted']} / {x['attempted']}" for x in (sp, s)]
        matches.append(f"| {name} | {cells[0]} | {cells[1]} |")
        # no wheel speed
        nw_inp = dataclasses.replace(inp, log=dataclasses.replace(log, wheel=None))
        nw = nw_inp.log
        nw_session = run_methods(nw_inp, Params())
        nw_base, nw_prop = nw_session["baseline"], nw_session["proposed"]
        nw_head = run_methods(nw_inp, heading_on, methods=("proposed",), reuse=nw_session)[
            "proposed"
        ]
        wheel_rows += [
            (name, "baseline, no wheel", _metrics(nw_base, route, nw)),
            (name, "routefuse, no wheel", _metrics(nw_prop, route, nw)),
            (name, "routefuse + heading obs., no wheel", _metrics(nw_head, route, nw)),
        ]
        # each extension switched from its default alone
        ablation[name] = {}
        for sw in switches:
            flipped = not getattr(defaults, sw)
            p = with_values(Params(), {f"extensions.{sw}": flipped})
            r = run_methods(inp, p, methods=("proposed",), reuse=session)["proposed"]
            mm = _metrics(r, route, log)
            assert mm.truth is not None
            label = f"`{sw}` {'on' if flipped else 'off'}"
            ablation[name][label] = (mm.truth.rmse_h_err_m or 0.0, mm.route.rmse_pos_dev_m or 0.0)
        biased[name] = _biased_map(inp)
        assert m["proposed"].truth is not None
        ablation[name]["(defaults)"] = (
            m["proposed"].truth.rmse_h_err_m or 0.0,
            m["proposed"].route.rmse_pos_dev_m or 0.0,
        )
        # entry error with and without the fixed-lag re-run (the baseline filter)
        off = with_values(Params(), {"extensions.portal_rerun": False})
        b_off = run_methods(inp, off, methods=("baseline",))["baseline"]
        on_e, off_e = _entry_errors(base, route, log), _entry_errors(b_off, route, log)
        for (a, _), e_on, e_off in zip(base.degraded_intervals, on_e, off_e, strict=True):
            entry_lines.append(f"| {name} | {a - base.t0:.1f} | {e_off:.2f} | {e_on:.2f} |")
        print(f"{name}: {time.perf_counter() - t_start:.0f} s", file=sys.stderr, flush=True)

    sw_names = [*next(iter(ablation.values()))]
    head = "| extension switched from its default | " + " | ".join(SAMPLES) + " |"
    abl = [head, "|" + "---|" * (len(SAMPLES) + 1)]
    for sw in sw_names:
        cells = [f"{ablation[n][sw][0]:.2f} / {ablation[n][sw][1]:.3f}" for n in SAMPLES]
        abl.append(f"| {sw} | " + " | ".join(cells) + " |")
    bias_rows = [f"| run on the biased map | {' | '.join(SAMPLES)} |", "|" + "---|" * 5]
    for label in BIASED_RUNS:
        cells = [f"{biased[n][label][0]:.2f} / {biased[n][label][1]:.3f}" for n in SAMPLES]
        bias_rows.append(f"| {label} | " + " | ".join(cells) + " |")
    return {
        "methods": format_table(main_rows, style="markdown"),
        "no-wheel": format_table(wheel_rows, style="markdown"),
        "ablation": "\n".join(abl),
        "biased-map": "\n".join(bias_rows),
        "entry": "\n".join([ENTRY_HEAD, "|---|---|---|---|", *entry_lines]),
        "matches": "\n".join([MATCH_HEAD, "|---|---|---|", *matches]),
        "readme": format_table(readme_rows, style="markdown"),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--write", action="store_true", help="replace the tables in docs/method.md and README.md"
    )
    args = parser.parse_args(argv)
    tables = measure()
    for name, body in tables.items():
        print(f"## {name}\n\n{body}\n")
    if args.write:
        doc = REPO / "docs" / "method.md"
        text = doc.read_text(encoding="utf-8")
        for name, body in tables.items():
            if name != "readme":
                text = replace_block(text, MARK, name, body)
        doc.write_text(text, encoding="utf-8")
        readme = REPO / "README.md"
        readme.write_text(
            replace_block(readme.read_text(encoding="utf-8"), MARK, "readme", tables["readme"]),
            encoding="utf-8",
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
