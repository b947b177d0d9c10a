"""Odometry, idc and kiss-icp on every log with ground truth, at full rate and sampled by distance.

    python benchmarks/scanmatch_variants.py [--datasets ../shared/datasets] [--starts 0,1,2,3,5]
                                            [--logs sample,mit-csail,aces,intel] [--no-kiss]

Logs: the bundled sample (scored against its ground truth: ATE RMSE after SE(2) alignment, and the largest
ATE) and MIT CSAIL, ACES, Intel (scored against the SLAM-benchmark relations of Kümmerle et al. 2009: mean
translational error). Variants of each:

- full: the log as recorded;
- dec: one scan per 0.2 m or 5 deg of odometry (benchmarks/scanmatch.py's decimation), as a log sampled by
  distance holds it, with long gaps while the robot stands;
- dec+int: the same with interleaved start bearings: scan k's bearings shifted by (k mod 4) * 0.25 deg and
  its ranges resampled there (scanmatch.interleave_bearings), as a ROBOTLASER log with four start angles.

Each matcher runs from each start scan (drift is chaotic: one run is one draw); printed per log and variant:
the error from scan 0, the median over the starts, and for idc on the relation logs the largest rotational
error of a relation shorter than 1 s over all starts (the relation and the start named when above 3 deg).
One thread; the figures are deterministic (no timing here: benchmarks/scanmatch.py times the matchers).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scanmatch import DECIMATE_M, DECIMATE_RAD  # noqa: E402

from gndreplay.evaluation import Relations, load_relations, relation_errors, trajectory_errors  # noqa: E402
from gndreplay.io import read_ticks  # noqa: E402
from gndreplay.scanmatch import (  # noqa: E402
    correct_trajectory,
    interleave_bearings,
    keep_by_travel,
    make_matcher,
)
from gndreplay.types import Tick  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_logs" / "office.clf.bz2"
RELATION_LOGS = ("mit-csail", "aces", "intel")
VARIANTS = ("full", "dec", "dec+int")
INTERLEAVE_RAD = math.radians(0.25)
INTERLEAVE_PHASES = 4
SHORT_S = 1.0
ROT_LIMIT_DEG = 3.0


def variant(ticks: list[Tick], name: str) -> list[Tick]:
    """The ticks of one variant (see the module docstring)."""
    if name == "full":
        return ticks
    kept = keep_by_travel(ticks, DECIMATE_M, DECIMATE_RAD)
    return kept if name == "dec" else interleave_bearings(kept, INTERLEAVE_RAD, INTERLEAVE_PHASES)


def score_truth(ticks: list[Tick], method: str) -> tuple[float, float, int]:
    """(ATE RMSE, ATE max) [m] of ``method`` against the ticks' ground truth, SE(2)-aligned, and -1 (no
    relation: the shape of score_relations' answer)."""
    traj = correct_trajectory(ticks, make_matcher(method))  # type: ignore[arg-type]
    truth = np.array([(t.truth.x, t.truth.y, t.truth.theta) for t in ticks if t.truth is not None])
    err = trajectory_errors(traj.t_ns, traj.poses, traj.t_ns, truth, alignment="se2")
    return err.ate_rmse_m, err.ate_max_m, -1


def score_relations(ticks: list[Tick], method: str, relations: Relations) -> tuple[float, float, int]:
    """(mean translational error [m], largest rotational error of a relation < 1 s [deg], that relation's
    index in the relations file) of ``method``."""
    traj = correct_trajectory(ticks, make_matcher(method))  # type: ignore[arg-type]
    st = relation_errors(traj.t_ns, traj.poses, relations)
    span = np.abs(relations.t2_ns - relations.t1_ns)[st.index] * 1e-9
    short = np.nonzero(span < SHORT_S)[0]
    worst = int(short[np.argmax(st.rot_err_deg[short])]) if short.size else -1
    return st.trans_mean_m, float(st.rot_err_deg[worst]) if worst >= 0 else math.nan, int(st.index[worst])


def run_log(name: str, datasets: Path, starts: list[int], methods: list[str]) -> list[str]:
    """The table rows of one log: one per variant, the matchers side by side."""
    truth = name == "sample"
    ticks = list(read_ticks(SAMPLE if truth else datasets / "carmen" / f"{name}.clf.bz2"))
    relations = None if truth else load_relations(datasets / "relations" / f"{name}.relations")
    rows = []
    for var in VARIANTS:
        vt = variant(ticks, var)
        cells = [name, var, str(len(vt))]
        notes = []
        for method in methods:
            runs = [score_truth(vt[s:], method) if relations is None
                    else score_relations(vt[s:], method, relations) for s in starts]
            first, med = runs[0][0], statistics.median(r[0] for r in runs)
            cells += [f"{first:.3f}", f"{med:.3f}"]
            if method == "idc":
                if relations is None:
                    cells.append(f"{max(r[1] for r in runs):.3f}")
                else:
                    worst = max(range(len(runs)), key=lambda i: runs[i][1])
                    cells.append(f"{runs[worst][1]:.2f}")
                    notes += [f"start {starts[i]}: relation {runs[i][2]} {runs[i][1]:.2f} deg"
                              for i in range(len(runs)) if runs[i][1] > ROT_LIMIT_DEG]
        rows.append("| " + " | ".join(cells) + " |" + (f" <!-- {'; '.join(notes)} -->" if notes else ""))
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--datasets", type=Path, default=ROOT.parent / "shared" / "datasets")
    ap.add_argument("--logs", default=",".join(("sample", *RELATION_LOGS)))
    ap.add_argument("--starts", default="0,1,2,3,5")
    ap.add_argument("--no-kiss", dest="kiss", action="store_false", help="odometry and idc only")
    args = ap.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    starts = [int(s) for s in args.starts.split(",")]
    methods = ["odom", "idc"] + (["kiss-icp"] if args.kiss else [])
    head = ["log", "variant", "scans"]
    for m in methods:
        head += [f"{m} from scan 0", f"{m} median"] + (["idc worst (ATE max [m] / rot. error < 1 s [deg])"]
                                                         if m == "idc" else [])
    print("errors: sample = ATE RMSE [m] (SE(2)-aligned); relation logs = mean translational relation error "
          f"[m]; starts {args.starts}")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    names = [n for n in args.logs.split(",")
             if n == "sample" or (args.datasets / "carmen" / f"{n}.clf.bz2").exists()]
    for name in names:
        run_log(name, args.datasets, starts, methods)


if __name__ == "__main__":
    main()
