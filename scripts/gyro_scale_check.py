#!/usr/bin/env python3
"""Is ``extensions.gyro_scale_state`` a calibration? Per stress-corpus drive, the z gyro's
scale factor the filter (baseline parameters, the switch on) holds at each GNSS outage's
start against the one the simulator drew, its sigma, and the z gyro bias error over its sigma
with the switch on and off; with dead reckoning's truth RMSE over the outages, off and on.

    python scripts/gyro_scale_check.py [--drives 50] [--workers 2]

The filter is stepped directly (:class:`estimator.filter.engine.Filter`) to each outage
start, so the state read there is the one dead reckoning starts the outage from; the RMSE
comes from the ordinary baseline run. The summary says whether the scale estimate is honest
(its normalised error's RMS near 1) and how much of its prior GNSS removed.
"""

from __future__ import annotations

import argparse
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

DEG_H = math.pi / 180.0 / 3600.0


@dataclass(frozen=True)
class OutageStart:
    """The filter's z scale and bias at one outage start, against the simulated truth."""

    scale: float
    scale_sigma: float
    bias_error_on_deg_h: float
    bias_sigma_on_deg_h: float
    bias_error_off_deg_h: float
    bias_sigma_off_deg_h: float


@dataclass(frozen=True)
class DriveCheck:
    drive: int
    base: str
    true_scale: float
    rmse_off_m: float
    rmse_on_m: float
    starts: tuple[OutageStart, ...]


def _at_starts(drive: object, on: bool) -> list[tuple[float, float, float, float]]:
    """(scale, its sigma, z bias, its sigma) at each tunnel entry, the switch ``on`` or off."""
    from estimator.filter import layout
    from estimator.filter.engine import Filter
    from estimator.filter.setup import prepare_inputs
    from estimator.params import Params, for_method, with_values
    from estimator.sim.stress import Drive

    assert isinstance(drive, Drive)
    log = drive.inputs.log
    p = for_method(with_values(Params(), {"extensions.gyro_scale_state": on}), "baseline")
    inp = prepare_inputs(log, p, drive.inputs.frame, ())
    f = Filter(inp, source=log.path, t_start=log.t_start)
    f.start(4000)
    rows = []
    for a, _ in drive.tunnels:
        f.advance(a)
        rows.append(
            (
                float(f.x[layout.X_GSF]),
                math.sqrt(max(f.P[layout.E_GSF, layout.E_GSF], 0.0)),
                float(f.x[layout.X_BG + 2]),
                math.sqrt(f.P[layout.E_BG + 2, layout.E_BG + 2]),
            )
        )
    return rows


def check(index: int) -> DriveCheck:
    """One drive's figures (runs in a worker process)."""
    from estimator.evaluation.metrics import method_metrics
    from estimator.params import Params, with_values
    from estimator.pipeline import run_methods
    from estimator.sim.stress import build, drive_spec

    spec = drive_spec(index)
    drive = build(spec)
    err, imu_t = drive.imu_errors, drive.imu_t
    assert err is not None and imu_t is not None
    rmse = {}
    for on in (False, True):
        values = {"extensions.gyro_scale_state": on}
        run = run_methods(drive.inputs, with_values(Params(), values), methods=("baseline",))
        t = method_metrics(run["baseline"], drive.inputs.route, drive.inputs.log).truth
        rmse[on] = float(t.rmse_h_err_m) if t and t.rmse_h_err_m is not None else math.nan
    on_rows, off_rows = _at_starts(drive, True), _at_starts(drive, False)
    starts = []
    for (a, _), (s, ss, b_on, bs_on), (_, _, b_off, bs_off) in zip(
        drive.tunnels, on_rows, off_rows, strict=True
    ):
        b_true = float(np.interp(a, imu_t, err.gyro_bias[:, 2]))
        starts.append(
            OutageStart(
                s,
                ss,
                (b_on - b_true) / DEG_H,
                bs_on / DEG_H,
                (b_off - b_true) / DEG_H,
                bs_off / DEG_H,
            )
        )
    return DriveCheck(
        index, spec.base, float(err.gyro_scale[2]), rmse[False], rmse[True], tuple(starts)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--drives", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    with ProcessPoolExecutor(a.workers) as ex:
        checks = list(ex.map(check, range(a.drives)))
    z, zb_on, zb_off, left = [], [], [], []
    print(
        "drive base           true[ppm]  DR off  DR on [m] | per outage: est+-sigma (z), "
        "bias err/sigma on, off [deg/h]"
    )
    for c in checks:
        line = (
            f"{c.drive:5d} {c.base:14s} {c.true_scale * 1e6:8.0f} {c.rmse_off_m:7.2f} "
            f"{c.rmse_on_m:6.2f} |"
        )
        for o in c.starts:
            zi = (c.true_scale - o.scale) / o.scale_sigma
            z.append(zi)
            zb_on.append(o.bias_error_on_deg_h / o.bias_sigma_on_deg_h)
            zb_off.append(o.bias_error_off_deg_h / o.bias_sigma_off_deg_h)
            line += (
                f" {o.scale * 1e6:6.0f}+-{o.scale_sigma * 1e6:4.0f} ({zi:5.2f})"
                f" {o.bias_error_on_deg_h:5.1f}/{o.bias_sigma_on_deg_h:3.1f}"
                f" {o.bias_error_off_deg_h:5.1f}/{o.bias_sigma_off_deg_h:3.1f};"
            )
        if c.starts:
            left.append(c.starts[0].scale_sigma)
        print(line)
    off = np.array([c.rmse_off_m for c in checks])
    on = np.array([c.rmse_on_m for c in checks])

    def rms(v: list[float]) -> float:
        return float(np.sqrt(np.mean(np.square(v))))

    print(
        f"scale at {len(z)} outage starts: normalised error mean {np.mean(z):.2f}, RMS "
        f"{rms(z):.2f}, max |z| {np.max(np.abs(z)):.2f}; sigma at the first outage median "
        f"{np.median(left) * 1e6:.0f} ppm (prior 1500)"
    )
    print(f"z gyro bias normalised error RMS: on {rms(zb_on):.2f}, off {rms(zb_off):.2f}")
    print(
        f"dead reckoning: worse by > 0.2 m on {int(np.sum(on > off + 0.2))}, better by > 0.2 "
        f"m on {int(np.sum(on < off - 0.2))} of {len(checks)}; median {np.median(off):.2f} -> "
        f"{np.median(on):.2f} m"
    )


if __name__ == "__main__":
    main()
