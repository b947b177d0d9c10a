"""ND+ for the rectangular differential chair: passages are crossed along their axis.

A kinematic unicycle loop (exact arcs) drives the 1.2 x 0.7 m chair with ``nd_step`` followed by the
stack's reflexive check ``safe_command`` through a 0.85 m door seen as synthetic points, from crooked and
off-centre starts; the real footprint must never touch the wall and the chair must end up through.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from numpy.typing import NDArray

from gndreplay.pipeline.nd import _ALIGN_GAIN, NdMemory, NdParams, _admissible_drive, nd_step
from gndreplay.pipeline.supervisor import SupervisorParams, footprint_signed_distance, safe_command
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig

F64 = NDArray[np.float64]
CHAIR = WHEELCHAIR_ROBOT
DOOR_M = 0.85
WALL_T = 0.1
CELL_M = 0.05


def _outline(x0: float, x1: float, y0: float, y1: float, step: float = 0.02) -> F64:
    """Points every ``step`` along the outline of the box [x0, x1] x [y0, y1]."""
    nx, ny = math.ceil((x1 - x0) / step) + 1, math.ceil((y1 - y0) / step) + 1
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    return np.vstack([np.column_stack([xs, np.full(nx, y0)]), np.column_stack([xs, np.full(nx, y1)]),
                      np.column_stack([np.full(ny, x0), ys]), np.column_stack([np.full(ny, x1), ys])])


def door_world(door_m: float = DOOR_M) -> F64:
    """A 0.1 m thick wall along y = 0 from x = -4 to 4 with a door of ``door_m`` centred on x = 0."""
    h = 0.5 * door_m
    return np.vstack([_outline(-4.0, -h, -0.5 * WALL_T, 0.5 * WALL_T), _outline(h, 4.0, -0.5 * WALL_T,
                                                                                  0.5 * WALL_T)])


def to_robot(pose: F64, xy: F64) -> F64:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = xy - pose[:2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def arc(pose: F64, v: float, w: float, h: float) -> F64:
    """Exact constant-twist motion of a unicycle for ``h`` seconds."""
    x, y, th = pose
    if abs(w) < 1e-12:
        return np.array([x + v * h * math.cos(th), y + v * h * math.sin(th), th])
    th1 = th + w * h
    r = v / w
    return np.array([x + r * (math.sin(th1) - math.sin(th)), y - r * (math.cos(th1) - math.cos(th)), th1])


def path_target(pose: F64, goal: F64, lookahead_m: float = 1.0) -> F64:
    """The stack's mpND target: ``lookahead_m`` along the shortest path, here the polyline from the
    rotation centre through the door's midpoint (while before it) to the goal."""
    p = pose[:2]
    legs = [p, np.zeros(2), goal] if p[1] < 0.0 else [p, goal]
    left = lookahead_m
    for a, b in itertools.pairwise(legs):
        d = float(np.hypot(*(b - a)))
        if d >= left:
            out: F64 = a + (b - a) * (left / d)
            return out
        left -= d
    return goal


def drive_through_door(start: tuple[float, float, float], goal: tuple[float, float],
                       *, seconds: float = 90.0, dt: float = 0.2) -> tuple[F64, float, list[str]]:
    """Closed loop: ND+ then the reflexive check on the wall points (the scan: exact hits, and the same
    points as grid cells, grown by half a cell); returns the final pose, the smallest real clearance
    of the footprint over the run (checked at 1 cm steps of the motion) and the rules that fired."""
    world = door_world()
    cells = np.unique(np.floor(world / CELL_M), axis=0) * CELL_M + 0.5 * CELL_M  # the grid's memory
    pose = np.array(start, dtype=np.float64)
    sup = SupervisorParams()
    goal_xy = np.asarray(goal, dtype=np.float64)
    min_clear = math.inf
    rules: list[str] = []
    for _ in range(round(seconds / dt)):
        pts = to_robot(pose, world)
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= 5.0]
        res = nd_step(pts, to_robot(pose, path_target(pose, goal_xy)[None, :])[0], CHAIR, NdParams())
        scan = pts[pts[:, 0] >= CHAIR.laser_x_m]  # the chair's laser sees the half plane ahead of it
        grid = to_robot(pose, cells)
        grid = grid[np.hypot(grid[:, 0], grid[:, 1]) <= 2.0]
        safe = safe_command(res.v_mps, 0.0, res.w_radps, scan, grid, CHAIR, sup, cell_m=CELL_M)
        if safe.rule is not None:
            rules.append(safe.rule.value)
        n_sub = max(1, math.ceil(max(abs(safe.v_mps) * dt, abs(safe.w_radps) * dt * 1.0) / 0.01))
        for _ in range(n_sub):
            pose = arc(pose, safe.v_mps, safe.w_radps, dt / n_sub)
            d = float(np.min(footprint_signed_distance(to_robot(pose, world), CHAIR)))
            min_clear = min(min_clear, d)
        if pose[1] - CHAIR.rear_m > 0.5 * WALL_T + 0.3:
            break
    return pose, min_clear, rules


