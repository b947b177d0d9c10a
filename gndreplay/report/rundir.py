"""The run directory: its files, their formats, the writers a replay streams into them and the readers
that read them back, each file's writer beside its reader.

- commands.csv (``COMMAND_COLUMNS``): each tick's command, what produced it, the assisted-navigation
  audit and the command the log recorded at the tick; timing.csv: milliseconds per module, the planner's
  work and the wall-clock ``*_OVER_BUDGET`` flags; stages.csv (``STAGE_COLUMNS``): what each stage handed
  on, exactly (the grid's digest, the planner's result, ND+'s region and direction, the proposal to the
  supervisor), so that ``gndreplay compare`` can name the first stage two runs differ in. Written a row per
  tick by :func:`tick_tables`, read by :func:`read_commands`, :func:`read_timing` and :func:`read_stages`.
- trajectory_odom.tum, trajectory_corrected.tum: the raw-odometry and the corrected pose of every scan (TUM,
  as evo reads it); trajectory_truth.tum, only when the log carries ground truth (CARMEN TRUEPOS, a truth
  topic, the simulator's world pose): the true pose of every scan that has one. Written by
  :class:`TrajectoryWriter`, read by :func:`read_tum`.
- summary.json (built by :func:`gndreplay.report.summary.summarise`): written by :func:`write_summary`, read
  by :func:`read_summary`.
- config.toml, the resolved configuration: written by :func:`write_config`, read by
  ``gndreplay.config.load_config``.
- the files of the replay's sinks (``RunSink``): maps.npz, results.mcap, the figures and report.md
  (``gndreplay.report.sinks.default_sinks``).

The records are a pure function of log + config: commands.csv, the trajectories and maps never carry
wall-clock facts (the ``*_OVER_BUDGET`` flags live in timing.csv unless ``enforce_budgets`` let them change a
command: :func:`recorded_flags`), and every file prints a tick's time with ``fsutil.format_stamp``.

Only the files are read back: ``gndreplay report RUN_DIR`` redraws everything without the log
(:func:`window_run` restricts what was read to a stretch of the run, :class:`TimeWindow`). The folder may
have been damaged since the run wrote it: each file is read through :mod:`gndreplay.io.userfile` (a regular
file of bounded size, UTF-8, JSON nesting bounded) and maps.npz's members are checked before they are
loaded (:func:`~gndreplay.report.maps.load_maps`); anything malformed is a one-line RunDirError naming the
file and the line, key or member.
"""

from __future__ import annotations

import csv
import io
import json
import math
from array import array
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Config, config_to_toml
from ..errors import ConfigError, GndReplayError
from ..evaluation import MAX_TUM_BYTES, write_tum
from ..evaluation import read_tum as read_tum_ns
from ..fsutil import format_stamp
from ..io.userfile import load_json, read_text
from ..pipeline.model import RobotCentredGrid
from ..pipeline.stack import MODULES, TickResult
from ..types import BUDGET_FLAGS, Command, Flag, Pose2D, Tick
from .maps import MAPS_FILE, MapsData, load_maps

__all__ = [
    "COMMANDS_FILE",
    "COMMAND_COLUMNS",
    "COMMAND_HEADER",
    "CONFIG_FILE",
    "CORRECTED_TRAJECTORY_FILE",
    "ODOM_TRAJECTORY_FILE",
    "STAGES_FILE",
    "STAGE_COLUMNS",
    "SUMMARY_FILE",
    "TIMING_FILE",
    "TIMING_HEADER",
    "TRUTH_TRAJECTORY_FILE",
    "Commands",
    "RunData",
    "RunDirError",
    "RunSink",
    "StagedSink",
    "Stages",
    "TimeWindow",
    "Timing",
    "TrajectoryWriter",
    "check_summary",
    "check_window",
    "command_row",
    "csv_text",
    "episodes",
    "load_run",
    "read_commands",
    "read_stages",
    "read_summary",
    "read_timing",
    "read_tum",
    "recorded_flags",
    "runs",
    "stage_row",
    "tick_edges",
    "tick_tables",
    "time_origin",
    "timing_row",
    "window_run",
    "write_config",
    "write_summary",
]

