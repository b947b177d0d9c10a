"""``gndreplay run``: stream a log through matcher -> goal lookahead -> NavigationStack -> run directory.

Data flows one way: io yields Ticks, the matcher corrects each pose, a bounded lookahead buffer assigns
each tick its goal (D metres further along the corrected trajectory, or a fixed goal), the stack decides,
and rows are streamed to files in a temporary directory that is renamed into place only on success.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import shutil
import tempfile
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from . import __version__
from .config import Config, config_to_dict, config_to_toml
from .evaluation import write_tum
from .fsutil import umask_mode
from .geometry import relative, wrap_angle
from .pipeline.model import RobotCentredGrid
from .pipeline.stack import MODULES, NavigationStack, TickResult, warm_up
from .scanmatch import Matcher, make_matcher
from .types import Flag, Pose2D, Scan, Tick

__all__ = [
    "RunOptions",
    "RunSink",
    "RunSummary",
    "assign_goals",
    "corrected_stream",
    "run_replay",
    "summarise",
]


class RunSink(Protocol):
    """Something that consumes the replay as it streams and writes its own files into the run directory
    (figures' map rasters, the results MCAP, ...). ``finish`` receives the temporary run directory; it is
    called once, only when the replay completed."""

    def add_scan(self, tick: Tick, pose_corrected: Pose2D) -> None:
        """Every scan of the log (also those skipped by ``every``), at its corrected pose."""

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Every tick the stack ran on, with its result and the robot-centred grid after integration."""

    def finish(self, run_dir: Path) -> None:
        """Write this sink's files into ``run_dir``."""

    def abort(self) -> None:
        """The replay failed: release whatever the sink holds (temporary files, writers)."""


@dataclass(frozen=True, slots=True)
class RunOptions:
    """How to drive a replay.

    Attributes:
        goal_xy: a fixed goal in the corrected odometry frame, or None for goal_ahead_m.
        goal_ahead_m: the goal is the pose this far further along the log's corrected trajectory.
        until_s: stop after this much log time (from the first scan).
        every: run the stack on every N-th tick (the matcher still sees every scan).
        max_lookahead_ticks: bound of the goal lookahead buffer (memory stays constant when the robot
            stands still; the goal is then the newest known pose).
    """

    goal_xy: tuple[float, float] | None = None
    goal_ahead_m: float = 5.0
    until_s: float | None = None
    every: int = 1
    max_lookahead_ticks: int = 5000


@dataclass(frozen=True, slots=True)
class Matched:
    """A tick after scan matching: corrected pose, time spent, and whether the match failed."""

    tick: Tick
    pose: Pose2D
    match_ms: float
    failed: bool
    s_m: float  # path length along the corrected trajectory since the first scan


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
            ranges = 4.0 + 0.4 * np.sin(5.0 * (angles + pose.theta)) - pose.x * np.cos(angles)
            ranges.flags.writeable = not ranges_ro
            matcher.update(Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=30.0), pose)


def corrected_stream(ticks: Iterable[Tick], cfg: Config, options: RunOptions) -> Iterator[Matched]:
    """Run the configured matcher over the ticks (all of them, in time order) within ``until_s``."""
    matcher = _make_matcher(cfg)
    t_first: int | None = None
    s, prev = 0.0, None
    for tick in ticks:
        if t_first is None:
            t_first = tick.t_ns
        if options.until_s is not None and (tick.t_ns - t_first) / 1e9 > options.until_s:
            break
        t0 = time.perf_counter_ns()
        res = matcher.update(tick.scan, tick.odom)
        ms = (time.perf_counter_ns() - t0) / 1e6
        if prev is not None:
            s += math.hypot(res.pose.x - prev.x, res.pose.y - prev.y)
        prev = res.pose
        yield Matched(tick, res.pose, ms, not res.ok, s)


def assign_goals(
    matched: Iterable[Matched], options: RunOptions
) -> Iterator[tuple[Matched, tuple[float, float]]]:
    """Pair each matched tick with its goal.

    With a fixed goal this is a pass-through. With goal_ahead_m the goal of tick i is the point of the
    corrected trajectory goal_ahead_m further along it (interpolated between the two poses bracketing
    that arc length), which needs a bounded buffer of future ticks; at the end of the log the goal is
    the final pose.
    """
    if options.goal_xy is not None:
        for m in matched:
            yield m, options.goal_xy
        return
    d = options.goal_ahead_m
    buf: deque[Matched] = deque()
    prev: Matched | None = None
    for m in matched:
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
            yield head, (gx, gy)
        prev = m
    if prev is not None:
        for head in buf:
            yield head, (prev.pose.x, prev.pose.y)


@dataclass(frozen=True, slots=True)
class RunSummary:
    """What a finished run reports (also written as summary.json)."""

    out_dir: Path
    ticks: int
    data: dict[str, Any] = field(repr=False)


_COMMAND_HEADER = "t,v,vy,w,mode,situation,flags\n"
_TIMING_HEADER = "t," + ",".join(f"{m}_ms" for m in MODULES) + ",total_ms\n"


def _command_row(r: TickResult) -> str:
    flags = "|".join(r.flags.names())
    return (
        f"{r.t_ns / 1e9:.9f},{r.v_mps:.6f},{r.vy_mps:.6f},{r.w_radps:.6f},"
        f"{r.mode.value},{r.situation.name},{flags}\n"
    )


