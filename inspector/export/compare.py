"""Two parameter sets on one log, headless (``routefuse export --compare A.toml B.toml``): the
metrics of A, B and their difference, and every match attempt whose verdict changed, with both
gate tables side by side, as CSV files and one self-contained page.

Attempts are paired by time: the matcher tries at fixed times into each outage, so the same
attempt of the two runs is the one at the same time (within half the trigger interval); an
attempt only one run made is listed with the other side empty.
"""

from __future__ import annotations

import csv
import html
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from estimator.io import AUTO_TOPICS, TopicChoice
from estimator.params import Method, Params, params_to_toml
from estimator.results import GateDecision, MatchRecord, Run
from inspector.numbers import signed

PAIR_TOLERANCE_S = 0.5
METRIC_KEYS = (
    ("truth", "rmse_h_err_m", "truth horizontal RMSE [m]"),
    ("truth", "max_h_err_m", "truth horizontal max [m]"),
    ("truth", "rmse_along_m", "truth along-track RMSE [m]"),
    ("truth", "rmse_cross_m", "truth cross-track RMSE [m]"),
    ("route", "rmse_pos_dev_m", "route deviation RMSE [m] (from the route line)"),
    ("route", "max_pos_dev_m", "route deviation max [m] (from the route line)"),
)


@dataclass(frozen=True)
class ChangedVerdict:
    """One attempt whose verdict differs between the runs (None: that run made no attempt)."""

    t: float
    """s after the log start"""
    a: MatchRecord | None
    b: MatchRecord | None


@dataclass(frozen=True)
class Comparison:
    metrics: tuple[tuple[str, float | None, float | None], ...]
    """(quantity, A, B)"""
    attempts: tuple[int, int]
    accepted: tuple[int, int]
    changed: tuple[ChangedVerdict, ...]


def compare_runs(
    a: Run, b: Run, metrics_a: dict[str, Any], metrics_b: dict[str, Any]
) -> Comparison:
    """A and B's figures (``method_metrics(...).to_dict()`` of each) and changed verdicts."""

    def value(doc: dict[str, Any], part: str, key: str) -> float | None:
        section = doc.get(part) or {}
        v = section.get(key)
        return None if v is None else float(v)

    rows = tuple(
        (label, value(metrics_a, part, key), value(metrics_b, part, key))
        for part, key, label in METRIC_KEYS
    )
    return Comparison(
        metrics=rows,
        attempts=(len(a.matches), len(b.matches)),
        accepted=(sum(m.accepted for m in a.matches), sum(m.accepted for m in b.matches)),
        changed=changed_verdicts(a, b),
    )


def changed_verdicts(a: Run, b: Run) -> tuple[ChangedVerdict, ...]:
    """Attempts paired by time whose verdicts differ, in time order."""
    out: list[ChangedVerdict] = []
    j = 0
    bs = list(b.matches)
    used = [False] * len(bs)
    for ma in a.matches:
        while j < len(bs) and bs[j].t < ma.t - PAIR_TOLERANCE_S:
            j += 1
        k = j
        partner = None
        while k < len(bs) and bs[k].t <= ma.t + PAIR_TOLERANCE_S:
            if not used[k]:
                partner = k
                break
            k += 1
        if partner is None:
            out.append(ChangedVerdict(ma.t - a.t0, ma, None))
            continue
        used[partner] = True
        mb = bs[partner]
        if ma.verdict != mb.verdict:
            out.append(ChangedVerdict(ma.t - a.t0, ma, mb))
    out += [ChangedVerdict(m.t - b.t0, None, m) for m, u in zip(bs, used, strict=True) if not u]
    return tuple(sorted(out, key=lambda c: c.t))


def _fmt(v: float | None) -> str:
    if v is None or not math.isfinite(v):
        return "" if v is None else str(v)
    return f"{v:.3f}"


def _delta(va: float | None, vb: float | None) -> str:
    """B - A with its sign, never ``-0.000``; empty where either is missing."""
    if va is None or vb is None:
        return ""
    d = vb - va
    return signed(d) if math.isfinite(d) else str(d)


def write_comparison(
    out: Path,
    comparison: Comparison,
    params_a: Params,
    params_b: Params,
    names: Sequence[str],
    *,
    log: Path | None = None,
    route: Path | None = None,
    method: str | None = None,
) -> tuple[Path, ...]:
    """``compare_metrics.csv``, ``changed_verdicts.csv``, ``compare.html`` and the two sets as
    ``set_a.toml`` / ``set_b.toml``; returns the paths. The page names the ``log``, ``route``
    and ``method`` compared on (a page mailed on its own says what it is about)."""
    metrics_csv = out / "compare_metrics.csv"
    with open(metrics_csv, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["quantity", "A", "B", "B - A"])
        for label, va, vb in comparison.metrics:
            w.writerow([label, _fmt(va), _fmt(vb), _delta(va, vb)])
        w.writerow(["match attempts", *comparison.attempts, ""])
        w.writerow(["accepted", *comparison.accepted, ""])
    changed_csv = out / "changed_verdicts.csv"
    with open(changed_csv, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "A_attempt", "A_verdict", "B_attempt", "B_verdict"])
        for c in comparison.changed:
            w.writerow(
                [
                    f"{c.t:.2f}",
                    "" if c.a is None else c.a.index,
                    "(no attempt)" if c.a is None else c.a.verdict,
                    "" if c.b is None else c.b.index,
                    "(no attempt)" if c.b is None else c.b.verdict,
                ]
            )
    toml_a, toml_b = out / "set_a.toml", out / "set_b.toml"
    toml_a.write_text(params_to_toml(params_a), encoding="utf-8")
    toml_b.write_text(params_to_toml(params_b), encoding="utf-8")
    page = out / "compare.html"
    page.write_text(_page(comparison, names, log, route, method), encoding="utf-8")
    return metrics_csv, changed_csv, toml_a, toml_b, page