F64 = NDArray[np.float64]

COMMANDS_FILE = "commands.csv"
TIMING_FILE = "timing.csv"
STAGES_FILE = "stages.csv"
ODOM_TRAJECTORY_FILE = "trajectory_odom.tum"
CORRECTED_TRAJECTORY_FILE = "trajectory_corrected.tum"
TRUTH_TRAJECTORY_FILE = "trajectory_truth.tum"
SUMMARY_FILE = "summary.json"
CONFIG_FILE = "config.toml"

#: commands.csv's columns: the command, what produced it (GND mode or reflexive rule, ND+ situation, flags),
#: then the audit: desired and active navigation mode, the takeover reason (why the active mode is not the
#: desired one, or why the desired module stood still: "teleop: no command", "teleop: command stale"; ""
#: when the desired module's own command won), the subgoal; last, the log's recorded command at the tick
#: (``Tick.cmd``: forward and turn rate, empty when the log records none).
COMMAND_COLUMNS = (
    "t", "v", "vy", "w", "mode", "situation", "flags", "desired", "active", "takeover", "subgoal",
    "log_v", "log_w",
)  # fmt: skip
COMMAND_HEADER = ",".join(COMMAND_COLUMNS) + "\n"
TIMING_HEADER = "t," + ",".join(f"{m}_ms" for m in MODULES) + ",total_ms,planner_nodes,path_m,flags\n"
#: stages.csv's columns: the tick's stamp; the grid after the scan (``GridDigest``: the digest of the cell
#: codes in 16 hex digits, cells the scan changed, the world offset's row and col); the planner (1 / 0: a
#: path or none; empty outside GND), its search effort, the path's length [m] and instantaneous direction
#: [rad, world]; ND+'s chosen region (first, last sector; empty without one) and motion direction [rad,
#: robot frame]; the proposal to the supervisor (mode, v, vy, w). Floats in Python's shortest exact form
#: (``repr``), empty when NaN.
STAGE_COLUMNS = (
    "t", "grid_digest", "grid_changed", "grid_row", "grid_col", "planner_ok", "planner_nodes", "path_m",
    "path_dir_rad", "nd_first", "nd_last", "nd_direction_rad", "proposed_mode", "proposed_v", "proposed_vy",
    "proposed_w",
)  # fmt: skip
STAGES_HEADER = ",".join(STAGE_COLUMNS) + "\n"
TIMING_MODULES = MODULES
"""The modules timing.csv has a ``<module>_ms`` column for."""
MAX_TABLE_BYTES = MAX_TUM_BYTES
"""Largest commands.csv / timing.csv read back (256 MB: millions of ticks, days of a long run)."""
MAX_SUMMARY_BYTES = 16 << 20
"""Largest summary.json read back (16 MB; a run writes a few KB)."""


# ---- what streams into a run directory ----------------------------------------------------------------


class RunSink(Protocol):
    """Something that consumes the replay as it streams and writes its own files into the run directory
    (figures' map rasters, the results MCAP, the report). ``finish`` receives the staging directory (the
    run directory before it is published); it is called once, only when the replay completed, in the
    order the sinks were given, after commands.csv, timing.csv, the trajectories, summary.json and
    config.toml were written there."""

    def add_scan(self, tick: Tick, pose_corrected: Pose2D) -> None:
        """Every scan of the log (also those skipped by ``every``), at its corrected pose."""

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Every tick the stack ran on, with its result and the robot-centred grid after integration."""

    def finish(self, run_dir: Path) -> None:
        """Write this sink's files into ``run_dir``."""

    def abort(self) -> None:
        """The replay failed: release whatever the sink holds (temporary files, writers)."""


@runtime_checkable
class StagedSink(Protocol):
    """Optional extra of a ``RunSink``: ``start`` receives the staging directory before the first tick, so
    the sink can keep its temporary files there (removed with it on any failure, never in $TMPDIR)."""

    def start(self, staging: Path, target: Path) -> None:
        """The replay is about to start; ``staging`` becomes the run directory ``target`` when complete."""


# ---- writing ------------------------------------------------------------------------------------------


