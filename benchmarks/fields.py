"""Random obstacle fields: generated fields x seeds for one preset at one top speed, dynamics on.

The fields are those of ``gndreplay scenario generate`` (``gndreplay.sim.fields``: a 4.5 m corridor of
clustered cylinders, the goal 10 m ahead, each passable by the preset's inscribed circle), field seed
``--field-seed``. Each runs with the preset, ``robot.vmax_mps`` set to ``--vmax``, the simulated drive's
first-order response and slip (``--ideal-dynamics`` for the exact model), latency 0, once per seed. Prints
one line per run and the totals: success, collisions, time-outs, goals missed, the mean challenge metric
(success * OT / clip(T, 2 OT, 8 OT), OT the optimal path at 2 m/s; a failure counts 0), the mean time to
goal of the successes and the mean optimal path. Runs are sequential in this process unless ``--jobs``.

    .venv/bin/python benchmarks/fields.py --fields 10 --seeds 1 --preset xr4000 --vmax 0.5 --jobs 1
    .venv/bin/python benchmarks/fields.py --fields 50 --seeds 3 --preset xr4000 --vmax 2.0 --jobs 2
    .venv/bin/python benchmarks/fields.py --fields 50 --preset compact --set planner.avoid_cost=1 --jobs 2
"""

from __future__ import annotations

import argparse
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
from gndreplay.sim import load_scenario, simulate_scenario
from gndreplay.sim.fields import generate_fields

# field file, preset, vmax, seed, ideal dynamics, output folder, --set pairs
Task = tuple[str, str, float, int, bool, str, tuple[str, ...]]


def config(preset_name: str, vmax: float, sets: tuple[str, ...] = ()) -> Config:
    """The preset with its top speed set, and the ``--set`` pairs."""
    return configure(preset_name=preset_name,
                     overrides=CliOverrides(sets=(f"robot.vmax_mps={vmax!r}", *sets)))


def one(task: Task) -> dict[str, Any]:
    """One run: outcome, time, challenge metric, optimal path."""
    path, preset_name, vmax, seed, ideal, out, sets = task
    t0 = time.perf_counter()
    spec = load_scenario(Path(path))
    o = simulate_scenario(spec, out_dir=Path(out) / f"{spec.name}-{seed}",
                          cfg=config(preset_name, vmax, sets), seed=seed, figures=False, overwrite=True,
                          ideal_dynamics=ideal)
    return {"field": spec.name, "seed": seed, "outcome": o.outcome, "t": o.time_to_goal_s,
            "metric": o.challenge_metric, "optimal": o.optimal_path_m, "clear": o.min_clearance_m,
            "passage": o.narrowest_passage_m,
            "wall": time.perf_counter() - t0}


