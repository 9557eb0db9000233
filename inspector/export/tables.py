"""The export's data files: metrics (JSON, CSV), one row per match attempt, trajectories as CSV,
GeoJSON (lon/lat, for QGIS and geojson.io) and TUM (for evo), the batch summary, and the
one-page report that links them.

TUM trajectories are in the session's local ENU frame (metres, one origin for every file of a
log), so ``evo_ape tum trajectory_truth.tum trajectory_proposed.tum`` compares them without an
alignment; timestamps are the log's clock.
"""

from __future__ import annotations

import csv
import html
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from estimator.evaluation.metrics import method_metrics
from estimator.log import Log
from estimator.nav.frames import LocalFrame
from estimator.nav.rotation import dcm_from_euler
from estimator.results import GateDecision, Run
from inspector.export.figures import (
    ACCEPTED_COLOR,
    OUTAGE_COLOR,
    REJECTED_COLOR,
    ROUTE_COLOR,
    TRUTH_COLOR,
)
from inspector.plots import BASELINE_COLOR, PROPOSED_COLOR
from inspector.scene_data import display_polyline

if TYPE_CHECKING:
    from inspector.export.batch import BatchItem

F64 = NDArray[np.float64]

TUM_SUFFIX = ".tum"


def metrics_document(
    inputs: Any,
    baseline: Run,
    compared: Run,
    log_path: Path,
    route_path: Path,
    *,
    outages: Sequence[tuple[float, float]] = (),
    subtract_lane_offset: bool = False,
) -> dict[str, Any]:
    """The ``routefuse run --json`` document of the two runs (built by the same function);
    ``subtract_lane_offset``: route deviations from the learned lane, as the README's table."""
    from estimator.evaluation.document import results_document

    runs: dict[str, Run] = {r.method: r for r in (baseline, compared)}
    metrics = {
        m: method_metrics(
            r, inputs.route, inputs.log, params=r.params, subtract_lane_offset=subtract_lane_offset
        )
        for m, r in runs.items()
    }
    return results_document(
        log_path,
        route_path,
        inputs.log,
        runs,
        metrics,
        outages=outages,
        lane_offset_subtracted=subtract_lane_offset,
    )


def write_tables(
    out: Path, inputs: Any, baseline: Run, compared: Run, doc: dict[str, Any]
) -> tuple[Path, ...]:
    """Every data file of one export; returns their paths."""
    files = [out / "metrics.json", out / "metrics.csv", out / "matches.csv"]
    files[0].write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    write_metrics_csv(files[1], doc)
    write_matches_csv(files[2], compared)
    for run in (baseline, compared):
        path = out / f"trajectory_{run.method}.csv"
        write_trajectory_csv(path, run)
        files.append(path)
    for run in (baseline, compared):
        path = out / f"trajectory_{run.method}{TUM_SUFFIX}"
        write_tum(path, run.epochs.t, run.epochs.position, run.epochs.attitude)
        files.append(path)
    truth = truth_pose(inputs.log, compared.frame)
    if truth is not None:
        path = out / f"trajectory_truth{TUM_SUFFIX}"
        write_tum(path, *truth)
        files.append(path)
    path = out / "trajectories.geojson"
    write_geojson(path, inputs, baseline, compared, truth)
    files.append(path)
    return tuple(files)


# ---------------------------------------------------------------------------------------------
# metrics and match attempts


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "" if not math.isfinite(float(v)) else f"{float(v):.6g}"
    return str(v)


def _write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([_cell(v) for v in r])


def write_metrics_csv(path: Path, doc: dict[str, Any]) -> None:
    """One row per method: the route columns, then the truth columns (empty without truth), and
    which measure the route columns are (from the route line or the learned lane)."""
    methods: dict[str, dict[str, Any]] = doc["methods"]
    route_keys = list(next(iter(methods.values()))["route"])
    truth_keys: list[str] = []
    for m in methods.values():
        if m.get("truth"):
            truth_keys = list(m["truth"])
            break
    rows = []
    for name, m in methods.items():
        truth = m.get("truth") or {}
        rows.append(
            [
                name,
                *[m["route"][k] for k in route_keys],
                *[truth.get(k) for k in truth_keys],
                doc.get("route_deviation_from", "route line"),
            ]
        )
    _write_csv(path, ["method", *route_keys, *truth_keys, "route_deviation_from"], rows)