def recorded_flags(flags: Flag, *, enforce_budgets: bool) -> Flag:
    """The flags commands.csv records: all of them when budgets are enforced (they then change commands),
    otherwise all but the wall-clock ``BUDGET_FLAGS`` (which timing.csv records)."""
    return flags if enforce_budgets else flags & ~BUDGET_FLAGS


def csv_text(text: str) -> str:
    """Free text as one CSV field without quoting: commas become semicolons, line breaks spaces."""
    return " ".join(text.replace(",", ";").split())


def command_row(r: TickResult, enforce_budgets: bool, logged: Command | None = None) -> str:
    """A tick's commands.csv row (``COMMAND_COLUMNS``); ``logged`` is the log's recorded command at the tick
    (``Tick.cmd``; None: the log records none, the last two fields are empty)."""
    flags = "|".join(recorded_flags(r.flags, enforce_budgets=enforce_budgets).names())
    log_vw = "," if logged is None else f"{logged.v_mps:.6f},{logged.w_radps:.6f}"
    return (
        f"{format_stamp(r.t_ns)},{r.command.v_mps:.6f},{r.command.vy_mps:.6f},{r.command.w_radps:.6f},"
        f"{r.mode.value},{r.situation.name},{flags},"
        f"{csv_text(r.desired_mode)},{csv_text(r.active_mode)},{csv_text(r.takeover_reason)},"
        f"{r.subgoal_index},{log_vw}\n"
    )


def timing_row(r: TickResult) -> str:
    """A tick's timing.csv row (``TIMING_HEADER``)."""
    ms = [r.timings_ms.get(m, 0.0) for m in MODULES]
    over = "|".join((r.flags & BUDGET_FLAGS).names())
    stats = f"{r.planner_nodes},{r.planner_length_m:.3f}"
    return f"{format_stamp(r.t_ns)}," + ",".join(f"{x:.4f}" for x in ms) + f",{sum(ms):.4f},{stats},{over}\n"


def _exact(x: float) -> str:
    """A float as stages.csv prints it: the shortest text that reads back to the same float; NaN empty."""
    return "" if math.isnan(x) else repr(float(x))


def stage_row(r: TickResult) -> str:
    """A tick's stages.csv row (``STAGE_COLUMNS``)."""
    g = r.grid
    planner = ("0" if math.isnan(r.planner_length_m) else "1") if r.desired_mode == "gnd" else ""
    region = ("", "") if r.nd_region is None else r.nd_region
    p = r.proposal
    proposed = ",,," if p is None else (f"{p.mode.value},{_exact(p.command.v_mps)},"
                                        f"{_exact(p.command.vy_mps)},{_exact(p.command.w_radps)}")
    return (f"{format_stamp(r.t_ns)},{g.digest:016x},{g.changed_cells},"
            f"{g.offset_cells[0]},{g.offset_cells[1]},"
            f"{planner},{r.planner_nodes},{_exact(r.planner_length_m)},{_exact(r.planner_direction_rad)},"
            f"{region[0]},{region[1]},{_exact(r.direction_rad)},{proposed}\n")


@contextmanager
def tick_tables(run_dir: Path, *, enforce_budgets: bool
                ) -> Iterator[Callable[[TickResult, Command | None], None]]:
    """Open commands.csv, timing.csv and stages.csv in ``run_dir``, write their headers and give the function
    that appends a tick's row to each, from the stack's result and the log's recorded command at the tick
    (``Tick.cmd``): the tables stream, one row per tick, and close with the ``with``."""
    with (
        open(run_dir / COMMANDS_FILE, "w", newline="") as f_cmd,
        open(run_dir / TIMING_FILE, "w", newline="") as f_tim,
        open(run_dir / STAGES_FILE, "w", newline="") as f_stg,
    ):
        f_cmd.write(COMMAND_HEADER)
        f_tim.write(TIMING_HEADER)
        f_stg.write(STAGES_HEADER)

        def write_tick(r: TickResult, logged: Command | None) -> None:
            f_cmd.write(command_row(r, enforce_budgets, logged))
            f_tim.write(timing_row(r))
            f_stg.write(stage_row(r))

        yield write_tick


