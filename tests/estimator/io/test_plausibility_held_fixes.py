"""A receiver holding its last fix (estimator.io.plausibility._held_fixes): some keep sending
the position they had when the sky went, with a valid status, through a tunnel. The filter saw
no outage (so no route update) and was pulled back to the portal by every repeat it took. The
repeats are named in one line and left out, so the span is an outage; a vehicle standing still
in static hold, the bundled samples and the real logs are not named."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.io import load_log
from estimator.io.plausibility import HELD_FIX_MIN_S, _held_fixes
from estimator.log import GnssData, ImuData, Log, WheelData
from estimator.params import Params
from estimator.pipeline import Inputs, open_inputs, run

REPO = Path(__file__).resolve().parents[3]
HELD_WORDS = "repeat the position of the fix at"


def _held_through_longest_gap(g: GnssData) -> tuple[GnssData, float, float]:
    """``g`` with its longest gap between valid fixes filled at the fixes' rate by repeats of
    the last fix before it (status and variance included); the gap's ends."""
    ok = np.flatnonzero(g.valid)
    dt = np.diff(g.t[ok])
    k = int(np.argmax(dt))
    last, a, b = ok[k], float(g.t[ok[k]]), float(g.t[ok[k + 1]])
    rate = float(np.median(dt))
    fill = np.arange(a + rate, b - rate / 2, rate)
    order = np.argsort(np.r_[g.t, fill], kind="stable")

    def repeated(v: np.ndarray) -> np.ndarray:
        return np.concatenate([v, np.repeat(v[last : last + 1], len(fill), axis=0)])[order]

    held = GnssData(
        np.r_[g.t, fill][order],
        repeated(g.lat),
        repeated(g.lon),
        repeated(g.alt),
        repeated(g.status),
        repeated(g.cov_enu),
    )
    return held, a, b


@functools.cache
def _monaco() -> Inputs:
    return open_inputs(
        REPO / "sample_logs" / "monaco_tunnel.mcap",
        REPO / "sample_logs" / "monaco_tunnel.route.geojson",
    )


def _named(path: Path, log: Log) -> tuple[GnssData, list[str]]:
    warnings: list[str] = []
    return _held_fixes(path, log, warnings), warnings


def test_a_fix_held_through_the_tunnel_is_named_left_out_and_the_tunnel_run_as_an_outage(
    tmp_path: Path,
) -> None:
    clean = _monaco()
    held, a, b = _held_through_longest_gap(clean.log.gnss)
    path = tmp_path / "held.mcap"
    log = dataclasses.replace(clean.log, path=str(path), gnss=held)
    gnss, (line,) = _named(path, log)
    t0 = clean.log.t_start
    assert line.startswith(
        f"held.mcap: GNSS /gnss/fix: the 579 fixes stamped {a - t0 + 0.2:.1f}-"
    ), line
    assert f"repeat the position of the fix at {a - t0:.1f} s while the vehicle drove on" in line
    inside = (gnss.t > a) & (gnss.t < b)
    assert inside.sum() == 579 and not gnss.valid[inside].any()
    assert np.array_equal(gnss.valid[~inside], held.valid[~inside])

    # the run: the tunnel is an outage again, with the route updates of the clean log
    checked = dataclasses.replace(log, gnss=gnss)
    held_run = run(checked, clean.route, Params(), frame=clean.frame)
    clean_run = run(clean.log, clean.route, Params(), frame=clean.frame)
    assert held_run.degraded_intervals == clean_run.degraded_intervals
    accepted = [sum(m.accepted for m in r.matches) for r in (held_run, clean_run)]
    assert accepted[0] == accepted[1] > 100
    truth = method_metrics(held_run, clean.route, clean.log, params=held_run.params).truth
    clean_truth = method_metrics(clean_run, clean.route, clean.log, params=clean_run.params).truth
    assert truth is not None and clean_truth is not None
    assert truth.rmse_h_err_m == pytest.approx(clean_truth.rmse_h_err_m, abs=0.05)