def _xy(a: Any) -> tuple[float, float]:
    v = np.asarray(a, np.float64).reshape(-1)
    return (float(v[0]), float(v[1])) if v.shape == (2,) else (math.nan, math.nan)


def _gate_cell(g: GateDecision) -> float:
    """A gate's value as the table prints it: a rival's margin is capped at 1e9, the table's
    text for 'no rival' (+inf in the record)."""
    return min(g.value, 1e9) if g.gate.rival is not None else g.value


def write_matches_csv(path: Path, run: Run) -> None:
    """One row per match attempt: time, verdict, every gate's value / threshold / verdict
    ("pass", "fail", or empty when the attempt stopped before it), then the fit and the
    update. Angles in degrees, positions in metres in the session's ENU frame."""
    gates: list[str] = []
    extras: list[str] = []
    for m in run.matches:
        for g in m.gates:
            if g.name not in gates:
                gates.append(g.name)
        for k in m.diagnostics():
            if k not in extras:
                extras.append(k)
    header = ["index", "t_s", "time", "verdict", "accepted"]
    for name in gates:
        header += [f"{name}_value", f"{name}_threshold", f"{name}_verdict"]
    header += [
        "rotation_deg", "translation_e_m", "translation_n_m", "residual_m", "pairs",
        "heading_cos", "lane_offset_m", "p_dr_e_m", "p_dr_n_m", "pseudo_e_m", "pseudo_n_m",
        "correction_e_m", "correction_n_m", "innovation_e_m", "innovation_n_m",
        "obs_sigma_e_m", "obs_sigma_n_m", "route_s_start_m", "route_s_end_m", "gate_notes",
    ]  # fmt: skip
    header += [f"extra_{k}" for k in extras]
    rows = []
    for m in run.matches:
        row: list[Any] = [m.index, m.t - run.t0, f"{m.t:.6f}", m.verdict, m.accepted]
        by_name = {g.name: g for g in m.gates}
        for name in gates:
            gate = by_name.get(name)
            row += (
                [None, None, None]
                if gate is None
                else [_gate_cell(gate), gate.threshold, "pass" if gate.passed else "fail"]
            )
        cov = np.asarray(m.obs_cov, np.float64)
        sig = np.sqrt(np.clip(np.diag(cov), 0, None)) if cov.shape == (2, 2) else (math.nan,) * 2
        row += [
            math.degrees(m.rotation_rad),
            *_xy(m.translation),
            m.residual_m,
            m.n_pairs,
            m.heading_cos,
            m.lane_offset_m,
            *_xy(m.p_dr),
            *_xy(m.pseudo_position),
            *_xy(m.correction),
            *_xy(m.innovation),
            *sig,
            *m.route_s,
            "; ".join(f"{g.name}: {g.note}" for g in m.gates if g.note),
        ]
        diagnostics = m.diagnostics()
        row += [diagnostics.get(k) for k in extras]
        rows.append(row)
    _write_csv(path, header, rows)


# ---------------------------------------------------------------------------------------------
# trajectories


