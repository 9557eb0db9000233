"""``report.html`` of a sweep: one self-contained page (figures inline as PNG, no script, no
address outside the folder) with the sets and what each changes, the distribution of the key
figures per set, each log's change against the reference set, the worst regressions and the
best improvements (each with the ``routefuse serve`` command that opens that log with that set,
and a link to its replay export when there is one), and the failed tasks.

Every string that reaches the page (log names, set names, errors, commands) goes through
:func:`html.escape`."""

from __future__ import annotations

import base64
import html
import io
import math
import shlex
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

from inspector.fleet.plan import SweepPlan, format_values
from inspector.fleet.table import KEY_METRICS
from inspector.numbers import signed

if TYPE_CHECKING:
    from inspector.fleet.engine import SweepLayout

RANKED = 10
"""regressions and improvements listed"""
MAX_DELTA_ROWS = 500
"""logs in the per-log table (the worst first); the full table is results.parquet"""
TRUTH_METRIC = "rmse_h_err_m"
ROUTE_METRIC = "rmse_pos_dev_m"


def ranking_metric(rows: Sequence[Mapping[str, Any]]) -> str:
    """What regressions are ranked by: the error against ground truth where the logs have it
    (a route-relative deviation rewards following a wrong map), else the paper's position
    deviation RMSE over the outages."""
    return TRUTH_METRIC if any(_finite(r.get(TRUTH_METRIC)) for r in rows) else ROUTE_METRIC


