"""Planner speed: NF1 and the tunnel planner side by side, on dev-log ticks and on synthetic offices.

Dev logs (``--log``, repeatable; default: the bundled sample log and ACES from ../shared/datasets when
present): the wheelchair stack (400 x 400 grid of 5 cm, IDC-corrected poses, goal 5 m ahead along the
corrected trajectory, as ``gndreplay run``) runs over the first ``--ticks`` ticks; on every tick both planners
plan on the same grid, robot cell and goal, each through its ``Planner.plan`` (C-space included), one after
the other on one core, ``--repeat`` times (the fastest counts: scheduling noise on a shared machine
otherwise dominates the p99 of both). Prints median / p99 / max [ms] per planner, how often each found a
way, the course difference where both did, and the tunnel planner's nodes expanded.

Synthetic offices (``--maps``, 0 to skip): each map has room walls every 3.5-6 m with 1 m doors, and
furniture blocks; occupied cells are inflated by 0.4 m (what ``cspace.free_cspace`` computes). The robot
stands on a random free cell of the central control zone (N/4 square), as in the robot-centred grid. Goals:
a free cell 5 m away, and a point 30 m away, outside the grid (NF1 plans to the best reachable free border
cell, ``Nf1Params.frontier_goal``; the tunnel planner to the goal's projection onto the border). Prints
median and p99 [ms] of each NF1 part (wavefront with early exit as ``plan`` runs it, descent, tightening),
of the whole ``plan`` call on the C-space computed beforehand, of a full-grid wave without early exit for
reference, and, side by side, of the two planners as the stack calls them, the C-space included
("nf1+cspace", "tunnel plan"), each the fastest of ``--repeat`` runs (as on the dev logs), and how often
the tunnel planner's node search failed and its complete fallback (NF1 on its C-space) answered. Use
``taskset -c 0`` for one core.

``--clock thread`` times with the thread's CPU clock instead of the wall clock: on a loaded shared machine
the wall clock's p99 is mostly other processes' time slices.

Run: ``.venv/bin/python benchmarks/planner.py [--log LOG ...] [--ticks 600] [--repeat 3] [--maps 10]
[--trials 40] [--clock wall|thread]``
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import time
from collections.abc import Callable
from itertools import pairwise
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from gndreplay.config import PRESETS
from gndreplay.geometry import wrap_angle
from gndreplay.io import read_ticks
from gndreplay.pipeline.cspace import free_cspace
from gndreplay.pipeline.model import FREE, OCCUPIED
from gndreplay.pipeline.nf1 import Nf1Params, descend, nf1_wavefront, plan, tighten
from gndreplay.pipeline.planner import Planner
from gndreplay.pipeline.stack import NavigationStack, make_planner, warm_up
from gndreplay.pipeline.tunnel import TunnelParams, tunnel_plan, warm_up_planners
from gndreplay.replay import RunOptions, assign_goals, corrected_stream

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


# the clock of every timing: wall (perf_counter) by default, or this thread's CPU time (``--clock thread``),
# which leaves out the time other processes hold the core (a shared machine's load otherwise sets the p99)
CLOCK: Callable[[], int] = time.perf_counter_ns


def timed(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float]:
    t0 = CLOCK()
    out = fn(*args, **kwargs)
    return out, (CLOCK() - t0) / 1e6


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


def nf1_with_cspace(
    cells: NDArray[np.uint8], start: tuple[int, int], goal: tuple[float, float], params: Nf1Params
) -> Any:
    """NF1 as ``Nf1Planner.plan`` runs it: the C-space of the grid, then the plan."""
    free = free_cspace(cells, cell_m=CELL_M, inflate_m=INFLATE_M)
    return plan(free, start, goal, cell_m=CELL_M, params=params)


def run(n_maps: int, trials: int, connectivity: Literal[4, 8], repeat: int, seed: int = 1) -> None:
    rng = np.random.default_rng(seed)
    params = Nf1Params(connectivity=connectivity)
    times: dict[str, dict[str, list[float]]] = {}
    flags: dict[str, dict[str, int]] = {}
    for _ in range(n_maps):
        occ = office(rng)
        free = cspace(occ)
        cells = np.where(occ, OCCUPIED, FREE).astype(np.uint8)
        for _ in range(trials):
            sg = start_and_goals(free, rng)
            if sg is None:
                continue
            start, near, far = sg
            for name, goal in (("goal 5 m", near), ("goal at border", far)):
                parts = ("wavefront", "descent", "tightening", "plan", "full wave", "nf1+cspace",
                         "tunnel plan")
                t = times.setdefault(name, {k: [] for k in parts})
                res, ms = timed(plan, free, start, goal, cell_m=CELL_M, params=params)
                t["plan"].append(ms)
                # the two planners as the stack calls them, C-space included, fastest of ``repeat`` runs
                t["nf1+cspace"].append(min(timed(nf1_with_cspace, cells, start, goal, params)[1]
                                           for _ in range(repeat)))
                runs = [timed(tunnel_plan, cells, start, goal, cell_m=CELL_M, radius_m=INFLATE_M)
                        for _ in range(repeat)]
                tun = runs[0][0]
                t["tunnel plan"].append(min(ms for _, ms in runs))
                ft = flags.setdefault(name + " tunnel", {})
                ft[tun.flag.name or "NONE"] = ft.get(tun.flag.name or "NONE", 0) + 1
                ft["fallback"] = ft.get("fallback", 0) + int(tun.fallback)
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
    print(f"synthetic offices, connectivity {connectivity}, {N}x{N} cells of {CELL_M} m, "
          f"inflation {INFLATE_M} m (tunnel: the same radius)")
    print(f"  {'case':<16}{'part':<12}{'n':>6}{'median ms':>12}{'p99 ms':>10}{'max ms':>10}")
    for name, t in times.items():
        for part, v in t.items():
            a = np.asarray(v)
            print(
                f"  {name:<16}{part:<12}{a.size:>6}{np.median(a):>12.3f}"
                f"{np.percentile(a, 99):>10.3f}{a.max():>10.3f}"
            )
        print(f"  {name:<16}flags {flags[name]}, tunnel {flags[name + ' tunnel']}")


def _stats(v: list[float]) -> str:
    a = np.asarray(v)
    return f"{np.median(a):>9.3f}{np.percentile(a, 99):>9.3f}{a.max():>9.3f}"


def dev_log(log: Path, n_ticks: int, repeat: int) -> None:
    """Both planners on the grids of the first ``n_ticks`` ticks of ``log`` (wheelchair preset); each plan
    runs ``repeat`` times per tick and the fastest counts (the machine's scheduling noise is not the
    planner's cost)."""
    cfg = PRESETS["wheelchair"]
    params = cfg.stack_params()
    tunnel = dataclasses.replace(params, planner=dataclasses.replace(params.planner, kind="tunnel"))
    planners: dict[str, Planner] = {"nf1": make_planner(params), "tunnel": make_planner(tunnel)}
    warm_up(params)
    warm_up_planners(params.planner.tunnel)
    stack = NavigationStack(params)
    ms: dict[str, list[float]] = {k: [] for k in planners}
    ok = dict.fromkeys(planners, 0)
    nodes: list[float] = []
    course_diff: list[float] = []
    length_ratio: list[float] = []
    ticks = itertools.islice(read_ticks(log), n_ticks)
    n = 0
    for m, goal in assign_goals(corrected_stream(ticks, cfg, RunOptions()), RunOptions()):
        stack.step(m.tick.scan, m.pose, goal, odom=m.tick.odom, cmd=m.tick.cmd)
        start = stack.grid.robot_cell(m.pose)
        goal_rc = stack.grid.world_to_cell_float(np.asarray([goal]))[0]
        res = {}
        for name, planner in planners.items():
            runs = [timed(planner.plan, stack.grid.cells, start, goal_rc) for _ in range(repeat)]
            res[name] = runs[0][0]
            ms[name].append(min(t for _, t in runs))
            ok[name] += res[name].ok
        nodes.append(res["tunnel"].nodes_expanded)
        if res["nf1"].ok and res["tunnel"].ok:
            course_diff.append(abs(float(wrap_angle(res["nf1"].direction_rad - res["tunnel"].direction_rad))))
            if res["nf1"].length_m > 0:
                length_ratio.append(res["tunnel"].length_m / res["nf1"].length_m)
        n += 1
    print(f"{log.name}: {n} ticks, {N}x{N} grid, wheelchair preset, fastest of {repeat} runs per tick")
    print(f"  {'planner':<10}{'median':>9}{'p99':>9}{'max':>9}  ms   found a way")
    for name in planners:
        print(f"  {name:<10}{_stats(ms[name])}       {ok[name]}/{n}")
    print(f"  tunnel / nf1 median time: {np.median(ms['tunnel']) / np.median(ms['nf1']):.2f}")
    print(f"  tunnel nodes expanded: median {np.median(nodes):.0f}, p99 {np.percentile(nodes, 99):.0f}, "
          f"max {max(nodes):.0f}")
    if course_diff:
        d = np.degrees(course_diff)
        print(f"  course difference where both found a way [deg]: median {np.median(d):.1f}, "
              f"p90 {np.percentile(d, 90):.1f}; tunnel/nf1 length median {np.median(length_ratio):.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", type=Path, action="append", help="dev log (repeatable)")
    ap.add_argument("--ticks", type=int, default=600, help="ticks per dev log (0: skip the dev logs)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per tick and planner; the fastest counts")
    ap.add_argument("--maps", type=int, default=10, help="synthetic office maps (0: skip)")
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--clock", choices=("wall", "thread"), default="wall",
                    help="wall time, or this thread's CPU time (robust to other processes on the core)")
    args = ap.parse_args()
    global CLOCK
    CLOCK = time.thread_time_ns if args.clock == "thread" else time.perf_counter_ns
    print(f"clock: {args.clock}")
    root = Path(__file__).resolve().parents[1]
    defaults = (root / "sample_logs" / "office.clf.bz2", root.parent / "shared/datasets/carmen/aces.clf.bz2")
    logs = args.log or [p for p in defaults if p.exists()]
    for log in logs if args.ticks > 0 else []:
        dev_log(log, args.ticks, max(args.repeat, 1))
    if args.maps <= 0:
        return
    warm = np.ones((N, N), dtype=bool)  # compile (or load the numba cache) outside timing
    warm[N // 2 - 5 : N // 2 + 5, N // 2 + 5] = False
    for c in (4, 8):
        plan(warm, (N // 2, N // 2), (N / 2, N + 100.5), cell_m=CELL_M, params=Nf1Params(connectivity=c))
    warm_up_planners(TunnelParams())
    run(args.maps, args.trials, 4, max(args.repeat, 1))
    run(args.maps, args.trials, 8, max(args.repeat, 1))


if __name__ == "__main__":
    main()
