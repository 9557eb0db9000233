"""IMU-only logs (issue 17, item 4): the wheel topic can be left out, the simulated IMU-only
drives carry their faults, and without wheel speed routefuse is no worse than dead reckoning
where it used to be (the matcher's no-wheel caution)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError
from estimator.evaluation.metrics import method_metrics
from estimator.filter import layout as ly
from estimator.filter.gnss import widen_heading
from estimator.io import TopicChoice
from estimator.matching.fit import FitSettings, _bend_variance, fit_window
from estimator.matching.gates import ShapeValues, gate_table
from estimator.matching.geometry import Polyline
from estimator.matching.match import match_window, search_half_width
from estimator.params import Params, for_method, load_params, matching_params, with_values
from estimator.pipeline import open_inputs, run_methods
from estimator.pipeline.driver import (
    aided_approach_m,
    along_drift_psd,
    grow_along_velocity,
    row_position_cov,
    window_scale_sigma,
)
from estimator.results import Gate
from estimator.route import Route
from estimator.sim.imu_only import build_imu_only, imu_only_spec
from estimator.sim.stress import build, drive_spec

REPO = Path(__file__).resolve().parents[2]
COMMA = REPO.parent / "shared" / "data" / "comma2k19"
needs_comma = pytest.mark.skipif(
    not (COMMA / "i280.mcap").is_file(), reason="comma2k19 data not present"
)


def _truth_rmse(inputs, params, method, outages=()):  # type: ignore[no-untyped-def]
    run = run_methods(inputs, params, methods=(method,), outages=outages).runs[method]
    truth = method_metrics(run, inputs.route, inputs.log, params=params).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return float(truth.rmse_h_err_m)


def test_the_caution_is_only_for_logs_without_wheel_speed() -> None:
    p = Params()
    assert matching_params(p, have_wheel=True) is p
    ext = matching_params(p, have_wheel=False).extensions
    assert ext.covariance_search and ext.curvature_covariance and ext.overlap_inflation
    assert ext.window_scale_covariance and not p.extensions.window_scale_covariance
    # the filter's own covariance is no yardstick without an odometer
    assert p.extensions.dr_separation and not ext.dr_separation
    assert p.extensions.weak_along_track and not ext.weak_along_track
    assert matching_params(p, have_wheel=False).offset.map_turn_honest_prior
    assert ext.cross_track_heading_widen and not p.extensions.cross_track_heading_widen
    assert ext.calibrated_approach and not p.extensions.calibrated_approach
    assert ext.along_drift_evidence and not p.extensions.along_drift_evidence
    assert ext.search_correction_cap and not p.extensions.search_correction_cap
    # the honest prior is the default since session 13; the caution keeps it on without wheels
    moments = with_values(p, {"offset.map_turn_honest_prior": False})
    assert matching_params(moments, have_wheel=False).offset.map_turn_honest_prior
    assert matching_params(moments, have_wheel=True) is moments
    off = with_values(p, {"extensions.no_wheel_caution": False})
    assert matching_params(off, have_wheel=False) is off
    paper = for_method(p, "paper")
    assert matching_params(paper, have_wheel=False) is paper


def test_the_search_widens_with_the_filters_along_track_sigma() -> None:
    p = with_values(Params(), {"extensions.covariance_search": True})
    road = Polyline.of(Route(np.array([[0.0, 0.0], [2000.0, 0.0]])))
    small = np.diag([4.0, 1.0])
    assert search_half_width(road, 500.0, small, p) == p.window.along_search_m
    assert search_half_width(road, 500.0, np.diag([50.0**2, 1.0]), p) == pytest.approx(150.0)
    assert search_half_width(road, 500.0, np.diag([1e6, 1.0]), p) == p.window.along_search_max_m
    # across the road the filter's uncertainty says nothing about where along it to look
    assert search_half_width(road, 500.0, np.diag([4.0, 1e6]), p) == p.window.along_search_m
    assert search_half_width(road, 500.0, np.diag([1e6, 1.0]), Params()) == 30.0


def test_a_bend_under_an_uncertain_along_track_is_cross_track_noise() -> None:
    tangent, normal = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    straight = Polyline.of(Route(np.array([[-1000.0, 0.0], [1000.0, 0.0]])))
    cov = np.diag([100.0**2, 1.0])
    assert _bend_variance(straight, 1000.0, tangent, normal, cov, 100.0, False) == 0.0
    radius = 2500.0
    a = np.linspace(-0.4, 0.4, 801)
    arc = np.column_stack([radius * np.sin(a), radius * (1.0 - np.cos(a))])
    road = Polyline.of(Route(arc))
    s_mid = float(road.s[-1] / 2)
    var = _bend_variance(road, s_mid, tangent, normal, cov, 100.0, False)
    # d = s^2 / (2 R), s ~ N(0, sigma^2): E[d^2] = 3 sigma^4 / (4 R^2)
    assert var == pytest.approx(3 * 100.0**4 / (4 * radius**2), rel=0.05)
    # a shape that observed along-track to 2 m leaves almost nothing of it
    assert _bend_variance(road, s_mid, tangent, normal, cov, 2.0, True) < 1e-4 * var


def test_a_window_of_uncertain_length_claims_less_along_track() -> None:
    """A corner observes along-track to metres; a window whose length is uncertain by tens of
    metres places the corner that much less surely, and one uncertain beyond
    ``pseudo.along_sigma_max_m`` not at all."""
    params = Params()
    route = Route(np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 300.0]]))
    road = Polyline.of(route)
    win = route.point_at(np.arange(150.0, 400.0 + 1e-9, params.window.spacing_m))
    settings = FitSettings.of(params)
    assert settings.with_window_scale(0.0) is settings
    sharp = fit_window(win, win[-1], road, 150.0, 0.0, settings)
    assert sharp is not None and sharp.along_observed
    assert sharp.along_sigma < 5.0
    wide = fit_window(win, win[-1], road, 150.0, 0.0, settings.with_window_scale(20.0))
    assert wide is not None and wide.along_observed
    assert wide.along_sigma == pytest.approx(float(np.hypot(sharp.along_sigma, 20.0)))
    tangent = wide.tangent
    assert float(tangent @ wide.obs_cov @ tangent) == pytest.approx(wide.along_sigma**2)
    lost = fit_window(win, win[-1], road, 150.0, 0.0, settings.with_window_scale(500.0))
    assert lost is not None and not lost.along_observed
    assert lost.along_sigma == params.pseudo.along_sigma_max_m


def test_the_window_length_sigma_is_the_velocity_sigma_along_travel_times_its_duration() -> None:
    n = 11
    out = np.zeros((n, ly.NO))
    out[:, ly.O_T] = np.arange(n, dtype=float)
    out[:, ly.O_DIST] = 10.0 * np.arange(n)
    aux = np.zeros(ly.NA)
    aux[ly.A_TIME], aux[ly.A_DIST] = 10.0, 100.0
    x = np.zeros(ly.NX)
    x[ly.X_VEL : ly.X_VEL + 2] = [10.0, 0.0]
    P = np.eye(ly.NE)
    P[ly.E_VEL : ly.E_VEL + 2, ly.E_VEL : ly.E_VEL + 2] = np.diag([0.2**2, 3.0**2])
    # the last 50 m took 5 s; along travel (East) the velocity is uncertain by 0.2 m/s
    assert window_scale_sigma(out, n, x, P, aux, 50.0) == pytest.approx(1.0)
    x[ly.X_VEL : ly.X_VEL + 2] = [0.0, 10.0]
    assert window_scale_sigma(out, n, x, P, aux, 50.0) == pytest.approx(15.0)
    x[ly.X_VEL : ly.X_VEL + 2] = 0.0
    assert window_scale_sigma(out, n, x, P, aux, 50.0) == 0.0


def _drifting_rows(jump: tuple[float, float], sigma: float) -> np.ndarray:
    """Output rows of a drive East at 20 m/s from 1 s before an outage at t = 0 to 60 s into
    it, dead-reckoned exactly but for a correction of ``jump`` (E, N) at t = 39.5 s, the filter
    claiming ``sigma`` per axis."""
    t = np.arange(-1.0, 60.0 + 1e-9, 0.05)
    out = np.zeros((len(t), ly.NO))
    out[:, ly.O_T] = t
    out[:, ly.O_VEL] = 20.0
    out[:, ly.O_DR] = 20.0 * t
    out[:, ly.O_POS] = out[:, ly.O_DR]
    after = t >= 39.5 - 1e-9
    out[after, ly.O_POS] += jump[0]
    out[after, ly.O_POS + 1] += jump[1]
    out[:, ly.O_SIG_POS : ly.O_SIG_POS + 2] = sigma
    return out


def test_a_correction_beyond_the_along_track_sigma_is_a_velocity_random_walk() -> None:
    """50 m corrected along the travel where the filter claimed 10 m, 30 s (the earliest
    10 s stretch holding it starts at 30 s) after the outage started: the random walk that
    grows the missing 50^2 - 10^2 m^2 in that time, 3 (c^2 - s^2) / tau^3."""
    q = along_drift_psd(_drifting_rows((-50.0, 0.0), 10.0), 0.0, 60.0)
    assert q == pytest.approx(3.0 * (50.0**2 - 10.0**2) / 30.0**3, rel=1e-2)
    # before the correction there is no evidence, within its sigma none, across the travel
    # it is no along-track drift
    assert along_drift_psd(_drifting_rows((-50.0, 0.0), 10.0), 0.0, 39.0) == 0.0
    assert along_drift_psd(_drifting_rows((-8.0, 0.0), 10.0), 0.0, 60.0) == 0.0
    assert along_drift_psd(_drifting_rows((0.0, 50.0), 10.0), 0.0, 60.0) == 0.0


def test_the_along_drift_evidence_after_a_clock_jump_of_years_is_the_same_and_small() -> None:
    """An attempt years after the last output row (a clock that jumped forward inside the
    outage): the stretches that end beyond the rows hold no row and say nothing, so the
    evidence is that of the rows, found without a stretch per second of the jump."""
    rows = _drifting_rows((-50.0, 0.0), 10.0)
    years = 10 * 365.25 * 86400.0 * 1e6  # a million times 10 years: 3e14 stretches of 1 s
    assert along_drift_psd(rows, 0.0, years) == along_drift_psd(rows, 0.0, 60.0)


def test_the_along_drift_grows_the_velocity_variance_along_the_travel_only() -> None:
    x = np.zeros(ly.NX)
    x[ly.X_VEL : ly.X_VEL + 2] = [0.0, 15.0]
    P = np.eye(ly.NE)
    grow_along_velocity(P, x, 0.5)
    expected = np.eye(ly.NE)
    expected[ly.E_VEL + 1, ly.E_VEL + 1] += 0.5
    np.testing.assert_array_equal(P, expected)
    x[ly.X_VEL : ly.X_VEL + 2] = 0.0  # standing: no travel to grow along
    grow_along_velocity(P, x, 0.5)
    np.testing.assert_array_equal(P, expected)


def test_an_imu_only_long_tunnel_beats_dead_reckoning_by_the_along_drift_evidence() -> None:
    """Sim 12: the bend half-way along the long tunnel puts the position right, and a
    mis-mounted, mis-scaled accelerometer takes it 230 m off by the next bend with the
    filter claiming 60 m; the non-holonomic constraint there then corrects little. The first
    bend's correction, about 270 m where the filter claimed 120 m, is the evidence of that drift:
    carried as a velocity random walk it keeps the covariance honest (within dead reckoning
    with it, beyond without it)."""
    inputs = build_imu_only(imu_only_spec(12)).inputs
    baseline = _truth_rmse(inputs, Params(), "baseline")
    assert _truth_rmse(inputs, Params(), "proposed") <= baseline
    without = _cautious_but(**{"extensions.along_drift_evidence": False})
    assert _truth_rmse(inputs, without, "proposed") > baseline


def test_an_imu_only_drive_is_a_pure_function_of_its_index_and_has_its_faults() -> None:
    spec = imu_only_spec(5)
    assert spec == imu_only_spec(5) and spec != imu_only_spec(6)
    assert 300 <= spec.gyro_bias_deg_h <= 720 and 5_000 <= spec.accel_scale_ppm <= 12_000
    assert 1.0 <= abs(spec.mount_pitch_deg) <= 4.0 and 1.0 <= abs(spec.mount_yaw_deg) <= 3.0
    assert 0.01 <= abs(spec.imu_time_offset_s) <= 0.05
    a, b = build_imu_only(spec), build_imu_only(spec)
    np.testing.assert_array_equal(a.inputs.log.imu.accel, b.inputs.log.imu.accel)
    log = a.inputs.log
    assert log.wheel is None and a.inputs.route is not None
    # standing still before the drive: gravity leaks into x by the mount's pitch (a nose-down
    # mount, a negative pitch as sensors.imu_pitch_deg has it, reads a negative x)
    still = log.imu.t < log.imu.t[0] + 2.0
    fx, fz = np.mean(log.imu.accel[still, 0]), np.mean(log.imu.accel[still, 2])
    pitch = np.degrees(np.arctan2(fx, fz))
    assert pitch == pytest.approx(spec.mount_pitch_deg, abs=0.3)


def test_without_wheel_speed_routefuse_is_no_worse_than_dead_reckoning_on_a_long_tunnel() -> None:
    """Drive 4: the long tunnel without wheel speed, a 557 deg/h gyro and a misaligned IMU.
    Before the caution routefuse was worse than the baseline there (a bend paired 100 m off
    and the covariance pinned along-track by it); with it, it is better."""
    drive = build_imu_only(imu_only_spec(4))
    inputs = drive.inputs
    baseline = _truth_rmse(inputs, Params(), "baseline")
    proposed = _truth_rmse(inputs, Params(), "proposed")
    before = _truth_rmse(
        inputs, with_values(Params(), {"extensions.no_wheel_caution": False}), "proposed"
    )
    assert proposed <= baseline
    assert before > baseline


@needs_comma
def test_the_wheel_topic_can_be_left_out() -> None:
    full = open_inputs(COMMA / "i280.mcap")
    assert full.log.wheel is not None
    bare = open_inputs(COMMA / "i280.mcap", topics=TopicChoice(no_wheel=True))
    assert bare.log.wheel is None
    np.testing.assert_array_equal(bare.log.imu.gyro, full.log.imu.gyro)
    with pytest.raises(LogError, match="--no-wheel"):
        open_inputs(COMMA / "i280.mcap", topics=TopicChoice(wheel="/wheel/odom", no_wheel=True))


@needs_comma
@pytest.mark.parametrize(
    ("outage", "gain_m"),
    [
        ((25.0, 55.0), 0.0),
        # 45 s of outage 10 s (116 m of driving with GNSS) in: 25.36 -> 23.24 m (Intel Xeon 2
        # cores, since portal_rerun_after_alignment; before it the re-run dropped the fixes
        # after the start and both were 75-84 m off); the dead-reckoning twin's test, which
        # undid such updates on the real MEMS unit's too small covariance, is off without an
        # odometer
        ((10.0, 55.0), 1.0),
    ],
)
def test_comma2k19_without_wheel_speed_routefuse_beats_dead_reckoning(
    outage: tuple[float, float], gain_m: float
) -> None:
    inputs = open_inputs(
        COMMA / "i280.mcap", COMMA / "i280_route.geojson", topics=TopicChoice(no_wheel=True)
    )
    params = load_params(REPO / "sample_logs" / "configs" / "comma2k19_i280.toml")
    baseline = _truth_rmse(inputs, params, "baseline", (outage,))
    proposed = _truth_rmse(inputs, params, "proposed", (outage,))
    assert proposed <= baseline - gain_m


def test_a_no_odometer_drive_on_a_biased_map_is_no_worse_than_dead_reckoning() -> None:
    """Stress drive 2: the multi-tunnel without wheel speed on a map 8.9 m off along the road
    (its bias learned on the approach and carried through the tunnels)."""
    drive = build(drive_spec(2))
    inputs = drive.inputs
    assert inputs.log.wheel is None
    baseline = _truth_rmse(inputs, Params(), "baseline")
    assert _truth_rmse(inputs, Params(), "proposed") <= baseline


def _cautious_but(**values: bool) -> Params:
    """What ``no_wheel_caution`` makes of the defaults for a log without wheel speed, with
    ``values`` changed (the caution itself off, or ``matching_params`` would set them again)."""
    cautious = matching_params(Params(), have_wheel=False)
    return with_values(cautious, {"extensions.no_wheel_caution": False, **values})


@pytest.mark.parametrize(
    ("index", "switch"),
    [
        # a map turned 0.19 deg, which the approach's fit cannot tell from zero: its
        # method-of-moments prior (no rotation) let the matches turn the heading instead of
        # the map, 0.2 m past dead reckoning; the honest prior lets them estimate the rotation
        (22, "offset.map_turn_honest_prior"),
        # the first fix after the tunnel is 12 m off along the road: widening the heading by
        # all of it (0.9 deg) let the fixes that followed corrupt the velocity, and the next
        # tunnel ran 15 m off (7.9 m RMSE against dead reckoning's 4.5); widened by the
        # innovation across the travel only, it is not taken for a heading error
        (42, "extensions.cross_track_heading_widen"),
    ],
)
def test_a_no_odometer_drive_beats_dead_reckoning_by_what_the_caution_turns_on(
    index: int, switch: str
) -> None:
    """Stress drives without wheel speed whose miss the caution's switch ends (on only
    through ``no_wheel_caution``): within dead reckoning with it, beyond without it."""
    inputs = build(drive_spec(index)).inputs
    assert inputs.log.wheel is None
    baseline = _truth_rmse(inputs, Params(), "baseline")
    assert _truth_rmse(inputs, Params(), "proposed") <= baseline
    assert _truth_rmse(inputs, _cautious_but(**{switch: False}), "proposed") > baseline


def test_the_heading_widening_takes_the_innovation_across_the_travel_only() -> None:
    x, aux = np.zeros(ly.NX), np.zeros(ly.NA)
    x[ly.X_VEL] = 20.0  # driving east
    aux[ly.A_DIST] = 1000.0
    along, across = np.array([12.0, 0.0]), np.array([0.0, 12.0])
    for y, cross_only, widened in (
        (along, False, True),
        (along, True, False),
        (across, True, True),
    ):
        P = np.eye(ly.NE) * 1e-6
        widen_heading(x, P, y, aux, cross_only)
        grown = P[ly.E_ATT + 2, ly.E_ATT + 2] - 1e-6
        assert (grown == pytest.approx((2 * 12.0 / 1000.0) ** 2)) == widened
        assert (grown > 0) == widened


def test_the_approach_counts_the_driving_with_gnss_offered_only() -> None:
    rows = np.zeros((6, ly.O_DIST + 1))
    rows[:, ly.O_T] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    rows[:, ly.O_DIST] = [0.0, 10.0, 30.0, 60.0, 100.0, 150.0]
    assert aided_approach_m(rows, 5.0, ()) == pytest.approx(150.0)
    assert aided_approach_m(rows, 3.5, ()) == pytest.approx(60.0)
    # the rows inside an earlier outage (2.5-3.5 s) are dead-reckoned, not an approach
    assert aided_approach_m(rows, 5.0, ((2.5, 3.5),)) == pytest.approx(120.0)
    assert aided_approach_m(rows[:1], 5.0, ()) == 0.0


@needs_comma
@pytest.mark.parametrize("outage", [(3.0, 61.0), (5.0, 50.0)])
def test_an_outage_after_too_short_an_approach_is_dead_reckoned_with_a_warning(
    outage: tuple[float, float],
) -> None:
    """comma2k19 without its wheels, GNSS lost 3-5 s (25-42 m) into the log: the cross-track
    updates turn the along-track velocity through a heading, tilt and accelerometer bias not
    yet told apart, and end past dead reckoning (28.29 against 24.97 m, 23.96 against 21.87 m,
    measured with ``align_track_accel``, Intel Xeon 2 cores; 5-20 and 5-35 s, which lost before
    it, now gain 0.3-0.4 m). ``calibrated_approach`` leaves the outage to dead reckoning, and
    says so."""
    inputs = open_inputs(
        COMMA / "i280.mcap", COMMA / "i280_route.geojson", topics=TopicChoice(no_wheel=True)
    )
    params = load_params(REPO / "sample_logs" / "configs" / "comma2k19_i280.toml")
    session = run_methods(inputs, params, outages=(outage,))
    base, prop = session["baseline"], session["proposed"]
    assert not prop.matches
    np.testing.assert_array_equal(prop.epochs.position, base.epochs.position)
    named = [w for w in prop.warnings if w.startswith("no route updates in the outage")]
    assert len(named) == 1 and f"{outage[0]:.1f}-" in named[0]
    off = with_values(
        matching_params(params, have_wheel=False),
        {"extensions.no_wheel_caution": False, "extensions.calibrated_approach": False},
    )
    ungated = run_methods(inputs, off, methods=("proposed",), outages=(outage,), reuse=session)
    assert ungated["proposed"].matches
    baseline = _truth_rmse(inputs, params, "baseline", (outage,))
    assert _truth_rmse(inputs, off, "proposed", (outage,)) > baseline
    # a run reused with the switch flipped back is the fresh run
    again = run_methods(inputs, params, methods=("proposed",), outages=(outage,), reuse=ungated)
    np.testing.assert_array_equal(again["proposed"].epochs.position, prop.epochs.position)
    assert again["proposed"].warnings == prop.warnings


def test_a_simulated_drive_losing_gnss_a_few_seconds_in_is_dead_reckoned_there() -> None:
    """IMU-only drive 4 with GNSS removed 3 s (36 m) into the drive: that outage takes no
    route updates and matches dead reckoning, the run says so, and the tunnels later on, after
    kilometres with GNSS, are matched as before."""
    inputs = build_imu_only(imu_only_spec(4)).inputs
    outage = (3.0, 30.0)
    end = inputs.log.t_start + outage[1]
    session = run_methods(inputs, Params(), outages=(outage,))
    base, prop = session["baseline"], session["proposed"]
    assert not [m for m in prop.matches if m.t < end]
    assert [m for m in prop.matches if m.t > end]
    early, same = base.epochs.t < end, prop.epochs.t < end
    np.testing.assert_array_equal(prop.epochs.t[same], base.epochs.t[early])
    np.testing.assert_array_equal(prop.epochs.position[same], base.epochs.position[early])
    assert sum(w.startswith("no route updates in the outage") for w in prop.warnings) == 1
    ungated = _cautious_but(**{"extensions.calibrated_approach": False})
    again = run_methods(inputs, ungated, methods=("proposed",), outages=(outage,))
    assert [m for m in again["proposed"].matches if m.t < end]


def test_the_scripts_values_reach_routefuse_or_with_everywhere_every_run() -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
    from imu_only import RUNS, run_values_of

    values = {"extensions.x": True}
    for label, (_, own) in RUNS.items():
        only = run_values_of(label, own, values, everywhere=False)
        assert (only == {**own, **values}) == (label == "routefuse")
        assert run_values_of(label, own, values, everywhere=True) == {**own, **values}
        assert run_values_of(label, own, None, everywhere=True) == own


def test_the_scripts_table_counts_the_outages_flagged_at_their_exit() -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
    from imu_only import RUNS, table

    def row(case: str, flagged: dict[str, int]) -> dict[str, object]:
        r: dict[str, object] = {"kind": "sim", "case": case, "outage": "tunnels", "faults": ""}
        r.update(error="", routefuse_le_baseline=True)
        for label in RUNS:
            r.update({f"{label}_truth_rmse_m": 1.0, f"{label}_accepted": 0})
            r.update({f"{label}_attempted": 0, f"{label}_exits": 2})
            r[f"{label}_exits_overconfident"] = flagged.get(label, 0)
        return r

    text = table([row("sim 0", {"baseline": 1}), row("sim 1", {"baseline": 2, "routefuse": 1})])
    assert "their sigmas (the exit check): baseline 3, routefuse 1 of 4" in text
    assert text.splitlines()[-1].endswith("| 2 / 1 of 2 |")


def test_a_correction_the_widened_search_found_is_not_capped_at_30_m() -> None:
    """A corner dead-reckoned 70 m short along the road, the filter claiming 60 m per axis:
    the widened search (180 m) finds the corner, and the fixed 30 m cap refused that correction
    unless ``extensions.search_correction_cap`` caps it at the search's half-width."""
    route = Route(np.array([[0.0, 0.0], [600.0, 0.0], [600.0, 600.0]]))
    truth = route.point_at(np.arange(450.0, 700.0 + 1e-9, 2.0))
    window = truth - np.array([70.0, 0.0])
    cov = np.diag([60.0**2, 60.0**2])
    base = {"extensions.covariance_search": True, "extensions.candidate_validation": False}
    decisions = {}
    for on in (False, True):
        p = with_values(Params(), {**base, "extensions.search_correction_cap": on})
        rec = match_window(
            window,
            window[-1],
            cov,
            route,
            s_guess=630.0,
            lane_offset=0.0,
            params=p,
            index=0,
            t=0.0,
            epoch=0,
        )
        assert rec.fit is not None
        assert np.hypot(*rec.innovation) == pytest.approx(70.0, abs=3.0)
        decisions[on] = next(d for d in rec.gates if d.gate is Gate.CORRECTION_CAP)
    assert not decisions[False].passed and decisions[False].threshold == 30.0
    assert decisions[True].passed and decisions[True].threshold == pytest.approx(180.0)
    # without the widened search the cap stays the fixed one
    p = with_values(Params(), {"extensions.search_correction_cap": True})
    capped = gate_table(ShapeValues(40, 1.0, 0.1, 0.1), None, 70.0, p, search_m=180.0)[-1]
    assert capped.gate is Gate.CORRECTION_CAP and not capped.passed