class TrajectoryWriter:
    """Raw-odometry, corrected and (where the log has it) true poses of every scan, written as TUM at the
    end; held packed (``array.array``: 64 bytes per scan, 96 with a true pose)."""

    def __init__(self) -> None:
        self.t_ns = array("q")
        self.odom = array("d")  # x, y, theta per scan
        self.corrected = array("d")
        self.truth_t_ns = array("q")
        self.truth = array("d")

    def add(self, t_ns: int, odom: Pose2D, corrected: Pose2D, truth: Pose2D | None = None) -> None:
        """A scan's stamp, raw-odometry pose, corrected pose and ground-truth pose (None: none at it)."""
        self.t_ns.append(t_ns)
        self.odom.extend((odom.x, odom.y, odom.theta))
        self.corrected.extend((corrected.x, corrected.y, corrected.theta))
        if truth is not None:
            self.truth_t_ns.append(t_ns)
            self.truth.extend((truth.x, truth.y, truth.theta))

    def arrays(self) -> dict[str, tuple[NDArray[np.int64], F64]]:
        """file name -> (stamps [ns], (N, 3) poses) of each trajectory; the truth only when a scan had one."""
        n = len(self.t_ns)
        t = np.array(self.t_ns, dtype=np.int64)
        out = {ODOM_TRAJECTORY_FILE: (t, np.array(self.odom, dtype=np.float64).reshape(n, 3)),
               CORRECTED_TRAJECTORY_FILE: (t, np.array(self.corrected, dtype=np.float64).reshape(n, 3))}
        if self.truth_t_ns:
            out[TRUTH_TRAJECTORY_FILE] = (np.array(self.truth_t_ns, dtype=np.int64),
                                          np.array(self.truth, dtype=np.float64).reshape(-1, 3))
        return out

    def write(self, run_dir: Path) -> dict[str, tuple[NDArray[np.int64], F64]]:
        """trajectory_odom.tum, trajectory_corrected.tum and (with ground truth) trajectory_truth.tum into
        ``run_dir``; returns what was written (:meth:`arrays`)."""
        arrays = self.arrays()
        for name, (t, poses) in arrays.items():
            write_tum(run_dir / name, t, poses)
        return arrays


def write_summary(run_dir: Path, summary: Mapping[str, Any]) -> None:
    """summary.json into ``run_dir`` (indented; NaN kept as JSON's NaN); :func:`read_summary` reads it."""
    (run_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, allow_nan=True) + "\n")


def write_config(run_dir: Path, cfg: Config) -> None:
    """config.toml, the resolved configuration, into ``run_dir``; ``config.load_config`` reads it back."""
    (run_dir / CONFIG_FILE).write_text(config_to_toml(cfg))


# ---- episodes: runs of equal consecutive ticks ----------------------------------------------------------


def runs(labels: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Start and end (exclusive) indices of the runs of equal consecutive labels."""
    a = np.asarray(labels)
    if a.size == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    cut = np.flatnonzero(a[1:] != a[:-1]) + 1
    return np.concatenate([[0], cut]).astype(np.intp), np.concatenate([cut, [a.size]]).astype(np.intp)


def episodes(keys: Sequence[str]) -> list[tuple[int, int]]:
    """(first, end) index pairs (end exclusive) of the maximal runs of equal non-empty consecutive keys."""
    start, end = runs(np.asarray(keys, dtype=np.str_))
    return [(int(i), int(j)) for i, j in zip(start, end, strict=True) if keys[i]]


def tick_edges(t: ArrayLike) -> NDArray[np.float64]:
    """(K + 1,) edges of the ticks' time spans: each tick lasts until the next one, the last for the median
    tick period (1 s for a single tick). The one definition of a tick's span: summary.json's episodes,
    report.md and the figures' bands all use it."""
    tt = np.asarray(t, dtype=np.float64)
    if tt.size == 0:
        return np.zeros(1)
    dt = float(np.median(np.diff(tt))) if tt.size > 1 else 1.0
    return np.concatenate([tt, [tt[-1] + dt]])


# ---- reading -------------------------------------------------------------------------------------------


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
        log_v_mps, log_w_radps: (K,) the log's recorded command at each tick, NaN where it records none
            (everywhere in a run written without these columns).
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
    log_v_mps: F64 = field(default_factory=lambda: np.zeros(0))
    log_w_radps: F64 = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True, eq=False)
