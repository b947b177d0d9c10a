"""Per-tick cost of the navigation stack on a real log, on one core.

Runs ``gndreplay run`` (wheelchair preset, 400 x 400 grid, IDC matching, sequential) over the ACES log
several times and prints, per module, the median of the per-run medians and p99s: the modules' own times
from timing.csv (match, model, planner, reactor, supervisor) and ``step``, the whole of
``NavigationStack.step`` per tick as this script times it from outside (model + planner + reactor +
supervisor and the glue between them; the same measurement on any revision). ``step`` is held against the
targets (median <= 0.5 ms, p99 <= 2 ms), and each module is set beside the wheelchair paper's figures
(model 20 ms, planner 30 ms, ND+ < 1 ms, 150 ms cycle on a Pentium III 850 MHz) as a ratio.

    python benchmarks/stack.py [--log PATH] [--repeats 3] [--until SECONDS] [--vs REF]

``--vs REF`` (a git revision, or the path of another checkout) runs the same slice on REF's code too,
alternating REF and this tree run by run in fresh processes on the same core, and prints per module the
median of the per-run medians of both, their ratio (this / REF) and both p99s: the guard against a slowdown
nobody noticed. A revision is checked out in a temporary git worktree, removed afterwards.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from gndreplay.config import PRESETS  # noqa: E402
from gndreplay.replay import RunOptions, run_log  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATASETS = ROOT.parent / "shared" / "datasets"
PAPER_MS = {"model": 20.0, "planner": 30.0, "reactor": 1.0, "cycle": 150.0}
MODULES = ("match", "model", "planner", "reactor", "supervisor", "step")
TARGET_MEDIAN_MS, TARGET_P99_MS = 0.5, 2.0


def one_run(log: Path, until: float | None) -> dict[str, np.ndarray]:
    """One run's per-tick milliseconds per module (NaN for a module the tree does not time)."""
    from gndreplay.pipeline.stack import NavigationStack

    step_ns: list[int] = []
    step = NavigationStack.step

    def timed(self: NavigationStack, *args: object, **kwargs: object) -> object:
        t0 = time.perf_counter_ns()
        out = step(self, *args, **kwargs)  # type: ignore[arg-type]
        step_ns.append(time.perf_counter_ns() - t0)
        return out

    NavigationStack.step = timed  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            run_log(log, PRESETS["wheelchair"], Path(tmp) / "run", options=RunOptions(until_s=until))
            data = np.genfromtxt(Path(tmp) / "run" / "timing.csv", delimiter=",", names=True)
    finally:
        NavigationStack.step = step  # type: ignore[method-assign]
    names = data.dtype.names or ()
    cols = {m: np.asarray(data[f"{m}_ms"]) if f"{m}_ms" in names else np.full(data.shape[0], np.nan)
            for m in MODULES[:-1]}
    cols["step"] = np.asarray(step_ns, dtype=np.float64) / 1e6
    return cols


def _stats(runs: list[dict[str, np.ndarray]], m: str) -> tuple[float, float, float, float]:
    """(median, p90, p99, max) of module ``m``: each the median over the runs of the per-run figure."""
    return (statistics.median(float(np.median(r[m])) for r in runs),
            statistics.median(float(np.percentile(r[m], 90)) for r in runs),
            statistics.median(float(np.percentile(r[m], 99)) for r in runs),
            statistics.median(float(r[m].max()) for r in runs))


