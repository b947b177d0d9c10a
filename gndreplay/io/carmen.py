"""CARMEN text logs (CLF; plain, ``.gz`` or ``.bz2``): a streaming reader and a writer.

Reader decisions (see also ECOSYSTEM.md §3 and the datasets README):

- Lines are parsed forward from their count fields; what follows the payload is the trailer
  (``ipc_timestamp ipc_hostname logger_timestamp`` in standard logs). The stamp is the first numeric trailer
  field: the ipc_timestamp in standard logs, the logger_timestamp in ``host logger_ts`` trailers, the ``0`` of
  laserazos' ``0 0 name``. It is parsed from its decimal text to int ns exactly (no float round-off).
- Scans: FLASER / RLASER (old style: geometry from the beam count, readlog.c: first beam at -90 deg, 180/181
  beams 1 deg, 360/361 0.5 deg, 400/401 0.25 deg, else 180 deg over n-1 steps; ``PARAM
  laser_{front,rear}_laser_{fov,resolution}`` [deg] override), RAWLASER1-4 and ROBOTLASER1/2 (geometry, max
  range and, for ROBOTLASER, laser and robot pose in the line). Auto choice: ROBOTLASER1, FLASER, RAWLASER1,
  then the rear lasers.
- Ranges: a numeric value >= the max range is a no-return (+inf). Literal NaN / inf and negative values are
  invalid (nan): laserazos writes NaN where nothing came back, but that is not a measured "free up to max
  range", so it is kept as invalid rather than guessed to be a no-return. The max range comes from PARAM
  (``laser_front_laser_max_range``), else from a saturation marker (a maximal value repeated across the first
  scans, like ACES' 50.0), else readlog.c's 80 m.
- Odometry: ODOM lines (interpolated at each scan stamp) when the log has them, else the odometry triple
  inside the scan line. In ACES the FLASER odometry triple is the latest ODOM sample before the scan (stale by
  ~0.1 s); interpolating ODOM at the scan stamp is closer in time and matches the ROS conversions of the log.
  ``odom_topic="FLASER"`` picks the embedded triple instead.
- Commands: ODOM lines carry the robot's translational and rotational velocity (``tv rv``). Loggers that do
  not record velocities write zeros there (ACES and Intel: every tv and rv is 0; MIT CSAIL has no ODOM
  line), and all-zero values are no command at all. So ODOM is a command stream only when the log has an ODOM
  line with a non-zero tv or rv, and its tv/rv become ``Tick.cmd`` from the first such line on (the ticks
  before it have no command: nothing was commanded yet, and a zero is indistinguishable from "not
  recorded"). This rule streams: the pass itself never looks ahead. Whether the log *has* commands
  (``describe().cmd_stream``, ``cmd_topic="ODOM"``) is known from the head when one of its ODOM lines moves,
  after a complete pass, or else from one scan of the ODOM lines that stops at the first non-zero tv/rv (the
  cost of decompressing the log once, paid only when the answer is asked for before a pass).
- The laser pose in the robot frame comes from ``PARAM robot_frontlaser_offset`` (+ ``_side_offset``,
  ``_angular_offset``; a missing one is 0), the rear laser facing backwards; ROBOTLASER lines give it per
  line. A log without any of these PARAMs records no mounting: ``ReadOptions.default_sensor_pose`` applies
  when given, else the identity (the rear laser facing backwards). The report's ``sensor_pose_source`` says
  which.
- File order is not time order: records go through the bounded reorder heap of :mod:`.sync`.
- Malformed lines are skipped and counted (``strict`` makes them an error); all-zero stamps get an index
  clock. A line is malformed when its fields do not add up: the trailer of each message must have as many
  fields as it has in the head of the log, so a FLASER with one range too many or too few is not read with
  every field shifted; when a value is out of the bounds of :mod:`.base` (stamps beyond
  ~2112, poses beyond 1000 km, NaN / inf poses, absurd bearings or max range); or when it is longer than
  4 MB (skipped unread in bounded chunks: a decompression bomb of zeros costs one chunk of memory). The
  head scan keeps at most 16 MB of text. Every decompression error (zlib.error, EOFError, OSError) is a
  LogFormatError naming the last line read.
"""

from __future__ import annotations

import bz2
import contextlib
import gzip
import io
import itertools
import logging
import math
import os
import queue
import re
import threading
import zlib
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import LogFormatError
from ..fsutil import atomic_path, format_stamp
from ..types import NS_PER_S, Odometry, Pose2D, Scan, Tick
from .base import (
    INDEX_CLOCK_PERIOD_NS,
    MAX_ABS_POSITION_M,
    MAX_ABS_TIME_NS,
    MAX_BEAMS,
    MAX_RANGE_LIMIT_M,
    Closing,
    LogDescription,
    ReadReport,
    SensorPoseSource,
    StreamInfo,
    StreamRole,
    check_bearings,
    check_pose,
    check_speed,
    check_time,
)
from .options import DEFAULT_READ, ReadOptions
from .sync import (
    Event,
    OdomEvent,
    PoseMode,
    ScanEvent,
    SyncStats,
    TruthEvent,
    reorder,
    synchronise,
    with_index_clock,
    wrap,
)

__all__ = [
    "CARMEN_HEADER",
    "DEFAULT_MAX_RANGE_M",
    "SCAN_MESSAGES",
    "CarmenReader",
    "flaser_angles",
    "odom_has_commands",
    "parse_time_ns",
    "write_carmen",
]

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]

#: readlog.c's maximum range; values at or beyond it are no-returns.
DEFAULT_MAX_RANGE_M = 80.0
#: Scan message names in the order the reader prefers them when several are present.
SCAN_MESSAGES = (
    "ROBOTLASER1", "FLASER", "RAWLASER1", "ROBOTLASER2", "RLASER", "RAWLASER2", "RAWLASER3", "RAWLASER4",
)  # fmt: skip
_OTHER_KNOWN = (  # readlog.c's "message formats defined" plus the old-style remission lines
    "ODOM", "TRUEPOS", "PARAM", "SYNC", "LASER3", "LASER4", "ROBOTLASER0", "REMISSIONFLASER",
    "REMISSIONRLASER", "REMISSIONLASER3", "REMISSIONLASER4", "POSITIONLASER", "NMEAGGA", "NMEARMC",
)  # fmt: skip
KNOWN_MESSAGES = frozenset(SCAN_MESSAGES + _OTHER_KNOWN)
_NAME_RE = re.compile(rb"^[A-Za-z][A-Za-z0-9_\-]*$")
_DEC_RE = re.compile(rb"^([+-]?)(\d+)(?:\.(\d*))?$")
_HEAD_LINES = 5000
_HEAD_SCANS = 50
_MAX_LINE = 4 << 20  # bytes; a 100k-beam line is ~1 MB
_HEAD_BYTES = 16 << 20  # the head keeps at most this much text (a log of huge lines still opens cheaply)
#: What ``_lines`` yields in place of a line longer than ``_MAX_LINE`` (the rest is skipped unread).
_TOO_LONG = b"\0too long\0"
_MAX_TRAILER = 3
_SATURATION_MIN_COUNT = 5
_SATURATION_MIN_SCANS = 3

