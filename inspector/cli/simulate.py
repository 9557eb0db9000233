"""``routefuse simulate SCENARIO --out DIR``: a simulated tunnel drive as a bag and a route."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from estimator.errors import ConfigError

NAME = "simulate"
HELP = (
    "Simulate a drive through tunnels (truth, MEMS IMU, wheel speed, GNSS with outages) and "
    "write DIR/SCENARIO.mcap and DIR/SCENARIO.route.geojson; --list shows the scenarios."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", nargs="?", metavar="SCENARIO", help="scenario name")
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
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

    if args.list:
        width = max(len(n) for n in SCENARIOS)
        for name in SCENARIOS:
            print(f"{name:<{width}}  {get_scenario(name).description}")
        return 0
    if not args.scenario:
        raise ConfigError(None, "give a SCENARIO (routefuse simulate --list shows them)")
    if args.out is None:
        raise ConfigError(None, "give the output folder with --out DIR")
    if args.out.exists() and not args.out.is_dir():
        raise ConfigError(args.out, "--out exists and is not a folder")
    if not 0 <= args.seed < 2**32:
        raise ConfigError("--seed", f"{args.seed} is outside [0, 2**32 - 1]")
    for flag, value in (("--imu-rate", args.imu_rate), ("--duration-scale", args.duration_scale)):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(flag, f"{value} is not a positive finite number")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError("--duration", f"{args.duration} is not a positive finite number")
    scenario = get_scenario(args.scenario)
    suffix = {"mcap": ".mcap", "sqlite3": "", "ros1": ".bag"}[args.storage]
    bag = args.out / f"{scenario.name}{suffix}"
    if bag.exists() and not args.force:
        raise ConfigError(bag, "already exists (use --force to overwrite)")
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
    tunnels = ", ".join(f"{a - sim.t0:.1f}-{b - sim.t0:.1f} s" for a, b in sim.tunnels)
    print(
        f"{bag}: {sim.duration_s:.1f} s, {sim.distance_m / 1000:.2f} km, "
        f"IMU {len(sim.imu.t)} at {sim.imu_rate_hz:g} Hz, GNSS {len(sim.gnss.t)} "
        f"({int(sim.gnss.valid.sum())} fixes), wheel {len(sim.wheel.t)}, "
        f"truth {len(sim.truth_fix.t)}; tunnels {tunnels or 'none'}"
    )
    print(f"{route}: {len(sim.route_xy)} vertices, {sim.route().length / 1000:.2f} km")
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0