def write_trajectory_csv(path: Path, run: Run) -> None:
    """Every epoch: times, ENU and geodetic position, velocity, attitude (deg), 1-sigma,
    whether GNSS was used / degraded, and the E-N covariance (last: the sigmas alone draw an
    outage's ellipse, long along a diagonal road, across it)."""
    ep = run.epochs
    geo = run.frame.to_geodetic(ep.position) if len(ep) else np.zeros((0, 3))
    cols = [
        ("time", ep.t, "%.6f"),
        ("t_s", ep.t - run.t0, "%.3f"),
        ("east_m", ep.position[:, 0], "%.4f"),
        ("north_m", ep.position[:, 1], "%.4f"),
        ("up_m", ep.position[:, 2], "%.4f"),
        ("lat_deg", geo[:, 0], "%.9f"),
        ("lon_deg", geo[:, 1], "%.9f"),
        ("h_m", geo[:, 2], "%.4f"),
        ("v_east_m_s", ep.velocity[:, 0], "%.4f"),
        ("v_north_m_s", ep.velocity[:, 1], "%.4f"),
        ("v_up_m_s", ep.velocity[:, 2], "%.4f"),
        ("roll_deg", np.degrees(ep.attitude[:, 0]), "%.4f"),
        ("pitch_deg", np.degrees(ep.attitude[:, 1]), "%.4f"),
        ("yaw_deg", np.degrees(ep.attitude[:, 2]), "%.4f"),
        ("sigma_east_m", ep.position_sigma[:, 0], "%.4f"),
        ("sigma_north_m", ep.position_sigma[:, 1], "%.4f"),
        ("sigma_up_m", ep.position_sigma[:, 2], "%.4f"),
        ("sigma_yaw_deg", np.degrees(ep.yaw_sigma), "%.4f"),
        ("gnss_used", ep.gnss_used.astype(np.int64), "%d"),
        ("degraded", ep.degraded.astype(np.int64), "%d"),
        ("cov_east_north_m2", ep.position_cov_en, "%.6g"),
    ]
    table = np.column_stack([np.asarray(c, np.float64) for _, c, _ in cols])
    np.savetxt(
        path,
        table,
        fmt=[f for _, _, f in cols],
        delimiter=",",
        header=",".join(name for name, _, _ in cols),
        comments="",
    )


def truth_pose(log: Log, frame: LocalFrame) -> tuple[F64, F64, F64] | None:
    """(t, ENU position, roll/pitch/yaw) of the log's ground truth, or None. Truth carries a
    heading only; where it is unknown, the direction of travel stands in; roll and pitch are
    zero."""
    truth = log.truth
    if truth is None or len(truth.t) < 2:
        return None
    enu = frame.to_enu(truth.lat, truth.lon, truth.alt)
    heading = np.asarray(truth.heading, np.float64)
    if not np.all(np.isfinite(heading)):
        d = np.gradient(enu[:, :2], axis=0)
        heading = np.where(np.isfinite(heading), heading, np.arctan2(d[:, 1], d[:, 0]))
    rpy = np.column_stack([np.zeros(len(heading)), np.zeros(len(heading)), heading])
    return np.asarray(truth.t, np.float64), enu, rpy


def tum_rows(t: F64, position: F64, rpy: F64) -> F64:
    """(N, 8) ``timestamp tx ty tz qx qy qz qw``: finite rows only, timestamps strictly
    increasing (later duplicates dropped), unit quaternions of the body -> ENU rotation."""
    t = np.asarray(t, np.float64)
    pos = np.asarray(position, np.float64).reshape(-1, 3)
    rpy = np.asarray(rpy, np.float64).reshape(-1, 3)
    ok = np.isfinite(t) & np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(rpy), axis=1)
    t, pos, rpy = t[ok], pos[ok], rpy[ok]
    order = np.argsort(t, kind="stable")
    t, pos, rpy = t[order], pos[order], rpy[order]
    keep = np.r_[True, np.diff(np.round(t, 6)) > 0] if len(t) else np.zeros(0, bool)
    t, pos, rpy = t[keep], pos[keep], rpy[keep]
    if not len(t):
        return np.zeros((0, 8))
    quat = Rotation.from_matrix(dcm_from_euler(rpy[:, 0], rpy[:, 1], rpy[:, 2])).as_quat()
    return np.column_stack([t, pos, quat])


def write_tum(path: Path, t: F64, position: F64, rpy: F64) -> None:
    """A TUM trajectory file (space-separated, no header) as ``evo_traj tum`` reads it."""
    np.savetxt(path, tum_rows(t, position, rpy), fmt=["%.6f"] + ["%.4f"] * 3 + ["%.9f"] * 4)


def _lonlat(frame: LocalFrame, xy: F64) -> list[list[float]]:
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if not len(xy):
        return []
    geo = frame.to_geodetic(np.column_stack([xy, np.zeros(len(xy))]))
    return [[round(float(lon), 9), round(float(lat), 9)] for lat, lon in geo[:, :2]]


def _line(frame: LocalFrame, xy: F64, props: dict[str, Any]) -> dict[str, Any]:
    return {
        "type": "Feature",
        "properties": props,
        "geometry": {"type": "LineString", "coordinates": _lonlat(frame, display_polyline(xy))},
    }


