"""Scan matching on the real dev logs: odom, idc and kiss-icp side by side in one run, on one core.

    python benchmarks/scanmatch.py [--datasets ../shared/datasets] [--logs mit-csail,aces] [--kiss-sweep]
                                   [--starts 0,1,2,3,5]

For each log (MIT CSAIL, ACES: CARMEN logs with the SLAM-benchmark relations of Kümmerle et al. 2009) it
prints one row per matcher: time per scan (median, p99), match failures, and the relation errors
(translational [m] and rotational [deg]: mean ± std, max; relations matched / unmatched; "<1 s": the mean
translational error over the relations between scans less than 1 s apart), then the idc/kiss time ratio.
Rows: raw odometry; idc (the default matcher); idc without its point-to-line polish (pure IDC); kiss-icp
at its best setting on these logs (KissParams defaults: odometry prior, voxel 0.25 m, range 40 m, initial
threshold 0.5 m); the same without the odometry prior, as kiss-icp's authors run it (constant-velocity
prediction).
``--kiss-sweep`` also runs the kiss-icp settings that were tried to choose that best setting.

Then idc and kiss-icp run again from later first scans (``--starts``): most of the relation error comes from
the relations that close loops, i.e. from drift, and drift is chaotic (one scan more or less at the start
moves it by tens of percent), so one run's number is one draw. The medians over the starts are the figures
to compare.

Only the matchers' ``update`` calls are timed (the log is read into memory first; numba is warmed up).
Threads are pinned to one (numba, BLAS, TBB via KissParams.max_num_threads) and so is the process's CPU.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from gndreplay.evaluation import Relations, load_relations  # noqa: E402
from gndreplay.io import read_ticks  # noqa: E402
from gndreplay.scanmatch import (  # noqa: E402
    IdcMatcher,
    IdcParams,
    KissIcpMatcher,
    KissParams,
    Matcher,
    MatcherReport,
    OdomMatcher,
    correct_trajectory,
    matcher_report,
)

ROOT = Path(__file__).resolve().parents[1]
LOGS = {"mit-csail": ("carmen/mit-csail.clf.bz2", "relations/mit-csail.relations", 0.106),
        "aces": ("carmen/aces.clf.bz2", "relations/aces.relations", 0.173)}

# kiss-icp settings tried on both logs before choosing the KissParams defaults (fields not given: KissParams
# defaults, i.e. odometry prior on, initial threshold 0.5 m); --kiss-sweep prints each one's row
_T2 = {"initial_threshold_m": 2.0}  # kiss-icp's own default threshold
KISS_SWEEP: list[dict[str, object]] = [
    {"voxel_m": 1.0, "max_range_m": 100.0, "min_range_m": 0.0, "odom_prior": False, **_T2},  # kiss defaults
    {"voxel_m": 0.5, "max_range_m": 30.0, "odom_prior": False, **_T2},
    {"voxel_m": 0.25, "max_range_m": 30.0, "odom_prior": False, **_T2},
    {"voxel_m": 0.1, "max_range_m": 30.0, "odom_prior": False, **_T2},
    {"voxel_m": 0.25, "max_range_m": 30.0, "odom_prior": False, "fixed_threshold_m": 0.3},
    {"voxel_m": 0.25, "max_range_m": 40.0, "odom_prior": False},
    {"voxel_m": 0.5, "max_range_m": 40.0, "odom_prior": False},
    {"voxel_m": 0.05, "max_range_m": 30.0, **_T2},
    {"voxel_m": 0.1, "max_range_m": 30.0, **_T2},
    {"voxel_m": 0.1, "max_range_m": 30.0, "fixed_threshold_m": 0.3},
    {"voxel_m": 0.15, "max_range_m": 30.0, **_T2},
    {"voxel_m": 0.25, "max_range_m": 15.0, **_T2},
    {"voxel_m": 0.25, "max_range_m": 30.0, **_T2},
    {"voxel_m": 0.25, "max_range_m": 30.0, "min_motion_m": 0.05, **_T2},
    {"voxel_m": 0.25, "max_range_m": 30.0, "max_points_per_voxel": 5, **_T2},
    {"voxel_m": 0.35, "max_range_m": 30.0, **_T2},
    {"voxel_m": 0.25, "max_range_m": 40.0, **_T2},
    {"voxel_m": 0.25, "max_range_m": 30.0},
    {"voxel_m": 0.2, "max_range_m": 40.0},
    {"voxel_m": 0.3, "max_range_m": 40.0},
    {"voxel_m": 0.25, "max_range_m": 50.0},
    {"voxel_m": 0.25, "max_range_m": 40.0, "max_points_per_voxel": 5},
    {"voxel_m": 0.25, "max_range_m": 40.0},  # the KissParams defaults
]


def _pin_one_cpu() -> None:
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))
        if cpus:
            os.sched_setaffinity(0, {cpus[0]})


def _local_mean(r: MatcherReport, relations: Relations) -> float:
    """Mean translational error over the relations between scans less than 1 s apart: the accuracy of the
    matches themselves, without the drift that the loop-closing relations measure."""
    s = r.relations
    if s is None:
        return float("nan")
    near = (relations.t2_ns - relations.t1_ns)[s.index] < 1_000_000_000
    return float(s.trans_err_m[near].mean()) if near.any() else float("nan")


def _row(name: str, r: MatcherReport, relations: Relations) -> str:
    s = r.relations
    rel = "" if s is None else (
        f"{s.trans_mean_m:7.3f} ± {s.trans_std_m:6.3f} {s.trans_max_m:7.2f} "
        f"{_local_mean(r, relations):7.3f}   "
        f"{s.rot_mean_deg:6.2f} ± {s.rot_std_deg:6.2f} {s.rot_max_deg:7.2f}   {s.matched:5d}/{s.unmatched}")
    return f"  {name:<16s} {r.ms_median:7.3f} {r.ms_p99:7.3f} {r.failures:6d}   {rel}"


HEADER = ("  matcher          ms/scan    p99  fails   trans err [m] mean ± std    max   <1 s   "
          "rot err [deg] mean ± std  max   matched/unmatched")


def run_log(name: str, datasets: Path, kiss_sweep: bool, starts: list[int]) -> dict[str, MatcherReport]:
    log_rel, rel_rel, baseline = LOGS[name]
    t0 = time.perf_counter()
    ticks = list(read_ticks(datasets / log_rel))
    relations = load_relations(datasets / rel_rel)
    beams = ticks[0].scan.ranges_m.shape[0]
    print(f"\n{name}: {len(ticks)} scans of {beams} beams, {len(relations)} relations "
          f"(read in {time.perf_counter() - t0:.1f} s); published scan-matching baseline {baseline} m")
    correct_trajectory(ticks[:50], IdcMatcher())  # numba warm-up (compiled code is cached on disk)
    matchers: list[tuple[str, Matcher]] = [
        ("odom", OdomMatcher()),
        ("idc", IdcMatcher()),
        ("idc (pure IDC)", IdcMatcher(IdcParams(polish_iterations=0))),
        ("kiss-icp", KissIcpMatcher(KissParams())),
        ("kiss-icp no odom", KissIcpMatcher(KissParams(odom_prior=False))),
    ]
    if kiss_sweep:
        for kw in KISS_SWEEP:
            label = ",".join(f"{k}={v}" for k, v in kw.items())
            matchers.append((label, KissIcpMatcher(dataclasses.replace(KissParams(), **kw))))  # type: ignore[arg-type]
    rows: dict[str, MatcherReport] = {}
    print(HEADER)
    for label, matcher in matchers:
        rows[label] = matcher_report(correct_trajectory(ticks, matcher), relations)
        print(_row(label, rows[label], relations), flush=True)
    ratio = rows["idc"].ms_median / rows["kiss-icp"].ms_median
    idc_e = _trans_mean(rows["idc"])
    print(f"  idc / kiss-icp median time: {rows['idc'].ms_median:.3f} / {rows['kiss-icp'].ms_median:.3f} ms "
          f"= {ratio:.2f};  idc error / baseline: {idc_e:.3f} / {baseline} = {idc_e / baseline:.2f}")
    if len(starts) > 1:
        print(f"  from first scans {starts}: mean translational error [m] and ms per scan (median):")
        errs: dict[str, list[float]] = {}
        times: dict[str, list[float]] = {}
        for label, make in (("idc", IdcMatcher), ("kiss-icp", lambda: KissIcpMatcher(KissParams()))):
            reports = [rows[label] if start == 0 else
                       matcher_report(correct_trajectory(ticks[start:], make()), relations)
                       for start in starts]
            errs[label] = [_trans_mean(r) for r in reports]
            times[label] = [r.ms_median for r in reports]
            print(f"  {label:<16s} " + "  ".join(f"{e:6.3f}" for e in errs[label])
                  + f"   median {np.median(errs[label]):.3f}  max {max(errs[label]):.3f};  "
                  + "ms " + " ".join(f"{t:.3f}" for t in times[label]), flush=True)
        time_ratios = np.array(times["idc"]) / np.array(times["kiss-icp"])
        print(f"  medians over the starts: idc / kiss-icp error "
              f"{np.median(errs['idc']) / np.median(errs['kiss-icp']):.2f}, idc / baseline "
              f"{np.median(errs['idc']) / baseline:.2f}, idc / kiss-icp time {np.median(time_ratios):.2f} "
              f"(per start {' '.join(f'{r:.2f}' for r in time_ratios)})")
    return rows


def _trans_mean(r: MatcherReport) -> float:
    return r.relations.trans_mean_m if r.relations else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", type=Path, default=ROOT.parent / "shared" / "datasets")
    ap.add_argument("--logs", default="mit-csail,aces")
    ap.add_argument("--kiss-sweep", action="store_true", help="also run the kiss-icp settings tried")
    ap.add_argument("--starts", default="0,1,2,3,5",
                    help="first scans of the repeated idc and kiss-icp runs (comma-separated, 0 first)")
    args = ap.parse_args(argv)
    if not args.datasets.is_dir():
        print(f"datasets not found: {args.datasets}", file=sys.stderr)
        return 2
    _pin_one_cpu()
    print(f"numpy {np.__version__}; one thread, CPU affinity {sorted(os.sched_getaffinity(0))}"
          if hasattr(os, "sched_getaffinity") else f"numpy {np.__version__}; one thread")
    for name in args.logs.split(","):
        run_log(name.strip(), args.datasets, args.kiss_sweep, [int(v) for v in args.starts.split(",")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
