"""Scan matching on the real logs: odom, idc and kiss-icp side by side in one run, on one core.

    python benchmarks/scanmatch.py [--datasets ../shared/datasets] [--logs mit-csail,aces,intel]
                                   [--starts 0,1,2,3,5] [--no-kiss] [--no-decimated] [--kiss-sweep]

For each log (MIT CSAIL, ACES, Intel: CARMEN logs with the SLAM-benchmark relations of Kümmerle et al. 2009;
only CSAIL and ACES were used to choose the defaults) it prints one row per matcher: time per scan (median,
p99), match failures, and the relation errors: translational [m] mean ± std and max, then the mean split by
relation span (<1 s: the matches' own accuracy; 1-10 s; >10 s: mostly drift, the loop-closing relations),
rotational [deg] mean and the largest rotational error of a relation < 1 s, relations matched / unmatched
(for idc from each start the worst relation < 1 s is named: its index in the relations file, its scans).
Rows: raw odometry; idc (the default matcher); idc without de-skewing of interlaced scans
(IdcParams.deskew) and idc whose rotation guard only widens (IdcParams.narrow_rotation_guard), for a
side-by-side comparison (both off: the matcher before them); idc without its point-to-line polish (pure
IDC); kiss-icp at its best setting on the dev logs (KissParams defaults: odometry prior, voxel 0.25 m, range
40 m, initial threshold 0.5 m); the same without the odometry prior, as kiss-icp's authors run it.
``--kiss-sweep`` also runs the kiss-icp settings that were tried to choose that best setting.

Then idc, its two variants and kiss-icp run again from later first scans (``--starts``; for idc the
interlace delay it learnt is printed per start): most of the relation error comes from
the relations that close loops, i.e. from drift, and drift is chaotic (one scan more or less at the start
moves it by tens of percent), so one run's number is one draw. The medians over the starts are the figures
to compare.

Decimated variant of each log (``--no-decimated`` skips it): only the scans after which the odometry has
moved 0.2 m or turned 5 deg since the last kept one, as a log sampled by distance (CARMEN robotlaser style)
would hold; long gaps where the robot stands. It is scored against the relations whose two scans survive
and against the full-rate idc trajectory (relations between consecutive kept scans and 50 kept scans
apart), for odom and idc.

Only the matchers' ``update`` calls are timed (the log is read into memory first; numba is warmed up).
Threads are pinned to one (numba, BLAS, TBB via KissParams.max_num_threads) and so is the process's CPU.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from gndreplay.evaluation import (  # noqa: E402
    Relations,
    RelationStats,
    load_relations,
    relation_errors,
    relations_from_trajectory,
)
from gndreplay.io import read_ticks  # noqa: E402
from gndreplay.scanmatch import (  # noqa: E402
    CorrectedTrajectory,
    IdcMatcher,
    IdcParams,
    KissIcpMatcher,
    KissParams,
    Matcher,
    MatcherReport,
    OdomMatcher,
    correct_trajectory,
    keep_by_travel,
    matcher_report,
)
from gndreplay.types import Tick  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# log -> (log file, relations file, published scan-matching baseline [m] (Kümmerle et al. 2009))
LOGS = {"mit-csail": ("carmen/mit-csail.clf.bz2", "relations/mit-csail.relations", 0.106),
        "aces": ("carmen/aces.clf.bz2", "relations/aces.relations", 0.173),
        "intel": ("carmen/intel.clf.bz2", "relations/intel.relations", 0.220)}
DECIMATE_M = 0.2
DECIMATE_RAD = math.radians(5.0)

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


def decimate(ticks: list[Tick]) -> list[Tick]:
    """The decimated variant: one scan per DECIMATE_M of travel or DECIMATE_RAD of turn (odometry)."""
    return keep_by_travel(ticks, DECIMATE_M, DECIMATE_RAD)


def _span(s: RelationStats | None, label: str, field: str) -> float:
    return float("nan") if s is None else float(getattr(s.span(label), field))


def _row(name: str, r: MatcherReport) -> str:
    s = r.relations
    rel = "" if s is None else (
        f"{s.trans_mean_m:7.3f} ± {s.trans_std_m:6.3f} {s.trans_max_m:7.2f}  "
        f"{_span(s, '<1 s', 'trans_mean_m'):6.3f} {_span(s, '1-10 s', 'trans_mean_m'):6.3f} "
        f"{_span(s, '>10 s', 'trans_mean_m'):6.3f}   {s.rot_mean_deg:6.2f} "
        f"{_span(s, '<1 s', 'rot_max_deg'):7.2f}"
        f"   {s.matched:5d}/{s.unmatched}")
    return f"  {name:<18s} {r.ms_median:7.3f} {r.ms_p99:7.3f} {r.failures:6d}   {rel}"


HEADER = ("  matcher            ms/scan    p99  fails   trans err [m] mean ± std  max    <1 s  1-10 s  >10 s"
          "   rot [deg] mean, max <1 s   matched/unmatched")


def _worst_short(s: RelationStats | None, relations: Relations, tick_t: np.ndarray) -> str:
    """The relation < 1 s with the largest rotational error: its index, its scans (indices into the log)
    and the error, so that it can be looked at."""
    if s is None or s.matched == 0:
        return "-"
    i = s.index
    short = np.abs(relations.t2_ns[i] - relations.t1_ns[i]) < 1_000_000_000
    if not short.any():
        return "-"
    k = int(np.argmax(np.where(short, s.rot_err_deg, -1.0)))
    r = int(i[k])
    a, b = (int(np.argmin(np.abs(tick_t - t))) for t in (relations.t1_ns[r], relations.t2_ns[r]))
    return f"{r} (scans {a}-{b}) {s.rot_err_deg[k]:.2f}"


def _trans_mean(r: MatcherReport) -> float:
    return r.relations.trans_mean_m if r.relations else float("nan")


@dataclasses.dataclass
class LogSummary:
    """The must-show figures of one log (see the summary table printed at the end)."""

    name: str
    baseline: float
    odom: float
    idc0: float
    kiss0: float
    idc_med: float = float("nan")
    kiss_med: float = float("nan")
    rot1s_max: float = float("nan")  # largest rotational error of a relation < 1 s over idc's runs [deg]
    ms_ratio: float = float("nan")  # idc / kiss-icp median time per scan
    idc_ms: float = float("nan")
    dec_odom: float = float("nan")
    dec_idc: float = float("nan")
    dec_vs_full_odom: float = float("nan")
    dec_vs_full_idc: float = float("nan")
    nd_idc0: float = float("nan")  # idc without de-skewing: from scan 0, median over starts, rot max < 1 s
    nd_idc_med: float = float("nan")
    nd_rot1s_max: float = float("nan")
    wg_idc0: float = float("nan")  # idc whose rotation guard only widens: the same three figures
    wg_idc_med: float = float("nan")
    wg_rot1s_max: float = float("nan")


def run_log(name: str, datasets: Path, kiss: bool, kiss_sweep: bool, starts: list[int],
            decimated: bool) -> LogSummary:
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
        ("idc (no de-skew)", IdcMatcher(IdcParams(deskew=False))),
        ("idc (wide guard)", IdcMatcher(IdcParams(narrow_rotation_guard=False))),
        ("idc (pure IDC)", IdcMatcher(IdcParams(polish_iterations=0))),
    ]
    if kiss:
        matchers += [("kiss-icp", KissIcpMatcher(KissParams())),
                     ("kiss-icp no odom", KissIcpMatcher(KissParams(odom_prior=False)))]
    if kiss_sweep:
        for kw in KISS_SWEEP:
            label = ",".join(f"{k}={v}" for k, v in kw.items())
            matchers.append((label, KissIcpMatcher(dataclasses.replace(KissParams(), **kw))))  # type: ignore[arg-type]
    rows: dict[str, MatcherReport] = {}
    trajs: dict[str, CorrectedTrajectory] = {}
    print(HEADER)
    idc_delays: dict[str, float] = {}
    for label, matcher in matchers:
        trajs[label] = correct_trajectory(ticks, matcher)
        if isinstance(matcher, IdcMatcher):
            idc_delays[label] = matcher.interlace_delay_s
        rows[label] = matcher_report(trajs[label], relations)
        print(_row(label, rows[label]), flush=True)
    idc_s = rows["idc"].relations
    summary = LogSummary(name, baseline, _trans_mean(rows["odom"]), _trans_mean(rows["idc"]),
                         _trans_mean(rows["kiss-icp"]) if kiss else float("nan"),
                         rot1s_max=_span(idc_s, "<1 s", "rot_max_deg"), idc_ms=rows["idc"].ms_median,
                         nd_idc0=_trans_mean(rows["idc (no de-skew)"]),
                         nd_rot1s_max=_span(rows["idc (no de-skew)"].relations, "<1 s", "rot_max_deg"),
                         wg_idc0=_trans_mean(rows["idc (wide guard)"]),
                         wg_rot1s_max=_span(rows["idc (wide guard)"].relations, "<1 s", "rot_max_deg"))
    if kiss:
        summary.ms_ratio = rows["idc"].ms_median / rows["kiss-icp"].ms_median
        print(f"  idc / kiss-icp median time: {rows['idc'].ms_median:.3f} / "
              f"{rows['kiss-icp'].ms_median:.3f} ms = {summary.ms_ratio:.2f}")
    print(f"  idc error / baseline: {summary.idc0:.3f} / {baseline} = {summary.idc0 / baseline:.2f}")
    if len(starts) > 1:
        print(f"  from first scans {starts}: mean translational error [m] and ms per scan (median):")
        errs: dict[str, list[float]] = {}
        times: dict[str, list[float]] = {}
        makers: list[tuple[str, Callable[[], Matcher]]] = [
            ("idc", IdcMatcher), ("idc (no de-skew)", lambda: IdcMatcher(IdcParams(deskew=False))),
            ("idc (wide guard)", lambda: IdcMatcher(IdcParams(narrow_rotation_guard=False)))]
        if kiss:
            makers.append(("kiss-icp", lambda: KissIcpMatcher(KissParams())))
        tick_t = np.array([t.t_ns for t in ticks], dtype=np.int64)
        for label, make in makers:
            reports: list[MatcherReport] = []
            delays: list[float] = []
            for start in starts:
                matcher = make()
                reports.append(matcher_report(correct_trajectory(ticks[start:], matcher), relations)
                               if start else rows[label])
                if isinstance(matcher, IdcMatcher):
                    delays.append(matcher.interlace_delay_s if start else idc_delays[label])
            errs[label] = [_trans_mean(r) for r in reports]
            times[label] = [r.ms_median for r in reports]
            rot_max = max(_span(r.relations, "<1 s", "rot_max_deg") for r in reports)
            if label == "idc":
                summary.rot1s_max = rot_max
            elif label == "idc (no de-skew)":
                summary.nd_idc_med, summary.nd_rot1s_max = float(np.median(errs[label])), rot_max
            elif label == "idc (wide guard)":
                summary.wg_idc_med, summary.wg_rot1s_max = float(np.median(errs[label])), rot_max
            print(f"  {label:<16s} " + "  ".join(f"{e:6.3f}" for e in errs[label])
                  + f"   median {np.median(errs[label]):.3f}  max {max(errs[label]):.3f};  "
                  + "ms " + " ".join(f"{t:.3f}" for t in times[label]), flush=True)
            if label.startswith("idc"):
                print(f"  {label} worst relation < 1 s per start: index (scans) error [deg]: "
                      + "; ".join(_worst_short(r.relations, relations, tick_t) for r in reports))
            if label == "idc":
                print("  idc interlace delay learnt per start [ms]: "
                      + " ".join(f"{1e3 * d:.1f}" for d in delays))
        summary.idc_med = float(np.median(errs["idc"]))
        line = f"  medians over the starts: idc / baseline {summary.idc_med / baseline:.2f}"
        if kiss:
            summary.kiss_med = float(np.median(errs["kiss-icp"]))
            time_ratios = np.array(times["idc"]) / np.array(times["kiss-icp"])
            summary.ms_ratio = float(np.median(time_ratios))
            line += (f", idc / kiss-icp error {summary.idc_med / summary.kiss_med:.2f}, idc / kiss-icp time "
                     f"{summary.ms_ratio:.2f} (per start {' '.join(f'{r:.2f}' for r in time_ratios)})")
        print(line)
    if decimated:
        _decimated(ticks, relations, trajs["idc"], summary)
    return summary


def _decimated(ticks: list[Tick], relations: Relations, full_idc: CorrectedTrajectory,
               summary: LogSummary) -> None:
    """The decimated variant: odom and idc against the surviving relations and the full-rate idc run."""
    kept = decimate(ticks)
    gaps = np.diff([t.t_ns for t in kept]) * 1e-9
    on_kept = np.isin(full_idc.t_ns, [t.t_ns for t in kept])
    reference = relations_from_trajectory(full_idc.t_ns[on_kept], full_idc.poses[on_kept], (1, 50))
    print(f"  decimated (one scan per {DECIMATE_M} m or {math.degrees(DECIMATE_RAD):.0f} deg of odometry): "
          f"{len(kept)} of {len(ticks)} scans, gaps up to {gaps.max():.1f} s "
          f"({int((gaps > 10).sum())} > 10 s)")
    print("  matcher            ms/scan    p99  fails   relations: mean  <1 s  >10 s  rot <1 s max  matched"
          "   vs full-rate idc: trans  rot [deg]")
    for label, matcher in (("odom", OdomMatcher()), ("idc", IdcMatcher()),
                           ("idc (no de-skew)", IdcMatcher(IdcParams(deskew=False))),
                           ("idc (wide guard)", IdcMatcher(IdcParams(narrow_rotation_guard=False)))):
        traj = correct_trajectory(kept, matcher)
        r = matcher_report(traj, relations)
        s = r.relations
        f = relation_errors(traj.t_ns, traj.poses, reference)
        assert s is not None
        print(f"  {label:<18s} {r.ms_median:7.3f} {r.ms_p99:7.3f} {r.failures:6d}   "
              f"{s.trans_mean_m:15.3f} {_span(s, '<1 s', 'trans_mean_m'):6.3f} "
              f"{_span(s, '>10 s', 'trans_mean_m'):6.3f}"
              f" {_span(s, '<1 s', 'rot_max_deg'):12.2f} {s.matched:8d}   {f.trans_mean_m:20.3f} "
              f"{f.rot_mean_deg:9.2f}", flush=True)
        if label == "odom":
            summary.dec_odom, summary.dec_vs_full_odom = s.trans_mean_m, f.trans_mean_m
        elif label == "idc":
            summary.dec_idc, summary.dec_vs_full_idc = s.trans_mean_m, f.trans_mean_m


def print_summary(rows: list[LogSummary]) -> None:
    """The must-show table: mean relation error [m] of each log."""
    print("\n| log | odom | idc from scan 0 | idc median over starts | kiss-icp from scan 0 "
          "| kiss-icp median | baseline | idc max rot err, relations < 1 s [deg] | idc ms/scan "
          "| idc / kiss time | decimated odom / idc | decimated vs full-rate idc: odom / idc "
          "| idc without de-skew: from scan 0 / median / max rot err < 1 s "
          "| idc with the wide guard: from scan 0 / median / max rot err < 1 s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r.name} | {r.odom:.3f} | {r.idc0:.3f} | {r.idc_med:.3f} | {r.kiss0:.3f} "
              f"| {r.kiss_med:.3f} | {r.baseline} | {r.rot1s_max:.2f} | {r.idc_ms:.3f} | {r.ms_ratio:.2f} "
              f"| {r.dec_odom:.3f} / {r.dec_idc:.3f} | {r.dec_vs_full_odom:.3f} / {r.dec_vs_full_idc:.3f} "
              f"| {r.nd_idc0:.3f} / {r.nd_idc_med:.3f} / {r.nd_rot1s_max:.2f} "
              f"| {r.wg_idc0:.3f} / {r.wg_idc_med:.3f} / {r.wg_rot1s_max:.2f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", type=Path, default=ROOT.parent / "shared" / "datasets")
    ap.add_argument("--logs", default=",".join(LOGS))
    ap.add_argument("--no-kiss", dest="kiss", action="store_false", help="skip kiss-icp (faster iterations)")
    ap.add_argument("--no-decimated", dest="decimated", action="store_false", help="skip the decimated runs")
    ap.add_argument("--kiss-sweep", action="store_true", help="also run the kiss-icp settings tried")
    ap.add_argument("--starts", default="0,1,2,3,5",
                    help="first scans of the repeated idc and kiss-icp runs (comma-separated, 0 first)")
    args = ap.parse_args(argv)
    if not args.datasets.is_dir():
        print(f"datasets not found: {args.datasets}", file=sys.stderr)
        return 2
    names = [n.strip() for n in args.logs.split(",")]
    unknown = [n for n in names if n not in LOGS]
    if unknown:
        print(f"unknown log(s) {', '.join(unknown)}: expected some of {', '.join(LOGS)}", file=sys.stderr)
        return 2
    _pin_one_cpu()
    print(f"numpy {np.__version__}; one thread, CPU affinity {sorted(os.sched_getaffinity(0))}"
          if hasattr(os, "sched_getaffinity") else f"numpy {np.__version__}; one thread")
    starts = [int(v) for v in args.starts.split(",")]
    summaries = [run_log(n, args.datasets, args.kiss, args.kiss_sweep and args.kiss, starts,
                         args.decimated) for n in names]
    print_summary(summaries)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