@pytest.mark.parametrize(
    ("x", "y", "heading_deg"),
    [(0.15, -2.0, 100.0), (-0.2, -2.5, 75.0), (0.3, -1.8, 110.0), (-0.5, -2.0, 60.0)],
)
def test_crooked_chair_crosses_the_door_without_touching(x: float, y: float, heading_deg: float) -> None:
    pose, min_clear, rules = drive_through_door((x, y, math.radians(heading_deg)), (0.0, 2.5))
    assert pose[1] - CHAIR.rear_m > 0.5 * WALL_T  # the whole chair is through
    assert abs(pose[0]) < 0.05 and abs(math.degrees(pose[2]) - 90.0) < 3.0  # straight, on the axis
    assert min_clear > 0.02  # the real footprint never came near a jamb
    assert "EMERGENCY" not in rules


def _corridor(half_w: float, x0: float = -3.0, x1: float = 4.0) -> F64:
    xs = np.arange(x0, x1, 0.02)
    return np.vstack([np.column_stack([xs, np.full(xs.size, half_w)]),
                      np.column_stack([xs, np.full(xs.size, -half_w)])])


def test_chair_in_a_narrow_corridor_goes_on_instead_of_turning_into_the_wall() -> None:
    """1.3 m between the wall faces: any turn towards the target 40 deg right sweeps the front corner
    into the right wall before the chair faces it; it drives on (the circle robot turns)."""
    pts = _corridor(0.65)
    target = (math.cos(-0.7), math.sin(-0.7))
    res = nd_step(pts, target, CHAIR)
    assert res.w_radps == 0.0 and res.v_mps > 0.0
    circle = nd_step(pts, target, XR4000_ROBOT)
    assert circle.w_radps < 0.0


def test_chair_turns_into_a_side_opening_once_its_corners_fit() -> None:
    """The right wall ends 0.9 m behind the axle: the opening lets the turn in place sweep freely."""
    xs = np.arange(-3.0, 4.0, 0.02)
    left = np.column_stack([xs, np.full(xs.size, 0.65)])
    right = np.column_stack([xs[xs < -0.9], np.full(int(np.sum(xs < -0.9)), -0.65)])
    res = nd_step(np.vstack([left, right]), (0.2, -1.5), CHAIR)
    assert res.w_radps < 0.0
    closed = nd_step(_corridor(0.65), (0.2, -1.5), CHAIR)  # the same target without the opening
    assert closed.w_radps == 0.0 or closed.v_mps < 0.0


def test_chair_backs_out_when_no_forward_arc_or_turn_fits() -> None:
    """A wall 0.15 m ahead of the front in a 1.3 m corridor, target to the right: nothing forward is
    admissible and the turn in place sweeps the walls; the chair reverses (turning its front right)."""
    front = np.column_stack([np.full(70, CHAIR.front_m + 0.15), np.linspace(-0.7, 0.7, 70)])
    res = nd_step(np.vstack([_corridor(0.65, x1=CHAIR.front_m + 0.15), front]), (0.3, -1.0), CHAIR)
    assert res.v_mps < 0.0 and res.w_radps <= 0.0


def test_chair_backs_out_of_a_narrow_corridor_towards_a_target_behind() -> None:
    """The way is behind (GND's trap: the far end closed): the 1.3 m corridor leaves no room to turn round
    (the corners sweep 0.87 m); the chair reverses along it, where the circle robot just turns."""
    pts = _corridor(0.65, x0=-0.5)  # the corridor ends 0.5 m behind the axle: it opens there
    res = nd_step(pts, (-2.0, 0.3), CHAIR)
    assert res.v_mps < 0.0
    circle = nd_step(pts, (-2.0, 0.3), XR4000_ROBOT)
    assert circle.w_radps > 0.0


