"""NavigationStack: one synchronous model -> planner -> reactor cycle per scan, under the supervisor; or, in
the multi-loop paper's modes (teleop, follow, local), the desired module -> mode selector -> reflexive loop.

Scan matching runs one step ahead of the stack (in ``gndreplay.replay``) because the default goal of a
replay is a pose further along the log's own *corrected* trajectory; the stack receives the corrected
pose with the scan and never looks at the future. It owns the per-module timers and sequences the stages;
the supervisor (``supervision.Supervisor``) owns the state of GND's rules and of the reflexive loop.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from ..errors import FOLLOW_NEEDS_SUBGOALS, ConfigError
from ..geometry import wrap_angle
from ..robot import RobotConfig
from ..types import Command, Flag, Mode, Pose2D, Scan, Subgoal
from .cspace import free_cspace
from .follow import FollowParams, PathFollower
from .local import STRATEGIES, LocalParams, warm_up_local
from .manoeuvre import warm_up_manoeuvre
from .model import GridParams, RobotCentredGrid
from .nd import NdMemory, NdParams, NdResult, Situation, nd_step
from .nf1 import reaches_border
from .planner import AvoidMarks, Planner, PlanResult
from .planners import PLANNERS, PlannerGeometry, PlannerParams
from .selector import ModeSelector, intention_xy, teleop_command
from .supervision import GndGoal, Proposal, Supervisor
from .supervisor import SupervisorParams, budget_flags, gnd_mode

__all__ = [
    "MODULES", "NAV_MODES", "GridDigest", "MatchInfo", "NavMode", "NavigationStack", "StackParams",
    "TickResult", "make_planner", "warm_up",
]

MODULES = ("match", "model", "planner", "reactor", "supervisor")

NavMode = Literal["gnd", "teleop", "follow", "local"]
NAV_MODES: tuple[str, ...] = ("gnd", "teleop", "follow", "local")
"""Navigation modes: GND to the goal (the default), the log's or script's teleoperation, path following of
subgoals, local navigation alone."""


@dataclass(frozen=True, slots=True)
class StackParams:
    """Everything the stack needs, one frozen section per stage (see ``gndreplay.config``).

    ``planner`` chooses the planner and holds its settings (``planners.PlannerParams``: NF1 dilates by the
    [cspace] margin, the tunnel planner by its own); ``planner.lookahead_m`` places the reactor's target,
    and local navigation's target ahead of a teleoperation command when the mode selector takes over.
    ``nav_mode``, ``selector``, ``selector_margin_m``, ``cmd_timeout_s``, ``selector_hold_s``, ``local``
    and ``follow``: the multi-loop architecture (``NavigationConfig``; see ``NavigationStack``).
    """

    robot: RobotConfig
    grid: GridParams
    planner: PlannerParams
    reactor: NdParams
    supervisor: SupervisorParams
    cspace_margin_m: float = 0.05
    unknown_is_free: bool = True
    nav_mode: NavMode = "gnd"
    selector: bool = True
    local: LocalParams = LocalParams()
    follow: FollowParams = FollowParams()
    selector_margin_m: float = 0.05
    cmd_timeout_s: float = 0.5
    selector_hold_s: float = 0.6


@dataclass(frozen=True, slots=True)
class MatchInfo:
    """The scan matcher's part of a tick: its wall time [ms] and whether it failed (Flag.MATCH_FAILED)."""

    ms: float = 0.0
    failed: bool = False


@dataclass(frozen=True, slots=True)
class GridDigest:
    """The model's grid after a tick's scan, in a few numbers (a run directory's stages.csv), so two runs'
    grids can be told apart without storing them.

    Attributes:
        digest: ``model.grid_digest`` of the cell codes (``RobotCentredGrid.cells``, row-major uint8).
        changed_cells: cells whose code the tick's scan changed (``IntegrateStats.changed_cells``).
        offset_cells: the grid's world offset (``RobotCentredGrid.offset_cells``: row, col).
    """

    digest: int = 0
    changed_cells: int = 0
    offset_cells: tuple[int, int] = (0, 0)