class Timing:
    """timing.csv as arrays: t_s (K,), ms per module name (K,) (match, model, planner, reactor, total),
    over_budget: flag name -> (K,) bool mask for the ``*_OVER_BUDGET`` flags that fired, and planner: the
    planner's work per tick, ``nodes`` and ``path_m`` (K,) (NaN without a plan), when the file has them."""

    t_s: F64
    ms: Mapping[str, F64]
    over_budget: Mapping[str, NDArray[np.bool_]] = field(default_factory=dict)
    planner: Mapping[str, F64] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, eq=False)
class Stages:
    """stages.csv as arrays (``STAGE_COLUMNS``), each (K,).

    Attributes:
        t_s: tick times [s].
        grid_digest: the grid's digest (16 hex digits); grid_changed: cells the scan changed;
            grid_offset: (K, 2) the grid's world offset (row, col).
        planner_ok: "1", "0" or "" (outside GND); planner_nodes; path_m, path_dir_rad: NaN without a path.
        nd_region: (K, 2) ND+'s first and last sector, -1 without a region; nd_direction_rad: NaN without one.
        proposed_mode: the proposal's mode; proposed: (K, 3) its v, vy, w (NaN when not recorded).
    """

    t_s: F64
    grid_digest: NDArray[np.str_]
    grid_changed: NDArray[np.int64]
    grid_offset: NDArray[np.int64]
    planner_ok: NDArray[np.str_]
    planner_nodes: NDArray[np.int64]
    path_m: F64
    path_dir_rad: F64
    nd_region: NDArray[np.int64]
    nd_direction_rad: F64
    proposed_mode: NDArray[np.str_]
    proposed: F64

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True, eq=False)
class RunData:
    """Everything the report needs from a run directory.

    Attributes:
        run_dir: the directory.
        commands, timing: the per-tick tables.
        traj_odom, traj_corrected: (M, 4) t [s], x, y [m], yaw [rad] from the TUM files (every scan).
        traj_truth: the same from trajectory_truth.tum, or None when the run has no ground truth.
        summary: summary.json.
        maps: maps.npz, or None when the run was written without it.
        window: the stretch of the run the tables and trajectories hold (:func:`window_run`); None: all of
            it.
    """

    run_dir: Path
    commands: Commands
    timing: Timing
    traj_odom: F64
    traj_corrected: F64
    summary: dict[str, Any]
    maps: MapsData | None
    window: TimeWindow | None = None
    traj_truth: F64 | None = None

    @property
    def has_truth(self) -> bool:
        """Whether the run has ground-truth poses (trajectory_truth.tum with at least one)."""
        return self.traj_truth is not None and self.traj_truth.shape[0] > 0


@dataclass(frozen=True, slots=True)
class TimeWindow:
    """A stretch of a run: from ``start_s`` to ``end_s`` seconds since ``origin_s``, the stamp [s] of the
    run's first tick (figures of a window keep the run's time axis)."""

    origin_s: float
    start_s: float
    end_s: float

    @property
    def tag(self) -> str:
        """The window in a file name: ``<start>-<end>`` in seconds, at most three decimals."""
        return f"{_seconds(self.start_s)}-{_seconds(self.end_s)}"


def _seconds(x: float) -> str:
    return f"{x + 0.0:.3f}".rstrip("0").rstrip(".")  # + 0.0: no "-0"


def _take(a: F64, keep: NDArray[np.bool_]) -> F64:
    """``a[keep]``; NaN for a column the tables do not have (``a`` empty)."""
    return a[keep] if a.shape == keep.shape else np.full(int(np.count_nonzero(keep)), np.nan)


def time_origin(data: RunData) -> float:
    """The stamp [s] the figures count time from: the run's first tick (its first scan, stack tick or
    timing row), also for a window of it."""
    if data.window is not None:
        return data.window.origin_s
    starts = [a[0] for a in (data.traj_corrected[:, 0], data.commands.t_s, data.timing.t_s) if a.size]
    return float(min(starts)) if starts else 0.0