def test_the_held_tunnel_through_the_decoder_gives_one_line(tmp_path: Path) -> None:
    """The check runs where every log is read (the warning reaches ``info`` and ``run``)."""
    from estimator.io import write_bag

    clean = _monaco()
    held, _, _ = _held_through_longest_gap(clean.log.gnss)
    path = tmp_path / "held.mcap"
    write_bag(path, imu=clean.log.imu, gnss=held, wheel=clean.log.wheel)
    log = load_log(path, cache_dir=tmp_path / "cache")
    assert len([w for w in log.warnings if HELD_WORDS in w]) == 1


T0 = 1_700_000_000.0


def _stop_and_go(hold_s: float, speed_after: float) -> Log:
    """60 s east at 10 m/s, a stop of ``hold_s`` seconds (the receiver in static hold repeats
    its position, as u-blox's does below its speed threshold), then on at ``speed_after``; 5 Hz
    fixes, wheels at 50 Hz."""
    t = T0 + np.arange(0.0, 60.0 + hold_s + 60.0, 0.01)
    rel = t - T0
    speed = np.where(rel < 60.0, 10.0, np.where(rel < 60.0 + hold_s, 0.0, speed_after))
    east = np.r_[0.0, np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))]
    imu = ImuData(t, np.zeros((len(t), 3)), np.tile([0.0, 0.0, 9.81], (len(t), 1)))
    wheel = WheelData(t[::2], speed[::2])
    ft = t[::20]
    e = east[::20]
    lat = np.full(len(ft), 48.0)
    lon = 11.0 + e / (111_320.0 * np.cos(np.radians(48.0)))
    n = len(ft)
    gnss = GnssData(
        ft, lat, lon, np.full(n, 500.0), np.zeros(n, np.int8), np.tile([1.0, 1.0, 4.0], (n, 1))
    )
    return Log("stop.mcap", imu, gnss, wheel)


@pytest.mark.parametrize("hold_s", [5.0, 40.0])
def test_a_vehicle_standing_in_static_hold_is_not_named(hold_s: float) -> None:
    log = _stop_and_go(hold_s, 10.0)
    repeats = np.diff(log.gnss.lon) == 0
    assert repeats.sum() >= hold_s * 5 - 1  # the stop's fixes repeat one position
    gnss, warnings = _named(Path(log.path), log)
    assert not warnings
    assert gnss is log.gnss


def test_repeats_at_the_log_s_end_are_judged_by_the_wheels() -> None:
    """No fix after the repeats: the wheels say whether the vehicle drove on."""
    log = _stop_and_go(30.0, 10.0)
    g = log.gnss
    end = g.t > T0 + 70.0
    frozen = dataclasses.replace(
        g,
        lat=np.where(end, g.lat[~end][-1], g.lat),
        lon=np.where(end, g.lon[~end][-1], g.lon),
    )
    gnss, (line,) = _named(Path(log.path), dataclasses.replace(log, gnss=frozen))
    assert "while the vehicle drove on" in line
    assert not gnss.valid[g.t > T0 + 90.0 + 1e-6].any()
    parked = dataclasses.replace(
        log, gnss=frozen, wheel=WheelData(log.wheel.t, 0 * log.wheel.speed)
    )  # type: ignore[union-attr]
    assert not _named(Path(log.path), parked)[1]


def test_a_short_repeat_is_not_named() -> None:
    """A receiver repeating one fix for less than HELD_FIX_MIN_S (a dropped update) is left
    to the filter's own tests."""
    log = _stop_and_go(5.0, 10.0)
    g = log.gnss
    k = int(np.searchsorted(g.t, T0 + 20.0))
    n = int(HELD_FIX_MIN_S * 5) - 1
    lon = g.lon.copy()
    lon[k + 1 : k + 1 + n] = lon[k]
    assert not _named(
        Path(log.path), dataclasses.replace(log, gnss=dataclasses.replace(g, lon=lon))
    )[1]
    lon[k + 1 : k + 2 + n] = lon[k]
    assert _named(Path(log.path), dataclasses.replace(log, gnss=dataclasses.replace(g, lon=lon)))[1]
