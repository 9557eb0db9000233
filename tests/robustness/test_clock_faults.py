"""Stamps that lie (issue 16): one corrupt stamp far from its stream, a clock that jumps
back mid-log, and one that jumps years forward. Each is repaired (or carried across) with a
warning naming the stream and what was done, the data is kept, and the run ends as the clean
log's does, in the memory and time of the data, not of the span its stamps claim."""

from __future__ import annotations

import dataclasses
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from _badinputs import base_sim, write_log

from estimator.evaluation.metrics import method_metrics
from estimator.io import load_log
from estimator.params import Params
from estimator.pipeline import open_inputs, run_methods
from estimator.sim.sdmap import write_geojson

YEAR_S = 365.25 * 86400.0


def _route(tmp_path: Path) -> Path:
    path = tmp_path / "drive.route.geojson"
    write_geojson(path, base_sim().route_geojson())
    return path


def _rmse(log: Path, route: Path, cache: Path) -> float:
    inputs = open_inputs(log, route, cache_dir=cache)
    run = run_methods(inputs, Params(), methods=("proposed",))["proposed"]
    assert inputs.route is not None
    truth = method_metrics(run, inputs.route, inputs.log).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return truth.rmse_h_err_m


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, float]:
    tmp = tmp_path_factory.mktemp("clean")
    log, route = write_log(tmp / "drive.mcap"), _route(tmp)
    return log, route, _rmse(log, route, tmp / "cache")


