"""The targets of issues 4 and 10, measured on the bundled sample logs.

Each target is asserted as the issue states it, and a failure says so with the measured
numbers. The paper's rows are those of ``../shared/method.md``; ``monaco_tunnel`` (not one of
the paper's drives) is compared with its curved-tunnel row. Route deviations are measured from
the learned lane (``--subtract-lane-offset``), over the GNSS-degraded intervals, as the paper
does.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from estimator.evaluation import MethodMetrics, deviation_series, method_metrics
from estimator.log import Log
from estimator.matching import shifted_route
from estimator.nav.frames import LocalFrame
from estimator.params import Params, with_values
from estimator.pipeline import open_inputs, run
from estimator.results import Run
from estimator.route import Route
from estimator.sim import get_scenario, simulate

SAMPLE_LOGS = Path(__file__).resolve().parents[1] / "sample_logs"
NAMES = ("long_tunnel", "spiral_tunnel", "multi_tunnel", "monaco_tunnel")

PAPER = {
    # scenario: ((baseline max, mean, rmse), (proposed max, mean, rmse)), metres
    "long": ((386.3, 142.909, 186.821), (22.7, 0.745, 1.672)),
    "curved": ((32.6, 7.908, 10.376), (27.5, 1.431, 1.889)),
    "multi": ((23.3, 3.576, 6.502), (8.5, 1.755, 2.351)),
}
PAPER_ROW = {
    "long_tunnel": "long",
    "spiral_tunnel": "curved",
    "multi_tunnel": "multi",
    "monaco_tunnel": "curved",
}
COLUMNS = ("max_pos_dev_m", "mean_pos_dev_m", "rmse_pos_dev_m")


@dataclasses.dataclass(frozen=True)
class Sample:
    log: Log
    route: Route
    frame: LocalFrame
    runs: dict[str, Run]
    metrics: dict[str, MethodMetrics]


def _metrics(r: Run, route: Route, log: Log) -> MethodMetrics:
    return method_metrics(r, route, log, subtract_lane_offset=True, params=r.params)


@pytest.fixture(scope="module")
def samples() -> dict[str, Sample]:
    if not (SAMPLE_LOGS / "README.md").is_file():
        pytest.skip(f"sample logs not found at {SAMPLE_LOGS}")
    return {}


def _sample(samples: dict[str, Sample], name: str) -> Sample:
    """Baseline and proposed on one sample log, run once per test session."""
    if name not in samples:
        inp = open_inputs(SAMPLE_LOGS / f"{name}.mcap", SAMPLE_LOGS / f"{name}.route.geojson")
        assert inp.route is not None
        base = run(inp.log, inp.route, Params(), method="baseline", frame=inp.frame)
        prop = run(inp.log, inp.route, Params(), method="proposed", frame=inp.frame, reuse=base)
        runs = {"baseline": base, "proposed": prop}
        samples[name] = Sample(
            inp.log,
            inp.route,
            inp.frame,
            runs,
            {m: _metrics(r, inp.route, inp.log) for m, r in runs.items()},
        )
    return samples[name]


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_proposed_beats_the_papers_proposed_row(samples, name) -> None:
    s = _sample(samples, name)
    ours = s.metrics["proposed"].route
    _, paper = PAPER[PAPER_ROW[name]]
    for column, theirs in zip(COLUMNS, paper, strict=True):
        assert getattr(ours, column) < theirs, f"{name} {column}: {getattr(ours, column):.3f}"


@pytest.mark.slow
@pytest.mark.parametrize("column", COLUMNS)
@pytest.mark.parametrize("name", NAMES)
def test_proposed_beats_the_baseline_by_the_papers_ratio(samples, name, column) -> None:
    s = _sample(samples, name)
    base, prop = (getattr(s.metrics[m].route, column) for m in ("baseline", "proposed"))
    paper_base, paper_prop = PAPER[PAPER_ROW[name]]
    i = COLUMNS.index(column)
    ratio = paper_base[i] / paper_prop[i]
    assert base / prop >= ratio, f"{name} {column}: {base:.3f} / {prop:.3f} < {ratio:.1f}"


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_truth_error_in_the_outages_is_at_most_2_m(samples, name) -> None:
    truth = _sample(samples, name).metrics["proposed"].truth
    assert truth is not None and truth.rmse_h_err_m is not None
    assert truth.rmse_h_err_m <= 2.0


@pytest.mark.slow
def test_position_covariance_in_the_outages_is_consistent(samples) -> None:
    """Mean position NEES of the proposed method over every sample's outages within chi-square
    bounds (issue 4's filter consistency, where the route is what holds the filter). The
    slowest error, the receiver's wander that the learned lane offset inherits, is correlated
    over about 60 s: only epochs that far apart count as independent."""
    nees, seconds = [], 0.0
    for name in NAMES:
        s = _sample(samples, name)
        r = s.runs["proposed"]
        e = r.epochs
        tr = s.frame.to_enu(s.log.truth.lat, s.log.truth.lon, s.log.truth.alt)
        for a, b in r.degraded_intervals:
            sel = (e.t >= a) & (e.t <= b) & (e.t <= s.log.truth.t[-1])
            truth = np.column_stack(
                [np.interp(e.t[sel], s.log.truth.t, tr[:, i]) for i in range(2)]
            )
            err = e.position[sel, :2] - truth
            nees.append(np.sum((err / e.position_sigma[sel, :2]) ** 2, axis=1))
            seconds += b - a
    n = int(seconds / 60.0)
    lo, hi = chi2.ppf([0.005, 0.995], 2 * n) / n
    mean = float(np.mean(np.concatenate(nees)))
    assert lo <= mean <= hi, (mean, lo, hi)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_along_track_error_is_at_most_a_thousandth_of_each_outage(samples, name) -> None:
    """Along-track RMSE in each outage <= 0.1 % of the distance driven in it (issue 10; every
    sample, the nearly straight long tunnel included)."""
    s = _sample(samples, name)
    r = s.runs["proposed"]
    ts = deviation_series(r, s.route, s.log).truth
    assert ts is not None
    tr = s.frame.to_enu(s.log.truth.lat, s.log.truth.lon, s.log.truth.alt)[:, :2]
    for a, b in r.degraded_intervals:
        inside = (ts.t >= a) & (ts.t <= b) & ts.heading_known
        along = float(np.sqrt(np.mean(ts.along_err_m[inside] ** 2)))
        sel = (s.log.truth.t >= a) & (s.log.truth.t <= b)
        driven = float(np.sum(np.hypot(*np.diff(tr[sel], axis=0).T)))
        assert driven > 500.0
        assert along <= 1e-3 * driven, f"{a - r.t0:.0f} s: {along:.2f} m over {driven:.0f} m"


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("wrong", ["shifted 25 m", "reversed"])
def test_a_wrong_route_is_never_accepted(samples, name, wrong) -> None:
    """A parallel road 25 m away and the route driven backwards: every match rejected with the
    correction cap at 100 m (the cap is not what saves us), no worse than the baseline."""
    s = _sample(samples, name)
    route = shifted_route(s.route, 25.0) if wrong != "reversed" else Route(s.route.xy[::-1])
    p = with_values(Params(), {"gates.max_correction_m": 100.0})
    r = run(s.log, route, p, method="proposed", frame=s.frame, reuse=s.runs["baseline"])
    assert len(r.matches) > 50
    assert sum(m.accepted for m in r.matches) == 0
    ours, base = _metrics(r, route, s.log).truth, s.metrics["baseline"].truth
    assert ours is not None and base is not None
    assert ours.rmse_h_err_m <= base.rmse_h_err_m + 0.01
    assert ours.max_h_err_m <= base.max_h_err_m + 0.01


def test_without_an_outage_baseline_and_proposed_are_identical() -> None:
    sim = simulate("short_tunnel", seed=0, duration_s=30.0)
    log, route = sim.log(), sim.route()
    assert sim.tunnels == ()
    base = run(log, route, Params(), method="baseline", frame=sim.frame)
    prop = run(log, route, Params(), method="proposed", frame=sim.frame)
    assert prop.degraded_intervals == () and prop.matches == ()
    for f in dataclasses.fields(base.epochs):
        assert np.array_equal(getattr(base.epochs, f.name), getattr(prop.epochs, f.name)), f.name


def _corrupt_before_portal(seed: int) -> tuple[Log, LocalFrame, float, np.ndarray]:
    """short_tunnel with clean fixes up to the portal, then, for the last 3 s before it, fixes
    that jump by 5-15 m (each jump held 1 s, like multipath) while claiming 3 m sigma. The
    receiver wanders by 0.3 m (not the samples' 0.8 m), so the entry error measures what the
    portal does rather than the receiver's own accuracy."""
    sc = get_scenario("short_tunnel")
    gnss_model = dataclasses.replace(
        sc.gnss, degraded_before_s=0.0, degraded_after_s=0.0, wander_h_m=0.3
    )
    sc = dataclasses.replace(sc, gnss=gnss_model)
    sim = simulate(sc, seed=seed)
    log = sim.log()
    entry = sim.tunnels[0][0]
    g = log.gnss
    bad = g.valid & (g.t >= entry - 3.0) & (g.t < entry)
    rng = np.random.default_rng(seed)
    size, angle = rng.uniform(5.0, 15.0, 4), rng.uniform(0.0, 2 * np.pi, 4)
    jumps = np.column_stack([size * np.cos(angle), size * np.sin(angle), np.zeros(4)])
    enu = sim.frame.to_enu(g.lat, g.lon, g.alt)
    enu[bad] += jumps[np.floor(g.t[bad] - (entry - 3.0)).astype(int)]
    geo = sim.frame.to_geodetic(enu)
    cov = g.cov_enu.copy()
    cov[bad] = (9.0, 9.0, 36.0)
    gnss = dataclasses.replace(
        g,
        lat=np.where(bad, geo[:, 0], g.lat),
        lon=np.where(bad, geo[:, 1], g.lon),
        alt=np.where(bad, geo[:, 2], g.alt),
        cov_enu=cov,
    )
    return dataclasses.replace(log, gnss=gnss), sim.frame, entry, g.t[bad]


@pytest.mark.parametrize("seed", [0, 3])
def test_corrupted_fixes_before_a_portal_are_left_out(seed) -> None:
    """Issue 10: entry error at a portal with corrupted fixes <= 1 m; the fixed-lag re-run
    leaves out every corrupted fix and hardly any good one."""
    log, frame, entry, corrupted = _corrupt_before_portal(seed)
    r = run(log, None, Params(), method="baseline", frame=frame)
    tr = frame.to_enu(log.truth.lat, log.truth.lon, log.truth.alt)
    e = r.epochs
    err = [np.interp(entry, e.t, e.position[:, i]) - np.interp(entry, log.truth.t, tr[:, i])
           for i in range(2)]  # fmt: skip
    assert float(np.hypot(*err)) <= 1.0
    dropped = np.asarray(r.dropped_fix_times)
    assert np.all(np.isin(corrupted, dropped))
    assert len(dropped) - len(corrupted) <= 2
    p_off = with_values(Params(), {"extensions.portal_rerun": False})
    off = run(log, None, p_off, method="baseline", frame=frame)
    assert off.dropped_fix_times == ()


@pytest.mark.slow
def test_without_wheel_speed_proposed_beats_baseline_on_a_curved_sample(samples) -> None:
    """Issue 10 part 4: IMU + GNSS only (the wheel topic dropped): NHC, ZUPT from the IMU and
    the route observations still carry the proposed method well ahead of the baseline."""
    s = _sample(samples, "spiral_tunnel")
    log = dataclasses.replace(s.log, wheel=None)
    runs = {m: run(log, s.route, Params(), method=m, frame=s.frame) for m in ("baseline",)}
    runs["proposed"] = run(
        log, s.route, Params(), method="proposed", frame=s.frame, reuse=runs["baseline"]
    )
    assert any("no wheel speed" in w for w in runs["proposed"].warnings)
    m = {k: _metrics(r, s.route, log) for k, r in runs.items()}
    for column in COLUMNS:
        assert getattr(m["proposed"].route, column) < 0.5 * getattr(m["baseline"].route, column)
    tb, tp = m["baseline"].truth, m["proposed"].truth
    assert tb is not None and tp is not None
    assert tp.rmse_h_err_m < tb.rmse_h_err_m and tp.max_h_err_m < tb.max_h_err_m
