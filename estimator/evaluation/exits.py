"""The exit check: where each GNSS outage's estimate ended against the fixes that followed it.

A log without ground truth still has this one measure of an outage, and it is the one that
tells a confident wrong answer from an honest one: an estimate that followed a wrong map, or
dead reckoning beyond its noise model, comes out of the tunnel far from the returning fixes
under a small claimed sigma. The fixes compared are the first ones the filter itself accepted
after the outage (its robust GNSS test drops the multipath jumps at a portal, and after a gap
takes fixes once they agree with each other), and the estimate is carried on to each from the
outage's end by the run's own velocity, so the position jumps their updates make play no
part. It is judged by the covariance it claimed at the outage's end, the claim the outage's
updates left: the seconds of dead reckoning before the filter trusts fixes again count against
it (without wheel speed a poor velocity then adds metres, and the check leans to flagging).
Taking the estimate and covariance just before the first accepted fix instead was measured and
not kept: after a multi-tunnel sim's outage (IMU-only sim 6) the non-holonomic constraint in
the turn after the portal moves the position 109 m before any fix is trusted, and the check
would then judge the turn, not the outage."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from estimator.errors import named_and_summed
from estimator.results import Epochs, OutageExit, Run

F64 = NDArray[np.float64]

EXIT_SPAN_S = 3.0
"""the fixes accepted within this long of the first are compared (their median): one fix is
one multipath jump away from a false alarm, and a receiver holds a jump for about a second"""


def outage_exits(
    epochs: Epochs,
    degraded: Sequence[tuple[float, float]],
    fix_t: F64,
    fix_pos: F64,
    fix_var: F64,
    lever_arm_m: Sequence[float],
) -> tuple[OutageExit, ...]:
    """One :class:`~estimator.results.OutageExit` per interval of ``degraded`` (absolute times)
    after which the run accepted a fix. ``fix_t``, ``fix_pos`` ((N, >=2) E, N m) and
    ``fix_var`` ((N, >=2) m^2, the fixes' whole variance) are the filter's fixes on the IMU
    clock; ``lever_arm_m`` the antenna in the body frame (forward, left, up: the horizontal
    part is turned by the yaw)."""
    e = epochs
    if len(e) < 2 or len(fix_t) == 0:
        return ()
    # where the estimate would be by its own velocity, from epoch 0 on (trapezoid)
    carried = np.zeros((len(e), 2))
    carried[1:] = np.cumsum(
        0.5 * (e.velocity[1:, :2] + e.velocity[:-1, :2]) * np.diff(e.t)[:, None], 0
    )
    fwd, left = float(lever_arm_m[0]), float(lever_arm_m[1])
    starts = np.sort(np.array([a for a, _ in degraded], np.float64))
    used = np.flatnonzero(e.gnss_used)
    used = used[used > 0]
    out = []
    for a, b in degraded:
        # fixes after the next outage would judge two outages' drift as one
        following = starts[np.searchsorted(starts, a, side="right") :]
        stop = float(following[0]) if len(following) else math.inf
        k_lo, k_b = np.searchsorted(e.t, [a, b], side="left")
        if k_b <= k_lo:
            continue
        k_end = int(k_b) - 1
        first = used[np.searchsorted(used, k_b) :]
        if len(first) == 0 or e.t[first[0]] >= stop:
            continue
        k_hi = min(
            np.searchsorted(e.t, e.t[first[0]] + EXIT_SPAN_S, side="right"),
            np.searchsorted(e.t, stop, side="left"),
        )
        accepted = first[: np.searchsorted(first, k_hi)]
        chosen: list[tuple[int, int]] = []
        for k in accepted.tolist():
            lo, hi = np.searchsorted(fix_t, [e.t[k - 1], e.t[k]], side="right")
            if hi > lo:
                chosen.append((int(hi) - 1, k))
        if not chosen:
            continue
        errors = []
        for i, k in chosen:
            yaw = float(e.attitude[k - 1, 2])
            c, s = math.cos(yaw), math.sin(yaw)
            lever = np.array([c * fwd - s * left, s * fwd + c * left])
            # the estimate at the fix: its place at the outage's end, moved by its velocity
            moved = (
                np.array([np.interp(fix_t[i], e.t, carried[:, j]) for j in range(2)])
                - carried[k_end]
            )
            errors.append(e.position[k_end, :2] + moved + lever - fix_pos[i, :2])
        idx = [i for i, _ in chosen]
        cov_en = float(e.position_cov_en[k_end])
        var_e, var_n = (float(v) ** 2 for v in e.position_sigma[k_end, :2])
        fv = np.median(np.asarray(fix_var, np.float64)[idx, :2], axis=0)
        out.append(
            OutageExit(
                start=float(a),
                end=float(b),
                fix_t=(float(fix_t[idx[0]]), float(fix_t[idx[-1]])),
                n_fixes=len(idx),
                error=np.median(np.asarray(errors), axis=0),
                estimate_at=errors[0] + np.asarray(fix_pos, np.float64)[idx[0], :2],
                estimate_cov=np.array([[var_e, cov_en], [cov_en, var_n]]),
                fix_cov=np.diag(fv),
            )
        )
    return tuple(out)


def _when(x: OutageExit, t0: float) -> str:
    return f"the outage at {x.start - t0:.1f}-{x.end - t0:.1f} s"


def exit_notes(run: Run) -> list[str]:
    """One line per outage the run came out of: how far its estimate ended from the returning
    fixes, against what it claimed."""
    return [
        f"exit of {_when(x, run.t0)}: the first {x.n_fixes} fixes after it "
        f"({x.fix_t[0] - run.t0:.1f}-{x.fix_t[1] - run.t0:.1f} s) were {x.distance_m:.1f} m from "
        f"the estimate, {math.sqrt(x.chi2):.1f} sigma (the estimate claimed "
        f"{x.estimate_sigma_m:.1f} m that way)"
        for x in run.exits
    ]


def exit_warnings(
    method: str, exits: Sequence[OutageExit], route_updated: Sequence[bool], t0: float
) -> tuple[str, ...]:
    """One line per outage whose estimate ended farther from the returning fixes than it and
    they claim (:attr:`~estimator.results.OutageExit.overconfident`), naming the ``method``
    (``routefuse run`` prints every method's warnings together). ``route_updated``: per exit,
    whether route updates were applied in its outage (what went wrong differs)."""
    flagged = [(x, r) for x, r in zip(exits, route_updated, strict=True) if x.overconfident]
    named, summed = named_and_summed(flagged)
    lines = []
    for x, routed in named:
        why = (
            "the route updates pulled it off unnoticed (a map off the road, a wrong match: "
            "check the route and the matches)"
            if routed
            else "dead reckoning drifted beyond its noise model (IMU noise, biases or "
            "mounting worse than configured)"
        )
        lines.append(
            f"{method} run: {_when(x, t0)} ended {x.distance_m:.1f} m from the fixes after it, "
            f"{math.sqrt(x.chi2):.1f} sigma, where the estimate claimed "
            f"{x.estimate_sigma_m:.1f} m: {why}, or the fixes are worse than they claim"
        )
    rest = [x for x, _ in summed]
    if rest:
        worst = max(rest, key=lambda x: x.chi2)
        lines.append(
            f"... and {len(rest)} more outages of the {method} run, between "
            f"{rest[0].start - t0:.1f} and {rest[-1].end - t0:.1f} s, ended farther from the "
            f"fixes after them than their sigmas allow (worst: {_when(worst, t0)}, "
            f"{worst.distance_m:.1f} m, {math.sqrt(worst.chi2):.1f} sigma)"
        )
    return tuple(lines)