def check_window(t_from: float | None, t_to: float | None, *, name: str = "run",
                 duration_s: float | None = None) -> None:
    """Check a window of the run ``name`` given as seconds since its first tick (None: from its start, to
    its end); ``duration_s``, the run's last tick, when known (before a run it is not).

    Raises:
        ConfigError: one line naming ``name`` (and its span when known): not finite, starting before 0,
            not starting before its end, or starting after the run's last tick.
    """
    span = "" if duration_s is None else f"; {name} spans 0-{_seconds(duration_s)} s since its first tick"
    ends = ("start" if t_from is None else _seconds(t_from), "end" if t_to is None else _seconds(t_to))
    asked = f"window {ends[0]}-{ends[1]} s"
    start = 0.0 if t_from is None else t_from
    if not all(np.isfinite(x) for x in (start, 0.0 if t_to is None else t_to)):
        raise ConfigError(f"{name}: {asked}: from and to must be finite numbers of seconds{span}")
    if start < 0.0:
        raise ConfigError(f"{name}: {asked} starts before the run (from must be >= 0){span}")
    if t_to is not None and start >= t_to:
        raise ConfigError(f"{name}: {asked} is empty (from must be before to){span}")
    if duration_s is not None and start > duration_s:
        raise ConfigError(f"{name}: {asked} is outside the run{span}")


def window_run(data: RunData, t_from: float | None, t_to: float | None) -> RunData:
    """``data`` restricted to the ticks, timing rows and poses from ``t_from`` to ``t_to`` seconds since
    the run's first tick (None: from its start, to its end; an end past the last tick is clipped to it).

    Raises:
        ConfigError: the window is empty or outside the run (``check_window``), or the run has no tick.
    """
    if len(data.commands) == 0:
        raise ConfigError(f"{data.run_dir}: the run has no tick to draw a window of")
    origin = time_origin(data)
    duration = float(data.commands.t_s[-1]) - origin
    check_window(t_from, t_to, name=str(data.run_dir), duration_s=duration)
    start = 0.0 if t_from is None else float(t_from)
    end = duration if t_to is None else min(float(t_to), duration)
    lo, hi = origin + start, origin + end

    def inside(t: F64) -> NDArray[np.bool_]:
        return (t >= lo) & (t <= hi)

    c, tm = data.commands, data.timing
    k = inside(c.t_s)
    commands = Commands(
        t_s=c.t_s[k], v_mps=c.v_mps[k], vy_mps=c.vy_mps[k], w_radps=c.w_radps[k], modes=c.modes[k],
        situations=c.situations[k], flags={n: m[k] for n, m in c.flags.items() if np.any(m[k])},
        desired=c.desired[k], active=c.active[k], takeover=c.takeover[k], subgoal=c.subgoal[k],
        log_v_mps=_take(c.log_v_mps, k), log_w_radps=_take(c.log_w_radps, k),
    )
    j = inside(tm.t_s)
    timing = Timing(t_s=tm.t_s[j], ms={n: v[j] for n, v in tm.ms.items()},
                    over_budget={n: m[j] for n, m in tm.over_budget.items() if np.any(m[j])},
                    planner={n: v[j] for n, v in tm.planner.items()})
    return RunData(
        run_dir=data.run_dir, commands=commands, timing=timing,
        traj_odom=data.traj_odom[inside(data.traj_odom[:, 0])],
        traj_corrected=data.traj_corrected[inside(data.traj_corrected[:, 0])],
        summary=data.summary, maps=data.maps, window=TimeWindow(origin, start, end),
        traj_truth=None if data.traj_truth is None else data.traj_truth[inside(data.traj_truth[:, 0])],
    )


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


#: The headers commands.csv is read with: all columns; without the log's recorded command (log_v, log_w
#: read as NaN); without the audit too (desired = active = "gnd").
_COMMAND_HEADERS = (list(COMMAND_COLUMNS), list(COMMAND_COLUMNS[:11]), list(COMMAND_COLUMNS[:7]))


def _number_or_nan(x: str) -> float:
    return float(x) if x else np.nan