def write_geojson(
    path: Path,
    inputs: Any,
    baseline: Run,
    compared: Run,
    truth: tuple[F64, F64, F64] | None,
) -> None:
    """One FeatureCollection (RFC 7946, lon/lat): the route, each trajectory (decimated to
    the display tolerance), the compared run's GNSS-outage stretches, and every match attempt
    as a point with its verdict. Colours in the simplestyle properties geojson.io draws."""
    frame = compared.frame
    features = [
        _line(frame, inputs.route.xy, {"name": "route", "stroke": ROUTE_COLOR}),
    ]
    for run in (baseline, compared):
        color = BASELINE_COLOR if run.method == "baseline" else PROPOSED_COLOR
        features.append(
            _line(
                frame,
                run.epochs.position[:, :2],
                {"name": run.method, "stroke": color, "stroke-width": 2},
            )
        )
    if truth is not None:
        features.append(_line(frame, truth[1][:, :2], {"name": "truth", "stroke": TRUTH_COLOR}))
    ep = compared.epochs
    for a, b in compared.degraded_intervals:
        inside = (ep.t >= a) & (ep.t <= b)
        if inside.sum() >= 2:
            features.append(
                _line(
                    frame,
                    ep.position[inside, :2],
                    {
                        "name": "GNSS outage",
                        "start_s": a - compared.t0,
                        "end_s": b - compared.t0,
                        "stroke": OUTAGE_COLOR,
                        "stroke-width": 6,
                        "stroke-opacity": 0.4,
                    },
                )
            )
    for m in compared.matches:
        p = np.asarray(m.p_dr, np.float64).reshape(-1)
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            continue
        features.append(
            {
                "type": "Feature",
                "properties": {
                    "name": f"attempt {m.index}",
                    "t_s": round(m.t - compared.t0, 3),
                    "verdict": m.verdict,
                    "marker-color": ACCEPTED_COLOR if m.accepted else REJECTED_COLOR,
                    "marker-size": "small",
                },
                "geometry": {"type": "Point", "coordinates": _lonlat(frame, p)[0]},
            }
        )
    doc = {"type": "FeatureCollection", "features": features}
    path.write_text(json.dumps(doc, separators=(",", ":")) + "\n", encoding="utf-8")


# ---------------------------------------------------------------------------------------------
# batch summary


SUMMARY_COLUMNS = (
    "log",
    "status",
    "duration_s",
    "distance_m",
    "outage_s",
    "attempts",
    "accepted",
    "baseline_max_pos_dev_m",
    "baseline_rmse_pos_dev_m",
    "proposed_max_pos_dev_m",
    "proposed_rmse_pos_dev_m",
    "baseline_rmse_h_err_m",
    "proposed_rmse_h_err_m",
    "seconds",
    "folder",
    "error",
    "warnings",
)


def summary_rows(items: Sequence[BatchItem]) -> list[dict[str, str]]:
    """One row per log of a batch (the compared method's columns are named ``proposed_``
    whatever the method)."""
    rows = []
    for it in items:
        row = dict.fromkeys(SUMMARY_COLUMNS, "")
        row.update(
            log=str(it.log),
            status="ok" if it.ok else "failed",
            seconds=f"{it.seconds:.1f}",
            folder=str(it.out_dir) if it.ok else "",
            error=it.error or "",
        )
        if it.result is not None:
            doc = it.result.metrics
            runs = list(doc["methods"].values())
            row.update(
                duration_s=_cell(doc["duration_s"]),
                distance_m=_cell(doc["distance_m"]),
                outage_s=_cell(sum(b - a for a, b in doc["degraded_intervals"])),
                attempts=_cell(doc["matches"]["attempted"]),
                accepted=_cell(doc["matches"]["accepted"]),
                warnings="; ".join(doc.get("warnings", ())),
            )
            for prefix, m in zip(("baseline", "proposed"), runs, strict=False):
                row[f"{prefix}_max_pos_dev_m"] = _cell(m["route"]["max_pos_dev_m"])
                row[f"{prefix}_rmse_pos_dev_m"] = _cell(m["route"]["rmse_pos_dev_m"])
                if m.get("truth"):
                    row[f"{prefix}_rmse_h_err_m"] = _cell(m["truth"]["rmse_h_err_m"])
        rows.append(row)
    return rows


