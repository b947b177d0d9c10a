"""Read a run directory back (commands.csv, timing.csv, the TUM trajectories, summary.json, maps.npz).

Only the files are used: ``gndreplay report RUN_DIR`` redraws everything without the log. The folder may
have been damaged since the run wrote it: each file is read through :mod:`gndreplay.io.userfile` (a regular
file of bounded size, UTF-8, JSON nesting bounded) and maps.npz's members are checked before they are
loaded (:func:`~gndreplay.report.maps.load_maps`); anything malformed is a one-line RunDirError naming the
file and the line, key or member.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import ConfigError, GndReplayError
from ..evaluation import MAX_TUM_BYTES
from ..evaluation import read_tum as read_tum_ns
from ..io.userfile import load_json, read_text
from .maps import MAPS_FILE, MapsData, load_maps

__all__ = ["Commands", "RunData", "RunDirError", "Timing", "check_summary", "load_run", "read_commands",
           "read_timing", "read_tum"]

F64 = NDArray[np.float64]
TIMING_MODULES = ("match", "model", "planner", "reactor")
MAX_TABLE_BYTES = MAX_TUM_BYTES
"""Largest commands.csv / timing.csv read back (256 MB: millions of ticks, days of a long run)."""
MAX_SUMMARY_BYTES = 16 << 20
"""Largest summary.json read back (16 MB; a run writes a few KB)."""


class RunDirError(GndReplayError):
    """A run directory cannot be read back: a file is missing or malformed (the message names it)."""


@dataclass(frozen=True, slots=True, eq=False)
class Commands:
    """commands.csv as arrays.

    Attributes:
        t_s: (K,) tick times [s]; v_mps, vy_mps, w_radps: (K,) the commands.
        modes, situations: (K,) str arrays.
        flags: flag name -> (K,) bool mask, for every flag that fired at least once (in first-seen order).
        desired, active, takeover: (K,) str arrays: the desired and the active navigation mode and the
            takeover reason ("" when none). A run written before the audit existed reads as "gnd", "gnd", "".
        subgoal: (K,) int: the path follower's subgoal (-1 outside path following).
    """

    t_s: F64
    v_mps: F64
    vy_mps: F64
    w_radps: F64
    modes: NDArray[np.str_]
    situations: NDArray[np.str_]
    flags: Mapping[str, NDArray[np.bool_]]
    desired: NDArray[np.str_] = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    active: NDArray[np.str_] = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    takeover: NDArray[np.str_] = field(default_factory=lambda: np.zeros(0, dtype=np.str_))
    subgoal: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True, eq=False)
class Timing:
    """timing.csv as arrays: t_s (K,), ms per module name (K,) (match, model, planner, reactor, total) and
    over_budget: flag name -> (K,) bool mask for the ``*_OVER_BUDGET`` flags that fired."""

    t_s: F64
    ms: Mapping[str, F64]
    over_budget: Mapping[str, NDArray[np.bool_]] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, eq=False)
class RunData:
    """Everything the report needs from a run directory.

    Attributes:
        run_dir: the directory.
        commands, timing: the per-tick tables.
        traj_odom, traj_corrected: (M, 4) t [s], x, y [m], yaw [rad] from the TUM files (every scan).
        summary: summary.json.
        maps: maps.npz, or None when the run was written without it.
    """

    run_dir: Path
    commands: Commands
    timing: Timing
    traj_odom: F64
    traj_corrected: F64
    summary: dict[str, Any]
    maps: MapsData | None


def _need(path: Path) -> Path:
    if not path.is_file():
        raise RunDirError(f"{path}: missing (is {path.parent} a gndreplay run directory?)")
    return path


def _rows(path: Path) -> list[list[str]]:
    """The rows of a CSV file of the run (bounded: see ``MAX_TABLE_BYTES``)."""
    try:
        text = read_text(_need(path), "run table", MAX_TABLE_BYTES)
    except ConfigError as err:
        raise RunDirError(str(err)) from None
    return list(csv.reader(io.StringIO(text, newline="")))


#: commands.csv's header before the assisted-navigation audit (still read: desired = active = "gnd").
_COMMAND_HEADER_V1 = ["t", "v", "vy", "w", "mode", "situation", "flags"]


def read_commands(path: Path) -> Commands:
    """Parse commands.csv (header ``replay.COMMAND_COLUMNS``, or the older one without the audit columns
    ``desired,active,takeover,subgoal``).

    Raises:
        RunDirError: missing file, wrong header or a malformed row (named by line).
    """
    from ..replay import COMMAND_COLUMNS

    rows = _rows(path)
    expected = list(COMMAND_COLUMNS)
    if not rows or rows[0] not in (expected, _COMMAND_HEADER_V1):
        raise RunDirError(f"{path}: expected header {','.join(expected)}")
    width = len(rows[0])
    body = rows[1:]
    num = np.empty((len(body), 4), dtype=np.float64)
    subgoal = np.full(len(body), -1, dtype=np.int64)
    flags: dict[str, NDArray[np.bool_]] = {}
    for k, r in enumerate(body):
        try:
            if len(r) != width:
                raise ValueError(f"{len(r)} fields")
            num[k] = [float(x) for x in r[:4]]
            if width > 7:
                subgoal[k] = int(r[10])
        except ValueError as err:
            raise RunDirError(
                f"{path} line {k + 2}: expected {width} fields t,v,vy,w (numbers),mode,situation,flags"
                f"{',desired,active,takeover,subgoal (an integer)' if width > 7 else ''} ({err})"
            ) from err
        for name in filter(None, r[6].split("|")):
            mask = flags.get(name)
            if mask is None:
                mask = flags[name] = np.zeros(len(body), dtype=bool)
            mask[k] = True
    return Commands(
        t_s=num[:, 0],
        v_mps=num[:, 1],
        vy_mps=num[:, 2],
        w_radps=num[:, 3],
        modes=np.array([r[4] for r in body], dtype=np.str_),
        situations=np.array([r[5] for r in body], dtype=np.str_),
        flags=flags,
        desired=np.array([r[7] if width > 7 else "gnd" for r in body], dtype=np.str_),
        active=np.array([r[8] if width > 7 else "gnd" for r in body], dtype=np.str_),
        takeover=np.array([r[9] if width > 7 else "" for r in body], dtype=np.str_),
        subgoal=subgoal,
    )


def read_timing(path: Path) -> Timing:
    """Parse timing.csv (``t,match_ms,model_ms,planner_ms,reactor_ms,total_ms[,flags]``).

    Raises:
        RunDirError: missing file, missing column or a malformed row (named by line).
    """
    rows = _rows(path)
    header = rows[0] if rows else []
    if not header or header[0] != "t":
        raise RunDirError(f"{path}: expected a header starting with t")
    numeric = [k for k, name in enumerate(header) if k == 0 or name.endswith("_ms")]
    flag_col = header.index("flags") if "flags" in header else None
    body = rows[1:]
    data = np.empty((len(body), len(numeric)), dtype=np.float64)
    over: dict[str, NDArray[np.bool_]] = {}
    for k, r in enumerate(body):
        try:
            if len(r) != len(header):
                raise ValueError(f"{len(r)} fields, expected {len(header)}")
            data[k] = [float(r[c]) for c in numeric]
        except ValueError as err:
            raise RunDirError(f"{path} line {k + 2}: malformed row ({err})") from err
        for name in filter(None, r[flag_col].split("|")) if flag_col is not None else ():
            mask = over.get(name)
            if mask is None:
                mask = over[name] = np.zeros(len(body), dtype=bool)
            mask[k] = True
    ms = {header[c].removesuffix("_ms"): data[:, j] for j, c in enumerate(numeric) if c}
    missing = [m for m in TIMING_MODULES if m not in ms]
    if missing:
        raise RunDirError(f"{path}: missing column(s) {', '.join(m + '_ms' for m in missing)}")
    return Timing(t_s=data[:, 0], ms=ms, over_budget=over)


def read_tum(path: Path) -> F64:
    """A planar TUM trajectory as (M, 4) t [s], x, y [m], yaw [rad] (see ``evaluation.read_tum``).

    Raises:
        RunDirError: missing file or not 8 numbers per line.
    """
    try:
        t_ns, poses = read_tum_ns(_need(path))
    except RunDirError:
        raise
    except GndReplayError as err:
        raise RunDirError(str(err)) from err
    return np.column_stack([t_ns / 1e9, poses]) if t_ns.size else np.zeros((0, 4))


def _is_num(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _is_count(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= 0


def _table_of(ok: Any) -> Any:
    return lambda x: isinstance(x, dict) and all(isinstance(k, str) and ok(v) for k, v in x.items())


def _opt(ok: Any) -> Any:
    return lambda x: x is None or ok(x)


_COUNTS = _table_of(_is_count)


def _episodes_ok(x: Any, label: str) -> bool:
    """A list of episodes: tables with numeric t_start_s and duration_s and a text ``label``."""
    return isinstance(x, list) and all(
        isinstance(e, dict) and _is_num(e.get("t_start_s")) and _is_num(e.get("duration_s"))
        and isinstance(e.get(label), str) for e in x)


def _interventions_ok(x: Any) -> bool:
    return (isinstance(x, dict) and all(_COUNTS(x.get(k, {})) for k in ("desired", "active"))
            and _episodes_ok(x.get("takeovers", []), "reason")
            and _episodes_ok(x.get("emergencies", []), "rule"))

#: summary.json key -> (what it must be, a test); keys the report reads, each optional.
_SUMMARY_FIELDS: Mapping[str, tuple[str, Any]] = {
    "ticks": ("a count (integer >= 0)", _is_count),
    "duration_s": ("a number", _opt(_is_num)),
    "flags": ("a table of counts", _COUNTS),
    "over_budget": ("a table of counts", _COUNTS),
    "modes": ("a table of counts", _COUNTS),
    "situations": ("a table of counts", _COUNTS),
    "latency_ms": ("a table of {median, p90, p99, max} numbers",
                   _table_of(_opt(_table_of(_opt(_is_num))))),
    "agreement": ("a table of numbers", _opt(_table_of(_opt(_is_num)))),
    "interventions": ("a table of mode counts and takeovers / emergencies lists", _interventions_ok),
    "config": ("a table", lambda x: isinstance(x, dict)
               and all(isinstance(x.get(k), dict | None) for k in ("supervisor", "scanmatch"))),
    "options": ("a table", lambda x: isinstance(x, dict)
                and all(_opt(_is_num)(x.get(k)) for k in ("goal_ahead_m", "until_s", "every"))
                and (x.get("goal") is None or (isinstance(x["goal"], list) and len(x["goal"]) == 2
                                               and all(map(_is_num, x["goal"]))))),
}


def check_summary(path: Path, summary: Any) -> dict[str, Any]:
    """``summary`` (summary.json's content) if it has the shape the report reads.

    Raises:
        RunDirError: not an object, or a key the report uses has the wrong type (named).
    """
    if not isinstance(summary, dict):
        raise RunDirError(f"{path}: expected a JSON object, got {type(summary).__name__}")
    for key, (what, ok) in _SUMMARY_FIELDS.items():
        if key in summary and not ok(summary[key]):
            raise RunDirError(f"{path}: key {key!r} must be {what}, got {json.dumps(summary[key])[:60]}")
    return summary


def load_run(run_dir: Path) -> RunData:
    """Read a run directory.

    Raises:
        RunDirError: a required file is missing or malformed (maps.npz is optional).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: not a directory")
    summary_path = _need(run_dir / "summary.json")
    try:
        summary = check_summary(summary_path, load_json(summary_path, "summary", MAX_SUMMARY_BYTES))
    except ConfigError as err:
        raise RunDirError(str(err)) from None
    maps = None
    if (run_dir / MAPS_FILE).is_file():
        try:
            maps = load_maps(run_dir / MAPS_FILE)
        except ValueError as err:
            raise RunDirError(f"{run_dir / MAPS_FILE}: {err}") from err
    return RunData(
        run_dir=run_dir,
        commands=read_commands(run_dir / "commands.csv"),
        timing=read_timing(run_dir / "timing.csv"),
        traj_odom=read_tum(run_dir / "trajectory_odom.tum"),
        traj_corrected=read_tum(run_dir / "trajectory_corrected.tum"),
        summary=summary,
        maps=maps,
    )
