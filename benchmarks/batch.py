"""Batch scaling: the same N inputs with --jobs 1 and --jobs 2 side by side, median wall time of a few runs.

Inputs are the bundled sample log and the dev logs in ../shared/datasets (when present), taken round-robin
until there are N, each replayed for ``--until`` seconds of log time so every input costs about the same.
A ratio close to 2 means the pool scales (each worker is pinned to one numeric thread); it cannot exceed
the number of free cores ("cores busy" = the workers' CPU time / wall time shows how many the machine
gave). ``--synthetic S`` replaces the replay by S seconds of pure-Python CPU work per
input, to measure the pool itself. ``--scenario NAME`` makes the inputs N seeds of a shipped closed-loop
scenario instead (each limited to ``--time-limit`` seconds of simulated time, no figures), and also prints
the median time of one run inside its worker beside the batch's wall time per run (the pool's overhead).

    .venv/bin/python benchmarks/batch.py [--inputs 6] [--until 120] [--runs 3] [--synthetic 0]
    .venv/bin/python benchmarks/batch.py --scenario u_trap [--inputs 6] [--time-limit 20] [--runs 3]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("MPLBACKEND", "Agg")

from gndreplay.batch import Job, SimOptions, Task, expand_inputs, run_batch, run_input

ROOT = Path(__file__).resolve().parents[1]
DEV_LOGS = (
    "carmen/mit-csail.clf.bz2",
    "carmen/aces.clf.bz2",
    "rosbag1/mit-csail.sort.bag",
    "rosbag1/aces.sort.bag",
    "rosbag2/mit-csail.sort.ros2_mcap",
)


@dataclass(frozen=True)
class Burned:
    out_dir: Path
    ticks: int
    data: dict[str, Any]


def burn_cpu(task: Task) -> Burned:
    """Synthetic runner: spin the CPU for SYNTHETIC_S seconds (pure Python, holds the GIL)."""
    seconds = float(os.environ["GNDREPLAY_BENCH_SYNTHETIC_S"])
    t_end, n = time.process_time() + seconds, 0
    while time.process_time() < t_end:
        n += sum(range(1000)) > 0
    return Burned(task.run_dir, n, {"ticks": n})


def inputs(n: int, datasets: Path) -> list[Job]:
    logs = [ROOT / "sample_logs" / "office.clf.bz2"]
    logs += [datasets / rel for rel in DEV_LOGS if (datasets / rel).exists()]
    return [
        Job(name=f"{k:02d}-{logs[k % len(logs)].name.split('.')[0]}", path=logs[k % len(logs)])
        for k in range(n)
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--inputs", type=int, default=6, help="number of inputs N")
    ap.add_argument("--until", type=float, default=120.0, help="log seconds replayed per input")
    ap.add_argument("--runs", type=int, default=3, help="repetitions per --jobs value (median)")
    ap.add_argument(
        "--synthetic", type=float, default=0.0, help="seconds of CPU work per input instead of a replay"
    )
    ap.add_argument("--datasets", type=Path, default=ROOT.parent / "shared" / "datasets")
    ap.add_argument("--scenario", help="N seeds of this shipped scenario instead of logs")
    ap.add_argument("--time-limit", type=float, default=20.0, help="simulated seconds per scenario run")
    args = ap.parse_args()

    jobs = inputs(args.inputs, args.datasets)
    cfg: Any = None
    options: Any = None
    runner: Any = run_input
    sim = SimOptions(time_limit_s=args.time_limit, figures=False)
    if args.scenario:
        from gndreplay.config import Config

        jobs = expand_inputs([], scenarios=[args.scenario], seeds=range(args.inputs))
        cfg = Config()  # the logs' configuration: unused, scenarios take their own preset
    elif args.synthetic > 0:
        os.environ["GNDREPLAY_BENCH_SYNTHETIC_S"] = str(args.synthetic)  # inherited by the spawned workers
        runner = burn_cpu
    else:
        from gndreplay.config import Config
        from gndreplay.replay import RunOptions

        cfg, options = Config(), RunOptions(until_s=args.until)
    if args.scenario:
        what = f"seeds of a scenario, {args.time_limit:g} s simulated each"
    elif args.synthetic > 0:
        what = f"{args.synthetic:g} s CPU each"
    else:
        what = f"until {args.until:g} s each"
    names = ", ".join(sorted({j.path.name for j in jobs}))
    print(f"{len(jobs)} inputs ({what}): {names}; cores: {os.cpu_count()}")
    walls: dict[int, list[float]] = {1: [], 2: []}
    cores: dict[int, list[float]] = {1: [], 2: []}
    in_worker: dict[int, list[float]] = {1: [], 2: []}
    with tempfile.TemporaryDirectory(prefix="gndreplay-bench-batch-") as tmp:
        # warm-up: page cache, numba's on-disk cache
        run_batch(jobs[:2], cfg=cfg, options=options, out_dir=Path(tmp) / "warm", workers=2, runner=runner,
                  sim=sim)
        # each repetition replaces the previous batch folder of the same --jobs value (--overwrite)
        for rep in range(args.runs):
            for workers in (1, 2):  # interleaved, so drifts of the machine hit both alike
                cpu0 = _children_cpu_s()
                t0 = time.perf_counter()
                res = run_batch(
                    jobs,
                    cfg=cfg,
                    options=options,
                    out_dir=Path(tmp) / f"j{workers}",
                    workers=workers,
                    runner=runner,
                    overwrite=True,
                    sim=sim,
                )
                wall = time.perf_counter() - t0
                in_worker[workers] += [r.wall_s for r in res.results]
                walls[workers].append(wall)
                cores[workers].append((_children_cpu_s() - cpu0) / wall)
                bad = [f"{r.name}: {r.error}" for r in res.results if r.status == "error"]
                if bad:
                    raise SystemExit("inputs failed:\n  " + "\n  ".join(bad))
                print(
                    f"  run {rep + 1}  --jobs {workers}: {wall:7.2f} s  ({cores[workers][-1]:.2f} cores busy)"
                )
    med = {w: statistics.median(v) for w, v in walls.items()}
    print(f"{'':2s}{'--jobs':>8s} {'median s':>9s} {'inputs/s':>9s} {'cores busy':>11s}")
    for w in (1, 2):
        print(f"{'':2s}{w:8d} {med[w]:9.2f} {len(jobs) / med[w]:9.2f} {statistics.median(cores[w]):11.2f}")
    print(f"speed-up --jobs 2 vs --jobs 1: {med[1] / med[2]:.2f}x")
    for w in (1, 2):
        print(f"--jobs {w}: one input {statistics.median(in_worker[w]):.2f} s in its worker (median), "
              f"batch wall time per input {med[w] / len(jobs):.2f} s")


def _children_cpu_s() -> float:
    """CPU time [s] of the finished worker processes (a busy machine shows as fewer cores busy)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


if __name__ == "__main__":
    main()
