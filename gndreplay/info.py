"""``gndreplay info``: what a log contains, as a frozen :class:`LogInfo` (plus rows for display).

CARMEN logs have no index, so they are streamed once through the same reader later commands use (the
numbers are exactly what a replay sees: skipped lines, reordering, scans without odometry). ROS bags and
MCAP files are summarised from their metadata (MCAP: the summary section, via the ``mcap`` library): message
counts come from the index, scan stamps from the raw header bytes (no decoding; on the replay's microsecond
clock, as the readers put them), and the beam statistics from a decoded, evenly spaced sample of at most
``sample`` scans (``LogInfo.stats_scans`` says how many).

The scan rate is the median scan period's (what the sensor runs at, whatever the gaps; count / duration is
reported beside it as the average), and a clock that was generated rather than recorded (every period the
same to the nanosecond, from a round start) is a warning: its rates and gaps describe the generator.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from .io import DEFAULT_READ, ReadOptions, detect_format, open_log
from .io.base import LogDescription, ReadReport
from .io.canonical import canonical_stamp
from .io.clock import fmt_ns, scan_clock
from .types import NS_PER_S, Pose2D, Scan

__all__ = [
    "Difference",
    "LogInfo",
    "StreamStat",
    "against_dict",
    "against_lines",
    "differences",
    "log_info",
    "stream_rows",
    "summary_rows",
]

DEFAULT_SAMPLE = 500
#: Start bearings closer than this are one [rad] (a bag's float32 fields round at ~1e-7 rad).
_SAME_START_RAD = 1e-5
#: At most this many distinct start bearings are told apart (a log's scanner has a handful).
_MAX_STARTS = 16
#: A scan's beams are unevenly spaced when a step departs from the scan's mean step by more than this share.
_UNEVEN_STEP = 0.01
#: Interleaved: consecutive scans start at different bearings in at least this share of the pairs seen.
_INTERLEAVED_SHARE = 0.25
#: The header stamps' median offset from the bag's record times shown in the table from this size on [s]
#: (a recorder writes within milliseconds of the stamp; a converter may not).
_LARGE_OFFSET_S = 1.0


@dataclass(frozen=True, slots=True)
class StreamStat:
    """One stream (ROS topic / CARMEN message type): count and rates.

    Attributes:
        rate_hz: the scan stream's 1 / median scan period; another stream's average (its stamps are not read).
        average_hz: (count - 1) / scan duration.
    """

    name: str
    msgtype: str
    role: str
    count: int | None
    rate_hz: float | None
    average_hz: float | None


@dataclass(frozen=True, slots=True)
class LogInfo:
    """Everything ``gndreplay info`` reports. Times are scan (sensor) stamps; angles in degrees for display.

    Attributes:
        path, format, size_bytes: the log.
        scans: number of scans (ticks a replay gets).
        start_ns, end_ns, duration_s: first / last scan stamp and their difference.
        scan_period_s: the median period between scans (None under two scans).
        clock_warning: the scan stamps are exactly periodic from a round start (``scan_clock``'s warning,
            also in ``warnings``), else None.
        streams: per topic / message type counts and rates.
        beams: distinct beam counts per scan.
        angle_min_deg, angle_max_deg, resolution_deg, fov_deg: scan geometry (of the first scan).
        range_min_m, range_max_m: sensor range limits (of the first scan).
        invalid_fraction, no_return_fraction: fraction of beams that are nan / +inf.
        shortest_return_m: the shortest finite range in the scans the statistics saw (None without any).
        stats_scans: scans the beam statistics were computed on (< scans when sampled).
        start_angles_deg: the distinct first-beam bearings, most frequent first (at most 16).
        start_pairs, start_changes: consecutive scan pairs seen (all, or the sampled scan and the next one)
            and how many of them start at different bearings: a scanner whose start bearing alternates
            (``interleaved``) takes each scan at other bearings.
        uneven_scans: scans whose beam spacing is not even (a step more than 1 % off the scan's mean).
        record_offset_s, record_offset_max_s: ROS bags / MCAP: the scans' header stamp minus the record
            (log) time, median and largest in magnitude [s]; None for CARMEN or without header stamps.
        laser_pose: the laser pose in the robot frame (x [m], y [m], theta [rad]).
        laser_pose_source: where it comes from (``ReadReport.sensor_pose_source``: log, tf, config default,
            none).
        odom_source, cmd_stream, truth_stream: where odometry, commands and ground truth come from.
        time_reversals: records stamped before the previous record of the same stream (scans, for bags).
        out_of_order: records stamped before a record read earlier (merged by time; CARMEN).
        late_dropped: records too late to place in time order (dropped).
        gaps, max_gap_s, gap_threshold_s: intervals between scans above the threshold; the longest.
        malformed, malformed_examples: skipped records.
        scans_without_odom_before, scans_without_odom_after: scans outside the odometry's time span
            (None when not computed).
        index_clock: the log had no timestamps.
        summary_source: "full pass" or what the summary was read from.
        warnings, notes: for the user.
    """

    path: str
    format: str
    size_bytes: int
    scans: int
    start_ns: int | None
    end_ns: int | None
    duration_s: float
    streams: tuple[StreamStat, ...]
    beams: tuple[int, ...]
    angle_min_deg: float
    angle_max_deg: float
    resolution_deg: float
    fov_deg: float
    range_min_m: float
    range_max_m: float
    invalid_fraction: float
    no_return_fraction: float
    stats_scans: int
    laser_pose: tuple[float, float, float]
    laser_pose_source: str
    odom_source: str
    cmd_stream: str | None
    truth_stream: str | None
    time_reversals: int
    out_of_order: int
    late_dropped: int
    gaps: int
    max_gap_s: float
    gap_threshold_s: float
    malformed: int
    malformed_examples: tuple[str, ...]
    scans_without_odom_before: int | None
    scans_without_odom_after: int | None
    index_clock: bool
    summary_source: str
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default=())
    scan_period_s: float | None = None
    clock_warning: str | None = None
    start_angles_deg: tuple[float, ...] = ()
    start_pairs: int = 0
    start_changes: int = 0
    uneven_scans: int = 0
    record_offset_s: float | None = None
    record_offset_max_s: float | None = None
    shortest_return_m: float | None = None

    @property
    def interleaved(self) -> bool:
        """Consecutive scans start at different bearings in at least a quarter of the pairs seen."""
        return (len(self.start_angles_deg) > 1 and self.start_pairs > 0
                and self.start_changes >= _INTERLEAVED_SHARE * self.start_pairs)

    @property
    def sampled(self) -> bool:
        return self.stats_scans < self.scans

    @property
    def synthetic_clock(self) -> bool:
        return self.clock_warning is not None

    @property
    def scan_rate_hz(self) -> float | None:
        """1 / the median scan period."""
        return 1.0 / self.scan_period_s if self.scan_period_s else None

    @property
    def average_rate_hz(self) -> float | None:
        """(scans - 1) / duration: the scan rate averaged over gaps."""
        return (self.scans - 1) / self.duration_s if self.scans > 1 and self.duration_s > 0 else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (tuples become lists; the streams a list of dicts; start and end also as UTC
        dates, ISO 8601)."""
        d = asdict(self)
        d["sampled"] = self.sampled
        d["start_s"] = None if self.start_ns is None else self.start_ns / NS_PER_S
        d["end_s"] = None if self.end_ns is None else self.end_ns / NS_PER_S
        d["start_utc"], d["end_utc"] = _utc(self.start_ns, "T"), _utc(self.end_ns, "T")
        d["scan_rate_hz"], d["average_rate_hz"] = self.scan_rate_hz, self.average_rate_hz
        d["synthetic_clock"] = self.synthetic_clock
        d["interleaved"] = self.interleaved
        out: dict[str, Any] = _jsonable(d)
        return out


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


# ---------------------------------------------------------------------------------------------------------


@dataclass(slots=True)
class _BeamStats:
    """Accumulates beam statistics over scans (constant memory)."""

    n: int = 0
    beams: set[int] = field(default_factory=set)
    total: int = 0
    invalid: int = 0
    no_return: int = 0
    shortest: float = math.inf
    first: Scan | None = None

    def add(self, scan: Scan) -> None:
        r = scan.ranges_m
        self.shortest = min(self.shortest, float(np.min(r, where=np.isfinite(r), initial=math.inf)))
        self.n += 1
        self.beams.add(int(r.size))
        self.total += int(r.size)
        self.invalid += int(np.count_nonzero(np.isnan(r)))
        self.no_return += int(np.count_nonzero(np.isposinf(r)))
        if self.first is None:
            self.first = scan


@dataclass(slots=True)
class _StartStats:
    """Accumulates the scans' start bearings, their changes between consecutive scans, and uneven spacing."""

    starts: dict[int, list[float]] = field(default_factory=dict)  # start // _SAME_START_RAD -> [scans, rad]
    pairs: int = 0
    changes: int = 0
    uneven: int = 0
    prev: int | None = None

    def add(self, scan: Scan, *, follows: bool) -> None:
        """``follows``: the scan comes right after the last one added (a consecutive pair)."""
        a = scan.angles_rad
        if a.size == 0:
            self.prev = None
            return
        key = round(float(a[0]) / _SAME_START_RAD)
        if key in self.starts:
            self.starts[key][0] += 1
        elif len(self.starts) < _MAX_STARTS:
            self.starts[key] = [1, float(a[0])]
        if follows and self.prev is not None:
            self.pairs += 1
            self.changes += key != self.prev
        self.prev = key
        if a.size > 2:
            mean = (float(a[-1]) - float(a[0])) / (a.size - 1)
            self.uneven += bool(np.max(np.abs(np.diff(a) - mean)) > _UNEVEN_STEP * abs(mean))

    def angles_deg(self) -> tuple[float, ...]:
        ranked = sorted(self.starts.items(), key=lambda kv: (-kv[1][0], kv[0]))
        return tuple(math.degrees(v[1]) for _, v in ranked)


def _geometry(
    first: Scan | None,
) -> tuple[float, float, float, float, float, float, tuple[float, float, float]]:
    if first is None or first.angles_rad.size == 0:
        nan = math.nan
        return nan, nan, nan, nan, nan, nan, (0.0, 0.0, 0.0)
    a = first.angles_rad
    res = float(np.degrees((a[-1] - a[0]) / (a.size - 1))) if a.size > 1 else 0.0
    amin, amax = float(np.degrees(a[0])), float(np.degrees(a[-1]))
    sp: Pose2D = first.sensor_pose
    return (
        amin,
        amax,
        res,
        abs(amax - amin),
        float(first.min_range_m),
        float(first.max_range_m),
        (sp.x, sp.y, sp.theta),
    )


def log_info(
    path: Path | str, *, options: ReadOptions = DEFAULT_READ, sample: int = DEFAULT_SAMPLE
) -> LogInfo:
    """Describe a log (see the module docstring for how each format is summarised).

    Args:
        path, options: as :func:`gndreplay.io.open_log` (``options.sync`` also sets the gap threshold).
        sample: at most this many scans are decoded for beam statistics of ROS bags / MCAP files.

    Raises:
        LogFormatError: as :func:`gndreplay.io.open_log`; also a log without scans.
    """
    path = Path(path)
    name, target = detect_format(path, options.fmt)
    size = _size(target)
    opts = replace(options, fmt=name)
    if name == "carmen":
        return _carmen_info(target, size, opts)
    return _ros_info(target, name, size, opts, sample=sample)


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(f.stat().st_size for f in path.iterdir() if f.is_file())
    return path.stat().st_size


def _streams(
    desc: LogDescription, counts: dict[str, int] | None, duration_s: float, scan_period_s: float | None
) -> tuple[StreamStat, ...]:
    """Each stream's count and rates; the scan stream's rate from its median period ``scan_period_s``."""
    out = []
    for s in desc.streams:
        count = counts.get(s.name, s.count) if counts is not None else s.count
        periodic = count is not None and count > 1 and s.role not in ("param", "tf_static")
        average = (count - 1) / duration_s if periodic and duration_s > 0 else None  # type: ignore[operator]
        median = 1.0 / scan_period_s if s.name == desc.scan_stream and scan_period_s else None
        out.append(StreamStat(s.name, s.msgtype, s.role, count, median or average, average))
    return tuple(out)


def _carmen_info(path: Path, size: int, opts: ReadOptions) -> LogInfo:
    from .io.carmen import CarmenReader

    stats, starts = _BeamStats(), _StartStats()
    stamps = array("q")
    with open_log(path, options=opts) as log:
        assert isinstance(log, CarmenReader)
        for tick in log.ticks():
            stats.add(tick.scan)
            starts.add(tick.scan, follows=True)
            stamps.append(tick.t_ns)
        desc, rep, counts = log.describe(), log.report, log.message_counts
    first_t, last_t = (stamps[0], stamps[-1]) if stamps else (None, None)
    duration = (last_t - first_t) / NS_PER_S if first_t is not None and last_t is not None else 0.0
    return _assemble(
        path,
        "carmen",
        size,
        desc,
        rep,
        stats,
        starts,
        stamps,
        duration,
        counts,
        opts.sync.gap_ns,
        "full pass",
        rep.scans_without_odom_before,
        rep.scans_without_odom_after,
    )


def _assemble(
    path: Path,
    fmt: str,
    size: int,
    desc: LogDescription,
    rep: ReadReport,
    stats: _BeamStats,
    starts: _StartStats,
    stamps: array[int],
    duration: float,
    counts: dict[str, int] | None,
    gap_ns: int,
    source: str,
    before: int | None,
    after: int | None,
    *,
    scans: int | None = None,
    reversals: int | None = None,
    gaps: int | None = None,
    max_gap_s: float | None = None,
    notes: tuple[str, ...] = (),
) -> LogInfo:
    amin, amax, res, fov, rmin, rmax, pose = _geometry(stats.first)
    total = max(stats.total, 1)
    period, clock = scan_clock(np.frombuffer(stamps, dtype=np.int64) if stamps else ())
    clock = None if rep.index_clock else clock
    return LogInfo(
        path=str(path), format=fmt, size_bytes=size, scans=rep.scans if scans is None else scans,
        start_ns=min(stamps) if stamps else None, end_ns=max(stamps) if stamps else None, duration_s=duration,
        streams=_streams(desc, counts, duration, period), scan_period_s=period, clock_warning=clock,
        beams=tuple(sorted(stats.beams)), angle_min_deg=amin, angle_max_deg=amax, resolution_deg=res,
        fov_deg=fov, range_min_m=rmin, range_max_m=rmax, invalid_fraction=stats.invalid / total,
        no_return_fraction=stats.no_return / total, stats_scans=stats.n, laser_pose=pose,
        laser_pose_source=rep.sensor_pose_source, odom_source=desc.odom_source, cmd_stream=desc.cmd_stream,
        truth_stream=desc.truth_stream, time_reversals=rep.time_reversals if reversals is None else reversals,
        out_of_order=rep.out_of_order, late_dropped=rep.late_dropped, gaps=rep.gaps if gaps is None else gaps,
        max_gap_s=rep.max_gap_s if max_gap_s is None else max_gap_s, gap_threshold_s=gap_ns / NS_PER_S,
        malformed=rep.malformed, malformed_examples=rep.malformed_examples, scans_without_odom_before=before,
        scans_without_odom_after=after, index_clock=rep.index_clock, summary_source=source,
        warnings=rep.warnings + ((clock,) if clock else ()), notes=desc.notes + notes,
        start_angles_deg=starts.angles_deg(), start_pairs=starts.pairs, start_changes=starts.changes,
        uneven_scans=starts.uneven,
        shortest_return_m=stats.shortest if math.isfinite(stats.shortest) else None,
    )


@dataclass(slots=True)
class _StampStats:
    """Scan stamps in file order: span, reversals, gaps, scans outside the odometry span."""

    gap_ns: int
    odom_span: tuple[int, int] | None
    seen: int = 0
    first: int | None = None
    last: int | None = None
    prev: int | None = None
    reversals: int = 0
    gaps: int = 0
    max_gap_ns: int = 0
    before: int = 0
    after: int = 0
    stamps: array[int] = field(default_factory=lambda: array("q"))
    offsets: array[int] = field(default_factory=lambda: array("q"))  # header stamp - record time [ns]

    def offset_s(self) -> tuple[float | None, float | None]:
        """The median and the largest-magnitude header - record time offset [s] (None without any)."""
        if not self.offsets:
            return None, None
        d = np.frombuffer(self.offsets, dtype=np.int64)
        return float(np.median(d)) / NS_PER_S, float(d[np.argmax(np.abs(d))]) / NS_PER_S

    def add(self, t: int) -> None:
        self.seen += 1
        self.stamps.append(t)
        if self.prev is not None:
            if t < self.prev:
                self.reversals += 1
            elif t - self.prev > self.gap_ns:
                self.gaps += 1
            self.max_gap_ns = max(self.max_gap_ns, t - self.prev)
        self.prev = t
        self.first = t if self.first is None else min(self.first, t)
        self.last = t if self.last is None else max(self.last, t)
        if self.odom_span is not None:
            self.before += t < self.odom_span[0]
            self.after += t > self.odom_span[1]


def _ros_info(path: Path, fmt: str, size: int, opts: ReadOptions, *, sample: int) -> LogInfo:
    from .errors import LogFormatError
    from .io.base import check_time
    from .io.mcap import mcap_files, read_mcap_summary
    from .io.rosbag import ODOMETRY, RosbagReader, rosbags_errors

    errors = rosbags_errors()
    malformed: list[str] = []

    def bad(i: int, topic: str, err: BaseException) -> None:
        where = f"message {i} on {topic}: cannot decode: {type(err).__name__}: {err}"
        if opts.strict:
            raise LogFormatError(f"{path} {where}") from err
        malformed.append(where)

    with open_log(path, options=opts) as log:
        assert isinstance(log, RosbagReader)
        desc, pose_source = log.describe(), log.report.sensor_pose_source
        counts: dict[str, int] | None = None
        source = "bag index / metadata"
        if mcap_files(path):
            summary = read_mcap_summary(path)
            counts = {c.topic: c.count for c in summary.channels}
            source = "MCAP summary section"
        n_scans = (counts or {}).get(log.scan_topic) or next(
            (s.count or 0 for s in desc.streams if s.name == log.scan_topic), 0
        )
        odom_span: tuple[int, int] | None = None  # from raw header stamps (Odometry topics only)
        if log.odom_topic is not None and log.topics[log.odom_topic].msgtype == ODOMETRY:
            stamps: list[int] = []
            for i, (_, raw) in enumerate(log.raw_messages(log.odom_topic), start=1):
                try:
                    s = canonical_stamp(check_time(log.header_stamp(raw)))
                except errors as err:
                    bad(i, log.odom_topic, err)
                    continue
                stamps = [min(stamps[0], s), max(stamps[1], s)] if stamps else [s, s]
            odom_span = (stamps[0], stamps[1]) if stamps else None
        every = max(1, math.ceil(n_scans / max(sample, 1)))
        beams, times, starts = _BeamStats(), _StampStats(opts.sync.gap_ns, odom_span), _StartStats()
        for i, (t_log, raw) in enumerate(log.raw_messages(log.scan_topic)):
            try:
                stamp = log.header_stamp(raw)
                times.add(canonical_stamp(check_time(stamp or t_log)))
                if stamp:
                    times.offsets.append(stamp - t_log)
                if i % every == 0 or (every > 1 and i % every == 1):  # the sample, each with the next scan
                    scan = log.decode_scan(raw, t_log)
                    starts.add(scan, follows=every == 1 or i % every == 1)
                    if i % every == 0:
                        beams.add(scan)
            except errors as err:
                bad(i + 1, log.scan_topic, err)
        if times.seen == 0:
            raise LogFormatError(f"{path}: no scans on {log.scan_topic}")
    rep = ReadReport(scans=times.seen, malformed=len(malformed), malformed_examples=tuple(malformed[:5]),
                     sensor_pose_source=pose_source)
    first_t, last_t = times.first, times.last
    duration = (last_t - first_t) / NS_PER_S if first_t is not None and last_t is not None else 0.0
    note = (f"beam statistics from {beams.n} of {times.seen} scans (every {every}th)",) if every > 1 else ()
    info = _assemble(
        path, fmt, size, desc, rep, beams, starts, times.stamps, duration, counts,
        opts.sync.gap_ns, source, times.before if odom_span else None, times.after if odom_span else None,
        reversals=times.reversals, gaps=times.gaps, max_gap_s=times.max_gap_ns / NS_PER_S, notes=note,
    )  # fmt: skip
    offset, largest = times.offset_s()
    return replace(info, record_offset_s=offset, record_offset_max_s=largest)


# ---------------------------------------------------------------------------------------------------------
# formatting as data


def _fmt_t(t_ns: int | None) -> str:
    """A stamp as seconds with microseconds, and its UTC date."""
    if t_ns is None:
        return "-"
    return f"{t_ns // NS_PER_S}.{t_ns % NS_PER_S // 1000:06d} s ({_utc(t_ns, ' ')} UTC)"


def _utc(t_ns: int | None, sep: str) -> str | None:
    """A stamp as an ISO 8601 UTC date to the millisecond (``sep`` between date and time)."""
    if t_ns is None:
        return None
    date = datetime(1970, 1, 1, tzinfo=UTC) + timedelta(microseconds=t_ns // 1000)
    return date.replace(tzinfo=None).isoformat(sep=sep, timespec="milliseconds") + ("Z" if sep == "T" else "")


def _fmt_rate(info: LogInfo) -> str:
    """The scan rate row: the median period's rate, then the average over the duration."""
    if info.scan_rate_hz is None or info.scan_period_s is None:
        return "-"
    average = "" if info.average_rate_hz is None else f"; average {info.average_rate_hz:.2f} Hz"
    return f"{info.scan_rate_hz:.2f} Hz (median period {1000 * info.scan_period_s:.1f} ms{average})"


def _fmt_starts(info: LogInfo) -> str:
    """The beam geometry row: one start bearing, or the distinct ones and how often consecutive scans differ;
    uneven spacing."""
    starts = info.start_angles_deg
    if not starts:
        return "-"
    if len(starts) == 1:
        out = f"every scan starts at {starts[0]:.3f} deg"
    else:
        kind = "interleaved: " if info.interleaved else ""
        out = (f"{kind}{len(starts)} start bearings ({', '.join(f'{a:.3f}' for a in starts)} deg), "
               f"different in {info.start_changes} of {info.start_pairs} consecutive scan pairs")
    uneven = f"; uneven beam spacing in {info.uneven_scans} scans" if info.uneven_scans else "; evenly spaced"
    return out + uneven


def summary_rows(info: LogInfo) -> list[tuple[str, str]]:
    """(label, value) rows for the summary table (the same facts as ``to_dict``)."""
    x, y, th = info.laser_pose
    beams = ", ".join(map(str, info.beams)) or "-"
    sampled = f" (sampled: {info.stats_scans} of {info.scans} scans)" if info.sampled else ""
    rows = [
        ("file", info.path),
        ("format", f"{info.format} ({info.size_bytes / 1e6:.1f} MB; {info.summary_source})"),
        ("scans", f"{info.scans} of {beams} beams"),
        ("start", _fmt_t(info.start_ns)),
        ("end", _fmt_t(info.end_ns)),
        ("duration", f"{info.duration_s:.1f} s"),
        ("scan rate", _fmt_rate(info)),
        (
            "field of view",
            f"{info.fov_deg:.1f} deg ({info.angle_min_deg:.2f} to {info.angle_max_deg:.2f} deg, "
            f"{info.resolution_deg:.3f} deg steps)",
        ),
        ("beam geometry", _fmt_starts(info)),
        ("range limits", f"{info.range_min_m:g} - {info.range_max_m:g} m"),
        ("invalid beams", f"{100 * info.invalid_fraction:.2f} %{sampled}"),
        ("no-return beams", f"{100 * info.no_return_fraction:.2f} %{sampled}"),
        ("laser pose in robot", f"x {x:g} m, y {y:g} m, theta {math.degrees(th):g} deg"),
        ("laser pose from", info.laser_pose_source),
        ("odometry", info.odom_source),
        ("commands", info.cmd_stream or "none"),
        ("ground truth", info.truth_stream or "none"),
        ("time reversals", str(info.time_reversals)),
        ("out of file order", f"{info.out_of_order} (merged by timestamp)" if info.out_of_order else "0"),
        ("gaps", f"{info.gaps} > {info.gap_threshold_s:g} s (longest {info.max_gap_s:.2f} s)"),
    ]
    if info.late_dropped:
        rows.append(("dropped (too late)", str(info.late_dropped)))
    if info.scans_without_odom_before is not None:
        rows.append(
            (
                "scans outside odometry",
                f"{info.scans_without_odom_before} before, {info.scans_without_odom_after} after",
            )
        )
    malformed = str(info.malformed)
    if info.malformed_examples:
        malformed += " (" + "; ".join(info.malformed_examples) + ")"
    rows.append(("malformed records", malformed))
    if info.record_offset_s is not None and abs(info.record_offset_s) >= _LARGE_OFFSET_S:
        side = "after" if info.record_offset_s > 0 else "before"
        rows.append(("header vs record time", f"scan header stamps {abs(info.record_offset_s):.3f} s {side} "
                     f"the bag's record times (median; largest {info.record_offset_max_s:+.3f} s)"))
    if info.index_clock:
        rows.append(("clock", "index clock (no timestamps in the log)"))
    if info.clock_warning is not None:
        rows.append(("clock", info.clock_warning))
    rows.extend(("note", n) for n in info.notes)
    return rows


def stream_rows(info: LogInfo) -> list[tuple[str, str, str, str, str, str]]:
    """(stream, type, used as, count, rate, average) rows for the streams table."""
    return [
        (
            s.name,
            s.msgtype,
            s.role if s.role != "other" else "",
            "?" if s.count is None else str(s.count),
            "" if s.rate_hz is None else f"{s.rate_hz:.2f} Hz",
            "" if s.average_hz is None else f"{s.average_hz:.2f} Hz",
        )
        for s in info.streams
    ]


#: What :func:`differences` calls the same: bearings [deg], lengths [m], the laser's heading [rad].
_SAME_DEG, _SAME_M, _SAME_RAD = 1e-3, 1e-4, 1e-4
#: The consequence of any difference in the scans' geometry or data.
_SCANS_DIFFER = "so the map and the corrected trajectories will differ"


@dataclass(frozen=True, slots=True)
class Difference:
    """One way two logs of the same recording disagree: ``what``, this log's value against the other's, what
    that changes, and whether a replay reads it (a range limit no return falls between changes nothing)."""

    what: str
    this: str
    other: str
    effect: str
    affects_replay: bool = True

    def __str__(self) -> str:
        return f"{self.what}: {self.this} against {self.other}"

    def line(self) -> str:
        """The difference and what it changes, in one line."""
        return f"{self}; {self.effect}"


def differences(a: LogInfo, b: LogInfo) -> list[Difference]:
    """Where ``a`` (this log) and ``b`` (the other: a bag converted from a CARMEN file, say) disagree in
    what a replay reads: scan count and beams, bearings, range limits, the laser's mounting, the stamps'
    start and clock, start-bearing interleaving, recorded commands and ground truth. Empty when they agree."""
    out: list[Difference] = []
    if a.scans != b.scans:
        more = "more" if b.scans > a.scans else "fewer"
        out.append(Difference("scans", str(a.scans), str(b.scans),
                              f"a replay of the other gets {abs(b.scans - a.scans)} {more} ticks"))
    if a.beams != b.beams:
        out.append(Difference("beams per scan", ", ".join(map(str, a.beams)), ", ".join(map(str, b.beams)),
                              f"the scans hold other beams, {_SCANS_DIFFER}"))
    out += _bearing_differences(a, b)
    if a.interleaved != b.interleaved:
        out.append(Difference("interleaved start bearings", _yes(a.interleaved), _yes(b.interleaved),
                              f"consecutive scans start at other bearings in one of them, {_SCANS_DIFFER}"))
    out += _range_differences(a, b)
    (ax, ay, ath), (bx, by, bth) = a.laser_pose, b.laser_pose
    if (abs(ax - bx) > _SAME_M or abs(ay - by) > _SAME_M
            or abs(math.remainder(ath - bth, 2.0 * math.pi)) > _SAME_RAD):
        out.append(Difference(
            "laser pose in robot",
            f"({ax:g} m, {ay:g} m, {math.degrees(ath):g} deg) from {a.laser_pose_source}",
            f"({bx:g} m, {by:g} m, {math.degrees(bth):g} deg) from {b.laser_pose_source}",
            f"the scan points sit elsewhere around the robot, {_SCANS_DIFFER}"))
    if a.start_ns is not None and b.start_ns is not None and a.start_ns != b.start_ns:
        d = b.start_ns - a.start_ns
        out.append(Difference("first scan stamp", _fmt_s(a.start_ns), _fmt_s(b.start_ns),
                              f"the other starts {fmt_ns(abs(d))} s {'later' if d > 0 else 'earlier'}: the "
                              "times in commands.csv and the trajectory files differ, and relations or "
                              "ground truth stamped on one clock do not match the other"))
    if a.synthetic_clock != b.synthetic_clock:
        out.append(Difference("scan clock", _clock(a), _clock(b),
                              "the stamps of one were generated, so the odometry interpolated at them, and "
                              "with it the corrected trajectories, differ"))
    for what, x, y, role in (("recorded commands", a.cmd_stream, b.cmd_stream, "--mode teleop and the "
                              "log_v, log_w columns of commands.csv have them in one only"),
                             ("ground truth", a.truth_stream, b.truth_stream, "ATE / RPE and the error "
                              "figures come with one only")):
        if (x is None) != (y is None):
            out.append(Difference(what, x or "none", y or "none", role))
    return out


def _bearing_differences(a: LogInfo, b: LogInfo) -> list[Difference]:
    """First and last bearing and beam step, each with how far the bearings end up apart."""
    d_first, d_last = abs(a.angle_min_deg - b.angle_min_deg), abs(a.angle_max_deg - b.angle_max_deg)
    far, where = max(d_first, d_last), "first" if d_first >= d_last else "last"
    out = []
    for what, x, y in (("first bearing", a.angle_min_deg, b.angle_min_deg),
                       ("last bearing", a.angle_max_deg, b.angle_max_deg),
                       ("beam step", a.resolution_deg, b.resolution_deg)):
        if math.isclose(x, y, rel_tol=0.0, abs_tol=_SAME_DEG):
            continue
        if what == "beam step":
            effect = f"the bearings are up to {far:.2f} deg apart (at the {where} beam)"
        else:
            effect = f"the {what.split()[0]} beam points {abs(x - y):.2f} deg apart"
        out.append(Difference(what, f"{x:.4f} deg", f"{y:.4f} deg", f"{effect}, {_SCANS_DIFFER}"))
    return out


def _range_differences(a: LogInfo, b: LogInfo) -> list[Difference]:
    """Range limits. A minimum matters only if the log with the lower one has a return below the higher one
    (the other reads it as invalid), which a full pass knows and a sample can only suggest."""
    out = []
    if not math.isclose(a.range_min_m, b.range_min_m, rel_tol=0.0, abs_tol=_SAME_M):
        low, high = (a, b) if a.range_min_m < b.range_min_m else (b, a)
        low_name, high_name = ("this log", "the other") if low is a else ("the other", "this log")
        hi = f"{high.range_min_m:g} m"
        shortest = low.shortest_return_m
        if shortest is not None and shortest < high.range_min_m:
            effect = (f"{low_name} has returns shorter than {hi}: hits in it, invalid in {high_name}, "
                      f"{_SCANS_DIFFER}")
            matters = True
        elif low.sampled:
            effect = (f"none of the {low.stats_scans} scans of {low_name} sampled has a return shorter than "
                      f"{hi}; one in another scan would be a hit in it and invalid in {high_name}")
            matters = True
        else:
            effect = f"no return in {low_name} is shorter than {hi}, so a replay reads the same"
            matters = False
        out.append(Difference("range min", f"{a.range_min_m:g} m", f"{b.range_min_m:g} m", effect, matters))
    if not math.isclose(a.range_max_m, b.range_max_m, rel_tol=0.0, abs_tol=_SAME_M):
        short, long = sorted((a.range_max_m, b.range_max_m))
        out.append(Difference("range max", f"{a.range_max_m:g} m", f"{b.range_max_m:g} m",
                              f"returns from {short:g} to {long:g} m are no-returns in one and hits in the "
                              f"other, and no-returns clear the map to other lengths, {_SCANS_DIFFER}"))
    return out


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _clock(info: LogInfo) -> str:
    return "generated" if info.synthetic_clock else "recorded"


def _fmt_s(t_ns: int) -> str:
    """A stamp as seconds, with as many decimals as it needs."""
    return f"{fmt_ns(t_ns)} s"


def against_lines(this: LogInfo, other: LogInfo) -> list[str]:
    """``info --against``: a heading naming the other log, then each difference that a replay reads with what
    it changes, or that there is none; then the differences a replay does not read."""
    found = differences(this, other)
    read = [d for d in found if d.affects_replay]
    unread = [d for d in found if not d.affects_replay]
    where = f"against {other.path} ({other.format})"
    if read:
        lines = [f"{where}: {len(read)} difference{'s' if len(read) > 1 else ''} in what a replay reads "
                 "(this log's value against the other's)", *(f"  {d.line()}" for d in read)]
    else:
        lines = [f"{where}: no difference in what a replay reads"]
    lines += [f"  without effect: {d.line()}" for d in unread]
    return lines


def against_dict(this: LogInfo, other: LogInfo) -> dict[str, Any]:
    """``info --against --json``: the other log, whether a replay reads the two differently, and every
    difference (``Difference``'s fields)."""
    found = differences(this, other)
    return {"path": other.path, "format": other.format,
            "replay_differs": any(d.affects_replay for d in found),
            "differences": [asdict(d) for d in found]}
