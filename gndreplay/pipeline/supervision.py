"""The supervisor: one object per stack that owns the state GND's rules and the reflexive loop act on.

Per tick the stack calls ``observe`` once the scan is in the model (the stale-data timer, the pose-doubt
track) and ``supervise`` with the command its modules propose; the mode selector asks ``obstacles`` first
for the same obstacles the reflexive loop then checks. The supervisor reads the robot-centred grid (shared
with the stack, never written here) and keeps: the trap detector, the escape and the manoeuvre in progress,
the pose-doubt track, the stale-data timer, GND's unreachable-goal count and ROTATE's turn direction. The
rules themselves are the pure functions of ``supervisor``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from itertools import pairwise
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..geometry import compose, relative, transform_points
from ..robot import RobotConfig
from ..types import Command, Flag, Mode, Pose2D, Scan
from .manoeuvre import ManoeuvreParams, Primitive, Speeds, end_poses, plan_manoeuvre
from .model import OCCUPIED, UNKNOWN, RobotCentredGrid
from .supervisor import (
    SafeCommand,
    SupervisorParams,
    blind_points,
    doubt_transforms,
    doubted_cells,
    escape_command,
    no_progress,
    rotate_command,
    safe_command,
    safety_reach_m,
    seen_through,
    unconfirmed_cells,
)

__all__ = [
    "DOUBT_TRACK_NS", "MANOEUVRE_DONE_M", "MANOEUVRE_DONE_RAD", "MANOEUVRE_FORWARD_FRAC",
    "MANOEUVRE_TIME_FACTOR", "GndGoal", "Obstacles", "PoseTrack", "Proposal", "Supervisor", "TrapDetector",
    "Verdict",
]

MANOEUVRE_DONE_M = 0.01
MANOEUVRE_DONE_RAD = math.radians(1.0)
"""A manoeuvre's primitive is over within this of its planned end (``Supervisor._manoeuvre_step``)."""
MANOEUVRE_FORWARD_FRAC = 0.5
"""A manoeuvre's forward speed, as a fraction of vmax (``Supervisor._manoeuvre_speeds``)."""
MANOEUVRE_TIME_FACTOR = 3.0
"""A manoeuvre ends at this many times its planned duration, plus a second, whatever is left of it."""

DOUBT_TRACK_NS = 250_000_000
"""Spacing of the ticks the pose-doubt track keeps (0.25 s: a 40 Hz log's 300 s window holds 1200, not
12000; ``PoseTrack.follow``)."""


class Obstacles(NamedTuple):
    """A tick's obstacles for the safety checks (robot frame): all raw scan hits, the hits within a reach,
    the grid's occupied cell centres within it."""

    raw_xy: NDArray[np.float64]
    near_xy: NDArray[np.float64]
    grid_xy: NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class GndGoal:
    """GND's goal this tick, for the rules it adds to the reflexive loop.

    Attributes:
        goal_xy: the goal in the robot frame (ROTATE turns towards it; within goal_tolerance_m: GOAL).
        no_way: the planner found no path to the goal and ND+ towards the goal itself did not connect it
            either (``NavigationStack._no_way``): counted towards holding the goal unreachable.
        world_xy: the goal in the corrected world frame (which goal it is, ``GoalArrival``).
    """

    goal_xy: NDArray[np.float64]
    no_way: bool
    world_xy: tuple[float, float]


@dataclass(frozen=True, slots=True, eq=False)
class Proposal:
    """The command the stack's modules propose for one tick, and what the supervisor judges it by.

    Attributes:
        mode: the mode that produced it (GND's mpND / mND / ROTATE, a module's TELEOP / FOLLOW / LOCAL /
            ROTATE, GOAL).
        command: the proposed command.
        flags: the exception flags raised so far this tick.
        want_rad: where the robot wants to head (robot frame; the manoeuvre's heading); nan: nowhere.
        trap: trap detection and escape this tick (False: a driver's command; an escape in progress ends).
        reflexive: False: the command goes out unchanged (the mode selector switched off).
        gnd: GND's goal, for GND's rules (unreachable goal, enforced reactor budget, goal reached); None
            outside GND.
    """

    mode: Mode
    command: Command
    flags: Flag = Flag.NONE
    want_rad: float = math.nan
    trap: bool = True
    reflexive: bool = True
    gnd: GndGoal | None = None