def report(log: Path, runs: list[dict[str, np.ndarray]]) -> None:
    """The per-module table of one tree, beside the paper's figures, and the issue's targets."""
    ticks = len(runs[0]["step"])
    print(f"log {log.name}: {ticks} ticks per run, {len(runs)} runs, wheelchair preset, one core")
    print(f"{'module':<11}{'median ms':>11}{'p90 ms':>9}{'p99 ms':>9}{'max ms':>9}   paper ms   paper/ours")
    for m in MODULES:
        med, p90, p99, mx = _stats(runs, m)
        paper = PAPER_MS.get(m, PAPER_MS["cycle"] if m == "step" else float("nan"))
        ratio = f"{paper / med:10.0f}x" if paper == paper and med == med else "          -"
        label = f"{paper:9.0f}" if paper == paper else "        -"
        print(f"{m:<11}{med:11.3f}{p90:9.3f}{p99:9.3f}{mx:9.2f}  {label}  {ratio}")
    med, _, p99, _ = _stats(runs, "step")
    print(
        f"step (model + planner + reactor + supervisor): median {med:.3f} ms (target <= {TARGET_MEDIAN_MS}: "
        f"{'ok' if med <= TARGET_MEDIAN_MS else 'NOT REACHED'}), p99 {p99:.2f} ms (target <= "
        f"{TARGET_P99_MS}: {'ok' if p99 <= TARGET_P99_MS else 'NOT REACHED'})"
    )


@contextmanager
def checkout(ref: str) -> Iterator[Path]:
    """REF's tree: the directory itself, or the revision in a temporary git worktree of this repository."""
    if Path(ref).is_dir():
        yield Path(ref).resolve()
        return
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "ref"
        git = ["git", "-C", str(ROOT), "worktree"]
        subprocess.run([*git, "add", "-q", "--detach", str(tree), ref], check=True)
        try:
            yield tree
        finally:
            subprocess.run([*git, "remove", "--force", str(tree)], check=False)


def run_in(tree: Path, log: Path, until: float | None) -> dict[str, np.ndarray]:
    """One run of this script's measurement on ``tree``'s code, in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--log", str(log), "--worker-out", str(out)]
        cmd += ["--until", str(until)] if until is not None else []
        env = {**os.environ, "PYTHONPATH": str(tree)}
        subprocess.run(cmd, check=True, cwd=tree, env=env, stdout=subprocess.DEVNULL)
        return {m: np.asarray(v) for m, v in json.loads(out.read_text()).items()}


def compare(ref: str, log: Path, until: float | None, repeats: int) -> None:
    """Alternate REF and this tree ``repeats`` times each and print the per-module side-by-side table."""
    with checkout(ref) as tree:
        runs: dict[str, list[dict[str, np.ndarray]]] = {"ref": [], "this": []}
        for _ in range(repeats):
            runs["ref"].append(run_in(tree, log, until))
            runs["this"].append(run_in(ROOT, log, until))
    print(f"log {log.name}: {len(runs['this'][0]['step'])} ticks per run, {repeats} runs each, alternated, "
          f"wheelchair preset, one core; REF = {ref}")
    print(f"{'module':<11}{'REF median':>12}{'this median':>13}{'ratio':>8}{'REF p99':>10}{'this p99':>10}")
    for m in MODULES:
        a, _, a99, _ = _stats(runs["ref"], m)
        b, _, b99, _ = _stats(runs["this"], m)
        print(f"{m:<11}{a:12.3f}{b:13.3f}{b / a:8.2f}{a99:10.3f}{b99:10.3f}")
    print("(nan: a module the tree does not time on its own)")


def main() -> None:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=fmt)
    parser.add_argument("--log", type=Path, default=DATASETS / "carmen" / "aces.clf.bz2")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--until", type=float, default=None, help="seconds of log time per run")
    parser.add_argument("--vs", metavar="REF", help="a git revision or another checkout to compare with")
    parser.add_argument("--worker-out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    log = args.log.resolve()
    if not log.exists():
        raise SystemExit(f"benchmark log not found: {log} (needs ../shared/datasets)")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    if args.worker_out is not None:
        run = one_run(log, args.until)
        args.worker_out.write_text(json.dumps({m: v.tolist() for m, v in run.items()}))
    elif args.vs:
        compare(args.vs, log, args.until, args.repeats)
    else:
        report(log, [one_run(log, args.until) for _ in range(args.repeats)])


if __name__ == "__main__":
    main()
