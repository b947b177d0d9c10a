#!/usr/bin/env python
"""Write a long synthetic CARMEN log that covers a large area (default 1 km x 1 km): the memory benchmark's
input (docs/benchmarks.md, benchmarks/memory.py).

The world is a city grid: square blocks (buildings) between streets every ``--pitch`` metres, each facade
lined with pillars at random spacing so a scan matcher has features along a street. The robot drives a
lawn-mower route: up the first north-south street, along the cross street at the end, down the next one,
and so on over every street, stopping and turning in place at each corner. Laser scans are ray-cast with
the simulator's kernel (``gndreplay.sim.world.cast_rays``, only the segments within laser range of the
robot), with the simulator's range noise, dropouts and drifting wheel odometry; the simulator's CARMEN
writer writes them. Deterministic: the same arguments give a byte-identical log.

Defaults: 1 km x 1 km, streets every 100 m (11 north-south streets), 2 m/s, 5 scans/s of 361 beams over
180 deg (8 m range): about 12 km and 1 h 45 min of log, 31,000 scans, 75 MB as .clf.gz; written in about
three minutes on one core.

Usage: python scripts/make_long_log.py [OUT] [--size 1000] [--pitch 100] [--street 12] [--speed 2.0]
    [--scan-hz 5] [--seed 0] [--overwrite]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from gndreplay.errors import GndReplayError
from gndreplay.geometry import compose
from gndreplay.io import write_carmen
from gndreplay.robot import WHEELCHAIR_ROBOT
from gndreplay.sim.scenario import (
    DEFAULT_T0_NS,
    RECORD_STEP,
    DriveParams,
    Scenario,
    SimulatedRun,
    carmen_params,
    check_log_output,
    iter_odometry,
    run_scenario,
)
from gndreplay.sim.world import LaserModel, World, add_laser_noise, box, cast_rays, quantize
from gndreplay.types import NS_PER_S, Command, Pose2D, Scan, Tick

F64 = NDArray[np.float64]
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "long" / "city_1km.clf.gz"
DT_S = 0.05  # control period of the route follower = ground-truth rate
LASER_RANGE_M = 20.0  # a SICK LMS in cm mode: sees far enough along a street for the facade pillars


def city_segments(size_m: float, pitch_m: float, street_m: float, rng: np.random.Generator) -> F64:
    """Blocks between the streets x, y = 0, pitch, ..., size (one ring of blocks beyond the outer streets,
    so every street has facades on both sides), each facade lined with 0.6 m pillars 3-10 m apart."""
    n = round(size_m / pitch_m)
    side = pitch_m - street_m
    parts: list[F64] = []
    for i in range(-1, n + 1):
        for j in range(-1, n + 1):
            x0, y0 = i * pitch_m + street_m / 2, j * pitch_m + street_m / 2  # the block's south-west corner
            parts.append(box(x0 + side / 2, y0 + side / 2, side, side))
            for k in range(4):  # the four facades: pillars standing 0.3 m off the wall
                along = np.cumsum(rng.uniform(3.0, 10.0, size=int(side / 3.0) + 1))
                along = along[along < side - 1.0]
                off = 0.6
                if k == 0:
                    cx, cy = x0 + along, np.full(along.size, y0 - off)
                elif k == 1:
                    cx, cy = x0 + along, np.full(along.size, y0 + side + off)
                elif k == 2:
                    cx, cy = np.full(along.size, x0 - off), y0 + along
                else:
                    cx, cy = np.full(along.size, x0 + side + off), y0 + along
                parts.extend(box(float(a), float(b), 0.6, 0.6) for a, b in zip(cx, cy, strict=True))
    return np.vstack(parts)


def lawnmower_route(size_m: float, pitch_m: float) -> tuple[F64, ...]:
    """Straight legs along the street centre lines: up x = 0, east along the end, down x = pitch, ..."""
    n = round(size_m / pitch_m)
    legs: list[F64] = []
    for i in range(n + 1):
        x = i * pitch_m
        y_from, y_to = (0.0, size_m) if i % 2 == 0 else (size_m, 0.0)
        legs.append(np.array([[x, y_from], [x, y_to]]))
        if i < n:
            legs.append(np.array([[x, y_to], [x + pitch_m, y_to]]))
    return tuple(legs)


def city_scenario(size_m: float, pitch_m: float, street_m: float, speed_mps: float, scan_hz: float,
                  seed: int) -> Scenario:
    """The city world, route, laser and drive of the long log."""
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2])  # the run uses spawn(2)
    route = lawnmower_route(size_m, pitch_m)
    length = sum(float(np.hypot(*(leg[1] - leg[0]))) for leg in route)
    drive = DriveParams(vmax_mps=speed_mps, wmax_radps=1.0, accel_mps2=0.5, ang_accel_radps2=1.0,
                        lookahead_m=1.5, dt_s=DT_S, max_duration_s=3.0 * length / speed_mps + 3600.0)
    scan_period_ns = round(NS_PER_S / scan_hz)
    if scan_period_ns % round(DT_S * NS_PER_S):
        raise SystemExit(f"--scan-hz {scan_hz}: the scan period must be a multiple of {DT_S} s")
    return Scenario(
        name=f"city_{size_m:g}m",
        description=__doc__ or "",
        world=World(city_segments(size_m, pitch_m, street_m, rng), name="city"),
        route=route,
        start=Pose2D(0.0, 0.0, math.pi / 2),
        robot=WHEELCHAIR_ROBOT,
        laser=LaserModel(max_range_m=LASER_RANGE_M),
        drive=drive,
        scan_period_ns=scan_period_ns,
        odom_period_ns=round(DT_S * NS_PER_S),
    )


def culled_ticks(run: SimulatedRun, t0_ns: int = DEFAULT_T0_NS) -> Iterator[Tick]:
    """``sim.scenario.iter_ticks`` over a large static world: each scan is cast against the segments whose
    bounding box lies within laser range of the laser only (the same ranges, far fewer segments)."""
    scn = run.scenario
    every = scn.scan_period_ns // int(run.t_ns[1] - run.t_ns[0])
    rng = run.laser_rng()
    angles = scn.laser.angles()
    sensor = scn.sensor_pose.as_array()
    segs = scn.world.segments
    lo = np.minimum(segs[:, :2], segs[:, 2:])
    hi = np.maximum(segs[:, :2], segs[:, 2:])
    reach = scn.laser.max_range_m + 0.01
    truth = quantize(run.truth, RECORD_STEP)
    odom = quantize(run.odom, RECORD_STEP)
    cmd = quantize(run.cmd, RECORD_STEP)
    for index, k in enumerate(range(0, len(run.t_ns), every)):
        t_ns = t0_ns + int(run.t_ns[k])
        laser = compose(run.truth[k], sensor)
        near = np.all((lo <= laser[:2] + reach) & (hi >= laser[:2] - reach), axis=1)
        exact = cast_rays(laser[:2], angles + laser[2], segs[near], max_range_m=scn.laser.max_range_m)
        ranges = add_laser_noise(exact, scn.laser, rng)
        scan = Scan(t_ns, ranges, angles, scn.laser.max_range_m, scn.laser.min_range_m, scn.sensor_pose)
        yield Tick(index=index, t_ns=t_ns, scan=scan, odom=Pose2D.from_array(odom[k]),
                   cmd=Command(t_ns, float(cmd[k, 0]), float(cmd[k, 1])), truth=Pose2D.from_array(truth[k]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, default=DEFAULT_OUT,
                        help=f"the log to write, .clf / .log, optionally .gz / .bz2 (default {DEFAULT_OUT})")
    parser.add_argument("--size", type=float, default=1000.0, help="side of the square covered [m]")
    parser.add_argument("--pitch", type=float, default=100.0, help="distance between streets [m]")
    parser.add_argument("--street", type=float, default=12.0, help="street width, facade to facade [m]")
    parser.add_argument("--speed", type=float, default=2.0, help="top speed [m/s]")
    parser.add_argument("--scan-hz", type=float, default=5.0, help="scans per second (5, 10 or 20)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (world, odometry, laser noise)")
    parser.add_argument("--overwrite", action="store_true", help="replace a log gndreplay wrote there")
    args = parser.parse_args()
    if not (args.size > 0 and 0 < args.pitch <= args.size and 2.0 < args.street < args.pitch - 2.0
            and args.speed > 0 and args.scan_hz > 0):
        parser.error("need size >= pitch > 0, 2 < street < pitch - 2, speed > 0, scan-hz > 0")
    start = time.perf_counter()
    try:
        check_log_output(args.out, overwrite=args.overwrite)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        scn = city_scenario(args.size, args.pitch, args.street, args.speed, args.scan_hz, args.seed)
        run = run_scenario(scn, seed=args.seed)
        write_carmen(args.out, culled_ticks(run), odometry=iter_odometry(run),
                     params=carmen_params(scn, seed=args.seed))
    except GndReplayError as err:
        print(f"make_long_log: {err}", file=sys.stderr)
        return 2
    travel = float(np.hypot(*np.diff(run.truth[:, :2], axis=0).T).sum())
    scans = -(-len(run.t_ns) // (scn.scan_period_ns // round(DT_S * NS_PER_S)))
    print(f"{args.out}  {args.out.stat().st_size / 2**20:.1f} MiB  {scans} scans  "
          f"{run.t_ns[-1] / NS_PER_S:.0f} s of log  {travel / 1000:.2f} km  "
          f"{len(scn.world.segments)} segments  written in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
