"""``gndreplay run``: stream a log through matcher -> goal lookahead -> NavigationStack -> run directory.

Data flows one way: io yields Ticks, the matcher corrects each pose, a bounded lookahead buffer assigns
each tick its goal (D metres further along the corrected trajectory, or a fixed goal), the stack decides,
and rows are streamed to files in a staging directory that is renamed into place only when complete
(``gndreplay.fsutil.staging_dir``: nothing the user owns is ever deleted or overwritten).

Records are a pure function of log + config: commands.csv, the trajectories and maps never carry wall-clock
facts (the ``*_OVER_BUDGET`` flags live in timing.csv unless ``enforce_budgets`` let them change a
command), every file prints a tick's time with ``fsutil.format_stamp``, and ``until_s`` does not change
earlier ticks (the goal lookahead reads past it).

The assisted-navigation audit (the multi-loop paper's takeovers) is part of the records: commands.csv
carries each tick's desired and active navigation mode, the takeover reason and the follower's subgoal, and
summary.json's ``interventions`` (:func:`interventions`) aggregates them into ticks per active mode, the
takeovers and the reflexive overrides, each with its start, duration and reason.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import __version__
from . import detmath as dm
from .config import Config, config_to_dict, config_to_toml
from .errors import FOLLOW_NEEDS_SUBGOALS, ConfigError, LogFormatError
from .evaluation import write_tum
from .fsutil import check_output_dir, format_stamp, resolve_output_dir, staging_dir
from .geometry import relative, wrap_angle
from .pipeline.model import RobotCentredGrid
from .pipeline.stack import MODULES, MatchInfo, NavigationStack, TickResult, warm_up
from .scanmatch import Matcher, make_matcher
from .types import BUDGET_FLAGS, REFLEXIVE_MODES, Flag, Pose2D, Scan, Subgoal, Tick

if TYPE_CHECKING:
    from .io import LogReader

__all__ = [
    "BUDGET_FLAGS",
    "COMMAND_COLUMNS",
    "COMMAND_GAP_WARN_SHARE",
    "NO_COMMAND_REASONS",
    "REFLEXIVE_MODES",
    "STAGES",
    "STALE_COMMAND_REASONS",
    "RunOptions",
    "RunSink",
    "RunSummary",
    "StagedSink",
    "assign_goals",
    "check_local_option",
    "check_navigation",
    "command_gap_warning",
    "corrected_stream",
    "episodes",
    "interventions",
    "local_strategy_used",
    "recorded_flags",
    "run_replay",
    "runs",
    "summarise",
    "tick_edges",
    "warm_up_all",
]

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


@dataclass(frozen=True, slots=True)
class RunOptions:
    """How to drive a replay.

    Attributes:
        goal_xy: a fixed goal in the corrected odometry frame, or None for goal_ahead_m.
        goal_ahead_m: the goal is the pose this far further along the log's corrected trajectory.
        until_s: stop after this much log time (from the first scan). Ticks before it are the same as
            without it: the goal lookahead still reads the log beyond ``until_s``.
        every: run the stack on every N-th tick (the matcher still sees every scan).
        max_lookahead_ticks: bound of the goal lookahead buffer (memory stays constant when the robot
            stands still; the goal is then the newest known pose).
        subgoals: the path follower's subgoals (corrected odometry frame; ``io.subgoals.load_subgoals``),
            needed by navigation mode "follow".
    """

    goal_xy: tuple[float, float] | None = None
    goal_ahead_m: float = 5.0
    until_s: float | None = None
    every: int = 1
    max_lookahead_ticks: int = 5000
    subgoals: tuple[Subgoal, ...] = ()


@dataclass(frozen=True, slots=True)
class Matched:
    """A tick after scan matching: corrected pose, time spent, and whether the match failed."""

    tick: Tick
    pose: Pose2D
    match_ms: float
    failed: bool
    s_m: float  # path length along the corrected trajectory since the first scan
    in_range: bool = True  # within until_s (later ticks are read only for the goal lookahead)


def _make_matcher(cfg: Config) -> Matcher:
    return make_matcher(cfg.scanmatch.method, idc=cfg.scanmatch.idc, kiss=cfg.scanmatch.kiss)


def _warm_up_matcher(cfg: Config) -> None:
    """Compile the matcher's kernels on synthetic scans of a bumpy round room before timing, with every
    mix of writable and read-only ranges and angles (numba compiles each apart; the CARMEN reader hands out
    writable ranges with shared read-only beam angles)."""
    for ranges_ro, angles_ro in itertools.product((False, True), repeat=2):
        matcher = _make_matcher(cfg)
        angles = np.linspace(-math.pi / 2, math.pi / 2, 361)
        angles.flags.writeable = not angles_ro
        for k in range(3):
            pose = Pose2D(0.05 * k, 0.0, 0.01 * k)
            ranges = 4.0 + 0.4 * dm.sin_a(5.0 * (angles + pose.theta)) - pose.x * dm.cos_a(angles)
            ranges.flags.writeable = not ranges_ro
            matcher.update(Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=30.0), pose)


def corrected_stream(ticks: Iterable[Tick], cfg: Config, options: RunOptions) -> Iterator[Matched]:
    """Run the configured matcher over the ticks (all of them, in time order), lazily.

    Ticks after ``until_s`` are yielded with ``in_range`` False when a goal lookahead needs them (goal
    ahead); with a fixed goal the stream stops at the first one.
    """
    matcher = _make_matcher(cfg)
    t_first: int | None = None
    s, prev = 0.0, None
    in_range = True
    for tick in ticks:
        if t_first is None:
            t_first = tick.t_ns
        if in_range and options.until_s is not None and (tick.t_ns - t_first) / 1e9 > options.until_s:
            in_range = False
            if options.goal_xy is not None:
                break
        t0 = time.perf_counter_ns()
        res = matcher.update(tick.scan, tick.odom)
        ms = (time.perf_counter_ns() - t0) / 1e6
        if prev is not None:
            s += math.hypot(res.pose.x - prev.x, res.pose.y - prev.y)
        prev = res.pose
        yield Matched(tick, res.pose, ms, not res.ok, s, in_range)


def assign_goals(
    matched: Iterable[Matched], options: RunOptions
) -> Iterator[tuple[Matched, tuple[float, float]]]:
    """Pair each matched tick with its goal.

    With a fixed goal this is a pass-through. With goal_ahead_m the goal of tick i is the point of the
    corrected trajectory goal_ahead_m further along it (interpolated between the two poses bracketing
    that arc length), which needs a bounded buffer of future ticks; at the end of the log the goal is
    the final pose. Only ticks ``in_range`` are yielded; later ones are read only as long as an earlier
    tick still waits for its goal, so a run cut by ``until_s`` gives its ticks the same goals as a full run.
    """
    if options.goal_xy is not None:
        for m in matched:
            if not m.in_range:
                return
            yield m, options.goal_xy
        return
    d = options.goal_ahead_m
    buf: deque[Matched] = deque()
    prev: Matched | None = None
    for m in matched:
        if not m.in_range and not (buf and buf[0].in_range):
            return  # every tick within until_s has its goal
        buf.append(m)
        while buf and (buf[0].s_m + d <= m.s_m or len(buf) > options.max_lookahead_ticks):
            head = buf.popleft()
            target = head.s_m + d
            if prev is not None and m.s_m > prev.s_m and prev.s_m <= target <= m.s_m:
                f = (target - prev.s_m) / (m.s_m - prev.s_m)
                gx = prev.pose.x + f * (m.pose.x - prev.pose.x)
                gy = prev.pose.y + f * (m.pose.y - prev.pose.y)
            else:
                gx, gy = m.pose.x, m.pose.y
            if head.in_range:
                yield head, (gx, gy)
        prev = m
    if prev is not None:
        for head in buf:
            if head.in_range:
                yield head, (prev.pose.x, prev.pose.y)


@dataclass(frozen=True, slots=True)
class RunSummary:
    """What a finished run reports (also written as summary.json)."""

    out_dir: Path
    ticks: int
    data: dict[str, Any] = field(repr=False)


#: commands.csv's columns: the command, what produced it (GND mode or reflexive rule, ND+ situation, flags),
#: then the audit: desired and active navigation mode, the takeover reason (why the active mode is not the
#: desired one, or why the desired module stood still: "teleop: no command", "teleop: command stale"; ""
#: when the desired module's own command won), the subgoal.
COMMAND_COLUMNS = (
    "t", "v", "vy", "w", "mode", "situation", "flags", "desired", "active", "takeover", "subgoal",
)  # fmt: skip
_COMMAND_HEADER = ",".join(COMMAND_COLUMNS) + "\n"
_TIMING_HEADER = "t," + ",".join(f"{m}_ms" for m in MODULES) + ",total_ms,planner_nodes,path_m,flags\n"


def recorded_flags(flags: Flag, *, enforce_budgets: bool) -> Flag:
    """The flags commands.csv records: all of them when budgets are enforced (they then change commands),
    otherwise all but the wall-clock ``BUDGET_FLAGS`` (which timing.csv records)."""
    return flags if enforce_budgets else flags & ~BUDGET_FLAGS


def _csv_text(text: str) -> str:
    """Free text as one CSV field without quoting: commas become semicolons, line breaks spaces."""
    return " ".join(text.replace(",", ";").split())


def _command_row(r: TickResult, enforce_budgets: bool) -> str:
    flags = "|".join(recorded_flags(r.flags, enforce_budgets=enforce_budgets).names())
    return (
        f"{format_stamp(r.t_ns)},{r.command.v_mps:.6f},{r.command.vy_mps:.6f},{r.command.w_radps:.6f},"
        f"{r.mode.value},{r.situation.name},{flags},"
        f"{_csv_text(r.desired_mode)},{_csv_text(r.active_mode)},{_csv_text(r.takeover_reason)},"
        f"{r.subgoal_index}\n"
    )


def _timing_row(r: TickResult) -> str:
    ms = [r.timings_ms.get(m, 0.0) for m in MODULES]
    over = "|".join((r.flags & BUDGET_FLAGS).names())
    stats = f"{r.planner_nodes},{r.planner_length_m:.3f}"
    return f"{format_stamp(r.t_ns)}," + ",".join(f"{x:.4f}" for x in ms) + f",{sum(ms):.4f},{stats},{over}\n"


class _Trajectories:
    """Raw-odometry and corrected poses of every scan (7 numbers a scan), written as TUM at the end."""

    def __init__(self) -> None:
        self.t_ns: list[int] = []
        self.odom: list[tuple[float, float, float]] = []
        self.corrected: list[tuple[float, float, float]] = []

    def add(self, m: Matched) -> None:
        self.t_ns.append(m.tick.t_ns)
        o, c = m.tick.odom, m.pose
        self.odom.append((o.x, o.y, o.theta))
        self.corrected.append((c.x, c.y, c.theta))

    def write(self, run_dir: Path) -> None:
        n = len(self.t_ns)
        t = np.asarray(self.t_ns, dtype=np.int64)
        for name, poses in (("odom", self.odom), ("corrected", self.corrected)):
            arr = np.asarray(poses, dtype=np.float64).reshape(n, 3)
            write_tum(run_dir / f"trajectory_{name}.tum", t, arr)


class _Recorder:
    """Accumulates the per-tick numbers the summary needs (a few floats per tick)."""

    def __init__(self, *, enforce_budgets: bool = False) -> None:
        self.enforce_budgets = enforce_budgets
        self.t_s: list[float] = []
        self.pose: list[tuple[float, float, float]] = []
        self.cmd: list[tuple[float, float, float]] = []  # v, w, direction
        self.timing: list[list[float]] = []
        self.modes: Counter[str] = Counter()
        self.situations: Counter[str] = Counter()
        self.flags: Counter[str] = Counter()
        self.over_budget: Counter[str] = Counter()
        self.planner: list[tuple[float, float]] = []  # nodes expanded (cells for NF1), path length [m]
        self.t_ns: list[int] = []
        self.audit: list[tuple[str, str, str, str]] = []  # desired, active, takeover reason, GND mode / rule

    def add(self, r: TickResult) -> None:
        self.t_s.append(r.t_ns / 1e9)
        self.t_ns.append(r.t_ns)
        self.audit.append((r.desired_mode, r.active_mode, _csv_text(r.takeover_reason), r.mode.value))
        p = r.pose_corrected
        self.pose.append((p.x, p.y, p.theta))
        self.cmd.append((r.command.v_mps, r.command.w_radps, r.direction_rad))
        self.timing.append([r.timings_ms.get(m, 0.0) for m in MODULES])
        self.modes[r.mode.value] += 1
        self.situations[r.situation.name] += 1
        for name in recorded_flags(r.flags, enforce_budgets=self.enforce_budgets).names():
            self.flags[name] += 1
        for name in (r.flags & BUDGET_FLAGS).names():
            self.over_budget[name] += 1
        self.planner.append((float(r.planner_nodes), r.planner_length_m))


def motion_agreement(
    t_s: NDArray[np.float64],
    poses: NDArray[np.float64],
    cmd: NDArray[np.float64],
    *,
    horizon_s: float = 1.0,
    min_motion_m: float = 0.05,
) -> dict[str, float]:
    """Agreement between the commands and the motion the robot actually made in the log.

    For tick i the actual motion is the corrected pose horizon_s later expressed in the robot frame at
    i: its bearing (where the robot went), its distance / horizon (speed) and its heading change /
    horizon (turn rate). Heading agreement compares the ND+ direction with that bearing on ticks where
    the robot moved at least min_motion_m; speed and turn-rate agreement compare v and w.
    """
    n = t_s.shape[0]
    if n < 2:
        return {"ticks_compared": 0}
    j = np.searchsorted(t_s, t_s + horizon_s)
    ok = j < n
    i = np.nonzero(ok)[0]
    j = j[ok]
    if i.size == 0:  # the run is shorter than the horizon
        return {"horizon_s": horizon_s, "ticks_compared": 0}
    dt = t_s[j] - t_s[i]
    rel = relative(poses[i], poses[j])
    dist = np.hypot(rel[:, 0], rel[:, 1])
    v_act = dist * np.sign(rel[:, 0]) / dt
    w_act = rel[:, 2] / dt
    bearing = dm.atan2_a(rel[:, 1], rel[:, 0])
    moved = (dist >= min_motion_m) & np.isfinite(cmd[i, 2]) & (cmd[i, 0] > 0)
    err = np.abs(np.asarray(wrap_angle(cmd[i, 2] - bearing)))[moved]
    out: dict[str, float] = {
        "horizon_s": horizon_s,
        "ticks_compared": int(i.size),
        "heading_ticks": int(err.size),
        "heading_err_median_deg": float(np.degrees(np.median(err))) if err.size else float("nan"),
        "heading_within_30deg": float(np.mean(err <= math.radians(30))) if err.size else float("nan"),
        "speed_mae_mps": float(np.mean(np.abs(cmd[i, 0] - v_act))),
        "turn_rate_mae_radps": float(np.mean(np.abs(cmd[i, 1] - w_act))),
        "turn_sign_agreement": float(
            np.mean(np.sign(cmd[i, 1]) == np.sign(w_act))
        ),
    }
    return out


def _latency(values: NDArray[np.float64]) -> dict[str, float]:
    if values.size == 0:
        return {}
    q = np.percentile(values, [50, 90, 99])
    return {"median": float(q[0]), "p90": float(q[1]), "p99": float(q[2]), "max": float(values.max())}


def _planner_stats(rec: _Recorder, cfg: Config) -> dict[str, Any]:
    """Which planner ran and its work per tick: nodes expanded (NF1: cells the wave labelled; tunnel: nodes
    expanded) and the length of the path or tunnel chain it returned, over the ticks where it found one."""
    stats = np.asarray(rec.planner, dtype=np.float64).reshape(-1, 2)
    out: dict[str, Any] = {"kind": cfg.planner.kind}
    for k, name in enumerate(("nodes", "path_m")):
        col = stats[np.isfinite(stats[:, k]), k]
        if col.size:
            q = np.percentile(col, [50, 99])
            out[name] = {"median": float(q[0]), "p99": float(q[1]), "max": float(col.max())}
    return out


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


def _span(edges: NDArray[np.float64], first: int, end: int) -> dict[str, Any]:
    """An episode's start [s since the first tick], duration (``tick_edges``: until the tick after it, or
    one tick period past the last tick at the end of the run) and ticks; times are rounded to the
    nanosecond, the stamps' resolution, so 0.2 s does not print as 0.1999999999999993."""
    return {"t_start_s": round(float(edges[first]), 9),
            "duration_s": round(float(edges[end] - edges[first]), 9), "ticks": end - first}