@dataclass(frozen=True, slots=True, eq=False)
class TickResult:
    """What the stack decided at one tick, and why, and how long each part took.

    Attributes:
        t_ns: the scan's time.
        pose_corrected: robot pose after scan matching (corrected odometry frame).
        command: the command out, stamped t_ns (vy only for a holonomic base; never NaN).
        mode: GND mode or reflexive override that produced the command (a reflexive override of the active
            module's command is recorded here; ``active_mode`` still names the module that won).
        situation: the ND+ situation (Situation.NONE without a region).
        flags: exception flags raised this tick.
        direction_rad: ND+ motion direction in the robot frame (nan without a region).
        goal: the goal in the corrected frame.
        path_xy: (K, 2) tightened planned path in the corrected frame (empty when the planner failed).
        timings_ms: per-module wall time [ms] ("match", "model", "planner", "reactor", "supervisor").
        planner_nodes: the planner's search effort this tick (NF1: cells the wave labelled; tunnel: nodes
            expanded), also when it failed.
        planner_length_m: length of the planned path / tunnel polyline [m] (nan when the planner failed).
        tunnel_width_m: width of the tunnel (nan for NF1 or when the planner failed).
        desired_mode: the navigation mode asked for ("gnd", "teleop", "follow", "local").
        active_mode: the mode whose command won this tick (the mode selector's choice).
        takeover_reason: why the active mode is not the desired one ("teleop: swept area occupied (scan)"),
            or why the desired module commands standing still ("teleop: no command", "teleop: command
            stale"); "" otherwise.
        subgoal_index: the path follower's current subgoal (-1 outside path following).
        nd_region: the ND+ region GND's reactor chose ((first, last) sectors; None without one or outside
            GND), for drawing the decision (``nd.nd_diagram``).
        nd_target_xy: where GND's reactor steered to (robot frame: the planner's direction point, or the
            goal itself in mND); None outside GND.
        grid: the grid after this tick's scan (``GridDigest``).
        planner_direction_rad: the planned path's instantaneous direction (world frame, ``PlanResult``;
            nan when the planner failed or did not run).
        proposal: what the modules proposed to the supervisor (mode and command before the reflexive loop
            and GND's rules); None only for a result not made by ``NavigationStack.step``.
    """

    t_ns: int
    pose_corrected: Pose2D
    command: Command
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
    nd_region: tuple[int, int] | None = None
    nd_target_xy: tuple[float, float] | None = None
    grid: GridDigest = GridDigest()
    planner_direction_rad: float = math.nan
    proposal: Proposal | None = None


def make_planner(params: StackParams) -> Planner:
    """The planner ``params.planner.kind`` names (``planners.PLANNERS``), built from its own settings and
    the grid geometry."""
    p = params
    geometry = PlannerGeometry(cell_m=p.grid.cell_m, inner_radius_m=p.robot.inner_radius_m,
                               cspace_margin_m=p.cspace_margin_m, unknown_is_free=p.unknown_is_free,
                               route=p.planner)
    return PLANNERS[p.planner.kind].build(p.planner.settings, geometry)


def _make_follower(params: StackParams, subgoals: Sequence[Subgoal]) -> PathFollower:
    """The path follower over ``subgoals`` (path following needs at least one)."""
    if not subgoals:
        raise ConfigError(f"{FOLLOW_NEEDS_SUBGOALS}: none given (navigation.mode = \"follow\")")
    return PathFollower(
        subgoals, params.follow, params.robot,
        inflate_m=params.robot.inner_radius_m + params.cspace_margin_m,
        unknown_is_free=params.unknown_is_free, escape_m=params.planner.nf1.escape_m,
    )


def _ms(t0: int) -> float:
    return (time.perf_counter_ns() - t0) / 1e6


