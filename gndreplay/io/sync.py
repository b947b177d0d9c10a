"""From a stream of records to time-ordered Ticks, with constant memory.

Two steps, both streaming:

1. :func:`reorder` puts records in stamp order with a bounded heap. A log's line / message order is not its
   time order (CARMEN ``aces.clf`` interleaves ODOM and FLASER up to 0.11 s out of order; a bag is in log-time
   order, not header-stamp order). Records more than ``window`` behind the newest stamp are released; one that
   arrives after the window has passed its stamp cannot be placed and is dropped and counted.
2. :func:`synchronise` pairs each scan with the odometry pose interpolated at the scan stamp (linear in x, y,
   shortest arc in theta), the ground-truth pose likewise, and the last command at or before it (a command
   record, or with ``cmd_from_odom`` the velocities of odometry samples from the first non-zero one on:
   CARMEN ODOM tv/rv). A scan waits (bounded in time and count) for the first odometry sample at or after
   its stamp; scans before the first or after the last odometry sample take the nearest sample and are
   counted. Every record is first put on the replay's microsecond clock, and each tick's scan and poses
   in one representation (:mod:`.canonical`), so that a log and its conversion to another container
   replay alike.

Both steps update a :class:`SyncStats`, which becomes the reader's :class:`~gndreplay.io.base.ReadReport`.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..types import NS_PER_S, Command, Odometry, Pose2D, Scan, Tick
from .base import ReadReport
from .canonical import canonical_pose, canonical_scan, canonical_stamp

__all__ = [
    "DEFAULT_SYNC",
    "CmdEvent",
    "Event",
    "OdomEvent",
    "PoseMode",
    "ScanEvent",
    "SyncOptions",
    "SyncStats",
    "TruthEvent",
    "interpolate_pose",
    "reorder",
    "synchronise",
    "wrap",
]

MAX_EXAMPLES = 5


@dataclass(frozen=True, slots=True)
class ScanEvent:
    """A scan, with the odometry / reference pose recorded in the same record (CARMEN FLASER), if any."""

    t_ns: int
    scan: Scan
    odom: Pose2D | None = None
    truth: Pose2D | None = None


@dataclass(frozen=True, slots=True)
class OdomEvent:
    """An odometry sample (robot pose in the odometry frame)."""

    t_ns: int
    odom: Odometry


@dataclass(frozen=True, slots=True)
class TruthEvent:
    """A ground-truth / reference pose sample."""

    t_ns: int
    pose: Pose2D


@dataclass(frozen=True, slots=True)
class CmdEvent:
    """A recorded velocity command."""

    t_ns: int
    cmd: Command


Event = ScanEvent | OdomEvent | TruthEvent | CmdEvent

#: Where a tick's pose comes from: a separate stream (interpolated), the scan record itself, or nowhere.
PoseMode = Literal["stream", "embedded", "none"]


@dataclass(frozen=True, slots=True)
class SyncOptions:
    """Bounds of the streaming sync; the defaults suit 1-100 Hz lasers and odometry.

    Attributes:
        reorder_window_ns: how far behind the newest stamp a record may arrive and still be placed.
        max_buffered: records held by the reorder heap at most (memory bound; older ones are released).
        max_wait_ns: how long (in log time) a scan waits for the odometry sample after it.
        max_pending: scans held waiting for odometry at most (memory bound).
        gap_ns: an interval between consecutive scans above this is reported as a gap.
    """

    reorder_window_ns: int = 2 * NS_PER_S
    max_buffered: int = 20_000
    max_wait_ns: int = 2 * NS_PER_S
    max_pending: int = 2_000
    gap_ns: int = NS_PER_S


#: The default bounds (a module-level instance, so it can be a default argument).
DEFAULT_SYNC = SyncOptions()


@dataclass(slots=True)
class SyncStats:
    """Mutable counters filled while streaming; ``to_report()`` freezes them."""

    scans: int = 0
    records: int = 0
    malformed: int = 0
    malformed_examples: list[str] = field(default_factory=list)
    out_of_order: int = 0
    time_reversals: int = 0
    late_dropped: int = 0
    scans_without_odom_before: int = 0
    scans_without_odom_after: int = 0
    scans_dropped_no_odom: int = 0
    gaps: int = 0
    max_gap_ns: int = 0
    index_clock: bool = False
    warnings: list[str] = field(default_factory=list)
    sensor_pose_source: str = "none"

    def add_malformed(self, where: str) -> None:
        """Count a skipped record; keep the first few descriptions."""
        self.malformed += 1
        if len(self.malformed_examples) < MAX_EXAMPLES:
            self.malformed_examples.append(where)

    def use_sensor_pose_source(self, source: str) -> None:
        """Record that the scans from here on take their laser pose from ``source`` (a change mid-log is
        appended: ``"config default then log"``)."""
        if source != self.sensor_pose_source.rsplit(" then ", 1)[-1]:
            self.sensor_pose_source += f" then {source}"

    def to_report(self) -> ReadReport:
        return ReadReport(
            scans=self.scans,
            records=self.records,
            malformed=self.malformed,
            malformed_examples=tuple(self.malformed_examples),
            out_of_order=self.out_of_order,
            time_reversals=self.time_reversals,
            late_dropped=self.late_dropped,
            scans_without_odom_before=self.scans_without_odom_before,
            scans_without_odom_after=self.scans_without_odom_after,
            scans_dropped_no_odom=self.scans_dropped_no_odom,
            gaps=self.gaps,
            max_gap_s=self.max_gap_ns / NS_PER_S,
            index_clock=self.index_clock,
            warnings=tuple(self.warnings),
            sensor_pose_source=self.sensor_pose_source,
        )


def wrap(a: float) -> float:
    """Wrap an angle [rad] to (-pi, pi] (scalar twin of ``geometry.wrap_angle``; in-range values kept)."""
    if -math.pi < a <= math.pi:
        return a
    w = math.pi - (math.pi - a) % (2.0 * math.pi)
    return w if w > -math.pi else math.pi


def interpolate_pose(t_ns: int, t0_ns: int, p0: Pose2D, t1_ns: int, p1: Pose2D) -> Pose2D:
    """Pose at ``t_ns`` between samples (t0, p0) and (t1, p1): linear in x, y, shortest arc in theta."""
    if t1_ns == t0_ns or t_ns >= t1_ns:
        return p1
    if t_ns <= t0_ns:
        return p0
    f = (t_ns - t0_ns) / (t1_ns - t0_ns)
    dth = wrap(p1.theta - p0.theta)
    return Pose2D(p0.x + f * (p1.x - p0.x), p0.y + f * (p1.y - p0.y), wrap(p0.theta + f * dth))


def reorder(events: Iterable[Event], stats: SyncStats, opts: SyncOptions = DEFAULT_SYNC) -> Iterator[Event]:
    """Yield ``events`` in stamp order using a heap bounded by a time window and a record count.

    Records equal in stamp keep their input order. A record stamped before one already yielded is dropped
    and counted in ``stats.late_dropped``; out-of-order and per-stream reversals are counted too.

    Yields:
        the events, non-decreasing in ``t_ns``.
    """
    heap: list[tuple[int, int, Event]] = []
    push, pop = heapq.heappush, heapq.heappop
    newest = last_out = -(2**63)
    last_by_kind: dict[type, int] = {}
    window, max_buffered = opts.reorder_window_ns, opts.max_buffered
    records = reversals = out_of_order = late = 0
    try:
        for seq, e in enumerate(events):
            t = e.t_ns
            records += 1
            kind = type(e)
            if t < last_by_kind.get(kind, t):
                reversals += 1
            last_by_kind[kind] = t
            if t > newest:
                newest = t
            elif t < newest:
                out_of_order += 1
            if t < last_out:
                late += 1
                continue
            push(heap, (t, seq, e))
            while heap[0][0] < newest - window or len(heap) > max_buffered:
                last_out, _, e_out = pop(heap)
                yield e_out
                if not heap:
                    break
        while heap:
            yield pop(heap)[2]
    finally:
        stats.records += records
        stats.time_reversals += reversals
        stats.out_of_order += out_of_order
        stats.late_dropped += late


@dataclass(slots=True)
class _Pending:
    ev: ScanEvent
    cmd: Command | None
    odom: Pose2D | None = None
    truth: Pose2D | None = None
    truth_done: bool = False


def synchronise(
    events: Iterable[Event],
    stats: SyncStats,
    *,
    odom_mode: PoseMode,
    truth_mode: PoseMode = "none",
    opts: SyncOptions = DEFAULT_SYNC,
    cmd_from_odom: bool = False,
) -> Iterator[Tick]:
    """Turn time-ordered events into Ticks (see the module docstring for the rules).

    Args:
        events: records in non-decreasing stamp order (the output of :func:`reorder`).
        stats: counters to update.
        odom_mode: "stream" interpolates OdomEvents, "embedded" uses ``ScanEvent.odom``, "none" gives the
            identity pose to every tick.
        truth_mode: the same for the ground-truth pose (``Tick.truth``); "none" leaves it None.
        opts: wait bounds and the gap threshold.
        cmd_from_odom: OdomEvents are also commands (their ``v_mps``, ``w_radps``; CARMEN ODOM tv/rv), with
            any ``odom_mode``, from the first one with a non-zero velocity on (before it a log that records
            no velocities cannot be told from one that commanded a stop: no command).

    Yields:
        Ticks numbered from 0, in stamp order.
    """
    pending: deque[_Pending] = deque()
    odom_prev: tuple[int, Pose2D] | None = None
    truth_prev: tuple[int, Pose2D] | None = None
    last_cmd: Command | None = None
    odom_commands = False  # cmd_from_odom: a non-zero odometry velocity was seen
    last_scan_t: int | None = None
    index = 0
    identity = Pose2D(0.0, 0.0, 0.0)
    bearings: dict[tuple[int, float, float], NDArray[np.float64]] = {}

    def emit(p: _Pending) -> Tick:
        nonlocal index, last_scan_t
        t = p.ev.t_ns
        if last_scan_t is not None:
            dt = t - last_scan_t
            if dt > opts.gap_ns:
                stats.gaps += 1
            stats.max_gap_ns = max(stats.max_gap_ns, dt)
        last_scan_t = t
        truth = canonical_pose(p.truth) if p.truth is not None else None
        tick = Tick(index=index, t_ns=t, scan=canonical_scan(p.ev.scan, bearings),
                    odom=canonical_pose(p.odom or identity), cmd=p.cmd, truth=truth)
        index += 1
        stats.scans += 1
        return tick

    def ready(p: _Pending) -> bool:
        return (odom_mode != "stream" or p.odom is not None) and (truth_mode != "stream" or p.truth_done)

    def force(p: _Pending) -> bool:
        """Complete a scan that waited too long; False if it must be dropped (no odometry at all)."""
        if odom_mode == "stream" and p.odom is None:
            if odom_prev is None:
                stats.scans_dropped_no_odom += 1
                return False
            p.odom = odom_prev[1]
            stats.scans_without_odom_after += 1
        p.truth_done = True
        return True

    def overdue(p: _Pending, now: int) -> bool:
        """Waited too long (in log time or in count); scans before the first odometry wait on count only."""
        if len(pending) > opts.max_pending:
            return True
        if now - p.ev.t_ns <= opts.max_wait_ns:
            return False
        return not (odom_mode == "stream" and p.odom is None and odom_prev is None)

    for e in map(canonical_event, events):
        if isinstance(e, ScanEvent):
            p = _Pending(e, last_cmd)
            if odom_mode == "embedded":
                p.odom = e.odom
            elif odom_mode == "stream" and odom_prev is not None and odom_prev[0] == e.t_ns:
                p.odom = odom_prev[1]  # a sample stamped exactly at the scan, read before it
            if truth_mode == "embedded":
                p.truth, p.truth_done = e.truth, True
            elif truth_mode == "stream" and truth_prev is not None and truth_prev[0] == e.t_ns:
                p.truth, p.truth_done = truth_prev[1], True
            pending.append(p)
        elif isinstance(e, OdomEvent):
            if odom_mode == "stream":
                pose = e.odom.pose
                for p in pending:
                    if p.odom is None and p.ev.t_ns <= e.t_ns:
                        if odom_prev is None:
                            p.odom = pose
                            if p.ev.t_ns < e.t_ns:
                                stats.scans_without_odom_before += 1
                        else:
                            p.odom = interpolate_pose(p.ev.t_ns, odom_prev[0], odom_prev[1], e.t_ns, pose)
                odom_prev = (e.t_ns, pose)
            v, w = e.odom.v_mps, e.odom.w_radps
            if cmd_from_odom and (odom_commands or v != 0.0 or w != 0.0):
                odom_commands = True
                last_cmd = _set_command(pending, Command(e.t_ns, v, w))
        elif isinstance(e, TruthEvent) and truth_mode == "stream":
            for p in pending:
                if not p.truth_done and p.ev.t_ns <= e.t_ns:
                    if truth_prev is not None:
                        p.truth = interpolate_pose(p.ev.t_ns, truth_prev[0], truth_prev[1], e.t_ns, e.pose)
                    p.truth_done = True
            truth_prev = (e.t_ns, e.pose)
        elif isinstance(e, CmdEvent):
            last_cmd = _set_command(pending, e.cmd)
        now = e.t_ns
        # release only once time has moved past a scan, so records stamped exactly at it are applied too
        while pending and ((now > pending[0].ev.t_ns and ready(pending[0])) or overdue(pending[0], now)):
            p = pending.popleft()
            if ready(p) or force(p):
                yield emit(p)
    while pending:
        p = pending.popleft()
        if ready(p) or force(p):
            yield emit(p)


def _set_command(pending: Iterable[_Pending], cmd: Command) -> Command:
    """A new command: also the command of the scans waiting with exactly its stamp ("at or before" them)."""
    for p in pending:
        if p.ev.t_ns == cmd.t_ns:
            p.cmd = cmd
    return cmd


def canonical_event(e: Event) -> Event:
    """The event on the replay's microsecond clock (see :mod:`.canonical`)."""
    t = canonical_stamp(e.t_ns)
    if t == e.t_ns and not (isinstance(e, CmdEvent) and e.cmd.t_ns != t):
        return e
    if isinstance(e, ScanEvent):
        return ScanEvent(t, replace(e.scan, t_ns=t), e.odom, e.truth)
    if isinstance(e, CmdEvent):
        return CmdEvent(t, replace(e.cmd, t_ns=canonical_stamp(e.cmd.t_ns)))
    return replace(e, t_ns=t)


def with_index_clock(e: Event, t_ns: int) -> Event:
    """The same event restamped (used for logs without timestamps)."""
    if isinstance(e, ScanEvent):
        return ScanEvent(t_ns, replace(e.scan, t_ns=t_ns), e.odom, e.truth)
    if isinstance(e, OdomEvent):
        return OdomEvent(t_ns, replace(e.odom, t_ns=t_ns))
    if isinstance(e, TruthEvent):
        return TruthEvent(t_ns, e.pose)
    return CmdEvent(t_ns, replace(e.cmd, t_ns=t_ns))
