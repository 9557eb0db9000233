#!/usr/bin/env python3
"""Validate routefuse on the real logs of ``../shared/data`` and write ``docs/validation.md``.

    python scripts/validate_real.py                 # all tables (about 3-5 minutes on 2 cores)
    python scripts/validate_real.py --skip-samples  # without the simulated-sample comparison

It runs what ``routefuse run`` runs (``estimator.pipeline.run_methods`` and
``estimator.evaluation.metrics``, the results in ``routefuse run --json``'s document,
:func:`estimator.evaluation.document.results_document`) on:

- comma2k19 I-280 (``i280.mcap`` + ``i280_route.geojson``) with the example config
  ``sample_logs/configs/comma2k19_i280.toml``, GNSS removed by injected outages of 20 s to the
  longest the 60 s log allows; errors against the log's ground truth and deviations from the
  route.
- the robot_localization Husky (``test1.bag``) with ``sample_logs/configs/husky_test1.toml`` and a
  route derived from its own smoothed GNSS (:func:`estimator.io.routebuild.route_from_gnss`), with
  outages on straight parts and corners of 20 s to the whole drive. It has no ground truth: the
  estimate is compared with the fixes the outage removed (5-fix moving average) and with the same
  filter's solution with every fix.
- the four simulated sample logs, with the defaults and with the comma setting of the
  non-holonomic sigma (why that setting is not the default).

Every number in docs/validation.md comes from this script; rerun it after changing the
estimator. ``--json FILE`` also writes every results document.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from estimator.evaluation.document import results_document  # noqa: E402
from estimator.evaluation.metrics import method_metrics  # noqa: E402
from estimator.io import load_log  # noqa: E402
from estimator.io.routebuild import moving_average, route_from_gnss  # noqa: E402
from estimator.io.topics import TopicChoice  # noqa: E402
from estimator.log import Log, TruthData  # noqa: E402
from estimator.params import Params, load_params, with_values  # noqa: E402
from estimator.pipeline import Inputs, open_inputs, run  # noqa: E402
from estimator.pipeline import run_methods as run_session  # noqa: E402
from estimator.results import Run  # noqa: E402

DATA = REPO.parent / "shared" / "data"
CONFIGS = REPO / "sample_logs" / "configs"
COMMA_CONFIG = CONFIGS / "comma2k19_i280.toml"
HUSKY_CONFIG = CONFIGS / "husky_test1.toml"
METHODS = ("baseline", "proposed", "paper")
SAMPLES = ("long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel")


@dataclass(frozen=True)
class Outage:
    start: float
    end: float
    place: str

    @property
    def length(self) -> float:
        return self.end - self.start

    def label(self, log_end: float) -> str:
        end = "end" if self.end >= log_end else f"{self.end:g}"
        return f"{self.start:g}-{end} s"


# i280 is straight everywhere (heading within 1 deg), so the places differ only in speed.
COMMA_OUTAGES = (
    Outage(10, 30, "19 -> 18 m/s, braking"),
    Outage(20, 40, "18 -> 14 m/s, slowing"),
    Outage(35, 55, "14 -> 18 m/s, accelerating"),
    Outage(20, 50, "slowing, then accelerating"),
    Outage(28, 58, "slowing, accelerating, cruising"),
    Outage(10, 50, "40 s"),
    Outage(5, 55, "50 s"),
    Outage(3, 61, "to the end (GNSS never returns)"),
)
# The Husky's lot: straight stretches north (20-130 s) and south (255-300 s); right-angle
# corners at about 140, 185, 235 and 310-335 s (see docs/validation.md).
HUSKY_OUTAGES = (
    Outage(20, 40, "straight"),
    Outage(100, 120, "straight"),
    Outage(135, 155, "corner"),
    Outage(175, 195, "corner"),
    Outage(90, 150, "straight, corner"),
    Outage(300, 360, "two corners"),
    Outage(20, 140, "straight, corner"),
    Outage(200, 320, "corners"),
    Outage(20, 260, "half the lot"),
    Outage(20, 396, "to the end (GNSS never returns)"),
)


# ---------------------------------------------------------------------------------------------
# running


def run_methods(
    inputs: Inputs,
    params: Params,
    outages: Sequence[tuple[float, float]],
    *,
    methods: Sequence[str] = METHODS,
) -> dict[str, Run]:
    """The methods over one log, as ``routefuse run`` runs them
    (:func:`estimator.pipeline.run_methods`)."""
    session = run_session(inputs, params, methods=methods, outages=outages)  # type: ignore[arg-type]  # method names as str
    return dict(session.runs)


def document(
    log_path: Path, route_path: Path, inputs: Inputs, runs: dict[str, Run], outages, truth_log
) -> dict[str, Any]:
    """``routefuse run --json``'s document; truth errors against ``truth_log``'s truth."""
    assert inputs.route is not None
    metrics = {
        m: method_metrics(r, inputs.route, truth_log, params=r.params) for m, r in runs.items()
    }
    return results_document(
        log_path, route_path, inputs.log, runs, metrics, outages=[tuple(o) for o in outages]
    )


def with_truth(log: Log, t: np.ndarray, lat: np.ndarray, lon: np.ndarray, alt: np.ndarray) -> Log:
    """The log with a stand-in truth (for the Husky, which has none). Only the metrics read it."""
    truth = TruthData(t, lat, lon, alt, np.full(len(t), np.nan))
    return dataclasses.replace(log, truth=truth)


def held_out_fixes(log: Log) -> Log:
    """Truth := the valid GNSS fixes, 5-fix moving average (about 0.5 m of white noise left)."""
    g = log.gnss
    ok = g.valid
    sm = moving_average(np.column_stack([g.lat[ok], g.lon[ok], g.alt[ok]]), 5)
    return with_truth(log, g.t[ok], sm[:, 0], sm[:, 1], sm[:, 2])


def full_gnss_solution(log: Log, r: Run) -> Log:
    """Truth := a run with every fix (the filter's own GNSS-aided solution)."""
    geo = r.frame.to_geodetic(r.epochs.position)
    return with_truth(log, r.epochs.t, geo[:, 0], geo[:, 1], geo[:, 2])


# ---------------------------------------------------------------------------------------------
# tables


def _f(v: float | None, nd: int = 2) -> str:
    return "-" if v is None else f"{v:.{nd}f}"


def _matches(doc: dict[str, Any], method: str) -> str:
    s = doc["matches_by_method"].get(method)
    if s is None:
        return ""
    rej = ", ".join(f"{k} {v}" for k, v in sorted(s["rejected"].items(), key=lambda kv: -kv[1]))
    return f"{s['accepted']}/{s['attempted']}" + (f" (rejected: {rej})" if rej else "")


def _exit(doc: dict[str, Any], method: str, o: Outage) -> str:
    """The exit check of the run's degraded interval that holds the outage ``o``: metres from
    the fixes after it, and sigmas (bold where it ended beyond them); "-" where GNSS did not
    come back."""
    for x in doc.get("exits", {}).get(method, ()):
        a, b = x["outage"]
        if a <= o.end and b >= o.start:
            cell = f"{x['distance_m']:.1f} ({x['chi2'] ** 0.5:.1f})"
            return f"**{cell}**" if x["overconfident"] else cell
    return "-"


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def outage_table(
    cases: Sequence[tuple[Outage, dict[str, Any]]],
    log_end: float,
    *,
    truth_title: str,
    methods: Sequence[str] = METHODS,
) -> str:
    header = [
        "outage",
        "where",
        "method",
        "route max [m]",
        "route RMSE [m]",
        "route hdg RMSE [deg]",
        f"{truth_title} max [m]",
        f"{truth_title} RMSE [m]",
        "along RMSE [m]",
        "cross RMSE [m]",
        "matches accepted/attempted",
        "exit [m] (sigmas)",
    ]
    rows = []
    for o, doc in cases:
        for m in methods:
            rt = doc["methods"][m]["route"]
            tr = doc["methods"][m]["truth"] or {}
            rows.append(
                [
                    o.label(log_end),
                    o.place,
                    m,
                    _f(rt["max_pos_dev_m"]),
                    _f(rt["rmse_pos_dev_m"]),
                    _f(rt["rmse_heading_dev_deg"]),
                    _f(tr.get("max_h_err_m")),
                    _f(tr.get("rmse_h_err_m")),
                    _f(tr.get("rmse_along_m")),
                    _f(tr.get("rmse_cross_m")),
                    _matches(doc, m),
                    _exit(doc, m, o),
                ]
            )
    return table(header, rows)


LOGS_TABLE = table(
    ["log", "what", "route", "reference"],
    [
        [
            "comma2k19 `i280.mcap`",
            "a car, 60 s, 1 km on I-280 at 8-20 m/s, CAN speed, u-blox",
            "`i280_route.geojson` (from the truth, smoothed, 1.8 m left, 25 m vertices)",
            "comma's post-fit pose (independent)",
        ],
        [
            "robot_localization `test1.bag`",
            "a Husky, 395 s, 358 m in a parking lot at 1 m/s, ROS 1",
            "derived from its own GNSS (no road exists)",
            "none: held-out fixes and the full-GNSS solution",
        ],
    ],
)
CONFIG_TABLE = table(
    ["need", "parameters"],
    [
        [
            "IMU mounted rotated (no /tf_static in the bag)",
            "`sensors.imu_roll_deg`, `imu_pitch_deg`, `imu_yaw_deg`: the IMU-to-body rotation "
            "`Rz(yaw) Ry(-pitch) Rx(roll)`, body forward-left-up; nose-down is a negative "
            "pitch, an x axis turned to the left a positive yaw. Where the bag has a "
            "`/tf_static` path from the IMU frame to the body frame, the loader applies it "
            "first and these angles come on top (leave them 0).",
        ],
        ["GNSS antenna not at the body origin", "`sensors.gnss_lever_arm_m` (forward, left, up)"],
        [
            "sensor noise",
            "`noise.gyro_arw_deg_sqrt_h`, `accel_vrw_m_s_sqrt_h`, the bias instabilities and "
            "initial sigmas, `wheel_speed_sigma_m_s`, `nhc_sigma_m_s`, `gnss_sigma_floor_m`, "
            "`gnss_sigma_default_m` (fixes without a covariance)",
        ],
        [
            "clocks",
            "`sensors.gnss_time_offset_s`, `wheel_time_offset_s` (added to those stamps to put "
            "them on the IMU clock), `truth_time_offset_s` (evaluation only)",
        ],
        [
            "topics",
            "found by message type; where a log has several of one type, `--imu-topic`, "
            "`--gnss-topic`, `--wheel-topic`, `--truth-topic` (command line; not in the TOML)",
        ],
        [
            "slow vehicles",
            "`trigger.min_outage_distance_m`, `window.length_m`, `window.spacing_m`, the "
            "`gates.*` angles and `gates.max_lateral_jump_m`",
        ],
    ],
)


def truth_mean(docs: Sequence[dict[str, Any]], method: str, key: str) -> float:
    return float(np.mean([d["methods"][method]["truth"][key] for d in docs]))


def route_mean(docs: Sequence[dict[str, Any]], method: str, key: str) -> float:
    return float(np.mean([d["methods"][method]["route"][key] for d in docs]))


# ---------------------------------------------------------------------------------------------
# comma2k19


def comma(data: Path, results: dict[str, Any]) -> dict[str, Any]:
    log_path = data / "comma2k19" / "i280.mcap"
    route_path = data / "comma2k19" / "i280_route.geojson"
    inputs = open_inputs(log_path, route_path)
    config = load_params(COMMA_CONFIG)
    end = inputs.log.duration_s
    cases = []
    for o in COMMA_OUTAGES:
        outs = [(o.start, min(o.end, end + 1))]
        runs = run_methods(inputs, config, outs)
        doc = document(log_path, route_path, inputs, runs, outs, inputs.log)
        cases.append((o, doc))
    results["comma"] = [doc for _, doc in cases]
    docs = [d for _, d in cases]

    # what each configuration choice does, averaged over the outages (baseline, proposed)
    base = Params()
    mount = {
        "sensors.truth_time_offset_s": -0.1,
        "sensors.imu_pitch_deg": -3.8,
        "sensors.imu_yaw_deg": 0.9,
    }
    variants: list[tuple[str, str, Params]] = [
        ("none", "defaults, no config", base),
        (
            "offset",
            "defaults + truth offset -0.1 s",
            with_values(base, {"sensors.truth_time_offset_s": -0.1}),
        ),
        (
            "pitch",
            "+ IMU pitch -3.8 deg",
            with_values(base, {"sensors.truth_time_offset_s": -0.1, "sensors.imu_pitch_deg": -3.8}),
        ),
        (
            "mount",
            "+ IMU yaw +0.9 deg (the data notes' mount; NHC sigma 0.1 m/s, the default)",
            with_values(base, mount),
        ),
        ("config", "+ NHC sigma 0.3 m/s = **the shipped config**", config),
        ("yaw0", "config, but IMU yaw 0", with_values(config, {"sensors.imu_yaw_deg": 0.0})),
        (
            "yawfit",
            "config, but IMU yaw -1.0 deg (about what the acceleration fit below says)",
            with_values(config, {"sensors.imu_yaw_deg": -1.0}),
        ),
        (
            "yawfit01",
            "IMU yaw -1.0 deg with NHC sigma 0.1 m/s",
            with_values(config, {"sensors.imu_yaw_deg": -1.0, "noise.nhc_sigma_m_s": 0.1}),
        ),
        (
            "nhc02",
            "config, but NHC sigma 0.2 m/s",
            with_values(config, {"noise.nhc_sigma_m_s": 0.2}),
        ),
    ]
    sens_rows = []
    sens: dict[str, Any] = {}
    for key, name, p in variants:
        vdocs = []
        for o in COMMA_OUTAGES:
            outs = [(o.start, min(o.end, end + 1))]
            runs = run_methods(inputs, p, outs, methods=("baseline", "proposed"))
            vdocs.append(document(log_path, route_path, inputs, runs, outs, inputs.log))
        row = [name]
        for m in ("baseline", "proposed"):
            row += [
                _f(truth_mean(vdocs, m, "rmse_h_err_m")),
                _f(truth_mean(vdocs, m, "max_h_err_m")),
                _f(truth_mean(vdocs, m, "rmse_along_m")),
                _f(truth_mean(vdocs, m, "rmse_cross_m")),
            ]
        sens_rows.append(row)
        sens[key] = {
            (m, k): truth_mean(vdocs, m, k)
            for m in ("baseline", "proposed")
            for k in ("rmse_h_err_m", "max_h_err_m", "rmse_along_m", "rmse_cross_m")
        }
    sens_table = table(
        [
            "parameters",
            "baseline RMSE [m]",
            "baseline max [m]",
            "baseline along [m]",
            "baseline cross [m]",
            "proposed RMSE [m]",
            "proposed max [m]",
            "proposed along [m]",
            "proposed cross [m]",
        ],
        sens_rows,
    )

    # the truth time offset: the filter with every fix, and the raw u-blox fixes, against truth
    full = run(inputs.log, None, config, method="baseline", frame=inputs.frame)
    g, tr = inputs.log.gnss, inputs.log.truth
    assert tr is not None
    ge = inputs.frame.to_enu(g.lat, g.lon, g.alt)[g.valid]
    gt = g.t[g.valid]
    te = inputs.frame.to_enu(tr.lat, tr.lon, tr.alt)
    off_rows = []
    best_ublox = best_filter = (np.inf, 0.0)
    floor = None
    for off in (0.0, -0.04, -0.06, -0.08, -0.10, -0.12, -0.14, -0.16):
        p_off = with_values(config, {"sensors.truth_time_offset_s": off})
        shifted = dataclasses.replace(full, params=p_off)
        whole = [(full.t0 + 2, full.t0 + 61)]
        m = method_metrics(shifted, inputs.route, inputs.log, intervals=whole)
        tt = tr.t + off
        sel = (gt > tt[0]) & (gt < tt[-1])
        p = np.column_stack([np.interp(gt[sel], tt, te[:, 0]), np.interp(gt[sel], tt, te[:, 1])])
        e = np.hypot(*(ge[sel, :2] - p).T)
        assert m.truth is not None and m.truth.rmse_along_m is not None
        best_ublox = min(best_ublox, (float(np.median(e)), off))
        best_filter = min(best_filter, (m.truth.rmse_along_m, off))
        if off == 0.0:
            floor = m.truth.rmse_along_m
        off_rows.append(
            [
                f"{off:+.2f}",
                _f(float(np.median(e))),
                _f(float(np.max(e))),
                _f(m.truth.rmse_along_m),
                _f(m.truth.rmse_h_err_m),
            ]
        )
    off_table = table(
        [
            "truth time offset [s]",
            "u-blox - truth median [m]",
            "u-blox - truth max [m]",
            "filter (every fix) along RMSE [m]",
            "filter (every fix) RMSE [m]",
        ],
        off_rows,
    )

    # the mount's yaw from the data: lateral specific force against the CAN acceleration
    yaw_fit = _mount_yaw_from_acceleration(inputs.log, config)
    return {
        "log": log_path,
        "route": route_path,
        "duration": end,
        "cases": cases,
        "docs": docs,
        "sens_table": sens_table,
        "sens": sens,
        "off_table": off_table,
        "best_ublox": best_ublox[1],
        "best_filter": best_filter[1],
        "off_floor": floor,
        "yaw_fit_deg": yaw_fit,
        "route_length": inputs.route.length if inputs.route is not None else 0.0,
    }


def _mount_yaw_from_acceleration(log: Log, p: Params) -> float:
    """IMU-to-body yaw that makes the lateral specific force uncorrelated with the forward
    acceleration from the wheel speed (1 s averages; centripetal part removed)."""
    from scipy.ndimage import uniform_filter1d

    imu, w = log.imu, log.wheel
    assert w is not None
    n = max(round(1.0 / float(np.median(np.diff(imu.t)))), 1)
    v = uniform_filter1d(np.interp(imu.t, w.t, w.speed), n)
    dv = np.gradient(v, imu.t)
    a = uniform_filter1d(imu.accel, n, axis=0)
    lat = a[:, 1] - v * uniform_filter1d(imu.gyro[:, 2], n)
    fwd = a[:, 0]
    sel = (imu.t > imu.t[0] + 2) & (imu.t < imu.t[-1] - 2)
    X = np.column_stack([dv[sel], np.ones(int(sel.sum()))])
    k_lat = np.linalg.lstsq(X, lat[sel], rcond=None)[0][0]
    k_fwd = np.linalg.lstsq(X, fwd[sel], rcond=None)[0][0]
    # a forward acceleration a appears as (a cos psi, -a sin psi) in an IMU yawed by psi
    return float(np.degrees(np.arctan2(-k_lat, k_fwd)))


# ---------------------------------------------------------------------------------------------
# the Husky


def husky(data: Path, work: Path, results: dict[str, Any]) -> dict[str, Any]:
    log_path = data / "robot_localization" / "test1.bag"
    route_path = work / "husky_test1.route.geojson"
    log = load_log(log_path)
    gj = route_from_gnss(log, name="Husky test1 lot (from its own GNSS)")
    route_path.write_text(json.dumps(gj) + "\n", encoding="utf-8")
    inputs = open_inputs(log_path, route_path)
    config = load_params(HUSKY_CONFIG)
    end = inputs.log.duration_s
    fixes = held_out_fixes(inputs.log)
    full = run(inputs.log, None, config, method="baseline", frame=inputs.frame)
    solution = full_gnss_solution(inputs.log, full)
    cases, cases_sol = [], []
    for o in HUSKY_OUTAGES:
        outs = [(o.start, min(o.end, end + 1))]
        runs = run_methods(inputs, config, outs)
        cases.append((o, document(log_path, route_path, inputs, runs, outs, fixes)))
        cases_sol.append((o, document(log_path, route_path, inputs, runs, outs, solution)))
    results["husky_vs_held_out_fixes"] = [d for _, d in cases]
    results["husky_vs_full_gnss_solution"] = [d for _, d in cases_sol]

    # the same outages with the wheel speed left out (an IMU-only log, issue 17)
    no_wheel = open_inputs(log_path, route_path, topics=TopicChoice(no_wheel=True))

    def without_wheels(p: Params) -> tuple[list[tuple[Outage, dict[str, Any]]], dict[Outage, Any]]:
        """Each outage's document against the fixes, and the proposed run's warnings."""
        docs, warned = [], {}
        for o in HUSKY_OUTAGES:
            outs = [(o.start, min(o.end, end + 1))]
            runs = run_methods(no_wheel, p, outs, methods=("baseline", "proposed"))
            docs.append((o, document(log_path, route_path, no_wheel, runs, outs, fixes)))
            warned[o] = runs["proposed"].warnings
        return docs, warned

    cases_nw, warnings_nw = without_wheels(config)
    results["husky_no_wheel_vs_held_out_fixes"] = [d for _, d in cases_nw]
    # ... and with the default pseudo-position sigma instead of the config's fixed 1 m
    defaults = Params().pseudo
    cases_nw_loose, _ = without_wheels(
        with_values(
            config,
            {
                "pseudo.cross_sigma_m": defaults.cross_sigma_m,
                "pseudo.cross_residual_factor": defaults.cross_residual_factor,
            },
        )
    )

    # defaults against the config (mean over the outages; held-out fixes)
    variants = [
        ("defaults, no config (IMU not rotated)", Params()),
        (
            "IMU rotation only (roll +90, yaw -90)",
            with_values(Params(), {"sensors.imu_roll_deg": 90, "sensors.imu_yaw_deg": -90}),
        ),
        (
            "config with the default window and gates",
            with_values(
                config,
                {
                    "window.length_m": 250.0,
                    "window.spacing_m": 5.0,
                    "trigger.min_outage_distance_m": 40.0,
                    "gates.max_heading_diff_deg": 10.0,
                    "gates.max_rotation_deg": 15.0,
                    "gates.max_lateral_jump_m": 5.0,
                },
            ),
        ),
        ("**the shipped config**", config),
        (
            "the shipped config, `extensions.weak_along_track` off",
            with_values(config, {"extensions.weak_along_track": False}),
        ),
    ]
    rows = []
    for name, p in variants:
        try:
            vdocs = []
            for o in HUSKY_OUTAGES:
                outs = [(o.start, min(o.end, end + 1))]
                runs = run_methods(inputs, p, outs, methods=("baseline", "proposed"))
                vdocs.append(document(log_path, route_path, inputs, runs, outs, fixes))
        except Exception as exc:  # a wrong mount can fail to align: that is the finding
            rows.append([name, f"fails: {exc}", "", "", "", "", ""])
            continue
        acc = sum(d["matches_by_method"]["proposed"]["accepted"] for d in vdocs)
        att = sum(d["matches_by_method"]["proposed"]["attempted"] for d in vdocs)
        rows.append(
            [
                name,
                _f(truth_mean(vdocs, "baseline", "rmse_h_err_m")),
                _f(truth_mean(vdocs, "baseline", "max_h_err_m")),
                _f(truth_mean(vdocs, "proposed", "rmse_h_err_m")),
                _f(truth_mean(vdocs, "proposed", "max_h_err_m")),
                _f(route_mean(vdocs, "baseline", "rmse_heading_dev_deg"), 1),
                f"{acc}/{att}",
            ]
        )
    var_table = table(
        [
            "parameters",
            "baseline RMSE [m]",
            "baseline max [m]",
            "proposed RMSE [m]",
            "proposed max [m]",
            "baseline route hdg RMSE [deg]",
            "matches accepted/attempted",
        ],
        rows,
    )
    # how far the held-out fixes and the full-GNSS solution are apart (the references' spread)
    m_ref = method_metrics(full, inputs.route, fixes, intervals="all", params=full.params)
    return {
        "log": log_path,
        "route_path": route_path,
        "duration": end,
        "cases": cases,
        "cases_sol": cases_sol,
        "cases_nw": cases_nw,
        "cases_nw_loose": cases_nw_loose,
        "warnings_nw": warnings_nw,
        "var_table": var_table,
        "ref_rmse": m_ref.truth.rmse_h_err_m if m_ref.truth else None,
        "ref_max": m_ref.truth.max_h_err_m if m_ref.truth else None,
        "route_vertices": len(gj["features"][0]["geometry"]["coordinates"]),
        "route_length": inputs.route.length if inputs.route is not None else 0.0,
    }


# ---------------------------------------------------------------------------------------------
# each extension flipped


def _mean_rmse(
    inputs: Inputs, params: Params, outages: Sequence[Outage], truth: Log
) -> tuple[float, int]:
    """Mean proposed truth RMSE over ``outages`` (one run each) and the matches accepted."""
    end = inputs.log.duration_s
    rmse, accepted = [], 0
    for o in outages:
        r = run_methods(inputs, params, [(o.start, min(o.end, end + 1))], methods=("proposed",))
        m = method_metrics(r["proposed"], inputs.route, truth, params=params)  # type: ignore[arg-type]
        assert m.truth is not None
        rmse.append(m.truth.rmse_h_err_m)
        accepted += sum(x.accepted for x in r["proposed"].matches)
    return float(np.mean(rmse)), accepted


def extension_flips(data: Path, husky_route: Path) -> tuple[str, int, float, list[str]]:
    """Every on/off extension flipped alone on the real logs with their configs (comma2k19
    with and without its wheel speed, the Husky): the proposed method's mean truth RMSE (the
    Husky against its held-out fixes). The rows that move any case by ``FLIP_SHOWN_M`` or more,
    the number left out, the threshold and the flips that lower every case's RMSE by
    ``FLIP_SHOWN_M`` or more."""
    comma = (data / "comma2k19" / "i280.mcap", data / "comma2k19" / "i280_route.geojson")
    comma_in = open_inputs(*comma)
    comma_nw = open_inputs(*comma, topics=TopicChoice(no_wheel=True))
    husky_in = open_inputs(data / "robot_localization" / "test1.bag", husky_route)
    comma_cfg, husky_cfg = load_params(COMMA_CONFIG), load_params(HUSKY_CONFIG)
    fixes = held_out_fixes(husky_in.log)

    def every_case(cp: Params, hp: Params) -> list[tuple[float, int]]:
        return [
            _mean_rmse(comma_in, cp, COMMA_OUTAGES, comma_in.log),
            _mean_rmse(comma_nw, cp, COMMA_OUTAGES, comma_nw.log),
            _mean_rmse(husky_in, hp, HUSKY_OUTAGES, fixes),
        ]

    shipped = every_case(comma_cfg, husky_cfg)
    rows = [["(none: the shipped configs)", "", *_flip_cells(shipped)]]
    left_out = 0
    helps_all = []
    for f in dataclasses.fields(comma_cfg.extensions):
        on = getattr(comma_cfg.extensions, f.name)
        if not isinstance(on, bool) or on != getattr(husky_cfg.extensions, f.name):
            continue
        key = f"extensions.{f.name}"
        got = every_case(
            with_values(comma_cfg, {key: not on}), with_values(husky_cfg, {key: not on})
        )
        moved = [g[0] - s[0] for g, s in zip(got, shipped, strict=True)]
        if max(abs(m) for m in moved) < FLIP_SHOWN_M:
            left_out += 1
            continue
        rows.append([f"`{f.name}`", "on -> off" if on else "off -> on", *_flip_cells(got)])
        if max(moved) <= -FLIP_SHOWN_M:
            helps_all.append(f.name)
    header = ["extension flipped", ""]
    for case in ("comma2k19", "comma2k19, no wheel speed", "Husky vs fixes"):
        header += [f"{case} RMSE [m]", "accepted"]
    return table(header, rows), left_out, FLIP_SHOWN_M, helps_all


FLIP_SHOWN_M = 0.1
"""a flipped extension is listed when it moves any case's mean RMSE by this much"""


def _flip_cells(cases: list[tuple[float, int]]) -> list[str]:
    return [cell for rmse, accepted in cases for cell in (_f(rmse), str(accepted))]


# ---------------------------------------------------------------------------------------------
# simulated samples


def samples(results: dict[str, Any]) -> tuple[str, str]:
    """The simulated samples with the default and the comma NHC sigma: (table, summary)."""
    rows = []
    out: dict[str, Any] = {}
    deltas = []
    for name in SAMPLES:
        log_path = REPO / "sample_logs" / f"{name}.mcap"
        route_path = REPO / "sample_logs" / f"{name}.route.geojson"
        inputs = open_inputs(log_path, route_path)
        for label, p in (
            ("default (NHC 0.1 m/s)", Params()),
            ("NHC 0.3 m/s (comma config)", with_values(Params(), {"noise.nhc_sigma_m_s": 0.3})),
        ):
            runs = run_methods(inputs, p, (), methods=("baseline", "proposed"))
            doc = document(log_path, route_path, inputs, runs, (), inputs.log)
            out[f"{name} {label}"] = doc
            row = [name, label]
            for m in ("baseline", "proposed"):
                rt, tr = doc["methods"][m]["route"], doc["methods"][m]["truth"]
                row += [
                    _f(rt["max_pos_dev_m"]),
                    _f(rt["rmse_pos_dev_m"]),
                    _f(tr["max_h_err_m"]),
                    _f(tr["rmse_h_err_m"]),
                ]
            rows.append(row)
        rmse = [
            out[f"{name} {label}"]["methods"]["proposed"]["truth"]["rmse_h_err_m"]
            for label in ("default (NHC 0.1 m/s)", "NHC 0.3 m/s (comma config)")
        ]
        deltas.append(f"{rmse[1] - rmse[0]:+.2f} m ({name})")
    results["samples"] = out
    summary = ", ".join(deltas)
    return table(
        [
            "sample",
            "parameters",
            "baseline route max [m]",
            "baseline route RMSE [m]",
            "baseline truth max [m]",
            "baseline truth RMSE [m]",
            "proposed route max [m]",
            "proposed route RMSE [m]",
            "proposed truth max [m]",
            "proposed truth RMSE [m]",
        ],
        rows,
    ), summary


# ---------------------------------------------------------------------------------------------
# the document


def _no_wheel_summary(h: dict[str, Any]) -> str:
    """What the IMU-only table shows, from its own figures."""
    end = h["duration"]
    quiet = [o for o, d in h["cases_nw"] if d["matches_by_method"]["proposed"]["attempted"] == 0]
    short_approach = [
        o for o in quiet if any("trigger.min_approach_m" in w for w in h["warnings_nw"][o])
    ]

    def rmse(d: dict[str, Any], m: str) -> float:
        return float(d["methods"][m]["truth"]["rmse_h_err_m"])

    def worse_than_dead_reckoning(cases: list[tuple[Outage, dict[str, Any]]]) -> list[str]:
        return [
            f"{o.label(end)} ({rmse(d, 'proposed'):.2f} against {rmse(d, 'baseline'):.2f} m)"
            for o, d in cases
            if rmse(d, "proposed") > rmse(d, "baseline") + 0.2
        ]

    worse = worse_than_dead_reckoning(h["cases_nw"])
    lines = [
        f"- {len(quiet)} of {len(h['cases_nw'])} outages make no attempt; {len(short_approach)} of "
        "them say why in a warning: the robot drives under `trigger.min_approach_m` (100 m "
        "without wheel speed) with GNSS before them, too little to calibrate the heading and "
        "the accelerometer, so the outage is dead-reckoned."
    ]
    if worse:
        lines.append(
            "- Worse than dead reckoning by more than 0.2 m: "
            + ", ".join(worse)
            + ". Traced at 77f81e1 on 200-320 s: routefuse is closer to the held-out fixes"
            " than dead reckoning from 224 to 300 s (1.3-1.7 m against 1.3-4.4 m), and the"
            " outage's last accepted match, at 311.6 s, moves the position 7.8 m and ends it"
            " 10.8 m off where dead reckoning is 7.2 m off under a 1-sigma of 19 m. The route"
            " is the robot's own GNSS on 25 m vertices, which cuts the lot's corners by metres,"
            " and without an odometer where the window lies along it is known to tens of"
            " metres. Issue 17's IMU-only target (never worse than dead reckoning) is not met"
            " here."
        )
    else:
        lines.append("- No outage is worse than dead reckoning by more than 0.2 m.")
    loose = h["cases_nw_loose"]
    worse_loose = worse_than_dead_reckoning(loose)
    tight_mean = float(np.mean([rmse(d, "proposed") for _, d in h["cases_nw"]]))
    loose_mean = float(np.mean([rmse(d, "proposed") for _, d in loose]))
    changed = [
        f"{o.label(end)} {rmse(a, 'proposed'):.2f} -> {rmse(b, 'proposed'):.2f} m"
        for (o, a), (_, b) in zip(h["cases_nw"], loose, strict=True)
        if abs(rmse(a, "proposed") - rmse(b, "proposed")) >= 0.01
    ]
    lines.append(
        "- The config's fixed 1 m pseudo-position sigma (below) was chosen with the wheel speed."
        " Without it, with the default sigma (`pseudo.cross_sigma_m` "
        f"{Params().pseudo.cross_sigma_m:g} m growing with the fit's residual, "
        f"`pseudo.cross_residual_factor` {Params().pseudo.cross_residual_factor:g}): "
        + ("; ".join(changed) if changed else "no outage changes")
        + f" (mean over the ten {tight_mean:.2f} -> {loose_mean:.2f} m); worse than dead reckoning"
        " by more than 0.2 m: "
        + (", ".join(worse_loose) if worse_loose else "none")
        + "."
        + (
            " An IMU-only run of this lot wants the default sigma: `--no-wheel --set"
            f" pseudo.cross_sigma_m={Params().pseudo.cross_sigma_m:g} --set"
            f" pseudo.cross_residual_factor={Params().pseudo.cross_residual_factor:g}` after"
            " `--config`."
            if loose_mean < tight_mean - 0.05 and len(worse_loose) <= len(worse)
            else " Neither sigma does better without wheel speed, so the config's stands."
        )
    )
    return "\n".join(lines)


def write_doc(
    path: Path,
    c: dict[str, Any],
    h: dict[str, Any],
    sample: tuple[str, str] | None,
    flips: tuple[str, int, float, list[str]] | None = None,
) -> None:
    cd = c["docs"]
    sens = c["sens"]
    mean = {
        (m, k): truth_mean(cd, m, k)
        for m in METHODS
        for k in ("rmse_h_err_m", "max_h_err_m", "rmse_along_m", "rmse_cross_m")
    }
    worse = [
        o.label(c["duration"])
        for o, d in c["cases"]
        if d["methods"]["proposed"]["truth"]["rmse_h_err_m"]
        > d["methods"]["baseline"]["truth"]["rmse_h_err_m"]
    ]
    hd = [d for _, d in h["cases"]]
    h_acc = sum(d["matches_by_method"]["proposed"]["accepted"] for d in hd)
    h_att = sum(d["matches_by_method"]["proposed"]["attempted"] for d in hd)
    h_rejected: dict[str, int] = {}
    for d in hd:
        for gate, n in d["matches_by_method"]["proposed"]["rejected"].items():
            h_rejected[gate] = h_rejected.get(gate, 0) + n
    h_top = ", ".join(
        f"{gate} {n}" for gate, n in sorted(h_rejected.items(), key=lambda kv: -kv[1])[:4]
    )
    short = [d for o, d in h["cases"] if o.length <= 20]
    long_ = [d for o, d in h["cases"] if o.length >= 120]
    long_sol = [d for o, d in h["cases_sol"] if o.length >= 120]
    better = truth_mean(long_, "proposed", "rmse_h_err_m") < truth_mean(
        long_, "baseline", "rmse_h_err_m"
    )
    pull = "pull it back towards" if better else "do not pull it back onto"
    text = f"""# Validation on real logs

Generated by `python scripts/validate_real.py` ({time.strftime("%Y-%m-%d")}); every number
below is measured by that script, which anyone can rerun (it reads `../shared/data`, see
`../shared/data/README.md`). It calls what `routefuse run` calls (`estimator.pipeline.run_methods`,
`estimator.evaluation.metrics`, and `results_document` for the numbers); `--json FILE` keeps every
results document. Methods: `baseline` = GNSS/INS/odometry, plain dead reckoning in outages;
`proposed` = routefuse (route matching with every extension); `paper` = the published method
(route matching, extensions off). Metrics cover the GNSS-degraded interval of each run only (the
injected outage plus the time until the next fix), as in `routefuse run`.

Two real logs, two very different cases:

{LOGS_TABLE}

Configs: [`sample_logs/configs/comma2k19_i280.toml`](../sample_logs/configs/comma2k19_i280.toml)
and [`sample_logs/configs/husky_test1.toml`](../sample_logs/configs/husky_test1.toml); each value
is explained in the file. Use them with `routefuse run LOG --route ROUTE --config FILE` or
`routefuse serve LOG --route ROUTE --config FILE`.

## comma2k19 I-280: injected outages against ground truth

```
routefuse run ../shared/data/comma2k19/i280.mcap \\
    --route ../shared/data/comma2k19/i280_route.geojson \\
    --config sample_logs/configs/comma2k19_i280.toml --outage 20:50 \\
    --method baseline proposed paper
```

Truth errors use `sensors.truth_time_offset_s = -0.1` (see below). "along" and "cross" are the
error components along and across the truth's direction of travel; "route" columns are the
paper's deviations from the route line (which lies 1.8 m left of the driven lane, so about
1.7 m is the floor of the route deviation of a perfect estimate). "exit" is the run's own exit
check, which needs no truth: how far the estimate ended from the fixes that came back after the
outage, and in how many of the sigmas it and they claimed; bold where that is beyond 99.9 %
(a warning of the run; `docs/integrity.md`, "The exit check"), "-" where GNSS never came back.

{outage_table(c["cases"], c["duration"], truth_title="truth")}

Mean over the {len(cd)} outages (truth RMSE / max / along / cross, m):
baseline {mean["baseline", "rmse_h_err_m"]:.2f} / {mean["baseline", "max_h_err_m"]:.2f} /
{mean["baseline", "rmse_along_m"]:.2f} / {mean["baseline", "rmse_cross_m"]:.2f};
proposed {mean["proposed", "rmse_h_err_m"]:.2f} / {mean["proposed", "max_h_err_m"]:.2f} /
{mean["proposed", "rmse_along_m"]:.2f} / {mean["proposed", "rmse_cross_m"]:.2f};
paper {mean["paper", "rmse_h_err_m"]:.2f} / {mean["paper", "max_h_err_m"]:.2f} /
{mean["paper", "rmse_along_m"]:.2f} / {mean["paper", "rmse_cross_m"]:.2f}.
Outages where the proposed truth RMSE is above the baseline's: {", ".join(worse) or "none"}.

What this shows, and what it does not:

- **Only cross-track is observable from this route.** I-280 is straight (heading within 1 deg
  over the kilometre), so a match can only say where across the road the car is. The proposed
  method removes most of the baseline's cross-track drift (mean cross RMSE
  {mean["baseline", "rmse_cross_m"]:.2f} -> {mean["proposed", "rmse_cross_m"]:.2f} m) and leaves
  the along-track error where it was ({mean["baseline", "rmse_along_m"]:.2f} ->
  {mean["proposed", "rmse_along_m"]:.2f} m): that part is dead reckoning with the CAN speed
  (about -0.7 % scale, estimated by the filter before the outage). The geometry-aware
  covariance (`extensions.geometry_covariance`) is what keeps a straight-road match from
  pulling the estimate along the road: `paper`, with the paper's isotropic R, has a mean
  along-track RMSE of {mean["paper", "rmse_along_m"]:.2f} m against the proposed
  {mean["proposed", "rmse_along_m"]:.2f} m, because every match also moves it along the road
  to wherever the fit happened to put it.
- These outages are short (20-58 s, at most 1 km), so the baseline's drift is only metres; the
  long, curved tunnels the method is made for are in the simulated samples.
- The route deviation of the proposed method is not smaller than the baseline's on every row:
  the route is 1.8 m left of the lane, and the method keeps the lane offset it learned before
  the outage, so its route deviation stays near 1.7 m by design. The truth columns are the ones
  that say who is closer to the car.

### What each setting does (mean over the same {len(cd)} outages, truth errors in m)

{c["sens_table"]}

- **Truth time offset.** The truth (camera frame times) lags the sensors. With every fix used,
  the filter and the raw u-blox fixes against the truth, by the offset added to the truth
  stamps (whole log):

{c["off_table"]}

  The u-blox fixes agree best with the truth at {c["best_ublox"]:+.2f} s, the filter's own
  solution at {c["best_filter"]:+.2f} s (of the offsets tried). We use -0.1 s, between the
  two. Without an offset, truth errors carry an along-track floor of about
  {_f(c["off_floor"], 1)} m that is a timing artefact, not an estimator error. In the table
  above the offset alone makes the unconfigured filter look worse (along
  {sens["none"]["baseline", "rmse_along_m"]:.2f} -> {sens["offset"]["baseline", "rmse_along_m"]:.2f}
  m): without the mount, the estimate runs behind the car, and the late truth hid part of that.
- **IMU pitch (-3.8 deg nose-down, from the data notes)** is the largest single effect:
  without it 6.6 % of gravity (0.65 m/s^2) leaks into the forward axis; with it the mean
  along-track RMSE falls from {sens["offset"]["baseline", "rmse_along_m"]:.2f} to
  {sens["pitch"]["baseline", "rmse_along_m"]:.2f} m (baseline) and from
  {sens["offset"]["proposed", "rmse_along_m"]:.2f} to
  {sens["pitch"]["proposed", "rmse_along_m"]:.2f} m (proposed).
- **IMU yaw is not well determined.** The data notes measure 0.9 deg to the left (from
  comma's attitude against the direction of travel). The accelerometer says otherwise: fitting
  the lateral specific force against the forward acceleration from the CAN speed gives
  {c["yaw_fit_deg"]:+.2f} deg. The baseline's cross-track error depends strongly on this angle:
  with the default non-holonomic sigma, yaw 0 / +0.9 / -1.0 deg give a mean cross RMSE of
  {sens["pitch"]["baseline", "rmse_cross_m"]:.2f} / {sens["mount"]["baseline", "rmse_cross_m"]:.2f}
  / {sens["yawfit01"]["baseline", "rmse_cross_m"]:.2f} m; with 0.3 m/s
  {sens["yaw0"]["baseline", "rmse_cross_m"]:.2f} / {sens["config"]["baseline", "rmse_cross_m"]:.2f}
  / {sens["yawfit"]["baseline", "rmse_cross_m"]:.2f} m. The proposed method's cross-track error
  stays between {min(v["proposed", "rmse_cross_m"] for v in sens.values()):.2f} and
  {max(v["proposed", "rmse_cross_m"] for v in sens.values()):.2f} m in every variant: the route
  observes what the mount spoils. The config keeps the notes' value and says it is uncertain.
- **Non-holonomic sigma.** A constraint of 0.1 m/s on the lateral body velocity assumes the IMU
  is aligned with the car to a fraction of a degree; 1 deg of mount yaw at 18 m/s is 0.3 m/s of
  apparent lateral velocity. With the notes' mount, NHC sigma 0.1 / 0.2 / 0.3 m/s gives a mean
  truth RMSE of {sens["mount"]["baseline", "rmse_h_err_m"]:.2f} /
  {sens["nhc02"]["baseline", "rmse_h_err_m"]:.2f} /
  {sens["config"]["baseline", "rmse_h_err_m"]:.2f} m (baseline) and
  {sens["mount"]["proposed", "rmse_h_err_m"]:.2f} /
  {sens["nhc02"]["proposed", "rmse_h_err_m"]:.2f} /
  {sens["config"]["proposed", "rmse_h_err_m"]:.2f} m (proposed). The config uses 0.3 m/s, the
  value the mount uncertainty argues for, not the one that suits either method best. It is a
  per-log setting, not a new default: see the simulated samples below.

## The Husky parking lot: no road, no truth

```
python scripts/validate_real.py --work /tmp/h --out /tmp/validation.md  # keeps the derived route
routefuse run ../shared/data/robot_localization/test1.bag \\
    --route /tmp/h/husky_test1.route.geojson \\
    --config sample_logs/configs/husky_test1.toml --outage 20:260
```

**A parking lot is not a road-level route.** The bag has no map and no road: the "route" here
is the Husky's own GNSS track, averaged over 5 fixes, then built like the shared data's routes:
smoothed (sigma 3 m), resampled every 25 m, Douglas-Peucker at 0.3 m, no lateral offset, and
extended 20 m at both ends ({h["route_vertices"]} vertices, {h["route_length"]:.0f} m;
`estimator.io.routebuild.route_from_gnss`). The 25 m vertices cut the lot's corners by metres,
as an SD map would. It is built from all fixes, including the ones the
outage later removes, so it carries the same metre-level SBAS wander the outage hides. This is
a test that routefuse runs on a slow ROS 1 robot with a rotated IMU and no tf, not evidence that
a map would help a robot in a parking lot: there is no map to match, and a match against your
own GNSS track can at best give back what GNSS said.

There is no ground truth. Two stand-ins are compared, and neither is truth:

1. **held-out fixes**: the GNSS fixes the outage removed, 5-fix moving average (SBAS, about 1 m
   of noise and metre-level wander: on the straight at 20-40 s the fixes swerve about 4 m to
   the east and back while the gyro shows no turn, so a 20 s outage there "errs" by metres);
2. **full-GNSS solution**: the same filter and config with every fix. It and the averaged fixes
   differ by {_f(h["ref_rmse"])} m RMSE ({_f(h["ref_max"])} m at most) over the whole drive:
   that is the size of the reference's own uncertainty.

Against the held-out fixes (the "exit" column is the run's own check against the fixes after
the outage, as for comma2k19 above; where it is bold the estimate and the fixes disagree
beyond what both claim: at walking speed this receiver's fixes wander metres more than they
report, as on the straight at 20-40 s above, and the heading the filter takes from them is
surer than they are, `docs/integrity.md`, "Husky without wheel speed ... why the yaw is 8-10
deg off under a 3 deg sigma"):

{outage_table(h["cases"], h["duration"], truth_title="fixes")}

Against the full-GNSS solution (truth columns only differ):

{outage_table(h["cases_sol"], h["duration"], truth_title="solution")}

Without the wheel speed (`--no-wheel`: IMU, GNSS and the non-holonomic constraint), against
the held-out fixes:

{outage_table(h["cases_nw"], h["duration"], truth_title="fixes", methods=("baseline", "proposed"))}

{_no_wheel_summary(h)}

What the method does here:

- **20 s outages: (next to) nothing.** At 1 m/s a 20 s outage is 20 m; matching starts after
  15 m of travel (`trigger.min_outage_distance_m`) and a match wants 20 point pairs of the
  60 m window, so few attempts are made (mean RMSE against the fixes: baseline
  {truth_mean(short, "baseline", "rmse_h_err_m"):.2f} m, proposed
  {truth_mean(short, "proposed", "rmse_h_err_m"):.2f} m).
- **Long outages (120 s and more):** the dead reckoning drifts by
  {truth_mean(long_, "baseline", "max_h_err_m"):.1f} m at most on average, and accepted matches
  {pull}
  the GNSS-derived track: mean RMSE against the fixes, baseline
  {truth_mean(long_, "baseline", "rmse_h_err_m"):.2f} m, proposed
  {truth_mean(long_, "proposed", "rmse_h_err_m"):.2f} m, paper
  {truth_mean(long_, "paper", "rmse_h_err_m"):.2f} m; against the full-GNSS solution, baseline
  {truth_mean(long_sol, "baseline", "rmse_h_err_m"):.2f} m, proposed
  {truth_mean(long_sol, "proposed", "rmse_h_err_m"):.2f} m, paper
  {truth_mean(long_sol, "paper", "rmse_h_err_m"):.2f} m. This is partly circular: the route is
  made of the same fixes. Over all outages {h_acc} of {h_att} attempts of the proposed method
  were accepted. The gates that refused most, first in each attempt: {h_top}. On this lot
  a window often fits another stretch of the lot's line, metres off along it, which the
  innovation gate refuses, and the terminal heading fails at corners. Where the proposed
  method's validation
  rejects matches that `paper` accepts, the paper's method can be closer to the fixes: it has
  no such checks, which is also what makes it accept wrong matches on parallel roads.
- **Route heading deviation is not meaningful in a parking lot:** the robot turns on the spot
  and on radii of a few metres, which a line with 25 m vertices cannot follow, so the
  heading deviation is tens of degrees at every corner whatever the estimate.

### What the configuration does (mean over the same {len(hd)} outages, against the held-out fixes)

{h["var_table"]}

- The **IMU rotation** (roll +90, yaw -90, from the package's launch file; the bag has no tf) is
  required: without it gravity is on the body y axis.
- The Microstrain 3DM-GX2's **noise** is taken from the bag's own message covariances (12.5
  deg/sqrt(h), 1.07 m/s/sqrt(h): 40 and 5 times the automotive defaults).
- The default **window and gates** are made for cars on roads (a 250 m window is four minutes of
  driving here, and a 10 deg terminal-heading gate fails at every corner of a route that cuts
  corners): with them almost no match is accepted and the proposed method is the baseline.
  The config shortens the window and widens the heading, rotation and lane-jump gates; that is
  a per-log setting for a slow robot, explained in the file.
- The **pseudo-position sigma** is the earlier fixed 1 m (`pseudo.cross_sigma_m = 1`,
  `pseudo.cross_residual_factor = 1`). The default grows the sigma with the registration
  residual, for map polylines that cut corners; this route is the log's own GNSS, and where it
  fits the DR track loosely it is wrong, so a looser sigma would only let the innovation gate
  pass bad matches (measured while choosing it: 156 of 298 attempts accepted instead of 103 of
  295, the long outages' mean RMSE against the fixes 5.84 instead of 3.92 m).
- **`extensions.weak_along_track`** (on by default, chosen on simulated drives) applies a fit
  across the road only when its along-track sigma is larger than the filter's and its along-track
  position far from the filter's. Until `pseudo.weak_along_max_chi2` (session 17) it did so also
  for fits that were far off by their own sigma too: on this lot, windows paired with another
  stretch of the line, 25 m off along it at a 3.2 m sigma, were applied across the road; the
  dead-reckoning separation gate then undid the outage's route updates and refused every later
  attempt (the 20-260 s outage at 3986458: 4 of 75 accepted, 12.76 m against the fixes, against
  the baseline's 12.98 m). Such a fit now goes whole to the innovation gate, which refuses it, as
  with the switch off: compare the last two rows.
"""
    if sample is not None:
        sample_table, sample_delta = sample
        text += f"""
## The simulated samples: default against the comma setting

The defaults are unchanged by this validation. The one candidate was the non-holonomic sigma
(0.3 m/s helps comma2k19, whose IMU mount is uncertain). On the four simulated sample logs
(`routefuse run sample_logs/NAME.mcap --route sample_logs/NAME.route.geojson`, whole GNSS-degraded
intervals, truth errors in m):

{sample_table}

With 0.3 m/s the proposed truth RMSE changes by {sample_delta} (positive = worse). The
simulated IMU is aligned exactly, and the change is not an improvement on every sample
(the long, straight tunnel gets worse), so the setting stays in the comma config and out of the
defaults: the simulated logs keep their numbers.
"""
    if flips is not None:
        flip_table, left_out, shown, helps_all = flips
        verdict = (
            "Flips that lower all three by that much: " + ", ".join(f"`{n}`" for n in helps_all)
            if helps_all
            else "No flip lowers all three by that much"
        )
        text += f"""
## Each extension flipped, on the real logs

Every on/off switch of `extensions` flipped alone, with each log's config otherwise as shipped:
the proposed method's mean truth RMSE over the outages above (comma2k19 against its truth, 8
outages, with its wheel speed and without it; the Husky against its held-out fixes, 10
outages) and the matches accepted. Listed where the flip moves any of the three by {shown:g} m
or more; the other {left_out} flips move none by that much. A switch whose flip helps all three
would be a default to question. {verdict}.

{flip_table}
"""
    text += f"""
## Configuring a real log

Everything a real log needs is a parameter (`routefuse run --help`, TOML tables named like the
groups, the inspector's parameter panel):

{CONFIG_TABLE}
"""
    path.write_text(text, encoding="utf-8")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "validation.md")
    ap.add_argument("--json", type=Path, default=None, help="also write every results document")
    ap.add_argument("--work", type=Path, default=None, help="folder for the derived Husky route")
    ap.add_argument("--skip-samples", action="store_true", help="no simulated-sample table")
    ap.add_argument("--skip-flips", action="store_true", help="no table of each extension flipped")
    args = ap.parse_args(argv)
    for need in ("comma2k19/i280.mcap", "robot_localization/test1.bag"):
        if not (args.data / need).exists():
            print(f"validate_real: {args.data / need} is missing", file=sys.stderr)
            return 2
    import tempfile

    results: dict[str, Any] = {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        c = comma(args.data, results)
        print(f"comma2k19 done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        h = husky(args.data, work, results)
        print(f"husky done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        st = None if args.skip_samples else samples(results)
        flips = None if args.skip_flips else extension_flips(args.data, h["route_path"])
        if flips is not None:
            print(f"extensions flipped ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        write_doc(args.out, c, h, st, flips)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1, default=str) + "\n", encoding="utf-8")
    print(f"wrote {args.out} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