def _to_robot(pose: Pose2D, xy: ArrayLike) -> NDArray[np.float64]:
    """A world point (x, y) in the robot frame of ``pose``, as a (2,) array."""
    p = np.asarray(xy, dtype=np.float64).reshape(2)
    return np.array(pose.to_local(float(p[0]), float(p[1])))


class NavigationStack:
    """Sequences one cycle per scan and holds what the stages carry between ticks: the robot-centred grid
    (the model), the planner, ND+'s commitment, the supervisor (``supervision.Supervisor``: the reflexive
    loop's state and GND's rules) and, in the multi-loop modes, the path follower and the mode selector's
    takeover. ``step`` runs one full cycle and always returns one command.

    ``params.nav_mode`` chooses the desired navigation mode (the multi-loop paper's three modes, plus GND):

    - "gnd": GND to the goal (model -> NF1/tunnel planner -> ND+ -> supervisor); no mode selector.
    - "teleop": the tick's velocity command (``cmd``, recorded in the log or scripted), clipped to the
      robot's velocity limits; no command (None, not finite, or older than ``cmd_timeout_s`` at the tick's
      time): stand still, the reason recorded.
    - "follow": ``PathFollower.step`` over ``subgoals``; once it reports the final subgoal reached, GOAL:
      stop, Flag.GOAL_REACHED.
    - "local": local navigation alone towards the goal: strategy "nd" is ND+ to the goal itself (GND's
      mND, and ROTATE towards it without a free walking area), the others ``local.STRATEGIES`` on the
      polar map of the grid's occupied cells.

    With ``params.selector`` (teleop and follow) the mode selector (``selector``) arbitrates every tick: when
    the area the desired command sweeps over the braking horizon holds a raw scan hit or an occupied cell
    (within ``selector_margin_m``), local navigation wins the tick and steers towards the desired mode's
    intention (path following: the first point of its trajectory beyond its look-ahead point that is free in
    C-space, ``PathFollower.local_target``; teleoperation: ``ModeSelector.teleop_target``, a point where the
    driver's command heads, fixed in the world while the takeover lasts). The desired mode wins again once its
    swept area has been clear for selector_hold_s (0: the first clear tick, the paper's rule) and, if the
    reflexive loop made local navigation turn first to look where it goes, once local navigation has made its
    way (``selector.arbitrate``: one rule for handing back); the path follower, told it was overridden, then
    plans a new trajectory from the robot's pose. Whatever won then goes through the reflexive loop (stale
    data, ``safe_command``, trap escape), as in GND, except that a teleop command is never replaced by a trap
    escape (a driver's dithering is the driver's). ``selector=False`` is the driver alone, for comparison: the
    desired mode's command goes out unchanged, with no takeover and no reflexive override (GND mode ignores
    it; local mode has no selector, its reflexive loop always runs).
    """

    def __init__(self, params: StackParams, subgoals: Sequence[Subgoal] = ()) -> None:
        if params.nav_mode not in NAV_MODES:
            raise ConfigError(f"navigation.mode must be one of {', '.join(NAV_MODES)}, "
                              f"got {params.nav_mode!r}")
        self.params = params
        self._follower = _make_follower(params, subgoals) if params.nav_mode == "follow" else None
        self.grid = RobotCentredGrid(params.grid)
        self._planner = make_planner(params)
        self._planner_follows_grid = PLANNERS[params.planner.kind].follows_grid
        self._planner_avoids = PLANNERS[params.planner.kind].avoids
        self._avoid = AvoidMarks(params.planner, cell_m=params.grid.cell_m,
                                 radius_m=params.robot.inner_radius_m)
        self.supervisor = Supervisor(params.robot, params.supervisor, self.grid)
        # the planner's no path to a goal beyond the grid means no free border cell is reachable
        self._no_path_is_no_border = self._planner.no_path_is_no_border
        # ND+'s last choice per user ("gnd": GND's reactor, "local": local navigation): the sub-goal's and
        # the target's world bearings (commitment, NdMemory)
        self._nd_memory: dict[str, tuple[float, float]] = {}
        self._local_side = 0  # the side the last local strategy command kept its wall / obstacle on
        self._selector = ModeSelector(
            params.robot, params.supervisor, cell_m=params.grid.cell_m, margin_m=params.selector_margin_m,
            hold_s=params.selector_hold_s, lookahead_m=params.planner.lookahead_m,
            inflate_m=params.robot.inner_radius_m + params.cspace_margin_m,
        )
        self._v_out = 0.0  # forward speed of the last command out (path following's at-rest test)
        self._w_out = 0.0  # ... and its turn rate (the start curvature of a regenerated trajectory)
        self._follow_overridden = False  # the last command out was not the path follower's own

    def step(self, scan: Scan, pose: Pose2D, goal: tuple[float, float], *, odom: Pose2D | None = None,
             cmd: Command | None = None, match: MatchInfo = MatchInfo()) -> TickResult:
        """One cycle for ``scan`` (its stamp is the tick's time) at ``pose`` (corrected frame) towards
        ``goal`` (x, y, corrected frame): GND's model -> planner -> reactor -> supervisor, or the desired
        mode's module -> mode selector -> reflexive loop (see the class). ``odom``: the raw odometry pose
        (the pose doubt and the manoeuvre's progress; None: ``pose``); ``cmd``: the recorded or scripted
        velocity command (teleop); ``match``: the scan matcher's time and failure."""
        odom = pose if odom is None else odom
        if self.params.nav_mode == "gnd":
            return self._gnd_step(scan, pose, goal, odom, match)
        return self._multi_loop_step(scan, pose, goal, odom, cmd, match)

    def _model(self, scan: Scan, pose: Pose2D, odom: Pose2D,
               match: MatchInfo) -> tuple[Flag, dict[str, float], GridDigest]:
        """The start of every cycle: the matcher's flag and time, the scan into the grid (and its digest)
        and the tick to the supervisor (timed "model")."""
        flags = Flag.MATCH_FAILED if match.failed else Flag.NONE
        timings = {"match": match.ms}
        t0 = time.perf_counter_ns()
        stats = self.grid.integrate(scan, pose)
        digest = GridDigest(stats.digest, stats.changed_cells, self.grid.offset_cells)
        self.supervisor.observe(scan, pose, odom)
        timings["model"] = _ms(t0)
        return flags, timings, digest

    def _gnd_step(self, scan: Scan, pose: Pose2D, goal_xy: tuple[float, float], odom: Pose2D,
                  match: MatchInfo) -> TickResult:
        """GND: model -> planner -> reactor -> supervisor."""
        p = self.params
        flags, timings, digest = self._model(scan, pose, odom, match)

        t0 = time.perf_counter_ns()
        goal = np.asarray(goal_xy, dtype=np.float64)
        planned = self._plan(pose, goal, scan.t_ns)
        timings["planner"] = _ms(t0)

        t0 = time.perf_counter_ns()
        target = self._reactor_target(pose, goal, planned)
        obstacles = self.grid.occupied_points(pose, p.reactor.max_range_m)
        nd = self._nd("gnd", pose, obstacles, target)
        timings["reactor"] = _ms(t0)

        over = budget_flags({k: v / 1e3 for k, v in timings.items()}, p.supervisor)
        flags |= over
        planner_ok = planned.ok
        if planned.fallback:
            flags |= Flag.PLANNER_FALLBACK
        if p.supervisor.enforce_budgets and over & Flag.PLANNER_OVER_BUDGET:
            planner_ok = False
            flags |= Flag.PLANNER_TIMEOUT
        if not planned.ok:
            flags |= planned.flag
        if nd.flag:
            flags |= nd.flag

        mode = gnd_mode(planner_ok, not (nd.flag & Flag.REACTOR_NO_REGION))
        if mode is Mode.MND and planned.ok:  # enforced planner time-out: steer to the goal itself
            target = _to_robot(pose, goal)
            nd = self._nd("gnd", pose, obstacles, target)
        goal_rel = _to_robot(pose, goal)
        # ND+ to the goal itself (the planner failed) chose the goal's own region: a way to it in view
        no_way = self._no_way(planned, pose, nd.region is not None and nd.memory is None)
        t0 = time.perf_counter_ns()
        proposal = Proposal(
            mode, Command(scan.t_ns, nd.v_mps, nd.w_radps, nd.vy_mps), flags,
            want_rad=dm.atan2(target[1], target[0]),
            gnd=GndGoal(goal_rel, no_way, (float(goal[0]), float(goal[1]))),
        )
        verdict = self.supervisor.supervise(proposal)
        timings["supervisor"] = _ms(t0)
        if verdict.flags & Flag.TRAP_DETECTED and planned.ok and self._planner_avoids and (
                p.planner.avoid_cost != 1.0):
            self._avoid.mark(planned, self.grid.offset_cells, scan.t_ns)
        path = planned.waypoints_cells
        path_xy = self.grid.cells_to_world(path) if path.shape[0] else np.zeros((0, 2))
        return TickResult(
            t_ns=scan.t_ns, pose_corrected=pose, command=verdict.command, mode=verdict.mode,
            situation=nd.situation, flags=verdict.flags, direction_rad=nd.direction_rad,
            goal=(float(goal[0]), float(goal[1])), path_xy=path_xy, timings_ms=timings,
            planner_nodes=planned.nodes_expanded, planner_length_m=planned.length_m,
            tunnel_width_m=planned.width_m if planned.ok else math.nan, nd_region=nd.region,
            nd_target_xy=(float(target[0]), float(target[1])), grid=digest,
            planner_direction_rad=planned.direction_rad if planned.ok else math.nan, proposal=proposal,
        )

    def _multi_loop_step(self, scan: Scan, pose: Pose2D, goal_xy: tuple[float, float], odom: Pose2D,
                         cmd: Command | None, match: MatchInfo) -> TickResult:
        """Teleop / follow / local: the desired module's command, the mode selector, the reflexive loop.

        Timings: "planner" is the desired module (the path follower, reading the teleop command),
        "reactor" the mode selector and local navigation."""
        p = self.params
        flags, timings, digest = self._model(scan, pose, odom, match)

        t0 = time.perf_counter_ns()
        desired: str = p.nav_mode
        goal = np.asarray(goal_xy, dtype=np.float64)
        goal_rel = _to_robot(pose, goal)
        path_xy: NDArray[np.float64] = np.zeros((0, 2))
        subgoal_index, reason, done = -1, "", False
        v = vy = w = 0.0
        intention: NDArray[np.float64] | None = goal_rel
        if desired == "teleop":
            v, vy, w, reason = teleop_command(cmd, p.robot, t_ns=scan.t_ns, timeout_s=p.cmd_timeout_s)
            intention = intention_xy(v, vy, w, p.planner.lookahead_m)
        elif desired == "follow":
            assert self._follower is not None  # built in __init__ for this mode
            fc = self._follower.step(pose, self.grid, v_mps=self._v_out, w_radps=self._w_out,
                                     overridden=self._follow_overridden)
            v, w = fc.v_mps, fc.w_radps
            subgoal_index, done, path_xy = fc.subgoal_index, fc.done, fc.trajectory_xy
        timings["planner"] = _ms(t0)

        t0 = time.perf_counter_ns()
        active, mode = desired, _MODULE_MODE[desired]
        situation, direction = Situation.NONE, math.nan
        reflexive = p.selector or desired == "local"  # local navigation has no selector to switch off
        points = self.supervisor.obstacles(p.selector_margin_m) if reflexive else None
        if desired == "local" or done:
            done = done or self.supervisor.at_goal(goal_rel, (float(goal[0]), float(goal[1])))
        elif p.selector:
            assert points is not None
            active, why = self._selector.select(desired, (v, vy, w), points.near_xy, points.grid_xy,
                                                t_ns=scan.t_ns, xy=(pose.x, pose.y))
            reason = why or reason
        if done:
            mode, v, vy, w = Mode.GOAL, 0.0, 0.0, 0.0
            flags |= Flag.GOAL_REACHED
        elif active == "local":
            if self._follower is not None:  # past the obstacle on the path, not at it (follow.local_target)
                intention = _to_robot(pose, self._follower.local_target(self.grid))
            elif desired == "teleop":
                intention = self._selector.teleop_target(pose, (v, vy, w), self.grid)
            if intention is None:  # a still command is never taken over; kept for the type checker
                intention = np.zeros(2)
            mode, v, vy, w, situation, direction, flag = self._local(pose, intention)
            flags |= flag
        timings["reactor"] = _ms(t0)
        flags |= budget_flags({k: x / 1e3 for k, x in timings.items()}, p.supervisor)

        # no trap escape for the driver: dithering under teleop is the driver's own (and an escape begun
        # under local navigation ends when the driver has the robot again)
        want = math.nan if intention is None else dm.atan2(intention[1], intention[0])
        t0 = time.perf_counter_ns()
        proposal = Proposal(mode, Command(scan.t_ns, v, w, vy), flags, want_rad=want, trap=active != "teleop",
                            reflexive=points is not None)
        verdict = self.supervisor.supervise(proposal, points)
        timings["supervisor"] = _ms(t0)
        self._selector.settle(active, verdict.looking, (pose.x, pose.y), scan.t_ns)
        self._v_out, self._w_out = verdict.command.v_mps, verdict.command.w_radps
        self._follow_overridden = active != "follow" or verdict.mode is not Mode.FOLLOW
        return TickResult(
            t_ns=scan.t_ns, pose_corrected=pose, command=verdict.command, mode=verdict.mode,
            situation=situation, flags=verdict.flags, direction_rad=direction,
            goal=(float(goal[0]), float(goal[1])), path_xy=path_xy, timings_ms=timings, desired_mode=desired,
            active_mode=active, takeover_reason=reason, subgoal_index=subgoal_index, grid=digest,
            proposal=proposal,
        )

    def _local(
        self, pose: Pose2D, target: NDArray[np.float64]
    ) -> tuple[Mode, float, float, float, Situation, float, Flag]:
        """Local navigation towards ``target`` (robot frame) with the configured strategy
        (``local.STRATEGIES``) on the grid's occupied cells, told the side it kept last time and given ND+
        with its commitment for local navigation (``_nd``): (mode, v, vy, w, ND+ situation, direction,
        flag). A strategy's ROTATE turns towards the target at ROTATE's rate (``_rotate_w``)."""
        p = self.params
        obstacles = self.grid.occupied_points(pose, p.reactor.max_range_m)
        lc = STRATEGIES[p.local.strategy](obstacles, target, p.robot, p.local, side_hint=self._local_side,
                                          nd=partial(self._nd, "local", pose))
        self._local_side = lc.side
        w = self._rotate_w(target) if lc.mode is Mode.ROTATE else lc.w_radps
        return lc.mode, lc.v_mps, lc.vy_mps, w, lc.situation, lc.direction_rad, lc.flag

    def _nd(self, user: str, pose: Pose2D, obstacles: NDArray[np.float64],
            target: NDArray[np.float64]) -> NdResult:
        """ND+ towards ``target`` (robot frame) with commitment: the user's previous choice (its sub-goal
        held as a world bearing, so the robot's own turning does not move it) is passed back in, unless the
        target's world bearing moved by more than ``ND_MEMORY_RESET_RAD`` since the previous tick (a new
        target: choose afresh)."""
        p = self.params
        bearing = pose.theta + dm.atan2(target[1], target[0])
        held = self._nd_memory.pop(user, None)
        prev = None
        if held is not None and abs(math.remainder(bearing - held[1], math.tau)) <= ND_MEMORY_RESET_RAD:
            prev = NdMemory(float(wrap_angle(held[0] - pose.theta)))
        nd = nd_step(obstacles, target, p.robot, p.reactor, prev)
        if nd.memory is not None:
            self._nd_memory[user] = (pose.theta + nd.memory.subgoal_rad, bearing)
        return nd

    def _rotate_w(self, goal_rel: NDArray[np.float64]) -> float:
        """ROTATE's turn rate towards ``goal_rel`` (robot frame), in the direction the supervisor keeps."""
        return self.supervisor.rotate_w(goal_rel)

    def _no_way(self, planned: PlanResult, pose: Pose2D, nd_to_goal: bool) -> bool:
        """Whether this tick has no way to the goal (the supervisor holds the goal unreachable after
        unreachable_ticks of them in a row, ``supervision.GndGoal``): the planner has found no path
        (PLANNER_NO_PATH) to a goal inside the grid *and* ND+ towards the goal itself did not connect it
        either (``nd_to_goal`` False: no region, or only a region through a gap elsewhere, the goal hidden
        behind obstacles). Any plan is a way, and so is ND+ choosing the goal's own region (the goal in view
        with a navigable way to it, e.g. between stale obstacle cells the planner's inflated C-space
        closes): GND's mND then goes on. Not just "ND+ has a region": ND+ finds some gap round almost any
        obstacle, so a goal inside a closed box would never be held unreachable. A goal beyond the grid
        only when the robot cannot reach the grid border at all: no path to the goal's border cell alone
        says nothing about the goal (NF1 with ``frontier_goal`` plans to the best reachable free border
        cell, so its no path already says so; the tunnel planner plans to one border cell:
        ``_reaches_border``)."""
        return not (planned.ok or nd_to_goal or not planned.flag & Flag.PLANNER_NO_PATH or (
            planned.goal_projected and not self._no_path_is_no_border and self._reaches_border(pose)
        ))

    def _reaches_border(self, pose: Pose2D) -> bool:
        """The robot's free region in the NF1 C-space of the grid touches the grid border (only asked on
        ticks without a path to a goal beyond the grid, of a planner that plans to one border cell)."""
        p = self.params
        free = free_cspace(self.grid.cells, cell_m=p.grid.cell_m, inflate_m=p.robot.inner_radius_m
                           + p.cspace_margin_m, unknown_is_free=p.unknown_is_free)
        return reaches_border(free, self.grid.robot_cell(pose))

    def _plan(self, pose: Pose2D, goal: NDArray[np.float64], t_ns: int) -> PlanResult:
        """The planner on this tick's grid, with the routes of recent traps to avoid (``AvoidMarks``)."""
        start = self.grid.robot_cell(pose)
        goal_rc = self.grid.world_to_cell_float(goal[None, :])[0]
        kw: dict[str, Any] = {}
        if self._planner_follows_grid:
            kw["offset_rc"] = self.grid.offset_cells
        if self._planner_avoids and self._avoid:
            kw["avoid"] = self._avoid.mask(self.grid.cells.shape, self.grid.offset_cells, t_ns)
        return self._planner.plan(self.grid.cells, start, goal_rc, **kw)

    def _reactor_target(
        self, pose: Pose2D, goal: NDArray[np.float64], planned: PlanResult
    ) -> NDArray[np.float64]:
        """mpND: a point lookahead_m along the instantaneous path direction; mND: the goal itself."""
        if planned.ok and math.isfinite(planned.direction_rad):
            bearing = float(wrap_angle(planned.direction_rad - pose.theta))
            d = self.params.planner.lookahead_m
            return np.array([d * dm.cos(bearing), d * dm.sin(bearing)])
        return _to_robot(pose, goal)