def write_summary(path: Path, items: Sequence[BatchItem]) -> Path:
    rows = summary_rows(items)
    _write_csv(path, SUMMARY_COLUMNS, [[r[c] for c in SUMMARY_COLUMNS] for r in rows])
    return path


def format_summary(items: Sequence[BatchItem]) -> str:
    """The summary as a text table for the terminal (errors on their own lines below): per
    method the error against ground truth beside the route deviation (a route deviation alone
    rewards following a wrong map), both RMSE over the GNSS outages."""
    method = next(
        (list(it.result.metrics["methods"])[-1] for it in items if it.result is not None),
        "proposed",
    )
    columns = (
        ("log", "log"),
        ("status", "status"),
        ("outage_s", "outage [s]"),
        ("attempts", "attempts"),
        ("accepted", "accepted"),
        ("baseline_rmse_h_err_m", "baseline truth RMSE [m]"),
        ("proposed_rmse_h_err_m", f"{method} truth RMSE [m]"),
        ("baseline_rmse_pos_dev_m", "baseline route dev. RMSE [m]"),
        ("proposed_rmse_pos_dev_m", f"{method} route dev. RMSE [m]"),
        ("seconds", "time [s]"),
    )
    figures = {"outage_s", "baseline_rmse_h_err_m", "proposed_rmse_h_err_m",
               "baseline_rmse_pos_dev_m", "proposed_rmse_pos_dev_m"}  # fmt: skip
    rows = summary_rows(items)
    titles = [t for _, t in columns]
    body = []
    for r in rows:
        cells = []
        for key, _ in columns:
            v = Path(r["log"]).name if key == "log" else r[key]
            cells.append((f"{float(v):.2f}" if v else "-") if key in figures else v)
        body.append(cells)
    widths = [max(len(x) for x in col) for col in zip(titles, *body, strict=True)]
    lines = ["  ".join(t.ljust(w) for t, w in zip(titles, widths, strict=True)).rstrip()]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in body]
    lines.append(
        "RMSE over the GNSS outages; truth: error against ground truth (- where the log has "
        "none); route dev.: position deviation from the route line"
    )
    lines += [f"failed: {r['error']}" for r in rows if r["error"]]
    lines += [f"warning: {Path(r['log']).name}: {r['warnings']}" for r in rows if r["warnings"]]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# the report page


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "–"
    return f"{v:.{digits}f}" if isinstance(v, float) else html.escape(str(v))


def _title(key: str) -> str:
    """``rmse_pos_dev_m`` -> ``rmse pos dev [m]``."""
    for suffix, unit in (("_deg", "deg"), ("_m", "m")):
        if key.endswith(suffix):
            return f"{key.removesuffix(suffix).replace('_', ' ')} [{unit}]"
    return key.replace("_", " ")


def _html_table(methods: dict[str, dict[str, Any]], group: str, caption: str) -> str:
    esc = html.escape
    keys = next((list(m[group]) for m in methods.values() if m.get(group)), [])
    head = "".join(f"<th>{esc(_title(k))}</th>" for k in keys)
    rows = ""
    for name, m in methods.items():
        values = m.get(group) or {}
        cells = "".join(f"<td>{_fmt(values.get(k))}</td>" for k in keys)
        rows += f"<tr><td>{esc(name)}</td>{cells}</tr>\n"
    return (
        f"<table><caption>{esc(caption)}</caption>\n"
        f"<tr><th>method</th>{head}</tr>\n{rows}</table>\n"
    )