def warm(out: str, path: str, preset_name: str, vmax: float, sets: tuple[str, ...]) -> None:
    """Compile every kernel with one short run (not timed)."""
    simulate_scenario(load_scenario(Path(path)), out_dir=Path(out) / f"warm-{os.getpid()}",
                      cfg=config(preset_name, vmax, sets), seed=0, figures=False, time_limit_s=2.0,
                      overwrite=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fields", type=int, default=10, help="fields 0 .. N-1")
    ap.add_argument("--field-seed", type=int, default=0, help="seed of the fields")
    ap.add_argument("--seeds", type=int, default=1, help="run seeds 0 .. N-1 per field")
    ap.add_argument("--preset", default="xr4000")
    ap.add_argument("--vmax", type=float, default=0.5, help="robot.vmax_mps [m/s]")
    ap.add_argument("--ideal-dynamics", action="store_true", help="the exact motion model (no lag, no slip)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--set", action="append", default=[], dest="sets",
                    help="a configuration override for every run, section.key=value (repeatable)")
    ap.add_argument("--out", default="", help="keep the fields and runs here (default: a temporary dir)")
    a = ap.parse_args()
    out = a.out or tempfile.mkdtemp(prefix="gndreplay-bench-fields-")
    sets = tuple(a.sets)
    cfg = config(a.preset, a.vmax, sets)
    folder, files = generate_fields(Path(out) / "fields", count=a.fields, seed=a.field_seed, robot=cfg.robot,
                                    preset_name=cfg.preset, overwrite=True)
    runs = str(Path(out) / "runs")
    tasks: list[Task] = [(str(f), a.preset, a.vmax, s, a.ideal_dynamics, runs, sets) for s in range(a.seeds)
                         for f in files]
    warm(runs, str(files[0]), a.preset, a.vmax, sets)
    t0 = time.perf_counter()
    results: list[dict[str, Any]] = []
    if a.jobs > 1:
        first = (runs, str(files[0]), a.preset, a.vmax, sets)
        with ProcessPoolExecutor(a.jobs, initializer=warm, initargs=first) as ex:
            results = list(ex.map(one, tasks))
    else:
        for k, t in enumerate(tasks):
            results.append(one(t))
            print(f"\r{k + 1}/{len(tasks)}", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
    wall = time.perf_counter() - t0
    print(f"{a.fields} fields (seed {a.field_seed}) x {a.seeds} seeds, {a.preset} at vmax {a.vmax:g} m/s, "
          f"{'ideal dynamics' if a.ideal_dynamics else 'dynamics on'}, latency 0 s, {a.jobs} process(es), "
          f"{'set ' + ' '.join(sets) + ', ' if sets else ''}"
          f"wall {wall:.0f} s; fields in {folder}\n")
    print("| field | seed | outcome | time s | optimal m | challenge metric | min clearance m "
          "| narrowest passage m |")
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        print(f"| {r['field']} | {r['seed']} | {r['outcome']} | {_f(r['t'], 1)} | {_f(r['optimal'], 2)} "
              f"| {_f(r['metric'], 3)} | {_f(r['clear'], 3)} | {_f(r['passage'], 2)} |")
    n = len(results)
    count = {k: sum(r["outcome"] == k for r in results) for k in ("success", "collision", "timeout",
                                                                  "goal_missed")}
    metrics = [r["metric"] for r in results if r["metric"] is not None]
    times = [r["t"] for r in results if r["outcome"] == "success"]
    print(f"\nruns {n}: success {count['success']} ({100 * count['success'] / n:.0f} %), collisions "
          f"{count['collision']}, time-outs {count['timeout']}, goals missed {count['goal_missed']}; "
          f"mean challenge metric {_f(statistics.fmean(metrics) if metrics else None, 4)}; mean time to goal "
          f"{_f(statistics.fmean(times) if times else None, 1)} s; mean optimal path "
          f"{_f(statistics.fmean(r['optimal'] for r in results if r['optimal']), 2)} m")

    _by_passage(results, 2.0 * cfg.robot.inner_radius_m)  # a rectangle's width, a circle's diameter


def _by_passage(results: list[dict[str, Any]], width_m: float) -> None:
    """Outcomes per band of the field's narrowest passage less the robot's width (the play it leaves)."""
    bands = [(-math.inf, 0.1), (0.1, 0.2), (0.2, math.inf)]  # a passage may measure a little below the width
    print(f"\n| play: narrowest passage - robot width ({width_m:g} m) | runs | success | time-outs "
          f"| goals missed | collisions |")
    print("|---|---|---|---|---|---|")
    for lo, hi in bands:
        rows = [r for r in results if r["passage"] is not None and lo <= r["passage"] - width_m < hi]
        n = {k: sum(r["outcome"] == k for r in rows)
             for k in ("success", "timeout", "goal_missed", "collision")}
        name = (f"{lo:g} m or more" if not math.isfinite(hi) else f"under {hi:g} m" if not math.isfinite(lo)
                else f"{lo:g} to {hi:g} m")
        print(f"| {name} | {len(rows)} | {n['success']} | {n['timeout']} | {n['goal_missed']} "
              f"| {n['collision']} |")


def _f(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


if __name__ == "__main__":
    main()