def _gate_table(rec: MatchRecord | None) -> str:
    if rec is None:
        return "<p><i>no attempt at this time</i></p>"
    rows = "".join(_gate_row(g) for g in rec.gates)
    return (
        f"<p><b>#{rec.index}: {html.escape(rec.verdict)}</b></p>"
        "<table><tr><th>gate</th><th>value</th><th>limit</th><th>verdict</th></tr>"
        f"{rows}</table>"
    )


def _gate_row(g: GateDecision) -> str:
    verdict = "passed" if g.passed else "<b>FAILED</b>"
    return (
        f"<tr><td>{html.escape(g.name)}</td><td>{html.escape(_fmt(g.value))}</td>"
        f"<td>{html.escape(g.comparison)} {html.escape(_fmt(g.threshold))}</td>"
        f"<td>{verdict}</td></tr>"
    )


def _page(
    c: Comparison,
    names: Sequence[str],
    log: Path | None = None,
    route: Path | None = None,
    method: str | None = None,
) -> str:
    esc = html.escape
    a_name, b_name = (esc(n) for n in names)
    about = []
    if log is not None:
        about.append(f"log <code>{esc(str(log))}</code>")
    if route is not None:
        about.append(f"route <code>{esc(str(route))}</code>")
    if method is not None:
        about.append(f"method {esc(method)}")
    if all(va is None and vb is None for label, va, vb in c.metrics if label.startswith("truth")):
        about.append(
            "no ground truth in this log: only the route deviation, which rewards following "
            "the map, is compared"
        )
    context = f"<p>{'<br>'.join(about)}</p>" if about else ""
    title = f"{esc(log.name)}: " if log is not None else ""
    metric_rows = "".join(
        f"<tr><td>{esc(label)}</td><td>{_fmt(va)}</td><td>{_fmt(vb)}</td>"
        f"<td>{_delta(va, vb)}</td></tr>"
        for label, va, vb in c.metrics
    )
    changed = "".join(
        f'<tr><td>{x.t:.2f} s</td><td class="side">{_gate_table(x.a)}</td>'
        f'<td class="side">{_gate_table(x.b)}</td></tr>'
        for x in c.changed
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>routefuse: {title}{a_name} vs {b_name}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }}
table {{ border-collapse: collapse; margin-bottom: 1em; }}
th, td {{ border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: right; vertical-align: top; }}
th:first-child, td:first-child {{ text-align: left; }}
td.side table {{ margin: 0; }}
</style></head><body>
<h1>A: {a_name} &nbsp;vs&nbsp; B: {b_name}</h1>
{context}
<h2>Metrics over the GNSS-degraded intervals</h2>
<table><tr><th>quantity</th><th>A</th><th>B</th><th>B - A</th></tr>{metric_rows}
<tr><td>match attempts</td><td>{c.attempts[0]}</td><td>{c.attempts[1]}</td><td></td></tr>
<tr><td>accepted</td><td>{c.accepted[0]}</td><td>{c.accepted[1]}</td><td></td></tr></table>
<h2>Attempts whose verdict changed ({len(c.changed)})</h2>
<table><tr><th>time</th><th>A: {a_name}</th><th>B: {b_name}</th></tr>{changed}</table>
</body></html>
"""


def export_comparison(
    log: Path,
    route: Path,
    out: Path,
    set_a: Path,
    set_b: Path,
    *,
    method: Method = "proposed",
    outages: Sequence[tuple[float, float]] = (),
    topics: TopicChoice = AUTO_TOPICS,
    route_feature: str | int | None = None,
) -> tuple[Comparison, tuple[Path, ...]]:
    """Run ``method`` with the parameter sets of two TOML files over one log (the second
    resuming from the first where only matching parameters differ) and write the comparison
    into ``out``."""
    from estimator.evaluation import method_metrics
    from estimator.params import load_params
    from estimator.pipeline import open_inputs, run_methods
    from inspector.export.replay import make_dir

    params_a, params_b = load_params(set_a), load_params(set_b)
    inputs = open_inputs(log, route, topics=topics, route_feature=route_feature)
    runs_a = run_methods(inputs, params_a, methods=(method,), outages=outages)
    runs_b = run_methods(inputs, params_b, methods=(method,), outages=outages, reuse=runs_a)
    a, b = runs_a[method], runs_b[method]
    assert inputs.route is not None
    docs = [method_metrics(r, inputs.route, inputs.log, params=r.params).to_dict() for r in (a, b)]
    comparison = compare_runs(a, b, docs[0], docs[1])
    make_dir(out)
    return comparison, write_comparison(
        out,
        comparison,
        params_a,
        params_b,
        (set_a.name, set_b.name),
        log=log,
        route=route,
        method=method,
    )
