"""Compare two run directories: where the behaviour first differs, which stage differed first, how often
each field differs, the latency per module and, for closed-loop runs, the outcome.

Ticks are joined on their stamps (commands.csv, timing.csv, stages.csv and the TUM files print them alike).
The behaviour is commands.csv: ``v``, ``vy``, ``w`` within an absolute tolerance (default 0: exact), the
other fields exactly. The stages are what the run directory records of each tick, in pipeline order
(``STAGES``): the corrected pose (trajectory_corrected.tum), the grid (stages.csv's digest), the planner
(its result), the reactor (commands.csv's ``situation``; ND+'s region and direction and the proposal to the
supervisor) and the supervisor (``mode``, ``flags`` and the command itself where the proposal was the same).
A run written without stages.csv is compared on what it has: the planner from timing.csv, the reactor from
the situation. Wall-clock files (timing.csv's milliseconds, sim_timing.json) only feed the latency table;
summary.json is not compared.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..errors import ConfigError, did_you_mean
from ..io.userfile import brief, check_number, load_json, load_toml
from ..types import REFLEXIVE_MODES
from .decision import DecisionInput
from .rundir import (
    COMMANDS_FILE,
    CORRECTED_TRAJECTORY_FILE,
    STAGES_FILE,
    TIMING_FILE,
    Commands,
    RunDirError,
    Stages,
    Timing,
    read_commands,
    read_stages,
    read_timing,
    read_tum,
)

__all__ = [
    "BEHAVIOUR_FIELDS",
    "COMPARE_FIGURE",
    "COMPARE_JSON",
    "COMPARE_SNAPSHOT",
    "STAGES",
    "CompareRun",
    "Comparison",
    "Divergence",
    "ModuleLatency",
    "OutcomeChange",
    "SnapshotPanel",
    "StageDivergence",
    "Tolerance",
    "compare_runs",
    "comparison_to_dict",
    "figure_compare_snapshot",
    "load_compare_run",
    "read_tolerance",
]

F64 = NDArray[np.float64]

RESULT_FILE = "result.json"
COMPARE_JSON = "compare.json"
COMPARE_FIGURE = "fig_compare.png"
COMPARE_SNAPSHOT = "fig_compare_snapshot.png"
MAX_TOLERANCE_BYTES = 64 * 1024
MAX_RESULT_BYTES = 16 * 1024 * 1024

#: commands.csv's behaviour fields, in the order they are reported.
BEHAVIOUR_FIELDS = ("v", "vy", "w", "mode", "situation", "flags", "desired", "active", "takeover", "subgoal")
#: The stages of a tick, in pipeline order.
STAGES = ("pose", "grid", "planner", "reactor", "supervisor")
#: result.json's scores compared between two closed-loop runs.
OUTCOME_KEYS = ("outcome", "collision", "end_time_s", "time_to_goal_s", "min_clearance_m", "longest_stall_s",
                "path_length_m", "time_inside_security_pct", "trap_count")


@dataclass(frozen=True, slots=True)
class Tolerance:
    """Absolute tolerances of the numeric comparisons (0: exact).

    Attributes:
        v_mps, vy_mps, w_radps: the command's forward, lateral speed and turn rate.
        pose_m, pose_rad: the corrected pose's position (distance) and heading.
        path_m: the planned path's length.
        direction_rad: the planned path's direction and ND+'s motion direction (stages.csv). The proposal
            to the supervisor (stages.csv's ``proposed_*``) is held to ``v_mps``, ``vy_mps``, ``w_radps``.
    """

    v_mps: float = 0.0
    vy_mps: float = 0.0
    w_radps: float = 0.0
    pose_m: float = 0.0
    pose_rad: float = 0.0
    path_m: float = 0.0
    direction_rad: float = 0.0


#: The upper bound of each tolerance key (a tolerance beyond it is a typo, not a tolerance).
_TOLERANCE_LIMITS = {"v_mps": 100.0, "vy_mps": 100.0, "w_radps": 100.0, "pose_m": 1e6, "pose_rad": math.pi,
                     "path_m": 1e6, "direction_rad": math.pi}


def read_tolerance(path: Path) -> Tolerance:
    """Read a tolerance file: TOML with one table ``[tolerance]`` of the keys of :class:`Tolerance`.

    Raises:
        ConfigError: unreadable, not TOML, another table, an unknown key (with the nearest known one) or a
            value that is not a number from 0 to the key's limit (one line naming the file).
    """
    doc = load_toml(Path(path), "tolerance file", MAX_TOLERANCE_BYTES)
    extra = [k for k in doc if k != "tolerance"]
    if extra:
        raise ConfigError(f"{path}: unknown table or key {extra[0]!r}; expected only [tolerance]"
                          f"{did_you_mean(extra[0], ['tolerance'])}")
    table = doc.get("tolerance", {})
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: tolerance must be a table [tolerance], got {brief(table)}")
    values: dict[str, float] = {}
    for key, value in table.items():
        if key not in _TOLERANCE_LIMITS:
            hint = did_you_mean(key, _TOLERANCE_LIMITS)
            raise ConfigError(f"{path}: [tolerance] unknown key {key!r}{hint}; "
                              f"known: {', '.join(_TOLERANCE_LIMITS)}")
        values[key] = check_number(value, f"{path}: [tolerance] {key}", 0.0, _TOLERANCE_LIMITS[key])
    return Tolerance(**values)


@dataclass(frozen=True, slots=True, eq=False)
class CompareRun:
    """What the comparison reads of a run directory.

    Attributes:
        run_dir: the directory.
        commands, timing: commands.csv and timing.csv.
        corrected: (M, 4) t [s], x, y [m], yaw [rad] of trajectory_corrected.tum.
        result: result.json of a closed-loop run, None for a replay.
        stages: stages.csv, None for a run directory without it.
    """

    run_dir: Path
    commands: Commands
    timing: Timing
    corrected: F64
    result: Mapping[str, Any] | None = None
    stages: Stages | None = None


def load_compare_run(run_dir: Path) -> CompareRun:
    """Read the files :func:`compare_runs` needs from ``run_dir``.

    Raises:
        RunDirError: not a directory, or a required file (commands.csv, timing.csv,
            trajectory_corrected.tum) missing or malformed, or result.json or stages.csv, when present,
            malformed or (stages.csv) not of the ticks of commands.csv (the message names the file).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: not a directory (expected a gndreplay run directory)")
    result = None
    if (path := run_dir / RESULT_FILE).exists():
        try:
            result = load_json(path, "result", MAX_RESULT_BYTES)
        except ConfigError as err:
            raise RunDirError(str(err)) from None
        if not isinstance(result, dict):
            raise RunDirError(f"{path}: expected a JSON object, got {brief(result)}")
    commands = read_commands(run_dir / COMMANDS_FILE)
    timing = read_timing(run_dir / TIMING_FILE)
    stages = read_stages(path) if (path := run_dir / STAGES_FILE).is_file() else None
    for name, t in ((TIMING_FILE, timing.t_s), (STAGES_FILE, None if stages is None else stages.t_s)):
        if t is not None and (len(t) != len(commands) or not np.array_equal(t, commands.t_s)):
            raise RunDirError(f"{run_dir / name}: its ticks are not those of {COMMANDS_FILE}")
    return CompareRun(run_dir=run_dir, commands=commands, timing=timing,
                      corrected=read_tum(run_dir / CORRECTED_TRAJECTORY_FILE), result=result, stages=stages)


@dataclass(frozen=True, slots=True)
class Divergence:
    """The first tick whose behaviour differs: its stamp, seconds since A's first tick, its index in each
    run, and per differing field both values (as commands.csv prints them)."""

    t_s: float
    elapsed_s: float
    index_a: int
    index_b: int
    fields: Mapping[str, tuple[Any, Any]]


@dataclass(frozen=True, slots=True)
class StageDivergence:
    """The first tick (at or before the behaviour's divergence) where a stage differs, both values, and
    what shows it (``evidence``: the file and columns)."""

    stage: str
    t_s: float
    elapsed_s: float
    a: Any
    b: Any
    evidence: str


@dataclass(frozen=True, slots=True)
class ModuleLatency:
    """One module's wall time [ms] in both runs: median and p99, and B over A (None when A's is 0)."""

    module: str
    median_a: float
    median_b: float
    median_ratio: float | None
    p99_a: float
    p99_b: float
    p99_ratio: float | None


@dataclass(frozen=True, slots=True)
class OutcomeChange:
    """result.json's scores of two closed-loop runs: key -> (A, B), and the keys that changed."""

    values: Mapping[str, tuple[Any, Any]]
    changed: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Comparison:
    """The comparison of run B against run A.

    Attributes:
        run_a, run_b: the directories.
        tolerance: the tolerances applied.
        same: the behaviour (and the outcome) is the same within tolerance, over the same ticks.
        ticks_a, ticks_b, common_ticks: ticks of each run and those both have.
        only_a, only_b: stamps [s] of ticks only one run has (the first of each; counts in ``only_*_count``).
        counts: ticks (of the common ones) that differ, per behaviour field.
        divergence: the first common tick that differs, or None.
        stage: the first stage that differs at or before ``divergence`` (the earliest tick; at one tick the
            first in pipeline order), or None.
        stages: every stage's first difference at or before ``divergence``, in that order.
        latency: per module present in both timing.csv.
        outcome: for two closed-loop runs (result.json in both), else None.
        notes: what could not be compared (e.g. result.json in one run only, stages.csv missing) or drawn.
        snapshot: the file of both runs' decisions at the divergent tick, when one was drawn.
    """

    run_a: str
    run_b: str
    tolerance: Tolerance
    same: bool
    ticks_a: int
    ticks_b: int
    common_ticks: int
    only_a_count: int
    only_b_count: int
    only_a: tuple[float, ...]
    only_b: tuple[float, ...]
    counts: Mapping[str, int]
    divergence: Divergence | None
    stage: StageDivergence | None
    stages: tuple[StageDivergence, ...]
    latency: tuple[ModuleLatency, ...]
    outcome: OutcomeChange | None
    notes: tuple[str, ...] = field(default=())
    snapshot: str | None = None


def _flag_strings(c: Commands) -> NDArray[np.str_]:
    """Each tick's flags as one string, sorted by name (the mask order does not depend on the file's)."""
    names = sorted(c.flags)
    return np.array(["|".join(n for n in names if c.flags[n][k]) for k in range(len(c))], dtype=np.str_)


def _field_arrays(c: Commands) -> dict[str, NDArray[Any]]:
    return {"v": c.v_mps, "vy": c.vy_mps, "w": c.w_radps, "mode": c.modes, "situation": c.situations,
            "flags": _flag_strings(c), "desired": c.desired, "active": c.active, "takeover": c.takeover,
            "subgoal": c.subgoal}


def _num_differs(a: F64, b: F64, tol: float) -> NDArray[np.bool_]:
    both_nan = np.isnan(a) & np.isnan(b)
    with np.errstate(invalid="ignore"):
        return ~both_nan & ~(np.abs(a - b) <= tol)


def _value(x: Any) -> Any:
    """A value for the report and JSON: floats as floats (NaN as None), numpy scalars as Python."""
    if isinstance(x, np.floating | float):
        return None if math.isnan(float(x)) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.str_):
        return str(x)
    return x


