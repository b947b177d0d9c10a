"""NavigationStack: one synchronous model -> planner -> reactor cycle per scan, under the supervisor; or, in
the multi-loop paper's modes (teleop, follow, local), the desired module -> mode selector -> reflexive loop.

Scan matching runs one step ahead of the stack (in ``gndreplay.replay``) because the default goal of a
replay is a pose further along the log's own *corrected* trajectory; the stack receives the corrected
pose with the tick and never looks at the future. It owns the per-module timers.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import FOLLOW_NEEDS_SUBGOALS, ConfigError
from ..geometry import compose, relative, transform_points, wrap_angle
from ..robot import RobotConfig
from ..types import Command, Flag, Mode, Pose2D, Scan, Subgoal, Tick
from .cspace import free_cspace
from .follow import FollowParams, PathFollower, first_free_point
from .local import STRATEGIES, LocalParams, warm_up_local
from .manoeuvre import ManoeuvreParams, Primitive, Speeds, end_poses, plan_manoeuvre, warm_up_manoeuvre
from .model import OCCUPIED, UNKNOWN, GridParams, RobotCentredGrid
from .nd import NdMemory, NdParams, NdResult, Situation, nd_step
from .nf1 import reaches_border
from .planner import Planner, PlanResult
from .planners import PLANNERS, PlannerGeometry, PlannerParams
from .selector import Takeover, arbitrate, intention_xy, look_hold, swept_area_occupied, turned_first
from .supervisor import (
    SafeCommand,
    SupervisorParams,
    TrapDetector,
    blind_points,
    budget_flags,
    doubt_transforms,
    doubted_cells,
    escape_command,
    gnd_mode,
    no_progress,
    rotate_command,
    safe_command,
    safety_reach_m,
    seen_through,
    unconfirmed_cells,
)

__all__ = [
    "MODULES", "NAV_MODES", "NavMode", "NavigationStack", "StackParams", "TickResult", "make_planner",
    "teleop_command", "warm_up",
]

MODULES = ("match", "model", "planner", "reactor")

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


@dataclass(frozen=True, slots=True, eq=False)
class TickResult:
    """What the stack decided at one tick, and why, and how long each part took.

    Attributes:
        t_ns: the scan's time.
        pose_corrected: robot pose after scan matching (corrected odometry frame).
        v_mps, vy_mps, w_radps: the command (vy only for a holonomic base).
        mode: GND mode or reflexive override that produced the command (a reflexive override of the active
            module's command is recorded here; ``active_mode`` still names the module that won).
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
        takeover_reason: why the active mode is not the desired one ("teleop: swept area occupied (scan)"),
            or why the desired module commands standing still ("teleop: no command", "teleop: command
            stale"); "" otherwise.
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
    """The planner ``params.planner.kind`` names (``planners.PLANNERS``), built from its own settings and
    the grid geometry."""
    p = params
    geometry = PlannerGeometry(cell_m=p.grid.cell_m, inner_radius_m=p.robot.inner_radius_m,
                               cspace_margin_m=p.cspace_margin_m, unknown_is_free=p.unknown_is_free,
                               route=p.planner)
    return PLANNERS[p.planner.kind].build(p.planner.settings, geometry)


def _ms(t0: int) -> float:
    return (time.perf_counter_ns() - t0) / 1e6


def _to_robot(pose: Pose2D, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """World points (K, 2) into the robot frame of ``pose``."""
    return transform_points(pose.inverse().as_array(), xy)


class NavigationStack:
    """Holds the state carried between ticks: the robot-centred grid, the previous scan time, the trap
    detector, an escape in progress and, in path following, the path follower. ``step`` runs one full
    cycle and always returns one command.

    ``params.nav_mode`` chooses the desired navigation mode (the multi-loop paper's three modes, plus GND):

    - "gnd": GND to the goal (model -> NF1/tunnel planner -> ND+ -> supervisor); no mode selector.
    - "teleop": the tick's velocity command (``Tick.cmd``, recorded in the log or scripted), clipped to the
      robot's velocity limits; no command (None, not finite, or older than ``cmd_timeout_s`` at the tick's
      time): stand still, the reason recorded.
    - "follow": ``PathFollower.step`` over ``subgoals``; once it reports the final subgoal reached, GOAL:
      stop, Flag.GOAL_REACHED.
    - "local": local navigation alone towards the goal with the strategy ``local.STRATEGIES`` names: "nd"
      is ND+ to the goal itself (GND's mND, and ROTATE towards it without a free walking area), the others
      work on the polar map of the grid's occupied cells.

    With ``params.selector`` (teleop and follow) the mode selector (``selector``) arbitrates every tick:
    when the area the desired command sweeps over the braking horizon holds a raw scan hit or an occupied
    cell (within ``selector_margin_m``), local navigation wins the tick and steers towards the desired
    mode's intention (path following: the first point of its trajectory beyond its look-ahead point that
    is free in C-space, ``PathFollower.local_target``; teleoperation: ``_teleop_target``, a point where the
    driver's command heads, fixed in the world while the takeover lasts). The desired mode wins again once
    its swept area has been clear for selector_hold_s (0: the first clear tick, the paper's rule) and,
    if the reflexive loop made local navigation turn first to look where it goes, once local navigation
    has made its way (``selector.arbitrate``: one rule for handing back); the path follower, told it was
    overridden, then plans a new trajectory from the robot's pose. Whatever won then goes through the
    reflexive loop (stale data, ``safe_command``, trap escape), as in GND, except that a teleop command
    is never replaced by a trap escape (a driver's dithering is the driver's). ``selector=False`` is the
    driver alone, for comparison: the desired mode's command goes out unchanged, with no takeover and no
    reflexive override (GND mode ignores it; local mode has no selector, its reflexive loop always runs).
    """

    def __init__(self, params: StackParams, subgoals: Sequence[Subgoal] = ()) -> None:
        if params.nav_mode not in NAV_MODES:
            raise ConfigError(f"navigation.mode must be one of {', '.join(NAV_MODES)}, "
                              f"got {params.nav_mode!r}")
        self.params = params
        self._follower: PathFollower | None = None
        if params.nav_mode == "follow":
            if not subgoals:
                raise ConfigError(f"{FOLLOW_NEEDS_SUBGOALS}: none given (navigation.mode = \"follow\")")
            self._follower = PathFollower(
                subgoals, params.follow, params.robot,
                inflate_m=params.robot.inner_radius_m + params.cspace_margin_m,
                unknown_is_free=params.unknown_is_free, escape_m=params.planner.nf1.escape_m,
            )
        self.grid = RobotCentredGrid(params.grid)
        self._planner = make_planner(params)
        self._trap = TrapDetector(params.supervisor, params.robot.wmax_radps, params.robot.vmax_mps)
        self._escape_left = 0
        self._escape_v = 0.0
        # the trap escape's manoeuvre in progress (``_manoeuvre_step``): its primitives still to drive, the
        # odometry pose each is to end at, and the tick stamp by which it must be over
        self._manoeuvre: tuple[Primitive, ...] = ()
        self._manoeuvre_ends = np.zeros((0, 3))
        self._manoeuvre_until_ns = 0
        self._refused_since: tuple[int, Pose2D] | None = None  # stamp and pose of the first of the
        # ticks in a row whose command the reflexive check replaced (``_held_up``)
        self._prev_t_ns: int | None = None
        self._no_path = 0  # consecutive PLANNER_NO_PATH ticks
        # the planner's no path to a goal beyond the grid means no free border cell is reachable
        self._no_path_is_no_border = self._planner.no_path_is_no_border
        self._looked_rad = 0.0  # turned in place since the goal was held unreachable
        self._prev_theta: float | None = None
        self._rotate_sign = 0.0  # turn direction of the previous tick's ROTATE (0: not rotating)
        self._v_out = 0.0  # forward speed of the last command out (path following's at-rest test)
        self._w_out = 0.0  # ... and its turn rate (the start curvature of a regenerated trajectory)
        self._local_side = 0  # the side the last local strategy command kept its wall / obstacle on
        self._looking = False  # the last reflexive check replaced the command by the blind side's turn first
        self._takeover: Takeover | None = None  # the mode selector's takeover in progress (its hold)
        self._follow_overridden = False  # the last command out was not the path follower's own
        self._intent: tuple[NDArray[np.float64], tuple[float, float, float]] | None = None  # held teleop
        # target (world) of the takeover in progress, and the driver's command it was aimed from
        # ND+'s last choice per user ("gnd": GND's reactor, "local": local navigation): the sub-goal's and
        # the target's world bearings (commitment, NdMemory)
        self._nd_memory: dict[str, tuple[float, float]] = {}
        # stamps, corrected poses and odometry of ticks within doubt_window_s, oldest first, the first
        # _track_n rows: the pose doubt of the grid's cells (``_doubted_points``, ``_follow_track``)
        cap = math.ceil(params.supervisor.doubt_window_s * 1e9 / DOUBT_TRACK_NS) + 2
        self._track_ns = np.zeros(cap, dtype=np.int64)
        self._track_c = np.zeros((cap, 3))
        self._track_o = np.zeros((cap, 3))
        self._track_n = 0

    def step(self, tick: Tick, pose: Pose2D, goal_xy: tuple[float, float], match_ms: float = 0.0,
             match_failed: bool = False) -> TickResult:
        """One cycle for the tick's scan at ``pose`` (corrected frame): GND's model -> planner -> reactor ->
        supervisor, or the desired mode's module -> mode selector -> reflexive loop (see the class)."""
        if self.params.nav_mode == "gnd":
            return self._gnd_step(tick, pose, goal_xy, match_ms, match_failed)
        return self._multi_loop_step(tick, pose, goal_xy, match_ms, match_failed)

    def _model(self, tick: Tick, pose: Pose2D, match_ms: float,
               match_failed: bool) -> tuple[Flag, dict[str, float]]:
        """The start of every cycle: the matcher's flag and time, the scan into the grid (timed "model")."""
        flags = Flag.MATCH_FAILED if match_failed else Flag.NONE
        timings = {"match": match_ms}
        t0 = time.perf_counter_ns()
        self.grid.integrate(tick.scan, pose)
        self._follow_track(tick, pose)
        timings["model"] = _ms(t0)
        return flags, timings

    def _follow_track(self, tick: Tick, pose: Pose2D) -> None:
        """Put this tick's corrected pose and odometry at the end of the track (``_doubted_points``' pose
        doubt): one tick kept per DOUBT_TRACK_NS, the newest always last (it replaces a last one kept less
        than that after its predecessor), none older than doubt_window_s. A tick stamped before the last
        one (a log that restarts) starts the track anew."""
        t, n = self._track_ns, self._track_n
        if n and t[n - 1] > tick.t_ns:
            n = 0
        if n >= 2 and t[n - 1] - t[n - 2] < DOUBT_TRACK_NS:
            n -= 1
        old = int(np.searchsorted(t[:n], tick.t_ns - round(self.params.supervisor.doubt_window_s * 1e9)))
        if old or n == t.shape[0]:  # drop the ticks past the window (and, if full, the oldest)
            old = max(old, 1)
            for a in (t, self._track_c, self._track_o):
                a[: n - old] = a[old:n]
            n -= old
        t[n] = tick.t_ns
        self._track_c[n] = (pose.x, pose.y, pose.theta)
        self._track_o[n] = (tick.odom.x, tick.odom.y, tick.odom.theta)
        self._track_n = n + 1

    def _gnd_step(self, tick: Tick, pose: Pose2D, goal_xy: tuple[float, float], match_ms: float,
                  match_failed: bool) -> TickResult:
        """GND: model -> planner -> reactor -> supervisor."""
        p = self.params
        flags, timings = self._model(tick, pose, match_ms, match_failed)

        t0 = time.perf_counter_ns()
        goal = np.asarray(goal_xy, dtype=np.float64)
        planned = self._plan(pose, goal)
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
            target = _to_robot(pose, goal[None, :])[0]
            nd = self._nd("gnd", pose, obstacles, target)
        v, vy, w = nd.v_mps, nd.vy_mps, nd.w_radps
        goal_rel = _to_robot(pose, goal[None, :])[0]
        # ND+ to the goal itself (the planner failed) chose the goal's own region: a way to it in view
        unreachable = self._unreachable(planned, pose, nd.region is not None and nd.memory is None)
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
        mode, v, vy, w, flags = self._reflexive(tick, pose, mode, v, vy, w, flags, unreachable,
                                                want_rad=dm.atan2(target[1], target[0]))
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

    def _multi_loop_step(self, tick: Tick, pose: Pose2D, goal_xy: tuple[float, float], match_ms: float,
                         match_failed: bool) -> TickResult:
        """Teleop / follow / local: the desired module's command, the mode selector, the reflexive loop.

        Timings: "planner" is the desired module (the path follower, reading the teleop command),
        "reactor" the mode selector and local navigation."""
        p = self.params
        flags, timings = self._model(tick, pose, match_ms, match_failed)

        t0 = time.perf_counter_ns()
        desired: str = p.nav_mode
        goal = np.asarray(goal_xy, dtype=np.float64)
        goal_rel = _to_robot(pose, goal[None, :])[0]
        path_xy: NDArray[np.float64] = np.zeros((0, 2))
        subgoal_index, reason, done = -1, "", False
        v = vy = w = 0.0
        intention: NDArray[np.float64] | None = goal_rel
        if desired == "teleop":
            v, vy, w, reason = teleop_command(tick.cmd, p.robot, t_ns=tick.t_ns, timeout_s=p.cmd_timeout_s)
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
        points = self._safety_points(tick, pose, self._reach_m()) if reflexive else None
        if desired == "local" or done:
            done = done or math.hypot(goal_rel[0], goal_rel[1]) <= p.supervisor.goal_tolerance_m
        elif p.selector:
            assert points is not None
            where = swept_area_occupied(v, vy, w, points[1], points[2], p.robot, p.supervisor,
                                        cell_m=p.grid.cell_m, margin_m=p.selector_margin_m)
            active, why, self._takeover = arbitrate(
                desired, where, t_ns=tick.t_ns, held=self._takeover,
                hold=look_hold(p.selector_hold_s, p.robot, p.supervisor),
                moving=v != 0.0 or vy != 0.0 or w != 0.0, xy=(pose.x, pose.y))
            reason = why or reason
        if done:
            mode, v, vy, w = Mode.GOAL, 0.0, 0.0, 0.0
            flags |= Flag.GOAL_REACHED
        elif active == "local":
            if self._follower is not None:  # past the obstacle on the path, not at it (follow.local_target)
                intention = _to_robot(pose, np.asarray(self._follower.local_target(self.grid))[None, :])[0]
            elif desired == "teleop":
                intention = self._teleop_target(pose, (v, vy, w))
            if intention is None:  # a still command is never taken over; kept for the type checker
                intention = np.zeros(2)
            mode, v, vy, w, situation, direction, flag = self._local(pose, intention)
            flags |= flag
        if active != "local":
            self._intent = None
        timings["reactor"] = _ms(t0)
        flags |= budget_flags({k: x / 1e3 for k, x in timings.items()}, p.supervisor)

        rotating = mode is Mode.ROTATE
        if points is not None:
            # no trap escape for the driver: dithering under teleop is the driver's own (and an escape
            # begun under local navigation ends when the driver has the robot again)
            want = math.nan if intention is None else dm.atan2(intention[1], intention[0])
            mode, v, vy, w, flags = self._reflexive(tick, pose, mode, v, vy, w, flags, points=points,
                                                    trap=active != "teleop", want_rad=want)
        if active != "local":
            self._takeover = None
        elif self._looking:
            self._takeover = turned_first(self._takeover, (pose.x, pose.y), tick.t_ns)
        self._rotate_sign = (1.0 if w > 0.0 else -1.0) if rotating and w != 0.0 else 0.0
        self._v_out, self._w_out = _finite(v), _finite(w)
        self._follow_overridden = active != "follow" or mode is not Mode.FOLLOW
        return TickResult(
            t_ns=tick.t_ns,
            pose_corrected=pose,
            v_mps=_finite(v),
            vy_mps=_finite(vy),
            w_radps=_finite(w),
            mode=mode,
            situation=situation,
            flags=flags,
            direction_rad=direction,
            goal=(float(goal[0]), float(goal[1])),
            path_xy=path_xy,
            timings_ms=timings,
            desired_mode=desired,
            active_mode=active,
            takeover_reason=reason,
            subgoal_index=subgoal_index,
        )

    def _teleop_target(self, pose: Pose2D, cmd: tuple[float, float, float]) -> NDArray[np.float64] | None:
        """Local navigation's target (robot frame) while it has taken over from the driver.

        Where the driver's command heads (``selector.intention_xy``), searched along that bearing from the
        look-ahead distance to ``TELEOP_REACH`` times it for the first point free in C-space with unknown
        cells counted as blocked (known free space past the obstacle, not the obstacle's unseen inside),
        else the far end. It is fixed in the world when the takeover starts and kept while it lasts: a
        target in the robot frame turns with the robot, so local navigation, turning to pass the obstacle,
        would never see it move aside and would only dither in front of it. It is aimed again when the
        driver asks for something else (``_intention_changed``: travel reversed, or his intention points
        away from the held target), not merely because he counter-steers."""
        p = self.params
        rel = intention_xy(*cmd, p.planner.lookahead_m)
        if rel is None:
            self._intent = None
            return None
        if self._intent is not None:
            held = _to_robot(pose, self._intent[0][None, :])[0]
            if not _intention_changed(self._intent[1], cmd, held, rel):
                return held
        bearing = dm.atan2(rel[1], rel[0])
        dists = np.arange(p.planner.lookahead_m, TELEOP_REACH * p.planner.lookahead_m + 1e-9, p.grid.cell_m)
        ray = np.column_stack([dists * dm.cos(bearing), dists * dm.sin(bearing)])
        world = transform_points(pose.as_array(), ray)
        i = first_free_point(world, self.grid, inflate_m=p.robot.inner_radius_m + p.cspace_margin_m,
                             unknown_is_free=False)
        target = world[-1 if i is None else i]
        self._intent = (target, cmd)
        return _to_robot(pose, target[None, :])[0]

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
        """ROTATE's turn rate. The direction is chosen towards the goal when ROTATE starts and kept while
        it lasts (the turn actually executed, also when the safety check reversed it): choosing it afresh
        every tick flips it each time the goal bearing crosses 0 or +-pi, a turn that never turns."""
        p = self.params
        w = rotate_command(dm.atan2(goal_rel[1], goal_rel[0]), p.robot, p.supervisor)
        return abs(w) * self._rotate_sign if self._rotate_sign else w

    def _unreachable(self, planned: PlanResult, pose: Pose2D, nd_to_goal: bool) -> bool:
        """True once, for unreachable_ticks in a row, the planner has found no path (PLANNER_NO_PATH) to a
        goal inside the grid *and* ND+ towards the goal itself did not connect it either (``nd_to_goal``
        False: no region, or only a region through a gap elsewhere, the goal hidden behind obstacles): the
        goal is held unreachable (GND: mND did not connect it; ROTATE, one full turn, then stop). Any plan
        ends it, and so does ND+ choosing the goal's own region (the goal in view with a navigable way to
        it, e.g. between stale obstacle cells the planner's inflated C-space closes): GND's mND then goes
        on. Not just "ND+ has a region": ND+ finds some gap round almost any obstacle, so a goal inside a
        closed box would never be held unreachable. A goal beyond the grid only when the robot cannot reach
        the grid border at all: no path to the goal's border cell alone says nothing about the goal (NF1
        with ``frontier_goal`` plans to the best reachable free border cell, so its no path already says
        so; the tunnel planner plans to one border cell: ``_reaches_border``). Tracks how far the robot
        turned since, from the corrected pose."""
        prev, self._prev_theta = self._prev_theta, pose.theta
        if planned.ok or nd_to_goal or not planned.flag & Flag.PLANNER_NO_PATH or (
            planned.goal_projected and not self._no_path_is_no_border and self._reaches_border(pose)
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
        ticks without a path to a goal beyond the grid, of a planner that plans to one border cell)."""
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
            return np.array([d * dm.cos(bearing), d * dm.sin(bearing)])
        return _to_robot(pose, goal[None, :])[0]

    def _reach_m(self) -> float:
        """How far from the rotation centre an obstacle matters to the mode selector and the reflexive
        loop: the loop's reach plus the selector's margin."""
        p = self.params
        return safety_reach_m(p.robot, p.supervisor, p.grid.cell_m) + p.selector_margin_m

    def _safety_points(self, tick: Tick, pose: Pose2D, reach_m: float) -> _Points:
        """The obstacles a command can touch (robot frame): all the tick's raw scan hits, those within
        ``reach_m`` of the rotation centre, and the grid's occupied cell centres within ``reach_m``."""
        raw = transform_points(tick.scan.sensor_pose.as_array(), tick.scan.points())
        near = raw[np.hypot(raw[:, 0], raw[:, 1]) <= reach_m]
        return raw, near, self.grid.occupied_points(pose, reach_m)

    def _doubted_points(self, scan: Scan, pose: Pose2D, reach_m: float) -> NDArray[np.float64]:
        """The occupied cells whose pose is in doubt, where they lie if the odometry is right, within
        ``reach_m`` (robot frame; ``supervisor.doubted_cells``: the matcher and the odometry disagree on
        the motion since the cell was last seen), less those the scan sees through (``seen_through``)."""
        n = self._track_n
        if n < 2 or self.params.supervisor.doubt_window_s <= 0.0:
            return np.zeros((0, 2))
        transforms, doubted = doubt_transforms(self._track_c[:n], self._track_o[:n], self.params.supervisor)
        if not doubted.any():
            return np.zeros((0, 2))
        # E p = R p + t keeps |R p| = |p|: only cells within reach + |t| can move into reach
        far = reach_m + float(np.max(np.hypot(transforms[doubted, 0], transforms[doubted, 1])))
        cells, seen_ns = self.grid.occupied_points_seen(pose, far)
        moved = doubted_cells(cells, seen_ns, self._track_ns[:n], transforms, doubted)
        moved = moved[np.hypot(moved[:, 0], moved[:, 1]) <= reach_m]
        sp = scan.sensor_pose
        return moved[~seen_through(moved, scan.ranges_m, scan.angles_rad, (sp.x, sp.y, sp.theta),
                                   self.params.grid.cell_m)]

    def _not_free_points(self, pose: Pose2D, radius_m: float) -> NDArray[np.float64]:
        """Centres (robot frame) of the cells within ``radius_m`` not known FREE (UNKNOWN or OCCUPIED):
        where a backward escape may not go (``supervisor.escape_command``)."""
        return np.vstack([self.grid.cell_points(pose, radius_m, s) for s in (UNKNOWN, OCCUPIED)])

    def _blind_points(self, scan: Scan, pose: Pose2D, radius_m: float) -> NDArray[np.float64]:
        """Centres (robot frame) of the cells within ``radius_m`` on the laser's blind side that no scan
        has seen within blind_memory_s of this scan's stamp (``supervisor.blind_points``)."""
        memory_ns = round(self.params.supervisor.blind_memory_s * 1e9)
        unseen = self.grid.unseen_points(pose, radius_m, scan.t_ns - memory_ns)
        sp = scan.sensor_pose
        fov = (float(np.min(scan.angles_rad)), float(np.max(scan.angles_rad)))
        return blind_points(unseen, self.params.robot, (sp.x, sp.y, sp.theta), fov)

    def _reflexive(
        self, tick: Tick, pose: Pose2D, mode: Mode, v: float, vy: float, w: float, flags: Flag,
        unreachable: bool = False, points: _Points | None = None, trap: bool = True,
        want_rad: float = math.nan,
    ) -> tuple[Mode, float, float, float, Flag]:
        """The reflexive loop: stale data, a command whose swept footprint would touch an obstacle of the
        raw scan or the grid (replaced by ``safe_command``'s rule, recorded as the mode), trap escape.

        With the goal held unreachable the robot only looks around: a turn the check slows down is kept,
        one it would reverse or replace stops the robot for good (ROTATE at rest: no way, stay still),
        and there is no trap escape (standing still is the intended behaviour, not a trap). ``points``:
        ``_safety_points`` of this tick if at hand (any reach at least the loop's: cut down to it).
        ``trap`` False: no trap detection or escape this tick, and an escape in progress ends.

        The trap escape of a rectangular robot is first a manoeuvre (``manoeuvre``): the quickest sequence
        of arcs and turns in place that heads it within a few degrees of ``want_rad`` (robot frame: where
        the planner or the intention leads; nan: none) with room to drive on, through known free space.
        Its primitives are driven one by one, each until the odometry reaches its planned end, every tick
        through the same check; refused, or over time, the manoeuvre ends and the reactor resumes. Without
        one (a circle turns where it stands: ND+'s own turn is its manoeuvre), the slow straight escape.
        The manoeuvre is also searched, without a trap, when the check has refused every command for
        manoeuvre_after_s without progress (``_held_up``)."""
        p = self.params
        self._looking = False
        prev, self._prev_t_ns = self._prev_t_ns, tick.t_ns
        if prev is not None and (tick.t_ns - prev) / 1e9 > p.supervisor.stale_scan_s:
            return Mode.STALE, 0.0, 0.0, 0.0, flags | Flag.STALE_SCAN
        cell_m = p.grid.cell_m
        reach = safety_reach_m(p.robot, p.supervisor, cell_m)
        if points is None:
            raw, near, grid_xy = self._safety_points(tick, pose, reach)
        else:
            raw, near, grid_xy = points
            near = near[np.hypot(near[:, 0], near[:, 1]) <= reach]
            grid_xy = grid_xy[np.hypot(grid_xy[:, 0], grid_xy[:, 1]) <= reach]
        grid_xy = unconfirmed_cells(grid_xy, near, cell_m)  # once for the up to three checks below
        unknown_xy = partial(self.grid.cell_points, pose, reach, UNKNOWN)
        blind_xy = partial(self._blind_points, tick.scan, pose, reach)
        doubt_xy = partial(self._doubted_points, tick.scan, pose, reach)
        view = _view_rad(tick.scan)

        def check(v: float, vy: float, w: float) -> SafeCommand:
            return safe_command(v, vy, w, near, grid_xy, p.robot, p.supervisor, cell_m=cell_m,
                                unknown_xy=unknown_xy, blind_xy=blind_xy, doubt_xy=doubt_xy, view_rad=view,
                                cells_unconfirmed=True)

        if not trap or mode is Mode.GOAL or unreachable:
            self._escape_left = 0
            self._manoeuvre = ()
            self._refused_since = None
        if self._manoeuvre:
            driven = self._drive_manoeuvre(tick, check)
            if driven is not None:
                return Mode.ESCAPE, driven[0], 0.0, driven[1], flags
        if self._escape_left > 0:
            self._escape_left -= 1
            if check(self._escape_v, 0.0, 0.0).rule is None:
                return Mode.ESCAPE, self._escape_v, 0.0, 0.0, flags
            self._escape_left = 0
        refused = False
        if mode is not Mode.GOAL:
            safe = check(v, vy, w)
            self._looking = safe.looking
            if unreachable and safe.rule not in (None, Mode.SAFE_SLOW):
                self._looked_rad = 2.0 * math.pi
                return Mode.ROTATE, 0.0, 0.0, 0.0, flags
            if safe.rule is not None:
                refused = True
                mode, v, vy, w = safe.rule, safe.v_mps, safe.vy_mps, safe.w_radps
                if safe.rule is Mode.EMERGENCY:
                    flags |= Flag.EMERGENCY_STOP
        held = self._held_up(tick, pose, refused and trap and not unreachable)
        trapped = trap and self._trap.update(mode, w, (pose.x, pose.y, pose.theta), v) and not unreachable
        if trapped:
            flags |= Flag.TRAP_DETECTED
        if (trapped or held) and self._plan_manoeuvre(tick, pose, raw, want_rad):
            self._refused_since = None
            driven = self._drive_manoeuvre(tick, check)
            if driven is not None:
                return Mode.ESCAPE, driven[0], 0.0, driven[1], flags
        if trapped:
            v_esc, possible = escape_command(raw, p.robot, p.supervisor, cell_m=cell_m,
                                             not_free_xy=partial(self._not_free_points, pose))
            if possible and check(v_esc, 0.0, 0.0).rule is None:
                self._escape_left, self._escape_v = p.supervisor.escape_ticks - 1, v_esc
                return Mode.ESCAPE, v_esc, 0.0, 0.0, flags
        return mode, v, vy, w, flags

    def _held_up(self, tick: Tick, pose: Pose2D, refused: bool) -> bool:
        """Whether the reflexive check has refused the command of every tick for manoeuvre_after_s while
        the robot neither moved trap_progress_m nor turned trap_turn_rad (the trap detector's progress):
        the reactor keeps asking for what cannot be done, so the manoeuvre is searched before a full trap
        window of dithering has passed. The count restarts once it has answered."""
        if not refused:
            self._refused_since = None
            return False
        if self._refused_since is None:
            self._refused_since = (tick.t_ns, pose)
            return False
        t0, p0 = self._refused_since
        sp = self.params.supervisor
        if (tick.t_ns - t0) * 1e-9 < sp.manoeuvre_after_s:
            return False
        self._refused_since = None
        return no_progress((p0.x, p0.y, p0.theta), (pose.x, pose.y, pose.theta), sp)

    def _plan_manoeuvre(self, tick: Tick, pose: Pose2D, raw: NDArray[np.float64], want_rad: float) -> bool:
        """Search the trap escape's manoeuvre (``manoeuvre.plan_manoeuvre``) and hold it; False when the
        robot is a circle, there is no wanted direction, the search is off or finds none. Obstacles: the
        raw scan's hits, the edge of the grid's known free space (``free_border_points``, those the scan
        does not confirm, grown by half a cell) and the pose doubt's moved cells, within reach."""
        p = self.params
        nodes = p.supervisor.manoeuvre_nodes
        if p.robot.shape == "circle" or not math.isfinite(want_rad) or nodes == 0:
            return False
        mp = ManoeuvreParams(max_nodes=nodes)
        cell_m, margin = p.grid.cell_m, p.supervisor.emergency_margin_m
        radius = mp.radius_m + p.robot.outer_radius_m + mp.room_m + margin + cell_m
        scan = raw[np.hypot(raw[:, 0], raw[:, 1]) <= radius]
        cells = np.vstack([unconfirmed_cells(self.grid.free_border_points(pose, radius), scan, cell_m),
                           self._doubted_points(tick.scan, pose, radius)])
        margins = np.concatenate([np.full(scan.shape[0], margin),
                                  np.full(cells.shape[0], margin + 0.5 * cell_m)])
        speeds = self._manoeuvre_speeds()
        sequence = plan_manoeuvre(np.vstack([scan, cells]), margins, p.robot, want_rad, mp, speeds)
        if sequence is None:
            return False
        odom = tick.odom.as_array()
        self._manoeuvre, self._manoeuvre_ends = sequence, compose(odom, end_poses(sequence))
        planned_s = sum(speeds.duration_s(q) for q in sequence)
        self._manoeuvre_until_ns = tick.t_ns + round((MANOEUVRE_TIME_FACTOR * planned_s + 1.0) * 1e9)
        return True

    def _drive_manoeuvre(self, tick: Tick,
                         check: Callable[[float, float, float], SafeCommand]) -> tuple[float, float] | None:
        """(v, w) out for the manoeuvre in progress this tick, through the reflexive ``check``: its
        current primitive's command, or the check's SAFE_SLOW of it (the same arc, slower: near a
        primitive's end the braking horizon looks past it, where the plan did not look). None, and the
        manoeuvre ends: it is over, or the check replaces the command otherwise."""
        cmd = self._manoeuvre_step(tick)
        if cmd is not None:
            safe = check(cmd[0], 0.0, cmd[1])
            if safe.rule is None or safe.rule is Mode.SAFE_SLOW:
                return safe.v_mps, safe.w_radps
        self._manoeuvre = ()
        return None

    def _manoeuvre_step(self, tick: Tick) -> tuple[float, float] | None:
        """(v, w) of the manoeuvre's current primitive at the manoeuvre's speeds (``_manoeuvre_speeds``;
        an arc keeps its curvature). A primitive is over once the odometry has reached its planned end
        (within 1 cm / 1 deg, or past it); the ends are absolute, so a tick's overshoot does not add up.
        None: the manoeuvre is over (done, or past its time)."""
        if tick.t_ns > self._manoeuvre_until_ns:
            self._manoeuvre = ()
        odom = tick.odom.as_array()
        while self._manoeuvre:
            q, rest = self._manoeuvre[0], relative(odom, self._manoeuvre_ends[0])
            left = (math.copysign(1.0, q.dth_rad) * rest[2] if q.ds_m == 0.0
                    else math.copysign(1.0, q.ds_m) * rest[0])
            if left > (MANOEUVRE_DONE_RAD if q.ds_m == 0.0 else MANOEUVRE_DONE_M):
                break
            self._manoeuvre, self._manoeuvre_ends = self._manoeuvre[1:], self._manoeuvre_ends[1:]
        if not self._manoeuvre:
            return None
        return self._manoeuvre_speeds().twist(self._manoeuvre[0])

    def _manoeuvre_speeds(self) -> Speeds:
        """The manoeuvre's speeds: forward at half the top speed (a few decimetres in known free space,
        every tick checked), reverse at the escape's creep (the blind side rule's limit for a front
        laser's robot backing, ``safe_command``), both no faster than the sharpest arc allows within
        wmax; turns in place at ROTATE's rate."""
        p = self.params
        arc_max = p.robot.wmax_radps / max(abs(k) for k in ManoeuvreParams().curvatures)  # w within wmax
        return Speeds(forward_mps=min(MANOEUVRE_FORWARD_FRAC * p.robot.vmax_mps, arc_max),
                      reverse_mps=min(p.supervisor.escape_v_frac * p.robot.vmax_mps, arc_max),
                      turn_radps=p.supervisor.rotate_w_frac * p.robot.wmax_radps)


MANOEUVRE_DONE_M = 0.01
MANOEUVRE_DONE_RAD = math.radians(1.0)
"""A manoeuvre's primitive is over within this of its planned end (``NavigationStack._manoeuvre_step``)."""
MANOEUVRE_FORWARD_FRAC = 0.5
"""A manoeuvre's forward speed, as a fraction of vmax (``NavigationStack._manoeuvre_speeds``)."""
MANOEUVRE_TIME_FACTOR = 3.0
"""A manoeuvre ends at this many times its planned duration, plus a second, whatever is left of it."""

DOUBT_TRACK_NS = 250_000_000
"""Spacing of the ticks the pose-doubt track keeps (0.25 s: a 40 Hz log's 300 s window holds 1200, not
12000; ``NavigationStack._follow_track``)."""

_Points = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
"""A tick's obstacles for the safety checks (robot frame): all raw scan hits, the hits within a reach, the
grid's occupied cell centres within it (``NavigationStack._safety_points``)."""

# the mode column of a tick the desired module or a local strategy commanded unchanged (ND+ as local
# navigation reports its own mND / ROTATE); ``active_mode`` names the module that won in any case
_MODULE_MODE: dict[str, Mode] = {"teleop": Mode.TELEOP, "follow": Mode.FOLLOW, "local": Mode.LOCAL}


TELEOP_REACH = 4.0
"""How far a takeover's target may lie along the driver's command, in look-ahead distances."""
TELEOP_REAIM_RAD = 0.25 * math.pi
"""A held takeover target is aimed again when the driver's intention points this far from it [rad]
(**choice**: a quarter turn is a new request, a counter-steer is not)."""
ND_MEMORY_RESET_RAD = 0.25 * math.pi
"""ND+'s commitment is dropped when its target's world bearing moves this far in one tick [rad]
(**choice**: a new target, e.g. a re-aimed takeover or a new route)."""


def _intention_changed(a: tuple[float, float, float], b: tuple[float, float, float],
                       held_rel: NDArray[np.float64], rel: NDArray[np.float64]) -> bool:
    """The driver asked for something else: the direction of travel reversed (a sign of v or vy changed),
    or the new command's intention (robot frame) points more than ``TELEOP_REAIM_RAD`` away from the held
    target. Compared as bearings, not as commands: a driver who counter-steers while local navigation turns
    the robot away from his line changes w, even its sign, yet still points at the same place; re-aiming
    then would swing the target from side to side with the robot and ND+ would dither in front of the
    obstacle (teleop_into_wall)."""
    if any(np.sign(x) != np.sign(y) for x, y in zip(a[:2], b[:2], strict=True)):
        return True
    diff = dm.atan2(rel[1], rel[0]) - dm.atan2(held_rel[1], held_rel[0])
    return abs(math.remainder(diff, math.tau)) > TELEOP_REAIM_RAD


def teleop_command(cmd: Command | None, robot: RobotConfig, *, t_ns: int | None = None,
                   timeout_s: float = math.inf) -> tuple[float, float, float, str]:
    """(v, vy, w, reason) of a teleoperation command: clipped to the robot's velocity limits (vy only for
    a holonomic base); none, one not finite, or one older than ``timeout_s`` at time ``t_ns`` (a driver who
    let go, a log whose commands stopped: ``Tick.cmd`` is the last one at or before the tick) is standing
    still with the reason ("teleop: no command", "teleop: command stale")."""
    if cmd is None:
        return 0.0, 0.0, 0.0, "teleop: no command"
    if t_ns is not None and (t_ns - cmd.t_ns) / 1e9 > timeout_s:
        return 0.0, 0.0, 0.0, "teleop: command stale"
    if not (math.isfinite(cmd.v_mps) and math.isfinite(cmd.vy_mps) and math.isfinite(cmd.w_radps)):
        return 0.0, 0.0, 0.0, "teleop: command not finite"
    vmax, wmax = robot.vmax_mps, robot.wmax_radps
    vy = min(max(cmd.vy_mps, -vmax), vmax) if robot.drive == "holonomic" else 0.0
    return min(max(cmd.v_mps, -vmax), vmax), vy, min(max(cmd.w_radps, -wmax), wmax), ""


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
        scan = Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=8.0)
        for cmd in (Command(k, v, 0.0), Command(k, -v, 0.5 * w), None):
            pose = Pose2D(0.0, 0.0, 0.0)
            stack.step(Tick(index=k, t_ns=k, scan=scan, odom=pose, cmd=cmd), pose, (3.0, 0.5))
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
    PLANNERS[params.planner.kind].warm_up(params.planner.settings, params.grid.size_cells)


def _view_rad(scan: Scan) -> tuple[float, float]:
    """The laser's field of view in the robot frame: its first and last beam bearings [rad]."""
    th = scan.sensor_pose.theta
    return th + float(np.min(scan.angles_rad)), th + float(np.max(scan.angles_rad))


def _finite(x: float) -> float:
    """No NaN ever leaves the stack: a non-finite command component becomes 0 (stop)."""
    return float(x) if math.isfinite(x) else 0.0