@pytest.mark.parametrize("stamp", [1.0, "years"], ids=["at 1 s", "three years ahead"])
def test_one_corrupt_stamp_is_dropped_and_the_time_base_kept(
    tmp_path: Path, clean: tuple[Path, Path, float], stamp: float | str
) -> None:
    sim = base_sim()
    imu_t = sim.imu.t.copy()
    k = len(imu_t) // 2
    imu_t[k] = 1.0 if stamp == 1.0 else imu_t[k] + 3 * YEAR_S
    gnss_t = sim.gnss.t.copy()
    gnss_t[len(gnss_t) // 3] += 3 * YEAR_S
    log_path = write_log(
        tmp_path / "drive.mcap",
        imu=dataclasses.replace(sim.imu, t=imu_t),
        gnss=dataclasses.replace(sim.gnss, t=gnss_t),
    )
    log = load_log(log_path, cache_dir=tmp_path / "cache")
    assert log.t_start == pytest.approx(sim.imu.t[0])
    assert log.t_end < sim.imu.t[-1] + 1.0
    assert len(log.imu.t) == len(imu_t) - 1 and len(log.gnss.t) == len(gnss_t) - 1
    dropped = [w for w in log.warnings if "corrupt stamps" in w]
    assert len(dropped) == 2
    assert any(w.startswith("IMU ") for w in dropped) and any(
        w.startswith("GNSS ") for w in dropped
    )
    _, route, clean_rmse = clean
    assert _rmse(log_path, route, tmp_path / "cache") == pytest.approx(clean_rmse, abs=0.05)


def test_a_clock_that_jumps_back_keeps_all_the_data(
    tmp_path: Path, clean: tuple[Path, Path, float]
) -> None:
    """The sensors' clock steps back 100 s, 60 s into the drive, while the recorder's receive
    times run on: every stream's stamps jump back at the same instant."""
    from estimator.io.bagwrite import write_bag

    sim = base_sim()
    at = sim.imu.t[0] + 60.0

    def stepped(t: np.ndarray) -> np.ndarray:
        return np.where(t >= at, t - 100.0, t)

    log_path = tmp_path / "drive.mcap"
    write_bag(
        log_path,
        imu=sim.imu,
        gnss=sim.gnss,
        wheel=sim.wheel,
        truth=sim.truth_fix,
        header_stamps={
            "imu": stepped(sim.imu.t),
            "gnss": stepped(sim.gnss.t),
            "wheel": stepped(sim.wheel.t),
        },
    )
    log = load_log(log_path, cache_dir=tmp_path / "cache")
    jumps = [w for w in log.warnings if "clock jumps back" in w]
    assert len(jumps) == 3, log.warnings
    assert all("moved 100.000 s forward" in w and "data kept" in w for w in jumps)
    assert len(log.imu.t) == len(sim.imu.t) and len(log.gnss.t) == len(sim.gnss.t)
    assert np.all(np.diff(log.imu.t) > 0)
    # the streams stay paired: all moved by the IMU's shift, the drive's span is kept
    assert log.imu.t[-1] - log.imu.t[0] == pytest.approx(sim.imu.t[-1] - sim.imu.t[0], abs=0.02)
    shift = (log.gnss.t - sim.gnss.t)[-1]
    assert (log.imu.t - sim.imu.t)[-1] == pytest.approx(shift, abs=1e-6)
    _, route, clean_rmse = clean
    # truth was stamped by the recorder: compare on the sensors' mended clock
    assert _rmse(log_path, route, tmp_path / "cache") < clean_rmse + 2.0


def _every_clock_jumped(path: Path, seconds: float) -> Path:
    """The base drive with every stream's stamps ``seconds`` later from halfway through."""
    sim = base_sim()
    mid = float(sim.imu.t[len(sim.imu.t) // 2])

    def stepped(t: np.ndarray) -> np.ndarray:
        return np.where(t > mid, t + seconds, t)

    return write_log(
        path,
        imu=dataclasses.replace(sim.imu, t=stepped(sim.imu.t)),
        gnss=dataclasses.replace(sim.gnss, t=stepped(sim.gnss.t)),
        wheel=dataclasses.replace(sim.wheel, t=stepped(sim.wheel.t)),
        truth=dataclasses.replace(sim.truth_fix, t=stepped(sim.truth_fix.t)),
    )


def test_a_clock_that_jumps_years_forward_runs_in_the_memory_of_its_data(
    tmp_path: Path, clean: tuple[Path, Path, float]
) -> None:
    """Every stream's stamps jump 10 years forward halfway through the drive (audit F2): the
    output rows were allocated at the output rate over the whole span (893 GiB asked) and the
    outage's attempts walked it a second at a time. Now the run takes what the data needs,
    and the jump is one IMU-gap warning line naming its span."""
    sim = base_sim()
    mid = float(sim.imu.t[len(sim.imu.t) // 2])
    log_path = _every_clock_jumped(tmp_path / "clock_step_10y.mcap", 10 * YEAR_S)
    _, route, _ = clean
    inputs = open_inputs(log_path, route, cache_dir=tmp_path / "cache")
    tracemalloc.start()
    try:
        runs = run_methods(inputs, Params(), methods=("baseline", "proposed"))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 200e6, f"{peak / 1e6:.0f} MB"
    for r in runs.runs.values():
        assert len(r.epochs.t) < 2 * len(sim.imu.t)
        assert np.all(np.isfinite(r.epochs.position))
        gap = [w for w in r.warnings if w.startswith("IMU gap ")]
        assert len(gap) == 1 and f"{(mid - sim.imu.t[0]):.1f}-" in gap[0], r.warnings


def test_info_names_a_jump_every_stream_shares_and_integrates_no_wheel_speed_across_it(
    tmp_path: Path,
) -> None:
    """A day's jump of every stream showed in ``info`` as a GNSS outage only, which reads as a
    tunnel, and the wheel-speed integral took the last speed over the whole day."""
    from inspector.cli.summary import distances_travelled, format_summary, summarize

    jumped = _every_clock_jumped(tmp_path / "clock_step_1d.mcap", 86_400.0)
    clean = write_log(tmp_path / "clean.mcap")
    text = format_summary(summarize(load_log(jumped, cache_dir=tmp_path / "cache")))
    (line,) = [w for w in text.splitlines() if "every stream is silent" in w]
    assert line.startswith("warning   clock_step_1d.mcap: every stream is silent at ")
    assert "(24.0 h): the recording paused, or its clock jumped forward" in line
    wheel = {
        path: next(
            d
            for name, d in distances_travelled(load_log(path, cache_dir=tmp_path / "cache"), None)
            if "wheel" in name
        )
        for path in (jumped, clean)
    }
    assert wheel[jumped] == pytest.approx(wheel[clean], rel=0.01)
    clean_text = format_summary(summarize(load_log(clean, cache_dir=tmp_path / "cache")))
    assert "silent" not in clean_text and "left out" not in clean_text