#: Takeover reasons the stack records on a teleop tick whose desired module stands still for want of a
#: usable command (``pipeline.stack``'s teleop command check): ``no_command_ticks`` / ``stale_command_ticks``.
NO_COMMAND_REASONS = ("teleop: no command", "teleop: command not finite")
STALE_COMMAND_REASONS = ("teleop: command stale",)


def interventions(
    t_ns: Sequence[int], desired: Sequence[str], active: Sequence[str], reasons: Sequence[str],
    modes: Sequence[str],
) -> dict[str, Any]:
    """The assisted-navigation audit of a run (summary.json's ``interventions``), from its ticks.

    Ticks per desired and per active navigation mode; the takeovers: consecutive ticks whose active mode is
    not the desired one are one takeover (its reason and active mode: those of its first tick); the
    reflexive overrides (``modes`` in ``REFLEXIVE_MODES``: emergency stops, safe replacements, stale data,
    trap escapes): consecutive ticks of the same rule are one. Each episode has ``t_start_s`` (since the
    first tick), ``duration_s`` (``tick_edges``: until the tick after it; at the end of the run, one median
    tick period past its last tick) and
    ``ticks``. ``no_command_ticks`` / ``stale_command_ticks``: ticks whose teleop command was missing or not
    finite / older than the timeout (the robot stood still for want of a driver's command, with active ==
    desired: not takeovers, but a replay where they are many did not test the driver's commands). Pure:
    behaviour only, no wall clock.
    """
    edges = tick_edges((np.asarray(t_ns, dtype=np.int64) - (t_ns[0] if len(t_ns) else 0)) / 1e9)
    taken = ["takeover" if a != d else "" for d, a in zip(desired, active, strict=True)]
    rules = [m if m in REFLEXIVE_MODES else "" for m in modes]
    takeovers = [{**_span(edges, i, j), "desired": desired[i], "active": active[i], "reason": reasons[i]}
                 for i, j in episodes(taken)]
    emergencies = [{**_span(edges, i, j), "rule": rules[i]} for i, j in episodes(rules)]
    return {
        "desired": dict(sorted(Counter(desired).items())),
        "active": dict(sorted(Counter(active).items())),
        "takeover_ticks": sum(1 for x in taken if x),
        "takeovers": takeovers,
        "reflexive_ticks": sum(1 for x in rules if x),
        "emergencies": emergencies,
        "no_command_ticks": sum(1 for r in reasons if r in NO_COMMAND_REASONS),
        "stale_command_ticks": sum(1 for r in reasons if r in STALE_COMMAND_REASONS),
    }


