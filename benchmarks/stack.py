"""Per-tick cost of the navigation stack (model + planner + reactor) on a real log, on one core.

Runs ``gndreplay run`` (wheelchair preset, 400 x 400 grid, IDC matching) over the ACES log several times
and prints, per module, the median of the per-run medians and p99s, the stack total against the issue's
targets (median <= 5 ms, p99 <= 15 ms), and each module beside the wheelchair paper's figures (model
20 ms, planner 30 ms, ND+ < 1 ms, 150 ms cycle on a Pentium III 850 MHz) as a ratio.

    python benchmarks/stack.py [--log PATH] [--repeats 3] [--until SECONDS]
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from gndreplay.config import PRESETS  # noqa: E402
from gndreplay.replay import RunOptions, run_log  # noqa: E402

DATASETS = Path(__file__).resolve().parents[1].parent / "shared" / "datasets"
PAPER_MS = {"model": 20.0, "planner": 30.0, "reactor": 1.0, "cycle": 150.0}
MODULES = ("match", "model", "planner", "reactor", "stack")


def one_run(log: Path, until: float | None) -> dict[str, np.ndarray]:
    with tempfile.TemporaryDirectory() as tmp:
        run_log(log, PRESETS["wheelchair"], Path(tmp) / "run", options=RunOptions(until_s=until))
        data = np.genfromtxt(Path(tmp) / "run" / "timing.csv", delimiter=",", names=True)
    cols = {m: np.asarray(data[f"{m}_ms"]) for m in MODULES[:-1]}
    cols["stack"] = cols["model"] + cols["planner"] + cols["reactor"]
    return cols


def main() -> None:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=fmt)
    parser.add_argument("--log", type=Path, default=DATASETS / "carmen" / "aces.clf.bz2")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--until", type=float, default=None, help="seconds of log time per run")
    args = parser.parse_args()
    if not args.log.exists():
        raise SystemExit(f"benchmark log not found: {args.log} (needs ../shared/datasets)")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    runs = [one_run(args.log, args.until) for _ in range(args.repeats)]
    ticks = len(runs[0]["stack"])
    print(f"log {args.log.name}: {ticks} ticks per run, {args.repeats} runs, wheelchair preset, one core")
    print(f"{'module':<9}{'median ms':>11}{'p90 ms':>9}{'p99 ms':>9}{'max ms':>9}   paper ms   paper/ours")
    for m in MODULES:
        med = statistics.median(float(np.median(r[m])) for r in runs)
        p90 = statistics.median(float(np.percentile(r[m], 90)) for r in runs)
        p99 = statistics.median(float(np.percentile(r[m], 99)) for r in runs)
        mx = statistics.median(float(r[m].max()) for r in runs)
        paper = PAPER_MS.get(m, PAPER_MS["cycle"] if m == "stack" else float("nan"))
        ratio = f"{paper / med:10.0f}x" if paper == paper else "          -"
        label = f"{paper:9.0f}" if paper == paper else "        -"
        print(f"{m:<9}{med:11.3f}{p90:9.3f}{p99:9.3f}{mx:9.2f}  {label}  {ratio}")
    stack_med = statistics.median(float(np.median(r["stack"])) for r in runs)
    stack_p99 = statistics.median(float(np.percentile(r["stack"], 99)) for r in runs)
    print(
        f"stack (model+planner+reactor): median {stack_med:.2f} ms (target <= 5: "
        f"{'ok' if stack_med <= 5 else 'MISSED'}), p99 {stack_p99:.2f} ms (target <= 15: "
        f"{'ok' if stack_p99 <= 15 else 'MISSED'})"
    )


if __name__ == "__main__":
    main()
