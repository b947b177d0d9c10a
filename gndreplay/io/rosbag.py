"""ROS1 ``.bag``, ROS2 bag folders (sqlite3 / mcap storage) and bare ``.mcap`` files, via rosbags.

- Scans: ``sensor_msgs/LaserScan``; sensor time = ``header.stamp`` (the log time only when the stamp is 0).
  Ranges >= ``range_max`` and +inf (REP 117 "no return") become +inf; NaN, -inf and ranges < ``range_min``
  become nan (invalid).
- Odometry: ``nav_msgs/Odometry``, or when the bag has none, ``/tf`` ``odom -> base`` transforms.
- Commands: ``geometry_msgs/Twist`` (stamped with the log time) or ``TwistStamped``.
- Ground truth: an Odometry / PoseStamped / PoseWithCovarianceStamped topic named like a ground truth
  (``truth``, ``ground``, ``gt``, ``mocap``, ``vicon``).
- Laser mounting: the chain base -> laser frame from ``/tf_static`` (or static-looking ``/tf`` edges); the
  identity when the scan's frame is the base frame; else (no such chain, no frame_id, no scan)
  ``ReadOptions.default_sensor_pose`` when given, or the identity. The report's ``sensor_pose_source`` says
  which.
- Topic choice: a single candidate is taken; among several, the conventional name (``/scan``, ``/odom``,
  ``/cmd_vel``) if present; otherwise, or for a topic that is not in the bag, a LogFormatError lists the
  candidates.

- Values: stamps, poses, twists, bearings, range_max and beam counts (``MAX_BEAMS``) outside the bounds of
  :mod:`.base` make a message malformed (skipped and counted; an error with ``strict``); what rosbags read
  from a bag's index or ``metadata.yaml`` (topic names, types, counts) is type-checked before use.

rosbags' storage readers (the ones AnyReader wraps) give the raw messages; the few fields used are decoded
directly by :mod:`.rosraw` (about 4x faster than rosbags' generic deserialiser, no per-bag code generation,
and no need for message definitions in the bag). Big-endian CDR, which no decoder here reads, goes through
rosbags' deserialiser with the default ROS2 Humble typestore. Errors of the reader library (including its
AssertionError on bags with odd index records) are translated into LogFormatError naming the file, at this
boundary only.
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import struct
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import LogFormatError
from ..types import NS_PER_S, Command, Odometry, Pose2D, Scan, Tick
from . import rosraw
from .base import (
    MAX_RANGE_LIMIT_M,
    Closing,
    LogDescription,
    ReadReport,
    SensorPoseSource,
    StreamInfo,
    StreamRole,
    check_beams,
    check_bearings,
    check_pose,
    check_speed,
    check_time,
)
from .options import DEFAULT_READ, ReadOptions
from .sync import (
    CmdEvent,
    Event,
    OdomEvent,
    PoseMode,
    ScanEvent,
    SyncStats,
    TruthEvent,
    reorder,
    synchronise,
    wrap,
)

__all__ = ["LASERSCAN", "ODOMETRY", "RosbagReader", "check_not_legacy", "clean_ros_ranges"]

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

LASERSCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TFMESSAGE = "tf2_msgs/msg/TFMessage"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
_TRUTH_RE = re.compile(r"truth|ground|(^|[/_])gt($|[/_])|mocap|vicon|true", re.IGNORECASE)
_PREFERRED = {"scan": "/scan", "odom": "/odom", "cmd": "/cmd_vel"}
_DEFAULT_MAX_RANGE_M = 80.0
_TF_PEEK = 200


def check_not_legacy(path: Path) -> None:
    """Refuse pre-2.0 ROS bags (``#ROSRECORD V1.2``) with a clear message.

    Raises:
        LogFormatError: the file starts with a legacy bag magic.
    """
    if not path.is_file():
        return
    with open(path, "rb") as fh:
        magic = fh.read(16)
    if magic.startswith(b"#ROSRECORD V"):
        version = magic[len(b"#ROSRECORD V") :].split(b"\n")[0].decode("ascii", "replace")
        raise LogFormatError(
            f"{path}: unsupported legacy ROS bag format V{version} "
            "(readable only by ROS1's own rosbag tools; convert it there)"
        )


def clean_ros_ranges(ranges: NDArray[Any], range_min: float, range_max: float) -> F64:
    """LaserScan ranges -> (N,) float64: >= range_max (and +inf) -> +inf; nan, -inf, < range_min -> nan.

    ``range_min`` must be >= 0 (so negative ranges are below it).
    """
    with np.errstate(invalid="ignore"):  # a float32 signalling NaN (corrupt bytes) is "invalid" to widen
        r = np.array(ranges, dtype=np.float64)
    valid = r >= range_min  # False for nan
    np.putmask(r, r >= range_max, np.inf)
    np.putmask(r, ~valid, np.nan)
    return r


def _frame(name: str) -> str:
    return name.lstrip("/")


def _compose(a: Pose2D, b: Pose2D) -> Pose2D:
    c, s = dm.cos(a.theta), dm.sin(a.theta)
    return Pose2D(a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, wrap(a.theta + b.theta))


def _is_odom_edge(parent: str, child: str) -> bool:
    return _frame(parent).split("/")[-1] == "odom" and _frame(child).split("/")[-1].startswith("base")


@dataclass(frozen=True, slots=True)
class _Topic:
    name: str
    msgtype: str
    count: int


def _pick(
    path: Path,
    role: str,
    flag: str,
    candidates: Sequence[str],
    requested: str | None,
    *,
    required: bool,
) -> str | None:
    """Choose a topic among candidates (see the module docstring).

    Raises:
        LogFormatError: ambiguous auto choice, or the requested topic is not a candidate.
    """
    listing = ", ".join(f"{flag} {c}" for c in candidates) or "none"
    if requested is not None:
        if requested in candidates:
            return requested
        raise LogFormatError(f"{path}: no {role} topic {requested!r}; candidates: {listing}")
    if len(candidates) == 1:
        return candidates[0]
    if not candidates:
        if required:
            raise LogFormatError(f"{path}: no scans: no sensor_msgs/LaserScan topic in the bag")
        return None
    preferred = _PREFERRED.get(role)
    if preferred in candidates:
        return preferred
    raise LogFormatError(f"{path}: several {role} topics, choose one: {listing}")


_ROSBAGS_ERRORS: tuple[type[BaseException], ...] | None = None


def rosbags_errors() -> tuple[type[BaseException], ...]:
    """Exception types the reader library (and the raw decoders) raise on bad input (imported lazily).

    rosbags parses bag, sqlite (apsw) and MCAP records and decompresses bz2 / lz4 / zstd chunks without
    converting what those raise on corrupt bytes: a record length read from a damaged file makes it allocate
    petabytes (MemoryError, OverflowError), lz4 raises RuntimeError, zstd its ZstdError, apsw CorruptError.
    This tuple is the one place that lists them; the callers below turn them into LogFormatError.
    """
    global _ROSBAGS_ERRORS
    if _ROSBAGS_ERRORS is None:
        import sqlite3

        import apsw
        from rosbags.highlevel import AnyReaderError
        from rosbags.rosbag1 import ReaderError as ReaderError1
        from rosbags.rosbag2 import ReaderError as ReaderError2
        from rosbags.serde import SerdeError
        from rosbags.typesys import TypesysError

        try:
            from compression.zstd import ZstdError  # type: ignore[import-not-found,unused-ignore]
        except ImportError:
            from backports.zstd import ZstdError

        _ROSBAGS_ERRORS = (
            AnyReaderError,
            ReaderError1,
            ReaderError2,
            SerdeError,
            TypesysError,
            ZstdError,
            apsw.Error,
            sqlite3.Error,
            struct.error,
            EOFError,
            OSError,
            ValueError,
            KeyError,
            IndexError,
            TypeError,
            AssertionError,
            UnicodeError,
            MemoryError,
            OverflowError,
            RuntimeError,
        )
    return _ROSBAGS_ERRORS


def check_index(path: Path, reader: Any) -> None:
    """Check the types and ranges of what rosbags read from a bag's index or ``metadata.yaml`` (it trusts
    them: a topic named ``1e300`` is a float, a message count a mapping).

    Raises:
        LogFormatError: a topic name / type that is not text, or a message count that is not a count.
    """
    where = f"{path / 'metadata.yaml'}" if path.is_dir() else f"{path}: bag index"
    for i, c in enumerate(reader.connections):
        if not (isinstance(c.topic, str) and isinstance(c.msgtype, str)):
            what = f"name {str(c.topic)[:40]!r} and type {str(c.msgtype)[:60]!r}"
            raise LogFormatError(f"{where}: topic {i + 1}: {what} must be text")
        n = c.msgcount
        if not isinstance(n, int) or isinstance(n, bool) or not 0 <= n < 2**63:
            raise LogFormatError(f"{where}: topic {c.topic}: message_count {str(n)[:40]!r} is not a count")


class RosbagReader(Closing):
    """Streams a ROS1 bag, a ROS2 bag folder or a bare MCAP file as time-ordered Ticks.

    Args:
        path: ``.bag`` file, ROS2 bag folder (with ``metadata.yaml``) or ``.mcap`` file.
        options: what to read (``fmt`` is the registry's): the topics override the auto-detected ones
            (``odom_topic="/tf"`` takes odometry from the odom -> base transforms); ``default_sensor_pose``
            is the laser mounting when the bag has no base -> laser transform (see the module docstring).
        format_name: registry name for reports ("rosbag1", "rosbag2", "mcap").

    Raises:
        LogFormatError: missing file, legacy or refused bag, no LaserScan, ambiguous or unknown topic.
    """

    def __init__(
        self, path: Path, *, options: ReadOptions = DEFAULT_READ, format_name: str = "rosbag"
    ) -> None:
        self.path = Path(path)
        self.format_name = format_name
        self._strict = options.strict
        self._sync = options.sync
        self._fallback = options.sensor_pose_fallback()
        self._stats = SyncStats()
        self._angles: dict[tuple[int, float, float], F64] = {}
        self._typestore: Any = None
        self._reader: Any = None
        if not self.path.exists():
            raise LogFormatError(f"{self.path}: no such file or directory")
        check_not_legacy(self.path)
        self._ros1 = self.path.is_file() and self.path.suffix.lower() == ".bag"
        try:
            if self._ros1:
                from rosbags.rosbag1 import Reader as Reader1

                self._reader = Reader1(self.path)
            else:
                from rosbags.rosbag2 import Reader as Reader2

                self._reader = Reader2(self.path)
            self._reader.open()
        except rosbags_errors() as err:
            self._reader = None
            raise LogFormatError(
                f"{self.path}: the ROS bag reader (rosbags) refuses it: {_describe_error(err)}"
            ) from err
        try:
            self._setup(options.scan_topic, options.odom_topic, options.cmd_topic, options.truth_topic)
        except BaseException:
            self.close()
            raise

    # -- setup ------------------------------------------------------------------------------------------
    def _setup(
        self, scan_topic: str | None, odom_topic: str | None, cmd_topic: str | None, truth_topic: str | None
    ) -> None:
        check_index(self.path, self._reader)
        topics: dict[str, _Topic] = {}
        for c in self._reader.connections:
            t = topics.get(c.topic)
            topics[c.topic] = _Topic(c.topic, c.msgtype, (t.count if t else 0) + c.msgcount)
        self.topics = topics

        def of(*types: str) -> list[str]:
            return sorted(n for n, t in topics.items() if t.msgtype in types)

        path = self.path
        scan = _pick(path, "scan", "--scan-topic", of(LASERSCAN), scan_topic, required=True)
        assert scan is not None
        self.scan_topic = scan
        odoms = [n for n in of(ODOMETRY) if not _TRUTH_RE.search(n)]
        truths = [n for n in of(ODOMETRY, POSE_STAMPED, POSE_COV_STAMPED) if _TRUTH_RE.search(n)]
        has_tf = topics.get("/tf", _Topic("", "", 0)).msgtype == TFMESSAGE
        self._tf_child: str | None = None
        self.odom_topic: str | None = None
        candidates = ", ".join(f"--odom-topic {o}" for o in odoms + (["/tf"] if has_tf else [])) or "none"
        if odom_topic is None:
            if odoms:
                self.odom_topic = _pick(path, "odom", "--odom-topic", odoms, None, required=False)
            elif has_tf:
                self._tf_child = self._find_tf_odom()
                self.odom_topic = "/tf" if self._tf_child else None
        elif odom_topic == "/tf" and has_tf:
            self._tf_child = self._find_tf_odom()
            if self._tf_child is None:
                raise LogFormatError(f"{path}: /tf has no odom -> base transform; candidates: {candidates}")
            self.odom_topic = "/tf"
        elif odom_topic in of(ODOMETRY):
            self.odom_topic = odom_topic
        else:
            raise LogFormatError(f"{path}: no odometry topic {odom_topic!r}; candidates: {candidates}")
        self.cmd_topic = _pick(
            path, "cmd", "--cmd-topic", of(TWIST, TWIST_STAMPED), cmd_topic, required=False
        )
        self.truth_topic = _pick(path, "truth", "--truth-topic", truths, truth_topic, required=False)
        self._sensor_pose, self._pose_source, self._pose_note = self._mounting()
        self._stats.sensor_pose_source = self._pose_source

    def _conn(self, topic: str) -> list[Any]:
        return [c for c in self._reader.connections if c.topic == topic]

    def _first(self, topic: str, limit: int = 1) -> list[tuple[int, bytes]]:
        """The first ``limit`` raw messages of a topic (log time, bytes)."""
        out: list[tuple[int, bytes]] = []
        conns = self._conn(topic)
        if not conns:
            return out
        gen = self._reader.messages(connections=conns)
        try:
            for _, t, raw in gen:
                out.append((t, raw))
                if len(out) >= limit:
                    break
        finally:
            gen.close()
        return out

    def _find_tf_odom(self) -> str | None:
        """Child frame of the first ``odom -> base*`` transform in /tf."""
        with _translate(self.path, "reading /tf"):
            for _, raw in self._first("/tf", _TF_PEEK):
                for tr in self._tf(raw):
                    if _is_odom_edge(tr.parent, tr.child):
                        return _frame(tr.child)
        return None

    def _mounting(self) -> tuple[Pose2D, SensorPoseSource, str]:
        """Laser pose in the base frame, its source and a note for the description: from static transforms;
        the identity for a scan in the base frame; else the fallback, or the identity."""
        identity = Pose2D(0.0, 0.0, 0.0)
        with _translate(self.path, "reading the first scan and transforms"):
            first = self._first(self.scan_topic)
            if not first:
                return self._unknown_mounting("no scan")
            laser = _frame(self._scan_fields(first[0][1]).frame_id)
            base = self._tf_child
            if base is None and self.odom_topic and self.topics[self.odom_topic].msgtype == ODOMETRY:
                o = self._first(self.odom_topic)
                base = _frame(self._odom_fields(o[0][1]).child_frame_id) if o else None
            edges: dict[str, tuple[str, Pose2D]] = {}
            for topic, limit in (("/tf", _TF_PEEK), ("/tf_static", 10_000)):
                if self.topics.get(topic, _Topic("", "", 0)).msgtype != TFMESSAGE:
                    continue
                for _, raw in self._first(topic, limit):
                    for tr in self._tf(raw):
                        parent, child = _frame(tr.parent), _frame(tr.child)
                        if parent.split("/")[-1] != "odom" and child not in edges:
                            pose = check_pose(tr.x, tr.y, rosraw.yaw_of(tr.q), "transform")
                            edges[child] = (parent, pose)
        base = base or "base_link"
        if not laser:
            return self._unknown_mounting("the scan has no frame_id")
        if laser == base:
            return identity, "log", "identity (the scan frame is the base frame)"
        pose, frame, seen = identity, laser, set()
        while frame in edges and frame not in seen:
            seen.add(frame)
            parent, p = edges[frame]
            pose = _compose(p, pose)
            if parent == base:
                with _translate(self.path, f"the transform {base} -> {laser}"):
                    mounting = check_pose(pose.x, pose.y, pose.theta, "laser mounting")
                return mounting, "tf", f"tf {base} -> {laser}"
            frame = parent
        return self._unknown_mounting(f"no transform {base} -> {laser} in the bag")

    def _unknown_mounting(self, why: str) -> tuple[Pose2D, SensorPoseSource, str]:
        """The mounting when the bag does not give one: the fallback if any, else the identity."""
        p = self._fallback
        if p is None:
            return Pose2D(0.0, 0.0, 0.0), "none", f"identity ({why})"
        where = f"x {p.x:g} m, y {p.y:g} m, theta {math.degrees(p.theta):g} deg"
        return p, "config default", f"{where} from the configuration ({why})"

    # -- decoding (raw bytes -> fields; big-endian CDR through rosbags) -----------------------------------
    def _fast(self, raw: bytes | memoryview) -> bool:
        return self._ros1 or rosraw.is_little_cdr(raw)

    def _slow(self, raw: bytes | memoryview, msgtype: str) -> Any:
        if self._typestore is None:
            from rosbags.typesys import Stores, get_typestore

            self._typestore = get_typestore(Stores.ROS2_HUMBLE)
        return self._typestore.deserialize_cdr(bytes(raw), msgtype)

    def _scan_fields(self, raw: bytes | memoryview) -> rosraw.ScanFields:
        if self._fast(raw):
            return rosraw.decode_laserscan(raw, not self._ros1)
        m = self._slow(raw, LASERSCAN)
        return rosraw.ScanFields(
            _stamp(m.header),
            m.header.frame_id,
            m.angle_min,
            m.angle_increment,
            m.range_min,
            m.range_max,
            m.ranges,
        )

    def _odom_fields(self, raw: bytes | memoryview) -> rosraw.OdometryFields:
        if self._fast(raw):
            return rosraw.decode_odometry(raw, not self._ros1)
        m = self._slow(raw, ODOMETRY)
        p, tw = m.pose.pose, m.twist.twist
        return rosraw.OdometryFields(
            _stamp(m.header),
            m.child_frame_id,
            p.position.x,
            p.position.y,
            _quat(p.orientation),
            tw.linear.x,
            tw.angular.z,
        )

    def _tf(self, raw: bytes | memoryview) -> list[rosraw.TransformFields]:
        if self._fast(raw):
            return rosraw.decode_tfmessage(raw, not self._ros1)
        m = self._slow(raw, TFMESSAGE)
        return [
            rosraw.TransformFields(_stamp(t.header), t.transform.translation.x, t.transform.translation.y,
                                   _quat(t.transform.rotation), parent=t.header.frame_id,
                                   child=t.child_frame_id)
            for t in m.transforms
        ]

    def _twist(self, raw: bytes | memoryview, stamped: bool) -> rosraw.TwistFields:
        if self._fast(raw):
            return rosraw.decode_twist(raw, not self._ros1, stamped=stamped)
        m = self._slow(raw, TWIST_STAMPED if stamped else TWIST)
        tw = m.twist if stamped else m
        return rosraw.TwistFields(
            _stamp(m.header) if stamped else None, tw.linear.x, tw.linear.y, tw.angular.z
        )

    def _pose(self, raw: bytes | memoryview, msgtype: str) -> rosraw.PoseFields:
        if msgtype == ODOMETRY:
            o = self._odom_fields(raw)
            return rosraw.PoseFields(o.stamp_ns, o.x, o.y, o.q)
        if self._fast(raw):
            return rosraw.decode_pose_stamped(raw, not self._ros1)
        m = self._slow(raw, msgtype)
        p = m.pose.pose if msgtype == POSE_COV_STAMPED else m.pose
        return rosraw.PoseFields(_stamp(m.header), p.position.x, p.position.y, _quat(p.orientation))

    # -- closing (the context manager is base.Closing) -----------------------------------------
    def close(self) -> None:
        """Close the bag (idempotent)."""
        if self._reader is not None:
            reader, self._reader = self._reader, None
            with contextlib.suppress(*rosbags_errors()):
                reader.close()

    # -- description ------------------------------------------------------------------------------------
    @property
    def odom_source(self) -> str:
        if self.odom_topic is None:
            return "none"
        if self.odom_topic == "/tf":
            return f"/tf odom -> {self._tf_child}"
        return self.odom_topic

    @property
    def sensor_pose(self) -> Pose2D:
        return self._sensor_pose

    def fraction_read(self) -> float | None:
        """None: a bag's description gives its time span, which measures progress instead."""
        return None

    def records_commands(self) -> bool:
        """A Twist / TwistStamped command topic was found or given."""
        return self.cmd_topic is not None

    def describe(self) -> LogDescription:
        """Topics, types and counts from the bag's metadata (no message decoded beyond the first few)."""
        roles: dict[str, StreamRole] = {self.scan_topic: "scan"}
        for name, role in ((self.odom_topic, "odom"), (self.cmd_topic, "cmd"), (self.truth_topic, "truth")):
            if name is not None:
                roles[name] = role  # type: ignore[assignment]
        for name in ("/tf", "/tf_static"):
            if name in self.topics and name not in roles:
                roles[name] = "tf" if name == "/tf" else "tf_static"
        streams = tuple(
            StreamInfo(t.name, t.msgtype, t.count, roles.get(t.name, "other"))
            for t in sorted(self.topics.values(), key=lambda t: t.name)
        )
        start, end = self._reader.start_time, self._reader.end_time
        try:
            start, end = check_time(start), check_time(max(start, end - 1))
        except (ValueError, TypeError):  # an empty or damaged index: the span is unknown
            start = end = None
        return LogDescription(
            path=self.path, format=self.format_name, streams=streams, scan_stream=self.scan_topic,
            odom_source=self.odom_source, cmd_stream=self.cmd_topic, truth_stream=self.truth_topic,
            start_ns=start, end_ns=end, notes=(f"laser mounting: {self._pose_note}",)
        )

    @property
    def report(self) -> ReadReport:
        return self._stats.to_report()

    # -- raw access for info (no full decoding) ---------------------------------------------------------
    def raw_messages(self, topic: str) -> Iterator[tuple[int, bytes]]:
        """(log time, raw bytes) of one topic in log-time order, undecoded.

        Raises:
            LogFormatError: the bag is corrupt.
        """
        conns = self._conn(topic)
        if not conns:
            return
        with _translate(self.path, f"reading {topic}"):
            for _, t, raw in self._reader.messages(connections=conns):
                yield t, raw

    def header_stamp(self, raw: bytes | memoryview) -> int:
        """``header.stamp`` [ns] of a raw message that starts with a std_msgs/Header (no decoding).

        Raises:
            ValueError, struct.error: bytes too short.
        """
        return rosraw.header_stamp(raw, not self._ros1)

    def decode_scan(self, raw: bytes | memoryview, t_log: int) -> Scan:
        """A raw LaserScan -> Scan (see ``clean_ros_ranges``; a zero stamp becomes ``t_log``).

        A non-finite or non-positive ``range_max`` means the default 80 m, a bad ``range_min`` 0.

        Raises:
            ValueError, struct.error: bytes that are not a LaserScan, or values out of range (stamp,
                bearings, a range_max above ``MAX_RANGE_LIMIT_M``, more than ``MAX_BEAMS`` beams).
        """
        f = self._scan_fields(raw)
        n = check_beams(len(f.ranges))  # before any array is made from them (the ranges are a view of raw)
        t = check_time(f.stamp_ns or t_log)
        rmax = float(f.range_max)
        if not (math.isfinite(rmax) and rmax > 0.0):
            rmax = _DEFAULT_MAX_RANGE_M
        elif rmax > MAX_RANGE_LIMIT_M:
            raise ValueError(f"range_max {rmax:.6g} m out of range")
        rmin = float(f.range_min)
        if not (math.isfinite(rmin) and 0.0 <= rmin < rmax):
            rmin = 0.0
        if n == 0:
            raise ValueError("LaserScan without ranges")
        key = (n, float(f.angle_min), float(f.angle_increment))
        angles = self._angles.get(key)
        if angles is None:
            check_bearings(key[1], key[2], n)
            angles = key[1] + key[2] * np.arange(n, dtype=np.float64)
            angles.flags.writeable = False
            if len(self._angles) > 64:
                self._angles.clear()
            self._angles[key] = angles
        return Scan(t, clean_ros_ranges(f.ranges, rmin, rmax), angles, rmax, rmin, self._sensor_pose)

    # -- streaming --------------------------------------------------------------------------------------
    def ticks(self) -> Iterator[Tick]:
        """Time-ordered ticks (header stamps; odometry interpolated at each scan stamp).

        Yields:
            one Tick per LaserScan message, in stamp order.

        Raises:
            LogFormatError: corrupt bag, no scans, or (strict) a message that fails to decode.
        """
        stats = SyncStats(sensor_pose_source=self._pose_source)
        self._stats = stats
        odom_mode: PoseMode = "stream" if self.odom_topic else "none"
        truth_mode: PoseMode = "stream" if self.truth_topic else "none"
        events = reorder(self._events(stats), stats, self._sync)
        yield from synchronise(events, stats, odom_mode=odom_mode, truth_mode=truth_mode, opts=self._sync)
        if stats.scans == 0:
            first = stats.malformed_examples[0] if stats.malformed_examples else None
            skipped = f" ({stats.malformed} malformed messages skipped, the first: {first})" if first else ""
            raise LogFormatError(f"{self.path}: no scans on {self.scan_topic}{skipped}")

    def _handlers(self) -> dict[str, Callable[[bytes, int], Event | list[Event]]]:
        h: dict[str, Callable[[bytes, int], Event | list[Event]]] = {self.scan_topic: self._on_scan}
        if self.odom_topic == "/tf":
            h["/tf"] = self._on_tf
        elif self.odom_topic is not None:
            h[self.odom_topic] = self._on_odom
        if self.cmd_topic is not None:
            h[self.cmd_topic] = self._on_cmd
        if self.truth_topic is not None:
            h[self.truth_topic] = self._on_truth
        return h

    def _events(self, stats: SyncStats) -> Iterator[Event]:
        handlers = self._handlers()
        conns = [c for c in self._reader.connections if c.topic in handlers]
        by_id = {id(c): (handlers[c.topic], c) for c in conns}
        self._zero_stamps = 0
        i = 0
        errors = rosbags_errors()
        with _translate(self.path, "reading messages", lambda: f"after message {i}"):
            for conn, t_log, raw in self._reader.messages(connections=conns):
                i += 1
                handler, c = by_id[id(conn)]
                try:
                    ev = handler(raw, t_log)
                except errors as err:
                    where = f"message {i} on {c.topic}: cannot decode {c.msgtype}: {_describe_error(err)}"
                    if self._strict:
                        raise LogFormatError(f"{self.path} {where}") from err
                    stats.add_malformed(where)
                    continue
                if type(ev) is list:
                    yield from ev
                elif ev is not None:
                    yield ev  # type: ignore[misc]
        if self._zero_stamps:
            msg = f"{self.path}: {self._zero_stamps} scans have a zero header stamp; used their log time"
            stats.warnings.append(msg)
            log.warning(msg)

    def _on_scan(self, raw: bytes, t_log: int) -> Event:
        scan = self.decode_scan(raw, t_log)
        if scan.t_ns == t_log and self.header_stamp(raw) == 0:
            self._zero_stamps += 1
        return ScanEvent(scan.t_ns, scan)

    # the handlers raise ValueError on values out of range (see base.check_*): a malformed message
    def _on_odom(self, raw: bytes, t_log: int) -> Event:
        f = self._odom_fields(raw)
        t = check_time(f.stamp_ns or t_log)
        pose = check_pose(f.x, f.y, rosraw.yaw_of(f.q), "odometry pose")
        v = check_speed(f.vx, "odometry velocity", allow_nan=True)
        w = check_speed(f.wz, "odometry turn rate", allow_nan=True)
        return OdomEvent(t, Odometry(t, pose, v, w))

    def _on_tf(self, raw: bytes, t_log: int) -> list[Event]:
        out: list[Event] = []
        for tr in self._tf(raw):
            if _frame(tr.child) == self._tf_child and _is_odom_edge(tr.parent, tr.child):
                t = check_time(tr.stamp_ns or t_log)
                out.append(OdomEvent(t, Odometry(t, check_pose(tr.x, tr.y, rosraw.yaw_of(tr.q), "odom tf"))))
        return out

    def _on_cmd(self, raw: bytes, t_log: int) -> Event:
        assert self.cmd_topic is not None
        stamped = self.topics[self.cmd_topic].msgtype == TWIST_STAMPED
        f = self._twist(raw, stamped)
        t = check_time(f.stamp_ns or t_log)
        v, w, vy = (check_speed(x, "command") for x in (f.vx, f.wz, f.vy))
        return CmdEvent(t, Command(t, v, w, vy))

    def _on_truth(self, raw: bytes, t_log: int) -> Event:
        assert self.truth_topic is not None
        f = self._pose(raw, self.topics[self.truth_topic].msgtype)
        t = check_time(f.stamp_ns or t_log)
        return TruthEvent(t, check_pose(f.x, f.y, rosraw.yaw_of(f.q), "ground-truth pose"))


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * NS_PER_S + int(header.stamp.nanosec)


def _quat(q: Any) -> tuple[float, float, float, float]:
    return (float(q.x), float(q.y), float(q.z), float(q.w))


def _describe_error(err: BaseException) -> str:
    text = str(err).strip().splitlines()[0] if str(err).strip() else ""
    name = type(err).__name__
    if isinstance(err, AssertionError):
        return "inconsistent index records (the library's consistency check failed)"
    if isinstance(err, (MemoryError, OverflowError)):
        return f"{name}: a record length or count beyond what the file can hold"
    return f"{name}: {text}" if text else name


class _translate:
    """Context manager: reader-library errors -> LogFormatError naming the file (and the record if known)."""

    def __init__(self, path: Path, what: str, where: Callable[[], str] | None = None) -> None:
        self.path, self.what, self.where = path, what, where

    def __enter__(self) -> None:
        return None

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> Literal[False]:
        if exc is not None and isinstance(exc, rosbags_errors()) and not isinstance(exc, LogFormatError):
            where = f" {self.where()}" if self.where else ""
            raise LogFormatError(
                f"{self.path}: corrupt or truncated bag ({self.what}{where}): {_describe_error(exc)}"
            ) from exc
        return False
