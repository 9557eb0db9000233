"""``routefuse simulate SCENARIO --out DIR``: a simulated tunnel drive as a bag and a route."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from estimator.errors import ConfigError

if TYPE_CHECKING:
    from estimator.log import Log
    from estimator.route import Route

NAME = "simulate"
HELP = (
    "Simulate a drive through tunnels (truth, MEMS IMU, wheel speed, GNSS with outages) and "
    "write DIR/SCENARIO.mcap and DIR/SCENARIO.route.geojson; --list shows the scenarios, "
    "--stress N writes drive N of the stress corpus (docs/integrity.md) as DIR/stress_N.*, "
    "--stress N --corpus K drive N of held-out corpus K as DIR/stress_cK_N.*."
)
SCENARIO_ONLY = {
    "--seed": ("seed", 0),
    "--imu-rate": ("imu_rate", 100.0),
    "--duration": ("duration", None),
    "--duration-scale": ("duration_scale", 1.0),
    "--perfect": ("perfect", False),
}
"""options a stress drive does not take (its index fixes everything): flag: (dest, default)"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", nargs="?", metavar="SCENARIO", help="scenario name")
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
    parser.add_argument(
        "--stress",
        type=int,
        metavar="N",
        help="instead of a scenario: drive N of the stress corpus, its faults and its biased or "
        "trap route as the corpus builds them",
    )
    parser.add_argument(
        "--corpus",
        type=int,
        default=0,
        metavar="K",
        help="with --stress: 0 (default) the corpus the defaults were chosen with, 1, 2, ... a "
        "held-out corpus (the same kinds of fault drawn afresh)",
    )
    parser.add_argument("--out", metavar="DIR", type=Path, help="output folder")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--imu-rate", type=float, default=100.0, metavar="HZ", help="IMU rate (default 100)"
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="stop the drive after S seconds (default: the whole scenario)",
    )
    parser.add_argument(
        "--duration-scale",
        type=float,
        default=1.0,
        metavar="X",
        help="stretch the straights (open sky and tunnels) by X; turns keep their angle",
    )
    parser.add_argument(
        "--perfect", action="store_true", help="no sensor errors (tunnels still block GNSS)"
    )
    parser.add_argument(
        "--storage",
        choices=("mcap", "sqlite3", "ros1"),
        default="mcap",
        help="bag format (default mcap: one bare .mcap file)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite an existing bag")


