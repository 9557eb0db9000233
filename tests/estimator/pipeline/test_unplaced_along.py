"""The warning for an outage whose route updates hold the position across the road while the
filter does not know where along it the vehicle is (``driver.unplaced_along_warnings``)."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from estimator.evaluation.metrics import deviation_series
from estimator.params import Params
from estimator.pipeline import run_methods
from estimator.pipeline.driver import UNPLACED_SIGMA_M, unplaced_along_warnings
from estimator.results import Epochs
from estimator.sim.stress import build, drive_spec
from inspector.app.playback import MAX_WARNING_CHARS

WARNING = re.compile(
    r"outage (?P<a>[\d.]+)-(?P<b>[\d.]+) s: (?P<n>\d+) route updates accepted, yet the "
    r"position's 1-sigma passed 20 m at (?P<first>[\d.]+) s and reached (?P<peak>\d+) m at "
    r"(?P<at>[\d.]+) s \((?P<lasting>\d+) s over 20 m\): "
    r"the route holds it across the road; on a straight road only dead reckoning places it "
    r"along, so the trace sits on the route unknown along it$"
)


def _epochs(t, sigma):
    n = len(t)
    return Epochs(
        t=np.asarray(t, float),
        position=np.zeros((n, 3)),
        velocity=np.zeros((n, 3)),
        attitude=np.zeros((n, 3)),
        position_sigma=np.column_stack([sigma, np.zeros(n), np.zeros(n)]) / 1.0,
        position_cov_en=np.zeros(n),
        yaw_sigma=np.zeros(n),
        gnss_used=np.zeros(n, bool),
        degraded=np.ones(n, bool),
    )


def test_a_sigma_over_the_threshold_with_updates_accepted_is_reported_once_per_outage():
    t = np.arange(0.0, 100.0, 1.0)
    sigma = np.where((t >= 40) & (t <= 60), 30.0, 5.0)
    sigma[50] = 45.0
    accepted = [SimpleNamespace(t=float(x), accepted=True, extra={}) for x in range(10, 90, 5)]
    (line,) = unplaced_along_warnings(_epochs(t, sigma), accepted, [(5.0, 95.0)], 0.0)
    m = WARNING.match(line)
    assert m, line
    assert len(line) <= MAX_WARNING_CHARS  # the inspector shows it whole
    assert (m["a"], m["b"], m["n"]) == ("5.0", "95.0", str(len(accepted)))
    assert (m["first"], m["peak"], m["at"], m["lasting"]) == ("40.0", "45", "50.0", "21")
    # another outage with the same sigma but only refused attempts: dead reckoning, which the
    # trace does not hide (it leaves the route), is not this warning's business
    refused = [SimpleNamespace(t=float(x), accepted=False, extra={}) for x in range(10, 90, 5)]
    assert unplaced_along_warnings(_epochs(t, sigma), refused, [(5.0, 95.0)], 0.0) == ()
    # at or under the threshold, or outside every outage: nothing
    low = np.minimum(sigma, UNPLACED_SIGMA_M)
    assert unplaced_along_warnings(_epochs(t, low), accepted, [(5.0, 95.0)], 0.0) == ()
    assert unplaced_along_warnings(_epochs(t, sigma), accepted, [(70.0, 95.0)], 0.0) == ()


def test_the_sigma_of_an_imu_gap_the_route_bridged_is_the_gaps_own():
    """From an IMU gap's end to its bridge along the route the sigma is the gap's (half its
    travel), which the gap's own line names; the bridge placed the vehicle along the road."""
    t = np.r_[np.arange(0.0, 40.0, 1.0), np.arange(70.0, 100.0, 1.0)]
    sigma = np.where(t == 70.0, 700.0, 5.0)
    records = [SimpleNamespace(t=float(x), accepted=True, extra={}) for x in range(10, 90, 5)]
    (line,) = unplaced_along_warnings(_epochs(t, sigma), records, [(5.0, 95.0)], 0.0)
    assert "reached 700 m at 70.0 s (31 s over" in line
    bridged = {"gap_bridge_end_s": 69.9}
    records[12] = SimpleNamespace(t=70.2, accepted=False, extra=bridged)
    assert unplaced_along_warnings(_epochs(t, sigma), records, [(5.0, 95.0)], 0.0) == ()


@pytest.mark.slow
def test_drive_32_is_warned_where_its_accepted_trace_is_far_off_along_the_road():
    """Stress drive 32 (long tunnel, no odometer): every route update in its 356 s outage is
    accepted and the trace sits on the route, but on the tunnel's straights the filter's
    sigma grows past 100 m and its error along the road with it (69 m at the peak since
    ``align_track_accel_ahead``, 7 m across). The warning names the outage and the sigma the
    filter itself reported; the error against truth at the peak shows it is no false alarm.
    The baseline (no route updates) gets no such line."""
    drive = build(drive_spec(32))
    runs = run_methods(drive.inputs, Params(), methods=("baseline", "proposed"))
    proposed, baseline = runs["proposed"], runs["baseline"]
    lines = [w for w in proposed.warnings if WARNING.match(w)]
    assert len(lines) == 1, proposed.warnings
    m = WARNING.match(lines[0])
    assert m is not None
    (a, b), t0 = proposed.degraded_intervals[0], proposed.t0
    assert float(m["a"]) == pytest.approx(a - t0, abs=0.05)
    assert int(m["n"]) == sum(r.accepted for r in proposed.matches if a <= r.t <= b)
    e = proposed.epochs
    sigma = np.hypot(e.position_sigma[:, 0], e.position_sigma[:, 1])
    # the peak's time is given to 0.1 s, and an update may shrink the sigma within that
    near = np.flatnonzero(np.abs(e.t - (t0 + float(m["at"]))) <= 0.05 + 1e-6)
    k = int(near[np.argmax(sigma[near])])
    assert int(m["peak"]) == round(sigma[k]) and sigma[k] > 100.0
    truth = deviation_series(proposed, drive.inputs.route, drive.inputs.log).truth
    j = np.searchsorted(truth.index, k)
    # tens of metres off along the road, where the sigma warned of, and metres across it
    assert abs(truth.along_err_m[j]) > max(UNPLACED_SIGMA_M, 5.0 * abs(truth.cross_err_m[j]))
    assert not any(WARNING.match(w) for w in baseline.warnings)