# which laser a message comes from: PARAM prefix and default mounting
_FRONT, _REAR = "front", "rear"
_SIDE = {
    "FLASER": _FRONT,
    "RLASER": _REAR,
    "RAWLASER1": _FRONT,
    "RAWLASER2": _REAR,
    "RAWLASER3": None,
    "RAWLASER4": None,
    "ROBOTLASER1": _FRONT,
    "ROBOTLASER2": _REAR,
}
_MAX_RANGE_PARAMS = ("laser_{s}_laser_max_range", "laser_{s}_laser_maxrange", "robot_{s}_laser_max")


class _Bad(ValueError):
    """A malformed line (internal; becomes a count or a LogFormatError)."""


# ---------------------------------------------------------------------------------------------------------
# small pure helpers


def parse_time_ns(token: bytes | str) -> int:
    """Seconds as decimal text -> int ns, exact for plain decimals (``"1134864629.895182"``).

    Raises:
        ValueError: not a finite number, or beyond ``MAX_ABS_TIME_NS`` (about year 2112).
    """
    tok = token.encode() if isinstance(token, str) else token
    m = _DEC_RE.match(tok)
    if m is not None:
        sign, sec, frac = m.groups()
        if len(sec.lstrip(b"0")) > 12:
            raise ValueError(f"timestamp {tok[:30]!r} out of range")
        ns = int(sec) * NS_PER_S + (int(frac[:9].ljust(9, b"0")) if frac else 0)
        return check_time(-ns if sign == b"-" else ns)
    value = float(tok)
    if not abs(value) <= MAX_ABS_TIME_NS / NS_PER_S:
        raise ValueError(f"timestamp {tok[:30]!r} is not finite or out of range")
    return check_time(round(value * NS_PER_S))


#: The first line of every CARMEN log gndreplay writes (how it recognises its own logs before replacing one)
CARMEN_HEADER = "# CARMEN log written by gndreplay"

#: int ns -> exact decimal seconds (``parse_time_ns`` inverse): the one stamp format of every output file
format_time_s = format_stamp


def flaser_angles(n: int, *, fov_rad: float | None = None, resolution_rad: float | None = None) -> F64:
    """Beam bearings [rad] of an n-beam FLASER/RLASER scan (readlog.c geometry unless fov/resolution given).

    With ``fov_rad`` the scan is centred (first beam at -fov/2); with only ``resolution_rad`` it starts at
    -pi/2. Without either: 180/181 beams at 1 deg, 360/361 at 0.5 deg, 400/401 at 0.25 deg, else pi/(n-1);
    first beam at -pi/2.
    """
    if fov_rad is not None:
        res = resolution_rad if resolution_rad is not None else (fov_rad / (n - 1) if n > 1 else 0.0)
        return -fov_rad / 2.0 + res * np.arange(n, dtype=np.float64)
    if resolution_rad is not None:
        res = resolution_rad
    elif n in (180, 181):
        res = math.radians(1.0)
    elif n in (360, 361):
        res = math.radians(0.5)
    elif n in (400, 401):
        res = math.radians(0.25)
    else:
        res = math.pi / (n - 1) if n > 1 else 0.0
    return -math.pi / 2.0 + res * np.arange(n, dtype=np.float64)


def clean_ranges(raw: F64, max_range_m: float, min_range_m: float = 0.0) -> F64:
    """Raw log ranges -> our convention, in place: >= max range -> +inf; nan/inf/negative/<min -> nan."""
    valid = (raw >= max(min_range_m, 0.0)) & (raw < np.inf)  # False for nan, +-inf, negative
    np.putmask(raw, raw >= max_range_m, np.inf)
    np.putmask(raw, ~valid, np.nan)
    return raw


def _floats(tokens: list[bytes], what: str) -> list[float]:
    try:
        vals = [float(t) for t in tokens]
    except ValueError:
        raise _Bad(f"{what} is not numeric") from None
    if not all(math.isfinite(v) for v in vals):
        raise _Bad(f"{what} is not finite")
    return vals


def _count(tok: list[bytes], i: int, what: str) -> int:
    try:
        n = int(tok[i])
    except (ValueError, IndexError):
        raise _Bad(f"{what} count missing or not an integer") from None
    if not 0 < n <= MAX_BEAMS:
        raise _Bad(f"{what} count {n} out of range")
    return n


def _need(tok: list[bytes], n_fields: int, what: str) -> None:
    """Check that the payload (n_fields tokens) plus a 1-3 token trailer is what the line holds."""
    extra = len(tok) - n_fields
    if extra < 1:
        raise _Bad(f"{what}: line ends early ({len(tok)} fields, expected {n_fields + 1} or more)")
    if extra > _MAX_TRAILER:
        raise _Bad(f"{what}: {extra - _MAX_TRAILER} unexpected extra fields")


def _is_number(t: bytes) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True


def _trailer_time(tok: list[bytes], start: int) -> int:
    """First numeric field of the trailer, in ns."""
    for t in tok[start:]:
        if _is_number(t):
            try:
                return parse_time_ns(t)
            except ValueError as err:
                raise _Bad(str(err)) from None
    raise _Bad("no timestamp")


def _ranges(tok: list[bytes], a: int, n: int) -> F64:
    try:
        return np.array(tok[a : a + n], dtype=np.float64)
    except ValueError:
        raise _Bad("ranges are not numeric") from None


def _pose(v: list[float], what: str = "pose") -> Pose2D:
    return check_pose(v[0], v[1], v[2], what)


def _relative(a: Pose2D, b: Pose2D) -> Pose2D:
    """inverse(a) ∘ b with scalar math (per line, so no numpy overhead)."""
    c, s = dm.cos(a.theta), dm.sin(a.theta)
    dx, dy = b.x - a.x, b.y - a.y
    return Pose2D(c * dx + s * dy, -s * dx + c * dy, wrap(b.theta - a.theta))


def _compose(a: Pose2D, b: Pose2D) -> Pose2D:
    c, s = dm.cos(a.theta), dm.sin(a.theta)
    return Pose2D(a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, wrap(a.theta + b.theta))


# ---------------------------------------------------------------------------------------------------------
# opening