#: Share of ticks without a usable teleop command above which ``command_gap_warning`` speaks.
COMMAND_GAP_WARN_SHARE = 0.2


def command_gap_warning(summary: dict[str, Any]) -> str | None:
    """One line when more than ``COMMAND_GAP_WARN_SHARE`` of a run's ticks had no usable teleop command
    (missing, not finite or stale: the robot stood still, so the audit says little about the driver's
    commands), else None. ``summary``: summary.json's content."""
    iv, n = summary.get("interventions") or {}, int(summary.get("ticks", 0) or 0)
    missing, stale = int(iv.get("no_command_ticks", 0) or 0), int(iv.get("stale_command_ticks", 0) or 0)
    if n == 0 or missing + stale <= COMMAND_GAP_WARN_SHARE * n:
        return None
    return (f"{missing + stale} of {n} ticks ({100.0 * (missing + stale) / n:.0f} %) had no usable teleop "
            f"command ({missing} none or not finite, {stale} stale): the robot stood still on them")


def summarise(
    rec: _Recorder, cfg: Config, log: Path, options: RunOptions, read_report: Any
) -> dict[str, Any]:
    """summary.json: counts, histograms, agreement and (last, the only non-deterministic part) latency and
    the ticks over each module's time budget. ``flags`` counts what commands.csv records."""
    n = len(rec.t_s)
    timing = np.asarray(rec.timing, dtype=np.float64).reshape(n, len(MODULES))
    latency = {m: _latency(timing[:, k]) for k, m in enumerate(MODULES)}
    latency["stack"] = _latency(timing[:, 1:].sum(axis=1))  # model + planner + reactor
    latency["total"] = _latency(timing.sum(axis=1))
    t = np.asarray(rec.t_s)
    agreement = motion_agreement(t, np.asarray(rec.pose).reshape(n, 3), np.asarray(rec.cmd).reshape(n, 3))
    desired, active, reasons, modes = (list(col) for col in zip(*rec.audit, strict=True)) if n else ([],) * 4
    return {
        "gndreplay_version": __version__,
        "log": str(log),
        "ticks": n,
        "duration_s": float(t[-1] - t[0]) if n else 0.0,
        "modes": dict(sorted(rec.modes.items())),
        "situations": dict(sorted(rec.situations.items())),
        "flags": {
            name: rec.flags.get(name, 0)
            for name in (f.name for f in Flag if f.value and f.name)
            if rec.enforce_budgets or not Flag[name] & BUDGET_FLAGS
        },
        "interventions": interventions(rec.t_ns, desired, active, reasons, modes),
        "agreement": agreement,
        "read_report": read_report,
        "options": {
            "goal": list(options.goal_xy) if options.goal_xy else None,
            "goal_ahead_m": options.goal_ahead_m,
            "until_s": options.until_s,
            "every": options.every,
            "subgoals": [[g.x, g.y, g.theta, g.kind] for g in options.subgoals],
        },
        "config": config_to_dict(cfg),
        "planner": _planner_stats(rec, cfg),
        "latency_ms": latency,
        "over_budget": {name: rec.over_budget.get(name, 0) for name in BUDGET_FLAGS.names()},
    }


