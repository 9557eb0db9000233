"""The Match tab: the attempt shown at the playhead, every gate with its verdict, then the fit."""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from estimator.results import Gate, GateDecision, MatchRecord
from inspector.controller import Session

UNDONE_HERE = (
    "This update moved the position too far from dead reckoning: the outage's route updates, "
    "this one included, were undone and the rest of the outage is dead-reckoned."
)
"""the line under the head of the attempt whose dr_separation gate undid the route updates
(a REJECTED whose other gates all passed reads as a contradiction without it)"""


REANCHORED = (
    "Accepted although the gates marked failed refused it: consecutive sound matches kept "
    "being refused for disagreeing with the filter by no more than a plausible drift, so the "
    "filter's heading and position covariance were widened to this innovation "
    "(extensions.reanchor)."
)
REACQUIRED = (
    "Accepted although the gates marked failed refused it: the IMU gap that ended at {end:.1f} s "
    "left the heading off by the road's turn inside it, which the route shows "
    "({turn:+.1f} deg here); heading and position were re-anchored to the route "
    "(extensions.gap_reacquire)."
)
"""the line under the head of a re-anchored attempt (an ACCEPTED with failed gates reads as a
contradiction without it)"""
BRIDGED = (
    "Before this attempt the IMU gap that ended at {end:.1f} s was bridged along the route: the "
    "wheels' {along:.0f} m along the road moved the position {moved:.1f} m from the straight "
    "line the gap left it on and turned its heading {turn:+.1f} deg to the road's "
    "(extensions.gap_route_bridge)."
)
"""the line under the head of the attempt an IMU gap was bridged along the route before"""


def _fmt(v: Any, digits: int = 3) -> str:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not np.isfinite(f):
        return "–"
    return f"{f:.{digits}f}" if abs(f) < 1e5 else f"{f:.3g}"


def _angle(cos: float) -> str:
    """The angle whose cosine the heading gate compares, in degrees."""
    return f"{np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))):.1f}°"


HEADING_NOTE = (
    "angle between the DR and route end directions, deg (gates.max_heading_diff_deg; the "
    "matcher compares its cosine, the fit's heading cos)"
)
"""the heading row's note: the row shows the angle, not the cosine the gate's own note names"""


def _gate_row(g: GateDecision) -> tuple[str, str, str]:
    """A gate's value, comparison and threshold as a person reads them: a count without
    decimals; the heading gate as the angle between the directions, the unit its parameter
    (gates.max_heading_diff_deg) is set in, not the cosines the matcher compares ('0.922 >=
    0.985' is '22.8° <= 10.0°'); the others as the matcher compares them."""
    value = "no rival" if g.no_rival else _fmt(g.value)
    if g.gate is Gate.MIN_PAIRS:
        return _fmt(g.value, 0), g.comparison, _fmt(g.threshold, 0)
    finite = np.isfinite([g.value, g.threshold]).all()
    if g.gate is Gate.HEADING and g.comparison == ">=" and finite:
        return _angle(g.value), "<=", _angle(g.threshold)
    return value, g.comparison, _fmt(g.threshold)


def _vec(v: Any, digits: int = 2) -> str:
    a = np.asarray(v, np.float64).reshape(-1)
    if a.size == 0 or not np.all(np.isfinite(a)):
        return "–"
    return "(" + ", ".join(f"{x:.{digits}f}" for x in a) + ")"


ROUTE_AXES_SHOWN = ("filter_along_sigma_m", "filter_cross_sigma_m")
"""diagnostics the route-axes table shows, left out of the rows of the rest"""


def route_axes_rows(m: MatchRecord) -> list[str]:
    """The innovation beside the two sigmas the Mahalanobis gate adds, S = filter_cov +
    obs_cov, along and across the route (+ left), in metres: whether a refusal came from a
    filter sure of a position it drifted from or from a fit claiming more than its shape
    shows. The filter's is before the update (the epoch row after it is the posterior), the
    position relative to the route (its map-bias error added where the run carries one).
    Nothing without a fit (no route direction)."""
    if m.fit is None:
        return []
    nu = np.asarray(m.innovation, np.float64)
    along, across = float(m.tangent @ nu), float(m.normal @ nu)
    f_along, f_across = m.route_sigmas(m.filter_cov)
    o_along, o_across = m.route_sigmas(m.obs_cov)
    return [
        "| route axes, m | along | across (+ left) |",
        "|---|---:|---:|",
        f"| innovation | {_fmt(along, 2)} | {_fmt(across, 2)} |",
        f"| filter 1-sigma, before the update | {_fmt(f_along, 2)} | {_fmt(f_across, 2)} |",
        f"| observation 1-sigma | {_fmt(o_along, 2)} | {_fmt(o_across, 2)} |",
    ]


