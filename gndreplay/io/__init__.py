"""Log readers: each yields time-ordered Ticks with constant memory; chosen by a small registry.

>>> with open_log(Path("mit-csail.clf.bz2"), options=ReadOptions(strict=True)) as log:  # doctest: +SKIP
...     for tick in log.ticks():
...         tick.scan.ranges_m, tick.odom
...     log.report.malformed

The format comes from the path (``LOG_SUFFIXES``; ``COMPRESSED_SUFFIXES`` by the inner suffix, for text
logs; a folder with ``metadata.yaml`` is a ROS2 bag) or from ``ReadOptions.fmt`` (``READERS`` keys, plus
the alias "rosbag" for any ROS bag). ``LOG_SUFFIXES`` is also what folder searches (``gndreplay batch``)
and default output names go by.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from pathlib import Path, PurePath

from ..errors import LogFormatError, did_you_mean
from ..types import Tick
from .base import LogDescription, LogReader, ReadReport, StreamInfo, special_file_kind
from .carmen import CarmenReader, write_carmen
from .options import DEFAULT_READ, ReadOptions
from .sync import SyncOptions

__all__ = [
    "COMPRESSED_SUFFIXES",
    "DEFAULT_READ",
    "LOG_SUFFIXES",
    "READERS",
    "LogDescription",
    "LogReader",
    "ReadOptions",
    "ReadReport",
    "StreamInfo",
    "SyncOptions",
    "detect_format",
    "log_stem",
    "log_suffix",
    "open_log",
    "read_ticks",
    "special_file_kind",
    "write_carmen",
]

ReaderFactory = Callable[..., LogReader]


def _rosbag(format_name: str) -> ReaderFactory:
    def make(path: Path, *, options: ReadOptions) -> LogReader:
        from .rosbag import RosbagReader  # rosbags is imported only when a bag is opened

        return RosbagReader(path, options=options, format_name=format_name)

    make.__name__ = f"open_{format_name}"
    return make


#: Format name -> reader factory (called as ``factory(path, options=...)``).
READERS: Mapping[str, ReaderFactory] = {
    "carmen": CarmenReader,
    "rosbag1": _rosbag("rosbag1"),
    "rosbag2": _rosbag("rosbag2"),
    "mcap": _rosbag("mcap"),
}
#: Log file suffix -> format name (lower case; compressed files by their inner suffix).
LOG_SUFFIXES: Mapping[str, str] = {
    ".clf": "carmen",
    ".log": "carmen",
    ".carmen": "carmen",
    ".bag": "rosbag1",
    ".mcap": "mcap",
}
#: Compression suffixes accepted after the suffix of a text (CARMEN) log: ``run.clf.bz2``.
COMPRESSED_SUFFIXES: tuple[str, ...] = (".gz", ".bz2")
_ALIASES = {"rosbag": None, "clf": "carmen", "ros1": "rosbag1", "ros2": "rosbag2"}
KNOWN_FORMATS_HELP = (
    "carmen (.clf, .log; plain, .gz or .bz2), rosbag1 (.bag), rosbag2 (folder with "
    "metadata.yaml), mcap (.mcap)"
)


def _ros2_dir(path: Path) -> Path | None:
    """The ROS2 bag folder for a folder or a file inside one (``.db3`` / ``.mcap``), else None."""
    if path.is_dir():
        return path if (path / "metadata.yaml").is_file() else None
    if path.suffix.lower() == ".db3" and (path.parent / "metadata.yaml").is_file():
        return path.parent
    return None


def _refuse_special(path: Path) -> None:
    """Refuse a FIFO, device or socket (or a folder holding one, a ROS2 bag's storage file) before anything
    opens it: reading one could block forever."""
    kind = special_file_kind(path)
    if kind is None and path.is_dir():
        try:
            kinds = ((e, special_file_kind(e)) for e in sorted(path.iterdir()))
            entry, kind = next(((e, k) for e, k in kinds if k is not None), (path, None))
        except OSError:
            entry = path
        path = entry
    if kind is not None:
        raise LogFormatError(f"{path}: is {kind}, not a log file (never opened)")


def detect_format(path: Path, fmt: str | None = None) -> tuple[str, Path]:
    """Format name and the path to open (a ``.db3`` inside a ROS2 bag opens its folder).

    Raises:
        LogFormatError: missing path, a FIFO / device / socket (never opened: reading could block), unknown
            suffix or ``fmt`` (the message lists the known formats).
    """
    path = Path(path)
    if not path.exists():
        raise LogFormatError(f"{path}: no such file or directory")
    _refuse_special(path)
    if fmt is not None:
        name = fmt.lower()
        if name in _ALIASES:
            name = _ALIASES[name] or ""
            if not name:  # "rosbag": any ROS bag, by its shape
                ros_fmt, target = detect_format(path)
                if ros_fmt == "carmen":
                    raise LogFormatError(
                        f"{path}: not a ROS bag (a .bag file, a ROS2 bag folder or an .mcap)"
                    )
                return ros_fmt, target
        if name not in READERS:
            raise LogFormatError(
                f"{path}: unknown format {fmt!r}; known formats: {', '.join(READERS)} "
                f"(and 'rosbag' for any ROS bag){did_you_mean(fmt, [*READERS, *_ALIASES])}"
            )
        ros2 = _ros2_dir(path)
        return name, ros2 if (ros2 is not None and name == "rosbag2") else path
    ros2 = _ros2_dir(path)
    if ros2 is not None:
        return "rosbag2", ros2
    if path.is_dir():
        raise LogFormatError(
            f"{path}: a folder without metadata.yaml is not a ROS2 bag; known formats: {KNOWN_FORMATS_HELP}"
        )
    suffixes = [s.lower() for s in path.suffixes]
    suffix = suffixes[-1] if suffixes else ""
    if suffix in COMPRESSED_SUFFIXES:
        suffix = suffixes[-2] if len(suffixes) >= 2 else ""
        if LOG_SUFFIXES.get(suffix) != "carmen":
            raise LogFormatError(
                f"{path}: unknown log format (compressed {suffix or 'file'}); known formats: "
                f"{KNOWN_FORMATS_HELP}; use --format"
            )
    found = LOG_SUFFIXES.get(suffix)
    if found is None:
        raise LogFormatError(
            f"{path}: unknown log format (suffix {suffix!r}); known formats: "
            f"{KNOWN_FORMATS_HELP}; use --format"
        )
    return found, path


def log_suffix(name: str | PurePath) -> str | None:
    """The log suffix a file name ends with, in lower case and with its compression (``".clf.bz2"``,
    ``".bag"``), or None when the name has none of ``LOG_SUFFIXES``."""
    suffixes = [s.lower() for s in PurePath(name).suffixes]
    if not suffixes:
        return None
    last = suffixes[-1]
    if last in COMPRESSED_SUFFIXES and len(suffixes) >= 2 and LOG_SUFFIXES.get(suffixes[-2]) == "carmen":
        return suffixes[-2] + last
    return last if last in LOG_SUFFIXES else None


def log_stem(name: str) -> str:
    """A log file name without its log suffix (``mit-csail.clf.bz2`` -> ``mit-csail``); the name itself
    when it has none (``.clf`` is a hidden name, not a suffix)."""
    suffix = log_suffix(name)
    return name[: -len(suffix)] if suffix else name


def open_log(path: Path | str, *, options: ReadOptions = DEFAULT_READ) -> LogReader:
    """Open a log with the reader for its format (a context manager; see :class:`LogReader`).

    Args:
        path: the log file or ROS2 bag folder.
        options: the format (instead of detecting it from the path), streams, strictness, laser-mounting
            fallback and sync bounds (see :class:`ReadOptions`).

    Raises:
        LogFormatError: missing file, unknown format, unreadable or refused log, unknown or ambiguous topic
            (messages name the file and list the candidates).
    """
    name, target = detect_format(Path(path), options.fmt)
    return READERS[name](target, options=options)


def read_ticks(path: Path | str, *, options: ReadOptions = DEFAULT_READ) -> Iterator[Tick]:
    """Convenience: open ``path`` (as :func:`open_log`) and yield its ticks, closing it at the end.

    Yields:
        time-ordered ticks.

    Raises:
        LogFormatError: as :func:`open_log` and ``LogReader.ticks``.
    """
    with open_log(path, options=options) as log:
        yield from log.ticks()
