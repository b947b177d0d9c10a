"""What every log reader shares: the ``LogReader`` protocol, the stream description and the read report.

A reader is a context manager. ``describe()`` says what the log contains (cheaply, before or without a full
pass); ``ticks()`` streams time-ordered :class:`~gndreplay.types.Tick` records with constant memory; after
the stream is exhausted ``report`` tells what was skipped, reordered, held or dropped on the way.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Protocol, Self

from ..types import Tick

__all__ = [
    "INDEX_CLOCK_PERIOD_NS",
    "LogDescription",
    "LogReader",
    "ReadReport",
    "StreamInfo",
    "StreamRole",
]

#: Period of the index clock given to logs whose timestamps are all zero (10 Hz, a typical laser rate).
INDEX_CLOCK_PERIOD_NS = 100_000_000

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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


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
