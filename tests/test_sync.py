"""io/sync.py: reorder window, odometry interpolation at scan stamps, held / dropped scans, commands."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gndreplay.io.sync import (
    CmdEvent,
    Event,
    OdomEvent,
    ScanEvent,
    SyncOptions,
    SyncStats,
    TruthEvent,
    interpolate_pose,
    reorder,
    synchronise,
    wrap,
)
from gndreplay.types import NS_PER_S, Command, Odometry, Pose2D, Scan

MS = 1_000_000


def scan(t: int) -> ScanEvent:
    return ScanEvent(t, Scan(t, np.ones(3), np.array([-0.1, 0.0, 0.1]), 10.0))


def odom(t: int, x: float, y: float = 0.0, th: float = 0.0) -> OdomEvent:
    return OdomEvent(t, Odometry(t, Pose2D(x, y, th)))


def run(events: list[Event], **kw: object) -> tuple[list, SyncStats]:
    stats = SyncStats()
    opts = kw.pop("opts", SyncOptions())
    assert isinstance(opts, SyncOptions)
    ticks = list(synchronise(reorder(events, stats, opts), stats, opts=opts, **kw))  # type: ignore[arg-type]
    return ticks, stats


def test_records_are_put_on_the_microsecond_clock() -> None:
    """A bag's stamps went through float seconds (+-120 ns at 1e9 s): on the replay's clock they are the
    CARMEN file's microseconds again, and the odometry is interpolated there."""
    t0 = 1_134_864_629_895_182_000
    ticks, _ = run([odom(t0 - 100 * MS + 37, 0.0), scan(t0 - 106), odom(t0 + 100 * MS - 91, 2.0)],
                   odom_mode="stream")
    assert ticks[0].t_ns == ticks[0].scan.t_ns == t0
    assert ticks[0].odom.x == 1.0


