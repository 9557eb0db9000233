"""A receiver coasting through an outage on its own dead reckoning
(estimator.io.plausibility._coasting_fixes): some go on through a tunnel with a valid status and
a small sigma, their position drifting. The run saw no outage (so no route update) and followed
the drift, 71 m RMS off in monaco's tunnel and 1094 m in the long one, with not one warning.
The jump when the sky comes back is named in one line; the fixes before it are left out when the
receiver's own variance says it coasted (the run is then the clean log's), and kept otherwise
(which side of the jump is wrong, and since when, the fixes do not say). A fix that jumps and
comes back, the bundled samples, the real logs and the stress drives are not named."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest

from estimator.evaluation.metrics import method_metrics
from estimator.io import load_log, write_bag
from estimator.io.plausibility import COAST_JUMP_M, _coasting_fixes
from estimator.log import GnssData, Log
from estimator.params import Params
from estimator.pipeline import Inputs, open_inputs, run

REPO = Path(__file__).resolve().parents[3]
JUMP_WORDS = "its fixes jump"
R_EARTH = 6_378_137.0


@functools.cache
def _monaco() -> Inputs:
    return open_inputs(
        REPO / "sample_logs" / "monaco_tunnel.mcap",
        REPO / "sample_logs" / "monaco_tunnel.route.geojson",
    )


def _coasting(log: Log, var_growth_per_s: float = 0.0) -> tuple[GnssData, float, float]:
    """``log``'s fixes with its longest gap filled at the fixes' rate by a receiver's own dead
    reckoning: the truth with a 3 % scale error and a heading drifting 0.1 deg/s, status valid,
    the log's median variance growing by ``var_growth_per_s`` of itself a second; the gap's
    ends."""
    g, truth = log.gnss, log.truth
    assert truth is not None
    ok = np.flatnonzero(g.valid)
    k = int(np.argmax(np.diff(g.t[ok])))
    a, b = float(g.t[ok[k]]), float(g.t[ok[k + 1]])
    rate = float(np.median(np.diff(g.t[ok])))
    ft = np.arange(a + rate, b - rate / 2, rate)
    lat = np.interp(np.r_[a, ft], truth.t, truth.lat)
    lon = np.interp(np.r_[a, ft], truth.t, truth.lon)
    de = np.diff(np.radians(lon)) * R_EARTH * np.cos(np.radians(lat[:-1]))
    dn = np.diff(np.radians(lat)) * R_EARTH
    psi = np.radians(0.1) * (ft - a)
    err_e = np.cumsum(1.03 * (np.cos(psi) * de - np.sin(psi) * dn) - de)
    err_n = np.cumsum(1.03 * (np.sin(psi) * de + np.cos(psi) * dn) - dn)
    f_lat = lat[1:] + np.degrees(err_n / R_EARTH)
    f_lon = lon[1:] + np.degrees(err_e / (R_EARTH * np.cos(np.radians(lat[1:]))))
    n = len(ft)
    cov = np.nanmedian(g.cov_enu[ok], axis=0) * (1.0 + var_growth_per_s * (ft - a))[:, None]
    keep = ~((g.t > a) & (g.t < b))
    t = np.r_[g.t[keep], ft]
    order = np.argsort(t, kind="stable")
    coasted = GnssData(
        t[order],
        np.r_[g.lat[keep], f_lat][order],
        np.r_[g.lon[keep], f_lon][order],
        np.r_[g.alt[keep], np.interp(ft, truth.t, truth.alt)][order],
        np.r_[g.status[keep], np.zeros(n, np.int8)][order],
        np.r_[g.cov_enu[keep], cov][order],
    )
    return coasted, a, b


def _named(path: Path, log: Log) -> tuple[GnssData, list[str]]:
    warnings: list[str] = []
    return _coasting_fixes(path, log, warnings), warnings


def _truth_rmse(inputs: Inputs, log: Log) -> tuple[float, int]:
    """routefuse's truth RMSE over the clean log's tunnel, and its accepted route updates."""
    clean = inputs.log
    r = run(log, inputs.route, Params(), frame=inputs.frame)
    tunnel = run(clean, inputs.route, Params(), frame=inputs.frame).degraded_intervals
    truth = method_metrics(r, inputs.route, clean, params=r.params, intervals=tunnel).truth
    assert truth is not None and truth.rmse_h_err_m is not None
    return truth.rmse_h_err_m, sum(m.accepted for m in r.matches)


def test_a_receiver_coasting_with_a_small_sigma_is_named_in_one_line_and_kept(
    tmp_path: Path,
) -> None:
    inputs = _monaco()
    coasted, _, b = _coasting(inputs.log)
    path = tmp_path / "coast.mcap"
    log = dataclasses.replace(inputs.log, path=str(path), gnss=coasted)
    gnss, (line,) = _named(path, log)
    t0 = inputs.log.t_start
    assert line.startswith(
        f"coast.mcap: GNSS /gnss/fix: its fixes jump 148 m from {b - t0 - 0.2:.1f} to "
        f"{b - t0:.1f} s, where the wheels drove 2.8 m, and stay there"
    ), line
    assert "their sigma 0.85 m" in line and "a receiver coasting on its own dead reckoning" in line
    assert line.endswith(f"(--outage START:{b - t0 - 0.2:.1f})"), line
    assert gnss is coasted  # kept: the fixes do not say since when they are off


def test_a_receiver_coasting_with_a_growing_variance_is_left_out_and_the_tunnel_run_as_an_outage(
    tmp_path: Path,
) -> None:
    """Its variance grew steadily through the tunnel and fell back at the exit: those fixes
    are its coasting. Left out, the tunnel is an outage again, routefuse's run the clean log's
    (it ran 74 m RMS off, with no route update and no warning)."""
    inputs = _monaco()
    coasted, a, b = _coasting(inputs.log, var_growth_per_s=0.2)
    path = tmp_path / "coast.mcap"
    log = dataclasses.replace(inputs.log, path=str(path), gnss=coasted)
    gnss, (line,) = _named(path, log)
    t0 = inputs.log.t_start
    assert f"their variance grew steadily from {a - t0 + 0.2:.1f} s" in line, line
    assert line.endswith(
        f"the 579 fixes stamped {a - t0 + 0.2:.1f}-{b - t0 - 0.2:.1f} s are left out of the run, "
        "which takes them as an outage"
    ), line
    inside = (gnss.t > a) & (gnss.t < b)
    assert inside.sum() == 579 and not gnss.valid[inside].any()
    assert np.array_equal(gnss.valid[~inside], coasted.valid[~inside])

    clean_rmse, clean_accepted = _truth_rmse(inputs, inputs.log)
    coasted_rmse, coasted_accepted = _truth_rmse(inputs, log)
    assert coasted_rmse > 50.0 and coasted_accepted == 0  # as it ran before
    rmse, accepted = _truth_rmse(inputs, dataclasses.replace(log, gnss=gnss))
    assert rmse == pytest.approx(clean_rmse, abs=0.05)
    assert accepted == clean_accepted > 100


def test_the_coasting_through_the_decoder_gives_one_line(tmp_path: Path) -> None:
    """The check runs where every log is read (the line reaches ``info`` and ``run``)."""
    inputs = _monaco()
    coasted, _, _ = _coasting(inputs.log)
    path = tmp_path / "coast.mcap"
    write_bag(path, imu=inputs.log.imu, gnss=coasted, wheel=inputs.log.wheel)
    log = load_log(path, cache_dir=tmp_path / "cache")
    assert len([w for w in log.warnings if JUMP_WORDS in w]) == 1


def _moved(g: GnssData, mask: np.ndarray, east_m: float) -> GnssData:
    lon = g.lon + np.where(mask, np.degrees(east_m / (R_EARTH * np.cos(np.radians(g.lat)))), 0)
    return dataclasses.replace(g, lon=lon)


def test_a_step_of_every_fix_after_it_is_named_and_nothing_left_out(tmp_path: Path) -> None:
    """A step of the fixes (another datum, another base station) is a jump that stays too:
    named, and, the variance steady, no fix left out."""
    log = _monaco().log
    g = log.gnss
    stepped = _moved(g, g.t - log.t_start > 60.0, 2 * COAST_JUMP_M)
    gnss, (line,) = _named(tmp_path / "step.mcap", dataclasses.replace(log, gnss=stepped))
    assert "m from 60.0 to 60.2 s, where the wheels drove" in line, line
    assert "or those after it are (a step" in line
    assert gnss is stepped


@pytest.mark.parametrize("every", [1, 2], ids=["one fix", "every other fix for 5 s"])
def test_fixes_that_jump_and_come_back_are_not_named(tmp_path: Path, every: int) -> None:
    """Multipath: one fix 60 m off, or every other one for 5 s: the filter's gate's work."""
    log = _monaco().log
    g = log.gnss
    rel = g.t - log.t_start
    k = int(np.searchsorted(rel, 50.0))
    mask = np.zeros(len(g.t), bool)
    mask[k : k + (25 if every == 2 else 1) : every] = True
    _, warnings = _named(tmp_path / "m.mcap", dataclasses.replace(log, gnss=_moved(g, mask, 60.0)))
    assert not warnings


@pytest.mark.parametrize("index", range(5))
def test_no_stress_drive_is_named(index: int) -> None:
    from estimator.sim.stress import build, drive_spec

    log = build(drive_spec(index)).inputs.log
    assert not _named(Path("stress.mcap"), log)[1]