def _go_round(robot: RobotConfig, half_w: float, commit: bool, *, dt: float = 0.2,
              seconds: float = 60.0) -> tuple[F64, int, float]:
    """Kinematic loop (exact motion, holonomic too) with the axle 1 m before the middle of a 0.6 m deep box
    ``2 half_w`` wide, facing it, towards a target fixed 1.2 m behind it; ND+'s memory held as a world
    bearing as the stack holds it (``commit``), or none. Returns the final pose, the number of turn (above a
    quarter of wmax: not the small corrections of the steering) direction flips before the robot passed
    the box's face, and the smallest clearance."""
    box = _outline(3.2, 3.8, -half_w, half_w)
    cells = np.unique(np.floor(box / CELL_M), axis=0) * CELL_M + 0.5 * CELL_M
    pose, target = np.array([2.2, 0.0, 0.0]), np.array([[5.0, 0.0]])
    held: float | None = None
    flips, last, min_clear = 0, 0.0, math.inf
    for _ in range(round(seconds / dt)):
        prev = NdMemory(math.remainder(held - pose[2], math.tau)) if commit and held is not None else None
        res = nd_step(to_robot(pose, cells), to_robot(pose, target)[0], robot, NdParams(), prev)
        held = None if res.memory is None else pose[2] + res.memory.subgoal_rad
        min_clear = min(min_clear, res.min_clearance_m)
        turn = math.copysign(1.0, res.w_radps) if abs(res.w_radps) > 0.25 * robot.wmax_radps else 0.0
        if turn and last and turn != last and pose[0] < 3.2:
            flips += 1
        last = turn or last
        if robot.drive == "differential":
            pose = arc(pose, res.v_mps, res.w_radps, dt)
        else:
            c, s = math.cos(pose[2]), math.sin(pose[2])
            pose = pose + dt * np.array([c * res.v_mps - s * res.vy_mps, s * res.v_mps + c * res.vy_mps,
                                         res.w_radps])
        if pose[0] > 4.5 and abs(pose[1]) < half_w:  # round the box, behind it
            break
    return pose, flips, min_clear


@pytest.mark.parametrize(("robot", "half_w"), [(CHAIR, 1.2), (XR4000_ROBOT, 1.5)])
def test_commitment_keeps_the_turn_direction_in_front_of_a_wide_obstacle(robot: RobotConfig,
                                                                         half_w: float) -> None:
    """Issue 10 item 3: facing the middle of a wide box with the target behind it, the two ways round are
    equally near the goal and ND+ choosing afresh each tick swaps them as the robot turns (it dithers in
    place); with its previous choice passed back in it keeps one side and gets round: the turn changes
    direction at most once (away to one side, then back towards the target)."""
    pose, flips, min_clear = _go_round(robot, half_w, commit=True)
    assert pose[0] > 4.5 and abs(pose[1]) < half_w  # behind the box
    assert flips <= 1
    assert min_clear > 0.0
    _, flips_free, _ = _go_round(robot, half_w, commit=False)
    assert flips_free > 10  # the input class is the one that dithered: without memory it swaps sides


def test_chair_in_a_door_keeps_its_axis_when_the_way_turns_beyond_it() -> None:
    """The chair's body in a doorway (wheelchair_office_exit, the grid's points there): a long left reveal
    0.41 m left of the axle, a short right jamb 0.44 m right, the way turning right just past it (target
    42 deg right). The target ray crosses the left reveal 0.6 m behind the axle; that pair of points along
    one wall (0.7 m apart, narrower than the door) was taken for the passage and turned the direction
    sideways (-2 rad: backing up) on some ticks and not others, so the chair went back and forth in the
    door. The door's own axis is kept: ahead, forward."""
    xl, xr = np.arange(-0.9, 0.26, 0.05), np.arange(0.05, 0.21, 0.05)
    pts = np.vstack([np.column_stack([xl, np.full(xl.size, 0.41)]),
                     np.column_stack([xr, np.full(xr.size, -0.44)]),
                     np.column_stack([np.full(5, -0.9), np.linspace(-0.44, -1.0, 5)])])
    res = nd_step(pts, (0.74, -0.67), CHAIR)
    assert abs(res.direction_rad) < 0.3 and res.v_mps > 0.0


def _door_cells(door_m: float = DOOR_M) -> F64:
    """The grid's occupied cell centres (5 cm) of the wall along y = 0 with a ``door_m`` door centred on
    x = 0: the cells holding the jamb faces lie half a cell inside the opening, as the scan hits put them
    (wheelchair_office_exit's 0.85 m door is 0.80 m between cell centres)."""
    xs = np.arange(0.5 * door_m - 0.5 * CELL_M, 4.0, CELL_M)
    xs = np.concatenate([-xs, xs])
    return np.vstack([np.column_stack([xs, np.full(xs.size, y)]) for y in (-0.5 * CELL_M, 0.5 * CELL_M)])


