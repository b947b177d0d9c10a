"""Closed-loop scorecard: every shipped scenario x preset over N seeds, one table.

Per row: success rate, collisions (of which hit-by-mover: the robot was standing still), goals missed
(the stack stopped at the goal it believed, the true axle outside the tolerance: its localisation error),
time-outs, mean time to goal of the successes, minimum clearance over all runs, longest stall (no 0.2 m
and no 45 deg net for that long), trap detections, takeovers of the mode selector (onsets of an active mode
other than the desired teleop / follow one) and the share of ticks local navigation held, and the wall time
split in two: the simulator (world, robot, laser, odometry) per step and the robot side (matcher + stack)
per tick, means over all ticks. Every kernel is compiled and every stage warmed by one short run per preset
before anything is timed; runs are sequential in this process (one core). Latency is the fixed default
(0 s), so the outcomes are reproducible; only the ms columns vary with the machine. The simulated drive's
lag and slip are on (``gndreplay.sim.dynamics``); ``--ideal-dynamics`` runs the exact motion model.

The planner only serves GND: a scenario with another navigation mode (``mode: teleop | follow | local``)
runs once per preset with the preset's own configuration, its planner column "-". ``--no-selector`` runs
with the mode selector disabled (the desired mode's command goes out: the driver or the follower alone);
``--compare-selector`` runs every row both ways, side by side (column "selector": on / off).

    .venv/bin/python benchmarks/scenarios.py [--seeds 20] [--scenarios a,b] [--presets wheelchair,xr4000]
        [--jobs 1] [--out DIR] [--jsonl FILE] [--no-selector | --compare-selector] [--ideal-dynamics]
        [--set robot.vmax_mps=0.5 ...]
    .venv/bin/python benchmarks/scenarios.py --table-from FILE      # the table of the runs so far
    .venv/bin/python benchmarks/scenarios.py --scenarios teleop_into_wall --seeds 5 --compare-selector
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

os.environ.setdefault("MPLBACKEND", "Agg")

from gndreplay.config import CliOverrides, Config, configure
from gndreplay.sim import resolve_scenario, shipped_scenarios, simulate_scenario

# scenario, preset, planner ("-": not GND), selector on, seed, output folder, ideal dynamics, --set pairs
Task = tuple[str, str, str, bool, int, str, bool, tuple[str, ...]]
NO_PLANNER = "-"


def config(preset_name: str, planner: str, selector: bool = True, sets: tuple[str, ...] = ()) -> Config:
    """The preset with the planner chosen ("-": the preset's own), the mode selector on or off and the
    ``--set`` pairs (e.g. ``robot.vmax_mps=0.5``)."""
    chosen = CliOverrides(planner=None if planner == NO_PLANNER else planner, no_selector=not selector,
                          sets=sets)
    return configure(preset_name=preset_name, overrides=chosen)


def planners_of(name: str, planners: list[str]) -> list[str]:
    """The planners a scenario runs with: all of them under GND, only "-" in another navigation mode."""
    return planners if (resolve_scenario(name).mode or "gnd") == "gnd" else [NO_PLANNER]


def one(args: Task) -> dict[str, Any]:
    """One run (in this process or a worker): the outcome and the timings."""
    name, preset_name, planner, selector, seed, out, ideal, sets = args
    t0 = time.perf_counter()
    tag = "" if selector else "-nosel"
    o = simulate_scenario(name, out_dir=Path(out) / f"{name}-{preset_name}-{planner}{tag}-{seed}",
                          cfg=config(preset_name, planner, selector, sets), seed=seed, figures=False,
                          overwrite=True, ideal_dynamics=ideal)
    c = o.collision or {}
    miss = o.goal_missed or {}
    return {
        "miss_m": miss.get("true_distance_m"),
        "outcome": o.outcome, "t": o.end_time_s, "clear": o.min_clearance_m, "stall": o.longest_stall_s,
        "traps": o.trap_count, "hit_by_mover": bool(c.get("hit_by_mover")), "ticks": o.ticks,
        "sim": o.sim_ms_per_step, "stack": o.stack_ms_per_tick, "wall": time.perf_counter() - t0,
        "object": c.get("object"), "takeovers": o.takeovers,
        "local_ticks": o.active_modes.get("local", 0),
    }


def warm(out: str, presets: list[str], planners: list[str], names: list[str]) -> None:
    """Compile and warm every stage once per preset and planner, and per navigation mode of ``names``
    (short runs)."""
    first: dict[str, str] = {}
    for n in [*shipped_scenarios(), *names]:
        first.setdefault(resolve_scenario(n).mode or "gnd", n)
    for mode, name in first.items():
        for p in presets:
            for k in planners if mode == "gnd" else [NO_PLANNER]:
                # one folder per process: the pool's workers warm up at the same time
                folder = Path(out) / f"warm-{os.getpid()}-{mode}-{p}-{k}"
                simulate_scenario(name, out_dir=folder, cfg=config(p, k), seed=0, figures=False,
                                  time_limit_s=2.0, overwrite=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20, help="seeds 0 .. N-1")
    ap.add_argument("--scenarios", default="", help="comma-separated names (default: every shipped one)")
    ap.add_argument("--presets", default="wheelchair,xr4000")
    ap.add_argument("--planners", default="nf1,tunnel", help="planners side by side (nf1, tunnel)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (timings are per process)")
    ap.add_argument("--out", default="", help="keep the run directories here (default: a temporary dir)")
    ap.add_argument("--jsonl", default="", help="append each run's numbers to this file as it finishes")
    ap.add_argument("--table-from", default="", help="print the table from such a file and exit")
    sel = ap.add_mutually_exclusive_group()
    sel.add_argument("--no-selector", action="store_true",
                     help="mode selector off: the desired mode's command goes out (driver / follower alone)")
    sel.add_argument("--compare-selector", action="store_true",
                     help="run every row with the mode selector on and off, side by side")
    ap.add_argument("--ideal-dynamics", action="store_true", help="the exact motion model (no lag, no slip)")
    ap.add_argument("--set", action="append", default=[], dest="sets",
                    help="a configuration override for every run, e.g. robot.vmax_mps=0.5 (repeatable)")
    a = ap.parse_args()
    sets = tuple(a.sets)
    selectors = [True, False] if a.compare_selector else [not a.no_selector]
    names = [s for s in a.scenarios.split(",") if s] or list(shipped_scenarios())
    presets = [p for p in a.presets.split(",") if p]
    planners = [p for p in a.planners.split(",") if p]
    out = a.out or tempfile.mkdtemp(prefix="gndreplay-bench-scenarios-")
    if a.table_from:
        rows = [json.loads(line) for line in Path(a.table_from).read_text().splitlines() if line.strip()]
        tasks = [(r["scenario"], r["preset"], r.get("planner", "nf1"), r.get("selector", True), r["seed"], "",
                  r.get("ideal_dynamics", False), tuple(r.get("sets", ()))) for r in rows]
        table(names, presets, [*planners, NO_PLANNER], [True, False], tasks, rows,
              f"from {a.table_from}: {len(rows)} runs")
        return
    warm(out, presets, planners, names)
    # seed-major order: stopped early, the runs so far cover every row equally
    tasks = [(n, p, k, on, s, out, a.ideal_dynamics, sets) for s in range(a.seeds) for n in names
             for p in presets for k in planners_of(n, planners) for on in selectors]
    t0 = time.perf_counter()
    log = open(a.jsonl, "a") if a.jsonl else None  # noqa: SIM115
    results: list[dict[str, Any]] = []

    def done(t: Task, r: dict[str, Any]) -> None:
        """Keep a finished run, append it to --jsonl and show progress (in task order, with any --jobs)."""
        results.append(r)
        if log is not None:
            row = {"scenario": t[0], "preset": t[1], "planner": t[2], "selector": t[3], "seed": t[4],
                   "ideal_dynamics": t[6], "sets": list(t[7]), **r}
            log.write(json.dumps(row) + "\n")
            log.flush()
        print(f"\r{len(results)}/{len(tasks)} {t[0]} {t[1]} {t[2]} {'' if t[3] else 'no selector '}"
              f"seed {t[4]}: {r['outcome']}    ", end="", file=sys.stderr, flush=True)

    if a.jobs > 1:
        with ProcessPoolExecutor(a.jobs, initializer=warm, initargs=(out, presets, planners, names)) as ex:
            for t, r in zip(tasks, ex.map(one, tasks), strict=True):
                done(t, r)
    else:
        for t in tasks:
            done(t, one(t))
    print(file=sys.stderr)
    wall = time.perf_counter() - t0
    table(names, presets, [*planners, NO_PLANNER], selectors, tasks, results,
          f"{a.seeds} seeds per row, latency 0 s, {'ideal dynamics' if a.ideal_dynamics else 'dynamics on'}, "
          f"{' '.join(sets) + ', ' if sets else ''}"
          f"{a.jobs} process(es), total wall {wall:.0f} s")


def table(names: list[str], presets: list[str], planners: list[str], selectors: list[bool],
          tasks: list[Task], results: list[dict[str, Any]], head: str) -> None:
    """Print the Markdown table (one row per scenario x preset x planner x selector, the planners and the
    selector settings side by side). "goal missed": runs the stack ended at the goal it believed, the true
    axle outside the tolerance (the largest such distance in brackets)."""
    print(head + "\n")
    print("| scenario | preset | planner | selector | runs | success | collisions (hit by mover) "
          "| goal missed (max m) | time-outs | mean time to goal s | min clearance m | longest stall s "
          "| traps | takeovers | local ticks | sim ms/step | stack ms/tick |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n, p, k, on in ((n, p, k, on) for n in names for p in presets for k in planners for on in selectors):
        rows = [r for (tn, tp, tk, ts, *_), r in zip(tasks, results, strict=True)
                if (tn, tp, tk, ts) == (n, p, k, on)]
        if not rows:
            continue
        ok = [r for r in rows if r["outcome"] == "success"]
        col = [r for r in rows if r["outcome"] == "collision"]
        miss = [r.get("miss_m") or math.nan for r in rows if r["outcome"] == "goal_missed"]
        missed = f"{len(miss)} ({max(miss):.2f})" if miss else "0"
        clear = [r["clear"] for r in rows if r["clear"] is not None]
        ticks = sum(r["ticks"] for r in rows)
        sim = sum(r["sim"] * r["ticks"] for r in rows) / max(ticks, 1)
        stack = sum(r["stack"] * r["ticks"] for r in rows) / max(ticks, 1)
        mean_t = f"{statistics.mean(r['t'] for r in ok):.1f}" if ok else "-"
        print(f"| {n} | {p} | {k} | {'on' if on else 'off'} | {len(rows)} "
              f"| {100 * len(ok) / len(rows):.0f} % | {len(col)} ({sum(r['hit_by_mover'] for r in col)}) "
              f"| {missed} | "
              f"{sum(r['outcome'] == 'timeout' for r in rows)} | {mean_t} | "
              f"{min(clear) if clear else math.nan:.3f} | {max(r['stall'] for r in rows):.1f} | "
              f"{sum(r['traps'] for r in rows)} | {sum(r.get('takeovers', 0) for r in rows)} | "
              f"{100 * sum(r.get('local_ticks', 0) for r in rows) / max(ticks, 1):.0f} % | "
              f"{sim:.2f} | {stack:.2f} |")


if __name__ == "__main__":
    main()