class _Progress:
    """One status line on stderr, rewritten in place when stderr is a terminal."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.last = ""

    def __call__(self, stage: str, fraction: float) -> None:
        line = f"simulating: {stage} {100 * fraction:3.0f}%"
        if line == self.last:
            return
        self.last = line
        if self.tty:
            print("\r" + line, end="", file=sys.stderr, flush=True)
        elif fraction >= 1.0:
            print(line, file=sys.stderr)

    def done(self) -> None:
        if self.tty and self.last:
            print(file=sys.stderr)


def execute(args: argparse.Namespace) -> int:
    from estimator.sim import SCENARIOS, get_scenario, simulate
    from estimator.sim.simulation import BAG_SUFFIX

    if args.list:
        width = max(len(n) for n in SCENARIOS)
        for name in SCENARIOS:
            print(f"{name:<{width}}  {get_scenario(name).description}")
        return 0
    if args.scenario and args.stress is not None:
        raise ConfigError(None, "give a SCENARIO or --stress N, not both")
    if not args.scenario and args.stress is None:
        raise ConfigError(
            None, "give a SCENARIO (routefuse simulate --list shows them) or --stress N"
        )
    if args.out is None:
        raise ConfigError(None, "give the output folder with --out DIR")
    if args.out.exists() and not args.out.is_dir():
        raise ConfigError(args.out, "--out exists and is not a folder")
    if args.stress is not None:
        return _stress(args)
    if args.corpus != 0:
        raise ConfigError("--corpus", "applies to --stress N only")
    if not 0 <= args.seed < 2**32:
        raise ConfigError("--seed", f"{args.seed} is outside [0, 2**32 - 1]")
    for flag, value in (("--imu-rate", args.imu_rate), ("--duration-scale", args.duration_scale)):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(flag, f"{value} is not a positive finite number")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError("--duration", f"{args.duration} is not a positive finite number")
    scenario = get_scenario(args.scenario)
    _refuse_existing(args.out / f"{scenario.name}{BAG_SUFFIX[args.storage]}", args.force)
    progress = _Progress()
    started = time.perf_counter()
    sim = simulate(
        scenario,
        seed=args.seed,
        imu_rate_hz=args.imu_rate,
        duration_s=args.duration,
        duration_scale=args.duration_scale,
        perfect=args.perfect,
        progress=progress,
    )
    progress("writing", 0.0)
    bag, route = sim.write(args.out, storage=args.storage, overwrite=args.force)
    progress("writing", 1.0)
    progress.done()
    about = f"{sim.duration_s:.1f} s, {sim.distance_m / 1000:.2f} km"
    _report(bag, route, sim.log(), sim.route(), sim.tunnels, about, imu_rate_hz=sim.imu_rate_hz)
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0


def _stress(args: argparse.Namespace) -> int:
    """Write corpus drive ``--stress N`` and say which faults it has."""
    from estimator.sim.simulation import BAG_SUFFIX, write_drive
    from estimator.sim.stress import build, drive_spec

    given = [f for f, (dest, default) in SCENARIO_ONLY.items() if getattr(args, dest) != default]
    if given:
        raise ConfigError(given[0], "does not apply to --stress (the drive's index fixes it)")
    if args.stress < 0:
        raise ConfigError("--stress", f"{args.stress} is not a corpus index (0, 1, 2, ...)")
    if args.corpus < 0:
        raise ConfigError("--corpus", f"{args.corpus}: 0 or a held-out corpus 1, 2, ...")
    spec = drive_spec(args.stress, corpus=args.corpus)
    _refuse_existing(args.out / f"{spec.name}{BAG_SUFFIX[args.storage]}", args.force)
    progress = _Progress()
    started = time.perf_counter()
    drive = build(spec, progress=progress)
    progress("writing", 0.0)
    log = drive.inputs.log
    bag, route = write_drive(
        args.out,
        spec.name,
        log,
        drive.route_geojson(),
        storage=args.storage,
        overwrite=args.force,
    )
    progress("writing", 1.0)
    progress.done()
    assert drive.inputs.route is not None
    about = f"{log.duration_s:.1f} s, {spec.base} seed {spec.seed}"
    _report(bag, route, log, drive.inputs.route, drive.tunnels, about)
    extra = ""
    if spec.first_fix_off_m:
        extra += f", first fix {spec.first_fix_off_m:.1f} m off"
    if spec.imu_gap_s:
        extra += f", IMU gap {spec.imu_gap_s:.1f} s"
    print(
        f"faults: {spec.fault}; map bias {spec.bias_along_m:+.2f} m along, "
        f"{spec.bias_across_m:+.2f} m across, {spec.bias_rotation_deg:+.2f} deg rotation; "
        f"gyro bias {spec.gyro_bias_deg_h:.0f} deg/h (1 sigma); "
        f"wheel scale error {100 * spec.wheel_scale_error:+.2f} %{extra}"
    )
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0


def _refuse_existing(bag: Path, force: bool) -> None:
    if bag.exists() and not force:
        raise ConfigError(bag, "already exists (use --force to overwrite)")


def _report(
    bag: Path,
    route_path: Path,
    log: Log,
    route: Route,
    tunnels: tuple[tuple[float, float], ...],
    about: str,
    *,
    imu_rate_hz: float | None = None,
) -> None:
    """What was written: the bag's streams and tunnels (seconds from the start), the route."""
    t0 = log.t_start
    spans = ", ".join(f"{a - t0:.1f}-{b - t0:.1f} s" for a, b in tunnels)
    wheel = "none" if log.wheel is None else str(len(log.wheel.t))
    truth = "none" if log.truth is None else str(len(log.truth.t))
    rate = "" if imu_rate_hz is None else f" at {imu_rate_hz:g} Hz"
    print(
        f"{bag}: {about}, IMU {len(log.imu.t)}{rate}, GNSS {len(log.gnss.t)} "
        f"({int(log.gnss.valid.sum())} fixes), wheel {wheel}, truth {truth}; "
        f"tunnels {spans or 'none'}"
    )
    print(f"{route_path}: {len(route.xy)} vertices, {route.length / 1000:.2f} km")