def _exits_table(doc: dict[str, Any]) -> str:
    """Where each outage's estimate ended against the fixes after it, per method (the exit
    check; bold beyond its sigmas), or "" when no outage was followed by fixes."""
    esc = html.escape
    rows = ""
    for method, exits in doc.get("exits", {}).items():
        for x in exits:
            a, b = x["outage"]
            cells = f"{x['distance_m']:.2f}</td><td>{x['estimate_sigma_m']:.2f}</td><td>"
            sigmas = f"{x['chi2'] ** 0.5:.1f}"
            cells += f"<b>{sigmas}</b>" if x["overconfident"] else sigmas
            rows += f"<tr><td>{esc(method)}</td><td>{a:.1f}–{b:.1f}</td><td>{cells}</td></tr>\n"
    if not rows:
        return ""
    return (
        "<table><caption>Where each outage ended: the estimate against the fixes after it "
        "(bold: beyond 99.9 % of what the estimate and the fixes claim)</caption>\n"
        "<tr><th>method</th><th>outage [s]</th><th>distance [m]</th>"
        "<th>estimate's sigma that way [m]</th><th>sigmas</th></tr>\n"
        f"{rows}</table>\n"
    )


def _replay_legend() -> str:
    """The replay's colours (it has no legend of its own), from the scene layers."""
    from inspector.layers import legend_entries, legend_html

    return legend_html(legend_entries())


def _size(n: int) -> str:
    for unit, scale in (("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def write_report(
    out: Path, doc: dict[str, Any], files: Sequence[Path], timings: dict[str, float]
) -> Path:
    """``report.html``: the metrics table, the figures and links to every other file."""
    esc = html.escape
    path = out / "report.html"
    methods: dict[str, dict[str, Any]] = doc["methods"]
    measured_from = doc.get("route_deviation_from", "route line")
    tables = _html_table(
        methods, "route", f"Deviation from the route (measured from the {measured_from})"
    )
    if any(m.get("truth") for m in methods.values()):
        tables += _html_table(methods, "truth", "Error against ground truth")
    tables += _exits_table(doc)
    matches = doc["matches"]
    rejected = ", ".join(f"{esc(k)} {v}" for k, v in matches["rejected"].items()) or "none"
    outages = ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in doc["degraded_intervals"]) or "none"
    links = ""
    for f in sorted(files, key=lambda p: p.name):
        if f.exists():
            size = f.stat().st_size
            links += (
                f'<li><a href="{esc(f.name)}">{esc(f.name)}</a> <small>{_size(size)}</small></li>\n'
            )
    timing = ", ".join(f"{k.removesuffix('_s')} {v:.1f} s" for k, v in timings.items())
    warned = doc.get("warnings", [])
    warnings = (
        '<div class="warnings"><b>Warnings about this log</b> (what was repaired or looks '
        "wrong; the figures below are computed on the repaired data)<ul>"
        + "".join(f"<li>{esc(w)}</li>" for w in warned)
        + "</ul></div>"
        if warned
        else ""
    )
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>routefuse: {esc(Path(doc["log"]).name)}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }}
table {{ border-collapse: collapse; margin-bottom: 1em; }}
caption {{ text-align: left; font-weight: 600; padding: 0.3em 0; }}
th, td {{ border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }}
th:first-child, td:first-child {{ text-align: left; }}
img {{ max-width: 100%; border: 1px solid #eee; }}
.legend span {{ margin-right: 1em; white-space: nowrap; }}
.warnings {{ background: #fff4e5; border-left: 4px solid #e8890c; padding: 0.4em 1em; }}
</style></head><body>
<h1>{esc(Path(doc["log"]).name)}</h1>
<p>log <code>{esc(doc["log"])}</code><br>route <code>{esc(doc["route"])}</code><br>
{doc["duration_s"]:.1f} s, {doc["distance_m"] / 1000:.2f} km; GNSS-degraded intervals
(s after start): {outages}</p>
{warnings}
<p><a href="replay.html"><b>Open the 3D replay</b></a> (play, pause, scrub;
<code>replay.viser</code> for viser's own player)</p>
<p class="legend">{_replay_legend()}</p>
<h2>Metrics over the GNSS-degraded intervals</h2>
{tables}<p>Match attempts: {matches["attempted"]}, accepted {matches["accepted"]};
rejected by first failed gate: {rejected}.</p>
<h2>Deviation from the route</h2>
<img src="deviation.svg" alt="position and heading deviation against time">
<h2>Trajectories</h2>
<img src="trajectory.png" alt="trajectories over the route with the outage zoomed">
<h2>Files</h2>
<ul>
{links}</ul>
<p><small>export times: {esc(timing)}</small></p>
</body></html>
"""
    path.write_text(page, encoding="utf-8")
    return path