class _CompileListener:
    """Reports each gndreplay numba kernel compiled (a disk-cache miss) while active."""

    def __init__(self, callback: Callable[[str], None]) -> None:
        from numba.core import event

        class Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
                func = getattr(disp, "py_func", None)
                module = str(getattr(func, "__module__", ""))
                if module.startswith("gndreplay."):  # not numba's own helpers compiled along
                    callback(f"{module.rsplit('.', 1)[-1]}.{getattr(func, '__qualname__', '?')}")

            def on_end(self, ev: Any) -> None:
                pass

        self._event = event
        self._listener = Listener()

    def __enter__(self) -> None:
        self._event.register("numba:compile", self._listener)

    def __exit__(self, *exc: object) -> None:
        self._event.unregister("numba:compile", self._listener)


def warm_up_all(cfg: Config, on_compile: Callable[[str], None] | None = None) -> None:
    """Compile (or load from numba's disk cache) every kernel a replay with ``cfg`` uses, before the
    first timed tick. ``on_compile(name)`` is called for each kernel actually compiled (a cold cache:
    the first run after installing), so a caller can say so."""
    if on_compile is None:
        warm_up(cfg.stack_params())
        _warm_up_matcher(cfg)
        return
    with _CompileListener(on_compile):
        warm_up(cfg.stack_params())
        _warm_up_matcher(cfg)