_COLUMNS = (
    "task_id", "log", "label", "route", "outages", "set", "set_index", "method", "status",
    "error", "export_dir", "total_s", "worker_peak_rss_mb", "matches_attempted",
    "matches_accepted", "exits", "exits_overconfident", "exit_chi2_max", *KEY_METRICS,
)  # fmt: skip
_TITLES = {
    "rmse_pos_dev_m": "position deviation RMSE [m]",
    "max_pos_dev_m": "max position deviation [m]",
    "rmse_heading_dev_deg": "heading deviation RMSE [deg]",
    "rmse_h_err_m": "horizontal error RMSE vs truth [m]",
}
_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em; color: #222; max-width: 1200px; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #f0f0f0; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.worse { color: #b00020; } td.better { color: #0a6e31; }
code { font-size: 0.85em; background: #f6f6f6; padding: 1px 3px; word-break: break-all; }
img { max-width: 100%; }
figure { display: inline-block; margin: 0.5em; }
"""


def read_rows(parquet: Path) -> list[dict[str, Any]]:
    """The report's columns of the table (not every figure: the page needs a few)."""
    import pyarrow.parquet as pq

    names = set(pq.read_schema(parquet).names)
    table = pq.read_table(parquet, columns=[c for c in _COLUMNS if c in names])
    rows: list[dict[str, Any]] = table.to_pylist()
    return rows


def write_report(plan: SweepPlan, layout: SweepLayout, parquet: Path) -> Path:
    path = layout.out / "report.html"
    tmp = path.with_name(".report.html.tmp")
    tmp.write_text(
        report_html(plan, read_rows(parquet), layout=layout, base=layout.out), encoding="utf-8"
    )
    tmp.replace(path)  # whole or not at all
    return path


def report_html(
    plan: SweepPlan, rows: Sequence[Mapping[str, Any]], *, layout: SweepLayout, base: Path
) -> str:
    esc = html.escape
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    ref = plan.reference.name
    metric = ranking_metric(ok)
    parts = [
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>",
        f"<title>routefuse sweep: {len(plan.logs)} logs x {len(plan.sets)} sets</title>",
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>routefuse sweep: {len(plan.logs)} logs &times; {len(plan.sets)} parameter sets</h1>",
        f"<p>{len(rows)} tasks, {len(ok)} ok, {len(failed)} failed. Reference set: "
        f"<b>{esc(ref)}</b>. Figures are those of each set's method over the GNSS-degraded "
        "intervals (<code>routefuse run</code>'s table); every figure of every task is in "
        "<code>results.parquet</code> / <code>results.csv</code>.</p>",
        _sets_table(plan, rows, layout, metric),
        _distributions(plan, ok),
        _ranked(plan, ok, layout, base, metric),
        *_per_log(plan, ok, metric),
        _overconfident(plan, ok, layout),
        _failures(failed),
        "</body></html>\n",
    ]
    return "\n".join(parts)


def _sets_table(
    plan: SweepPlan, rows: Sequence[Mapping[str, Any]], layout: SweepLayout, metric: str
) -> str:
    esc = html.escape
    body = []
    for s in plan.sets:
        mine = [r for r in rows if r["set"] == s.name]
        good = [r for r in mine if r["status"] == "ok"]
        med = _median([r.get(metric) for r in good])
        cost = _median([r.get("total_s") for r in good])
        peak = max((r.get("worker_peak_rss_mb") or 0.0 for r in mine), default=0.0)
        config = layout.set_config(s.slug).relative_to(layout.out).as_posix()
        body.append(
            f"<tr><td>{esc(s.name)}</td><td>{esc(s.method)}</td>"
            f"<td>{esc(format_values(plan.differing(s))) or '(reference)'}</td>"
            f"<td><a href='{esc(quote(config))}'>{esc(config)}</a></td>"
            f"<td class='num'>{len(good)}/{len(mine)}</td><td class='num'>{_num(med)}</td>"
            f"<td class='num'>{_num(cost, 2)}</td><td class='num'>{_num(peak, 0)}</td></tr>"
        )
    return (
        "<h2>Parameter sets</h2><table><tr><th>set</th><th>method</th>"
        "<th>differs from the reference</th><th>parameters</th><th>ok</th>"
        f"<th>median {esc(_TITLES[metric])}</th><th>median task [s]</th>"
        "<th>worker peak [MB]</th></tr>\n" + "\n".join(body) + "</table>"
    )


def _distributions(plan: SweepPlan, ok: Sequence[Mapping[str, Any]]) -> str:
    """One box-and-strip plot per key figure, a box per set."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = [s.name for s in plan.sets]
    figures = []
    for metric in KEY_METRICS:
        data = [
            [float(r[metric]) for r in ok if r["set"] == n and _finite(r.get(metric))]
            for n in names
        ]
        if not any(data):
            continue
        fig, ax = plt.subplots(figsize=(max(4.0, 1.1 * len(names) + 2.0), 3.2), dpi=96)
        positions = [i for i, d in enumerate(data) if d]
        ax.boxplot([data[i] for i in positions], positions=positions, widths=0.5, showfliers=False)
        rng = np.random.default_rng(0)
        for i in positions:
            jitter = rng.uniform(-0.15, 0.15, len(data[i]))
            ax.plot(i + jitter, data[i], "o", ms=3, alpha=0.6, color="#1f77b4")
        ax.set_xticks(range(len(names)), [_short(n) for n in names], rotation=20, ha="right")
        ax.set_ylabel(_TITLES[metric])
        ax.grid(axis="y", alpha=0.3)
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
        plt.close(fig)
        encoded = base64.b64encode(buf.getvalue()).decode("ascii")
        figures.append(
            f"<figure><img alt='{html.escape(_TITLES[metric])} per set' "
            f"src='data:image/png;base64,{encoded}'></figure>"
        )
    if not figures:
        return "<h2>Distributions</h2><p>No task has figures (no GNSS-degraded interval?).</p>"
    return "<h2>Distributions per set</h2>\n" + "\n".join(figures)


def _deltas(plan: SweepPlan, ok: Sequence[Mapping[str, Any]], metric: str) -> list[dict[str, Any]]:
    """(task row, reference row, delta) for every non-reference task with both figures."""
    ref_name = plan.reference.name
    reference = {r["label"]: r for r in ok if r["set"] == ref_name}
    out = []
    for r in ok:
        if r["set"] == ref_name:
            continue
        base = reference.get(r["label"])
        if base is None or not (_finite(r.get(metric)) and _finite(base.get(metric))):
            continue
        out.append({"row": r, "ref": base, "delta": r[metric] - base[metric]})
    return out


def _ranked(
    plan: SweepPlan,
    ok: Sequence[Mapping[str, Any]],
    layout: SweepLayout,
    base: Path,
    metric: str,
) -> str:
    deltas = _deltas(plan, ok, metric)
    if len(plan.sets) < 2:
        return "<h2>Regressions</h2><p>One parameter set: nothing to compare.</p>"
    worst = sorted((d for d in deltas if d["delta"] > 0), key=lambda d: -d["delta"])[:RANKED]
    best = sorted((d for d in deltas if d["delta"] < 0), key=lambda d: d["delta"])[:RANKED]
    return _ranked_table("Worst regressions", worst, plan, layout, base, metric) + _ranked_table(
        "Best improvements", best, plan, layout, base, metric
    )


def _ranked_table(
    title: str,
    items: Sequence[Mapping[str, Any]],
    plan: SweepPlan,
    layout: SweepLayout,
    base: Path,
    metric: str,
) -> str:
    esc = html.escape
    head = (
        f"<h2>{esc(title)}</h2><p>by {esc(_TITLES[metric])}, the set against "
        f"<b>{esc(plan.reference.name)}</b> on the same log</p>"
    )
    if not items:
        return head + "<p>None.</p>"
    slugs = {s.name: s.slug for s in plan.sets}
    replays = [_replay_link(d["row"], base) for d in items]
    extra = "<th>replay</th>" if any(replays) else ""
    body = []
    for d, replay in zip(items, replays, strict=True):
        r, ref = d["row"], d["ref"]
        command = serve_command(r, layout.set_config(slugs[r["set"]]))
        cls = "worse" if d["delta"] > 0 else "better"
        body.append(
            f"<tr><td>{esc(r['label'])}</td><td>{esc(r['set'])}</td>"
            f"<td class='num'>{_num(ref[metric])}</td>"
            f"<td class='num'>{_num(r[metric])}</td>"
            f"<td class='num {cls}'>{d['delta']:+.3f}</td>"
            f"<td><code>{esc(command)}</code></td>"
            + (f"<td>{replay}</td>" if extra else "")
            + "</tr>"
        )
    return (
        head + "<table><tr><th>log</th><th>set</th><th>reference [m]</th><th>this set [m]</th>"
        f"<th>change [m]</th><th>open it</th>{extra}</tr>\n" + "\n".join(body) + "</table>"
    )


def _replay_link(row: Mapping[str, Any], base: Path) -> str:
    """A link to the row's replay export (relative to the report when it is inside its
    folder), or "" when the task wrote none."""
    if not row.get("export_dir"):
        return ""
    target = (Path(row["export_dir"]) / "replay.html").resolve()
    if not target.is_file():
        return ""
    try:
        href = target.relative_to(base.resolve()).as_posix()
    except ValueError:
        href = target.as_posix()
    return f"<a href='{html.escape(quote(href))}'>replay</a>"


def serve_command(row: Mapping[str, Any], config: Path) -> str:
    """The shell command that opens the row's log with its set in the inspector."""
    words = ["routefuse", "serve", str(row["log"])]
    if row.get("route"):
        words += ["--route", str(row["route"])]
    words += ["--config", str(config)]
    for outage in str(row.get("outages") or "").split():
        words += ["--outage", outage]
    return shlex.join(words)