# the mode column of a tick the desired module or a local strategy commanded unchanged (ND+ as local
# navigation reports its own mND / ROTATE); ``active_mode`` names the module that won in any case
_MODULE_MODE: dict[str, Mode] = {"teleop": Mode.TELEOP, "follow": Mode.FOLLOW, "local": Mode.LOCAL}


ND_MEMORY_RESET_RAD = 0.25 * math.pi
"""ND+'s commitment is dropped when its target's world bearing moves this far in one tick [rad]
(**choice**: a new target, e.g. a re-aimed takeover or a new route)."""


def warm_up(params: StackParams) -> None:
    """Run a throwaway stack on synthetic scans so numba compiles (or loads) every kernel before the
    first timed tick; otherwise tick 0 would report hundreds of milliseconds of JIT as model time.

    Readers may hand out read-only arrays (shared beam angles, buffers decoded in place), which numba
    compiles as a separate specialisation, so every writable/read-only combination is exercised. The GND
    cycle is always warmed (its kernels serve the other modes too); for another navigation mode a stack in
    that mode then runs its module, a mode selector takeover and the local strategy (``_warm_up_mode``)."""
    gnd = dataclasses.replace(params, nav_mode="gnd")
    _warm_up_gnd(gnd)
    warm_up_manoeuvre()
    if params.nav_mode != "gnd":
        warm_up_local(params.robot)
        _warm_up_mode(params)