def _timing_row(r: TickResult) -> str:
    ms = [r.timings_ms.get(m, 0.0) for m in MODULES]
    return f"{r.t_ns / 1e9:.9f}," + ",".join(f"{x:.4f}" for x in ms) + f",{sum(ms):.4f}\n"


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

    def __init__(self) -> None:
        self.t_s: list[float] = []
        self.pose: list[tuple[float, float, float]] = []
        self.cmd: list[tuple[float, float, float]] = []  # v, w, direction
        self.timing: list[list[float]] = []
        self.modes: Counter[str] = Counter()
        self.situations: Counter[str] = Counter()
        self.flags: Counter[str] = Counter()

    def add(self, r: TickResult) -> None:
        self.t_s.append(r.t_ns / 1e9)
        p = r.pose_corrected
        self.pose.append((p.x, p.y, p.theta))
        self.cmd.append((r.v_mps, r.w_radps, r.direction_rad))
        self.timing.append([r.timings_ms.get(m, 0.0) for m in MODULES])
        self.modes[r.mode.value] += 1
        self.situations[r.situation.name] += 1
        for name in r.flags.names():
            self.flags[name] += 1


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
    bearing = np.arctan2(rel[:, 1], rel[:, 0])
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


def summarise(
    rec: _Recorder, cfg: Config, log: Path, options: RunOptions, read_report: Any
) -> dict[str, Any]:
    """summary.json: counts, histograms, agreement and (last, the only non-deterministic part) latency."""
    n = len(rec.t_s)
    timing = np.asarray(rec.timing, dtype=np.float64).reshape(n, len(MODULES))
    latency = {m: _latency(timing[:, k]) for k, m in enumerate(MODULES)}
    latency["stack"] = _latency(timing[:, 1:].sum(axis=1))  # model + planner + reactor
    latency["total"] = _latency(timing.sum(axis=1))
    t = np.asarray(rec.t_s)
    agreement = motion_agreement(t, np.asarray(rec.pose).reshape(n, 3), np.asarray(rec.cmd).reshape(n, 3))
    return {
        "gndreplay_version": __version__,
        "log": str(log),
        "ticks": n,
        "duration_s": float(t[-1] - t[0]) if n else 0.0,
        "modes": dict(sorted(rec.modes.items())),
        "situations": dict(sorted(rec.situations.items())),
        "flags": {name: rec.flags.get(name, 0) for name in (f.name for f in Flag if f.value and f.name)},
        "agreement": agreement,
        "read_report": read_report,
        "options": {
            "goal": list(options.goal_xy) if options.goal_xy else None,
            "goal_ahead_m": options.goal_ahead_m,
            "until_s": options.until_s,
            "every": options.every,
        },
        "config": config_to_dict(cfg),
        "latency_ms": latency,
    }


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
) -> RunSummary:
    """Replay ``ticks`` through the stack and write the run directory ``out_dir``.

    Files are written into a sibling temporary directory and moved into place only when the run
    finished, so an error (bad log record, interrupt) never leaves a half-written run directory.
    """
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    sinks = list(sinks)
    try:
        warm_up(cfg.stack_params())
        _warm_up_matcher(cfg)
        rec = _Recorder()
        traj = _Trajectories()
        stack = NavigationStack(cfg.stack_params())
        with (
            open(tmp / "commands.csv", "w", newline="") as f_cmd,
            open(tmp / "timing.csv", "w", newline="") as f_tim,
        ):
            f_cmd.write(_COMMAND_HEADER)
            f_tim.write(_TIMING_HEADER)
            for k, (m, goal) in enumerate(assign_goals(corrected_stream(ticks, cfg, options), options)):
                traj.add(m)
                for sink in sinks:
                    sink.add_scan(m.tick, m.pose)
                if k % options.every:
                    continue
                r = stack.step(m.tick, m.pose, goal, match_ms=m.match_ms, match_failed=m.failed)
                for sink in sinks:
                    sink.add_result(m.tick, r, stack.grid)
                f_cmd.write(_command_row(r))
                f_tim.write(_timing_row(r))
                rec.add(r)
                if on_tick is not None:
                    on_tick(r)
        traj.write(tmp)
        summary = summarise(rec, cfg, log, options, read_report())
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=True) + "\n")
        (tmp / "config.toml").write_text(config_to_toml(cfg))
        for sink in sinks:
            sink.finish(tmp)
        os.chmod(tmp, umask_mode(0o777))
        if out_dir.exists():
            shutil.rmtree(out_dir)
        tmp.rename(out_dir)
    except BaseException:
        for sink in sinks:
            sink.abort()
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return RunSummary(out_dir=out_dir, ticks=len(rec.t_s), data=summary)


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
) -> RunSummary:
    """Open ``log``, replay it and write ``out_dir`` (the whole of ``gndreplay run`` minus the terminal)."""
    from .io import open_log

    with open_log(
        Path(log),
        fmt=read.fmt,
        scan_topic=read.scan_topic,
        odom_topic=read.odom_topic,
        cmd_topic=read.cmd_topic,
        truth_topic=read.truth_topic,
        strict=read.strict,
    ) as reader:
        return run_replay(
            reader.ticks(),
            cfg,
            out_dir,
            log=Path(log),
            options=options,
            read_report=lambda: reader.report.to_dict(),
            on_tick=on_tick,
            sinks=sinks,
        )