def _per_log(plan: SweepPlan, ok: Sequence[Mapping[str, Any]], metric: str) -> list[str]:
    """The per-log table by ``metric``; with truth as the metric, the logs without ground truth
    get a table of their own by the route deviation, said to be that (they used to be a row of
    dashes in the truth table, their change shown nowhere); without truth anywhere, a warning
    that the route deviation is all there is."""
    if len(plan.sets) < 2:
        return []
    if metric == ROUTE_METRIC:
        return [
            "<p><b>No log has ground truth</b>: logs are compared by their position deviation "
            "from the route, which rewards following a wrong map; open the worst in the "
            "inspector before trusting a change.</p>",
            _delta_table(plan, ok, metric),
        ]
    with_truth = {r["label"] for r in ok if _finite(r.get(metric))}
    parts = [_delta_table(plan, [r for r in ok if r["label"] in with_truth], metric)]
    without = [r for r in ok if r["label"] not in with_truth]
    if without:
        parts.append(
            _delta_table(
                plan,
                without,
                ROUTE_METRIC,
                title=f"Logs without ground truth ({len({r['label'] for r in without})}): "
                f"change of {_TITLES[ROUTE_METRIC]} from the route",
                note="Not in the rankings above, which use the error against ground truth. A "
                "route deviation rewards following a wrong map: a smaller one is not "
                "necessarily better.",
            )
        )
    return parts


