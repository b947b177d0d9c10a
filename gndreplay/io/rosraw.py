"""Direct decoders for the few ROS message types gndreplay reads, from ROS1 or CDR (little-endian) bytes.

rosbags' generic deserialiser builds a dataclass tree per message (~15-20 us each, plus code generation
when a bag is opened); the replay only needs a handful of fields, so these read them with ``struct`` at
computed offsets and the ranges with one ``np.frombuffer``. Layouts:

- ROS1: fields packed without padding; ``Header`` = ``uint32 seq, uint32 sec, uint32 nsec, string frame_id``;
  strings = ``uint32 length`` + bytes.
- CDR (ROS2): a 4-byte encapsulation header (``00 01`` = little-endian), then fields aligned to their size
  relative to the end of that header; ``Header`` = ``int32 sec, uint32 nanosec, string frame_id``; strings =
  ``uint32 length`` (with the NUL) + bytes + NUL; sequences = ``uint32 count`` + elements.

Every decoder raises one of ``DECODE_ERRORS`` on bytes that do not fit the layout. They read ROS1 and
little-endian CDR only; callers send big-endian CDR (``not is_little_cdr(raw)``) to rosbags.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..types import NS_PER_S

__all__ = [
    "DECODE_ERRORS",
    "OdometryFields",
    "PoseFields",
    "ScanFields",
    "TransformFields",
    "TwistFields",
    "decode_laserscan",
    "decode_odometry",
    "decode_pose_stamped",
    "decode_tfmessage",
    "decode_twist",
    "header_stamp",
    "is_little_cdr",
    "yaw_of",
]

#: What a decoder raises on bytes that do not fit the layout.
DECODE_ERRORS = (struct.error, ValueError, IndexError, UnicodeDecodeError)

_U32 = struct.Struct("<I")
_SEC_NSEC1 = struct.Struct("<II")
_SEC_NSEC2 = struct.Struct("<iI")
_HDR1 = struct.Struct("<III")  # ROS1 header after seq: sec, nsec, frame_id length
_HDR2 = struct.Struct("<iII")  # CDR header: sec, nanosec, frame_id length
_F32X7_U32 = struct.Struct("<7fI")  # LaserScan angle_min .. range_max, then len(ranges)
_F64X3 = struct.Struct("<3d")
_F64X6 = struct.Struct("<6d")
_F64X7 = struct.Struct("<7d")
_CDR_OFFSET = 4  # the encapsulation header


@dataclass(frozen=True, slots=True)
class ScanFields:
    """What gndreplay reads of a sensor_msgs/LaserScan."""

    stamp_ns: int
    frame_id: str
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: NDArray[np.float32]


@dataclass(frozen=True, slots=True)
class OdometryFields:
    """nav_msgs/Odometry: pose (x, y, quaternion) and twist (vx, wz)."""

    stamp_ns: int
    child_frame_id: str
    x: float
    y: float
    q: tuple[float, float, float, float]  # x, y, z, w
    vx: float
    wz: float


@dataclass(frozen=True, slots=True)
class PoseFields:
    """geometry_msgs/PoseStamped or PoseWithCovarianceStamped."""

    stamp_ns: int
    x: float
    y: float
    q: tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class TransformFields(PoseFields):
    """One geometry_msgs/TransformStamped of a tf2_msgs/TFMessage: the stamped pose of frame ``child`` in
    frame ``parent``."""

    parent: str
    child: str


@dataclass(frozen=True, slots=True)
class TwistFields:
    """geometry_msgs/Twist (stamp None) or TwistStamped."""

    stamp_ns: int | None
    vx: float
    vy: float
    wz: float


def is_little_cdr(raw: bytes | memoryview) -> bool:
    """True for CDR little-endian encapsulation (``00 01``), the only one these decoders read."""
    return len(raw) >= 4 and raw[0] == 0 and raw[1] == 1


def yaw_of(q: tuple[float, float, float, float]) -> float:
    """Yaw [rad] of a quaternion (x, y, z, w), in (-pi, pi]."""
    qx, qy, qz, qw = q
    yaw = dm.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return math.pi if yaw <= -math.pi else yaw  # NaN (a NaN quaternion) stays NaN


class _Reader:
    """A cursor over one message's bytes."""

    __slots__ = ("buf", "cdr", "frame", "pos")

    def __init__(self, buf: bytes | memoryview, cdr: bool) -> None:
        self.buf, self.cdr = buf, cdr
        self.pos = _CDR_OFFSET if cdr else 0
        self.frame = ""

    def align(self, n: int) -> None:
        if self.cdr:
            rel = self.pos - _CDR_OFFSET
            self.pos += -rel % n

    def u32(self) -> int:
        self.align(4)
        (v,) = _U32.unpack_from(self.buf, self.pos)
        self.pos += 4
        return int(v)

    def string(self) -> str:
        n = self.u32()
        end = self.pos + n
        if end > len(self.buf):
            raise ValueError("string runs past the end of the message")
        raw = bytes(self.buf[self.pos : end - 1 if self.cdr and n else end])
        self.pos = end
        return raw.decode()

    def header(self) -> int:
        """Reads a std_msgs/Header; returns the stamp in ns (frame_id kept in ``self.frame``)."""
        if self.cdr:
            self.align(4)
            sec, nsec = _SEC_NSEC2.unpack_from(self.buf, self.pos)
        else:
            sec, nsec = _SEC_NSEC1.unpack_from(self.buf, self.pos + 4)  # after seq
            self.pos += 4
        self.pos += 8
        self.frame = self.string()
        return int(sec) * NS_PER_S + int(nsec)

    def f64s(self, st: struct.Struct) -> tuple[float, ...]:
        self.align(8)
        v = st.unpack_from(self.buf, self.pos)
        self.pos += st.size
        return v


