"""The closed loop: the stack's commands drive a simulated robot in a scenario's world.

:class:`ClosedLoop` is a tick generator plus an ``on_tick`` callback for :func:`gndreplay.replay.run_replay`
(which pulls tick k + 1 only after it handed the command of tick k to ``on_tick``). Between two scans the
world advances in pieces of at most ``SimParams.dt_s``, also cut at every event and at the moment the new
command takes effect (scan time + latency):

- the wheel velocity follows the command through the drive's first-order response within the robot's
  acceleration limits (:mod:`.dynamics`; with ``ideal_dynamics`` it moves toward the command at those
  limits), then stays constant over the piece; the body moves with it corrupted by slip and skid (not with
  ``ideal_dynamics``), along an exact arc (SE(2) exponential);
- collision is continuous: conservative advancement with the exact clearance between the real footprint
  and every element, divided by an upper bound of the closing speed (the fastest footprint point plus the
  fastest moving element); no tunnelling whatever the speed, and the first contact ends the run with the
  contact point and the element's id;
- movers walk their paths and, with ``yield_m > 0``, wait while a step would bring them closer than that
  to the footprint; door leaves wait likewise (0.3 m), as the people moving them would;
- wheel odometry integrates the wheels' motion, so slip shows as its drift, and drifts more
  (``OdometryNoise``); the laser is ray cast (exact circles, thick walls) with noise, one scan per tick at
  its period.

Navigation modes: the scenario's ``mode`` / ``local`` override the configuration's
(:func:`navigation_config`). In teleop mode the operator of :mod:`.teleop` gives the command of each scan
(``Tick.cmd``, what a log's recorded command would be; otherwise ``Tick.cmd`` is the robot's true velocity,
as wheel odometry reports it). A teleop run succeeds when the script's time is over or the track's end is
reached, a follow run when the stack reports the final subgoal reached, any other when the true axle is
within the supervisor's goal tolerance of the goal; always without contact. A goal run whose stack reports
GOAL_REACHED while the true axle is outside that tolerance (its corrected pose is wrong) ends as
``goal_missed`` once the robot has stood still, the stack still reporting the goal, for
``SimParams.goal_settle_s``: the robot stopped short because of its localisation error, nothing timed out
(the success criterion is not loosened). Each tick's desired and active
modes are counted; a takeover is a tick whose active mode differs from the desired one after one where
they agreed.

Everything random comes from the seed; with a fixed latency the run is a pure function of (scenario,
config, seed).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..config import NO_OVERRIDES, CliOverrides, Config, apply_overrides, configure, navigation_choices
from ..errors import ConfigError
from ..geometry import compose, relative
from ..io.userfile import check_number
from ..pipeline.stack import TickResult
from ..report.rundir import recorded_flags
from ..types import Command, Flag, Pose2D, Scan, Subgoal, Tick
from .dynamics import SlipNoise, SlipState, next_velocity, speed_bound
from .geometry import (
    Clearance,
    Shapes,
    cast,
    footprint_clearance,
    footprint_vertices,
    max_point_speed,
)
from .scenario import DEFAULT_T0_NS, OdometryNoise, check_seed
from .scenario_file import DEFAULT_YIELD_M, MAX_TIME_S, MIN_TIME_LIMIT_S, Element, ScenarioSpec
from .score import CELL_M, OptimalPath, challenge_metric, narrowest_passage_m, optimal_path, optimal_time_s
from .teleop import TeleopDriver
from .world import LaserModel, add_laser_noise

__all__ = [
    "ClosedLoop", "SimParams", "SimRecord", "arc_step", "configure_scenario", "navigation_config",
    "scenario_navigation", "static_shapes",
]

F64 = NDArray[np.float64]
NS = 1_000_000_000
#: Longest command latency [s] (``runner.parse_latency`` takes less than 10 s).
MAX_LATENCY_S = 10.0


@dataclass(frozen=True, slots=True)
class SimParams:
    """Simulator settings (not the robot's: those come from the preset).

    Attributes:
        dt_s: longest piece of constant velocity [s] (acceleration is applied piece by piece).
        contact_m: a clearance at or below this is a contact [m].
        resolution_m: ranges are rounded to this (the SICK reports millimetres).
        odometry: wheel odometry errors.
        t0_ns: clock of the first scan (the log's time stamps).
        max_iterations: conservative-advancement steps per piece before a near-touch counts as contact.
        goal_settle_s: how long the robot must stand still with the stack reporting GOAL_REACHED, outside the
            goal tolerance, before the run ends as ``goal_missed`` (the stop must be the stack's final one,
            not a pause while it decelerates or the corrected pose settles).
        slip: slip and skid of the executed motion (not with ideal dynamics).
    """

    dt_s: float = 0.01
    contact_m: float = 1e-4
    resolution_m: float = 0.001
    odometry: OdometryNoise = OdometryNoise()
    t0_ns: int = DEFAULT_T0_NS
    max_iterations: int = 10_000
    goal_settle_s: float = 1.0
    slip: SlipNoise = SlipNoise()


def arc_step(pose: F64, vx: float, vy: float, w: float, h: float) -> F64:
    """Exact motion of a body with constant body twist (vx, vy, w) for ``h`` seconds."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    a = w * h
    if abs(a) < 1e-12:
        dx, dy = vx * h, vy * h
    else:
        s, c1 = dm.sin(a), 1.0 - dm.cos(a)
        dx, dy = (vx * s - vy * c1) / w, (vx * c1 + vy * s) / w
    c, s = dm.cos(th), dm.sin(th)
    return np.array([x + c * dx - s * dy, y + s * dx + c * dy, _wrap(th + a)])


def _wrap(a: float) -> float:
    """An angle in (-pi, pi] (scalar; the hot loop's version of ``geometry.wrap_angle``)."""
    if -math.pi < a <= math.pi:
        return a
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@dataclass(slots=True)
class SimRecord:
    """What the loop recorded (for result.json, the log and the figure)."""

    scan_t_ns: list[int] = field(default_factory=list)
    scan_ranges: list[F64] = field(default_factory=list)
    scan_truth: list[tuple[float, float, float]] = field(default_factory=list)
    scan_odom: list[tuple[float, float, float]] = field(default_factory=list)
    scan_vel: list[tuple[float, float, float]] = field(default_factory=list)  # true body twist at each scan
    cmd: list[tuple[int, float, float, float]] = field(default_factory=list)  # t_ns, v, vy, w per tick
    modes: Counter[str] = field(default_factory=Counter)
    flags: Counter[str] = field(default_factory=Counter)
    trap_count: int = 0
    stack_goal_t_s: float | None = None
    goal_stop_t_s: float | None = None  # since when the stack reports GOAL_REACHED and the robot stands still
    stack_ms: list[float] = field(default_factory=list)
    truth_t: list[float] = field(default_factory=list)  # every piece end
    truth: list[tuple[float, float, float]] = field(default_factory=list)
    clearance: list[tuple[float, float]] = field(default_factory=list)  # (duration s, clearance m)
    min_clearance_m: float = math.inf
    movers_t: list[float] = field(default_factory=list)  # every second
    movers_xy: list[list[tuple[float, float]]] = field(default_factory=list)
    sim_ns: list[int] = field(default_factory=list)  # wall time of the simulator per tick
    active_modes: Counter[str] = field(default_factory=Counter)  # ticks per active navigation mode
    takeovers: int = 0
    takeover_reasons: Counter[str] = field(default_factory=Counter)  # per takeover onset
    mode_stretches: list[list[Any]] = field(default_factory=list)  # [active mode, from s, to s]
    subgoal_index: int = -1
    teleop_cmd: list[tuple[float, float]] = field(default_factory=list)  # the operator's (v, w) per tick


def navigation_config(spec: ScenarioSpec, cfg: Config) -> Config:
    """``cfg`` with the scenario's ``mode`` and ``local`` (when it gives them) as ``[navigation]``.

    Raises:
        ConfigError: the resulting mode needs what the scenario lacks (teleop without an operator, follow
            without subgoals), naming the scenario file.
    """
    nav: dict[str, Any] = {}
    if spec.mode is not None:
        nav["mode"] = spec.mode
    if spec.local is not None:
        nav["local"] = {"strategy": spec.local}
    out = apply_overrides(cfg, {"navigation": nav}) if nav else cfg
    mode = out.navigation.mode
    if mode == "teleop" and spec.teleop is None:
        raise ConfigError(f"{spec.source}: teleop: missing (mode teleop needs commands or a track)")
    if mode == "follow" and not spec.subgoals:
        raise ConfigError(f"{spec.source}: subgoals: missing (navigation mode follow needs them)")
    return out


def scenario_navigation(spec: ScenarioSpec, mode: str | None = None, local: str | None = None,
                        subgoals: tuple[Subgoal, ...] = ()) -> ScenarioSpec:
    """The scenario with ``--mode``, ``--local`` and ``--subgoals`` in place of its own ``mode``, ``local``
    and ``subgoals`` (the scenario's keys override [navigation]; the command line overrides the scenario).

    Raises:
        ConfigError: an unknown mode or strategy, or subgoals for a scenario that does not run mode
            follow (one line naming the option).
    """
    from .scenario_file import check_subgoals_used

    mode, local = navigation_choices(mode, local)
    changes: dict[str, Any] = {}
    if mode is not None:
        changes["mode"] = mode
    if local is not None:
        changes["local"] = local
    if subgoals:
        changes["subgoals"] = tuple(subgoals)
    out = dataclasses.replace(spec, **changes) if changes else spec
    if subgoals:
        check_subgoals_used(out)
    return out


def configure_scenario(spec: ScenarioSpec, *, config: Path | None = None, preset: str | None = None,
                       overrides: CliOverrides = NO_OVERRIDES,
                       subgoals: tuple[Subgoal, ...] = ()) -> tuple[ScenarioSpec, Config]:
    """A scenario run's scenario and stack configuration from the command line: ``--mode``, ``--local`` and
    ``--subgoals`` replace the scenario's own keys (``scenario_navigation``); the preset (``preset``, else
    the scenario's), the ``config`` file and the other overrides make the configuration
    (``config.configure``), as for a log.

    Raises:
        ConfigError: a bad option, config file or key (one line naming it), or subgoals for a scenario that
            does not run mode follow.
    """
    spec = scenario_navigation(spec, overrides.mode, overrides.local, subgoals)
    own = dataclasses.replace(overrides, mode=None, local=None)
    return spec, configure(config, preset_name=preset or spec.preset, overrides=own)


def static_shapes(elements: tuple[Element, ...], t_s: float, door_delay: F64) -> Shapes:
    """The elements present at ``t_s`` as shapes, each door leaf as it stands ``door_delay`` [s] late."""
    polys, pe, circles, ce = [], [], [], []
    for i, e in enumerate(elements):
        if e.circle is not None:
            if e.present(t_s):
                circles.append(e.circle)
                ce.append(i)
            continue
        v = e.outline_at(t_s, t_s - door_delay[i])
        if v is not None:
            polys.append(v)
            pe.append(i)
    return Shapes.build(polys, pe, circles, ce)


class _World:
    """The scenario's elements and movers over time; polygon snapshots cached between changes."""

    def __init__(self, spec: ScenarioSpec) -> None:
        self.spec = spec
        self.elements = spec.elements
        self.movers = spec.movers
        self.n = len(self.elements)
        self.mover_s = np.zeros(len(self.movers))
        self.mover_xy = np.array([m.position(0.0) for m in self.movers], dtype=np.float64).reshape(-1, 2)
        self._cache: dict[tuple[Any, ...], Shapes] = {}
        self._mover_elem = np.arange(self.n, self.n + len(self.movers), dtype=np.int64)
        self._mover_r = np.array([m.radius_m for m in self.movers], dtype=np.float64)
        times: set[float] = set()
        for e in self.elements:
            times.update(t for t in (e.appear_s, e.remove_s) if t is not None)
            for a in e.door:
                times.update((a.t0_s, a.t1_s))
        times.update(m.start_at_s for m in self.movers)
        self.breaks_ns = sorted(round(t * NS) for t in times if t > 0.0)
        self._dynamic = [i for i, e in enumerate(self.elements) if e.door]
        self.door_delay = np.zeros(self.n)  # how long each door leaf's mover has waited so far [s]

    def next_break(self, t_ns: int) -> int | None:
        """The first break time after ``t_ns`` (a bisection: a scenario may have thousands of events)."""
        k = bisect.bisect_right(self.breaks_ns, t_ns)
        return self.breaks_ns[k] if k < len(self.breaks_ns) else None

    def _static(self, t_s: float) -> Shapes:
        key = (tuple(e.present(t_s) for e in self.elements),
               tuple(self.elements[i].closed_fraction(t_s - self.door_delay[i]) for i in self._dynamic))
        hit = self._cache.get(key)
        if hit is None:
            hit = static_shapes(self.elements, t_s, self.door_delay)
            if len(self._cache) > 256:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def shapes(self, t_s: float, mover_xy: F64) -> Shapes:
        """Every shape present at ``t_s``, the movers at ``mover_xy``."""
        if not self.movers:
            return self._static(t_s)
        return self._static(t_s).with_circles(np.column_stack([mover_xy, self._mover_r]), self._mover_elem)

    def step_key(self, t_s: float) -> tuple[Any, ...]:
        """What changes the world by a step at ``t_s`` (appear / remove, instant door actions): equal keys
        mean the world differs only by bounded-speed motion."""
        return (tuple(e.present(t_s) for e in self.elements),
                tuple(self.elements[i].steps_done(t_s - self.door_delay[i]) for i in self._dynamic))

    def leaf_speed(self, t_s: float) -> float:
        return max((self.elements[i].leaf_speed(t_s - self.door_delay[i]) for i in self._dynamic
                    if self.elements[i].present(t_s)), default=0.0)

    def moving_doors(self, t_s: float) -> list[int]:
        """Indices of the door leaves moving at ``t_s``."""
        return [i for i in self._dynamic if self.elements[i].present(t_s)
                and self.elements[i].leaf_speed(t_s - self.door_delay[i]) > 0]


class ClosedLoop:
    """Drives a scenario in closed loop with the stack (see the module docstring).

    Args:
        spec: the scenario.
        cfg: robot, laser and stack configuration (the preset); the scenario's navigation mode is applied
            over it (``self.cfg``, see :func:`navigation_config`).
        seed: fixes the laser noise and the odometry errors.
        latency_s: the command computed from scan k applies from t_k + latency_s; None uses the stack's
            measured time of that tick (then the run is not deterministic).
        perfect_odometry: odometry = ground truth.
        time_limit_s: overrides the scenario's time limit.
        ideal_dynamics: the exact model: no response lag, no slip (see :mod:`.dynamics`).

    Raises:
        ConfigError: a seed out of ``check_seed``'s range, a latency above MAX_LATENCY_S or a time limit
            outside MIN_TIME_LIMIT_S..MAX_TIME_S (beyond them the clock's nanoseconds overflow, below it
            the run has no step to take), in one line.
    """

    def __init__(self, spec: ScenarioSpec, cfg: Config, *, seed: int, latency_s: float | None = 0.0,
                 perfect_odometry: bool = False, time_limit_s: float | None = None,
                 params: SimParams = SimParams(), ideal_dynamics: bool = False) -> None:
        cfg = navigation_config(spec, cfg)
        check_seed(seed)
        if latency_s is not None:
            check_number(latency_s, "latency [s]", 0.0, MAX_LATENCY_S)
        if time_limit_s is not None:
            check_number(time_limit_s, "time limit [s]", MIN_TIME_LIMIT_S, MAX_TIME_S)
        self.spec, self.cfg, self.seed, self.params = spec, cfg, seed, params
        self.nav_mode = cfg.navigation.mode
        self.latency_s, self.perfect_odometry = latency_s, perfect_odometry
        self.time_limit_s = time_limit_s if time_limit_s is not None else spec.time_limit_s
        robot = cfg.robot
        self.local = None if robot.shape == "circle" else footprint_vertices(robot.front_m, robot.rear_m,
                                                                              robot.width_m)
        self.radius = robot.radius_m
        self.holonomic = robot.drive == "holonomic"
        self.mount = Pose2D(robot.laser_x_m, robot.laser_y_m, robot.laser_theta_rad)
        lc = cfg.laser
        self.laser = LaserModel(n_beams=lc.beams, fov_rad=math.radians(lc.fov_deg),
                                max_range_m=lc.max_range_m,
                                range_sigma_m=lc.noise_std_m, dropout_prob=lc.dropout_prob,
                                resolution_m=params.resolution_m)
        self.angles = self.laser.angles()
        self.angles.flags.writeable = False
        self.period_ns = round(lc.period_s * NS)
        self.dt_ns = round(params.dt_s * NS)
        # spawn(3)[:2] equal spawn(2): the slip stream leaves the laser and odometry draws as they are
        laser_seq, odom_seq, slip_seq = np.random.SeedSequence(seed).spawn(3)
        self.laser_rng = np.random.default_rng(laser_seq)
        self.odom_rng = np.random.default_rng(odom_seq)
        self.ideal_dynamics = ideal_dynamics
        self.slip = None if ideal_dynamics else SlipState(params.slip, np.random.default_rng(slip_seq))
        self.world = _World(spec)
        spec.check_endpoints(self.world, self.local, self.radius, params.contact_m)
        self.goal = spec.goal
        self.goal_tol = cfg.supervisor.goal_tolerance_m
        self._security_m = cfg.stack_params().reactor.security_m  # ND+'s Ds in force (robot-scaled)
        self.driver = None if spec.teleop is None or self.nav_mode != "teleop" else TeleopDriver(
            spec.teleop, wmax_radps=robot.wmax_radps, accel_mps2=robot.accel_mps2, tolerance_m=self.goal_tol)
        # state
        self.t_ns = 0
        self.pose = np.array(spec.start, dtype=np.float64)
        self.odom = self.pose.copy()
        self.bias = params.odometry.slip_bias_sigma_radps * float(self.odom_rng.standard_normal())
        self.vel = (0.0, 0.0, 0.0)
        self.cmd = (0.0, 0.0, 0.0)
        self.pending: tuple[tuple[float, float, float], int] | None = None
        self._got_command = True
        self.rec = SimRecord()
        self.outcome: str | None = None
        self.end_t_s: float | None = None
        self.contact: dict[str, Any] | None = None
        self._next_mover_record = 0.0
        self._prev_flags = Flag.NONE
        self._prev_taken = False
        self.goal_task = self.driver is None and self.nav_mode != "follow"  # the goal's tolerance decides
        # clearance bookkeeping: the last exact clearance and an upper bound of every closing speed, so
        # pieces far from everything skip the exact test (their clearance is above the security distance)
        reach = self.radius if self.local is None else float(np.max(np.hypot(*self.local.T)))
        leaf = max((e.leaf_speed((a.t0_s + a.t1_s) / 2.0) for e in spec.elements for a in e.door),
                   default=0.0)
        self._vmax = speed_bound(robot, reach, params.slip, ideal=ideal_dynamics) + leaf + max(
            (m.speed_mps for m in spec.movers), default=0.0)
        # (time ns, clearance m, the world's step key then)
        self._last_exact: tuple[int, float, tuple[Any, ...]] | None = None
        self._breaks = set(self.world.breaks_ns)
        self._optimal: OptimalPath | None = None
        self._static: Shapes | None = None

    # ---- the two halves of the loop -------------------------------------------------------------------

    def ticks(self) -> Iterator[Tick]:
        """Scan k, then (after ``on_tick`` got its command) the world advanced to scan k + 1, until the
        goal, a contact or the time limit."""
        t0 = time.perf_counter_ns()
        self._check_start()
        k = 0
        while True:
            if self.outcome is not None:
                return
            tick = self._tick(k)
            self.rec.sim_ns.append(time.perf_counter_ns() - t0)
            self._got_command = False
            yield tick
            t0 = time.perf_counter_ns()
            if not self._got_command:
                raise RuntimeError("ClosedLoop: the consumer pulled the next tick before calling on_tick")
            self._advance(self.t_ns + self.period_ns)
            k += 1

    def on_tick(self, r: TickResult) -> None:
        """The stack's command for the last tick: it takes effect after the latency."""
        cmd = (r.command.v_mps, r.command.vy_mps if self.holonomic else 0.0, r.command.w_radps)
        ms = sum(r.timings_ms.values())
        lat_s = ms / 1e3 if self.latency_s is None else self.latency_s
        self.pending = (cmd, self.t_ns + round(lat_s * NS))
        self._got_command = True
        rec = self.rec
        rec.cmd.append((r.t_ns, cmd[0], cmd[1], cmd[2]))
        rec.modes[r.mode.value] += 1
        # as commands.csv: the wall-clock budget flags only when they act (result.json is deterministic)
        for name in recorded_flags(r.flags, enforce_budgets=self.cfg.supervisor.enforce_budgets).names():
            rec.flags[name] += 1
        if r.flags & Flag.TRAP_DETECTED and not self._prev_flags & Flag.TRAP_DETECTED:
            rec.trap_count += 1
        if r.flags & Flag.GOAL_REACHED and rec.stack_goal_t_s is None:
            rec.stack_goal_t_s = self.t_ns / NS
        self._prev_flags = r.flags
        rec.stack_ms.append(ms)
        self._record_modes(r)
        self._check_goal_missed(r)

    def _check_goal_missed(self, r: TickResult) -> None:
        """End a goal run as ``goal_missed`` once the stack has reported GOAL_REACHED with the robot standing
        still for ``goal_settle_s`` (the true axle outside the tolerance, or the run would have succeeded)."""
        rec, now = self.rec, self.t_ns / NS
        if not (self.goal_task and self.outcome is None and r.flags & Flag.GOAL_REACHED
                and self.vel == (0.0, 0.0, 0.0)):
            rec.goal_stop_t_s = None
            return
        if rec.goal_stop_t_s is None:
            rec.goal_stop_t_s = now
        if now - rec.goal_stop_t_s >= self.params.goal_settle_s - 1e-9:
            self.outcome, self.end_t_s = "goal_missed", now

    def _record_modes(self, r: TickResult) -> None:
        """Count the tick's active mode, takeover onsets and their reasons, stretches of one active mode;
        a follow run ends once the stack reports the final subgoal reached (GOAL_REACHED, or the subgoal
        index past the last one)."""
        rec, now = self.rec, self.t_ns / NS
        rec.active_modes[r.active_mode] += 1
        taken = r.active_mode != r.desired_mode
        if taken and not self._prev_taken:
            rec.takeovers += 1
            rec.takeover_reasons[r.takeover_reason or "unspecified"] += 1
        self._prev_taken = taken
        if rec.mode_stretches and rec.mode_stretches[-1][0] == r.active_mode:
            rec.mode_stretches[-1][2] = now
        else:
            rec.mode_stretches.append([r.active_mode, now, now])
        rec.subgoal_index = r.subgoal_index
        n = len(self.spec.subgoals)
        if self.nav_mode == "follow" and self.outcome is None and (
                r.subgoal_index >= n or r.flags & Flag.GOAL_REACHED):
            self.outcome, self.end_t_s = "success", now

    # ---- internals ------------------------------------------------------------------------------------

    def _clearance(self, t_s: float, mover_xy: F64) -> Clearance:
        return footprint_clearance(self.pose, self.local, self.radius, self.world.shapes(t_s, mover_xy))

    def _check_start(self) -> None:
        c = self._clearance(0.0, self.world.mover_xy)
        self.rec.truth_t.append(0.0)
        self.rec.truth.append(tuple(float(v) for v in self.pose))  # type: ignore[arg-type]
        self._record_movers(0.0)
        if c.distance_m <= self.params.contact_m:
            self._end_contact(0.0, c, moving=False)

    def _tick(self, k: int) -> Tick:
        t_s = self.t_ns / NS
        shapes = self.world.shapes(t_s, self.world.mover_xy)
        lp = compose(self.pose, self.mount.as_array())
        exact = cast((float(lp[0]), float(lp[1])), self.angles + float(lp[2]), shapes, self.laser.max_range_m)
        ranges = add_laser_noise(exact, self.laser, self.laser_rng)
        t = self.params.t0_ns + self.t_ns
        scan = Scan(t, ranges, self.angles, self.laser.max_range_m, self.laser.min_range_m, self.mount)
        truth = Pose2D.from_array(self.pose)
        odom = truth if self.perfect_odometry else Pose2D.from_array(self.odom)
        rec = self.rec
        rec.scan_t_ns.append(t)
        rec.scan_ranges.append(ranges)
        rec.scan_truth.append((truth.x, truth.y, truth.theta))
        rec.scan_odom.append((odom.x, odom.y, odom.theta))
        v, vy, w = self.vel
        rec.scan_vel.append((v, vy, w))
        if self.driver is not None:  # the operator's command, as a log records it
            v, w = self.driver.command(t_s, self.pose)
            vy = 0.0
            rec.teleop_cmd.append((v, w))
        return Tick(index=k, t_ns=t, scan=scan, odom=odom, cmd=Command(t, v, w, vy), truth=truth)

    def _record_movers(self, t_s: float) -> None:
        if t_s + 1e-9 >= self._next_mover_record:
            self.rec.movers_t.append(t_s)
            self.rec.movers_xy.append([(float(x), float(y)) for x, y in self.world.mover_xy])
            self._next_mover_record += 1.0

    def _end_contact(self, t_s: float, c: Clearance, *, moving: bool) -> None:
        ids = self.spec.element_ids()
        inv = relative(self.pose, np.array([c.on_robot[0], c.on_robot[1], 0.0]))
        obj = ids[c.element] if c.element >= 0 else None
        n = len(self.spec.elements)
        dynamic = c.element >= n or (0 <= c.element < n and bool(self.spec.elements[c.element].door))
        self.outcome = "collision"
        self.end_t_s = t_s
        self.contact = {
            "t_s": t_s,
            "object": obj,
            "contact_world": [c.on_robot[0], c.on_robot[1]],
            "contact_robot": [float(inv[0]), float(inv[1])],
            "robot_moving": moving,
            "hit_by_mover": (not moving) and dynamic,
        }

    def _mover_targets(self, h: float, t_s: float) -> F64:
        """Where each mover will be after ``h`` s (it waits when yielding)."""
        w = self.world
        new = w.mover_xy.copy()
        for j, m in enumerate(w.movers):
            if t_s + 1e-12 < m.start_at_s or m.speed_mps <= 0.0:
                continue
            s1 = w.mover_s[j] + m.speed_mps * h
            x, y = m.position(s1)
            if m.yield_m > 0.0 and self._would_crowd(m.radius_m, m.yield_m, w.mover_xy[j], (x, y)):
                continue
            new[j] = (x, y)
            w.mover_s[j] = s1
        return new

    def _would_crowd(self, radius: float, yield_m: float, old: F64, new: tuple[float, float]) -> bool:
        body = self.radius if self.local is None else float(np.max(np.hypot(*self.local.T)))
        reach = radius + yield_m + body
        if math.hypot(new[0] - self.pose[0], new[1] - self.pose[1]) > reach + 1e-9:
            return False
        solo_new = Shapes.circle(new[0], new[1], radius)
        solo_old = Shapes.circle(float(old[0]), float(old[1]), radius)
        d_new = footprint_clearance(self.pose, self.local, self.radius, solo_new).distance_m
        d_old = footprint_clearance(self.pose, self.local, self.radius, solo_old).distance_m
        return d_new < yield_m and d_new < d_old

    def _hold_doors(self, t_s: float, h: float) -> None:
        """A door leaf whose next step would bring it closer than ``DEFAULT_YIELD_M`` to the footprint
        (and closer than it is) waits for this piece, as the person moving it would."""
        w = self.world
        for i in w.moving_doors(t_s):
            e = w.elements[i]
            d = []
            for tt in (t_s, t_s + h):
                v = e.outline_at(t_s, tt - w.door_delay[i])
                d.append(math.inf if v is None else footprint_clearance(
                    self.pose, self.local, self.radius, Shapes.build([v], [0], [], [])).distance_m)
            if d[1] < DEFAULT_YIELD_M and d[1] < d[0]:
                w.door_delay[i] += h

    def _advance(self, t_end_ns: int) -> None:
        """Move the world and the robot to ``t_end_ns`` (or to the end of the run)."""
        p, rob = self.params, self.cfg.robot
        limit_ns = round(self.time_limit_s * NS)
        while self.t_ns < t_end_ns and self.outcome is None:
            if self.pending is not None and self.t_ns >= self.pending[1]:
                self.cmd, self.pending = self.pending[0], None
            t1 = min(t_end_ns, (self.t_ns // self.dt_ns + 1) * self.dt_ns, limit_ns)
            if self.pending is not None:
                t1 = min(t1, max(self.pending[1], self.t_ns + 1))
            b = self.world.next_break(self.t_ns)
            if b is not None:
                t1 = min(t1, b)
            h = (t1 - self.t_ns) / NS
            t_s = self.t_ns / NS
            # the wheels: toward the (limited) command; the body: the wheels' twist with slip
            cv, cvy, cw = self.cmd
            cw = max(-rob.wmax_radps, min(rob.wmax_radps, cw))
            if self.holonomic:
                sp = math.hypot(cv, cvy)
                if sp > rob.vmax_mps:
                    cv, cvy = cv * rob.vmax_mps / sp, cvy * rob.vmax_mps / sp
            else:
                cv = max(-rob.vmax_mps, min(rob.vmax_mps, cv))
            self.vel = next_velocity(self.vel, (cv, cvy, cw), h, rob, holonomic=self.holonomic,
                                     ideal=self.ideal_dynamics)
            if self.slip is None:
                vx, vy, w = self.vel
            else:
                self.slip.advance(h)
                vx, vy, w = self.slip.executed(*self.vel)
            self._hold_doors(t_s, h)
            # movers: from their positions now to their targets at t1, linearly
            start_xy = self.world.mover_xy.copy()
            end_xy = self._mover_targets(h, t_s)
            mover_speed = float(np.max(np.hypot(*(end_xy - start_xy).T)) / h) if len(start_xy) else 0.0
            world_speed = mover_speed + self.world.leaf_speed(t_s)
            robot_speed = max_point_speed(self.local, vx, vy, w)
            bound = robot_speed + world_speed
            moving = robot_speed > 0.0
            start_pose = self.pose
            tau, it = 0.0, 0
            key = self.world.step_key(t_s)
            if self.t_ns in self._breaks or (self._last_exact is not None and (
                    self._last_exact[2] != key or self.world.step_key((t1 - 1) / NS) != key)):
                self._last_exact = None  # the world changed by a step: the old clearance bounds nothing
            sec = self._security_m
            if self._last_exact is not None:
                lb = self._last_exact[1] - self._vmax * (t1 - self._last_exact[0]) / NS
                if lb > sec and world_speed <= self._vmax:
                    self.rec.clearance.append((h, lb))
                    self.pose = arc_step(self.pose, vx, vy, w, h)
                    tau = h
            while tau < h:
                f = tau / h
                xy = start_xy + (end_xy - start_xy) * f
                self.world.mover_xy = xy
                c = self._clearance(t_s + tau, xy)
                self._last_exact = (self.t_ns + round(tau * NS), c.distance_m, key)
                if it == 0:
                    self.rec.clearance.append((h, c.distance_m))
                    self.rec.min_clearance_m = min(self.rec.min_clearance_m, c.distance_m)
                if c.distance_m <= p.contact_m or it >= p.max_iterations:
                    self.rec.min_clearance_m = min(self.rec.min_clearance_m, c.distance_m)
                    self._end_contact(t_s + tau, c, moving=moving)
                    break
                step = h - tau if bound <= 0.0 else min(h - tau, c.distance_m / bound)
                self.pose = arc_step(self.pose, vx, vy, w, step)
                tau = h if step >= h - tau else tau + step
                it += 1
            self.world.mover_xy = end_xy if self.outcome is None else self.world.mover_xy
            # wheel odometry follows the wheels: with slip, their arc from the piece's start, not the body's
            wheels = self.pose if self.slip is None else arc_step(start_pose, *self.vel, tau)
            self._odometry(start_pose, wheels, tau)
            self.t_ns = t1 if self.outcome is None else self.t_ns + round(tau * NS)
            now = self.t_ns / NS
            self.rec.truth_t.append(now)
            self.rec.truth.append((float(self.pose[0]), float(self.pose[1]), float(self.pose[2])))
            self._record_movers(now)
            if self.outcome is not None:
                break
            if self._arrived(now):
                self.outcome, self.end_t_s = "success", now
            elif self.t_ns >= limit_ns:
                self.outcome, self.end_t_s = "timeout", now

    def _arrived(self, now: float) -> bool:
        """The run's task is done at ``now`` (a follow run's end is the stack's report, see on_tick)."""
        if self.driver is not None:
            return self.driver.ended(now, self.pose)
        if self.nav_mode == "follow":
            return False
        return math.hypot(self.pose[0] - self.goal[0], self.pose[1] - self.goal[1]) <= self.goal_tol

    def _odometry(self, a: F64, b: F64, h: float) -> None:
        """Wheel odometry over one piece: the true increment split into wheel travels, corrupted, recombined
        with the (wrong) wheel base, plus the Gauss-Markov heading-rate bias (as ``corrupt_odometry``), and
        the lateral travel of a holonomic base with the same relative error and noise."""
        if h <= 0.0:
            return
        n = self.params.odometry
        z = self.odom_rng.standard_normal(4)
        ea = dm.exp(-h / n.slip_bias_tau_s)
        self.bias = ea * self.bias + n.slip_bias_sigma_radps * math.sqrt(1.0 - ea * ea) * float(z[3])
        dth = _wrap(b[2] - a[2])
        mid = a[2] + dth / 2.0
        dx, dy = b[0] - a[0], b[1] - a[1]
        ds = dx * dm.cos(mid) + dy * dm.sin(mid)
        dn = -dx * dm.sin(mid) + dy * dm.cos(mid)
        wb = n.wheelbase_m
        dl, dr = ds - dth * wb / 2.0, ds + dth * wb / 2.0
        k = n.wheel_sigma_m_per_sqrt_m
        dl_m = dl * (1.0 + n.left_scale) + k * math.sqrt(abs(dl)) * float(z[0])
        dr_m = dr * (1.0 + n.right_scale) + k * math.sqrt(abs(dr)) * float(z[1])
        dn_m = dn * (1.0 + n.left_scale) + k * math.sqrt(abs(dn)) * float(z[2])
        moving = abs(dl) + abs(dr) + abs(dn) > 1e-9
        ds_o = (dl_m + dr_m) / 2.0
        dth_o = (dr_m - dl_m) / (wb * (1.0 + n.wheelbase_scale)) + (self.bias * h if moving else 0.0)
        mid_o = self.odom[2] + dth_o / 2.0
        c, s = dm.cos(mid_o), dm.sin(mid_o)
        self.odom = np.array([self.odom[0] + ds_o * c - dn_m * s, self.odom[1] + ds_o * s + dn_m * c,
                              _wrap(self.odom[2] + dth_o)])

    # ---- the result ---------------------------------------------------------------------------------

    def optimal_path(self) -> OptimalPath:
        """The shortest path of the robot's inscribed circle from the start to the goal in the static world
        at t = 0 (:mod:`.score`; computed once)."""
        if self._optimal is None:
            self._optimal = optimal_path(self._static_world(), (self.spec.start[0], self.spec.start[1]),
                                         self.goal, self.cfg.robot.inscribed_radius_m)
        return self._optimal

    def narrowest_passage(self) -> tuple[float | None, str | None]:
        """The narrowest passage on the widest way from the start to the goal in the static world at t = 0
        (:func:`.score.narrowest_passage_m`), and a warning when it is narrower than the robot plus the
        reflexive check's margin on each side (no robot with those margins crosses it, whatever the stack
        does)."""
        width = narrowest_passage_m(self._static_world(), (self.spec.start[0], self.spec.start[1]), self.goal)
        body = 2.0 * self.cfg.robot.inner_radius_m  # a rectangle's width, a circle's diameter
        need = body + 2.0 * self.cfg.supervisor.emergency_margin_m
        if width is None or width >= need:
            return width, None
        return width, (f"the narrowest passage on the way to the goal is {width:.2f} m wide (to about "
                       f"{CELL_M:g} m): the robot is {body:.2f} m wide and keeps "
                       f"{self.cfg.supervisor.emergency_margin_m:g} m on each side, so it needs {need:.2f} m")

    def _static_world(self) -> Shapes:
        """The static world at t = 0: every element present then, door leaves as they stand, no mover
        (built once: the optimal path and the narrowest passage both read it)."""
        if self._static is None:
            self._static = static_shapes(self.spec.elements, 0.0, np.zeros(len(self.spec.elements)))
        return self._static

    def result(self) -> dict[str, Any]:
        """result.json: a pure function of (scenario, config, seed) with a fixed latency.

        Fields: ``outcome`` success (the task done, see the module docstring: by default the true axle
        within the supervisor's goal tolerance of the goal) / collision / goal_missed (the stack reported
        GOAL_REACHED and stopped, the true axle outside the tolerance: ``goal_missed`` holds
        ``stack_goal_reached_s``, ``stopped_s``, ``true_distance_m`` and ``tolerance_m``, else None) /
        timeout; ``end_time_s``;
        ``time_to_goal_s``; ``collision``: ``t_s``, ``object`` (the
        element's or mover's id), ``contact_world`` and ``contact_robot`` (the touching point of the
        footprint, world and robot frame), ``robot_moving``, ``hit_by_mover`` (the robot stood still and
        a mover or door leaf moved into it); ``path_length_m`` (true); ``min_clearance_m`` (footprint to
        any element, exact below the security distance); ``time_inside_security_pct`` (time with the
        clearance below ``reactor.security_m``); ``mean_abs_dw_dt_radps2`` (commanded turn rate changes
        per second); ``longest_stall_s`` (see :func:`longest_stall`); ``modes`` and ``flags`` (ticks per
        name); ``trap_count`` (TRAP_DETECTED onsets); ``stack_goal_reached_s`` (first GOAL_REACHED tick,
        the stack's own belief); ``ticks``; start, goal, final pose and distance to the goal;
        ``navigation``: the desired ``mode``, ``selector``, ``local`` strategy, ``active_modes`` (ticks per
        active mode), ``takeovers`` (onsets of an active mode other than the desired one) and their
        ``takeover_reasons``, ``mode_stretches`` ([active mode, first tick s, last tick s] in order),
        ``subgoals`` (how many) and the last ``subgoal_index``; ``teleop`` (script / track / None);
        ``ideal_dynamics``; the challenge score (:mod:`.score`): ``optimal_path_m`` (the inscribed circle's
        shortest path from the start to the goal in the static world at t = 0; None when there is none),
        ``optimal_time_s`` (OT: that at 2 m/s) and ``challenge_metric`` (success * OT / clip(time to goal,
        2 OT, 8 OT); None without an optimal path), ``narrowest_passage_m`` (the narrowest passage on the
        widest way to the goal, :func:`.score.narrowest_passage_m`; None without a way) and
        ``passage_warning`` (a line when it is narrower than the robot plus the reflexive check's margins,
        else None); ``world_warnings``: what the world's map or SDF files held that the simulator skipped
        (one line per file).
        """
        rec = self.rec
        truth = np.asarray(rec.truth, dtype=np.float64).reshape(-1, 3)
        tt = np.asarray(rec.truth_t, dtype=np.float64)
        path = float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))) if len(truth) > 1 else 0.0
        clear = np.asarray(rec.clearance, dtype=np.float64).reshape(-1, 2)
        sec = self._security_m
        total = float(clear[:, 0].sum())
        inside = float(clear[clear[:, 1] < sec, 0].sum())
        cmd = np.asarray(rec.cmd, dtype=np.float64).reshape(-1, 4)
        dwdt = (float(np.mean(np.abs(np.diff(cmd[:, 3])) / (np.diff(cmd[:, 0]) / NS)))
                if len(cmd) > 1 else 0.0)
        end = truth[-1]
        best = self.optimal_path().length_m
        ot = None if best is None else optimal_time_s(best)
        passage, passage_warning = self.narrowest_passage()
        return {
            "scenario": self.spec.name,
            "source": self.spec.source,
            "preset": self.cfg.preset,
            "seed": self.seed,
            "latency_s": "measured" if self.latency_s is None else self.latency_s,
            "perfect_odometry": self.perfect_odometry,
            "outcome": self.outcome,
            "end_time_s": self.end_t_s,
            "time_limit_s": self.time_limit_s,
            "time_to_goal_s": self.end_t_s if self.outcome == "success" else None,
            "collision": self.contact,
            "goal_missed": None if self.outcome != "goal_missed" else {
                "stack_goal_reached_s": rec.stack_goal_t_s,
                "stopped_s": rec.goal_stop_t_s,
                "true_distance_m": math.hypot(end[0] - self.goal[0], end[1] - self.goal[1]),
                "tolerance_m": self.goal_tol,
            },
            "path_length_m": path,
            "min_clearance_m": None if not math.isfinite(rec.min_clearance_m) else rec.min_clearance_m,
            "security_distance_m": sec,
            "time_inside_security_pct": 100.0 * inside / total if total > 0 else 0.0,
            "mean_abs_dw_dt_radps2": dwdt,
            "longest_stall_s": longest_stall(tt, truth),
            "modes": dict(sorted(rec.modes.items())),
            "flags": dict(sorted(rec.flags.items())),
            "trap_count": rec.trap_count,
            "stack_goal_reached_s": rec.stack_goal_t_s,
            "ticks": len(rec.cmd),
            "start": list(self.spec.start),
            "goal": list(self.spec.goal),
            "final_pose": [float(v) for v in end],
            "final_goal_distance_m": math.hypot(end[0] - self.goal[0], end[1] - self.goal[1]),
            "active_modes": dict(sorted(rec.active_modes.items())),
            "takeovers": rec.takeovers,
            "navigation": {
                "mode": self.nav_mode,
                "selector": self.cfg.navigation.selector,
                "local": self.cfg.navigation.local.strategy,
                "teleop": None if self.driver is None else self.driver.spec.kind,
                "takeover_reasons": dict(sorted(rec.takeover_reasons.items())),
                "mode_stretches": [[m, round(a, 9), round(b, 9)] for m, a, b in rec.mode_stretches],
                "subgoals": len(self.spec.subgoals),
                "subgoal_index": rec.subgoal_index,
            },
            "ideal_dynamics": self.ideal_dynamics,
            "optimal_path_m": best,
            "optimal_time_s": ot,
            "challenge_metric": None if ot is None else challenge_metric(
                self.outcome == "success", self.end_t_s, ot),
            "narrowest_passage_m": passage,
            "passage_warning": passage_warning,
            "world_warnings": list(self.spec.world_warnings),
        }


def longest_stall(t_s: F64, poses: F64, *, move_m: float = 0.2, turn_rad: float = math.pi / 4,
                  every_s: float = 0.1) -> float:
    """Longest stretch [s] in which the robot neither moved ``move_m`` away nor turned ``turn_rad`` net
    from where it was at the stretch's start (sampled every ``every_s``; the run's end closes a stretch)."""
    if len(t_s) < 2:
        return 0.0
    grid = np.arange(t_s[0], t_s[-1] + 1e-9, every_s)
    idx = np.clip(np.searchsorted(t_s, grid), 0, len(t_s) - 1)
    xy = poses[idx, :2]
    th = np.unwrap(poses[:, 2])[idx]
    n = len(grid)
    best = 0.0
    for lo in range(0, n, 256):
        rows = np.arange(lo, min(lo + 256, n))
        dist = np.hypot(xy[None, :, 0] - xy[rows, None, 0], xy[None, :, 1] - xy[rows, None, 1])
        moved = (dist >= move_m) | (np.abs(th[None, :] - th[rows, None]) >= turn_rad)
        later = np.arange(n)[None, :] > rows[:, None]
        hit = moved & later
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), n - 1)
        best = max(best, float(np.max(grid[first] - grid[rows])))
    return best