def check_navigation(cfg: Config, options: RunOptions) -> None:
    """Refuse, before any work, a navigation mode the run cannot drive ("follow" without subgoals) and
    subgoals the mode would silently ignore (any mode but "follow").

    Raises:
        ConfigError: one line saying what is missing or unused.
    """
    mode = cfg.navigation.mode
    if mode == "follow" and not options.subgoals:
        raise ConfigError(f"{FOLLOW_NEEDS_SUBGOALS}: give --subgoals FILE (x y theta [kind] per line)")
    if mode != "follow" and options.subgoals:
        raise ConfigError(f"--subgoals: only navigation mode follow uses subgoals (mode is {mode}): "
                          "give --mode follow or drop --subgoals")


def local_strategy_used(cfg: Config) -> bool:
    """Whether ``cfg``'s navigation runs a local strategy: mode "local", or "teleop" / "follow" with the
    mode selector (local navigation takes over); never "gnd" (GND's own ND+, no selector)."""
    nav = cfg.navigation
    return nav.mode == "local" or (nav.mode in ("teleop", "follow") and nav.selector)


def check_local_option(cfg: Config, local: str | None) -> None:
    """Refuse ``--local`` given (``local`` not None) for a navigation that runs no local strategy.

    Raises:
        ConfigError: one line naming the option and the mode.
    """
    if local is not None and not local_strategy_used(cfg):
        nav = cfg.navigation
        why = f"mode {nav.mode}" + (" without the mode selector" if nav.mode != "gnd" else "")
        raise ConfigError(f"--local {local}: {why} runs no local strategy (mode local, or teleop / follow "
                          "with the selector, do): drop --local")