def header_stamp(raw: bytes | memoryview, cdr: bool) -> int:
    """``header.stamp`` [ns] of a message that starts with a std_msgs/Header."""
    if cdr:
        sec, nsec = (_SEC_NSEC2 if raw[1] == 1 else struct.Struct(">iI")).unpack_from(raw, _CDR_OFFSET)
    else:
        sec, nsec = _SEC_NSEC1.unpack_from(raw, 4)
    return int(sec) * NS_PER_S + int(nsec)


def _after_header(raw: bytes | memoryview, cdr: bool) -> tuple[int, str, int]:
    """(stamp ns, frame_id, offset after the header) with direct offset arithmetic (the hot path)."""
    if cdr:
        sec, nsec, n = _HDR2.unpack_from(raw, 4)
        end = 16 + n
        frame = bytes(raw[16 : end - 1 if n else end])
    else:
        sec, nsec, n = _HDR1.unpack_from(raw, 4)
        end = 16 + n
        frame = bytes(raw[16:end])
    if end > len(raw):
        raise ValueError("header runs past the end of the message")
    return int(sec) * NS_PER_S + int(nsec), frame.decode(), end


def _align(pos: int, n: int) -> int:
    """CDR: pad ``pos`` to a multiple of n relative to the end of the encapsulation header."""
    return pos + (-(pos - _CDR_OFFSET) % n)


def decode_laserscan(raw: bytes | memoryview, cdr: bool) -> ScanFields:
    """sensor_msgs/LaserScan -> ScanFields (ranges are a float32 view into ``raw``)."""
    stamp, frame, pos = _after_header(raw, cdr)
    if cdr:
        pos = _align(pos, 4)
    amin, _amax, ainc, _tinc, _stime, rmin, rmax, n = _F32X7_U32.unpack_from(raw, pos)
    pos += 32
    if pos + 4 * n > len(raw):
        raise ValueError(f"LaserScan declares {n} ranges beyond the end of the message")
    ranges = np.frombuffer(raw, dtype="<f4", count=n, offset=pos)
    return ScanFields(stamp, frame, amin, ainc, rmin, rmax, ranges)


def decode_odometry(raw: bytes | memoryview, cdr: bool) -> OdometryFields:
    """nav_msgs/Odometry -> OdometryFields."""
    stamp, _, pos = _after_header(raw, cdr)
    if cdr:
        pos = _align(pos, 4)
    (n,) = _U32.unpack_from(raw, pos)
    child = bytes(raw[pos + 4 : pos + 4 + n - (1 if cdr and n else 0)]).decode()
    pos += 4 + n
    if cdr:
        pos = _align(pos, 8)
    x, y, _z, qx, qy, qz, qw = _F64X7.unpack_from(raw, pos)
    vx, _vy, _vz, _wx, _wy, wz = _F64X6.unpack_from(raw, pos + 56 + 36 * 8)  # after the pose covariance
    return OdometryFields(stamp, child, x, y, (qx, qy, qz, qw), vx, wz)


def decode_pose_stamped(raw: bytes | memoryview, cdr: bool) -> PoseFields:
    """geometry_msgs/PoseStamped or PoseWithCovarianceStamped (the pose comes first in both)."""
    r = _Reader(raw, cdr)
    stamp = r.header()
    x, y, _z, qx, qy, qz, qw = r.f64s(_F64X7)
    return PoseFields(stamp, x, y, (qx, qy, qz, qw))


def decode_tfmessage(raw: bytes | memoryview, cdr: bool) -> list[TransformFields]:
    """tf2_msgs/TFMessage -> its transforms."""
    r = _Reader(raw, cdr)
    n = r.u32()
    if n > len(raw):
        raise ValueError(f"TFMessage declares {n} transforms")
    out = []
    for _ in range(n):
        stamp = r.header()
        parent = r.frame
        child = r.string()
        x, y, _z, qx, qy, qz, qw = r.f64s(_F64X7)
        out.append(TransformFields(stamp, x, y, (qx, qy, qz, qw), parent=parent, child=child))
    return out


def decode_twist(raw: bytes | memoryview, cdr: bool, *, stamped: bool) -> TwistFields:
    """geometry_msgs/Twist or TwistStamped -> TwistFields."""
    r = _Reader(raw, cdr)
    stamp = r.header() if stamped else None
    vx, vy, _vz, _wx, _wy, wz = r.f64s(_F64X6)
    return TwistFields(stamp, vx, vy, wz)
