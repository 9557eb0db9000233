"""Defective but usable logs: each is repaired as ``docs/robustness.md`` documents, the repair
is recorded as a warning (in ``Log.warnings``, ``Run.warnings`` and ``routefuse info``), and the
estimator then runs to the end with finite results."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from _badinputs import (
    Corpus,
    assert_cli_ok,
    base_sim,
    cli_argv,
    finite_log,
    finite_run,
    replace_field,
    rewrite_bag,
    write_log,
)

from estimator.io import load_log
from estimator.log import GnssData, ImuData, Log, WheelData
from estimator.params import Params
from estimator.pipeline import open_inputs, run

IMU_BAD = np.array([100, 101, 2000, 3000, 3001, 3002])
WHEEL_BAD = np.array([50, 51, 1000])
FIX_BAD = np.array([20, 21, 150])  # open-sky fixes (the tunnel starts at about fix 190)
SWAPS = {"/imu/data": range(100, 7000, 97), "/gnss/fix": range(5, 180, 13)}


@dataclass(frozen=True)
class Repair:
    make: Callable[[Path, Corpus], Path]
    check: Callable[[Log], None]
    """asserts the repaired arrays"""
    warning: str
    """text of the warning the repair records (in the log's or the run's warnings)"""
    in_log: bool = True
    """the warning comes from the loader (else from the runner)"""


def _swap(n: int, at: range) -> np.ndarray:
    order = np.arange(n)
    for i in at:
        order[i], order[i + 1] = order[i + 1], order[i]
    return order


# --- builders --------------------------------------------------------------------------------


def _no_wheel(tmp: Path, c: Corpus) -> Path:
    return write_log(tmp / "no_wheel.mcap", wheel=None)


def _imu_nonfinite(tmp: Path, c: Corpus) -> Path:
    imu = base_sim().imu
    gyro, accel = imu.gyro.copy(), imu.accel.copy()
    gyro[IMU_BAD[:2], 1] = np.nan
    gyro[IMU_BAD[2], 0] = np.inf
    accel[IMU_BAD[3:], 2] = -np.inf
    return write_log(tmp / "imu_nan.mcap", imu=ImuData(imu.t, gyro, accel))


def _wheel_nonfinite(tmp: Path, c: Corpus) -> Path:
    w = base_sim().wheel
    speed = w.speed.copy()
    speed[WHEEL_BAD[:2]] = np.nan
    speed[WHEEL_BAD[2]] = np.inf
    return write_log(tmp / "wheel_nan.mcap", wheel=WheelData(w.t, speed))


def _imu_impossible(tmp: Path, c: Corpus) -> Path:
    """Finite but impossible values (a corrupt message): 1e300 rad/s, -5e4 m/s^2, 1e6 m/s."""
    imu = base_sim().imu
    gyro, accel = imu.gyro.copy(), imu.accel.copy()
    gyro[IMU_BAD[:3], 2] = 1e300
    accel[IMU_BAD[3:], 0] = -5e4
    wheel = base_sim().wheel
    speed = wheel.speed.copy()
    speed[WHEEL_BAD] = 1e6
    return write_log(
        tmp / "imu_wild.mcap", imu=ImuData(imu.t, gyro, accel), wheel=WheelData(wheel.t, speed)
    )


def _fix_nonfinite(tmp: Path, c: Corpus) -> Path:
    """NavSatFix messages that say STATUS_FIX but carry NaN/inf (written raw)."""
    values = dict(zip(FIX_BAD.tolist(), [np.nan, np.inf, -np.inf], strict=True))

    def edit(topic, i, msg):
        if topic == "/gnss/fix" and i in values:
            return replace_field(msg, "latitude", values[i])
        return None

    return rewrite_bag(c.valid(), tmp / "fix_nan.mcap", edit=edit)


def _fix_bad_variance(tmp: Path, c: Corpus) -> Path:
    """Zero and negative variances (written through write_bag) and inf (written raw)."""
    g = base_sim().gnss
    cov = g.cov_enu.copy()
    ok = g.valid
    cov[np.flatnonzero(ok)[::3]] = 0.0
    cov[np.flatnonzero(ok)[1::3], 1] = -4.0
    src = write_log(tmp / "cov0.mcap", gnss=replace(g, cov_enu=cov))

    def edit(topic, i, msg):
        if topic == "/gnss/fix" and i == int(np.flatnonzero(ok)[2]):
            return replace_field(msg, "position_covariance[8]", np.inf)
        return None

    return rewrite_bag(src, tmp / "cov.mcap", edit=edit)


def _duplicates(tmp: Path, c: Corpus) -> Path:
    sim = base_sim()

    def dup(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return np.insert(x, idx, x[idx], axis=0)

    i_imu, i_gnss, i_wheel = np.arange(500, 600, 10), np.arange(10, 40, 3), np.arange(7, 300, 29)
    imu = ImuData(*(dup(a, i_imu) for a in (sim.imu.t, sim.imu.gyro, sim.imu.accel)))
    fields = ("t", "lat", "lon", "alt", "status", "cov_enu")
    gnss = GnssData(*(dup(getattr(sim.gnss, f), i_gnss) for f in fields))
    wheel = WheelData(dup(sim.wheel.t, i_wheel), dup(sim.wheel.speed, i_wheel))
    return write_log(tmp / "dup.mcap", imu=imu, gnss=gnss, wheel=wheel)


def _backwards(tmp: Path, c: Corpus) -> Path:
    """Header stamps run backwards at every swap while the file stays in receive order."""
    sim = base_sim()
    order = {
        "/imu/data": _swap(len(sim.imu.t), SWAPS["/imu/data"]),
        "/gnss/fix": _swap(len(sim.gnss.t), SWAPS["/gnss/fix"]),
    }
    return rewrite_bag(c.valid(), tmp / "backwards.mcap", order=order)


def _gap(tmp: Path, c: Corpus) -> Path:
    """No sensor says anything for 10 minutes, 20 s into the drive."""
    sim = base_sim()
    t0 = sim.imu.t[0]

    def shift(t: np.ndarray) -> np.ndarray:
        return np.where(t >= t0 + 20.0, t + 600.0, t)

    return write_log(
        tmp / "gap.mcap",
        imu=replace(sim.imu, t=shift(sim.imu.t)),
        gnss=replace(sim.gnss, t=shift(sim.gnss.t)),
        wheel=replace(sim.wheel, t=shift(sim.wheel.t)),
        truth=replace(sim.truth_fix, t=shift(sim.truth_fix.t)),
    )


def _irregular(tmp: Path, c: Corpus) -> Path:
    """40 % of the IMU samples lost at random (intervals of 10, 20, 30 ... ms)."""
    imu = base_sim().imu
    keep = np.random.default_rng(3).random(len(imu.t)) > 0.4
    return write_log(
        tmp / "irregular.mcap", imu=ImuData(imu.t[keep], imu.gyro[keep], imu.accel[keep])
    )


def _jitter(tmp: Path, c: Corpus) -> Path:
    """Stamps jittered by up to +-4 ms at 100 Hz (still in order)."""
    imu = base_sim().imu
    t = imu.t + np.random.default_rng(4).uniform(-0.004, 0.004, len(imu.t))
    return write_log(tmp / "jitter.mcap", imu=replace(imu, t=t))


# --- checks ----------------------------------------------------------------------------------


def _check_no_wheel(log: Log) -> None:
    assert log.wheel is None


def _check_imu_dropped(log: Log) -> None:
    assert np.array_equal(log.imu.t, np.delete(base_sim().imu.t, IMU_BAD))


def _check_wheel_dropped(log: Log) -> None:
    assert log.wheel is not None
    assert np.array_equal(log.wheel.t, np.delete(base_sim().wheel.t, WHEEL_BAD))


def _check_fix_invalid(log: Log) -> None:
    g = base_sim().gnss
    assert np.all(log.gnss.status[FIX_BAD] == -1) and not log.gnss.valid[FIX_BAD].any()
    assert np.count_nonzero(log.gnss.valid) == np.count_nonzero(g.valid) - len(FIX_BAD)


def _check_variance_unknown(log: Log) -> None:
    ok = np.flatnonzero(base_sim().gnss.valid)
    changed = np.r_[ok[::3], ok[1::3], ok[2]]
    assert np.all(np.isnan(log.gnss.cov_enu[changed]))
    untouched = np.setdiff1d(ok, changed)
    np.testing.assert_allclose(log.gnss.cov_enu[untouched], base_sim().gnss.cov_enu[untouched])


def _check_deduplicated(log: Log) -> None:
    sim = base_sim()
    assert np.array_equal(log.imu.t, sim.imu.t)
    assert np.array_equal(log.gnss.t, sim.gnss.t)
    assert log.wheel is not None and np.array_equal(log.wheel.t, sim.wheel.t)


def _check_sorted(log: Log) -> None:
    sim = base_sim()
    assert np.array_equal(log.imu.t, sim.imu.t)
    np.testing.assert_array_equal(log.imu.gyro, sim.imu.gyro)
    assert np.array_equal(log.gnss.t, sim.gnss.t)


def _check_gap(log: Log) -> None:
    assert np.max(np.diff(log.imu.t)) == pytest.approx(600.0, abs=0.02)


def _check_unchanged_imu(log: Log) -> None:
    assert np.all(np.diff(log.imu.t) > 0)


REPAIRS: dict[str, Repair] = {
    "no wheel topic": Repair(_no_wheel, _check_no_wheel, "no wheel speed", in_log=False),
    "IMU NaN/inf": Repair(
        _imu_nonfinite, _check_imu_dropped, "IMU /imu/data: dropped 6 samples with non-finite"
    ),
    "wheel NaN/inf": Repair(
        _wheel_nonfinite,
        _check_wheel_dropped,
        "wheel /wheel/odom: dropped 3 samples with non-finite",
    ),
    "IMU and wheel with impossible values": Repair(
        _imu_impossible,
        lambda log: (_check_imu_dropped(log), _check_wheel_dropped(log)),
        "IMU /imu/data: dropped 6 samples with physically impossible values (beyond 100, 2000)",
    ),
    "fix with NaN/inf position": Repair(
        _fix_nonfinite,
        _check_fix_invalid,
        "GNSS /gnss/fix: 3 fixes without a finite, in-range position, treated as no fix",
    ),
    "zero/negative/inf GNSS variance": Repair(
        _fix_bad_variance,
        _check_variance_unknown,
        "fixes with a zero, negative or non-finite variance, treated as unknown",
    ),
    "duplicated stamps": Repair(
        _duplicates, _check_deduplicated, "IMU /imu/data: dropped 10 samples with a repeated stamp"
    ),
    "backwards stamps": Repair(
        _backwards,
        _check_sorted,
        f"IMU /imu/data: {len(SWAPS['/imu/data'])} samples out of time order, sorted by stamp",
    ),
    "10-minute gap in all sensors": Repair(
        _gap, _check_gap, "1 IMU gaps longer than 1 s (largest 600.0 s)", in_log=False
    ),
    "IMU at irregular rate": Repair(
        _irregular, _check_unchanged_imu, "IMU /imu/data: irregular sample intervals"
    ),
    "IMU stamps jittered": Repair(
        _jitter, _check_unchanged_imu, "IMU /imu/data: irregular sample intervals"
    ),
}


def _has(warnings: tuple[str, ...], text: str) -> bool:
    return any(text in w for w in warnings)


@pytest.mark.parametrize("name", list(REPAIRS))
def test_repaired_log_runs_to_a_finite_end(
    tmp_path: Path, corpus: Corpus, route: Path, capsys, name: str
) -> None:
    case = REPAIRS[name]
    path = corpus.build(name, case.make)
    log = load_log(path, cache_dir=tmp_path / "cache")
    finite_log(log)
    case.check(log)
    if case.in_log:
        assert _has(log.warnings, case.warning), log.warnings
    inputs = open_inputs(path, route, cache_dir=tmp_path / "cache")
    result = run(inputs.log, inputs.route, Params(), frame=inputs.frame)
    finite_run(result)
    assert result.epochs.t[-1] == pytest.approx(log.t_end, abs=0.2)  # ran to the end
    assert _has(result.warnings, case.warning), result.warnings
    if case.in_log:
        out = assert_cli_ok(capsys, cli_argv("info", path, route))
        assert case.warning in out


@pytest.mark.parametrize(
    "name",
    [
        "IMU NaN/inf",
        "IMU and wheel with impossible values",
        "backwards stamps",
        "10-minute gap in all sensors",
    ],
)
def test_routefuse_run_accepts_a_repaired_log(
    corpus: Corpus, route: Path, capsys, name: str
) -> None:
    path = corpus.build(name, REPAIRS[name].make)
    assert_cli_ok(capsys, cli_argv("run", path, route))


def test_the_unrepaired_log_of_the_base_drive_has_no_warning(
    tmp_path: Path, corpus: Corpus
) -> None:
    """The warnings above come from the defects, not from the drive."""
    assert load_log(corpus.valid(), cache_dir=tmp_path / "cache").warnings == ()


def test_runner_repairs_a_log_built_in_memory() -> None:
    """A Log made in Python (not through the loader) with NaN IMU samples, out-of-order and
    repeated IMU stamps, NaN wheel speeds and non-positive GNSS variances still runs finite."""
    sim = base_sim()
    log = sim.log()
    t = log.imu.t.copy()
    gyro = log.imu.gyro.copy()
    gyro[[10, 500, 4000]] = np.nan
    t[[200, 201]] = t[[201, 200]]
    t[300] = t[299]
    speed = log.wheel.speed.copy()
    speed[[5, 700]] = np.nan
    cov = log.gnss.cov_enu.copy()
    cov[::4] = 0.0
    cov[1::4] = -1.0
    bad = replace(
        log,
        imu=ImuData(t, gyro, log.imu.accel),
        wheel=WheelData(log.wheel.t, speed),
        gnss=replace(log.gnss, cov_enu=cov),
    )
    result = run(bad, sim.route(), Params(), frame=sim.frame)
    finite_run(result)
    assert _has(result.warnings, "dropped 3 non-finite IMU samples")
    assert _has(result.warnings, "IMU time not increasing: sorted, dropped 1 repeats")


def test_a_long_gap_does_not_stall_a_run_with_progress(
    tmp_path: Path, corpus: Corpus, route: Path
) -> None:
    """The CLI and the inspector pass a progress callback, which makes the runner advance in
    chunks; a 10-minute gap once made that loop spin forever."""
    import threading

    path = corpus.build(
        "10-minute gap in all sensors", REPAIRS["10-minute gap in all sensors"].make
    )
    inputs = open_inputs(path, route, cache_dir=tmp_path / "cache")
    seen: list[float] = []
    done: list[object] = []

    def work() -> None:
        done.append(
            run(inputs.log, inputs.route, Params(), frame=inputs.frame, progress=seen.append)
        )

    worker = threading.Thread(target=work, daemon=True)
    worker.start()
    worker.join(timeout=60.0)
    assert not worker.is_alive(), f"run still going after 60 s (progress {seen[-3:]})"
    assert done and seen[-1] == 1.0 and np.all(np.diff(seen) >= 0)
    finite_run(done[0])  # type: ignore[arg-type]


@pytest.mark.parametrize("rotation", [(0.0, 0.0, 0.0, 0.0), (np.nan, 0.0, 0.0, 1.0)])
def test_a_tf_static_without_a_rotation_is_ignored(tmp_path: Path, rotation) -> None:
    """Found by the loader fuzz test: a zero or NaN quaternion in /tf_static made every IMU
    sample NaN. The transform is now ignored with a warning and the IMU is left as it is."""
    from estimator.io.bagwrite import StaticTransform

    sim = base_sim()
    path = write_log(
        tmp_path / "tf.mcap",
        imu_frame="imu_link",
        static_transforms=[StaticTransform("base_link", "imu_link", rotation)],
    )
    log = load_log(path, cache_dir=tmp_path / "cache")
    finite_log(log)
    np.testing.assert_array_equal(log.imu.gyro, sim.imu.gyro)
    assert _has(log.warnings, "/tf_static: ignored 1 transforms with a zero or non-finite")
