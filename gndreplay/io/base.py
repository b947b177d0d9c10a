"""What every log reader shares: the ``LogReader`` protocol, the stream description and the read report.

A reader is a context manager. ``describe()`` says what the log contains (cheaply, before or without a full
pass); ``ticks()`` streams time-ordered :class:`~gndreplay.types.Tick` records with constant memory; after
the stream is exhausted ``report`` tells what was skipped, reordered, held or dropped on the way.
"""

from __future__ import annotations

import math
import os
import stat
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Protocol, Self

from ..types import NS_PER_S, Pose2D, Tick

__all__ = [
    "INDEX_CLOCK_PERIOD_NS",
    "MAX_ABS_BEARING_RAD",
    "MAX_ABS_POSITION_M",
    "MAX_ABS_TIME_NS",
    "MAX_BEAMS",
    "MAX_RANGE_LIMIT_M",
    "MAX_SPEED",
    "Closing",
    "LogDescription",
    "LogReader",
    "ReadReport",
    "SensorPoseSource",
    "StreamInfo",
    "StreamRole",
    "check_beams",
    "check_bearings",
    "check_pose",
    "check_speed",
    "check_time",
    "special_file_kind",
]

_SPECIAL_KINDS = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def special_file_kind(path: Path) -> str | None:
    """``"a FIFO"``, ``"a socket"``, ... for a path that is neither a regular file nor a folder (reading it
    could block forever or never end); None otherwise, and for a missing path. Never opens the path."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    return next((what for test, what in _SPECIAL_KINDS if test(mode)), None)


#: Period of the index clock given to logs whose timestamps are all zero (10 Hz, a typical laser rate).
INDEX_CLOCK_PERIOD_NS = 100_000_000

# Bounds of what a reader hands downstream: a value outside them comes from a corrupt record, not a robot,
# and could overflow int64 arithmetic or allocate absurd grids later. Readers raise ValueError (a malformed
# record, skipped and counted) through the checks below.
#: |stamp| bound (about year 2112): the difference of two stamps still fits in int64 ns.
MAX_ABS_TIME_NS = 4_500_000_000 * NS_PER_S
#: |x|, |y| bound of poses [m] (1000 km).
MAX_ABS_POSITION_M = 1e6
#: |theta| bound before wrapping [rad] (unwrapped odometry headings stay far below it).
MAX_ABS_HEADING_RAD = 1e6
#: |bearing| bound of laser beams [rad].
MAX_ABS_BEARING_RAD = 4.0 * math.pi
#: most beams a scan may have (a 2D laser has at most a few thousand; 100,000 float64 ranges are 800 KB).
MAX_BEAMS = 100_000
#: largest maximum range a laser may declare [m].
MAX_RANGE_LIMIT_M = 1e5
#: |speed| bound of recorded commands and odometry twists [m/s, rad/s].
MAX_SPEED = 1e3


def check_time(t_ns: int) -> int:
    """``t_ns`` if within ``MAX_ABS_TIME_NS``.

    Raises:
        ValueError: out of range.
    """
    if not -MAX_ABS_TIME_NS <= t_ns <= MAX_ABS_TIME_NS:
        raise ValueError(f"timestamp {t_ns / NS_PER_S:.6g} s out of range")
    return t_ns


def check_pose(x: float, y: float, theta: float, what: str = "pose") -> Pose2D:
    """A Pose2D (theta wrapped to (-pi, pi]) from finite values within the bounds.

    Raises:
        ValueError: a non-finite or absurd value (NaN, inf, 1e308 m).
    """
    if not (abs(x) < MAX_ABS_POSITION_M and abs(y) < MAX_ABS_POSITION_M and abs(theta) < MAX_ABS_HEADING_RAD):
        raise ValueError(f"{what} ({x:.6g}, {y:.6g}, {theta:.6g}) is not finite or out of range")
    if -math.pi < theta <= math.pi:
        return Pose2D(x, y, theta)
    w = math.pi - (math.pi - theta) % (2.0 * math.pi)
    return Pose2D(x, y, w if w > -math.pi else math.pi)


def check_speed(v: float, what: str, *, allow_nan: bool = False) -> float:
    """``v`` if finite (or NaN when ``allow_nan``: unknown) and within ``MAX_SPEED``.

    Raises:
        ValueError: infinite, NaN (unless allowed) or absurd.
    """
    if abs(v) <= MAX_SPEED or (allow_nan and math.isnan(v)):
        return v
    raise ValueError(f"{what} {v:.6g} is not finite or out of range")


def check_beams(n: int) -> int:
    """``n`` if a scan of that many beams is within ``MAX_BEAMS`` (checked before arrays are made of them).

    Raises:
        ValueError: more beams than that.
    """
    if n > MAX_BEAMS:
        raise ValueError(f"{n} beams, more than the {MAX_BEAMS} a scan may have")
    return n


def check_bearings(first: float, step: float, n: int) -> None:
    """Check that the n bearings ``first + i * step`` are finite and within ``MAX_ABS_BEARING_RAD``.

    Raises:
        ValueError: a non-finite or absurd bearing.
    """
    last = first + step * (n - 1) if n > 1 else first
    if not (abs(first) <= MAX_ABS_BEARING_RAD and abs(last) <= MAX_ABS_BEARING_RAD):
        raise ValueError(f"beam bearings from {first:.6g} to {last:.6g} rad are not finite or out of range")


#: Where the laser pose in the base frame comes from: the log's own record (CARMEN laser offset PARAMs or
#: ROBOTLASER lines, a ROS scan in the base frame), the bag's base -> laser transforms, the reader's
#: ``ReadOptions.default_sensor_pose``, or nowhere (the identity; CARMEN's rear laser faces backwards).
SensorPoseSource = Literal["log", "tf", "config default", "none"]

StreamRole = Literal["scan", "odom", "cmd", "truth", "tf", "tf_static", "param", "other"]


@dataclass(frozen=True, slots=True)
class StreamInfo:
    """One stream of a log: a ROS topic, or a CARMEN message type.

    Attributes:
        name: topic (``/scan``) or CARMEN message name (``FLASER``).
        msgtype: ROS message type (``sensor_msgs/msg/LaserScan``) or the CARMEN message name.
        count: number of messages, or None when not known without a full pass.
        role: what gndreplay uses the stream for ("other" when unused).
    """

    name: str
    msgtype: str
    count: int | None
    role: StreamRole = "other"


@dataclass(frozen=True, slots=True)
class LogDescription:
    """What a log contains, as far as the reader knows before streaming it.

    Attributes:
        path: the log.
        format: registry name of the reader ("carmen", "rosbag1", "rosbag2", "mcap").
        streams: every stream, in a stable order.
        scan_stream: name of the stream scans come from.
        odom_source: human-readable odometry source ("ODOM", "FLASER (embedded)", "/odom",
            "/tf odom->base_link",
            "none").
        cmd_stream: recorded velocity commands, if any.
        truth_stream: ground-truth / reference poses, if any.
        start_ns, end_ns: first and last stamp when known from metadata (None for CARMEN before a pass).
        notes: anything worth telling the user (chosen defaults, detected markers).
    """

    path: Path
    format: str
    streams: tuple[StreamInfo, ...]
    scan_stream: str
    odom_source: str
    cmd_stream: str | None = None
    truth_stream: str | None = None
    start_ns: int | None = None
    end_ns: int | None = None
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class ReadReport:
    """What happened while streaming a log (complete once ``ticks()`` is exhausted).

    Attributes:
        scans: ticks yielded.
        records: records (lines / messages) of the streams used, as read.
        malformed: malformed records skipped (CARMEN lines; ROS messages that failed to decode).
        malformed_examples: the first few, as ``"line 42: FLASER declares 181 ranges, found 179"``.
        out_of_order: records stamped earlier than a record read before them (any stream; merged by time).
        time_reversals: records stamped earlier than the previous record of the same stream.
        late_dropped: records that arrived after the reorder window had moved past them (dropped).
        scans_without_odom_before: scans with no odometry sample before them (took the first one after).
        scans_without_odom_after: scans with no odometry sample after them (held the last one before).
        scans_dropped_no_odom: scans dropped because no odometry arrived while they waited.
        gaps: intervals between consecutive scans longer than the gap threshold.
        max_gap_s: the longest interval between consecutive scans [s].
        index_clock: True when the log had no timestamps and an index clock was used.
        warnings: messages for the user (e.g. the index clock).
        sensor_pose_source: where the scans' laser pose in the base frame came from (a
            ``SensorPoseSource``; several joined by " then " when a CARMEN PARAM line changed it mid-log).
    """

    scans: int = 0
    records: int = 0
    malformed: int = 0
    malformed_examples: tuple[str, ...] = ()
    out_of_order: int = 0
    time_reversals: int = 0
    late_dropped: int = 0
    scans_without_odom_before: int = 0
    scans_without_odom_after: int = 0
    scans_dropped_no_odom: int = 0
    gaps: int = 0
    max_gap_s: float = 0.0
    index_clock: bool = False
    warnings: tuple[str, ...] = field(default=())
    sensor_pose_source: str = "none"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


class Closing:
    """A reader's context manager: ``with`` closes it on the way out (the reader defines ``close``)."""

    def close(self) -> None:
        """Release the file handles."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class LogReader(Protocol):
    """A log opened for reading; close it (or use ``with``) when done."""

    path: Path
    format_name: str

    def __enter__(self) -> Self: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...

    def close(self) -> None:
        """Release the file handles."""
        ...

    def describe(self) -> LogDescription:
        """What the log contains, without a full pass."""
        ...

    def records_commands(self) -> bool:
        """Whether the log records velocity commands (``Tick.cmd``); may read the log once to find out
        (CARMEN: whether any ODOM tv/rv is non-zero), unlike ``describe``."""
        ...

    def fraction_read(self) -> float | None:
        """Share of the log read by the pass in progress, when the reader knows it (for progress bars when
        the description gives no duration); None otherwise."""
        ...

    def ticks(self) -> Iterator[Tick]:
        """Time-ordered ticks (odometry interpolated at each scan stamp).

        Raises:
            LogFormatError: the log is unreadable, has no scans, or (strict) has a malformed record.
        """
        ...

    @property
    def report(self) -> ReadReport:
        """The read report so far (complete once ``ticks()`` is exhausted)."""
        ...