def test_wrap_matches_half_open_interval() -> None:
    assert wrap(math.pi) == math.pi
    assert wrap(-math.pi) == pytest.approx(math.pi)
    assert wrap(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap(-7.0) == pytest.approx(-7.0 + 2 * math.pi)
    assert wrap(0.25) == 0.25


def test_interpolate_pose_linear_and_shortest_arc() -> None:
    p0, p1 = Pose2D(0.0, 0.0, 3.0), Pose2D(2.0, 4.0, -3.0)  # crossing +-pi: the short way is through pi
    mid = interpolate_pose(5, 0, p0, 10, p1)
    assert (mid.x, mid.y) == (1.0, 2.0)
    assert mid.theta == pytest.approx(math.pi)
    quarter = interpolate_pose(25, 0, p0, 100, p1)
    assert quarter.theta == pytest.approx(3.0 + 0.25 * (2 * math.pi - 6.0))
    assert interpolate_pose(0, 0, p0, 10, p1) == p0
    assert interpolate_pose(10, 0, p0, 10, p1) == p1
    assert interpolate_pose(7, 7, p0, 7, p1) == p1


def test_reorder_sorts_within_window_and_counts() -> None:
    ts = [0, 30, 10, 20, 50, 40, 60]
    stats = SyncStats()
    out = [
        e.t_ns for e in reorder([scan(t * MS) for t in ts], stats, SyncOptions(reorder_window_ns=100 * MS))
    ]
    assert out == sorted(t * MS for t in ts)
    assert stats.out_of_order == 3  # 10, 20, 40 arrive after a later stamp
    assert stats.time_reversals == 2  # 30 -> 10 and 50 -> 40 within the scan stream
    assert stats.late_dropped == 0
    assert stats.records == len(ts)


def test_reorder_drops_what_arrives_after_the_window() -> None:
    stats = SyncStats()
    events = [scan(t * MS) for t in (0, 100, 200, 300, 50, 400)]
    out = [e.t_ns // MS for e in reorder(events, stats, SyncOptions(reorder_window_ns=120 * MS))]
    assert out == [0, 100, 200, 300, 400]
    assert stats.late_dropped == 1


def test_reorder_memory_is_bounded_by_max_buffered() -> None:
    stats = SyncStats()
    opts = SyncOptions(reorder_window_ns=10**18, max_buffered=4)
    seen = []
    held_max = 0
    for produced, e in enumerate(reorder((scan(t) for t in range(100)), stats, opts), start=1):
        seen.append(e.t_ns)
        held_max = max(held_max, stats.records - produced)
    assert seen == list(range(100))
    assert held_max <= 5


def test_scan_gets_odometry_interpolated_at_its_stamp() -> None:
    ticks, stats = run(
        [odom(0, 0.0), scan(25 * MS), odom(100 * MS, 1.0, 2.0, 0.4), scan(100 * MS)], odom_mode="stream"
    )
    assert [t.index for t in ticks] == [0, 1]
    assert ticks[0].odom == Pose2D(0.25, 0.5, pytest.approx(0.1))
    assert ticks[1].odom == Pose2D(1.0, 2.0, 0.4)
    assert stats.scans == 2 and stats.scans_without_odom_before == 0 and stats.scans_without_odom_after == 0


def test_scans_outside_the_odometry_span_take_the_nearest_sample_and_are_counted() -> None:
    events = [scan(0), scan(10 * MS), odom(20 * MS, 1.0), scan(30 * MS), odom(40 * MS, 2.0), scan(50 * MS)]
    ticks, stats = run(events, odom_mode="stream")
    assert [t.odom.x for t in ticks] == [1.0, 1.0, 1.5, 2.0]
    assert stats.scans_without_odom_before == 2
    assert stats.scans_without_odom_after == 1


def test_a_scan_waits_at_most_max_wait_then_holds_the_last_odometry() -> None:
    opts = SyncOptions(max_wait_ns=1 * NS_PER_S)
    events = [odom(0, 1.0), scan(10 * MS), scan(2 * NS_PER_S), odom(3 * NS_PER_S, 4.0)]
    ticks, stats = run(events, odom_mode="stream", opts=opts)
    assert ticks[0].odom.x == 1.0  # released after the wait: held, counted
    assert ticks[1].odom.x == pytest.approx(1.0 + 3.0 * 2 / 3)
    assert stats.scans_without_odom_after == 1


def test_scans_with_no_odometry_at_all_within_the_buffer_are_dropped() -> None:
    opts = SyncOptions(max_pending=3)
    ticks, stats = run([scan(t * MS) for t in range(6)] + [odom(10 * MS, 1.0)], odom_mode="stream", opts=opts)
    assert stats.scans_dropped_no_odom == 3  # at most 3 wait; older ones go
    assert [t.t_ns // MS for t in ticks] == [3, 4, 5]
    assert [t.index for t in ticks] == [0, 1, 2]


def test_embedded_and_absent_odometry() -> None:
    e = ScanEvent(5, Scan(5, np.ones(1), np.zeros(1), 1.0), odom=Pose2D(1.0, 2.0, 3.0))
    ticks, _ = run([e, odom(6, 9.0)], odom_mode="embedded")
    assert ticks[0].odom == Pose2D(1.0, 2.0, 3.0)
    ticks, _ = run([scan(1), odom(2, 9.0)], odom_mode="none")
    assert ticks[0].odom == Pose2D(0.0, 0.0, 0.0)


def test_last_command_at_or_before_the_scan_is_attached() -> None:
    c1, c2, c3 = (CmdEvent(t, Command(t, v, 0.0)) for t, v in ((0, 0.1), (20 * MS, 0.2), (40 * MS, 0.3)))
    events: list[Event] = [c1, scan(10 * MS), c2, scan(20 * MS), c3, scan(30 * MS), odom(50 * MS, 0.0)]
    ticks, _ = run(events, odom_mode="none")
    assert [t.cmd.v_mps for t in ticks] == [0.1, 0.2, 0.2]
    ticks, _ = run([scan(0), CmdEvent(0, Command(0, 0.5, 0.0))], odom_mode="none")
    assert ticks[0].cmd is not None and ticks[0].cmd.v_mps == 0.5  # same stamp, read after the scan


def test_truth_is_interpolated_and_none_outside_its_span() -> None:
    events: list[Event] = [
        scan(0),
        TruthEvent(10 * MS, Pose2D(0.0, 0.0, 0.0)),
        scan(15 * MS),
        TruthEvent(20 * MS, Pose2D(1.0, 0.0, 0.0)),
        scan(30 * MS),
    ]
    ticks, _ = run(events, odom_mode="none", truth_mode="stream")
    assert ticks[0].truth is None
    assert ticks[1].truth == Pose2D(0.5, 0.0, 0.0)
    assert ticks[2].truth is None


def test_gaps_are_counted_and_the_longest_kept() -> None:
    ticks, stats = run(
        [scan(0), scan(100 * MS), scan(3 * NS_PER_S), scan(3 * NS_PER_S + 100 * MS)], odom_mode="none"
    )
    assert len(ticks) == 4
    assert stats.gaps == 1
    assert stats.to_report().max_gap_s == pytest.approx(2.9)


def test_report_keeps_the_first_malformed_examples() -> None:
    stats = SyncStats()
    for i in range(8):
        stats.add_malformed(f"line {i}: bad")
    rep = stats.to_report()
    assert rep.malformed == 8
    assert rep.malformed_examples == tuple(f"line {i}: bad" for i in range(5))


def test_report_to_dict_is_json_ready() -> None:
    import json

    stats = SyncStats()
    stats.add_malformed("line 3: bad")
    stats.warnings.append("w")
    d = stats.to_report().to_dict()
    assert d["malformed"] == 1 and d["malformed_examples"] == ["line 3: bad"] and d["warnings"] == ["w"]
    assert json.loads(json.dumps(d)) == d