@dataclass(frozen=True, slots=True)
class Verdict:
    """What goes out: the command (finite: a non-finite component becomes 0, stop), the mode that produced
    it (a reflexive override's rule, or the proposal's), the flags, and whether the reflexive check
    replaced the command by the blind side's turn first (``looking``)."""

    command: Command
    mode: Mode
    flags: Flag
    looking: bool = False


class TrapDetector:
    """Trap conditions over a sliding window of ticks.

    The multi-loop paper's: repeated stopped rotations (ROTATE) to the left and right, or frequent
    imminent collisions (EMERGENCY). And dithering, whatever the mode (mpND, mND, the safety rules):
    within a full window, the turn direction (|w| >= trap_w_frac * wmax) and the direction of travel
    (|v| >= trap_w_frac * vmax) reverse at least trap_count times together while the robot neither moved
    trap_progress_m nor turned trap_turn_rad net. Rocking forward and back without turning (a chair wedged
    between a wall ahead and obstacles beside it, w = 0) is the same stall as turning left and right.
    ``update`` returns True when a trap holds and then starts a new window.
    """

    def __init__(self, params: SupervisorParams, wmax_radps: float = 1.0, vmax_mps: float = 1.0) -> None:
        self._p = params
        self._w_min = params.trap_w_frac * wmax_radps
        self._v_min = params.trap_w_frac * vmax_mps
        self._events: deque[int] = deque(maxlen=params.trap_window)  # -1/+1 rotation, 2 emergency, 0 else
        self._turns: deque[int] = deque(maxlen=params.trap_window)  # -1/+1 turning in any mode, 0 else
        self._drives: deque[int] = deque(maxlen=params.trap_window)  # -1/+1 driving back / forward, 0 else
        self._poses: deque[tuple[float, float, float]] = deque(maxlen=params.trap_window)

    def update(self, mode: Mode, w_radps: float, pose: tuple[float, float, float] | None = None,
               v_mps: float = 0.0) -> bool:
        """Record one tick (its final mode, turn rate and, for the dithering rule, the robot pose
        (x, y, theta) in any fixed frame and the forward speed); True when the window holds a trap."""
        if mode is Mode.ROTATE:
            self._events.append(1 if w_radps >= 0 else -1)
        elif mode is Mode.EMERGENCY:
            self._events.append(2)
        else:
            self._events.append(0)
        turning = abs(w_radps) >= self._w_min and mode is not Mode.GOAL
        self._turns.append((1 if w_radps > 0 else -1) if turning else 0)
        driving = abs(v_mps) >= self._v_min and mode is not Mode.GOAL
        self._drives.append((1 if v_mps > 0 else -1) if driving else 0)
        if pose is not None:
            self._poses.append(pose)
        emergencies = self._events.count(2)
        rot = [e for e in self._events if e == 1 or e == -1]
        trapped = emergencies >= self._p.trap_count or (
            len(rot) >= self._p.trap_count and _changes(rot) >= 2
        ) or self._dithering()
        if trapped:
            self._events.clear()
            self._turns.clear()
            self._drives.clear()
            self._poses.clear()
        return trapped

    def _dithering(self) -> bool:
        """A full window of poses with trap_count reversals of turn and travel direction and no progress."""
        if len(self._poses) < self._p.trap_window:
            return False
        if _reversals(self._turns) + _reversals(self._drives) < self._p.trap_count:
            return False
        return no_progress(self._poses[0], self._poses[-1], self._p)


def _reversals(signs: deque[int]) -> int:
    """Sign changes in a sequence of -1 / 0 / +1, the zeros skipped."""
    return _changes([a for a in signs if a != 0])


