"""Scan matching on the real dev logs against the SLAM-benchmark relations (skips without ../shared/datasets).

On MIT CSAIL and ACES, idc's mean translational relation error must beat the published scan-matching
baseline of the benchmark (Kümmerle et al. 2009: CSAIL 0.106 m, ACES 0.173 m), raw odometry and kiss-icp
(at its best setting on these logs, KissParams defaults) measured here on the same ticks.

Most of that error comes from the relations that close loops (scans minutes apart at one place), where it is
the drift accumulated in between, and drift is chaotic: starting the same matcher one scan later moves idc
between 0.04 and 0.08 m on CSAIL and kiss-icp between 0.44 and 0.80 m. So every matcher runs from three
start scans and the medians are compared; idc must beat the baseline from every start. Runs in ~40 s; the
Intel and decimated checks below add ~30 s.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path

import pytest

from gndreplay.evaluation import RelationStats, load_relations, relation_errors
from gndreplay.scanmatch import (
    IdcParams,
    correct_trajectory,
    interleave_bearings,
    keep_by_travel,
    make_matcher,
    matcher_report,
)

pytestmark = pytest.mark.slow

LOGS = {"mit-csail": 0.106, "aces": 0.173}  # published scan-matching baseline, mean translational error [m]
STARTS = (0, 2, 5)  # first scan of each run
Result = tuple[str, dict[str, list[RelationStats]], dict[str, int]]


@pytest.fixture(scope="module", params=sorted(LOGS))
def errors(request: pytest.FixtureRequest, datasets: Path) -> Result:
    from gndreplay.io import read_ticks

    name = request.param
    ticks = list(read_ticks(datasets / "carmen" / f"{name}.clf.bz2"))
    relations = load_relations(datasets / "relations" / f"{name}.relations")
    stats: dict[str, list[RelationStats]] = {}
    failures: dict[str, int] = {}
    for method in ("odom", "idc", "kiss-icp"):
        for start in STARTS:
            row = matcher_report(correct_trajectory(ticks[start:], make_matcher(method)), relations)
            assert row.relations is not None
            stats.setdefault(method, []).append(row.relations)
            failures[method] = max(failures.get(method, 0), row.failures)
    return name, stats, failures


def _median(runs: list[RelationStats], field: str) -> float:
    return statistics.median(getattr(s, field) for s in runs)


def test_all_relations_matched(errors: Result) -> None:
    _, stats, _ = errors
    assert all(runs[0].unmatched == 0 for runs in stats.values())  # STARTS[0] == 0: every scan is there
    assert all(s.matched > 1000 for runs in stats.values() for s in runs)


def test_idc_beats_baseline_odometry_and_kiss(errors: Result) -> None:
    name, stats, failures = errors
    worst = max(s.trans_mean_m for s in stats["idc"])
    assert worst < LOGS[name], f"{name}: idc {worst:.3f} m >= published baseline {LOGS[name]} m"
    idc = _median(stats["idc"], "trans_mean_m")
    assert idc < _median(stats["odom"], "trans_mean_m"), f"{name}: idc {idc:.3f} m >= odometry"
    assert idc < _median(stats["kiss-icp"], "trans_mean_m"), f"{name}: idc {idc:.3f} m >= kiss-icp"
    assert _median(stats["idc"], "rot_mean_deg") < _median(stats["odom"], "rot_mean_deg")
    assert failures["idc"] < 0.01 * stats["idc"][0].matched  # failures are rare on real data
    # no relation < 1 s with a rotational error above 3 deg, from any start (CSAIL 3.1-3.8 deg before the
    # de-skewing of interlaced scans, ACES 2.5-3.9 deg before the rotation guard could narrow)
    worst_rot = max(s.span("<1 s").rot_max_deg for s in stats["idc"])
    assert worst_rot < 3.0, f"{name}: a relation < 1 s off by {worst_rot:.2f} deg"


def test_idc_params_are_the_defaults() -> None:
    """The numbers above are for the defaults; a changed default must be re-benchmarked."""
    p = IdcParams()
    defaults = (p.map_keyframes, p.keyframe_dist_m, p.n_bins, p.tol_m, p.polish_iterations)
    assert defaults == (40, 0.5, 1440, 3e-3, 12)


def test_idc_on_intel_below_baseline_and_odometry(datasets: Path) -> None:
    """Intel, a log never used to choose the defaults (fast turns, stale odometry): idc from scan 0 below the
    published baseline (0.220 m) and odometry (before the coarse rotation search and the guard: 1.30 m), and
    no relation < 1 s with a rotational error above 3 deg (35 deg before stale scans 11550-11554 stopped
    derailing the next ones, see idc's module docstring; from start scan 3 the relation of scans 8420-8421
    reached 3.8 deg, a neighbouring minimum accepted unchecked, until the rotation guard could narrow for
    good odometry; benchmarks/scanmatch.py measures all starts). Runs in ~20 s."""
    from gndreplay.io import read_ticks

    ticks = list(read_ticks(datasets / "carmen" / "intel.clf.bz2"))
    relations = load_relations(datasets / "relations" / "intel.relations")
    idc = matcher_report(correct_trajectory(ticks, make_matcher("idc")), relations).relations
    odom = matcher_report(correct_trajectory(ticks, make_matcher("odom")), relations).relations
    assert idc is not None and odom is not None and idc.unmatched == 0
    assert idc.trans_mean_m < 0.220 and idc.trans_mean_m < odom.trans_mean_m, idc.trans_mean_m
    assert idc.span("<1 s").trans_mean_m < 0.5 * odom.span("<1 s").trans_mean_m
    assert idc.span("<1 s").rot_max_deg < 3.0, idc.span("<1 s").rot_max_deg


@pytest.mark.parametrize("interleaved", [False, True], ids=["decimated", "decimated-interleaved"])
def test_decimated_csail_never_worse_than_odometry(datasets: Path, interleaved: bool) -> None:
    """One scan per 0.2 m or 5 deg of odometry (a log sampled by distance), and the same with four start
    bearings 0.25 deg apart in turn (a ROBOTLASER-style log): idc beats raw odometry and kiss-icp on the
    relations whose scans survive, and the published baseline, with no relation < 1 s above 3 deg."""
    from gndreplay.io import read_ticks

    ticks = keep_by_travel(read_ticks(datasets / "carmen" / "mit-csail.clf.bz2"), 0.2, math.radians(5.0))
    if interleaved:
        ticks = interleave_bearings(ticks, math.radians(0.25), 4)
    relations = load_relations(datasets / "relations" / "mit-csail.relations")
    errs = {}
    for method in ("odom", "idc", "kiss-icp"):
        traj = correct_trajectory(ticks, make_matcher(method))
        errs[method] = relation_errors(traj.t_ns, traj.poses, relations)
    assert errs["idc"].matched > 500 and errs["idc"].matched == errs["odom"].matched
    assert errs["idc"].trans_mean_m < min(errs["odom"].trans_mean_m, errs["kiss-icp"].trans_mean_m, 0.106)
    assert errs["idc"].span("<1 s").rot_max_deg < 3.0, errs["idc"].span("<1 s").rot_max_deg