#: Stages ``run_replay`` reports through ``on_stage``, in order.
STAGES = ("warm-up", "replay", "write")


def run_replay(
    ticks: Iterable[Tick],
    cfg: Config,
    out_dir: Path,
    *,
    log: Path,
    options: RunOptions = RunOptions(),
    read_report: Callable[[], Any] = lambda: None,
    on_tick: Callable[[TickResult], None] | None = None,
    sinks: Iterable[RunSink] = (),
    overwrite: bool = False,
    on_stage: Callable[[str], None] | None = None,
    on_compile: Callable[[str], None] | None = None,
) -> RunSummary:
    """Replay ``ticks`` through the stack and write the run directory ``out_dir``.

    ``ticks`` is consumed lazily, one tick per stack step: with a fixed goal (``options.goal_xy``) tick
    k+1 is pulled only after ``on_tick`` was called for tick k (with a goal ahead the lookahead reads up
    to ``goal_ahead_m`` of trajectory further). Kernels are compiled before the first tick
    (``warm_up_all``; ``on_compile`` hears each cold compile); ``on_stage`` hears each of ``STAGES``.

    ``out_dir`` is checked before any work (``fsutil.check_output_dir``: never a file, the current folder,
    a folder holding the log or files gndreplay did not write). An existing run directory there is
    replaced only with ``overwrite``; otherwise the run is written beside it as ``out_dir-2``, ... (the
    returned summary says where; also when a concurrent run took the name first). Everything, the sinks'
    files included, is written into a staging directory beside it that is published only when complete
    and removed on any failure.

    Raises:
        OutputError: ``out_dir`` is unsafe to write, or the disk is full (quota, read-only) while writing.
        ConfigError: navigation mode "follow" without ``options.subgoals`` (checked first).
    """
    out_dir = Path(out_dir)
    log_path = Path(log)
    check_navigation(cfg, options)
    check_output_dir(out_dir, inputs=(log_path,) if log_path.exists() else (), overwrite=overwrite)
    target = resolve_output_dir(out_dir, overwrite=overwrite)
    stage = on_stage if on_stage is not None else (lambda name: None)
    sinks = list(sinks)
    enforce = cfg.supervisor.enforce_budgets
    staging = staging_dir(target, overwrite=overwrite, base=out_dir)
    with staging as tmp:
        try:
            for sink in sinks:
                if isinstance(sink, StagedSink):
                    sink.start(tmp, target)
            stage("warm-up")
            warm_up_all(cfg, on_compile)
            stage("replay")
            rec = _Recorder(enforce_budgets=enforce)
            traj = _Trajectories()
            stack = NavigationStack(cfg.stack_params(), options.subgoals)
            with (
                open(tmp / "commands.csv", "w", newline="") as f_cmd,
                open(tmp / "timing.csv", "w", newline="") as f_tim,
            ):
                f_cmd.write(_COMMAND_HEADER)
                f_tim.write(_TIMING_HEADER)
                pairs = assign_goals(corrected_stream(ticks, cfg, options), options)
                for k, (m, goal) in enumerate(pairs):
                    traj.add(m)
                    for sink in sinks:
                        sink.add_scan(m.tick, m.pose)
                    if k % options.every:
                        continue
                    r = stack.step(m.tick.scan, m.pose, goal, odom=m.tick.odom, cmd=m.tick.cmd,
                                   match=MatchInfo(m.match_ms, m.failed))
                    for sink in sinks:
                        sink.add_result(m.tick, r, stack.grid)
                    f_cmd.write(_command_row(r, enforce))
                    f_tim.write(_timing_row(r))
                    rec.add(r)
                    if on_tick is not None:
                        on_tick(r)
            stage("write")
            traj.write(tmp)
            summary = summarise(rec, cfg, log_path, options, read_report())
            (tmp / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=True) + "\n")
            (tmp / "config.toml").write_text(config_to_toml(cfg))
            for sink in sinks:
                sink.finish(tmp)
        except BaseException:  # abort before the staging directory (holding the sinks' files) goes
            for sink in sinks:
                sink.abort()
            raise
    return RunSummary(out_dir=staging.out, ticks=len(rec.t_s), data=summary)