def _changes(values: list[int]) -> int:
    """How many times a sequence changes value from one element to the next (a window of a few dozen
    ticks: plain Python beats numpy's per-call overhead)."""
    return sum(1 for a, b in pairwise(values) if a != b)


class PoseTrack:
    """Stamps, corrected poses and odometry of ticks within doubt_window_s, oldest first: what the pose
    doubt of the grid's cells is judged by (``supervisor.doubt_transforms``). Bounded: one tick kept per
    DOUBT_TRACK_NS."""

    def __init__(self, window_s: float) -> None:
        self._window_s = window_s
        cap = math.ceil(window_s * 1e9 / DOUBT_TRACK_NS) + 2
        self._ns = np.zeros(cap, dtype=np.int64)
        self._c = np.zeros((cap, 3))
        self._o = np.zeros((cap, 3))
        self._n = 0

    def __len__(self) -> int:
        return self._n

    @property
    def t_ns(self) -> NDArray[np.int64]:
        """(N,) stamps of the ticks kept, oldest first."""
        return self._ns[: self._n]

    @property
    def corrected(self) -> NDArray[np.float64]:
        """(N, 3) their corrected poses."""
        return self._c[: self._n]

    @property
    def odom(self) -> NDArray[np.float64]:
        """(N, 3) their odometry poses."""
        return self._o[: self._n]

    def follow(self, t_ns: int, pose: Pose2D, odom: Pose2D) -> None:
        """Put this tick's corrected pose and odometry at the end of the track: one tick kept per
        DOUBT_TRACK_NS, the newest always last (it replaces a last one kept less than that after its
        predecessor), none older than doubt_window_s. A tick stamped before the last one (a log that
        restarts) starts the track anew."""
        t, n = self._ns, self._n
        if n and t[n - 1] > t_ns:
            n = 0
        if n >= 2 and t[n - 1] - t[n - 2] < DOUBT_TRACK_NS:
            n -= 1
        old = int(np.searchsorted(t[:n], t_ns - round(self._window_s * 1e9)))
        if old or n == t.shape[0]:  # drop the ticks past the window (and, if full, the oldest)
            old = max(old, 1)
            for a in (t, self._c, self._o):
                a[: n - old] = a[old:n]
            n -= old
        t[n] = t_ns
        self._c[n] = (pose.x, pose.y, pose.theta)
        self._o[n] = (odom.x, odom.y, odom.theta)
        self._n = n + 1


@dataclass(frozen=True, slots=True, eq=False)
class _Sensed:
    """What ``observe`` was given this tick: the scan (its stamp is the tick's time), the corrected pose,
    the odometry."""

    scan: Scan
    pose: Pose2D
    odom: Pose2D


_GOAL_PROGRESS_M = 0.02
"""Progress towards the goal that restarts ``GoalArrival``'s settling time [m]."""
_GOAL_MOVED_M = 0.01
"""A goal that moves this far in the world is a new goal for ``GoalArrival`` [m]."""


class GoalArrival:
    """Whether the goal is reached, tick by tick (``SupervisorParams.goal_arrive_frac``, ``goal_settle_s``):
    within goal_arrive_frac x goal_tolerance_m of it at once; within goal_tolerance_m once the distance has
    not shrunk by ``_GOAL_PROGRESS_M`` for goal_settle_s (the robot cannot get closer: a goal beside an
    obstacle). Once reached it stays reached while the robot is within the tolerance of the same goal, so
    the pose estimate's jitter about the inner radius does not restart the robot."""

    def __init__(self, params: SupervisorParams) -> None:
        self.params = params
        self._goal: tuple[float, float] | None = None  # world goal of the last tick
        self._best = math.inf  # the smallest distance within the tolerance so far
        self._since_ns = 0  # when it last shrank by _GOAL_PROGRESS_M
        self._reached = False

    def update(self, goal_xy: NDArray[np.float64], world: tuple[float, float], t_ns: int) -> bool:
        """The goal at ``goal_xy`` in the robot frame, ``world`` in the world, at tick time ``t_ns``: is it
        reached?"""
        p = self.params
        d = math.hypot(goal_xy[0], goal_xy[1])
        moved = self._goal is None or math.hypot(world[0] - self._goal[0], world[1] - self._goal[1]) > (
            _GOAL_MOVED_M)
        self._goal = world
        if moved or d > p.goal_tolerance_m:
            self._best, self._reached = math.inf, False
            if d > p.goal_tolerance_m:
                return False
        if d < self._best - _GOAL_PROGRESS_M:
            self._best, self._since_ns = d, t_ns
        settled = (t_ns - self._since_ns) * 1e-9 >= p.goal_settle_s
        self._reached = self._reached or d <= p.goal_arrive_frac * p.goal_tolerance_m or settled
        return self._reached