def _enter_door(front_x: float, heading_deg: float, gap_m: float, *, dt: float = 0.2,
                seconds: float = 30.0) -> tuple[F64, float, list[float]]:
    """Closed loop (ND+, the reflexive check, exact arcs) from the chair's front edge ``gap_m`` before the
    jambs' cells, its centre ``front_x`` off the door's axis, heading ``heading_deg`` (90: along the axis),
    until the axle has passed the wall line. Returns the final pose, the smallest real clearance to the
    wall (a 0.1 m wall with the ``DOOR_M`` door) and the commanded speeds."""
    cells, world = _door_cells(), door_world()
    th = math.radians(heading_deg)
    pose = np.array([front_x - CHAIR.front_m * math.cos(th), -CELL_M - gap_m - CHAIR.front_m * math.sin(th),
                     th])
    goal, sup = np.array([0.0, 2.5]), SupervisorParams()
    min_clear, vs = math.inf, []
    for _ in range(round(seconds / dt)):
        pts = to_robot(pose, cells)
        res = nd_step(pts, to_robot(pose, path_target(pose, goal)[None, :])[0], CHAIR, NdParams())
        safe = safe_command(res.v_mps, 0.0, res.w_radps, pts[pts[:, 0] >= CHAIR.laser_x_m], pts, CHAIR, sup,
                            cell_m=CELL_M, unknown_xy=lambda: np.zeros((0, 2)))
        vs.append(safe.v_mps)
        n_sub = max(1, math.ceil(max(abs(safe.v_mps) * dt, abs(safe.w_radps) * dt) / 0.01))
        for _ in range(n_sub):
            pose = arc(pose, safe.v_mps, safe.w_radps, dt / n_sub)
            min_clear = min(min_clear, float(np.min(footprint_signed_distance(to_robot(pose, world), CHAIR))))
        if pose[1] > 0.0:
            break
    return pose, min_clear, vs


@pytest.mark.parametrize(
    ("front_x", "heading_deg"),
    [(0.075, 90.0), (-0.075, 90.0), (0.1, 85.0), (-0.1, 95.0), (0.04, 85.0), (-0.04, 95.0)],
)
def test_chair_off_the_door_axis_at_the_jambs_enters_without_rocking(front_x: float,
                                                                     heading_deg: float) -> None:
    """Issue 10 (wheelchair_office_exit, every seed: 6-10 s without progress at its 0.85 m door): the chair
    arrives with its front 0.1 m before the jambs, a few centimetres off the axis or a few degrees
    crooked. The correction it needs (a few degrees) is below the turn in place's threshold and no forward
    arc makes it without sweeping a front corner into a jamb: it crept, backed straight off and came back.
    It must enter driving forward only (the commanded speed never changes sign), without touching."""
    pose, min_clear, vs = _enter_door(front_x, heading_deg, 0.1)
    assert pose[1] > 0.0  # the axle is in the door: the front is through
    assert abs(pose[0]) < 0.05
    assert min(vs) >= 0.0  # no backing off, so no forward / backward alternation
    assert min_clear > 0.03


@pytest.mark.parametrize("theta", [0.03, -0.03, 0.1])
def test_a_small_correction_while_backing_off_turns_by_the_error_not_at_half_wmax(theta: float) -> None:
    """A wall 3 cm before the chair's front: nothing forward fits, so it backs off while turning towards
    theta. The turn rate follows the error (``_ALIGN_GAIN`` x theta, at most half of wmax): at half of wmax
    (0.25 rad/s) a 2 deg correction turned 3 deg in one 0.2 s tick, overshot to the other side, and the
    chair rocked at the jambs of a door 0.15 m wider than itself, creeping and reversing for 15-30 s."""
    ys = np.arange(-1.0, 1.01, 0.02)
    wall_ahead = np.column_stack([np.full(ys.size, CHAIR.front_m + 0.03), ys])
    v, w = _admissible_drive(theta, 0.1, CHAIR, wall_ahead)
    assert v < 0.0
    assert w == pytest.approx(math.copysign(min(_ALIGN_GAIN * abs(theta), 0.5 * CHAIR.wmax_radps), theta))
