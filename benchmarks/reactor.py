"""ND+ reactor speed: one ``nd_step`` on grid-like obstacle points around the robot.

Target: < 1 ms median per step with ~1000-3000 obstacle points (the wheelchair paper: ND+ runs at more than
1000 Hz). Obstacles are the centres of 5 cm cells, as the stack passes occupied grid cells within 4 m.
Scenes: an office room with furniture and a door, a corridor with side doors, random clutter, and a fence
of posts with gaps narrower than the robot (every discontinuity is tested and fails: the search's worst case).
Each scene runs for the XR4000 (circle) and the wheelchair (rectangle) and many goal directions.

Run: ``python benchmarks/reactor.py [--steps N]``. Prints median and p99 in microseconds.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from gndreplay.pipeline.nd import NdParams, nd_step
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig

F64 = NDArray[np.float64]
CELL_M = 0.05
RADIUS_M = 4.0


Mask = Callable[[F64, F64], NDArray[np.bool_]]


def cells(mask_fn: Mask) -> F64:
    """Centres of the 5 cm cells within RADIUS_M for which ``mask_fn(x, y)`` is True, robot at the origin."""
    ax = (np.arange(-int(RADIUS_M / CELL_M), int(RADIUS_M / CELL_M)) + 0.5) * CELL_M
    x, y = np.meshgrid(ax, ax)
    keep = mask_fn(x, y) & (np.hypot(x, y) <= RADIUS_M)
    return np.column_stack([x[keep], y[keep]])


def office(rng: np.random.Generator) -> F64:
    """8 x 6 m room, walls 3 cells thick, a 1 m door, eight boxes of furniture."""
    def mask(x: F64, y: F64) -> NDArray[np.bool_]:
        walls = ((np.abs(x - 4.0) < 0.08) | (np.abs(x + 4.0) < 0.08)) & (np.abs(y) < 3.0)
        walls |= ((np.abs(y - 3.0) < 0.08) | (np.abs(y + 3.0) < 0.08)) & (np.abs(x) < 4.0)
        walls &= ~((np.abs(y - 3.0) < 0.1) & (np.abs(x - 1.5) < 0.5))  # the door
        for cx, cy in rng.uniform([-3.5, -2.5], [3.5, 2.5], (8, 2)):
            if math.hypot(cx, cy) > 1.3:
                walls |= (np.abs(x - cx) < 0.3) & (np.abs(y - cy) < 0.2)
        return walls
    return cells(mask)


def corridor() -> F64:
    """A 1.6 m corridor, walls 4 cells thick, with 1 m side doors."""
    def mask(x: F64, y: F64) -> NDArray[np.bool_]:
        w = (np.abs(np.abs(y) - 0.9) < 0.1)
        for dx in (-2.5, 1.5, 3.0):
            w &= ~((np.abs(x - dx) < 0.5) & (y > 0))
        return w
    return cells(mask)


def clutter(rng: np.random.Generator) -> F64:
    """Random blobs of occupied cells (people, chairs, table legs) outside a 0.8 m disc."""
    centres = rng.uniform(-3.8, 3.8, (60, 2))
    centres = centres[np.hypot(centres[:, 0], centres[:, 1]) > 1.2]
    def mask(x: F64, y: F64) -> NDArray[np.bool_]:
        m = np.zeros(x.shape, dtype=bool)
        for cx, cy in centres:
            m |= np.hypot(x - cx, y - cy) < 0.18
        return m
    return cells(mask)


def fence() -> F64:
    """Posts on a 2 m circle, 0.3 m gaps (narrower than both robots): no region, every gap tested."""
    def mask(x: F64, y: F64) -> NDArray[np.bool_]:
        r, a = np.hypot(x, y), np.arctan2(y, x)
        ring = np.abs(r - 2.0) < 0.1
        period = 2.0 * math.pi / 20
        return ring & (np.mod(a, period) * 2.0 > 0.3)
    return cells(mask)


def time_scene(name: str, pts: F64, robot: RobotConfig, label: str, steps: int,
               rng: np.random.Generator) -> list[float]:
    params = NdParams()
    goals = rng.uniform(-math.pi, math.pi, steps)
    nd_step(pts, (3.0, 0.0), robot, params)  # warm the per-robot geometry cache
    us: list[float] = []
    situations: Counter[str] = Counter()
    for a in goals:
        g = (5.0 * math.cos(a), 5.0 * math.sin(a))
        t0 = time.perf_counter_ns()
        res = nd_step(pts, g, robot, params)
        us.append((time.perf_counter_ns() - t0) / 1e3)
        situations[res.situation.value] += 1
    arr = np.asarray(us)
    top = ", ".join(f"{k} {v}" for k, v in situations.most_common(4))
    print(f"  {name:<9s} {label:<10s} {pts.shape[0]:5d} pts   median {np.median(arr):7.1f} us   "
          f"p99 {np.percentile(arr, 99):7.1f} us   max {arr.max():7.1f} us   [{top}]")
    return us


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=400, help="steps per scene and robot (default 400)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    scenes = {"office": office(rng), "corridor": corridor(), "clutter": clutter(rng), "fence": fence()}
    print(f"nd_step, {args.steps} goal directions per scene; obstacles: 5 cm cells within {RADIUS_M} m")
    every: list[float] = []
    for name, pts in scenes.items():
        for robot, label in ((XR4000_ROBOT, "xr4000"), (WHEELCHAIR_ROBOT, "wheelchair")):
            every += time_scene(name, pts, robot, label, args.steps, rng)
    arr = np.asarray(every)
    print(f"  all scenes: median {np.median(arr):.1f} us, p99 {np.percentile(arr, 99):.1f} us "
          f"(target: median < 1000 us)")


if __name__ == "__main__":
    main()
