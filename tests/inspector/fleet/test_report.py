"""The sweep's report page, from rows (no cluster): what it compares logs by."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from inspector.fleet import SweepPlan, build_sets
from inspector.fleet.engine import SweepLayout
from inspector.fleet.plan import LogEntry
from inspector.fleet.report import report_html, write_report


def _rows(plan: SweepPlan, figures: dict[str, dict[str, tuple[float | None, float]]]):
    """figures[label][set] = (truth RMSE or None, route deviation RMSE)"""
    rows = []
    for entry in plan.logs:
        for s in plan.sets:
            truth, route = figures[entry.label][s.name]
            rows.append(
                {
                    "log": str(entry.log),
                    "label": entry.label,
                    "route": str(entry.route),
                    "outages": "",
                    "set": s.name,
                    "method": s.method,
                    "status": "ok",
                    "error": "",
                    "export_dir": "",
                    "total_s": 1.0,
                    "worker_peak_rss_mb": 300.0,
                    "rmse_h_err_m": truth,
                    "rmse_pos_dev_m": route,
                    "max_pos_dev_m": route,
                    "rmse_heading_dev_deg": 0.1,
                }
            )
    return rows


def _plan(tmp_path: Path, *labels: str) -> SweepPlan:
    logs = tuple(
        LogEntry(tmp_path / f"{x}.mcap", tmp_path / f"{x}.route.geojson", x) for x in labels
    )
    return SweepPlan(logs, build_sets([("method", "proposed"), ("method", "paper")]))


def test_a_log_without_truth_is_compared_by_route_deviation_said_to_be_that(tmp_path):
    """In a sweep ranked by the error against truth, a log without ground truth used to be a
    row of dashes: its change was shown nowhere."""
    plan = _plan(tmp_path, "sim", "real")
    rows = _rows(
        plan,
        {
            "sim": {"proposed": (1.0, 0.5), "paper": (3.0, 0.25)},
            "real": {"proposed": (None, 1.5), "paper": (None, 4.0)},
        },
    )
    page = report_html(plan, rows, layout=SweepLayout(tmp_path), base=tmp_path)
    truth_table, rest = page.split("Logs without ground truth (1)", 1)
    per_log = truth_table.split("Per log: change of horizontal error RMSE vs truth [m]", 1)[1]
    assert "<td>real</td>" not in per_log and "<td>sim</td>" in per_log
    assert "position deviation RMSE [m] from the route" in rest
    assert "<td>real</td><td class='num'>1.500</td><td class='num worse'>+2.500</td>" in rest
    assert "rewards following a wrong map" in rest


def test_without_truth_anywhere_the_report_warns_the_route_deviation_is_all_there_is(tmp_path):
    plan = _plan(tmp_path, "real")
    rows = _rows(plan, {"real": {"proposed": (None, 1.5), "paper": (None, 1.0)}})
    page = report_html(plan, rows, layout=SweepLayout(tmp_path), base=tmp_path)
    assert "No log has ground truth" in page
    assert "Per log: change of position deviation RMSE [m]" in page


def test_the_outages_that_ended_beyond_their_sigmas_are_listed_worst_first(tmp_path):
    """A fleet user without ground truth sorts nothing by hand: the tasks whose exit check
    flagged an outage are listed, worst first, with the command that opens each, escaped."""
    plan = _plan(tmp_path, "calm", "<b>wrong map</b>", "worse")
    rows = _rows(
        plan,
        {
            label: {"proposed": (None, 1.0), "paper": (None, 1.0)}
            for label in ("calm", "<b>wrong map</b>", "worse")
        },
    )
    flags = {("<b>wrong map</b>", "proposed"): (1, 3, 25.0), ("worse", "paper"): (2, 3, 400.0)}
    for r in rows:
        n, total, chi2 = flags.get((r["label"], r["set"]), (0, 3, 1.0))
        r.update(exits_overconfident=n, exits=total, exit_chi2_max=chi2)
    # through the table file, as a sweep writes it and the report reads it back
    parquet = tmp_path / "results.parquet"
    pq.write_table(pa.Table.from_pylist(rows), parquet)
    page = write_report(plan, SweepLayout(tmp_path), parquet).read_text(encoding="utf-8")
    section = page.split("<h2>Outages that ended beyond their sigmas</h2>", 1)[1]
    section = section.split("<h2>", 1)[0]
    assert "2 tasks." in section
    worse, wrong = section.index("<td>worse</td>"), section.index("&lt;b&gt;wrong map&lt;/b&gt;")
    assert worse < wrong and "<b>wrong map</b>" not in section
    assert "<td class='num'>2 of 3</td><td class='num'>20.0</td>" in section
    assert "<td class='num'>1 of 3</td><td class='num'>5.0</td>" in section
    assert "routefuse serve " in section and "calm" not in section
    quiet = [{**r, "exits_overconfident": 0} for r in rows]
    page = report_html(plan, quiet, layout=SweepLayout(tmp_path), base=tmp_path)
    assert "as good as they claim). None.</p>" in page
