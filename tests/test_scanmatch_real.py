"""Scan matching on the real dev logs against the SLAM-benchmark relations (skips without ../shared/datasets).

On MIT CSAIL and ACES, idc's mean translational relation error must beat the published scan-matching
baseline of the benchmark (Kümmerle et al. 2009: CSAIL 0.106 m, ACES 0.173 m), raw odometry and kiss-icp
(at its best setting on these logs, KissParams defaults) measured here on the same ticks. Runs in ~20 s.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from gndreplay.evaluation import RelationStats, load_relations
from gndreplay.scanmatch import IdcParams, correct_trajectory, make_matcher, matcher_report

pytestmark = pytest.mark.slow

LOGS = {"mit-csail": 0.106, "aces": 0.173}  # published scan-matching baseline, mean translational error [m]
Result = tuple[str, dict[str, RelationStats], dict[str, int]]


@pytest.fixture(scope="module", params=sorted(LOGS))
def errors(request: pytest.FixtureRequest, datasets: Path) -> Result:
    from gndreplay.io import read_ticks

    name = request.param
    ticks = list(read_ticks(datasets / "carmen" / f"{name}.clf.bz2"))
    relations = load_relations(datasets / "relations" / f"{name}.relations")
    stats: dict[str, RelationStats] = {}
    failures: dict[str, int] = {}
    for method in ("odom", "idc", "kiss-icp"):
        row = matcher_report(correct_trajectory(ticks, make_matcher(method)), relations)
        assert row.relations is not None
        stats[method], failures[method] = row.relations, row.failures
    return name, stats, failures


def test_all_relations_matched(errors: Result) -> None:
    _, stats, _ = errors
    assert all(s.unmatched == 0 and s.matched > 1000 for s in stats.values())


def test_idc_beats_baseline_odometry_and_kiss(errors: Result) -> None:
    name, stats, failures = errors
    idc = stats["idc"].trans_mean_m
    assert idc < LOGS[name], f"{name}: idc {idc:.3f} m >= published baseline {LOGS[name]} m"
    assert idc < stats["odom"].trans_mean_m, f"{name}: idc {idc:.3f} m >= odometry"
    assert idc < stats["kiss-icp"].trans_mean_m, f"{name}: idc {idc:.3f} m >= kiss-icp"
    assert stats["idc"].rot_mean_deg < stats["odom"].rot_mean_deg
    assert failures["idc"] < 0.01 * stats["idc"].matched  # failures are rare on real data


def test_idc_params_are_the_defaults() -> None:
    """The numbers above are for the defaults; a changed default must be re-benchmarked."""
    p = IdcParams()
    assert (p.map_keyframes, p.n_bins, p.polish_iterations) == (40, 1440, 6)
