"""NF1 planner speed on synthetic 400 x 400 office C-spaces (5 cm cells, 20 m x 20 m).

Each map has room walls every 3.5-6 m with 1 m doors, and furniture blocks; occupied cells
are inflated by 0.4 m with a Euclidean distance transform (what ``cspace.free_cspace`` computes). The robot
stands on a random free cell of the central control zone (N/4 square), as in the robot-centred grid. Goals:
a free cell 5 m away, and a point 30 m away, projected onto the grid border. Prints median and p99 [ms] of
each part (wavefront with early exit as ``plan`` runs it, descent, tightening), of the whole ``plan`` call,
and of a full-grid wave without early exit for reference.

Run: ``/work/venv/bin/python benchmarks/planner.py [--maps 10] [--trials 40]``
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from itertools import pairwise
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from gndreplay.pipeline.cspace import free_cspace
from gndreplay.pipeline.model import FREE, OCCUPIED
from gndreplay.pipeline.nf1 import Nf1Params, descend, nf1_wavefront, plan, tighten

N = 400
CELL_M = 0.05
INFLATE_M = 0.4


def office(rng: np.random.Generator, n: int = N) -> NDArray[np.bool_]:
    """Occupied cells of a random office floor: a room lattice with one door per room side, furniture."""
    occ = np.zeros((n, n), dtype=bool)
    door, thick = round(1.0 / CELL_M), 3

    def lines() -> list[int]:
        out, k = [], int(rng.integers(40, 90))
        while k < n - 40:
            out.append(k)
            k += int(rng.integers(70, 120))
        return out

    rows, cols = lines(), lines()
    for axis, mine, other in ((0, rows, cols), (1, cols, rows)):
        cuts = [0, *other, n]
        for k in mine:
            wall = np.ones(n, dtype=bool)
            for a, b in pairwise(cuts):  # a door in every room side
                lo, hi = a + thick + 2, b - door - 2
                if hi > lo:
                    d = int(rng.integers(lo, hi))
                    wall[d : d + door] = False
            if axis == 0:
                occ[k : k + thick, :] |= wall
            else:
                occ[:, k : k + thick] |= wall[:, None]
    for _ in range(30):  # furniture 0.3-1.2 m
        r, c = rng.integers(5, n - 30, size=2)
        h, w = rng.integers(6, 24, size=2)
        occ[r : r + h, c : c + w] = True
    return occ


def cspace(occ: NDArray[np.bool_]) -> NDArray[np.bool_]:
    cells = np.where(occ, OCCUPIED, FREE).astype(np.uint8)
    return free_cspace(cells, cell_m=CELL_M, inflate_m=INFLATE_M)


def timed(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float]:
    t0 = time.perf_counter_ns()
    out = fn(*args, **kwargs)
    return out, (time.perf_counter_ns() - t0) / 1e6


def start_and_goals(
    free: NDArray[np.bool_], rng: np.random.Generator
) -> tuple[tuple[int, int], tuple[float, float], tuple[float, float]] | None:
    """A free robot cell in the control zone, a free goal 5 m away, a goal 30 m away (outside)."""
    lo, hi = 3 * N // 8, 5 * N // 8
    zone = np.argwhere(free[lo:hi, lo:hi]) + lo
    if len(zone) == 0:
        return None
    s = zone[rng.integers(len(zone))]
    for _ in range(50):
        a = rng.uniform(-math.pi, math.pi)
        g = s + 5.0 / CELL_M * np.array([math.sin(a), math.cos(a)])
        gi = np.floor(g + 0.5).astype(int)
        if 0 <= gi[0] < N and 0 <= gi[1] < N and free[gi[0], gi[1]]:
            a2 = rng.uniform(-math.pi, math.pi)
            far = s + 30.0 / CELL_M * np.array([math.sin(a2), math.cos(a2)])
            return (int(s[0]), int(s[1])), (gi[0] + 0.5, gi[1] + 0.5), (far[0] + 0.5, far[1] + 0.5)
    return None


def run(n_maps: int, trials: int, connectivity: Literal[4, 8], seed: int = 1) -> None:
    rng = np.random.default_rng(seed)
    params = Nf1Params(connectivity=connectivity)
    times: dict[str, dict[str, list[float]]] = {}
    flags: dict[str, dict[str, int]] = {}
    for _ in range(n_maps):
        free = cspace(office(rng))
        for _ in range(trials):
            sg = start_and_goals(free, rng)
            if sg is None:
                continue
            start, near, far = sg
            for name, goal in (("goal 5 m", near), ("goal at border", far)):
                parts = ("wavefront", "descent", "tightening", "plan", "full wave")
                t = times.setdefault(name, {k: [] for k in parts})
                res, ms = timed(plan, free, start, goal, cell_m=CELL_M, params=params)
                t["plan"].append(ms)
                f = flags.setdefault(name, {})
                f[res.flag.name or "NONE"] = f.get(res.flag.name or "NONE", 0) + 1
                if not res.ok or res.n_escape:
                    continue
                g = res.goal_cell
                nf, ms = timed(
                    nf1_wavefront, free, g, connectivity=params.connectivity, robot_rc=start, early_exit=True
                )
                t["wavefront"].append(ms)
                path, ms = timed(descend, nf, free, start)
                t["descent"].append(ms)
                _, ms = timed(tighten, path, free)
                t["tightening"].append(ms)
                _, ms = timed(nf1_wavefront, free, g, connectivity=params.connectivity)
                t["full wave"].append(ms)  # reference: the whole grid, no early exit
    print(f"connectivity {connectivity}, {N}x{N} cells of {CELL_M} m, inflation {INFLATE_M} m")
    print(f"  {'case':<16}{'part':<12}{'n':>6}{'median ms':>12}{'p99 ms':>10}{'max ms':>10}")
    for name, t in times.items():
        for part, v in t.items():
            a = np.asarray(v)
            print(
                f"  {name:<16}{part:<12}{a.size:>6}{np.median(a):>12.3f}"
                f"{np.percentile(a, 99):>10.3f}{a.max():>10.3f}"
            )
        print(f"  {name:<16}flags {flags[name]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=int, default=10)
    ap.add_argument("--trials", type=int, default=40)
    args = ap.parse_args()
    warm = np.ones((N, N), dtype=bool)  # compile (or load the numba cache) outside timing
    warm[N // 2 - 5 : N // 2 + 5, N // 2 + 5] = False
    for c in (4, 8):
        plan(warm, (N // 2, N // 2), (N / 2, N + 100.5), cell_m=CELL_M, params=Nf1Params(connectivity=c))
    run(args.maps, args.trials, 4)
    run(args.maps, args.trials, 8)


if __name__ == "__main__":
    main()