def match_markdown(
    m: MatchRecord | None,
    *,
    t_rel: float | None = None,
    age_s: float = 0.0,
    total: int | None = None,
) -> str:
    """The match panel: every gate with value, threshold and verdict, then the fit.

    ``#index`` is the attempt's number in its run (from 0, as on the map, in ``routefuse run``
    and in the export); with ``total`` (the run's attempt count) the head also says which of
    them it is counted from 1, so that the last of 352 does not read "#351 of 352"."""
    if m is None:
        return "*No match attempt before this time.*"
    failed = [g for g in m.gates if not g.passed]
    head = "ACCEPTED" if m.accepted else "REJECTED"
    if failed and not m.accepted:
        head += " by " + ", ".join(g.name for g in failed)
    if m.accepted and m.reanchored:
        head += " (re-anchored)"
    when = f" at t = {t_rel:.2f} s" if t_rel is not None else ""
    age = f" ({age_s:.2f} s ago)" if age_s > 0.005 else ""
    count = f" ({m.index + 1} of {total})" if total else ""
    lines = [f"**Attempt #{m.index}{count}{when}{age}: {head}**", ""]
    undone = next((g for g in failed if g.gate is Gate.DR_SEPARATION), None)
    if undone is not None:
        here = "dr_separation_m" in m.extra  # the undoing attempt; a later one's note says when
        lines += [f"*{UNDONE_HERE if here else undone.note}*", ""]
    if m.accepted and m.reanchored:
        end = m.extra.get("gap_end_s")
        why = (
            REANCHORED
            if end is None
            else REACQUIRED.format(end=end, turn=float(np.degrees(m.rotation_rad)))
        )
        lines += [f"*{why}*", ""]
    if "gap_bridge_end_s" in m.extra:
        e = m.extra
        bridged = BRIDGED.format(
            end=e["gap_bridge_end_s"],
            along=e["gap_bridge_along_m"],
            moved=e["gap_bridge_moved_m"],
            turn=e["gap_bridge_turn_deg"],
        )
        lines += [f"*{bridged}*", ""]
    lines += [
        "| gate | value | limit | verdict |",
        "|---|---:|---:|---|",
    ]
    notes = []
    for g in m.gates:
        verdict = "✓ passed" if g.passed else "✗ **FAILED**"
        value, comparison, threshold = _gate_row(g)
        lines.append(f"| {g.name} | {value} | {comparison} {threshold} | {verdict} |")
        note = HEADING_NOTE if g.gate is Gate.HEADING and value.endswith("°") else g.note
        if note:
            notes.append(f"*{g.name}*: {note}")
    axes = route_axes_rows(m)
    if axes:
        lines += ["", *axes]
    corr = np.asarray(m.correction, np.float64).reshape(-1)
    corr_norm = float(np.hypot(*corr)) if corr.size == 2 and np.all(np.isfinite(corr)) else np.nan
    cov = np.asarray(m.obs_cov, np.float64)
    sig = np.sqrt(np.clip(np.diag(cov), 0, None)) if cov.shape == (2, 2) else np.full(2, np.nan)
    lines += [
        "",
        "| fit | |",
        "|---|---:|",
        f"| rotation | {_fmt(np.degrees(m.rotation_rad))} deg |",
        f"| translation E, N | {_vec(m.translation)} m |",
        f"| residual (RMS) | {_fmt(m.residual_m)} m |",
        f"| pairs | {m.n_pairs} |",
        f"| heading cos | {_fmt(m.heading_cos, 4)} |",
        f"| route arc length | {_fmt(m.route_s[0], 1)} – {_fmt(m.route_s[1], 1)} m |",
        f"| lane offset | {_fmt(m.lane_offset_m, 2)} m |",
        f"| p_dr → z | {_vec(m.p_dr)} → {_vec(m.pseudo_position)} |",
        f"| innovation E, N | {_vec(m.innovation)} m |",
        f"| correction E, N | {_vec(m.correction)} m (\\|c\\| = {_fmt(corr_norm, 2)} m) |",
        f"| obs. 1-sigma E, N | {_vec(sig)} m |",
    ]
    lines += [
        f"| {k} | {_fmt(v)} |"
        for k, v in sorted(m.diagnostics().items())
        if k not in ROUTE_AXES_SHOWN
    ]
    if notes:
        lines += ["", "<small>" + "; ".join(notes) + "</small>"]
    return "\n".join(lines)


class MatchPanel:
    """The markdown of the attempt at the playhead, redrawn only when that attempt (or the
    off-route note above it) changes."""

    def __init__(self, gui: viser.GuiApi) -> None:
        self.markdown = gui.add_markdown(match_markdown(None))
        self.shown: tuple[int, int | None, str] | None = None

    def forget(self) -> None:
        """Redraw at the next :meth:`show` (a new session)."""
        self.shown = None

    def show(self, s: Session, t: float) -> None:
        tl = s.timeline
        i = tl.match_at(t)
        off_head = s.off_route.panel_text(t, i) if s.off_route is not None else ""
        key = (s.version, i, off_head)
        if key == self.shown:
            return
        self.shown = key
        m = s.proposed.matches[i] if i is not None else None
        panel = match_markdown(
            m,
            t_rel=None if i is None else float(tl.match_t[i]),
            age_s=0.0 if i is None else t - float(tl.match_t[i]),
            total=len(tl.match_t),
        )
        self.markdown.content = f"{off_head}\n\n{panel}" if off_head else panel
