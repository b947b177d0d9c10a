"""GND supervision and the reflexive loop of the multi-loop architecture.

GND (Minguez & Montano) chooses one of three modes per tick from what the planner and the reactor
return: mpND (planner OK: the reactor steers to the instantaneous path direction), mND (planner failed:
the reactor steers to the goal itself) and ROTATE (no free walking area: stop and rotate until the model
changes). The multi-loop paper adds a reflexive loop below them that overrides everything: brake on an
imminent collision, stop on stale sensor data, and escape a trap (repeated stopped rotations or
emergencies) with a slow straight motion where there is room: ahead in the scan, else behind in the grid
(``escape_command`` can try backward first; the supervisor always tries forward first).

The collision check (``safe_command``) sweeps the real footprint (rectangle or circle) along the commanded
arc over the braking horizon the robot's acceleration limits give, against the raw current scan *and* the
grid's occupied cells (the wheelchair's laser sees only its front half: what it passes while turning was
seen earlier, and is only in the grid). A command that would touch is replaced by the first admissible one
of: a slower arc, no turn or the other turn direction, a short reverse through grid cells known FREE, and
only then a stop; the tick's mode says which rule fired (SAFE_SLOW, SAFE_TURN, SAFE_REVERSE, EMERGENCY).

The blind side (``blind_points``): the grid's FREE is what the laser saw *when it last looked*. In front
the scan refreshes it every tick; behind a front laser it may be seconds old, and a person may have walked
in since - neither the scan nor the grid then holds them. So translation whose leading edge is on the blind
side must not approach cells the laser has not seen within ``blind_memory_s`` (UNKNOWN ones included): the
unseen space counts as not free for that motion (a holonomic base turns first to look; a differential one,
which cannot look behind, creeps). The reactor (GND/ND) stays purely sensor-based; this is
the reflexive loop refusing to move where the sensor has no recent word.

These are the rules, as pure functions; the state they act on from tick to tick (the trap window, the
escape and the manoeuvre in progress, the pose-doubt track, the stale-data timer) is ``supervision``'s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .. import detmath as dm
from ..geometry import compose, inverse, relative, wrap_angle
from ..robot import RobotConfig
from ..types import Flag, Mode

F64 = NDArray[np.float64]

__all__ = [
    "SafeCommand",
    "SupervisorParams",
    "arc_poses",
    "arc_touches",
    "blind_points",
    "braking_time_s",
    "budget_flags",
    "doubt_transforms",
    "doubted_cells",
    "escape_command",
    "footprint_contains",
    "footprint_distance_at",
    "footprint_signed_distance",
    "gnd_mode",
    "kernel_points",
    "no_progress",
    "rotate_command",
    "safe_command",
    "safety_reach_m",
    "seen_through",
    "straight_min_m",
    "swept_collision",
    "swept_touch",
    "unconfirmed_cells",
]


@dataclass(frozen=True, slots=True)
class SupervisorParams:
    """Supervisor constants.

    Attributes:
        budget_match_s, budget_model_s, budget_planner_s, budget_reactor_s: per-module time-outs (the
            wheelchair paper: model 0.05 s, planner 0.08 s, reactor 0.02 s; matching is part of the model
            builder in the paper, so its budget is reported separately with the same order of magnitude).
        enforce_budgets: False (default, **choice**) reports *_OVER_BUDGET flags without changing the
            result, so replays are deterministic; True applies the papers' exception path (a planner over
            budget counts as a planner failure, a reactor over budget stops the vehicle for the tick).
        rotate_w_frac: turn rate of ROTATE, as a fraction of wmax (**choice**: 0.5).
        goal_tolerance_m: distance within which the goal counts as reached (the task's tolerance).
        goal_arrive_frac, goal_settle_s: when, within the tolerance, the robot stops (``supervision.
            GoalArrival``): at once within goal_arrive_frac x goal_tolerance_m, else once its distance has
            not shrunk by 2 cm for goal_settle_s (a goal beside an obstacle). **Choice**: 0.5 and 1 s. The
            papers stop at the tolerance's edge, which hands the whole pose error to the result: the
            compact base at 0.5 m/s stopped believing it was 0.3 m from the goal and was 0.31 to 0.44 m
            from it in 15 of 150 obstacle-field runs. 1.0 is the papers' rule.
        stale_scan_s: a scan older than this at tick time (gap to the previous scan) stops the robot.
        reaction_s: time the command is held before braking starts in the swept-area check (**choice**:
            0.3 s, more than a scan period of both presets).
        emergency_margin_m: extra margin around the footprint in the swept-area check.
        trap_window: number of recent ticks inspected for a trap.
        trap_count: stopped rotations with alternating sign, or emergencies, within the window that
            make a trap (the multi-loop paper's "repetitive stopped rotation"); also, in any mode, this
            many turn-direction reversals within a full window without progress (dithering).
        trap_progress_m, trap_turn_rad: progress that clears a dithering window: the robot moved at least
            this far, or turned at least this much net, between the window's first and last tick
            (**choice**: 0.2 m and 45 deg, the issue's stall definition).
        trap_w_frac: a tick counts as turning for the dithering rule when |w| >= this fraction of wmax,
            as driving when |v| >= this fraction of vmax (**choice**: 0.1; smaller steering corrections
            and creeping are not dithering).
        unreachable_ticks: consecutive ticks of PLANNER_NO_PATH to a goal inside the grid (the goal's free
            region and the robot's are not connected in the model) after which the goal is held
            unreachable: GND's ROTATE for one full turn in place (to look around), then stop, until a plan
            exists again (**choice**: 25, 5 s for the wheelchair's 5 Hz laser).
        escape_ticks: how many ticks the escape motion lasts once triggered.
        trap_window_s, unreachable_s, escape_s: the three tick counts above as durations [s]; when given,
            the configuration turns each into ticks of its laser period (``Config.stack_params``:
            ``max(1, round(duration / period_s))``, the trap window at least ``trap_count``). None (the
            default): the counts as given, which assume the papers' 5 Hz cycle.
        brake_lag: the braking horizon (``braking_time_s``) also covers the drive's lag: a first-order
            response of time constant tau brakes tau later than commanded, so the horizon grows by
            ``max(tau_v_s, tau_w_s)``. False (the default): the papers' horizon (reaction and ramp).
        escape_v_frac: escape speed, and speed of the safety check's short reverse, as a fraction of vmax
            (**choice**: 0.3).
        escape_clearance_m: free distance the raw scan must show ahead/behind to escape that way.
        manoeuvre_nodes: the rectangular robot's trap escape is first a manoeuvre searched over this many
            lattice expansions at most (``manoeuvre``; **choice**: 1500, tens of ms); 0: the straight
            escape only.
        manoeuvre_after_s: ... and searched already when the reflexive check has replaced every command
            for this long without progress (see ``trap_progress_m``; **choice**: 2 s, a quarter of the
            wheelchair's trap window: the trap's dithering rule needs a full window, and the closed-loop
            scenarios' stall bound is 10 s).
        blind_memory_s: how long a cell outside the laser's current field of view stays trusted as free
            after the laser last saw it, for translation towards it (``safe_command``'s blind side rule).
            **Choice**: 1.0 s, five to seven scans of the presets: a person walking at 1 m/s covers 1 m
            in it, so a cell seen free that recently can only hold someone who was then within about a
            metre of it; a holonomic base that turns to look where it goes (turn first) refreshes the
            cells in a fraction of that. Older FREE cells out of view are old news (in a scenario the XR4000
            backed at 0.45 m/s into a person who had walked in behind it since the laser last looked).
            0 trusts no cell out of view; a huge value counts only UNKNOWN cells.
        doubt_window_s, doubt_tol_m, doubt_tol_frac: the pose doubt (``doubted_cells``). The grid is
            built at the matcher's corrected poses; where the corrected motion since a cell was last seen
            disagrees with the odometry's by more than doubt_tol_m + doubt_tol_frac of the odometry's
            displacement, the cell is also checked where it lies if the odometry is right (the case:
            backing out of gnd_exp1_three_traps' side passage, the matcher held its pose while the chair
            reversed 0.5 m, and the chair's blind rear met a wall its grid put 0.5 m further). The poses
            are tracked over doubt_window_s, one per 0.25 s. **Choice**: 300 s, 0.05 m and 10 %:
            wheel odometry drifts a few percent of its travel, and the simulated one less; 0 s disables
            the rule.
    """

    budget_match_s: float = 0.05
    budget_model_s: float = 0.05
    budget_planner_s: float = 0.08
    budget_reactor_s: float = 0.02
    enforce_budgets: bool = False
    rotate_w_frac: float = 0.5
    goal_tolerance_m: float = 0.3
    goal_arrive_frac: float = 0.5
    goal_settle_s: float = 1.0
    stale_scan_s: float = 1.0
    reaction_s: float = 0.3
    emergency_margin_m: float = 0.02
    trap_window: int = 40
    trap_count: int = 6
    trap_progress_m: float = 0.2
    trap_turn_rad: float = 0.785
    trap_w_frac: float = 0.1
    unreachable_ticks: int = 25
    escape_ticks: int = 10
    escape_v_frac: float = 0.3
    escape_clearance_m: float = 0.6
    manoeuvre_nodes: int = 1500
    manoeuvre_after_s: float = 2.0
    blind_memory_s: float = 1.0
    doubt_window_s: float = 300.0
    doubt_tol_m: float = 0.05
    doubt_tol_frac: float = 0.1
    trap_window_s: float | None = None
    unreachable_s: float | None = None
    escape_s: float | None = None
    brake_lag: bool = False


def doubt_transforms(corrected: NDArray[np.float64], odom: NDArray[np.float64],
                     params: SupervisorParams) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """For each earlier tick k (rows of ``corrected`` and ``odom`` (N, 3), oldest first, the last one
    now): the rigid transform E_k (N, 3) that takes a point of the robot frame now, placed by the corrected
    poses, to where it lies if the odometry is right since tick k, E_k = inv(odometry's motion since k) ∘
    corrected motion since k; and whether the two motions disagree by more than the odometry's own error,
    doubt_tol_m + doubt_tol_frac of its displacement since k. Each motion is taken in the robot frame at
    tick k, so the frames' offset does not count. The displacement, not the path: a robot rocking on the
    spot covers metres of path while its odometry's error stays that of the net motion (the scale errors of
    forward and back cancel), and a tolerance growing with the path let a matcher stuck for a minute pass.
    """
    dc = relative(corrected, corrected[-1])
    do = relative(odom, odom[-1])
    gap = np.hypot(dc[:, 0] - do[:, 0], dc[:, 1] - do[:, 1])
    doubted = gap > params.doubt_tol_m + params.doubt_tol_frac * np.hypot(do[:, 0], do[:, 1])
    return compose(inverse(do), dc), doubted


def doubted_cells(cells_xy: NDArray[np.float64], seen_ns: NDArray[np.int64], track_ns: NDArray[np.int64],
                  transforms: NDArray[np.float64], doubted: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The cells (robot frame) whose pose is in doubt, moved to where they lie if the odometry is right.

    A cell last seen at ``seen_ns`` was placed by the corrected pose then: its error is the disagreement
    since, that of the first tracked tick at or after its stamp (``track_ns``, oldest first;
    ``doubt_transforms``'s ``transforms`` and ``doubted`` of those ticks; a cell older than the track gets
    the oldest). The reflexive loop checks these as well as the cells where the grid has them: of the
    matcher and the odometry, it cannot tell which is wrong; a cell the current scan sees has no doubt,
    and a moved cell the scan sees through is dropped (``seen_through``)."""
    if cells_xy.shape[0] == 0 or not doubted.any():
        return np.zeros((0, 2))
    k = np.minimum(np.searchsorted(track_ns, seen_ns, side="left"), track_ns.shape[0] - 1)
    sel = doubted[k]
    cells = np.column_stack([cells_xy[sel], np.zeros(int(np.count_nonzero(sel)))])
    moved: NDArray[np.float64] = compose(transforms[k[sel]], cells)[:, :2]
    return moved


def seen_through(points_xy: NDArray[np.float64], ranges_m: NDArray[np.float64],
                 angles_rad: NDArray[np.float64], laser_pose: tuple[float, float, float],
                 tolerance_m: float) -> NDArray[np.bool_]:
    """(M,) mask of the points (robot frame) the scan sees through: within its field of view, the beam
    nearest their bearing returned from more than ``tolerance_m`` beyond them, or not at all (+inf). The
    scan is exact where it looks; a hypothesis it contradicts there is dropped (``doubted_cells``: with a
    poor odometry the cells moved by it would otherwise stand in the way of every command). Beams in
    angle order, either way round; a nan beam sees nothing."""
    if points_xy.shape[0] == 0 or ranges_m.shape[0] < 2:
        return np.zeros(points_xy.shape[0], dtype=bool)
    if angles_rad[0] > angles_rad[-1]:  # a clockwise scan
        angles_rad, ranges_m = angles_rad[::-1], ranges_m[::-1]
    lx, ly, lth = laser_pose
    dx, dy = points_xy[:, 0] - lx, points_xy[:, 1] - ly
    r = np.hypot(dx, dy)
    a = np.asarray(wrap_angle(dm.atan2_a(dy, dx) - lth))
    in_view = (a >= angles_rad[0]) & (a <= angles_rad[-1])
    i = np.clip(np.searchsorted(angles_rad, a), 1, angles_rad.shape[0] - 1)
    i = np.where(np.abs(angles_rad[i - 1] - a) <= np.abs(angles_rad[i] - a), i - 1, i)
    beam = ranges_m[i]
    return in_view & ((beam > r + tolerance_m) | np.isposinf(beam))


def gnd_mode(planner_ok: bool, reactor_has_region: bool) -> Mode:
    """GND's mode from the planner and reactor outcomes (no free area wins over everything)."""
    if not reactor_has_region:
        return Mode.ROTATE
    return Mode.MPND if planner_ok else Mode.MND


def rotate_command(goal_bearing_rad: float, robot: RobotConfig, params: SupervisorParams) -> float:
    """Turn rate of ROTATE: towards the goal side, at rotate_w_frac * wmax [rad/s]."""
    sign = 1.0 if goal_bearing_rad >= 0.0 else -1.0
    return sign * params.rotate_w_frac * robot.wmax_radps


def footprint_contains(
    points_xy: NDArray[np.float64], robot: RobotConfig, margin_m: float
) -> NDArray[np.bool_]:
    """(M,) mask of points (robot frame) inside the footprint grown by ``margin_m``."""
    return footprint_signed_distance(points_xy, robot) <= margin_m


def footprint_signed_distance(points_xy: NDArray[np.float64], robot: RobotConfig) -> NDArray[np.float64]:
    """(..., 2) points in the robot frame -> (...) signed distance [m] to the footprint: positive outside,
    negative inside (exact Euclidean distance to the rectangle or circle)."""
    x, y = points_xy[..., 0], points_xy[..., 1]
    if robot.shape == "circle":
        return np.hypot(x, y) - robot.radius_m
    dx = np.maximum(x - robot.front_m, -robot.rear_m - x)
    dy = np.abs(y) - robot.width_m / 2.0
    outside = np.hypot(np.maximum(dx, 0.0), np.maximum(dy, 0.0))
    return outside + np.minimum(np.maximum(dx, dy), 0.0)


def braking_time_s(v_mps: float, vy_mps: float, w_radps: float, robot: RobotConfig,
                   params: SupervisorParams) -> float:
    """Time [s] the command sweeps at full twist: reaction_s (plus the drive's lag with ``brake_lag``),
    plus half the braking time.

    The command is held for reaction_s, then v and w ramp down together to zero (the path stays on the
    commanded arc) at the robot's limits, in max(|v| / accel, |w| / alpha); a linear ramp covers half the
    distance and angle the full twist would in that time."""
    speed = math.hypot(v_mps, vy_mps)
    brake = max(speed / robot.accel_mps2, abs(w_radps) / robot.alpha_radps2)
    if params.brake_lag:
        return params.reaction_s + max(robot.tau_v_s, robot.tau_w_s) + 0.5 * brake
    return params.reaction_s + 0.5 * brake


def safety_reach_m(robot: RobotConfig, params: SupervisorParams, cell_m: float) -> float:
    """Radius [m] around the rotation centre that holds every obstacle any command within the robot's
    limits can touch over its braking horizon (the grid cells to collect for ``safe_command``)."""
    speed = math.hypot(robot.vmax_mps, robot.vmax_mps if robot.drive == "holonomic" else 0.0)
    t = braking_time_s(speed, 0.0, robot.wmax_radps, robot, params)
    return robot.outer_radius_m + speed * t + params.emergency_margin_m + cell_m


def straight_min_m(robot: RobotConfig, params: SupervisorParams) -> float:
    """Least free travel [m] for ``safe_command``'s "same speed, straight on" replacement of a turning
    command: the robot's stop distance from full speed (vmax over ``braking_time_s``; 0.18 m for the
    wheelchair preset, 0.23 m for the XR4000's).

    **Choice**, and why not the command's own horizon: the replacement is not a one-off. The reactor asks
    for its turn again next tick, is refused again, and the robot goes on straight, tick after tick. A
    slow command's own braking horizon is tiny (2 cm at 0.05 m/s), so a chair heading into a wall (the
    reactor turning away, the turn swinging a corner into stale cells beside it) crept on straight until
    it was wedged at the wall (gnd_exp2_people_room). Straight on is the right replacement where it is a
    passage (a door whose jambs the chair passes parallel): that stays free over a full-speed stop
    distance, a wall ahead does not. Derived from the robot's limits rather than a constant: it is the
    distance any command the reactor may send next must be able to stop in."""
    return robot.vmax_mps * braking_time_s(robot.vmax_mps, 0.0, 0.0, robot, params)


_SWEEP_STEP_M = 0.02  # largest displacement of any footprint point between two checked poses [m]
_SWEEP_MAX_POSES = 48


def arc_poses(
    v_mps: float, vy_mps: float, w_radps: float, t_end_s: float, robot: RobotConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The footprint poses ``arc_touches`` checks along the constant-twist arc of ``t_end_s``: x, y [m] and
    theta [rad] (each (n + 1,), the first the robot now), robot frame, one every 2 cm of the farthest
    footprint point's travel (at most 48 steps)."""
    travel = math.hypot(v_mps, vy_mps) * t_end_s
    reach = travel + abs(w_radps) * robot.outer_radius_m * t_end_s
    n = min(max(math.ceil(reach / _SWEEP_STEP_M), 1), _SWEEP_MAX_POSES)
    px, py, th = np.empty(n + 1), np.empty(n + 1), np.empty(n + 1)
    _arc_fill(v_mps, vy_mps, w_radps, t_end_s, n, px, py, th)
    return px, py, th


@njit(cache=True)
def _arc_fill(v: float, vy: float, w: float, t_end: float, n: int, px: F64, py: F64, th: F64) -> None:
    """Fill px, py, th (n + 1,) with the poses along the constant-twist arc at n + 1 evenly spaced times
    from 0 to ``t_end`` (numpy's ``linspace``, to the bit: i * (t_end / n), the last exactly t_end)
    (exact for an arc; below 1e-9 rad/s the straight line, its limit)."""
    step = t_end / n
    turning = abs(w) > 1e-9
    for i in range(n + 1):
        if i == n:
            t = t_end
        elif step == 0.0:  # a subnormal t_end (linspace's own branch)
            t = i / n * t_end + 0.0
        else:
            t = i * step + 0.0
        a = w * t
        if turning:
            s, c1 = dm.sin(a) / w, (1.0 - dm.cos(a)) / w
        else:
            s, c1 = t, 0.0
        px[i] = v * s - vy * c1
        py[i] = v * c1 + vy * s
        th[i] = a


@njit(cache=True)
def footprint_distance_at(x: float, y: float, circle: bool, radius: float, front: float, rear: float,
                          half_w: float) -> float:
    """``footprint_signed_distance`` of one point, for the kernels (the circle of ``radius``, else the
    rectangle ``[-rear, front] x [-half_w, half_w]``)."""
    if circle:
        return math.hypot(x, y) - radius
    dx = max(x - front, -rear - x)
    dy = abs(y) - half_w
    return math.hypot(max(dx, 0.0), max(dy, 0.0)) + min(max(dx, dy), 0.0)


@njit(cache=True)
def _sweep_touches(points: F64, v: float, vy: float, w: float, t_end: float, travel: float, margin: float,
                   outer_r: float, circle: bool, radius: float, front: float, rear: float,
                   half_w: float) -> int:
    """``arc_touches`` on C-contiguous (M, 2) points, ``travel`` = |(v, vy)| t_end given (Python's
    ``math.hypot`` is not the C library's): 1 touches, 0 not, -1 a non-finite sweep with points within
    reach (no pose count)."""
    bound = outer_r + travel + margin
    b2 = bound * bound
    m = points.shape[0]
    idx = np.empty(m, dtype=np.int64)
    cnt = 0
    for i in range(m):
        x, y = points[i, 0], points[i, 1]
        if x * x + y * y <= b2:
            idx[cnt] = i
            cnt += 1
    if cnt == 0:
        return 0
    reach = travel + abs(w) * outer_r * t_end
    if not math.isfinite(reach):
        return -1
    n = min(max(math.ceil(reach / _SWEEP_STEP_M), 1), _SWEEP_MAX_POSES)
    px, py, th = np.empty(n + 1), np.empty(n + 1), np.empty(n + 1)
    _arc_fill(v, vy, w, t_end, n, px, py, th)
    ct, st = np.empty(n + 1), np.empty(n + 1)
    for k in range(n + 1):
        ct[k] = dm.cos(th[k])
        st[k] = dm.sin(th[k])
    for t in range(cnt):
        x, y = points[idx[t], 0], points[idx[t], 1]
        lim = 0.0
        for k in range(n + 1):
            dx, dy = x - px[k], y - py[k]
            qx, qy = ct[k] * dx + st[k] * dy, -st[k] * dx + ct[k] * dy  # in the robot frame at pose k
            d = footprint_distance_at(qx, qy, circle, radius, front, rear, half_w)
            if k == 0:
                lim = d - 1e-9
            elif d <= margin and d < lim:
                return 1
    return 0


def kernel_points(points_xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, 2) points as the kernels take them: C-contiguous, float64 and writable (a read-only array would
    compile a second specialisation of each kernel)."""
    pts = np.ascontiguousarray(points_xy, dtype=np.float64)
    return pts if pts.flags.writeable else pts.copy()


def arc_touches(
    points_xy: NDArray[np.float64], v_mps: float, vy_mps: float, w_radps: float, t_end_s: float,
    robot: RobotConfig, margin_m: float
) -> bool:
    """True when the footprint, moved along the constant-twist arc for ``t_end_s``, comes within
    ``margin_m`` of a point *and closer than it is now* (a point beside a robot driving parallel to it,
    or already under it, does not block every motion; one the motion approaches does). Footprint poses
    are checked every 2 cm of the farthest footprint point's travel (at most 48 poses, ``arc_poses``);
    only points the moving footprint's enclosing circle can reach are tested (the centre moves at most
    the travel)."""
    if points_xy.shape[0] == 0 or t_end_s <= 0.0:
        return False
    pts = kernel_points(points_xy)
    travel = math.hypot(v_mps, vy_mps) * t_end_s
    hit = _sweep_touches(pts, v_mps, vy_mps, w_radps, t_end_s, travel, margin_m, robot.outer_radius_m,
                         robot.shape == "circle", robot.radius_m, robot.front_m, robot.rear_m,
                         robot.width_m / 2.0)
    if hit < 0:
        raise ValueError(f"arc_touches: a non-finite sweep (v {v_mps}, vy {vy_mps}, w {w_radps}, "
                         f"t {t_end_s})")
    return hit == 1


def swept_collision(
    points_xy: NDArray[np.float64], v_mps: float, w_radps: float, robot: RobotConfig,
    params: SupervisorParams, *, vy_mps: float = 0.0, grow_m: float = 0.0
) -> bool:
    """True when the footprint swept along the commanded motion over the braking horizon touches a point.

    ``points_xy``: (M, 2) obstacle points in the robot frame (raw scan hits, or occupied cell centres with
    ``grow_m`` = half a cell: the obstacle lies anywhere in its cell). Touching means coming within
    emergency_margin_m + grow_m of a point and closer than now; a pure rotation sweeps the rotating
    footprint (it matters for the rectangular wheelchair)."""
    t_end = braking_time_s(v_mps, vy_mps, w_radps, robot, params)
    return arc_touches(points_xy, v_mps, vy_mps, w_radps, t_end, robot, params.emergency_margin_m + grow_m)


def blind_points(points_xy: NDArray[np.float64], robot: RobotConfig, laser_pose: tuple[float, float, float],
                 fov_rad: tuple[float, float]) -> NDArray[np.float64]:
    """The points (robot frame) on the laser's blind side: bearing from the laser (pose ``laser_pose``
    (x, y, theta) in the robot frame) outside its field of view ``fov_rad`` (first, last beam angle),
    and outside the robot's own footprint (no mover can stand under the robot).

    Fed with ``RobotCentredGrid.unseen_points`` (cells not seen within blind_memory_s), these are the
    cells the safety check treats as not free for translation (``safe_command``). Cells in the field of
    view that the scan did not reach (in an obstacle's shadow, beyond range) are not among them: any
    mover there must first cross the view, and the scan and the obstacle in front are checked anyway."""
    if points_xy.shape[0] == 0:
        return points_xy
    lx, ly, lth = laser_pose
    bearing = dm.atan2_a(points_xy[:, 1] - ly, points_xy[:, 0] - lx) - lth
    bearing = np.mod(bearing - fov_rad[0], 2.0 * math.pi)  # 0 at the first beam, counter-clockwise
    blind = (bearing > fov_rad[1] - fov_rad[0]) & (footprint_signed_distance(points_xy, robot) >= 0.0)
    out: NDArray[np.float64] = points_xy[blind]
    return out


def unconfirmed_cells(grid_xy: NDArray[np.float64], scan_xy: NDArray[np.float64],
                      cell_m: float) -> NDArray[np.float64]:
    """The occupied cell centres that hold no raw hit of the current scan.

    A cell the scan confirms (a hit within half a cell diagonal of its centre, i.e. in the cell) is checked
    through its hits, which are exact to the laser's noise, instead of as a cell grown by half its side:
    the growth exists because the grid forgets where in the cell the obstacle was. In a 0.85 m door the
    grown jamb cells alone leave the 0.7 m chair less than a centimetre per side; the hits leave it the
    real 7.5 cm. Cells out of the scan's view (beside and behind the chair) keep the grown check."""
    if grid_xy.shape[0] == 0 or scan_xy.shape[0] == 0:
        return grid_xy
    r = 0.5 * math.sqrt(2.0) * cell_m
    keep = np.empty(grid_xy.shape[0], dtype=np.bool_)
    _unconfirmed_kernel(kernel_points(grid_xy), kernel_points(scan_xy), r * r, keep)
    out: NDArray[np.float64] = grid_xy[keep]
    return out


@njit(cache=True)
def _unconfirmed_kernel(grid: F64, scan: F64, r2: float, keep: NDArray[np.bool_]) -> None:
    """keep[i]: no scan point within squared distance ``r2`` of grid point i."""
    for i in range(grid.shape[0]):
        gx, gy = grid[i, 0], grid[i, 1]
        keep[i] = True
        for j in range(scan.shape[0]):
            dx, dy = gx - scan[j, 0], gy - scan[j, 1]
            if dx * dx + dy * dy <= r2:
                keep[i] = False
                break


def swept_touch(
    v_mps: float, vy_mps: float, w_radps: float, scan_xy: NDArray[np.float64], cells_xy: NDArray[np.float64],
    robot: RobotConfig, params: SupervisorParams, *, cell_m: float, margin_m: float = 0.0
) -> str:
    """Which obstacles the command's swept footprint touches: "scan", "grid" or "" (none).

    The one obstacle test of the reflexive loop (``safe_command``, margin 0) and the mode selector (its
    tolerance ``margin_m`` on top). ``scan_xy``: raw hits of the current scan; ``cells_xy``: OCCUPIED cell
    centres the scan does not confirm (``unconfirmed_cells``, computed once by the caller: safe_command
    tries several commands against the same cells), grown by half a cell; both robot frame. Touching is
    ``swept_collision``'s, within emergency_margin_m + ``margin_m`` (+ half a cell for the grid). A still
    command sweeps nothing; the scan is tried first (it is exact, and usually the smaller set)."""
    if v_mps == 0.0 and vy_mps == 0.0 and w_radps == 0.0:
        return ""
    if swept_collision(scan_xy, v_mps, w_radps, robot, params, vy_mps=vy_mps, grow_m=margin_m):
        return "scan"
    grow = 0.5 * cell_m + margin_m
    if swept_collision(cells_xy, v_mps, w_radps, robot, params, vy_mps=vy_mps, grow_m=grow):
        return "grid"
    return ""


@dataclass(frozen=True, slots=True)
class SafeCommand:
    """The command after the collision check, and the rule that replaced it (None: unchanged);
    ``looking``: the replacement is the blind side rule's turn first (``safe_command``)."""

    v_mps: float
    vy_mps: float
    w_radps: float
    rule: Mode | None
    looking: bool = False


def safe_command(
    v_mps: float, vy_mps: float, w_radps: float, scan_xy: NDArray[np.float64], grid_xy: NDArray[np.float64],
    robot: RobotConfig, params: SupervisorParams, *, cell_m: float,
    unknown_xy: Callable[[], NDArray[np.float64]] | None = None,
    blind_xy: Callable[[], NDArray[np.float64]] | None = None,
    doubt_xy: Callable[[], NDArray[np.float64]] | None = None,
    view_rad: tuple[float, float] = (-math.pi, math.pi), cells_unconfirmed: bool = False
) -> SafeCommand:
    """The command if its swept footprint touches nothing, else the safest admissible replacement.

    Obstacles: ``scan_xy`` raw hits of the current scan and ``grid_xy`` OCCUPIED cell centres (both robot
    frame); cell centres are grown by half a cell (``swept_touch``). Replacements, first admissible
    wins: the same arc at 1/2 then 1/4 of the speed (SAFE_SLOW: a shorter braking horizon); the same speed
    straight on (a chair in a door: any turn swings a side towards a jamb it passes parallel), then the
    other turn direction, on the same arc then in place (SAFE_TURN; straight on only if it is also free
    for ``straight_min_m``, see there); for a turning command, a straight
    reverse at escape_v_frac * vmax whose sweep also avoids every cell not known FREE (``unknown_xy()``:
    UNKNOWN cell centres, computed only if needed; without it no reverse) (SAFE_REVERSE); else stop
    (EMERGENCY). A still command is never checked. A differential base's commanded reverse (the reactor
    backing out of a turn the chair cannot make) must avoid the UNKNOWN cells too: the chair's laser never
    saw what is behind it.

    Grid cells that hold a hit of the current scan are checked through the hit (``unconfirmed_cells``;
    ``cells_unconfirmed``: the caller already filtered ``grid_xy`` against ``scan_xy``, e.g. once for the
    several checks of one tick).

    The pose doubt (``doubt_xy()``: the occupied cells moved to where they lie if the odometry is right,
    ``doubted_cells``; computed only if needed): a command whose direction of travel lies outside the
    laser's view must not touch them either (grown by half a cell, as the grid's). Only there: in view
    the scan is exact and refutes what it sees through, and a turn in place is how the robot looks; the
    class is a front laser's robot backing into what it remembers behind it while its matcher is stuck,
    and testing every command against the moved cells made a robot with poor odometry (the
    Intel log) stop and turn aside for walls that were where the matcher had them.

    The blind side (``blind_xy()``: centres of the cells out of the laser's view not seen within
    blind_memory_s, ``blind_points``; computed only if needed; without it no such rule): a command whose
    direction of travel atan2(vy, v) lies outside the laser's view ``view_rad`` (first and last beam
    bearings in the robot frame: the motion's leading edge is on the blind side) and whose translation,
    straight over the command's braking horizon, approaches one of those cells (within emergency_margin_m
    + half a cell, as ``swept_collision``) is replaced like one that touches, and every replacement must
    pass the same test. Travel into the view is not tested: the scan sees where the motion leads (a
    sideways component of a circular base also nears the rear quarter of its side, but only grazing it;
    stopping that would stop nearly every motion of a holonomic base that stood still for a second). Only
    the translation is tested: turning is how a front laser looks at its blind side (a circular base's
    turn sweeps nothing; a rectangle's swing stays checked against the scan and the grid's obstacles). A
    holonomic base tries first to turn in place towards its direction of travel (SAFE_TURN, "turn
    first"): the scan then covers where it is going, and a later tick translates there on fresh cells. A
    differential base cannot look behind it: turning in place does not bring its rear into a front
    laser's view, and in a dead end there is no room to turn round; forbidding the reverse would trap it
    (measured: the chair then times out in u_trap and gnd_exp1_three_traps). Its reverse into stale cells
    is slowed to a creep instead (SAFE_SLOW, escape_v_frac * vmax, the turn rate scaled alike): the
    issue's "reverse where the way behind is known free" with the grid's FREE taken as old news. What the
    chair's rear may meet there is met at creep speed; only a rear sensor would see it coming.

    The reverse only serves a turn: backing off makes room for the sweep of a rectangle turning (the
    wheelchair's problem); for a straight command it would only back off and come again, tick after tick.
    """
    grow = 0.5 * cell_m
    if not cells_unconfirmed:
        grid_xy = unconfirmed_cells(grid_xy, scan_xy, cell_m)
    unknown = _once(unknown_xy)
    blind = _once(blind_xy)
    doubt = _once(doubt_xy)

    def touches(v: float, vy: float, w: float) -> bool:
        return swept_touch(v, vy, w, scan_xy, grid_xy, robot, params, cell_m=cell_m) != ""

    def backs_into_unknown(v: float, w: float) -> bool:  # a differential base backing up
        return v < 0.0 and robot.drive == "differential" and unknown is not None and swept_collision(
            unknown(), v, w, robot, params, grow_m=grow
        )

    creep = params.escape_v_frac * robot.vmax_mps

    def in_view(v: float, vy: float) -> bool:  # the direction of travel lies within the laser's view
        return (dm.atan2(vy, v) - view_rad[0]) % math.tau <= view_rad[1] - view_rad[0]

    def into_blind(v: float, vy: float, w: float) -> bool:  # translation towards cells not seen lately
        if blind is None or (v == 0.0 and vy == 0.0):
            return False
        if robot.drive == "differential" and abs(v) <= creep * (1.0 + 1e-9):
            return False  # the differential base's creep (see above)
        if in_view(v, vy):
            return False
        t_end = braking_time_s(v, vy, w, robot, params)
        return arc_touches(blind(), v, vy, 0.0, t_end, robot, params.emergency_margin_m + grow)

    def into_doubt(v: float, vy: float, w: float) -> bool:  # travel out of view towards moved cells
        if doubt is None or (v == 0.0 and vy == 0.0) or in_view(v, vy):
            return False
        return swept_collision(doubt(), v, w, robot, params, vy_mps=vy, grow_m=grow)

    def blocked(v: float, vy: float, w: float) -> bool:
        return touches(v, vy, w) or backs_into_unknown(v, w) or into_blind(v, vy, w) or into_doubt(v, vy, w)

    if (v_mps == 0.0 and vy_mps == 0.0 and w_radps == 0.0) or not blocked(v_mps, vy_mps, w_radps):
        return SafeCommand(v_mps, vy_mps, w_radps, None)
    candidates: list[tuple[float, float, float, Mode]] = []
    looks = False  # candidates[0] is the turn first
    if into_blind(v_mps, vy_mps, w_radps):
        if robot.drive == "holonomic":
            looks = True
            candidates.append((0.0, 0.0, _look_w(v_mps, vy_mps, w_radps, robot, params), Mode.SAFE_TURN))
        else:
            f = creep / abs(v_mps)
            candidates.append((f * v_mps, 0.0, f * w_radps, Mode.SAFE_SLOW))
    candidates += [(f * v_mps, f * vy_mps, f * w_radps, Mode.SAFE_SLOW) for f in (0.5, 0.25)]
    straight = -1  # index of the straight-on candidate
    if w_radps != 0.0:
        if v_mps != 0.0 or vy_mps != 0.0:  # the same speed without turning: parallel to what it passes
            straight = len(candidates)
            candidates.append((v_mps, vy_mps, 0.0, Mode.SAFE_TURN))
        candidates.append((v_mps, vy_mps, -w_radps, Mode.SAFE_TURN))
        if v_mps != 0.0 or vy_mps != 0.0:
            candidates.append((0.0, 0.0, -w_radps, Mode.SAFE_TURN))

    def straight_short(v: float, vy: float) -> bool:  # not free for the full-speed stop distance
        t_end = straight_min_m(robot, params) / math.hypot(v, vy)
        if t_end <= braking_time_s(v, vy, 0.0, robot, params):
            return False  # its own horizon is longer, and was checked
        m = params.emergency_margin_m
        return arc_touches(scan_xy, v, vy, 0.0, t_end, robot, m) or arc_touches(
            grid_xy, v, vy, 0.0, t_end, robot, m + grow)

    for k, (v, vy, w, rule) in enumerate(candidates):
        if not blocked(v, vy, w) and not (k == straight and straight_short(v, vy)):
            return SafeCommand(v, vy, w, rule, looking=k == 0 and looks)
    if unknown is not None and w_radps != 0.0:
        v_back = -params.escape_v_frac * robot.vmax_mps
        # a differential base's reverse was already tested against the UNKNOWN cells by ``blocked``
        if not blocked(v_back, 0.0, 0.0) and (robot.drive == "differential" or not swept_collision(
                unknown(), v_back, 0.0, robot, params, grow_m=grow)):
            return SafeCommand(v_back, 0.0, 0.0, Mode.SAFE_REVERSE)
    return SafeCommand(0.0, 0.0, 0.0, Mode.EMERGENCY)


def _once(f: Callable[[], NDArray[np.float64]] | None) -> Callable[[], NDArray[np.float64]] | None:
    """``f`` evaluated at most once (the lazy point sets ``safe_command`` may test several commands
    against)."""
    if f is None:
        return None
    memo: list[NDArray[np.float64]] = []

    def get() -> NDArray[np.float64]:
        if not memo:
            memo.append(f())
        return memo[0]

    return get


def _look_w(v_mps: float, vy_mps: float, w_radps: float, robot: RobotConfig,
            params: SupervisorParams) -> float:
    """Turn rate of the blind side rule's "turn first": towards the direction of travel atan2(vy, v), at
    least rotate_w_frac * wmax; the commanded turn direction when the travel points more than 135 deg off
    straight ahead (either way round is then about as long, and keeping the reactor's choice does not
    flip the turn when the direction wobbles across 180 deg)."""
    bearing = dm.atan2(vy_mps, v_mps)
    rate = max(abs(w_radps), params.rotate_w_frac * robot.wmax_radps)
    if w_radps != 0.0 and abs(bearing) > 0.75 * math.pi:
        return math.copysign(rate, w_radps)
    return math.copysign(rate, bearing)


def escape_command(
    points_xy: NDArray[np.float64],
    robot: RobotConfig,
    params: SupervisorParams,
    *,
    prefer_backward: bool = False,
    not_free_xy: Callable[[float], NDArray[np.float64]] | None = None,
    cell_m: float = 0.0,
) -> tuple[float, bool]:
    """The trap escape: a slow straight motion (escape_v_frac * vmax) forward or backward, where there is
    room for ``escape_clearance_m`` beyond the footprint's edge in a corridor of the robot's width (+
    emergency_margin_m). Returns (v [m/s], possible).

    Forward is tried first, unless ``prefer_backward`` (the planned course points behind the robot: in a
    U-shaped trap, forward pushes deeper into the U). Forward needs no raw hit of ``points_xy`` (robot
    frame) in its corridor. Backward needs that too, and, since both presets' lasers see only the front
    half, the corridor behind known free in the grid, as ``safe_command``'s SAFE_REVERSE: no centre of a
    cell not known FREE (UNKNOWN or OCCUPIED), grown by half a cell (``cell_m``), in it.
    ``not_free_xy(radius_m)`` returns those centres (robot frame) within ``radius_m``; without it there is
    no backward escape. The stack also runs every escape tick through ``safe_command`` (scan and grid) and
    ends the escape when it would touch."""
    reach = params.escape_clearance_m
    half = (robot.radius_m if robot.shape == "circle" else robot.width_m / 2.0) + params.emergency_margin_m

    def in_corridor(pts: NDArray[np.float64], direction: float, grow: float) -> bool:
        x = direction * pts[:, 0]  # distance along the escape direction
        edge = robot.front_m if direction > 0 else robot.rear_m
        return bool(np.any((x > -grow) & (x < edge + reach + grow) & (np.abs(pts[:, 1]) <= half + grow)))

    def clear(direction: float) -> bool:
        if in_corridor(points_xy, direction, 0.0):
            return False
        if direction > 0:
            return True
        if not_free_xy is None:
            return False
        grow = 0.5 * cell_m
        return not in_corridor(not_free_xy(math.hypot(robot.rear_m + reach + grow, half + grow)), -1.0, grow)

    v = params.escape_v_frac * robot.vmax_mps
    for direction in ((-1.0, 1.0) if prefer_backward else (1.0, -1.0)):
        if clear(direction):
            return direction * v, True
    return 0.0, False


def no_progress(a: tuple[float, float, float], b: tuple[float, float, float],
                params: SupervisorParams) -> bool:
    """Whether between poses a and b (x, y, theta) the robot neither moved trap_progress_m nor turned
    trap_turn_rad net: the stall of the trap detector's dithering rule and of the manoeuvre's trigger."""
    net_turn = abs(math.remainder(b[2] - a[2], math.tau))
    return math.hypot(b[0] - a[0], b[1] - a[1]) < params.trap_progress_m and net_turn < params.trap_turn_rad


def budget_flags(timings_s: dict[str, float], params: SupervisorParams) -> Flag:
    """*_OVER_BUDGET flags for the modules whose time exceeded their budget."""
    flags = Flag.NONE
    for name, budget, flag in (
        ("match", params.budget_match_s, Flag.MATCH_OVER_BUDGET),
        ("model", params.budget_model_s, Flag.MODEL_OVER_BUDGET),
        ("planner", params.budget_planner_s, Flag.PLANNER_OVER_BUDGET),
        ("reactor", params.budget_reactor_s, Flag.REACTOR_OVER_BUDGET),
    ):
        if timings_s.get(name, 0.0) > budget:
            flags |= flag
    return flags