class Supervisor:
    """GND's rules after the reactor and the reflexive loop, with the state they carry between ticks.

    ``observe(scan, pose, odom)`` starts a tick, once the scan is in the grid: the gap to the previous
    scan (stale data) and the pose-doubt track. ``supervise(proposal)`` ends it:

    - GND (``proposal.gnd``): the goal held unreachable once, for unreachable_ticks in a row, the tick has
      no way to it (ROTATE one full turn, then stop; any way ends it), ROTATE's turn rate (``rotate_w``),
      the enforced reactor budget (stop), the goal reached (GOAL).
    - The reflexive loop (``proposal.reflexive``): stale data, a command whose swept footprint would touch
      an obstacle of the raw scan or the grid (replaced by ``safe_command``'s rule, recorded as the mode),
      trap escape.

    The mode selector asks ``obstacles`` for the obstacles its swept-area test and the reflexive loop
    share; local navigation asks ``rotate_w`` for ROTATE's turn. The grid is the stack's, only read here.
    """

    def __init__(self, robot: RobotConfig, params: SupervisorParams, grid: RobotCentredGrid) -> None:
        self.robot = robot
        self.params = params
        self._grid = grid
        self._cell_m = grid.params.cell_m
        self._sensed: _Sensed | None = None
        self._prev_t_ns: int | None = None
        self._stale = False  # this tick's scan came more than stale_scan_s after the previous one
        self._track = PoseTrack(params.doubt_window_s)
        self._trap = TrapDetector(params, robot.wmax_radps, robot.vmax_mps)
        self._escape_left = 0
        self._escape_v = 0.0
        # the trap escape's manoeuvre in progress (``_manoeuvre_step``): its primitives still to drive, the
        # odometry pose each is to end at, and the tick stamp by which it must be over
        self._manoeuvre: tuple[Primitive, ...] = ()
        self._manoeuvre_ends = np.zeros((0, 3))
        self._manoeuvre_until_ns = 0
        self._refused_since: tuple[int, Pose2D] | None = None  # stamp and pose of the first of the
        # ticks in a row whose command the reflexive check replaced (``_held_up``)
        self._no_path = 0  # consecutive ticks without a way to GND's goal
        self._looked_rad = 0.0  # turned in place since the goal was held unreachable
        self._prev_theta: float | None = None
        self._rotate_sign = 0.0  # turn direction of the previous tick's ROTATE (0: not rotating)
        self._looking = False  # the last reflexive check replaced the command by the blind side's turn first
        self._arrival = GoalArrival(params)

    def observe(self, scan: Scan, pose: Pose2D, odom: Pose2D) -> None:
        """Start a tick: its scan (whose stamp is the tick's time), corrected pose and odometry pose. Times
        the gap to the previous scan and puts the poses on the pose-doubt track."""
        prev, self._prev_t_ns = self._prev_t_ns, scan.t_ns
        self._stale = prev is not None and (scan.t_ns - prev) / 1e9 > self.params.stale_scan_s
        self._sensed = _Sensed(scan, pose, odom)
        self._track.follow(scan.t_ns, pose, odom)

    def obstacles(self, margin_m: float = 0.0) -> Obstacles:
        """This tick's obstacles within the reflexive loop's reach plus ``margin_m`` (the mode selector's
        margin): computed once, they serve the selector's swept-area test and then ``supervise``."""
        p = self.params
        return self._points(self._now(), safety_reach_m(self.robot, p, self._cell_m) + margin_m)

    def rotate_w(self, toward_xy: NDArray[np.float64]) -> float:
        """ROTATE's turn rate towards ``toward_xy`` (robot frame). The direction is chosen when ROTATE
        starts and kept while it lasts (the turn actually executed, also when the safety check reversed
        it): choosing it afresh every tick flips it each time the bearing crosses 0 or +-pi, a turn that
        never turns."""
        w = rotate_command(dm.atan2(toward_xy[1], toward_xy[0]), self.robot, self.params)
        return abs(w) * self._rotate_sign if self._rotate_sign else w

    def supervise(self, proposal: Proposal, obstacles: Obstacles | None = None) -> Verdict:
        """End the tick: GND's rules (``proposal.gnd``), then the reflexive loop (``proposal.reflexive``;
        ``obstacles``: this tick's ``obstacles`` if at hand, else gathered here at the loop's reach)."""
        s = self._now()
        c = proposal.command
        mode, v, vy, w, flags = proposal.mode, c.v_mps, c.vy_mps, c.w_radps, proposal.flags
        self._looking = False
        unreachable = False
        if proposal.gnd is not None:
            mode, v, vy, w, flags, unreachable = self._gnd(s, mode, v, vy, w, flags, proposal.gnd)
        rotating = mode is Mode.ROTATE
        if proposal.reflexive:
            mode, v, vy, w, flags = self._reflexive(s, mode, v, vy, w, flags, unreachable, obstacles,
                                                    proposal.trap, proposal.want_rad)
        self._rotate_sign = (1.0 if w > 0.0 else -1.0) if rotating and w != 0.0 else 0.0
        return Verdict(Command(s.scan.t_ns, _finite(v), _finite(w), _finite(vy)), mode, flags, self._looking)

    def _now(self) -> _Sensed:
        if self._sensed is None:
            raise RuntimeError("Supervisor: observe() a tick before supervising it")
        return self._sensed

    def _gnd(
        self, s: _Sensed, mode: Mode, v: float, vy: float, w: float, flags: Flag, gnd: GndGoal
    ) -> tuple[Mode, float, float, float, Flag, bool]:
        """GND's rules before the reflexive loop; also whether the goal is held unreachable."""
        p = self.params
        unreachable = self._unreachable(gnd.no_way, s.pose)
        if unreachable:
            mode = Mode.ROTATE
        if mode is Mode.ROTATE:
            v, vy, w = 0.0, 0.0, self.rotate_w(gnd.goal_xy)
            if unreachable and self._looked_rad >= 2.0 * math.pi:
                w = 0.0
        if p.enforce_budgets and flags & Flag.REACTOR_OVER_BUDGET:
            v, vy, w = 0.0, 0.0, 0.0
        if self.at_goal(gnd.goal_xy, gnd.world_xy):
            mode, v, vy, w = Mode.GOAL, 0.0, 0.0, 0.0
            flags |= Flag.GOAL_REACHED
        return mode, v, vy, w, flags, unreachable

    def at_goal(self, goal_xy: NDArray[np.float64], world_xy: tuple[float, float]) -> bool:
        """Whether this tick's goal (``goal_xy`` in the robot frame, ``world_xy`` in the world) is reached
        (``GoalArrival``); once per tick."""
        return self._arrival.update(goal_xy, world_xy, self._now().scan.t_ns)

    def _unreachable(self, no_way: bool, pose: Pose2D) -> bool:
        """True once, for unreachable_ticks in a row, the tick has had no way to the goal (``GndGoal``):
        the goal is held unreachable (GND: mND did not connect it; ROTATE, one full turn, then stop). Any
        way ends it. Tracks how far the robot turned since, from the corrected pose."""
        prev, self._prev_theta = self._prev_theta, pose.theta
        if not no_way:
            self._no_path, self._looked_rad = 0, 0.0
            return False
        self._no_path += 1
        if self._no_path <= self.params.unreachable_ticks:
            return False
        if prev is not None and self._no_path > self.params.unreachable_ticks + 1:
            self._looked_rad += abs(math.remainder(pose.theta - prev, math.tau))
        return True

    def _points(self, s: _Sensed, reach_m: float) -> Obstacles:
        """The obstacles a command can touch (robot frame): all the tick's raw scan hits, those within
        ``reach_m`` of the rotation centre, and the grid's occupied cell centres within ``reach_m``."""
        raw = transform_points(s.scan.sensor_pose.as_array(), s.scan.points())
        near = raw[np.hypot(raw[:, 0], raw[:, 1]) <= reach_m]
        return Obstacles(raw, near, self._grid.occupied_points(s.pose, reach_m))

    def _doubted_points(self, scan: Scan, pose: Pose2D, reach_m: float) -> NDArray[np.float64]:
        """The occupied cells whose pose is in doubt, where they lie if the odometry is right, within
        ``reach_m`` (robot frame; ``supervisor.doubted_cells``: the matcher and the odometry disagree on
        the motion since the cell was last seen), less those the scan sees through (``seen_through``)."""
        track = self._track
        if len(track) < 2 or self.params.doubt_window_s <= 0.0:
            return np.zeros((0, 2))
        transforms, doubted = doubt_transforms(track.corrected, track.odom, self.params)
        if not doubted.any():
            return np.zeros((0, 2))
        # E p = R p + t keeps |R p| = |p|: only cells within reach + |t| can move into reach
        far = reach_m + float(np.max(np.hypot(transforms[doubted, 0], transforms[doubted, 1])))
        cells, seen_ns = self._grid.occupied_points_seen(pose, far)
        moved = doubted_cells(cells, seen_ns, track.t_ns, transforms, doubted)
        moved = moved[np.hypot(moved[:, 0], moved[:, 1]) <= reach_m]
        sp = scan.sensor_pose
        return moved[~seen_through(moved, scan.ranges_m, scan.angles_rad, (sp.x, sp.y, sp.theta),
                                   self._cell_m)]

    def _not_free_points(self, pose: Pose2D, radius_m: float) -> NDArray[np.float64]:
        """Centres (robot frame) of the cells within ``radius_m`` not known FREE (UNKNOWN or OCCUPIED):
        where a backward escape may not go (``supervisor.escape_command``)."""
        return np.vstack([self._grid.cell_points(pose, radius_m, s) for s in (UNKNOWN, OCCUPIED)])

    def _blind_points(self, scan: Scan, pose: Pose2D, radius_m: float) -> NDArray[np.float64]:
        """Centres (robot frame) of the cells within ``radius_m`` on the laser's blind side that no scan
        has seen within blind_memory_s of this scan's stamp (``supervisor.blind_points``)."""
        memory_ns = round(self.params.blind_memory_s * 1e9)
        unseen = self._grid.unseen_points(pose, radius_m, scan.t_ns - memory_ns)
        sp = scan.sensor_pose
        fov = (float(np.min(scan.angles_rad)), float(np.max(scan.angles_rad)))
        return blind_points(unseen, self.robot, (sp.x, sp.y, sp.theta), fov)

    def _reflexive(
        self, s: _Sensed, mode: Mode, v: float, vy: float, w: float, flags: Flag, unreachable: bool,
        points: Obstacles | None, trap: bool, want_rad: float,
    ) -> tuple[Mode, float, float, float, Flag]:
        """The reflexive loop: stale data, a command whose swept footprint would touch an obstacle of the
        raw scan or the grid (replaced by ``safe_command``'s rule, recorded as the mode), trap escape.

        With the goal held unreachable the robot only looks around: a turn the check slows down is kept,
        one it would reverse or replace stops the robot for good (ROTATE at rest: no way, stay still),
        and there is no trap escape (standing still is the intended behaviour, not a trap). ``points``:
        ``obstacles`` of this tick if at hand (any reach at least the loop's: cut down to it).
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
        pose = s.pose
        if self._stale:
            return Mode.STALE, 0.0, 0.0, 0.0, flags | Flag.STALE_SCAN
        cell_m = self._cell_m
        reach = safety_reach_m(self.robot, p, cell_m)
        if points is None:
            raw, near, grid_xy = self._points(s, reach)
        else:
            raw, near, grid_xy = points
            near = near[np.hypot(near[:, 0], near[:, 1]) <= reach]
            grid_xy = grid_xy[np.hypot(grid_xy[:, 0], grid_xy[:, 1]) <= reach]
        grid_xy = unconfirmed_cells(grid_xy, near, cell_m)  # once for the up to three checks below
        unknown_xy = partial(self._grid.cell_points, pose, reach, UNKNOWN)
        blind_xy = partial(self._blind_points, s.scan, pose, reach)
        doubt_xy = partial(self._doubted_points, s.scan, pose, reach)
        view = _view_rad(s.scan)

        def check(v: float, vy: float, w: float) -> SafeCommand:
            return safe_command(v, vy, w, near, grid_xy, self.robot, p, cell_m=cell_m,
                                unknown_xy=unknown_xy, blind_xy=blind_xy, doubt_xy=doubt_xy, view_rad=view,
                                cells_unconfirmed=True)

        if not trap or mode is Mode.GOAL or unreachable:
            self._escape_left = 0
            self._manoeuvre = ()
            self._refused_since = None
        if self._manoeuvre:
            driven = self._drive_manoeuvre(s, check)
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
        held = self._held_up(s, refused and trap and not unreachable)
        trapped = trap and self._trap.update(mode, w, (pose.x, pose.y, pose.theta), v) and not unreachable
        if trapped:
            flags |= Flag.TRAP_DETECTED
        if (trapped or held) and self._plan_manoeuvre(s, raw, want_rad):
            self._refused_since = None
            driven = self._drive_manoeuvre(s, check)
            if driven is not None:
                return Mode.ESCAPE, driven[0], 0.0, driven[1], flags
        if trapped:
            v_esc, possible = escape_command(raw, self.robot, p, cell_m=cell_m,
                                             not_free_xy=partial(self._not_free_points, pose))
            if possible and check(v_esc, 0.0, 0.0).rule is None:
                self._escape_left, self._escape_v = p.escape_ticks - 1, v_esc
                return Mode.ESCAPE, v_esc, 0.0, 0.0, flags
        return mode, v, vy, w, flags

    def _held_up(self, s: _Sensed, refused: bool) -> bool:
        """Whether the reflexive check has refused the command of every tick for manoeuvre_after_s while
        the robot neither moved trap_progress_m nor turned trap_turn_rad (the trap detector's progress):
        the reactor keeps asking for what cannot be done, so the manoeuvre is searched before a full trap
        window of dithering has passed. The count restarts once it has answered."""
        if not refused:
            self._refused_since = None
            return False
        pose = s.pose
        if self._refused_since is None:
            self._refused_since = (s.scan.t_ns, pose)
            return False
        t0, p0 = self._refused_since
        sp = self.params
        if (s.scan.t_ns - t0) * 1e-9 < sp.manoeuvre_after_s:
            return False
        self._refused_since = None
        return no_progress((p0.x, p0.y, p0.theta), (pose.x, pose.y, pose.theta), sp)

    def _plan_manoeuvre(self, s: _Sensed, raw: NDArray[np.float64], want_rad: float) -> bool:
        """Search the trap escape's manoeuvre (``manoeuvre.plan_manoeuvre``) and hold it; False when the
        robot is a circle, there is no wanted direction, the search is off or finds none. Obstacles: the
        raw scan's hits, the edge of the grid's known free space (``free_border_points``, those the scan
        does not confirm, grown by half a cell) and the pose doubt's moved cells, within reach."""
        robot, pose = self.robot, s.pose
        nodes = self.params.manoeuvre_nodes
        if robot.shape == "circle" or not math.isfinite(want_rad) or nodes == 0:
            return False
        mp = ManoeuvreParams(max_nodes=nodes)
        cell_m, margin = self._cell_m, self.params.emergency_margin_m
        radius = mp.radius_m + robot.outer_radius_m + mp.room_m + margin + cell_m
        scan = raw[np.hypot(raw[:, 0], raw[:, 1]) <= radius]
        cells = np.vstack([unconfirmed_cells(self._grid.free_border_points(pose, radius), scan, cell_m),
                           self._doubted_points(s.scan, pose, radius)])
        margins = np.concatenate([np.full(scan.shape[0], margin),
                                  np.full(cells.shape[0], margin + 0.5 * cell_m)])
        speeds = self._manoeuvre_speeds()
        sequence = plan_manoeuvre(np.vstack([scan, cells]), margins, robot, want_rad, mp, speeds)
        if sequence is None:
            return False
        odom = s.odom.as_array()
        self._manoeuvre, self._manoeuvre_ends = sequence, compose(odom, end_poses(sequence))
        planned_s = sum(speeds.duration_s(q) for q in sequence)
        self._manoeuvre_until_ns = s.scan.t_ns + round((MANOEUVRE_TIME_FACTOR * planned_s + 1.0) * 1e9)
        return True

    def _drive_manoeuvre(self, s: _Sensed,
                         check: Callable[[float, float, float], SafeCommand]) -> tuple[float, float] | None:
        """(v, w) out for the manoeuvre in progress this tick, through the reflexive ``check``: its
        current primitive's command, or the check's SAFE_SLOW of it (the same arc, slower: near a
        primitive's end the braking horizon looks past it, where the plan did not look). None, and the
        manoeuvre ends: it is over, or the check replaces the command otherwise."""
        cmd = self._manoeuvre_step(s)
        if cmd is not None:
            safe = check(cmd[0], 0.0, cmd[1])
            if safe.rule is None or safe.rule is Mode.SAFE_SLOW:
                return safe.v_mps, safe.w_radps
        self._manoeuvre = ()
        return None

    def _manoeuvre_step(self, s: _Sensed) -> tuple[float, float] | None:
        """(v, w) of the manoeuvre's current primitive at the manoeuvre's speeds (``_manoeuvre_speeds``;
        an arc keeps its curvature). A primitive is over once the odometry has reached its planned end
        (within 1 cm / 1 deg, or past it); the ends are absolute, so a tick's overshoot does not add up.
        None: the manoeuvre is over (done, or past its time)."""
        if s.scan.t_ns > self._manoeuvre_until_ns:
            self._manoeuvre = ()
        odom = s.odom.as_array()
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
        robot, p = self.robot, self.params
        arc_max = robot.wmax_radps / max(abs(k) for k in ManoeuvreParams().curvatures)  # w within wmax
        return Speeds(forward_mps=min(MANOEUVRE_FORWARD_FRAC * robot.vmax_mps, arc_max),
                      reverse_mps=min(p.escape_v_frac * robot.vmax_mps, arc_max),
                      turn_radps=p.rotate_w_frac * robot.wmax_radps)


def _view_rad(scan: Scan) -> tuple[float, float]:
    """The laser's field of view in the robot frame: its first and last beam bearings [rad]."""
    th = scan.sensor_pose.theta
    return th + float(np.min(scan.angles_rad)), th + float(np.max(scan.angles_rad))


def _finite(x: float) -> float:
    """No NaN ever leaves the supervisor: a non-finite command component becomes 0 (stop)."""
    return float(x) if math.isfinite(x) else 0.0
