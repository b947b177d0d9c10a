"""MCAP files: the summary section (channels, message counts, start/end) without decoding any message.

Bare ``.mcap`` files and ROS2 bags with MCAP storage are *read* through rosbags like every bag (it is ~13x
faster than mcap-ros2-support, see ECOSYSTEM.md §2); this module only serves ``gndreplay info``, which must
not decode every message of a large recording, and raw stamp access (header stamps read from the CDR bytes).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import LogFormatError

__all__ = ["McapChannel", "McapSummary", "mcap_files", "read_mcap_summary"]


@dataclass(frozen=True, slots=True)
class McapChannel:
    """One channel of an MCAP summary."""

    topic: str
    schema: str
    encoding: str
    count: int


@dataclass(frozen=True, slots=True)
class McapSummary:
    """What an MCAP file's summary section says (summed over the files of a ROS2 bag folder).

    Attributes:
        files: the MCAP files read.
        channels: per topic (channels of the same topic merged), sorted by topic.
        message_count: all messages.
        start_ns, end_ns: log time of the first and last message.
        compression: chunk compressions seen ("" = none).
    """

    files: tuple[Path, ...]
    channels: tuple[McapChannel, ...]
    message_count: int
    start_ns: int
    end_ns: int
    compression: tuple[str, ...]


def mcap_files(path: Path) -> list[Path]:
    """The MCAP files of a bare ``.mcap`` path or of a ROS2 bag folder (empty if none)."""
    if path.is_dir():
        return sorted(path.glob("*.mcap"))
    return [path] if path.suffix.lower() == ".mcap" else []


def _errors() -> tuple[type[BaseException], ...]:
    """What the mcap library raises on corrupt bytes (the one place that lists them): its own errors, and
    what a damaged record length or compressed block makes the parsing and decompression below it raise."""
    from mcap.exceptions import McapError

    from .rosbag import rosbags_errors

    return (McapError, *rosbags_errors())


def read_mcap_summary(path: Path) -> McapSummary:
    """Read the summary section of the MCAP file(s) at ``path`` (seeks to the footer; no message is read).

    Raises:
        LogFormatError: not an MCAP file, corrupt or truncated, or written without a summary section.
    """
    from mcap.reader import make_reader

    files = mcap_files(path)
    if not files:
        raise LogFormatError(f"{path}: no .mcap file")
    counts: dict[str, list[object]] = {}
    total, start, end = 0, None, None
    compression: set[str] = set()
    for f in files:
        try:
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
        except _errors() as err:
            raise LogFormatError(f"{f}: corrupt or truncated MCAP file: {type(err).__name__}: {err}") from err
        if summary is None or summary.statistics is None:
            raise LogFormatError(f"{f}: MCAP file has no summary section (was the recording interrupted?)")
        st = summary.statistics
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            entry = counts.setdefault(ch.topic, [schema.name if schema else "", ch.message_encoding, 0])
            entry[2] = int(entry[2]) + st.channel_message_counts.get(cid, 0)  # type: ignore[call-overload]
        total += st.message_count
        if st.message_count:
            start = st.message_start_time if start is None else min(start, st.message_start_time)
            end = st.message_end_time if end is None else max(end, st.message_end_time)
        compression.update(ci.compression for ci in summary.chunk_indexes)
    channels = tuple(
        McapChannel(t, _ros_type(str(v[0])), str(v[1]), int(v[2]))  # type: ignore[call-overload]
        for t, v in sorted(counts.items())
    )
    return McapSummary(tuple(files), channels, total, start or 0, end or 0, tuple(sorted(compression)))


def _ros_type(schema: str) -> str:
    """``sensor_msgs/LaserScan`` -> ``sensor_msgs/msg/LaserScan`` (the rosbags spelling)."""
    parts = schema.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else schema