class _Decompressing(io.RawIOBase):
    """A compressed stream decompressed ahead by a thread, ``_CHUNK`` bytes at a time, at most ``_AHEAD``
    chunks ahead: bz2 and zlib release the GIL while they work, so a log's decompression overlaps its
    parsing (on a second core). The same bytes in the same order; a decompression error is raised by the
    read that reaches it."""

    _CHUNK = 1 << 16
    _AHEAD = 4

    def __init__(self, stream: io.BufferedIOBase) -> None:
        super().__init__()
        self._stream = stream
        self._chunks: queue.Queue[bytes | BaseException] = queue.Queue(self._AHEAD)
        self._stop = threading.Event()
        self._buf = b""
        self._eof = False
        self._thread = threading.Thread(target=self._fill, name="gndreplay-decompress", daemon=True)
        self._thread.start()

    def _fill(self) -> None:
        while not self._stop.is_set():
            try:
                # read1: one decompression step, so the data before an error is handed over first (a
                # read of the whole chunk would drop what it had decompressed when the error came)
                chunk: bytes | BaseException = self._stream.read1(self._CHUNK)
            except BaseException as err:  # handed to the reader, raised where the data ends
                chunk = err
            while not self._stop.is_set():
                try:
                    self._chunks.put(chunk, timeout=0.1)
                    break
                except queue.Full:
                    continue
            if not chunk or isinstance(chunk, BaseException):
                return

    def readable(self) -> bool:
        return True

    def readinto(self, b: Any) -> int:
        if not self._buf and not self._eof:
            chunk = self._chunks.get()
            if isinstance(chunk, BaseException):
                self._eof = True
                raise chunk
            self._eof = not chunk
            self._buf = chunk
        n = min(len(b), len(self._buf))
        b[:n] = self._buf[:n]
        self._buf = self._buf[n:]
        return n

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self._stream.close()
        super().close()


class _LogFile:
    """A log's bytes, decompressed by suffix (plain / .gz / .bz2, ahead of the parsing by a thread: lines
    are parsed as bytes), and how far into the file on disk they have been read: the progress of a pass
    whose length is unknown."""

    def __init__(self, path: Path) -> None:
        self._raw = open(path, "rb")  # noqa: SIM115 - closed by close()
        try:
            self._size = os.fstat(self._raw.fileno()).st_size
            suffix = path.suffix.lower()
            self._fh: IO[bytes] = self._raw
            if suffix == ".gz":
                self._fh = io.BufferedReader(_Decompressing(gzip.GzipFile(fileobj=self._raw, mode="rb")))
            elif suffix == ".bz2":
                self._fh = io.BufferedReader(_Decompressing(bz2.BZ2File(self._raw, "rb")))
        except BaseException:
            self._raw.close()
            raise
        self.readline = self._fh.readline

    def fraction_read(self) -> float | None:
        """Share of the file on disk read so far, in [0, 1] (None: closed or empty)."""
        if self._raw.closed or not self._size:
            return None
        return min(self._raw.tell() / self._size, 1.0)

    def close(self) -> None:
        self._fh.close()
        self._raw.close()


#: What reading plain / gzip / bz2 data raises on damaged input (zlib.error is not an OSError).
_READ_ERRORS = (OSError, EOFError, ValueError, zlib.error, MemoryError)


def _lines(path: Path, fh: _LogFile, lineno: int = 0) -> Iterator[tuple[int, bytes]]:
    """Numbered lines after line ``lineno``. A line longer than ``_MAX_LINE`` bytes is yielded as
    ``_TOO_LONG`` and its rest skipped in bounded chunks (once the consumer asks for the next line), so a
    binary or decompression-bomb file never holds more than one chunk in memory.

    Raises:
        LogFormatError: decompression or I/O error, naming the last line read.
    """
    readline = fh.readline
    skipping = False
    while True:
        try:
            line = readline(_MAX_LINE)
        except _READ_ERRORS as err:  # gzip/bz2 raise all of these on bad data
            what = type(err).__name__ if isinstance(err, MemoryError) else str(err)
            raise LogFormatError(f"{path}: truncated or corrupt data after line {lineno}: {what}") from err
        if not line:
            return
        if skipping:
            skipping = not line.endswith(b"\n")
            continue
        lineno += 1
        if len(line) == _MAX_LINE and not line.endswith(b"\n"):
            skipping = True
            yield lineno, _TOO_LONG
            continue
        yield lineno, line


# ---------------------------------------------------------------------------------------------------------
# the head of the file: what is in it, params, saturation marker, all-zero clock


@dataclass(frozen=True, slots=True)
class _Head:
    names: Counter[str]
    params: dict[str, str]
    samples: dict[str, list[F64]]
    any_stamp: bool
    all_zero: bool
    first_name: str | None
    trailers: dict[bytes, int]  # per message: the usual number of trailer fields
    odom_moves: bool = False  # an ODOM line of the head has a non-zero tv or rv


@dataclass(slots=True)
class _Opened:
    """A file handle positioned after ``lines`` (kept so the first pass does not decompress them again);
    ``resumable`` is False when the head stopped inside an over-long line (the pass then reopens the file)."""

    fh: _LogFile
    lines: list[tuple[int, bytes]]
    resumable: bool = True


def _peek(path: Path) -> tuple[_Head, _Opened]:
    """Read the head of the log (a few thousand lines at most); the handle stays open for the first pass.

    Raises:
        LogFormatError: missing / unreadable file, or not a CARMEN log.
    """
    try:
        fh = _LogFile(path)
    except OSError as err:
        raise LogFormatError(f"{path}: cannot open: {err.strerror or err}") from err
    opened = _Opened(fh, [])
    try:
        return _read_head(path, opened), opened
    except BaseException:
        fh.close()
        raise


def _read_head(path: Path, opened: _Opened) -> _Head:
    names: Counter[str] = Counter()
    params: dict[str, str] = {}
    samples: dict[str, list[F64]] = {}
    any_stamp, all_zero = False, True
    first_name: str | None = None
    trailer_sizes: dict[bytes, Counter[int]] = {}
    scans = kept = 0
    odom_moves = False
    for lineno, line in _lines(path, opened.fh):
        if line is _TOO_LONG:
            opened.resumable = False
            break
        opened.lines.append((lineno, line))
        kept += len(line)
        if lineno > _HEAD_LINES or scans >= _HEAD_SCANS or kept > _HEAD_BYTES:
            break
        tok = line.split()
        if not tok or tok[0].startswith(b"#"):
            continue
        if first_name is None:
            first_name = tok[0][:40].decode("ascii", "replace")
        if not _NAME_RE.match(tok[0]):
            continue
        name = tok[0].decode()
        names[name] += 1
        if name == "PARAM" and len(tok) >= 3:
            params[tok[1].decode("ascii", "replace")] = tok[2].decode("ascii", "replace")
            continue
        if name not in KNOWN_MESSAGES or name == "PARAM":
            continue
        with contextlib.suppress(_Bad, ValueError, IndexError):
            raw, t_ns, start = _peek_record(name, tok)
            trailer_sizes.setdefault(tok[0], Counter())[len(tok) - start] += 1
            any_stamp = True
            all_zero = all_zero and t_ns == 0
            if raw is not None:
                scans += 1
                samples.setdefault(name, []).append(raw)
            elif name == "ODOM" and not odom_moves:
                odom_moves = _odom_velocity_nonzero(tok)
    if not any(n in KNOWN_MESSAGES for n in names):
        what = f"first record starts with {first_name!r}" if first_name else "no records"
        if not opened.resumable:
            what += f", then a line longer than {_MAX_LINE >> 20} MB: binary data?"
        raise LogFormatError(f"{path}: not a CARMEN log (no CARMEN message in the first lines; {what})")
    trailers = {k: c.most_common(1)[0][0] for k, c in trailer_sizes.items()}
    return _Head(names, params, samples, any_stamp, any_stamp and all_zero, first_name, trailers, odom_moves)