def test_the_along_track_sigma_of_a_diagonal_drive_is_the_ellipses_length() -> None:
    """The drive above turned to run north-east, the filter's ellipse 20 m along the travel
    and 2 m across: its E and N sigmas are both about 14 m. A 15 m correction along the travel
    is within the 20 m the filter claims there, so no drift; read with the sigmas alone (the
    E-N covariance dropped) the claim would be 14 m and the 15 m drift."""
    along, across = np.array([1.0, 1.0]) / np.sqrt(2.0), np.array([-1.0, 1.0]) / np.sqrt(2.0)
    cov = 20.0**2 * np.outer(along, along) + 2.0**2 * np.outer(across, across)
    rows = _drifting_rows((0.0, 0.0), 0.0)
    speed_t = rows[:, ly.O_DR].copy()
    for i in range(2):
        rows[:, ly.O_VEL + i] = 20.0 * along[i]
        rows[:, ly.O_DR + i] = speed_t * along[i]
        rows[:, ly.O_POS + i] = rows[:, ly.O_DR + i] - 15.0 * along[i] * (rows[:, ly.O_T] >= 39.5)
    rows[:, ly.O_SIG_POS] = np.sqrt(cov[0, 0])
    rows[:, ly.O_SIG_POS + 1] = np.sqrt(cov[1, 1])
    rows[:, ly.O_COV_EN] = cov[0, 1]
    np.testing.assert_allclose(row_position_cov(rows[0]), cov)
    assert along_drift_psd(rows, 0.0, 60.0) == 0.0
    rows[:, ly.O_COV_EN] = 0.0
    assert along_drift_psd(rows, 0.0, 60.0) > 0.0