def read_commands(path: Path) -> Commands:
    """Parse commands.csv (header ``COMMAND_COLUMNS``, or one without the recorded command ``log_v,log_w``
    or also without the audit columns ``desired,active,takeover,subgoal``).

    Raises:
        RunDirError: missing file, wrong header or a malformed row (named by line).
    """
    rows = _rows(path)
    if not rows or rows[0] not in _COMMAND_HEADERS:
        raise RunDirError(f"{path}: expected header {','.join(COMMAND_COLUMNS)}")
    width = len(rows[0])
    body = rows[1:]
    num = np.empty((len(body), 4), dtype=np.float64)
    logged = np.full((len(body), 2), np.nan)
    subgoal = np.full(len(body), -1, dtype=np.int64)
    flags: dict[str, NDArray[np.bool_]] = {}
    for k, r in enumerate(body):
        try:
            if len(r) != width:
                raise ValueError(f"{len(r)} fields")
            num[k] = [float(x) for x in r[:4]]
            if width > 7:
                subgoal[k] = int(r[10])
            if width > 11:
                logged[k] = [_number_or_nan(x) for x in r[11:13]]
        except ValueError as err:
            raise RunDirError(
                f"{path} line {k + 2}: expected {width} fields t,v,vy,w (numbers),mode,situation,flags"
                f"{',desired,active,takeover,subgoal (an integer)' if width > 7 else ''}"
                f"{',log_v,log_w (numbers or empty)' if width > 11 else ''} ({err})"
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
        log_v_mps=logged[:, 0],
        log_w_radps=logged[:, 1],
    )


#: timing.csv's columns of the planner's work -> the names in ``Timing.planner``.
_PLANNER_COLUMNS = {"planner_nodes": "nodes", "path_m": "path_m"}


def read_timing(path: Path) -> Timing:
    """Parse timing.csv (``t,match_ms,model_ms,planner_ms,reactor_ms[,supervisor_ms],total_ms[,flags]``;
    the supervisor's column is optional: the figures and tables show the modules present).

    Raises:
        RunDirError: missing file, missing column or a malformed row (named by line).
    """
    rows = _rows(path)
    header = rows[0] if rows else []
    if not header or header[0] != "t":
        raise RunDirError(f"{path}: expected a header starting with t")
    numeric = [k for k, name in enumerate(header) if k == 0 or name.endswith("_ms")]
    work = [k for k, name in enumerate(header) if name in _PLANNER_COLUMNS]
    numeric += work
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
    ms = {header[c].removesuffix("_ms"): data[:, j] for j, c in enumerate(numeric) if c and c not in work}
    planner = {_PLANNER_COLUMNS[header[c]]: data[:, j] for j, c in enumerate(numeric) if c in work}
    missing = [m for m in TIMING_MODULES if m not in ms and m != "supervisor"]
    if missing:
        raise RunDirError(f"{path}: missing column(s) {', '.join(m + '_ms' for m in missing)}")
    return Timing(t_s=data[:, 0], ms=ms, over_budget=over, planner=planner)


def _int_or(x: str, missing: int) -> int:
    return int(x) if x else missing