def _odom_velocity_nonzero(tok: list[bytes]) -> bool:
    """Whether an ODOM line (``ODOM x y theta tv rv accel ...``) carries a valid non-zero tv or rv."""
    try:
        tv, rv = check_speed(float(tok[4]), "velocity"), check_speed(float(tok[5]), "turn rate")
    except (ValueError, IndexError):
        return False
    return tv != 0.0 or rv != 0.0


def odom_has_commands(path: Path) -> bool:
    """Whether any ODOM line of the log carries a non-zero tv or rv (read until the first one).

    Malformed ODOM lines are skipped (the replay's own pass counts them).

    Raises:
        LogFormatError: the file cannot be opened, or its data is truncated or corrupt before a non-zero
            ODOM tv/rv was found (the answer would be a guess): one line naming the last line read.
    """
    try:
        fh = _LogFile(path)
    except OSError as err:
        raise LogFormatError(f"{path}: cannot open: {err.strerror or err}") from err
    try:
        for _, line in _lines(path, fh):
            if line.startswith(b"ODOM") and _odom_velocity_nonzero(line.split(None, 7)):
                return True
    finally:
        fh.close()
    return False


def _peek_record(name: str, tok: list[bytes]) -> tuple[F64 | None, int, int]:
    """Raw ranges (scan lines), the stamp and the trailer start of one record, for the head sample."""
    if name in ("FLASER", "RLASER"):
        n = _count(tok, 1, name)
        _need(tok, 2 + n + 6, name)
        return _ranges(tok, 2, n), _trailer_time(tok, 2 + n + 6), 2 + n + 6
    if name.startswith("RAWLASER") or name.startswith("ROBOTLASER"):
        n = _count(tok, 8, name)
        m = int(tok[9 + n])
        tail = 11 if name.startswith("ROBOTLASER") else 0
        _need(tok, 10 + n + m + tail, name)
        return _ranges(tok, 9, n), _trailer_time(tok, 10 + n + m + tail), 10 + n + m + tail
    if name in ("ODOM", "TRUEPOS"):
        _need(tok, 7, name)
        return None, _trailer_time(tok, 7), 7
    raise _Bad("not sampled")


def detect_saturation(samples: list[F64]) -> float | None:
    """A no-return marker below the default max range: the maximal value, repeated across scans.

    ACES writes 50.0 where the beam saw nothing; such a value is the scan-wide maximum, occurs at least 5
    times and in at least 3 scans of the sample. Returns None when there is no such value.
    """
    if not samples:
        return None
    allr = np.concatenate(samples)
    fin = allr[np.isfinite(allr) & (allr > 0.0)]
    if fin.size == 0:
        return None
    m = float(fin.max())
    if m >= DEFAULT_MAX_RANGE_M:
        return None
    n_scans = sum(bool(np.any(s == m)) for s in samples)
    if int(np.count_nonzero(fin == m)) >= _SATURATION_MIN_COUNT and n_scans >= _SATURATION_MIN_SCANS:
        return m
    return None


# ---------------------------------------------------------------------------------------------------------
# laser configuration from PARAMs


@dataclass(frozen=True, slots=True)
class _Laser:
    """Per-laser settings that old-style lines do not carry."""

    sensor_pose: Pose2D
    sensor_pose_source: SensorPoseSource
    max_range_m: float
    max_range_source: str
    min_range_m: float
    fov_rad: float | None
    resolution_rad: float | None


def _param_float(params: Mapping[str, str], key: str, limit: float = MAX_ABS_POSITION_M) -> float | None:
    """A numeric PARAM, or None when missing, not a number, or not below ``limit`` in magnitude."""
    v = params.get(key)
    if v is None:
        return None
    try:
        f = float(v)
    except ValueError:
        return None
    return f if abs(f) < limit else None


def _mounting(
    side: str | None, params: Mapping[str, str], fallback: Pose2D | None
) -> tuple[Pose2D, SensorPoseSource]:
    """The ``side`` laser's pose in the robot frame and its source: the laser offset PARAMs when the log has
    any of them (a missing one is 0), else ``fallback``, else the identity (the rear laser facing
    backwards)."""
    if side is None:
        offsets: list[float | None] = [None, None, None]
        pose = Pose2D(0.0, 0.0, 0.0)
    else:
        offsets = [_param_float(params, f"robot_{side}laser_{k}") for k in ("offset", "side_offset",
                                                                             "angular_offset")]
        x, y, th = (v or 0.0 for v in offsets)
        pose = Pose2D(x, y, wrap(th + (math.pi if side == _REAR else 0.0)))
    if any(v is not None for v in offsets):
        return pose, "log"
    return (pose, "none") if fallback is None else (fallback, "config default")


def _laser_config(
    side: str | None, params: Mapping[str, str], saturation: float | None, fallback: Pose2D | None
) -> _Laser:
    """The settings of the ``side`` laser from the PARAMs (``fallback``: its pose when no PARAM gives one)."""
    pose, source = _mounting(side, params, fallback)
    if side is None:
        return _Laser(pose, source, DEFAULT_MAX_RANGE_M, "readlog.c default", 0.0, None, None)
    max_r, range_source = DEFAULT_MAX_RANGE_M, "readlog.c default"
    for key in _MAX_RANGE_PARAMS:
        v = _param_float(params, key.format(s=side), MAX_RANGE_LIMIT_M)
        if v is not None and v > 0:
            max_r, range_source = v, f"PARAM {key.format(s=side)}"
            break
    else:
        if saturation is not None:
            max_r, range_source = saturation, f"no-return marker {saturation:g} m"
    min_r = _param_float(params, f"laser_{side}_laser_min_range") or 0.0
    if not 0.0 <= min_r < max_r:
        min_r = 0.0
    fov = _param_float(params, f"laser_{side}_laser_fov", 720.0)
    res = _param_float(params, f"laser_{side}_laser_resolution", 720.0)
    return _Laser(
        pose, source, max_r, range_source, min_r, math.radians(fov) if fov else None,
        math.radians(res) if res else None,
    )


# ---------------------------------------------------------------------------------------------------------
# the reader


