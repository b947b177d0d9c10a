"""``gndreplay run``: stream a log through matcher -> goal lookahead -> NavigationStack -> run directory.

Data flows one way: io yields Ticks, the matcher corrects each pose, a bounded lookahead buffer assigns
each tick its goal (D metres further along the corrected trajectory, or a fixed goal), the stack decides,
and each result goes to the run directory's writers (:mod:`gndreplay.report.rundir`), the summary
(:mod:`gndreplay.report.summary`) and the sinks, in a staging directory that is renamed into place only
when complete (``gndreplay.fsutil.staging_dir``: nothing the user owns is ever deleted or overwritten).

Records are a pure function of log + config (see :mod:`gndreplay.report.rundir`), and ``until_s`` does not
change earlier ticks (the goal lookahead reads past it).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .compiling import CompileListener
from .config import Config
from .errors import FOLLOW_NEEDS_SUBGOALS, ConfigError, LogFormatError
from .fsutil import check_output_dir, resolve_output_dir, staging_dir
from .io import DEFAULT_READ, ReadOptions
from .pipeline.model import GridParams, RobotCentredGrid
from .pipeline.stack import MatchInfo, NavigationStack, TickResult, warm_up
from .report.rundir import RunSink, StagedSink, TrajectoryWriter, tick_tables, write_config, write_summary
from .report.summary import SummaryRecorder, summarise
from .scanmatch import MatchAhead, Matcher, MatchResult, make_matcher, timed_matches, warm_up_matcher
from .types import Pose2D, Subgoal, Tick

if TYPE_CHECKING:
    from .io import LogReader

__all__ = [
    "STAGES",
    "RunOptions",
    "RunSummary",
    "assign_goals",
    "check_navigation",
    "corrected_stream",
    "far_goal_warning",
    "log_source",
    "matcher_factory",
    "mounting_for",
    "replay_steps",
    "run_replay",
    "warm_up_all",
]


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
        match_ahead: scan matching runs in a second process, up to 32 ticks ahead of the stack
            (``scanmatch.MatchAhead``): the same results, sooner on a machine with a second core.
    """

    goal_xy: tuple[float, float] | None = None
    goal_ahead_m: float = 5.0
    until_s: float | None = None
    every: int = 1
    max_lookahead_ticks: int = 5000
    subgoals: tuple[Subgoal, ...] = ()
    match_ahead: bool = False


@dataclass(frozen=True, slots=True)
class Matched:
    """A tick after scan matching: corrected pose, time spent, and whether the match failed (and why)."""

    tick: Tick
    pose: Pose2D
    match_ms: float
    failed: bool
    s_m: float  # path length along the corrected trajectory since the first scan
    in_range: bool = True  # within until_s (later ticks are read only for the goal lookahead)
    reason: str = ""  # why the match failed (MatchResult.reason)


def matcher_factory(cfg: Config) -> Callable[[], Matcher]:
    """Builds the configured matcher (a picklable partial: ``MatchAhead`` builds it in its child)."""
    return partial(make_matcher, cfg.scanmatch.method, idc=cfg.scanmatch.idc, kiss=cfg.scanmatch.kiss)


def _warm_up_matcher(cfg: Config) -> None:
    warm_up_matcher(matcher_factory(cfg))


def _matched(ticks: Iterable[Tick], cfg: Config, ahead: MatchAhead | None,
             ahead_while: Callable[[Tick], bool]) -> Iterator[tuple[Tick, MatchResult, float]]:
    """(tick, match, match ms) in order: by ``ahead``'s child process (reading ahead while
    ``ahead_while``), or here."""
    if ahead is not None:
        yield from ahead.results(ticks, ahead_while)
        return
    yield from timed_matches(ticks, matcher_factory(cfg)())


def corrected_stream(ticks: Iterable[Tick], cfg: Config, options: RunOptions,
                     ahead: MatchAhead | None = None) -> Iterator[Matched]:
    """Run the configured matcher over the ticks (all of them, in time order), lazily; in ``ahead``'s
    child process when given (the same poses; the ticks are then read up to its depth ahead).

    Ticks after ``until_s`` are yielded with ``in_range`` False when a goal lookahead needs them (goal
    ahead); with a fixed goal the stream stops at the first one.
    """
    s, prev = 0.0, None
    in_range = True
    first: list[int] = []  # the log's first stamp, set by whichever reads the first tick: here or ahead

    def within(tick: Tick) -> bool:
        if not first:
            first.append(tick.t_ns)
        return options.until_s is None or (tick.t_ns - first[0]) / 1e9 <= options.until_s

    for tick, res, ms in _matched(ticks, cfg, ahead, within):
        if in_range and not within(tick):
            in_range = False
            if options.goal_xy is not None:
                break
        if prev is not None:
            s += math.hypot(res.pose.x - prev.x, res.pose.y - prev.y)
        prev = res.pose
        yield Matched(tick, res.pose, ms, not res.ok, s, in_range, res.reason)


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


def replay_steps(
    ticks: Iterable[Tick], cfg: Config, options: RunOptions, ahead: MatchAhead | None = None
) -> Iterator[tuple[Matched, TickResult | None, RobotCentredGrid]]:
    """The replay itself, lazily: every tick within ``until_s`` scan-matched (``corrected_stream``), given its
    goal (``assign_goals``) and, every ``options.every``-th, stepped through a new ``NavigationStack``;
    yields (the matched tick, the stack's result or None for a tick skipped by ``every``, the stack's grid
    after it). The next tick is pulled only after the consumer is done with this one (a closed loop hears
    each command before the world moves on)."""
    stack = NavigationStack(cfg.stack_params(), options.subgoals)
    pairs = assign_goals(corrected_stream(ticks, cfg, options, ahead), options)
    for k, (m, goal) in enumerate(pairs):
        if k % options.every:
            yield m, None, stack.grid
            continue
        r = stack.step(m.tick.scan, m.pose, goal, odom=m.tick.odom, cmd=m.tick.cmd,
                       match=MatchInfo(m.match_ms, m.failed))
        yield m, r, stack.grid