def _warm_up_mode(params: StackParams) -> None:
    """The teleop / follow / local module on the synthetic scans: a command driving at an obstacle close
    ahead (the selector hands over to the local strategy), a reverse arc, no command."""
    subgoals = (Subgoal(1.0, 0.0, 0.0), Subgoal(2.0, 0.5, 0.3, "stop")) if params.nav_mode == "follow" else ()
    stack = NavigationStack(params, subgoals)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    open_ranges = np.where(np.arange(angles.size) % 7 == 0, np.inf, 3.0)
    close = np.where(np.abs(angles) < 0.3, params.robot.front_m + 0.1, 3.0)
    v, w = params.robot.vmax_mps, params.robot.wmax_radps
    k = 0
    for ranges in (open_ranges, close):
        for cmd in (Command(k, v, 0.0), Command(k, -v, 0.5 * w), None):
            scan = Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=8.0)
            stack.step(scan, Pose2D(0.0, 0.0, 0.0), (3.0, 0.5), cmd=cmd)
            k += 1


def _warm_up_gnd(params: StackParams) -> None:
    """GND's kernels (model, planner, ND+, supervisor) on synthetic scans (see ``warm_up``)."""
    stack = NavigationStack(params)
    k = 0
    for ro_ranges in (False, True):
        for ro_angles in (False, True):
            angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
            ranges = np.where(np.arange(angles.size) % 7 == 0, np.inf, 3.0)
            ranges.flags.writeable = not ro_ranges
            angles.flags.writeable = not ro_angles
            for goal in ((2.0, 0.5), (-5.0, 0.0), (30.0, 30.0)):
                scan = Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=8.0)
                stack.step(scan, Pose2D(0.05 * k, 0.0, 0.0), goal)
                k += 1
    # half a grid side on: the grid re-centres (the C-space tracker's move)
    scan = Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=8.0)
    stack.step(scan, Pose2D(0.5 * params.grid.side_m, 0.0, 0.0), (30.0, 30.0))
    k += 1
    # an obstacle closer than the robot's inner radius: the robot cell is not free, so the planner escapes
    # along a straight line of cells to the nearest reachable one (nf1's escape kernels)
    stack = NavigationStack(params)
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    close = np.where(np.abs(angles) < 0.3, 0.6 * params.robot.inner_radius_m, 3.0)
    for goal in ((3.0, 0.0), (-3.0, 0.5)):
        scan = Scan(t_ns=k, ranges_m=close, angles_rad=angles, max_range_m=8.0)
        stack.step(scan, Pose2D(0.0, 0.0, 0.0), goal)
        k += 1
    PLANNERS[params.planner.kind].warm_up(params.planner.settings, params.grid.size_cells)