def _join(ta: F64, tb: F64) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices into A and B of the stamps both have, in time order."""
    _, ia, ib = np.intersect1d(ta, tb, assume_unique=False, return_indices=True)
    return ia, ib


def _angle_differs(a: F64, b: F64, tol: float) -> NDArray[np.bool_]:
    """Angles [rad] further apart than ``tol`` on the circle (NaN equals only NaN)."""
    both_nan = np.isnan(a) & np.isnan(b)
    with np.errstate(invalid="ignore"):
        return ~both_nan & ~(np.abs(np.angle(np.exp(1j * (a - b)))) <= tol)


def _pose_stage(a: F64, b: F64, t_end: float, tol: Tolerance, t0: float) -> StageDivergence | None:
    ia, ib = _join(a[:, 0], b[:, 0])
    keep = a[ia, 0] <= t_end
    ia, ib = ia[keep], ib[keep]
    dist = np.hypot(a[ia, 1] - b[ib, 1], a[ia, 2] - b[ib, 2])
    bad = ~(dist <= tol.pose_m) | _angle_differs(a[ia, 3], b[ib, 3], tol.pose_rad)
    if not np.any(bad):
        return None
    k = int(np.argmax(bad))
    pa, pb = a[ia[k]], b[ib[k]]
    return StageDivergence("pose", float(pa[0]), float(pa[0]) - t0,
                           tuple(float(x) for x in pa[1:]), tuple(float(x) for x in pb[1:]),
                           f"{CORRECTED_TRAJECTORY_FILE} x, y, yaw")


def _first(bad: NDArray[np.bool_]) -> int | None:
    return int(np.argmax(bad)) if np.any(bad) else None


@dataclass(frozen=True, slots=True, eq=False)
class _Check:
    """One recorded column of a stage over the joined ticks: where A and B differ and both values."""

    file: str
    column: str
    differs: NDArray[np.bool_]
    a: NDArray[Any]
    b: NDArray[Any]


def _exact(file: str, column: str, a: NDArray[Any], b: NDArray[Any]) -> _Check:
    return _Check(file, column, np.asarray(a != b), a, b)


def _within(file: str, column: str, a: F64, b: F64, tol: float, *, angle: bool = False) -> _Check:
    return _Check(file, column, _angle_differs(a, b, tol) if angle else _num_differs(a, b, tol), a, b)


def _stage(stage: str, checks: Sequence[_Check], t: F64, t0: float) -> StageDivergence | None:
    """The stage's first tick where any of its ``checks`` differs: every checked value of both runs there,
    the evidence naming the files and the columns that differ."""
    if not checks:
        return None
    bad = np.logical_or.reduce([c.differs for c in checks])
    if (k := _first(bad)) is None:
        return None
    files: dict[str, list[str]] = {}
    for c in checks:
        if c.differs[k]:
            files.setdefault(c.file, []).append(c.column)
    return StageDivergence(stage, float(t[k]), float(t[k]) - t0, {c.column: _value(c.a[k]) for c in checks},
                           {c.column: _value(c.b[k]) for c in checks},
                           "; ".join(f"{f} {', '.join(cols)}" for f, cols in files.items()))


def _tick_stages(a: CompareRun, b: CompareRun, ia: NDArray[np.intp], ib: NDArray[np.intp], tol: Tolerance,
                 t0: float) -> list[StageDivergence]:
    """The grid's, planner's, reactor's and supervisor's first difference over the joined ticks ``ia``,
    ``ib``: from stages.csv when both runs have it, else (no grid) from timing.csv and commands.csv."""
    ca, cb = a.commands, b.commands
    t = ca.t_s[ia]
    sa, sb = a.stages, b.stages
    grid: list[_Check] = []
    planner: list[_Check] = []
    reactor = [_exact(COMMANDS_FILE, "situation", ca.situations[ia], cb.situations[ib])]
    fa, fb = _flag_strings(ca), _flag_strings(cb)
    supervisor = [_exact(COMMANDS_FILE, "mode", ca.modes[ia], cb.modes[ib]),
                  _exact(COMMANDS_FILE, "flags", fa[ia], fb[ib])]
    if sa is not None and sb is not None:
        f = STAGES_FILE
        grid = [_exact(f, "grid_digest", sa.grid_digest[ia], sb.grid_digest[ib]),
                _exact(f, "grid_changed", sa.grid_changed[ia], sb.grid_changed[ib]),
                _exact(f, "grid_row", sa.grid_offset[ia, 0], sb.grid_offset[ib, 0]),
                _exact(f, "grid_col", sa.grid_offset[ia, 1], sb.grid_offset[ib, 1])]
        planner = [_exact(f, "planner_ok", sa.planner_ok[ia], sb.planner_ok[ib]),
                   _exact(f, "planner_nodes", sa.planner_nodes[ia], sb.planner_nodes[ib]),
                   _within(f, "path_m", sa.path_m[ia], sb.path_m[ib], tol.path_m),
                   _within(f, "path_dir_rad", sa.path_dir_rad[ia], sb.path_dir_rad[ib], tol.direction_rad,
                           angle=True)]
        reactor += [_exact(f, "nd_first", sa.nd_region[ia, 0], sb.nd_region[ib, 0]),
                    _exact(f, "nd_last", sa.nd_region[ia, 1], sb.nd_region[ib, 1]),
                    _within(f, "nd_direction_rad", sa.nd_direction_rad[ia], sb.nd_direction_rad[ib],
                            tol.direction_rad, angle=True),
                    _exact(f, "proposed_mode", sa.proposed_mode[ia], sb.proposed_mode[ib])]
        limits = (("v", tol.v_mps), ("vy", tol.vy_mps), ("w", tol.w_radps))
        reactor += [_within(f, f"proposed_{n}", sa.proposed[ia, j], sb.proposed[ib, j], limit)
                    for j, (n, limit) in enumerate(limits)]
        # the proposal the same, a command out that differs is the supervisor's
        supervisor += [_within(COMMANDS_FILE, n, x[ia], y[ib], limit) for n, x, y, limit in (
            ("v", ca.v_mps, cb.v_mps, tol.v_mps), ("vy", ca.vy_mps, cb.vy_mps, tol.vy_mps),
            ("w", ca.w_radps, cb.w_radps, tol.w_radps))]
    else:
        pa, pb = a.timing.planner, b.timing.planner
        if all(k in p for p in (pa, pb) for k in ("nodes", "path_m")):
            planner = [_exact(TIMING_FILE, "planner_nodes", pa["nodes"][ia], pb["nodes"][ib]),
                       _within(TIMING_FILE, "path_m", pa["path_m"][ia], pb["path_m"][ib], tol.path_m)]
    found = (_stage(name, checks, t, t0) for name, checks in (
        ("grid", grid), ("planner", planner), ("reactor", reactor), ("supervisor", supervisor)))
    return [s for s in found if s is not None]


def _command_stage(d: Divergence, mode_a: str, mode_b: str) -> StageDivergence:
    """The stage behind a command (or navigation-mode fields) that differs while every recorded stage
    before it agrees, in a run directory without stages.csv: the supervisor when a reflexive rule produced
    it in either run, else the reactor (ND+, or in the multi-loop modes the selector and local navigation:
    what timing.csv's reactor column times)."""
    stage = "supervisor" if mode_a in REFLEXIVE_MODES or mode_b in REFLEXIVE_MODES else "reactor"
    keys = list(d.fields)
    return StageDivergence(stage, d.t_s, d.elapsed_s, {n: d.fields[n][0] for n in keys} | {"mode": mode_a},
                           {n: d.fields[n][1] for n in keys} | {"mode": mode_b},
                           f"{COMMANDS_FILE} {', '.join(keys)}; mode, situation and flags the same")


def _ratio(b: float, a: float) -> float | None:
    return b / a if a > 0 and math.isfinite(a) and math.isfinite(b) else None


def _latency(a: Timing, b: Timing) -> tuple[ModuleLatency, ...]:
    rows = []
    for name in (m for m in a.ms if m in b.ms):
        xa, xb = a.ms[name], b.ms[name]
        if xa.size == 0 or xb.size == 0:
            continue
        ma, mb = float(np.median(xa)), float(np.median(xb))
        qa, qb = float(np.percentile(xa, 99)), float(np.percentile(xb, 99))
        rows.append(ModuleLatency(name, ma, mb, _ratio(mb, ma), qa, qb, _ratio(qb, qa)))
    return tuple(rows)


def _outcome_value(key: str, value: Any) -> Any:
    if key == "collision":  # an object describing the contact, or null
        return value is not None
    return value


def _outcome(a: Mapping[str, Any], b: Mapping[str, Any]) -> OutcomeChange:
    values = {k: (_outcome_value(k, a.get(k)), _outcome_value(k, b.get(k))) for k in OUTCOME_KEYS
              if k in a or k in b}
    return OutcomeChange(values=values, changed=tuple(k for k, (x, y) in values.items() if x != y))


def compare_runs(a: CompareRun, b: CompareRun, tolerance: Tolerance = Tolerance()) -> Comparison:
    """Compare run B against run A (see the module docstring): a pure function of the two runs."""
    ca, cb = a.commands, b.commands
    ia, ib = _join(ca.t_s, cb.t_s)
    only_a = np.setdiff1d(ca.t_s, cb.t_s)
    only_b = np.setdiff1d(cb.t_s, ca.t_s)
    t0 = float(ca.t_s[0]) if len(ca) else (float(cb.t_s[0]) if len(cb) else 0.0)
    fa, fb = _field_arrays(ca), _field_arrays(cb)
    tol = {"v": tolerance.v_mps, "vy": tolerance.vy_mps, "w": tolerance.w_radps}
    differs: dict[str, NDArray[np.bool_]] = {}
    for name in BEHAVIOUR_FIELDS:
        x, y = fa[name][ia], fb[name][ib]
        differs[name] = _num_differs(x, y, tol[name]) if name in tol else np.asarray(x != y)
    any_bad = np.zeros(ia.size, dtype=bool)
    for mask in differs.values():
        any_bad |= mask
    divergence = None
    stages: list[StageDivergence] = []
    if (k := _first(any_bad)) is not None:
        t = float(ca.t_s[ia[k]])
        divergence = Divergence(
            t_s=t, elapsed_s=t - t0, index_a=int(ia[k]), index_b=int(ib[k]),
            fields={n: (_value(fa[n][ia[k]]), _value(fb[n][ib[k]])) for n in BEHAVIOUR_FIELDS
                    if differs[n][k]})
        pose = _pose_stage(a.corrected, b.corrected, t, tolerance, t0)
        stages = ([pose] if pose is not None else []) + _tick_stages(a, b, ia[: k + 1], ib[: k + 1],
                                                                     tolerance, t0)
        stages.sort(key=lambda s: (s.t_s, STAGES.index(s.stage)))
        if not stages:
            stages = [_command_stage(divergence, str(ca.modes[ia[k]]), str(cb.modes[ib[k]]))]
    notes: list[str] = []
    missing = [label for label, run in (("A", a), ("B", b)) if run.stages is None]
    if missing:
        notes.append(f"{STAGES_FILE} missing in run {' and '.join(missing)}: the grid, the planner's "
                     f"direction, ND+'s region and direction and the proposal not compared (planner from "
                     f"{TIMING_FILE})")
    outcome = None
    if a.result is not None and b.result is not None:
        outcome = _outcome(a.result, b.result)
    elif (a.result is None) != (b.result is None):
        which = "A" if a.result is not None else "B"
        notes.append(f"{RESULT_FILE} only in run {which}: outcome not compared")
    same = (divergence is None and only_a.size == 0 and only_b.size == 0
            and (outcome is None or not outcome.changed))
    return Comparison(
        run_a=str(a.run_dir), run_b=str(b.run_dir), tolerance=tolerance, same=same,
        ticks_a=len(ca), ticks_b=len(cb), common_ticks=int(ia.size),
        only_a_count=int(only_a.size), only_b_count=int(only_b.size),
        only_a=tuple(float(t) for t in only_a[:1]), only_b=tuple(float(t) for t in only_b[:1]),
        counts={n: int(np.count_nonzero(m)) for n, m in differs.items()},
        divergence=divergence, stage=stages[0] if stages else None, stages=tuple(stages),
        latency=_latency(a.timing, b.timing), outcome=outcome, notes=tuple(notes),
    )


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return _value(x)


def comparison_to_dict(c: Comparison) -> dict[str, Any]:
    """The comparison as JSON-ready data (compare.json, ``--json``)."""
    d: dict[str, Any] = _jsonable(asdict(c))
    d["verdict"] = "same" if c.same else "different"
    return d


def comparison_json(c: Comparison) -> str:
    """compare.json's text."""
    return json.dumps(comparison_to_dict(c), indent=2, allow_nan=False) + "\n"


def _fmt(x: Any) -> str:
    if isinstance(x, float):
        return f"{x:.6g}"
    if isinstance(x, tuple):
        return "(" + ", ".join(_fmt(v) for v in x) + ")"
    if isinstance(x, Mapping):
        return " ".join(f"{k}={_fmt(v)}" for k, v in x.items())
    return repr(x) if isinstance(x, str) else str(x)


def comparison_lines(c: Comparison) -> list[str]:
    """The comparison as plain text lines for the terminal."""
    lines = [f"A: {c.run_a}", f"B: {c.run_b}",
             f"verdict: {'same' if c.same else 'different'}",
             f"ticks: A {c.ticks_a}, B {c.ticks_b}, common {c.common_ticks}, only in A {c.only_a_count}, "
             f"only in B {c.only_b_count}"]
    for label, first in (("A", c.only_a), ("B", c.only_b)):
        if first:
            lines.append(f"first tick only in {label}: t={first[0]:.6f}")
    if c.divergence is not None:
        d = c.divergence
        lines.append(f"first divergence: t={d.t_s:.6f} (+{d.elapsed_s:.3f} s), tick {d.index_a} of A, "
                     f"{d.index_b} of B")
        lines += [f"  {n}: {_fmt(x)} -> {_fmt(y)}" for n, (x, y) in d.fields.items()]
    if c.stage is not None:
        s = c.stage
        lines.append(f"first stage that differs: {s.stage} at t={s.t_s:.6f} (+{s.elapsed_s:.3f} s): "
                     f"{_fmt(_differing(s.a, s.b))} -> {_fmt(_differing(s.b, s.a))} ({s.evidence})")
        lines += [f"  then {s.stage} at +{s.elapsed_s:.3f} s" for s in c.stages[1:]]
    differing = [f"{n} {k}" for n, k in c.counts.items() if k]
    lines.append("ticks differing: " + (", ".join(differing) if differing else "none"))
    if c.latency:
        lines.append("latency [ms]     median A   median B   ratio      p99 A      p99 B   ratio")
        lines += [f"  {m.module:<12} {m.median_a:10.4f} {m.median_b:10.4f} {_ratio_text(m.median_ratio)} "
                  f"{m.p99_a:10.4f} {m.p99_b:10.4f} {_ratio_text(m.p99_ratio)}" for m in c.latency]
    if c.outcome is not None:
        if "outcome" in c.outcome.values and "outcome" not in c.outcome.changed:
            lines.append(f"outcome: {_fmt(c.outcome.values['outcome'][0])} in both")
        if c.outcome.changed:
            lines.append("scores changed: " + ", ".join(
                f"{k} {_fmt(c.outcome.values[k][0])} -> {_fmt(c.outcome.values[k][1])}"
                for k in c.outcome.changed))
        else:
            lines.append("scores: the same")
    lines += [f"note: {n}" for n in c.notes]
    return lines


def _differing(x: Any, other: Any) -> Any:
    """A stage's values ``x`` shown on the terminal: of a table, only those that differ from ``other``'s."""
    if isinstance(x, Mapping) and isinstance(other, Mapping):
        return {k: v for k, v in x.items() if other.get(k) != v}
    return x


def _ratio_text(r: float | None) -> str:
    return f"{r:7.2f}" if r is not None else "      -"


def figure_compare(a: CompareRun, b: CompareRun, c: Comparison) -> Any:
    """Both runs' v and w over time and their corrected xy trajectories overlaid, the first divergence
    marked."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 6.5))
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=(1.6, 1.0), left=0.07, right=0.98, bottom=0.09, top=0.92,
                            wspace=0.22, hspace=0.12)
    ax_v = fig.add_subplot(grid[0, 0])
    ax_w = fig.add_subplot(grid[1, 0], sharex=ax_v)
    ax_xy = fig.add_subplot(grid[:, 1])
    t0 = float(a.commands.t_s[0]) if len(a.commands) else 0.0
    for run, label, style in ((a, "A", dict(color="tab:blue", lw=1.4)),
                              (b, "B", dict(color="tab:orange", lw=1.0, ls="--"))):
        t = run.commands.t_s - t0
        ax_v.plot(t, run.commands.v_mps, label=label, **style)  # type: ignore[arg-type]
        ax_w.plot(t, run.commands.w_radps, label=label, **style)  # type: ignore[arg-type]
        ax_xy.plot(run.corrected[:, 1], run.corrected[:, 2], label=label, **style)  # type: ignore[arg-type]
    ax_v.set_ylabel("v [m/s]")
    ax_w.set_ylabel("w [rad/s]")
    ax_w.set_xlabel("time since A's first tick [s]")
    ax_xy.set_xlabel("x [m]")
    ax_xy.set_ylabel("y [m]")
    ax_xy.set_aspect("equal", adjustable="datalim")
    d = c.divergence
    if d is not None:
        for ax in (ax_v, ax_w):
            ax.axvline(d.elapsed_s, color="tab:red", lw=1.0, label="first divergence" if ax is ax_v else None)
            if c.stage is not None and c.stage.t_s < d.t_s:
                ax.axvline(c.stage.elapsed_s, color="tab:red", lw=1.0, ls=":",
                           label=f"first stage ({c.stage.stage})" if ax is ax_v else None)
        for run, marker in ((a, "o"), (b, "s")):
            k = int(np.searchsorted(run.corrected[:, 0], d.t_s))
            if k < run.corrected.shape[0]:
                ax_xy.plot(run.corrected[k, 1], run.corrected[k, 2], marker, color="tab:red", mfc="none",
                           ms=9)
    title = "same within tolerance" if c.same else (
        f"first divergence at +{d.elapsed_s:.3f} s ({', '.join(d.fields)})"
        + (f", first stage: {c.stage.stage}" if c.stage is not None else "") if d is not None
        else "different ticks")
    fig.suptitle(f"B against A: {title}", fontsize=10)
    ax_v.legend(loc="upper right", fontsize=8)
    ax_xy.legend(loc="best", fontsize=8)
    return fig


@dataclass(frozen=True, slots=True, eq=False)
class SnapshotPanel:
    """One run's side of the snapshot at the first divergent tick: its label, its decision there and its
    configuration (None when it could not be had), and a note (why not, or a caveat; "" for none)."""

    label: str
    decision: DecisionInput | None
    config: Config | None
    note: str = ""


def _panel_headline(p: SnapshotPanel) -> str:
    """Run label, command, mode / situation and ND+'s direction: the top line of a panel's title (the time
    leads it)."""
    assert p.decision is not None
    d = p.decision
    c = d.command
    vy = f" vy {c.vy_mps:+.3f}" if c.vy_mps else ""
    direction = f", ND+ {d.direction_rad:+.4f} rad" if math.isfinite(d.direction_rad) else ""
    return f"{p.label}: v {c.v_mps:+.3f} w {c.w_radps:+.3f}{vy}, {d.mode} / {d.situation}{direction}"


def figure_compare_snapshot(panels: Sequence[SnapshotPanel], c: Comparison, *, radius_m: float = 5.0) -> Any:
    """Both runs' decisions at the first divergent tick side by side (``decision.draw_decision``), each
    titled with its run, time, command and mode / situation; a run without a decision shows why."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .decision import decision_view, draw_decision

    n = max(len(panels), 1)
    fig = Figure(figsize=(7.0 * n, 8.6))
    FigureCanvasAgg(fig)
    for k, p in enumerate(panels):
        ax = fig.add_axes((k / n + 0.1 / n, 0.16, 0.86 / n, 0.7))
        if p.decision is None or p.config is None:
            ax.set_axis_off()
            ax.text(0.5, 0.5, f"{p.label}\n{p.note}", ha="center", va="center", wrap=True, fontsize=9,
                    transform=ax.transAxes)
            continue
        draw_decision(ax, decision_view(p.decision, p.config, headline=_panel_headline(p), radius_m=radius_m))
        if p.note:
            ax.text(0.99, 0.01, p.note, transform=ax.transAxes, ha="right", va="bottom", fontsize=7,
                    color="tab:red", wrap=True)
    d = c.divergence
    head = "B against A" if d is None else (f"B against A: first divergence at t={d.t_s:.6f} "
                                            f"(+{d.elapsed_s:.3f} s; {', '.join(d.fields)} "
                                            f"{'differs' if len(d.fields) == 1 else 'differ'})")
    if c.stage is not None:
        st = c.stage
        head += f"\nfirst stage that differs: {st.stage} at +{st.elapsed_s:.3f} s ({st.evidence})"
    fig.suptitle(head, fontsize=10)
    return fig


def write_comparison(out: Path, a: CompareRun, b: CompareRun, c: Comparison, *, overwrite: bool = False,
                     inputs: Sequence[Path] = (), snapshot: Sequence[SnapshotPanel] = ()) -> Path:
    """Write compare.json, fig_compare.png and, given ``snapshot`` panels, fig_compare_snapshot.png into a
    new output folder ``out`` (checked, staged and published as every output of gndreplay; beside an
    earlier one unless ``overwrite``). Returns where it went.

    Raises:
        OutputError: ``out`` is unsafe to write.
    """
    from ..fsutil import atomic_write_text, check_output_dir, resolve_output_dir, staging_dir, write_marker
    from .figures import save_figure

    check_output_dir(out, inputs=inputs, overwrite=overwrite)
    target = resolve_output_dir(out, overwrite=overwrite)
    stage = staging_dir(target, overwrite=overwrite, base=out)
    files = [COMPARE_JSON, COMPARE_FIGURE] + ([COMPARE_SNAPSHOT] if snapshot else [])
    with stage as tmp:
        atomic_write_text(tmp / COMPARE_JSON, comparison_json(c))
        save_figure(figure_compare(a, b, c), tmp / COMPARE_FIGURE)
        if snapshot:
            save_figure(figure_compare_snapshot(snapshot, c), tmp / COMPARE_SNAPSHOT)
        write_marker(tmp, files)
    return stage.out
