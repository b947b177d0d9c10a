"""NavigationStack: one synchronous model -> planner -> reactor cycle per scan, under the supervisor.

Scan matching runs one step ahead of the stack (in ``gndreplay.replay``) because the default goal of a
replay is a pose further along the log's own *corrected* trajectory; the stack receives the corrected
pose with the tick and never looks at the future. It owns the per-module timers.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..geometry import transform_points, wrap_angle
from ..robot import RobotConfig
from ..types import Flag, Pose2D, Scan, Tick
from .cspace import free_cspace
from .follow import FollowParams
from .local import LocalParams
from .model import UNKNOWN, GridParams, RobotCentredGrid
from .nd import NdParams, Situation, nd_step
from .nf1 import Nf1Params, Nf1Planner, Planner, PlanResult, reaches_border
from .supervisor import (
    Mode,
    SafeCommand,
    SupervisorParams,
    TrapDetector,
    budget_flags,
    escape_command,
    gnd_mode,
    rotate_command,
    safe_command,
    safety_reach_m,
)
from .tunnel import TunnelParams, TunnelPlanner, warm_up_planners

__all__ = [
    "MODULES", "NAV_MODES", "PLANNERS", "NavMode", "NavigationStack", "StackParams", "TickResult",
    "make_planner", "warm_up",
]

MODULES = ("match", "model", "planner", "reactor")

PLANNERS = ("nf1", "tunnel")
"""Planner kinds ``make_planner`` builds."""

NavMode = Literal["gnd", "teleop", "follow", "local"]
NAV_MODES: tuple[str, ...] = ("gnd", "teleop", "follow", "local")
"""Navigation modes: GND to the goal (the default), the log's or script's teleoperation, path following of
subgoals, local navigation alone."""


@dataclass(frozen=True, slots=True)
class StackParams:
    """Everything the stack needs, one frozen section per stage (see ``gndreplay.config``).

    ``planner_kind`` chooses the planner ("nf1": ``planner`` settings and the [cspace] margin; "tunnel":
    ``tunnel`` settings, its own margin); ``planner.lookahead_m`` places the reactor's target for both.
    """

    robot: RobotConfig
    grid: GridParams
    planner: Nf1Params
    reactor: NdParams
    supervisor: SupervisorParams
    cspace_margin_m: float = 0.05
    unknown_is_free: bool = True
    planner_kind: Literal["nf1", "tunnel"] = "nf1"
    tunnel: TunnelParams = TunnelParams()
    nav_mode: NavMode = "gnd"
    selector: bool = True
    local: LocalParams = LocalParams()
    follow: FollowParams = FollowParams()


@dataclass(frozen=True, slots=True, eq=False)
class TickResult:
    """What the stack decided at one tick, and why, and how long each part took.

    Attributes:
        t_ns: the scan's time.
        pose_corrected: robot pose after scan matching (corrected odometry frame).
        v_mps, vy_mps, w_radps: the command (vy only for a holonomic base).
        mode: GND mode or reflexive override that produced the command.
        situation: the ND+ situation (Situation.NONE without a region).
        flags: exception flags raised this tick.
        direction_rad: ND+ motion direction in the robot frame (nan without a region).
        goal: the goal in the corrected frame.
        path_xy: (K, 2) tightened planned path in the corrected frame (empty when the planner failed).
        timings_ms: per-module wall time [ms] ("match", "model", "planner", "reactor").
        planner_nodes: the planner's search effort this tick (NF1: cells the wave labelled; tunnel: nodes
            expanded), also when it failed.
        planner_length_m: length of the planned path / tunnel polyline [m] (nan when the planner failed).
        tunnel_width_m: width of the tunnel (nan for NF1 or when the planner failed).
        desired_mode: the navigation mode asked for ("gnd", "teleop", "follow", "local").
        active_mode: the mode whose command won this tick (the mode selector's choice).
        takeover_reason: why the active mode is not the desired one ("" when it is).
        subgoal_index: the path follower's current subgoal (-1 outside path following).
    """

    t_ns: int
    pose_corrected: Pose2D
    v_mps: float
    vy_mps: float
    w_radps: float
    mode: Mode
    situation: Situation
    flags: Flag
    direction_rad: float
    goal: tuple[float, float]
    path_xy: NDArray[np.float64] = field(repr=False)
    timings_ms: dict[str, float] = field(default_factory=dict)
    planner_nodes: int = 0
    planner_length_m: float = math.nan
    tunnel_width_m: float = math.nan
    desired_mode: str = "gnd"
    active_mode: str = "gnd"
    takeover_reason: str = ""
    subgoal_index: int = -1


def make_planner(params: StackParams) -> Planner:
    """The planner ``params.planner_kind`` names, built with its own settings and the grid geometry."""
    p = params
    if p.planner_kind == "tunnel":
        return TunnelPlanner(
            p.tunnel, cell_m=p.grid.cell_m, inner_radius_m=p.robot.inner_radius_m,
            unknown_is_free=p.unknown_is_free,
        )
    if p.planner_kind == "nf1":
        return Nf1Planner(
            p.planner, cell_m=p.grid.cell_m, inflate_m=p.robot.inner_radius_m + p.cspace_margin_m,
            unknown_is_free=p.unknown_is_free,
        )
    raise ValueError(f"unknown planner kind {p.planner_kind!r}; known: {', '.join(PLANNERS)}")


def _ms(t0: int) -> float:
    return (time.perf_counter_ns() - t0) / 1e6


def _to_robot(pose: Pose2D, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """World points (K, 2) into the robot frame of ``pose``."""
    return transform_points(pose.inverse().as_array(), xy)


class NavigationStack:
    """Holds the state carried between ticks: the robot-centred grid, the previous scan time, the trap
    detector and an escape in progress. ``step`` runs one full cycle and always returns one command."""

    def __init__(self, params: StackParams) -> None:
        self.params = params
        self.grid = RobotCentredGrid(params.grid)
        self._planner = make_planner(params)
        self._trap = TrapDetector(params.supervisor, params.robot.wmax_radps)
        self._escape_left = 0
        self._escape_v = 0.0
        self._prev_t_ns: int | None = None
        self._no_path = 0  # consecutive PLANNER_NO_PATH ticks
        self._looked_rad = 0.0  # turned in place since the goal was held unreachable
        self._prev_theta: float | None = None
        self._rotate_sign = 0.0  # turn direction of the previous tick's ROTATE (0: not rotating)

    def step(self, tick: Tick, pose: Pose2D, goal_xy: tuple[float, float], match_ms: float = 0.0,
             match_failed: bool = False) -> TickResult:
        """One cycle: model -> planner -> reactor -> supervisor, for the tick's scan at ``pose``."""
        p = self.params
        flags = Flag.MATCH_FAILED if match_failed else Flag.NONE
        timings = {"match": match_ms}

        t0 = time.perf_counter_ns()
        self.grid.integrate(tick.scan, pose)
        timings["model"] = _ms(t0)

        t0 = time.perf_counter_ns()
        goal = np.asarray(goal_xy, dtype=np.float64)
        planned = self._plan(pose, goal)
        timings["planner"] = _ms(t0)

        t0 = time.perf_counter_ns()
        target = self._reactor_target(pose, goal, planned)
        obstacles = self.grid.occupied_points(pose, p.reactor.max_range_m)
        nd = nd_step(obstacles, target, p.robot, p.reactor)
        timings["reactor"] = _ms(t0)

        over = budget_flags({k: v / 1e3 for k, v in timings.items()}, p.supervisor)
        flags |= over
        planner_ok = planned.ok
        if p.supervisor.enforce_budgets and over & Flag.PLANNER_OVER_BUDGET:
            planner_ok = False
            flags |= Flag.PLANNER_TIMEOUT
        if not planned.ok:
            flags |= planned.flag
        if nd.flag:
            flags |= nd.flag

        mode = gnd_mode(planner_ok, not (nd.flag & Flag.REACTOR_NO_REGION))
        if mode is Mode.MND and planned.ok:  # enforced planner time-out: steer to the goal itself
            target = _to_robot(pose, goal[None, :])[0]
            nd = nd_step(obstacles, target, p.robot, p.reactor)
        v, vy, w = nd.v_mps, nd.vy_mps, nd.w_radps
        goal_rel = _to_robot(pose, goal[None, :])[0]
        unreachable = self._unreachable(planned, pose)
        if unreachable:
            mode = Mode.ROTATE
        if mode is Mode.ROTATE:
            v, vy, w = 0.0, 0.0, self._rotate_w(goal_rel)
            if unreachable and self._looked_rad >= 2.0 * math.pi:
                w = 0.0
        if p.supervisor.enforce_budgets and over & Flag.REACTOR_OVER_BUDGET:
            v, vy, w = 0.0, 0.0, 0.0
        if math.hypot(goal_rel[0], goal_rel[1]) <= p.supervisor.goal_tolerance_m:
            mode, v, vy, w = Mode.GOAL, 0.0, 0.0, 0.0
            flags |= Flag.GOAL_REACHED

        rotating = mode is Mode.ROTATE
        mode, v, vy, w, flags = self._reflexive(tick, pose, mode, v, vy, w, flags, unreachable)
        self._rotate_sign = (1.0 if w > 0.0 else -1.0) if rotating and w != 0.0 else 0.0
        path = planned.waypoints_cells
        path_xy = self.grid.cells_to_world(path) if path.shape[0] else np.zeros((0, 2))
        return TickResult(
            t_ns=tick.t_ns,
            pose_corrected=pose,
            v_mps=_finite(v),
            vy_mps=_finite(vy),
            w_radps=_finite(w),
            mode=mode,
            situation=nd.situation,
            flags=flags,
            direction_rad=nd.direction_rad,
            goal=(float(goal[0]), float(goal[1])),
            path_xy=path_xy,
            timings_ms=timings,
            planner_nodes=planned.nodes_expanded,
            planner_length_m=planned.length_m,
            tunnel_width_m=planned.width_m if planned.ok else math.nan,
        )

    def _rotate_w(self, goal_rel: NDArray[np.float64]) -> float:
        """ROTATE's turn rate. The direction is chosen towards the goal when ROTATE starts and kept while
        it lasts (the turn actually executed, also when the safety check reversed it): choosing it afresh
        every tick flips it each time the goal bearing crosses 0 or +-pi, a turn that never turns."""
        p = self.params
        w = rotate_command(math.atan2(goal_rel[1], goal_rel[0]), p.robot, p.supervisor)
        return abs(w) * self._rotate_sign if self._rotate_sign else w

    def _unreachable(self, planned: PlanResult, pose: Pose2D) -> bool:
        """True once the planner has found no path (PLANNER_NO_PATH) to a goal inside the grid for
        unreachable_ticks in a row: the goal is held unreachable (GND: mND did not connect it either;
        ROTATE, one full turn, then stop). Any plan ends it. A goal beyond the grid only when the robot
        cannot reach the grid border at all: no path to the goal's border cell alone says nothing about
        the goal (GND's mND goes on). Tracks how far the robot turned since, from the corrected pose."""
        prev, self._prev_theta = self._prev_theta, pose.theta
        if planned.ok or not planned.flag & Flag.PLANNER_NO_PATH or (
            planned.goal_projected and self._reaches_border(pose)
        ):
            self._no_path, self._looked_rad = 0, 0.0
            return False
        self._no_path += 1
        if self._no_path <= self.params.supervisor.unreachable_ticks:
            return False
        if prev is not None and self._no_path > self.params.supervisor.unreachable_ticks + 1:
            self._looked_rad += abs(math.remainder(pose.theta - prev, math.tau))
        return True

    def _reaches_border(self, pose: Pose2D) -> bool:
        """The robot's free region in the NF1 C-space of the grid touches the grid border (only asked on
        ticks without a path to a goal beyond the grid)."""
        p = self.params
        free = free_cspace(self.grid.cells, cell_m=p.grid.cell_m, inflate_m=p.robot.inner_radius_m
                           + p.cspace_margin_m, unknown_is_free=p.unknown_is_free)
        return reaches_border(free, self.grid.robot_cell(pose))

    def _plan(self, pose: Pose2D, goal: NDArray[np.float64]) -> PlanResult:
        start = self.grid.robot_cell(pose)
        goal_rc = self.grid.world_to_cell_float(goal[None, :])[0]
        return self._planner.plan(self.grid.cells, start, goal_rc)

    def _reactor_target(
        self, pose: Pose2D, goal: NDArray[np.float64], planned: PlanResult
    ) -> NDArray[np.float64]:
        """mpND: a point lookahead_m along the instantaneous path direction; mND: the goal itself."""
        if planned.ok and math.isfinite(planned.direction_rad):
            bearing = float(wrap_angle(planned.direction_rad - pose.theta))
            d = self.params.planner.lookahead_m
            return np.array([d * math.cos(bearing), d * math.sin(bearing)])
        return _to_robot(pose, goal[None, :])[0]

    def _reflexive(
        self, tick: Tick, pose: Pose2D, mode: Mode, v: float, vy: float, w: float, flags: Flag,
        unreachable: bool = False,
    ) -> tuple[Mode, float, float, float, Flag]:
        """The reflexive loop: stale data, a command whose swept footprint would touch an obstacle of the
        raw scan or the grid (replaced by ``safe_command``'s rule, recorded as the mode), trap escape.

        With the goal held unreachable the robot only looks around: a turn the check slows down is kept,
        one it would reverse or replace stops the robot for good (ROTATE at rest: no way, stay still),
        and there is no trap escape (standing still is the intended behaviour, not a trap)."""
        p = self.params
        prev, self._prev_t_ns = self._prev_t_ns, tick.t_ns
        if prev is not None and (tick.t_ns - prev) / 1e9 > p.supervisor.stale_scan_s:
            return Mode.STALE, 0.0, 0.0, 0.0, flags | Flag.STALE_SCAN
        raw = transform_points(tick.scan.sensor_pose.as_array(), tick.scan.points())
        cell_m = p.grid.cell_m
        reach = safety_reach_m(p.robot, p.supervisor, cell_m)
        near = raw[np.hypot(raw[:, 0], raw[:, 1]) <= reach]
        grid_xy = self.grid.occupied_points(pose, reach)
        unknown_xy = partial(self.grid.cell_points, pose, reach, UNKNOWN)

        def check(v: float, vy: float, w: float) -> SafeCommand:
            return safe_command(v, vy, w, near, grid_xy, p.robot, p.supervisor, cell_m=cell_m,
                                unknown_xy=unknown_xy)

        if self._escape_left > 0:
            self._escape_left -= 1
            if check(self._escape_v, 0.0, 0.0).rule is None:
                return Mode.ESCAPE, self._escape_v, 0.0, 0.0, flags
            self._escape_left = 0
        if mode is not Mode.GOAL:
            safe = check(v, vy, w)
            if unreachable and safe.rule not in (None, Mode.SAFE_SLOW):
                self._looked_rad = 2.0 * math.pi
                return Mode.ROTATE, 0.0, 0.0, 0.0, flags
            if safe.rule is not None:
                mode, v, vy, w = safe.rule, safe.v_mps, safe.vy_mps, safe.w_radps
                if safe.rule is Mode.EMERGENCY:
                    flags |= Flag.EMERGENCY_STOP
        if self._trap.update(mode, w, (pose.x, pose.y, pose.theta)) and not unreachable:
            flags |= Flag.TRAP_DETECTED
            v_esc, possible = escape_command(raw, p.robot, p.supervisor)
            if possible and check(v_esc, 0.0, 0.0).rule is None:
                self._escape_left, self._escape_v = p.supervisor.escape_ticks - 1, v_esc
                return Mode.ESCAPE, v_esc, 0.0, 0.0, flags
        return mode, v, vy, w, flags


def warm_up(params: StackParams) -> None:
    """Run a throwaway stack on synthetic scans so numba compiles (or loads) every kernel before the
    first timed tick; otherwise tick 0 would report hundreds of milliseconds of JIT as model time.

    Readers may hand out read-only arrays (shared beam angles, buffers decoded in place), which numba
    compiles as a separate specialisation, so every writable/read-only combination is exercised."""
    stack = NavigationStack(params)
    k = 0
    for ro_ranges in (False, True):
        for ro_angles in (False, True):
            angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
            ranges = np.where(np.arange(angles.size) % 7 == 0, np.inf, 3.0)
            ranges.flags.writeable = not ro_ranges
            angles.flags.writeable = not ro_angles
            scan = Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=8.0)
            for goal in ((2.0, 0.5), (-5.0, 0.0), (30.0, 30.0)):
                pose = Pose2D(0.05 * k, 0.0, 0.0)
                stack.step(Tick(index=k, t_ns=k, scan=scan, odom=pose), pose, goal)
                k += 1
    # an obstacle closer than the robot's inner radius: the robot cell is not free, so the planner escapes
    # along a straight line of cells to the nearest reachable one (nf1's escape kernels)
    stack = NavigationStack(params)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    close = np.where(np.abs(angles) < 0.3, 0.6 * params.robot.inner_radius_m, 3.0)
    scan = Scan(t_ns=k, ranges_m=close, angles_rad=angles, max_range_m=8.0)
    for goal in ((3.0, 0.0), (-3.0, 0.5)):
        pose = Pose2D(0.0, 0.0, 0.0)
        stack.step(Tick(index=k, t_ns=k, scan=scan, odom=pose), pose, goal)
        k += 1
    if params.planner_kind == "tunnel":  # its search kernels, on cases the synthetic scans above may miss
        warm_up_planners(params.tunnel)


def _finite(x: float) -> float:
    """No NaN ever leaves the stack: a non-finite command component becomes 0 (stop)."""
    return float(x) if math.isfinite(x) else 0.0

