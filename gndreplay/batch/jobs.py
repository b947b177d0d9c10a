"""Batch inputs: what one batch row runs (a :class:`Job`) and how command-line paths expand into jobs.

A path names a log (CARMEN ``.clf``/``.log``/``.carmen``, plain or ``.gz``/``.bz2``; ROS1 ``.bag``; ``.mcap``;
a ROS2 bag folder, i.e. a folder holding ``metadata.yaml``) or a folder searched recursively for logs.
Jobs carry a ``kind`` so closed-loop scenarios can join later as ``kind="scenario"`` without changing the
pool, the thresholds or the reports.
"""

from __future__ import annotations

import os
import re
import stat
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from .. import fsutil
from ..errors import ConfigError

__all__ = [
    "COMPRESSED_SUFFIXES",
    "LOG_SUFFIXES",
    "RESERVED_NAMES",
    "Job",
    "JobKind",
    "expand_inputs",
    "find_logs",
    "input_stem",
    "is_log",
    "safe_name",
    "special_file_kind",
    "special_files",
    "unique_names",
]

JobKind = Literal["log", "scenario"]

#: Suffixes of log files found in folders (ROS2 bag folders are recognised by their metadata.yaml).
LOG_SUFFIXES: tuple[str, ...] = (".clf", ".log", ".carmen", ".bag", ".mcap")
#: Compression suffixes accepted after a text-log suffix (``run.clf.bz2``).
COMPRESSED_SUFFIXES: tuple[str, ...] = (".gz", ".bz2")
_TEXT_LOG_SUFFIXES = (".clf", ".log", ".carmen")
_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")
#: Names of the batch folder's own files, never given to an input's run directory.
RESERVED_NAMES: tuple[str, ...] = ("summary.csv", "summary.md", "junit.xml")


@dataclass(frozen=True, slots=True)
class Job:
    """One batch input.

    Attributes:
        name: unique in the batch; names the run directory, the summary row and the JUnit test case.
        path: the log file or ROS2 bag folder (a scenario file once scenarios join).
        kind: "log" (replayed with ``run_log``) or "scenario" (closed loop; not implemented yet).
        relations: SLAM-benchmark relations file to score the corrected trajectory against, or None.
        goal_xy: fixed goal [m] in the corrected odometry frame instead of the run options' goal.
    """

    name: str
    path: Path
    kind: JobKind = "log"
    relations: Path | None = None
    goal_xy: tuple[float, float] | None = None


def _log_suffix(path: Path) -> str | None:
    """The recognised log suffix of a file name (``".clf.bz2"``, ``".bag"``), or None."""
    suffixes = [s.lower() for s in path.suffixes]
    if not suffixes:
        return None
    last = suffixes[-1]
    if last in COMPRESSED_SUFFIXES and len(suffixes) >= 2 and suffixes[-2] in _TEXT_LOG_SUFFIXES:
        return suffixes[-2] + last
    return last if last in LOG_SUFFIXES else None


def _is_ros2_bag(path: Path) -> bool:
    return path.is_dir() and (path / "metadata.yaml").is_file()


def is_log(path: Path) -> bool:
    """True for a file with a log suffix or a ROS2 bag folder (what a folder search picks up)."""
    return _is_ros2_bag(path) or (path.is_file() and _log_suffix(path) is not None)


def find_logs(folder: Path) -> list[Path]:
    """Logs inside ``folder``, recursively, in sorted path order.

    Hidden entries (``.name``) and gndreplay's own output folders (run directories, batch folders: their
    results.mcap is not a log) are skipped; a ROS2 bag folder is one log (its files are not searched).
    """
    found: list[Path] = []
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith(".") or fsutil.is_output_dir(entry):
            continue
        if is_log(entry):
            found.append(entry)
        elif entry.is_dir():
            found.extend(find_logs(entry))
    return found


def safe_name(name: str) -> str:
    """``name`` usable as a run-directory name: characters outside ``[A-Za-z0-9._+-]`` become ``_``, then
    ``fsutil.safe_name`` (never hidden, ``.`` or ``..``); ``"input"`` if nothing is left."""
    return fsutil.safe_name(_UNSAFE.sub("_", name), "input")


def input_stem(path: Path) -> str:
    """A log name without its log suffix (``mit-csail.clf.bz2`` -> ``mit-csail``; a bag folder: its name),
    made safe for a folder name (``.hidden.clf`` -> ``hidden``)."""
    suffix = None if path.is_dir() else _log_suffix(path)
    name = path.name[: -len(suffix)] if suffix and len(path.name) > len(suffix) else path.name
    return safe_name(name)


def unique_names(paths: Sequence[Path]) -> list[str]:
    """One name per path, unique in the list: the stem, qualified by the parent folder where stems collide,
    then numbered (``-2``, ``-3``) if still equal."""
    stems = [input_stem(p) for p in paths]
    counts = Counter(stems)
    wanted = [
        safe_name(f"{p.parent.name}-{s}") if counts[s] > 1 and p.parent.name else s
        for p, s in zip(paths, stems, strict=True)
    ]
    used: set[str] = set(RESERVED_NAMES)
    names: list[str] = []
    for name in wanted:
        candidate, k = name, 1
        while candidate in used:
            k += 1
            candidate = f"{name}-{k}"
        used.add(candidate)
        names.append(candidate)
    return names


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


def special_files(path: Path) -> list[str]:
    """``"<path> (a FIFO)"`` for ``path`` if it is a FIFO, device or socket, or for each such file
    directly inside it when it is a folder (a ROS2 bag folder's storage files); never opens any of them."""
    kind = special_file_kind(path)
    if kind is not None:
        return [f"{path} ({kind})"]
    if not path.is_dir():
        return []
    try:
        entries = sorted(path.iterdir())
    except OSError:
        return []
    return [f"{e} ({k})" for e in entries if (k := special_file_kind(e)) is not None]


def _expand_one(path: Path) -> list[Path]:
    if path.is_dir() and not _is_ros2_bag(path):
        logs = find_logs(path)
        if not logs:
            raise ConfigError(
                f"{path}: no logs in this folder (looked for {', '.join(LOG_SUFFIXES)}, "
                "compressed .gz/.bz2 text logs and ROS2 bag folders)"
            )
        return logs
    return [path]  # a file, a bag folder, or a missing path (reported as that input's error)


def expand_inputs(inputs: Iterable[str | Path]) -> list[Job]:
    """Jobs for command-line inputs, in the order given (folders expanded in sorted order).

    A file is taken as given whatever its suffix (a file that cannot be read becomes that input's error);
    a path given twice (also through a folder) runs once. Names are safe folder names (see ``safe_name``).
    Nothing is opened here (FIFOs, devices and sockets are refused by ``make_tasks``).

    Raises:
        ConfigError: no inputs, or a folder without any log in it.
    """
    paths: list[Path] = []
    seen: set[Path] = set()
    for raw in inputs:
        for path in _expand_one(Path(raw)):
            key = path.resolve()
            if key not in seen:
                seen.add(key)
                paths.append(path)
    if not paths:
        raise ConfigError("no inputs: give log files or folders of logs")
    return [Job(name=n, path=p) for n, p in zip(unique_names(paths), paths, strict=True)]