class CarmenReader(Closing):
    """Streams a CARMEN log as time-ordered Ticks (see the module docstring for the rules).

    Args:
        path: the log (plain, .gz or .bz2).
        options: what to read (``fmt`` is the registry's); for CARMEN logs:
            ``scan_topic``: scan message name (FLASER, RLASER, ROBOTLASER1/2, RAWLASER1-4); auto when None.
            ``odom_topic``: "ODOM" (interpolated ODOM lines) or the scan message name (its embedded
            odometry).
            ``cmd_topic``: "ODOM" (the tv/rv of ODOM lines; an error when they are all zero), or None: ODOM
            when the log has a non-zero tv or rv (see the module docstring); anything else is an error.
            ``truth_topic``: "TRUEPOS", or the scan message name (its first pose triple, as a reference
            pose).
            ``default_sensor_pose``: the laser pose when no laser offset PARAM gives one (not for
            ROBOTLASER lines, which carry it).

    Raises:
        LogFormatError: missing file, not CARMEN, or a stream that is not in the log (lists the candidates).
    """

    format_name = "carmen"

    def __init__(self, path: Path, *, options: ReadOptions = DEFAULT_READ) -> None:
        self.path = Path(path)
        self._strict = options.strict
        self._sync = options.sync
        self._fallback = options.sensor_pose_fallback()
        self._stats = SyncStats()
        self._fh: _LogFile | None = None
        self._opened: _Opened | None = None
        self._odom_cmds: bool | None = None  # ODOM tv/rv are commands (None: not known yet)
        self._odom_moved = False  # the pass in progress has read an ODOM line with a non-zero tv or rv
        head, self._opened = _peek(self.path)
        self._head = head
        try:
            self._choose(options.scan_topic, options.odom_topic, options.cmd_topic, options.truth_topic)
        except BaseException:
            self.close()
            raise
        self._saturation = detect_saturation(head.samples.get(self.scan_stream, []))
        self._params: dict[str, str] = dict(head.params)
        self._laser = self._configure_laser()
        self._stats.sensor_pose_source = self._sensor_pose_source()
        self._angles: dict[tuple[int, float, float], F64] = {}
        self._stats_counts: dict[str, int] = {}
        self._trailers: dict[bytes, int] = {}

    def _choose(
        self, scan_topic: str | None, odom_topic: str | None, cmd_topic: str | None, truth_topic: str | None
    ) -> None:
        """Pick the scan, odometry and truth streams (see the class docstring).

        Raises:
            LogFormatError: a requested stream is not in the log (the message lists the candidates).
        """
        head = self._head
        present = [n for n in SCAN_MESSAGES if n in head.names]
        if scan_topic is None:
            if not present:
                raise LogFormatError(
                    f"{self.path}: no scans: no laser message ({', '.join(SCAN_MESSAGES)}) in the first lines"
                )
            scan_topic = present[0]
        elif scan_topic not in SCAN_MESSAGES:
            raise LogFormatError(
                f"{self.path}: {scan_topic!r} is not a CARMEN laser message; candidates: "
                f"{', '.join(present) or 'none'}"
            )
        self.scan_stream = scan_topic
        embeds_odom = not scan_topic.startswith("RAWLASER")
        odom_default: PoseMode = "stream" if "ODOM" in head.names else ("embedded" if embeds_odom else "none")
        self._odom_mode = self._pose_mode(odom_topic, "ODOM", scan_topic, embeds_odom, "odometry",
                                          odom_default)
        if cmd_topic is not None:
            if cmd_topic != "ODOM" or "ODOM" not in head.names:
                raise LogFormatError(
                    f"{self.path}: no command stream {cmd_topic!r}; CARMEN logs record velocity commands "
                    f"only as ODOM tv/rv (candidates: {'ODOM' if 'ODOM' in head.names else 'none'})"
                )
            if not self.has_commands:
                raise LogFormatError(
                    f"{self.path}: no command stream 'ODOM': every ODOM tv and rv is 0 (the log recorded "
                    "no velocity commands)"
                )
        truth_default: PoseMode = "stream" if "TRUEPOS" in head.names else "none"
        self._truth_mode = self._pose_mode(truth_topic, "TRUEPOS", scan_topic, embeds_odom, "ground-truth",
                                           truth_default)

    def _pose_mode(self, asked: str | None, message: str, scan_topic: str, embeds: bool, what: str,
                   default: PoseMode) -> PoseMode:
        """Where a pose stream (odometry, ground truth) is read from: ``default`` when none is asked, else
        its own ``message`` ("stream") or the poses embedded in the scan messages ("embedded").

        Raises:
            LogFormatError: the asked stream is neither (the message lists the candidates).
        """
        names = self._head.names
        if asked is None:
            return default
        if asked == message and message in names:
            return "stream"
        if asked == scan_topic and embeds:
            return "embedded"
        candidates = ([message] if message in names else []) + ([scan_topic] if embeds else [])
        raise LogFormatError(f"{self.path}: no {what} stream {asked!r}; candidates: "
                             f"{', '.join(candidates) or 'none'}")

    # -- closing (the context manager is base.Closing) -----------------------------------------
    def close(self) -> None:
        """Close the file (of a pass in progress, or kept open since the reader was opened)."""
        self._close_pass()
        if self._opened is not None:
            self._opened.fh.close()
            self._opened = None

    def _close_pass(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def fraction_read(self) -> float | None:
        """Share of the log file read by the pass in progress (CARMEN logs do not say their length)."""
        fh = self._fh if self._fh is not None else self._opened.fh if self._opened is not None else None
        return None if fh is None else fh.fraction_read()

    # -- description -------------------------------------------------------------------------------
    def _known_commands(self) -> bool | None:
        """Whether ODOM tv/rv are a command stream, as far as known without reading ahead (None: not yet).

        Only a non-zero tv/rv in the head settles it early: ODOM lines may start after the head (scans
        first, odometry later), so neither "no ODOM in the head" nor "all zero in the head" does."""
        if self._odom_cmds is None and self._head.odom_moves:
            self._odom_cmds = True
        return self._odom_cmds

    @property
    def has_commands(self) -> bool:
        """Whether the ODOM lines' tv/rv are a command stream: the log has ODOM lines and one of them has a
        non-zero tv or rv (known from the head or a complete pass, else by one scan of the ODOM lines).

        Raises:
            LogFormatError: the log is corrupt before the scan could answer (see ``odom_has_commands``)."""
        known = self._known_commands()
        if known is None:
            known = self._odom_cmds = odom_has_commands(self.path)
        return known

    def records_commands(self) -> bool:
        """``has_commands`` (the reader protocol's question; may read the ODOM lines once)."""
        return self.has_commands

    @property
    def odom_source(self) -> str:
        if self._odom_mode == "stream":
            return "ODOM (interpolated at scan stamps)"
        if self._odom_mode == "embedded":
            return f"{self.scan_stream} (odometry triple in the scan line)"
        return "none"

    def describe(self) -> LogDescription:
        """Streams seen in the head of the log (counts only after a full pass: see ``message_counts``).

        Commands are named when known without reading ahead (``records_commands`` asks, at a cost)."""
        known = self._known_commands()
        roles: dict[str, StreamRole] = {self.scan_stream: "scan", "PARAM": "param"}
        if self._odom_mode == "stream":
            roles["ODOM"] = "odom"  # the role column has one entry: the note below says when it is both
        elif known:
            roles["ODOM"] = "cmd"
        if self._truth_mode == "stream":
            roles["TRUEPOS"] = "truth"
        counts = self._stats_counts
        streams = tuple(
            StreamInfo(n, n, counts.get(n) if counts else None, roles.get(n, "other"))
            for n in sorted(self._head.names)
        )
        notes = [f"max range {self._laser.max_range_m:g} m ({self._laser.max_range_source})"]
        if self._head.all_zero:
            notes.append("timestamps are all zero: index clock")
        if "ODOM" in self._head.names or known is not None:
            both = (" (ODOM is both the odometry and the command stream)"
                    if self._odom_mode == "stream" else "")
            notes.append({True: f"commands: ODOM tv/rv{both}",
                          False: "ODOM tv/rv are all zero: no recorded velocity commands",
                          None: "ODOM tv/rv: not known before the log is read"}[known])
        return LogDescription(
            path=self.path,
            format=self.format_name,
            streams=streams,
            scan_stream=self.scan_stream,
            odom_source=self.odom_source,
            cmd_stream="ODOM" if known else None,
            truth_stream="TRUEPOS"
            if self._truth_mode == "stream"
            else (self.scan_stream if self._truth_mode == "embedded" else None),
            notes=tuple(notes),
        )

    @property
    def message_counts(self) -> dict[str, int]:
        """Lines per message name seen by the last complete pass (empty before one)."""
        return dict(self._stats_counts)

    @property
    def report(self) -> ReadReport:
        return self._stats.to_report()

    def _configure_laser(self) -> _Laser:
        """The scan laser's settings from the PARAMs read so far."""
        return _laser_config(_SIDE[self.scan_stream], self._params, self._saturation, self._fallback)

    def _sensor_pose_source(self) -> SensorPoseSource:
        """Where the scans' laser pose comes from: ROBOTLASER lines carry it, other scans take the laser's."""
        return "log" if self.scan_stream.startswith("ROBOTLASER") else self._laser.sensor_pose_source

    # -- streaming ---------------------------------------------------------------------------------
    def ticks(self) -> Iterator[Tick]:
        """Time-ordered ticks; see the class docstring.

        Yields:
            one Tick per scan line, in stamp order.

        Raises:
            LogFormatError: truncated/corrupt compressed data, no scans, or (strict) a malformed line.
        """
        stats = SyncStats(sensor_pose_source=self._sensor_pose_source())
        self._stats = stats
        self._odom_moved = False
        events = self._events(stats)
        yield from synchronise(
            reorder(events, stats, self._sync),
            stats,
            odom_mode=self._odom_mode,
            truth_mode=self._truth_mode,
            opts=self._sync,
            cmd_from_odom=self._known_commands() is not False,
        )
        if self._odom_cmds is None:  # a complete pass read every ODOM line
            self._odom_cmds = self._odom_moved
        if stats.scans == 0:
            raise LogFormatError(f"{self.path}: no scans ({self.scan_stream} lines) in the log")

    def _events(self, stats: SyncStats) -> Iterator[Event]:
        counts: Counter[str] = Counter()
        index_clock = self._head.all_zero
        if index_clock:
            stats.index_clock = True
            msg = (
                f"{self.path}: all timestamps are zero; using an index clock "
                f"({INDEX_CLOCK_PERIOD_NS / NS_PER_S:g} s per scan)"
            )
            stats.warnings.append(msg)
            log.warning(msg)
        handlers = self._handlers()
        n_scans = 0
        scan_name = self.scan_stream.encode()
        self._close_pass()
        self._trailers = dict(self._head.trailers)
        if self._opened is not None and not self._opened.resumable:
            self._opened.fh.close()
            self._opened = None
        if self._opened is not None:  # the first pass continues from the head that was read to open
            opened, self._opened = self._opened, None
            self._fh = opened.fh
            lines: Iterable[tuple[int, bytes]] = itertools.chain(
                opened.lines, _lines(self.path, opened.fh, opened.lines[-1][0] if opened.lines else 0)
            )
        else:
            try:
                self._fh = _LogFile(self.path)
            except OSError as err:
                raise LogFormatError(f"{self.path}: cannot open: {err.strerror or err}") from err
            lines = _lines(self.path, self._fh)
        for lineno, line in lines:
            if line is _TOO_LONG:
                self._malformed(stats, lineno, f"line longer than {_MAX_LINE >> 20} MB", None)
                continue
            tok = line.split()
            if not tok or tok[0].startswith(b"#"):
                continue
            key = tok[0]
            handler = handlers.get(key)
            if handler is None:
                if _NAME_RE.match(key):
                    counts[key.decode()] += 1
                    continue
                self._malformed(stats, lineno, f"not a CARMEN record ({key[:20]!r})", None)
                continue
            name = key.decode()
            counts[name] += 1
            try:
                ev = handler(tok)
            except (ValueError, IndexError, OverflowError) as err:
                self._malformed(
                    stats, lineno, f"{name} {err}" if isinstance(err, _Bad) else f"{name}: {err}", err,
                    fatal=self._strict and (key != b"ODOM" or self._odom_mode == "stream"),
                )
                continue
            if ev is None:
                continue
            if index_clock:
                if key == scan_name:
                    n_scans += 1
                    ev = with_index_clock(ev, n_scans * INDEX_CLOCK_PERIOD_NS)
                else:
                    ev = with_index_clock(ev, n_scans * INDEX_CLOCK_PERIOD_NS + INDEX_CLOCK_PERIOD_NS // 2)
            yield ev
        self._close_pass()
        self._stats_counts = dict(counts)

    def _malformed(self, stats: SyncStats, lineno: int, what: str, err: BaseException | None,
                   *, fatal: bool | None = None) -> None:
        """Count a malformed line, or raise (``fatal``; default: strict mode). An ODOM line read only for its
        commands (odometry from the scan lines) is never fatal: a run that uses no command must not stop on
        it, and a teleop run sees the gap as ticks without a command (counted in its audit)."""
        where = f"line {lineno}: {what}"
        if self._strict if fatal is None else fatal:
            raise LogFormatError(f"{self.path} {where}") from err
        stats.add_malformed(where)

    def _handlers(self) -> dict[bytes, Callable[[list[bytes]], Event | None]]:
        h: dict[bytes, Callable[[list[bytes]], Event | None]] = {b"PARAM": self._on_param}
        scan = self.scan_stream
        if scan in ("FLASER", "RLASER"):
            h[scan.encode()] = self._on_flaser
        elif scan.startswith("ROBOTLASER"):
            h[scan.encode()] = self._on_robotlaser
        else:
            h[scan.encode()] = self._on_rawlaser
        if self._odom_mode == "stream" or self._known_commands() is not False:
            h[b"ODOM"] = self._on_odom
        if self._truth_mode == "stream":
            h[b"TRUEPOS"] = self._on_truepos
        return h

    # -- per-line parsers (raise _Bad / ValueError on malformed lines) ---------------------------------------
    def _on_param(self, tok: list[bytes]) -> None:
        if len(tok) < 3:
            raise _Bad("needs a name and a value")
        key, value = tok[1].decode("ascii", "replace"), tok[2].decode("ascii", "replace")
        if self._params.get(key) != value:
            self._params[key] = value
            self._laser = self._configure_laser()
            self._stats.use_sensor_pose_source(self._sensor_pose_source())
            self._angles.clear()  # the bearings may depend on the PARAM
        return None

    def _angles_for(self, n: int, start: float | None, res: float | None) -> F64:
        key = (n, start if start is not None else math.nan, res if res is not None else math.nan)
        a = self._angles.get(key)
        if a is None:
            if start is None:
                a = flaser_angles(n, fov_rad=self._laser.fov_rad, resolution_rad=self._laser.resolution_rad)
                check_bearings(float(a[0]), float(a[-1] - a[0]) / max(n - 1, 1), n)
            else:
                check_bearings(start, res or 0.0, n)
                a = start + (res or 0.0) * np.arange(n, dtype=np.float64)
            a.flags.writeable = False
            if len(self._angles) > 64:
                self._angles.clear()
            self._angles[key] = a
        return a

    def _time(self, tok: list[bytes], start: int, what: str) -> int:
        """The stamp of a line whose payload ends at ``start``, after checking that its trailer has as many
        fields as this message's lines have in the head of the log (the trailer variants have 1, 2 or 3): a
        line with a field too many or too few (one range more than declared) shifts the trailer and is
        malformed, not read with every field shifted."""
        n = len(tok) - start
        extra = n - self._trailers.setdefault(tok[0], n)
        if extra:
            if not any(_is_number(t) for t in tok[start:]):
                raise _Bad("no timestamp")
            many = f"field{'s' if abs(extra) > 1 else ''} too {'many' if extra > 0 else 'few'}"
            raise _Bad(f"{what}: {abs(extra)} {many}")
        return _trailer_time(tok, start)

    def _on_flaser(self, tok: list[bytes]) -> ScanEvent:
        n = _count(tok, 1, "range")
        _need(tok, 2 + n + 6, f"declares {n} ranges")
        t = self._time(tok, 2 + n + 6, f"declares {n} ranges")
        raw = _ranges(tok, 2, n)
        v = _floats(tok[2 + n : 2 + n + 6], "pose")
        las = self._laser
        scan = Scan(
            t,
            clean_ranges(raw, las.max_range_m, las.min_range_m),
            self._angles_for(n, None, None),
            las.max_range_m,
            las.min_range_m,
            las.sensor_pose,
        )
        odom = _pose(v[3:6], "odometry")
        truth = None
        if self._truth_mode == "embedded":
            tp = _compose(_pose(v[0:3]), las.sensor_pose.inverse())
            truth = check_pose(tp.x, tp.y, tp.theta, "laser pose")
        return ScanEvent(t, scan, odom, truth)

    def _new_style(self, tok: list[bytes], robot: bool) -> tuple[int, Scan, list[float] | None]:
        head = _floats(tok[1:8], "laser header")
        _, start, _fov, res, max_r = head[:5]
        n = _count(tok, 8, "range")
        if len(tok) < 10 + n:
            raise _Bad(f"declares {n} ranges: line ends early")
        m = int(tok[9 + n])
        if not 0 <= m <= MAX_BEAMS:
            raise _Bad(f"remission count {m} out of range")
        tail = 11 if robot else 0
        what = f"declares {n} ranges and {m} remissions"
        _need(tok, 10 + n + m + tail, what)
        t = self._time(tok, 10 + n + m + tail, what)
        raw = _ranges(tok, 9, n)
        poses = _floats(tok[10 + n + m : 10 + n + m + 6], "pose") if robot else None
        if max_r > MAX_RANGE_LIMIT_M:
            raise _Bad(f"max range {max_r:.6g} m out of range")
        max_range = max_r if max_r > 0 else self._laser.max_range_m
        min_range = self._laser.min_range_m if self._laser.min_range_m < max_range else 0.0
        sensor_pose = self._laser.sensor_pose
        if poses is not None:
            sp = _relative(_pose(poses[3:6], "robot pose"), _pose(poses[0:3], "laser pose"))
            sensor_pose = check_pose(sp.x, sp.y, sp.theta, "laser mounting")
        scan = Scan(
            t,
            clean_ranges(raw, max_range, min_range),
            self._angles_for(n, start, res),
            max_range,
            min_range,
            sensor_pose,
        )
        return t, scan, poses

    def _on_rawlaser(self, tok: list[bytes]) -> ScanEvent:
        t, scan, _ = self._new_style(tok, robot=False)
        return ScanEvent(t, scan)

    def _on_robotlaser(self, tok: list[bytes]) -> ScanEvent:
        t, scan, poses = self._new_style(tok, robot=True)
        assert poses is not None
        odom = _pose(poses[3:6], "robot pose")
        return ScanEvent(t, scan, odom, odom if self._truth_mode == "embedded" else None)

    def _on_odom(self, tok: list[bytes]) -> OdomEvent:
        _need(tok, 7, "x y theta tv rv accel")
        t = self._time(tok, 7, "x y theta tv rv accel")
        v = _floats(tok[1:7], "odometry")
        tv, rv = check_speed(v[3], "velocity"), check_speed(v[4], "turn rate")
        event = OdomEvent(t, Odometry(t, _pose(v, "odometry"), tv, rv))
        self._odom_moved = self._odom_moved or tv != 0.0 or rv != 0.0
        return event

    def _on_truepos(self, tok: list[bytes]) -> TruthEvent:
        _need(tok, 7, "true pose and odometry")
        t = self._time(tok, 7, "true pose and odometry")
        v = _floats(tok[1:7], "pose")
        return TruthEvent(t, _pose(v, "true pose"))


# ---------------------------------------------------------------------------------------------------------
# the writer


def _fmt(values: Iterable[float], decimals: int | None) -> str:
    if decimals is None:
        return " ".join(map(repr, values))
    return " ".join(f"{v:.{decimals}f}" for v in values)


def _pose_fields(p: Pose2D, decimals: int | None) -> str:
    return _fmt((p.x, p.y, p.theta), decimals)


def _open_write(path: Path, tmp: Path) -> IO[str]:
    suffix = path.suffix.lower()
    if suffix == ".gz":
        return gzip.open(tmp, "wt", encoding="ascii", newline="\n")
    if suffix == ".bz2":
        return bz2.open(tmp, "wt", encoding="ascii", newline="\n")
    return open(tmp, "w", encoding="ascii", newline="\n")


# bearings agree when within float32 precision: every reader keeps them as a float32 start and step
# (io.canonical), so a scan read from a bag or from CARMEN is written back with the geometry it was read with
_BEARING_TOL = 1e-6


def _geometry_params(scan: Scan) -> dict[str, str] | None:
    """PARAMs needed so the reader rebuilds the scan's bearings; None if the readlog.c default matches.

    Raises:
        LogFormatError: the bearings are not uniform and centred on 0 (or readlog.c's layout).
    """
    a = scan.angles_rad
    n = a.size
    if n < 2:
        raise LogFormatError(f"cannot write a {n}-beam scan as CARMEN FLASER")
    if np.allclose(a, flaser_angles(n), rtol=0.0, atol=_BEARING_TOL):
        return None
    res = float((a[-1] - a[0]) / (n - 1))
    fov = float(a[-1] - a[0])
    if np.allclose(a, flaser_angles(n, fov_rad=fov, resolution_rad=res), rtol=0.0, atol=_BEARING_TOL):
        return {
            "laser_front_laser_fov": repr(math.degrees(fov)),
            "laser_front_laser_resolution": repr(math.degrees(res)),
        }
    raise LogFormatError(
        f"cannot write the scan as CARMEN FLASER: {n} bearings from {a[0]:.6f} to {a[-1]:.6f} rad are not "
        "uniform and centred on 0"
    )


def write_carmen(
    path: Path,
    ticks: Iterable[Tick],
    *,
    odometry: Iterable[Odometry] | None = None,
    params: Mapping[str, str] | None = None,
    hostname: str = "gndreplay",
    decimals: int | None = None,
) -> None:
    """Write ticks as a CARMEN log (plain, .gz or .bz2 by suffix) that :class:`CarmenReader` reads back.

    Lines: PARAMs (``params``, then the laser mounting ``robot_frontlaser_offset`` / ``_side_offset`` /
    ``_angular_offset``, ``laser_front_laser_max_range`` / ``_min_range``, and fov/resolution when the
    bearings
    are not readlog.c's), then in time order ODOM (``odometry`` if given, else one per tick from ``tick.odom``
    with zero velocities), TRUEPOS when ``tick.truth`` is set, and FLASER. FLASER's first triple is the laser
    pose (``odom ∘ sensor_pose``), the second the robot odometry. No-return beams (+inf) are written as the
    max range, invalid ones (nan) as ``nan``. Numbers are written with full precision (``decimals=None``) so
    the reader gets the same values back; times exactly to the ns. The file appears only once complete
    (written to a temporary file in the same folder, then renamed).

    Args:
        path: output file; ``.gz`` / ``.bz2`` compress.
        ticks: time-ordered ticks; all must share the first tick's scan geometry, max range and mounting.
        odometry: time-ordered odometry samples for the ODOM lines (e.g. at a higher rate than the scans).
        params: extra PARAM lines (name -> value).
        hostname: the ipc_hostname field.
        decimals: fixed decimals for ranges and poses instead of full precision.

    Raises:
        LogFormatError: a scan cannot be expressed as FLASER, or the laser changes between ticks.
    """
    path = Path(path)
    it = iter(ticks)
    first = next(it, None)
    with atomic_path(path) as tmp, _open_write(path, tmp) as out:
        _write_body(out, first, it, odometry, params or {}, hostname, decimals)


def _write_body(
    out: IO[str],
    first: Tick | None,
    rest: Iterator[Tick],
    odometry: Iterable[Odometry] | None,
    params: Mapping[str, str],
    host: str,
    decimals: int | None,
) -> None:
    out.write(
        f"{CARMEN_HEADER}\n"
        "# message_name [message contents] ipc_timestamp ipc_hostname logger_timestamp\n"
        "# PARAM param_name param_value\n"
        "# ODOM x y theta tv rv accel\n"
        "# TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta\n"
        "# FLASER num_readings [range_readings] x y theta odom_x odom_y odom_theta\n"
    )
    all_params = dict(params)
    if first is not None:
        sp, scan = first.scan.sensor_pose, first.scan
        all_params.update(
            {
                "robot_frontlaser_offset": repr(sp.x),
                "robot_frontlaser_side_offset": repr(sp.y),
                "robot_frontlaser_angular_offset": repr(sp.theta),
                "laser_front_laser_max_range": repr(float(scan.max_range_m)),
                "laser_front_laser_min_range": repr(float(scan.min_range_m)),
            }
        )
        all_params.update(_geometry_params(scan) or {})
    t0 = first.t_ns if first is not None else 0
    for k, v in all_params.items():
        if not k or any(c.isspace() for c in k + str(v)) or not str(v):
            raise LogFormatError(f"PARAM {k!r} = {v!r}: names and values must be single words")
        out.write(f"PARAM {k} {v} {host} 0\n")
    if first is None:
        return

    def trailer(t_ns: int) -> str:
        return f"{format_time_s(t_ns)} {host} {(t_ns - t0) / NS_PER_S:.6f}"

    ref = first.scan

    def scan_line(tick: Tick) -> str:
        s = tick.scan
        if (
            s.sensor_pose != ref.sensor_pose
            or s.max_range_m != ref.max_range_m
            or s.min_range_m != ref.min_range_m
            or s.angles_rad.shape != ref.angles_rad.shape
            or (
                s.angles_rad is not ref.angles_rad
                and not np.allclose(s.angles_rad, ref.angles_rad, rtol=0.0, atol=1e-9)
            )
        ):
            raise LogFormatError(
                f"tick {tick.index}: the laser (bearings, range limits or mounting) differs "
                "from the first tick's; a CARMEN FLASER stream has one laser"
            )
        r = np.where(np.isposinf(s.ranges_m), s.max_range_m, s.ranges_m)
        laser = _compose(tick.odom, s.sensor_pose)
        return (
            f"FLASER {r.size} {_fmt(r.tolist(), decimals)} {_pose_fields(laser, decimals)} "
            f"{_pose_fields(tick.odom, decimals)} {trailer(tick.t_ns)}\n"
        )

    def odom_line(o: Odometry) -> str:
        v = 0.0 if math.isnan(o.v_mps) else o.v_mps
        w = 0.0 if math.isnan(o.w_radps) else o.w_radps
        return f"ODOM {_pose_fields(o.pose, decimals)} {_fmt((v, w, 0.0), decimals)} {trailer(o.t_ns)}\n"

    def tick_lines(tick: Tick) -> str:
        lines = "" if odometry is not None else odom_line(Odometry(tick.t_ns, tick.odom))
        if tick.truth is not None:
            lines += (
                f"TRUEPOS {_pose_fields(tick.truth, decimals)} {_pose_fields(tick.odom, decimals)} "
                f"{trailer(tick.t_ns)}\n"
            )
        return lines + scan_line(tick)

    def all_ticks() -> Iterator[Tick]:
        yield first
        yield from rest

    if odometry is None:
        for tick in all_ticks():
            out.write(tick_lines(tick))
        return
    odo = iter(odometry)
    pending = next(odo, None)
    for tick in all_ticks():
        while pending is not None and pending.t_ns <= tick.t_ns:
            out.write(odom_line(pending))
            pending = next(odo, None)
        out.write(tick_lines(tick))
    while pending is not None:
        out.write(odom_line(pending))
        pending = next(odo, None)