def read_stages(path: Path) -> Stages:
    """Parse stages.csv (header ``STAGE_COLUMNS``).

    Raises:
        RunDirError: missing file, another header or a malformed row (named by line).
    """
    rows = _rows(path)
    if not rows or rows[0] != list(STAGE_COLUMNS):
        raise RunDirError(f"{path}: expected header {','.join(STAGE_COLUMNS)}")
    body = rows[1:]
    n = len(body)
    ints = np.empty((n, 6), dtype=np.int64)  # changed, row, col, nodes, nd_first, nd_last
    floats = np.empty((n, 7), dtype=np.float64)  # t, path_m, path_dir, nd_direction, v, vy, w
    for k, r in enumerate(body):
        try:
            if len(r) != len(STAGE_COLUMNS):
                raise ValueError(f"{len(r)} fields")
            int(r[1], 16)
            ints[k] = [int(r[2]), int(r[3]), int(r[4]), int(r[6]), _int_or(r[9], -1), _int_or(r[10], -1)]
            floats[k] = [float(r[0]), *(_number_or_nan(r[j]) for j in (7, 8, 11, 13, 14, 15))]
        except ValueError as err:
            raise RunDirError(f"{path} line {k + 2}: expected {len(STAGE_COLUMNS)} fields "
                              f"{','.join(STAGE_COLUMNS)} (numbers, a hex checksum, empty where none) "
                              f"({err})") from None
    return Stages(
        t_s=floats[:, 0], grid_digest=np.array([r[1] for r in body], dtype=np.str_), grid_changed=ints[:, 0],
        grid_offset=ints[:, 1:3], planner_ok=np.array([r[5] for r in body], dtype=np.str_),
        planner_nodes=ints[:, 3], path_m=floats[:, 1], path_dir_rad=floats[:, 2], nd_region=ints[:, 4:6],
        nd_direction_rad=floats[:, 3], proposed_mode=np.array([r[12] for r in body], dtype=np.str_),
        proposed=floats[:, 4:7],
    )


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

def _truth_ok(x: Any) -> bool:
    """summary.json's truth section: per trajectory, per alignment, a table of numbers (and its labels)."""
    return isinstance(x, dict) and all(
        _table_of(_table_of(lambda v: _is_num(v) or isinstance(v, str | list)))(x.get(k, {}))
        for k in ("odom", "corrected"))


def _health_ok(x: Any) -> bool:
    """summary.json's matcher_health: counts, failures per reason, tables of numbers, a text warning."""
    return (isinstance(x, dict) and all(_is_count(x.get(k, 0)) for k in ("scans", "failed", "refused",
                                                                           "after_gap"))
            and _COUNTS(x.get("reasons", {}))
            and all(_table_of(_opt(_is_num))(x.get(k, {}))
                    for k in ("step_vs_odometry", "longest_without_match", "worst_window"))
            and all(_opt(_is_num)(x.get(k)) for k in ("failed_share", "ate_odom_m", "ate_matcher_m"))
            and all(_opt(lambda v: isinstance(v, str))(x.get(k)) for k in ("matcher", "verdict", "warning")))


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
    "truth": ("a table of trajectory errors per trajectory and alignment", _opt(_truth_ok)),
    "matcher_health": ("a table of the scan matcher's health", _opt(_health_ok)),
    "config": ("a table", lambda x: isinstance(x, dict)
               and all(isinstance(x.get(k), dict | None) for k in ("supervisor", "scanmatch"))),
    "source": ("a table or null", lambda x: x is None or isinstance(x, dict)),
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


def read_summary(path: Path) -> dict[str, Any]:
    """Read summary.json (written by :func:`write_summary`), checked by :func:`check_summary`.

    Raises:
        RunDirError: missing, too large (``MAX_SUMMARY_BYTES``), not JSON, or a key of the wrong shape.
    """
    summary_path = _need(path)
    try:
        return check_summary(summary_path, load_json(summary_path, "summary", MAX_SUMMARY_BYTES))
    except ConfigError as err:
        raise RunDirError(str(err)) from None


def load_run(run_dir: Path) -> RunData:
    """Read a run directory.

    Raises:
        RunDirError: a required file is missing or malformed (maps.npz and trajectory_truth.tum are
            optional).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: not a directory")
    summary = read_summary(run_dir / SUMMARY_FILE)
    maps = None
    if (run_dir / MAPS_FILE).is_file():
        try:
            maps = load_maps(run_dir / MAPS_FILE)
        except ValueError as err:
            raise RunDirError(f"{run_dir / MAPS_FILE}: {err}") from err
    return RunData(
        run_dir=run_dir,
        commands=read_commands(run_dir / COMMANDS_FILE),
        timing=read_timing(run_dir / TIMING_FILE),
        traj_odom=read_tum(run_dir / ODOM_TRAJECTORY_FILE),
        traj_corrected=read_tum(run_dir / CORRECTED_TRAJECTORY_FILE),
        summary=summary,
        maps=maps,
        traj_truth=read_tum(truth) if (truth := run_dir / TRUTH_TRAJECTORY_FILE).is_file() else None,
    )