@dataclass(frozen=True, slots=True)
class RunSummary:
    """What a finished run reports (also written as summary.json)."""

    out_dir: Path
    ticks: int
    data: dict[str, Any] = field(repr=False)


def warm_up_all(cfg: Config, on_compile: Callable[[str], None] | None = None,
                ahead: MatchAhead | None = None) -> None:
    """Compile (or load from numba's disk cache) every kernel a replay with ``cfg`` uses, before the
    first timed tick. ``on_compile(name)`` is called for each kernel actually compiled (a cold cache:
    the first run after installing), so a caller can say so. With ``ahead`` the matcher's kernels are
    its child's, warmed there at the same time: this waits for it."""
    with CompileListener(on_compile) if on_compile is not None else nullcontext():
        warm_up(cfg.stack_params())
        if ahead is None:
            _warm_up_matcher(cfg)
    if ahead is not None:
        ahead.ready(on_compile)


def _match_ahead(cfg: Config) -> MatchAhead:
    make = matcher_factory(cfg)
    return MatchAhead(make, partial(warm_up_matcher, make))


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


def mounting_for(read: ReadOptions, cfg: Config) -> ReadOptions:
    """``read`` with the robot's laser pose as the fallback mounting of a log that records none, when the
    configuration asks for it (``[robot] mounting_fallback``) and ``read`` gives none of its own."""
    if not cfg.robot.mounting_fallback or read.default_sensor_pose is not None:
        return read
    return dataclasses.replace(read, default_sensor_pose=cfg.robot.laser_pose)


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
    source: Mapping[str, Any] | None = None,
) -> RunSummary:
    """Replay ``ticks`` through the stack and write the run directory ``out_dir``.

    ``source`` says how to read ``ticks`` again (summary.json's ``source``: ``gndreplay.rerun`` re-runs
    the input from it; None: the run cannot be re-run).

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
            ahead = _match_ahead(cfg) if options.match_ahead else None
            with ahead or nullcontext(), tick_tables(tmp, enforce_budgets=enforce) as write_tick:
                warm_up_all(cfg, on_compile, ahead)
                stage("replay")
                rec = SummaryRecorder(enforce_budgets=enforce)
                traj = TrajectoryWriter()
                for m, r, grid in replay_steps(ticks, cfg, options, ahead):
                    traj.add(m.tick.t_ns, m.tick.odom, m.pose, m.tick.truth)
                    rec.add_match(not m.failed, m.reason)
                    for sink in sinks:
                        sink.add_scan(m.tick, m.pose)
                    if r is None:
                        continue
                    for sink in sinks:
                        sink.add_result(m.tick, r, grid)
                    write_tick(r, m.tick.cmd)
                    rec.add(r)
                    if on_tick is not None:
                        on_tick(r)
            stage("write")
            summary = summarise(rec, cfg, log_path, options, read_report(), traj.write(tmp), source)
            write_summary(tmp, summary)
            write_config(tmp, cfg)
            for sink in sinks:
                sink.finish(tmp)
        except BaseException:  # abort before the staging directory (holding the sinks' files) goes
            for sink in sinks:
                sink.abort()
            raise
    return RunSummary(out_dir=staging.out, ticks=len(rec.t_s), data=summary)


def run_log(
    log: Path,
    cfg: Config,
    out_dir: Path,
    *,
    options: RunOptions = RunOptions(),
    read: ReadOptions = DEFAULT_READ,
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

    read = mounting_for(read, cfg)
    check_navigation(cfg, options)
    check_output_dir(Path(out_dir), inputs=(Path(log),), overwrite=overwrite)
    with open_log(Path(log), options=read) as reader:
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
            source=log_source(Path(log), read),
        )


def log_source(log: Path, read: ReadOptions) -> dict[str, Any]:
    """summary.json's ``source`` of a replayed log: its absolute path and how it was read."""
    return {"kind": "log", "path": str(log.resolve()), "read": read.to_dict()}


def far_goal_warning(goal_xy: tuple[float, float], trajectory_xy: Any, grid: GridParams) -> str | None:
    """One line when the fixed goal ``goal_xy`` lies farther than half the grid's side from every pose of
    the corrected trajectory ``trajectory_xy`` ((N, 2) x, y [m]), else None: the goal was then never on the
    robot-centred grid the planner plans over, so every tick planned toward the grid's border instead (most
    often a goal given in another frame or unit)."""
    xy = np.asarray(trajectory_xy, dtype=np.float64).reshape(-1, 2)
    if xy.shape[0] == 0:
        return None
    reach_m = 0.5 * grid.size_cells * grid.cell_m
    nearest = float(np.min(np.hypot(xy[:, 0] - goal_xy[0], xy[:, 1] - goal_xy[1])))
    if not nearest > reach_m:
        return None
    return (f"goal ({goal_xy[0]:g}, {goal_xy[1]:g}) is {nearest:.1f} m from the nearest pose of the "
            f"corrected trajectory, beyond the grid's half side ({reach_m:g} m): it was never on the "
            "planner's grid, which planned toward its border on every tick")