@dataclass(frozen=True, slots=True)
class ReadOptions:
    """How to open the log (see ``gndreplay.io.open_log``)."""

    fmt: str | None = None
    scan_topic: str | None = None
    odom_topic: str | None = None
    cmd_topic: str | None = None
    truth_topic: str | None = None
    strict: bool = False


def run_log(
    log: Path,
    cfg: Config,
    out_dir: Path,
    *,
    options: RunOptions = RunOptions(),
    read: ReadOptions = ReadOptions(),
    sinks: Iterable[RunSink] = (),
    on_tick: Callable[[TickResult], None] | None = None,
    overwrite: bool = False,
    on_open: Callable[[LogReader], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
    on_compile: Callable[[str], None] | None = None,
) -> RunSummary:
    """Open ``log``, replay it and write ``out_dir`` (the whole of ``gndreplay run`` minus the terminal).

    ``out_dir`` is checked before the log is opened; ``on_open`` receives the open reader: its
    ``describe()`` (stream counts, start and end when the format knows them) and ``fraction_read()`` (how
    far the pass is, for formats that do not know their length) give a progress bar its total.

    Raises:
        OutputError: ``out_dir`` is unsafe to write (see ``run_replay``).
        LogFormatError: the log cannot be read, or navigation mode "teleop" on a log without recorded
            velocity commands.
        ConfigError: navigation mode "follow" without subgoals.
    """
    from .io import open_log

    check_navigation(cfg, options)
    check_output_dir(Path(out_dir), inputs=(Path(log),), overwrite=overwrite)
    with open_log(
        Path(log),
        fmt=read.fmt,
        scan_topic=read.scan_topic,
        odom_topic=read.odom_topic,
        cmd_topic=read.cmd_topic,
        truth_topic=read.truth_topic,
        strict=read.strict,
    ) as reader:
        if cfg.navigation.mode == "teleop" and not reader.records_commands():
            raise LogFormatError(f"{log}: no recorded velocity commands (cmd topic / CARMEN ODOM tv,rv); "
                                 "--mode teleop needs them")
        if on_open is not None:
            on_open(reader)
        return run_replay(
            reader.ticks(),
            cfg,
            out_dir,
            log=Path(log),
            options=options,
            read_report=lambda: reader.report.to_dict(),
            on_tick=on_tick,
            sinks=sinks,
            overwrite=overwrite,
            on_stage=on_stage,
            on_compile=on_compile,
        )