def _delta_table(
    plan: SweepPlan,
    ok: Sequence[Mapping[str, Any]],
    metric: str,
    *,
    title: str | None = None,
    note: str = "",
) -> str:
    esc = html.escape
    others = [s.name for s in plan.sets[1:]]
    if not others or not ok:
        return ""
    ref_name = plan.reference.name
    by_log: dict[str, dict[str, Any]] = {}
    for r in ok:
        by_log.setdefault(r["label"], {})[r["set"]] = r.get(metric)
    rows = []
    for label, values in by_log.items():
        ref = float(values[ref_name]) if _finite(values.get(ref_name)) else None
        deltas: dict[str, float] = {}
        if ref is not None:
            deltas = {n: float(values[n]) - ref for n in others if _finite(values.get(n))}
        rows.append((max(deltas.values(), default=-math.inf), label, ref, deltas))
    rows.sort(key=lambda t: -t[0])
    body = []
    for _, label, ref, deltas in rows[:MAX_DELTA_ROWS]:
        cells = "".join(
            f"<td class='num {_cls(deltas.get(n))}'>{_signed(deltas.get(n))}</td>" for n in others
        )
        body.append(f"<tr><td>{esc(label)}</td><td class='num'>{_num(ref)}</td>{cells}</tr>")
    more = (
        f"<p>{len(rows) - MAX_DELTA_ROWS} more logs in results.parquet.</p>"
        if len(rows) > MAX_DELTA_ROWS
        else ""
    )
    head = "".join(f"<th>{esc(_short(n))}</th>" for n in others)
    heading = title or f"Per log: change of {_TITLES[metric]} against {ref_name}"
    return (
        f"<h2>{esc(heading)}</h2>" + (f"<p>{esc(note)}</p>" if note else "") + "<table><tr>"
        f"<th>log</th><th>{esc(_short(ref_name))} [m]</th>"
        f"{head}</tr>\n" + "\n".join(body) + "</table>" + more
    )


def _overconfident(plan: SweepPlan, ok: Sequence[Mapping[str, Any]], layout: SweepLayout) -> str:
    """The tasks with an outage that ended farther from the fixes after it than its sigmas allow
    (the exit check, ``exits_overconfident``), worst first, each with the command that opens it
    in the inspector: on logs without ground truth, the one sign that a run was confidently
    wrong (or its receiver's fixes worse than they claim)."""
    esc = html.escape
    slugs = {s.name: s.slug for s in plan.sets}
    flagged = [r for r in ok if (r.get("exits_overconfident") or 0) > 0]
    intro = (
        "<h2>Outages that ended beyond their sigmas</h2><p>The exit check: where each outage's "
        "estimate ended against the fixes that came back after it, a chi-square of 2 degrees of "
        "freedom over 13.8 (once in a thousand outages when the estimate and the fixes are as "
        "good as they claim)."
    )
    if not flagged:
        return intro + " None.</p>"
    flagged.sort(key=lambda r: -(r.get("exit_chi2_max") or 0.0))
    body = "\n".join(
        f"<tr><td>{esc(r['label'])}</td><td>{esc(r['set'])}</td>"
        f"<td class='num'>{int(r['exits_overconfident'])} of {int(r.get('exits') or 0)}</td>"
        f"<td class='num'>{_num(math.sqrt(r.get('exit_chi2_max') or 0.0), 1)}</td>"
        f"<td><code>{esc(serve_command(r, layout.set_config(slugs[r['set']])))}</code></td></tr>"
        for r in flagged[:MAX_DELTA_ROWS]
    )
    more = (
        f"<p>{len(flagged) - MAX_DELTA_ROWS} more in results.parquet.</p>"
        if len(flagged) > MAX_DELTA_ROWS
        else ""
    )
    return (
        f"{intro} {len(flagged)} task{'s' if len(flagged) > 1 else ''}.</p><table><tr>"
        "<th>log</th><th>set</th>"
        "<th>outages flagged</th><th>worst [sigma]</th><th>open it</th></tr>\n"
        f"{body}</table>{more}"
    )


def _failures(failed: Sequence[Mapping[str, Any]]) -> str:
    if not failed:
        return "<h2>Failed tasks</h2><p>None.</p>"
    esc = html.escape
    body = "\n".join(
        f"<tr><td>{esc(r['label'])}</td><td>{esc(r['set'])}</td><td>{esc(r['error'] or '')}</td>"
        "</tr>"
        for r in failed
    )
    return (
        f"<h2>Failed tasks ({len(failed)})</h2><table><tr><th>log</th><th>set</th>"
        f"<th>error</th></tr>\n{body}</table>"
    )


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and math.isfinite(v)


def _median(values: Sequence[Any]) -> float | None:
    finite = sorted(float(v) for v in values if _finite(v))
    if not finite:
        return None
    mid = len(finite) // 2
    return finite[mid] if len(finite) % 2 else 0.5 * (finite[mid - 1] + finite[mid])


def _num(v: Any, digits: int = 3) -> str:
    return f"{float(v):.{digits}f}" if _finite(v) else "&ndash;"


def _signed(v: Any) -> str:
    return signed(float(v)) if _finite(v) else "&ndash;"


def _cls(v: Any) -> str:
    if not _finite(v) or v == 0:
        return ""
    return "worse" if v > 0 else "better"


def _short(name: str, limit: int = 40) -> str:
    return name if len(name) <= limit else name[: limit - 3] + "..."
