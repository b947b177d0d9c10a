"""Known-answer tests of the GND supervision rules and the reflexive loop."""

from __future__ import annotations

import numpy as np
import pytest

from gndreplay import detmath as dm
from gndreplay.pipeline.model import FREE, OCCUPIED, UNKNOWN, GridParams, RobotCentredGrid
from gndreplay.pipeline.selector import swept_area_occupied
from gndreplay.pipeline.supervision import GoalArrival, TrapDetector
from gndreplay.pipeline.supervisor import (
    Mode,
    SafeCommand,
    SupervisorParams,
    arc_poses,
    arc_touches,
    braking_time_s,
    budget_flags,
    escape_command,
    footprint_contains,
    footprint_signed_distance,
    gnd_mode,
    rotate_command,
    safe_command,
    safety_reach_m,
    straight_min_m,
    swept_collision,
    swept_touch,
    unconfirmed_cells,
)
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig
from gndreplay.types import Flag, Pose2D

P = SupervisorParams()


@pytest.mark.parametrize(
    ("planner_ok", "has_region", "mode"),
    [
        (True, True, Mode.MPND),
        (False, True, Mode.MND),
        (True, False, Mode.ROTATE),
        (False, False, Mode.ROTATE),
    ],
)
def test_gnd_modes(planner_ok: bool, has_region: bool, mode: Mode) -> None:
    assert gnd_mode(planner_ok, has_region) is mode


def test_rotate_turns_towards_the_goal_side() -> None:
    assert rotate_command(0.3, WHEELCHAIR_ROBOT, P) == pytest.approx(0.5 * 0.5)
    assert rotate_command(-2.0, WHEELCHAIR_ROBOT, P) == pytest.approx(-0.25)


def test_footprint_rectangle_and_circle() -> None:
    pts = np.array([[0.79, 0.0], [0.81, 0.0], [-0.39, 0.34], [-0.41, 0.0], [0.0, 0.36]])
    assert footprint_contains(pts, WHEELCHAIR_ROBOT, 0.0).tolist() == [True, False, True, False, False]
    pts = np.array([[0.29, 0.0], [0.0, -0.31], [0.2, 0.2]])
    assert footprint_contains(pts, XR4000_ROBOT, 0.0).tolist() == [True, False, True]


def test_swept_collision_straight_ahead() -> None:
    # at 0.3 m/s: 0.3 s held, then 0.6 s of braking at 0.5 m/s^2 -> 0.09 + 0.09 = 0.18 m of travel;
    # front edge at 0.8 m (+ 0.02 margin)
    near = np.array([[0.97, 0.0]])
    far = np.array([[1.03, 0.0]])
    assert swept_collision(near, 0.3, 0.0, WHEELCHAIR_ROBOT, P)
    assert not swept_collision(far, 0.3, 0.0, WHEELCHAIR_ROBOT, P)
    assert not swept_collision(near, 0.0, 0.0, WHEELCHAIR_ROBOT, P)  # standing still sweeps nothing new
    assert not swept_collision(np.zeros((0, 2)), 0.3, 0.0, WHEELCHAIR_ROBOT, P)


def test_swept_collision_rotation_sweeps_the_rectangle_corners() -> None:
    # a point just beside the front-left corner is hit when the wheelchair turns left in place
    corner = np.array([[0.70, 0.45]])
    assert not swept_collision(corner, 0.0, 0.0, WHEELCHAIR_ROBOT, P)
    assert swept_collision(corner, 0.0, 0.5, WHEELCHAIR_ROBOT, P)
    # the circular robot rotating in place sweeps nothing
    assert not swept_collision(np.array([[0.35, 0.0]]), 0.0, 1.5, XR4000_ROBOT, P)


def test_swept_collision_holonomic_sideways() -> None:
    left = np.array([[0.0, 0.4]])  # 0.1 m from the disc; 0.3 m/s sideways sweeps 0.3 * 0.4 = 0.12 m
    assert swept_collision(left, 0.0, 0.0, XR4000_ROBOT, P, vy_mps=0.3)
    assert not swept_collision(left, 0.0, 0.0, XR4000_ROBOT, P, vy_mps=-0.3)


def known_free(radius_m: float) -> np.ndarray:
    """``escape_command``'s not_free_xy for a grid known FREE all around."""
    assert radius_m > WHEELCHAIR_ROBOT.rear_m + P.escape_clearance_m
    return np.zeros((0, 2))


def test_escape_prefers_forward_then_backward() -> None:
    v, ok = escape_command(np.array([[3.0, 0.0]]), WHEELCHAIR_ROBOT, P)
    assert ok and v == pytest.approx(0.3 * 0.3)
    v, ok = escape_command(np.array([[1.0, 0.0]]), WHEELCHAIR_ROBOT, P, not_free_xy=known_free, cell_m=0.05)
    assert ok and v == pytest.approx(-0.09)
    v, ok = escape_command(np.array([[1.0, 0.0], [-0.6, 0.1]]), WHEELCHAIR_ROBOT, P, not_free_xy=known_free,
                           cell_m=0.05)
    assert not ok and v == 0.0


def test_escape_never_backs_blind() -> None:
    """Without the grid behind (the lasers see only the front half) there is no backward escape, as there
    is no SAFE_REVERSE: the scan's empty rear half says nothing."""
    v, ok = escape_command(np.array([[1.0, 0.0]]), WHEELCHAIR_ROBOT, P)
    assert not ok and v == 0.0
    v, ok = escape_command(np.array([[3.0, 0.0]]), WHEELCHAIR_ROBOT, P, prefer_backward=True)
    assert ok and v == pytest.approx(0.09)  # forward instead


def test_escape_backward_first_when_preferred() -> None:
    clear_ahead = np.array([[3.0, 0.0]])
    v, ok = escape_command(clear_ahead, WHEELCHAIR_ROBOT, P, prefer_backward=True, not_free_xy=known_free,
                           cell_m=0.05)
    assert ok and v == pytest.approx(-0.09)
    # a raw hit behind (e.g. a 360 deg laser) still forbids backing: forward then
    hit_behind = np.array([[3.0, 0.0], [-0.9, 0.2]])
    v, ok = escape_command(hit_behind, WHEELCHAIR_ROBOT, P, prefer_backward=True, not_free_xy=known_free,
                           cell_m=0.05)
    assert ok and v == pytest.approx(0.09)


@pytest.mark.parametrize(
    ("cell_xy", "blocks"),
    [
        ((-0.95, 0.0), True),  # 0.55 m beyond the rear edge, on the axis: within the clearance
        ((-1.02, 0.0), True),  # beyond it, but the cell reaches into it (grown by half a cell)
        ((-1.05, 0.0), False),
        ((-0.6, 0.39), True),  # beside the corridor's edge (0.35 + 0.02), within half a cell
        ((-0.6, 0.42), False),
        ((0.5, 0.0), False),  # ahead: backing away from it
    ],
)
def test_escape_backward_needs_every_cell_behind_known_free(cell_xy: tuple[float, float],
                                                            blocks: bool) -> None:
    blocked_ahead = np.array([[1.0, 0.0]])
    radii: list[float] = []

    def not_free(radius_m: float) -> np.ndarray:
        radii.append(radius_m)
        return np.array([cell_xy])

    v, ok = escape_command(blocked_ahead, WHEELCHAIR_ROBOT, P, not_free_xy=not_free, cell_m=0.05)
    assert (ok, v) == ((False, 0.0) if blocks else (True, pytest.approx(-0.09)))
    # the cells asked for cover the corridor behind and its half-cell growth
    assert radii == [pytest.approx(np.hypot(0.4 + 0.6 + 0.025, 0.35 + 0.02 + 0.025))]


def u_trap(pose: Pose2D, bottom_x: float) -> tuple[RobotCentredGrid, np.ndarray]:
    """A U around the chair (world = robot frame at ``pose`` = origin): side walls 0.6 m from its axis from
    1 m behind to ``bottom_x``, closed there; the mouth behind known FREE. Returns the grid and the raw scan
    of what the laser (0.72 m ahead, front half) sees of the U."""
    walls = [(-1.0, 0.6, bottom_x, 0.6), (-1.0, -0.6, bottom_x, -0.6), (bottom_x, -0.6, bottom_x, 0.6)]
    grid = grid_with_wall(pose, *walls[0])
    scan = []
    for w in walls:
        t = np.linspace(0.0, 1.0, 400)[:, None]
        rc = grid.world_to_cell(np.hstack([w[0] + t * (w[2] - w[0]), w[1] + t * (w[3] - w[1])]))
        grid.cells[rc[:, 0], rc[:, 1]] = OCCUPIED
        pts = wall_points(pose, *w)
        scan.append(pts[pts[:, 0] > 0.72])
    return grid, np.vstack(scan)


def test_u_trap_escape_backs_out_when_the_course_points_behind() -> None:
    """The chair faces the bottom of a U with room before it: forward, the default, drives deeper into the
    U; with the course behind (prefer_backward) it backs out through the known-free mouth; with the mouth
    never seen it does not back, and with the bottom close too there is no escape."""
    pose = Pose2D(0.0, 0.0, 0.0)
    grid, scan = u_trap(pose, 2.2)  # 0.6 m clearance ahead of the front edge (0.8 m): 1.4 m < 2.2 m

    def not_free(radius_m: float) -> np.ndarray:
        return np.vstack([grid.cell_points(pose, radius_m, state) for state in (UNKNOWN, OCCUPIED)])

    kw = {"not_free_xy": not_free, "cell_m": CELL}
    assert escape_command(scan, CHAIR, P, **kw) == (pytest.approx(0.09), True)
    assert escape_command(scan, CHAIR, P, prefer_backward=True, **kw) == (pytest.approx(-0.09), True)
    rc = grid.world_to_cell([[-0.8, 0.0]])[0]
    grid.cells[rc[0] - 2 : rc[0] + 3, rc[1] - 2 : rc[1] + 3] = UNKNOWN  # the mouth, never seen
    assert escape_command(scan, CHAIR, P, prefer_backward=True, **kw) == (pytest.approx(0.09), True)
    grid, scan = u_trap(pose, 1.2)
    assert escape_command(scan, CHAIR, P, prefer_backward=True, **kw) == (pytest.approx(-0.09), True)
    grid.cells[rc[0] - 2 : rc[0] + 3, rc[1] - 2 : rc[1] + 3] = UNKNOWN
    assert escape_command(scan, CHAIR, P, prefer_backward=True, **kw) == (0.0, False)


def test_trap_detector_needs_alternating_stopped_rotations() -> None:
    det = TrapDetector(SupervisorParams(trap_window=20, trap_count=4))
    # rotating steadily one way is not a trap
    assert not any(det.update(Mode.ROTATE, 0.25) for _ in range(10))
    det = TrapDetector(SupervisorParams(trap_window=20, trap_count=4))
    seen = [det.update(Mode.ROTATE, w) for w in (0.25, -0.25, 0.25, -0.25)]
    assert seen == [False, False, False, True]


def test_trap_detector_counts_emergencies() -> None:
    det = TrapDetector(SupervisorParams(trap_window=10, trap_count=3))
    seen = [det.update(m, 0.0) for m in (Mode.EMERGENCY, Mode.MPND, Mode.EMERGENCY, Mode.EMERGENCY)]
    assert seen == [False, False, False, True]


def test_budget_flags() -> None:
    flags = budget_flags({"match": 0.001, "model": 0.06, "planner": 0.01, "reactor": 0.03}, P)
    assert flags == Flag.MODEL_OVER_BUDGET | Flag.REACTOR_OVER_BUDGET
    assert budget_flags({}, P) == Flag.NONE


# ---- shape- and kinematics-aware safety (issue 10) -------------------------------------------------

CHAIR = WHEELCHAIR_ROBOT  # 0.8 m ahead of the axle, 0.4 m behind, 0.7 m wide; laser 0.72 m ahead
CELL = 0.05
NO_SCAN = np.zeros((0, 2))


def test_footprint_signed_distance() -> None:
    pts = np.array([[1.0, 0.0], [0.0, 0.45], [-0.5, 0.0], [0.9, 0.45], [0.0, 0.0], [0.7, 0.3]])
    np.testing.assert_allclose(footprint_signed_distance(pts, CHAIR),
                               [0.2, 0.1, 0.1, np.hypot(0.1, 0.1), -0.35, -0.05])
    np.testing.assert_allclose(footprint_signed_distance(np.array([[0.5, 0.0]]), XR4000_ROBOT), [0.2])


def test_braking_time_uses_the_robots_limits() -> None:
    assert braking_time_s(0.3, 0.0, 0.0, CHAIR, P) == pytest.approx(0.3 + 0.5 * 0.3 / 0.5)
    assert braking_time_s(0.0, 0.0, 0.5, CHAIR, P) == pytest.approx(0.3 + 0.5 * 0.5 / 1.0)
    assert braking_time_s(0.3, 0.4, 0.0, XR4000_ROBOT, P) == pytest.approx(0.3 + 0.5 * 0.5 / 1.5)


def grid_with_wall(pose: Pose2D, x0: float, y0: float, x1: float, y1: float) -> RobotCentredGrid:
    """A 10 x 10 m grid, FREE around ``pose`` (it drove there), with the wall from (x0, y0) to (x1, y1)
    [world m] OCCUPIED: the cells a head-on view of it would mark."""
    grid = RobotCentredGrid(GridParams(200, CELL), centre_xy=(pose.x, pose.y))
    grid.cells[:] = FREE
    t = np.linspace(0.0, 1.0, 400)[:, None]
    rc = grid.world_to_cell(np.hstack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)]))
    grid.cells[rc[:, 0], rc[:, 1]] = OCCUPIED
    return grid


def wall_points(pose: Pose2D, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Dense points of the true wall in the robot frame of ``pose``."""
    t = np.linspace(0.0, 1.0, 2000)
    dx, dy = x0 + t * (x1 - x0) - pose.x, y0 + t * (y1 - y0) - pose.y
    c, s = np.cos(pose.theta), np.sin(pose.theta)
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy])


def check(grid: RobotCentredGrid, pose: Pose2D, v: float, w: float, robot: RobotConfig = CHAIR,
          scan: np.ndarray = NO_SCAN, vy: float = 0.0) -> SafeCommand:
    reach = safety_reach_m(robot, P, CELL)
    return safe_command(v, vy, w, scan, grid.occupied_points(pose, reach), robot, P, cell_m=CELL,
                        unknown_xy=lambda: grid.cell_points(pose, reach, UNKNOWN))


def drive(pose: Pose2D, v: float, w: float, dt: float) -> Pose2D:
    """Exact constant-twist motion of a differential-drive robot."""
    if abs(w) < 1e-12:
        return Pose2D(pose.x + v * dt * np.cos(pose.theta), pose.y + v * dt * np.sin(pose.theta), pose.theta)
    th = pose.theta + w * dt
    return Pose2D(pose.x + v / w * (np.sin(th) - np.sin(pose.theta)),
                  pose.y - v / w * (np.cos(th) - np.cos(pose.theta)), th)


def touches_wall(pose: Pose2D, wall: tuple[float, float, float, float]) -> bool:
    return bool((footprint_signed_distance(wall_points(pose, *wall), CHAIR) <= 0.0).any())


def test_chair_turning_in_place_beside_a_wall_behind_the_laser_does_not_touch_it() -> None:
    # a wall 4 cm from the chair's left side, beside its rear half: behind the laser (0.72 m ahead, 180 deg
    # field of view), so only the grid holds it. Turning right in place swings the rear-left corner into it.
    pose = Pose2D(0.013, 0.021, 0.0)
    wall = (-1.5, 0.411, -0.05, 0.411)
    grid = grid_with_wall(pose, *wall)
    p = pose
    for _ in range(20):  # 4 s of turning right at 0.25 rad/s would turn the chair into the wall
        p = drive(p, 0.0, -0.25, 0.2)
    assert touches_wall(p, wall)
    safe = check(grid, pose, 0.0, -0.25)
    assert safe.rule is Mode.SAFE_SLOW and safe.w_radps == pytest.approx(-0.0625)
    # closed loop: keep asking for the right turn, apply what the check allows: slower, then the other way
    p, rules = pose, []
    for _ in range(40):
        cmd = check(grid_with_wall(p, *wall), p, 0.0, -0.25)
        rules.append(cmd.rule)
        p = drive(p, cmd.v_mps, cmd.w_radps, 0.2)
        assert not touches_wall(p, wall)
    assert Mode.SAFE_TURN in rules


def test_turning_towards_the_free_side_is_not_altered() -> None:
    pose = Pose2D(0.013, 0.021, 0.0)
    grid = grid_with_wall(pose, -1.5, 0.411, -0.05, 0.411)
    assert check(grid, pose, 0.0, 0.25).rule is None


def test_a_command_towards_a_wall_seen_only_in_the_grid_is_replaced_before_contact() -> None:
    wall = (1.5, -3.0, 1.5, 3.0)  # 0.7 m ahead of the chair's front edge, not in the scan
    pose = Pose2D(0.013, 0.021, 0.0)
    rules = []
    for _ in range(60):
        cmd = check(grid_with_wall(pose, *wall), pose, 0.3, 0.0)
        rules.append(cmd.rule)
        pose = drive(pose, cmd.v_mps, cmd.w_radps, 0.2)
        assert not touches_wall(pose, wall)
    assert rules[0] is None  # far enough at first
    assert Mode.SAFE_SLOW in rules and rules[-1] is Mode.EMERGENCY  # slowed, then stopped short
    front_gap = 1.5 - pose.x - CHAIR.front_m
    assert 0.0 < front_gap < 0.1


def test_a_command_parallel_to_a_wall_is_not_altered() -> None:
    # driving along a wall 5 cm beside the chair, in the grid and in the scan
    pose = Pose2D(0.013, 0.021, 0.0)
    wall = (-3.0, 0.421, 3.0, 0.421)
    grid = grid_with_wall(pose, *wall)
    scan = wall_points(pose, *wall)
    scan = scan[scan[:, 0] > 0.72]  # what the laser sees of it
    for v, w in ((0.3, 0.0), (0.15, 0.0), (0.3, -0.05)):  # straight, slower, veering away
        cmd = check(grid, pose, v, w, scan=scan)
        assert cmd.rule is None and (cmd.v_mps, cmd.w_radps) == (v, w)


def test_slower_arc_when_only_the_full_speed_arc_touches() -> None:
    pose = Pose2D(0.013, 0.021, 0.0)
    grid = grid_with_wall(pose, 0.97, -3.0, 0.97, 3.0)  # 0.16 m ahead of the front edge
    cmd = check(grid, pose, 0.3, 0.1)
    assert cmd.rule is Mode.SAFE_SLOW
    assert (cmd.v_mps, cmd.w_radps) == pytest.approx((0.15, 0.05))


def test_short_reverse_only_through_known_free_cells() -> None:
    # a dead end: walls ahead and 3 cm from both sides; every forward motion and turn touches
    pose = Pose2D(0.013, 0.021, 0.0)
    grid = grid_with_wall(pose, 0.85, -3.0, 0.85, 3.0)
    for y in (0.401, -0.401):
        rc = grid.world_to_cell(np.column_stack([np.linspace(-2.0, 0.9, 300), np.full(300, y)]))
        grid.cells[rc[:, 0], rc[:, 1]] = OCCUPIED
    cmd = check(grid, pose, 0.3, 0.2)
    assert cmd.rule is Mode.SAFE_REVERSE and cmd.v_mps == pytest.approx(-0.3 * 0.3) and cmd.w_radps == 0.0
    # the same dead end, never seen behind: stop
    rc = grid.world_to_cell([[-0.6, 0.0]])[0]
    grid.cells[rc[0] - 3 : rc[0] + 4, rc[1] - 3 : rc[1] + 4] = UNKNOWN
    cmd = check(grid, pose, 0.3, 0.2)
    assert cmd.rule is Mode.EMERGENCY and (cmd.v_mps, cmd.vy_mps, cmd.w_radps) == (0.0, 0.0, 0.0)


def test_raw_scan_points_count_as_well() -> None:
    grid = grid_with_wall(Pose2D(0.0, 0.0, 0.0), 4.0, -1.0, 4.0, 1.0)
    scan = np.array([[0.95, 0.0]])
    assert check(grid, Pose2D(0.0, 0.0, 0.0), 0.3, 0.0, scan=scan).rule is not None
    assert check(grid, Pose2D(0.0, 0.0, 0.0), 0.0, 0.0, scan=scan).rule is None  # standing still


def test_trap_detector_counts_dithering_in_any_mode() -> None:
    """w flipping sign every tick while the robot stays put is a trap in mpND and the safety modes too,
    not only in ROTATE; the same turning with progress (or steady one-way turning) is not."""
    params = SupervisorParams(trap_window=20, trap_count=6)
    wmax = WHEELCHAIR_ROBOT.wmax_radps
    modes = (Mode.MPND, Mode.SAFE_SLOW, Mode.SAFE_TURN, Mode.MND)
    det = TrapDetector(params, wmax)
    seen = [det.update(modes[i % 4], 0.5 * (-1) ** i, (1.0, 2.0, 0.3 + 0.01 * (-1) ** i)) for i in range(20)]
    assert seen[-1] and not any(seen[:-1])  # fires once the window is full
    moving = TrapDetector(params, wmax)
    assert not any(moving.update(Mode.MPND, 0.5 * (-1) ** i, (0.03 * i, 0.0, 0.0)) for i in range(40))
    steady = TrapDetector(params, wmax)
    assert not any(steady.update(Mode.SAFE_SLOW, 0.2, (0.0, 0.0, 0.0)) for _ in range(40))
    tiny = TrapDetector(params, wmax)  # small steering corrections are not dithering
    assert not any(tiny.update(Mode.MPND, 0.01 * (-1) ** i, (0.0, 0.0, 0.0)) for i in range(40))


def test_grid_cells_the_scan_confirms_are_checked_through_its_hits() -> None:
    cells = np.array([[1.025, 0.425], [1.025, -0.425], [2.025, 1.025]])
    hits = np.array([[1.01, 0.41], [3.0, 0.0]])  # a hit in the first cell only
    kept = unconfirmed_cells(cells, hits, 0.05)
    assert kept.tolist() == [[1.025, -0.425], [2.025, 1.025]]
    assert unconfirmed_cells(cells, np.zeros((0, 2)), 0.05).shape == (3, 2)


def test_chair_between_jamb_cells_goes_straight_instead_of_turning() -> None:
    """Jambs beside the chair, seen only in the grid, 4 cm from each side (inside the grown margin): any
    turn swings a side towards one; the same speed straight on passes them parallel (SAFE_TURN, w = 0)."""
    r = WHEELCHAIR_ROBOT
    xs = np.arange(0.0, 0.1, 0.05) + 0.125
    side = r.width_m / 2.0 + 0.04
    jambs = np.vstack([np.column_stack([xs, np.full(xs.size, side)]),
                       np.column_stack([xs, np.full(xs.size, -side)])])
    out = safe_command(0.1, 0.0, 0.05, np.zeros((0, 2)), jambs, r, P, cell_m=0.05)
    assert out.rule is Mode.SAFE_TURN and out.w_radps == 0.0 and out.v_mps == 0.1


def test_a_commanded_reverse_must_avoid_unknown_cells() -> None:
    r = WHEELCHAIR_ROBOT
    behind = np.array([[-r.rear_m - 0.04, 0.0], [-r.rear_m - 0.04, 0.1]])  # within the grown margin
    free = safe_command(-0.09, 0.0, 0.0, np.zeros((0, 2)), np.zeros((0, 2)), r, P, cell_m=0.05,
                        unknown_xy=lambda: np.zeros((0, 2)))
    assert free.rule is None and free.v_mps == -0.09
    unseen = safe_command(-0.09, 0.0, 0.0, np.zeros((0, 2)), np.zeros((0, 2)), r, P, cell_m=0.05,
                          unknown_xy=lambda: behind)
    assert unseen.rule is Mode.EMERGENCY and unseen.v_mps == 0.0


# ---- one obstacle test for the reflexive loop and the mode selector ----------------------------------


def door_jambs(gap_m: float) -> np.ndarray:
    """Jamb points ``gap_m`` beside each side of the chair's middle (robot frame)."""
    xs = np.array([0.125, 0.175])
    side = CHAIR.width_m / 2.0 + gap_m
    return np.vstack([np.column_stack([xs, np.full(2, side)]), np.column_stack([xs, np.full(2, -side)])])


def test_swept_touch_names_the_source_and_adds_the_margin() -> None:
    ahead = np.array([[0.95, 0.0]])  # 0.15 m ahead of the front edge; 0.3 m/s sweeps 0.18 m
    none = np.zeros((0, 2))
    assert swept_touch(0.3, 0.0, 0.0, ahead, none, CHAIR, P, cell_m=CELL) == "scan"
    assert swept_touch(0.3, 0.0, 0.0, none, ahead, CHAIR, P, cell_m=CELL) == "grid"
    assert swept_touch(0.3, 0.0, 0.0, ahead, ahead, CHAIR, P, cell_m=CELL) == "scan"  # the scan first
    assert swept_touch(0.0, 0.0, 0.0, ahead, ahead, CHAIR, P, cell_m=CELL) == ""
    assert swept_touch(-0.3, 0.0, 0.0, ahead, ahead, CHAIR, P, cell_m=CELL) == ""
    # 0.04 m beside the chair: a slight turn approaches; a hit is outside the 0.02 m margin, a cell (grown
    # by 0.025 m) inside it; a selector margin of 0.05 m catches the hit too
    jambs = door_jambs(0.04)
    assert swept_touch(0.1, 0.0, 0.05, jambs, none, CHAIR, P, cell_m=CELL) == ""
    assert swept_touch(0.1, 0.0, 0.05, none, jambs, CHAIR, P, cell_m=CELL) == "grid"
    assert swept_touch(0.1, 0.0, 0.05, jambs, none, CHAIR, P, cell_m=CELL, margin_m=0.05) == "scan"


def test_selector_treats_scan_confirmed_cells_as_the_safety_check_does() -> None:
    """The jamb cells hold the scan's hits: both the safety check and the selector (margin 0) check them
    through the hits and let a slight turn through; unconfirmed (no scan), both flag the grid."""
    jambs = door_jambs(0.04)
    none = np.zeros((0, 2))
    for scan, where in ((jambs, ""), (none, "grid")):
        safe = safe_command(0.1, 0.0, 0.05, scan, jambs, CHAIR, P, cell_m=CELL)
        assert swept_area_occupied(0.1, 0.0, 0.05, scan, jambs, CHAIR, P, cell_m=CELL, margin_m=0.0) == where
        assert (safe.rule is None) == (where == "")


def test_selector_at_margin_zero_agrees_with_the_safety_check() -> None:
    """Over a spread of commands and a cluttered neighbourhood (some cells confirmed by hits, some not),
    the selector with no margin flags a command exactly when ``safe_command`` replaces it."""
    rng = np.random.default_rng(3)
    cells = (np.floor(rng.uniform(-1.5, 1.5, (60, 2)) / CELL) + 0.5) * CELL
    cells = cells[footprint_signed_distance(cells, CHAIR) > 0.05]
    scan = cells[cells[:, 0] > 0.72][::2] + rng.uniform(-0.02, 0.02, (1, 2))  # hits in half the cells ahead
    flagged = 0
    for v in (-0.2, 0.0, 0.1, 0.3):
        for w in (-0.5, -0.1, 0.0, 0.1, 0.5):
            where = swept_area_occupied(v, 0.0, w, scan, cells, CHAIR, P, cell_m=CELL, margin_m=0.0)
            assert (where == "") == (safe_command(v, 0.0, w, scan, cells, CHAIR, P, cell_m=CELL).rule is None)
            flagged += where != ""
    assert 0 < flagged < 19  # the spread covers both outcomes


@pytest.mark.parametrize("n_side", [3, 15])  # 9 and 225 cells
def test_unconfirmed_cells_keeps_exactly_the_cells_without_a_hit(n_side: int) -> None:
    rng = np.random.default_rng(n_side)
    ij = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side)), axis=-1).reshape(-1, 2)
    cells = ij * 0.2 + 0.025  # cell centres 0.2 m apart
    confirmed = rng.random(cells.shape[0]) < 0.5
    hits_in = cells[confirmed] + rng.uniform(-0.024, 0.024, (int(confirmed.sum()), 2))  # inside the cell
    hits_far = cells[~confirmed] + 0.1  # between cells, 0.14 m from any centre
    kept = unconfirmed_cells(cells, np.vstack([hits_in, hits_far]), CELL)
    assert kept.tolist() == cells[~confirmed].tolist()


def test_trap_detector_counts_rocking_forward_and_back_without_turning() -> None:
    """v flipping sign (|v| >= trap_w_frac * vmax) with w = 0 while the robot stays put is dithering too
    (a chair wedged at a wall, rocking); the same rocking with progress, steady driving, creeping below the
    threshold, or reversals short of trap_count are not."""
    params = SupervisorParams(trap_window=20, trap_count=6)
    r = WHEELCHAIR_ROBOT
    v = 0.2 * r.vmax_mps

    def rock(v_of: object, pose_of: object, n: int = 20) -> list[bool]:
        det = TrapDetector(params, r.wmax_radps, r.vmax_mps)
        return [det.update(Mode.MND, 0.0, pose_of(i), v_of(i)) for i in range(n)]  # type: ignore[operator]

    seen = rock(lambda i: v * (-1) ** (i // 2), lambda i: (1.0, 2.0, 0.3))
    assert seen[-1] and not any(seen[:-1])
    assert not any(rock(lambda i: v * (-1) ** (i // 2), lambda i: (0.02 * i, 0.0, 0.0), 40))  # progress
    assert not any(rock(lambda i: v, lambda i: (1.0, 2.0, 0.3), 40))  # one way (pushing at nothing)
    creep = 0.05 * r.vmax_mps
    assert not any(rock(lambda i: creep * (-1) ** i, lambda i: (1.0, 2.0, 0.3), 40))
    assert not any(rock(lambda i: v * (-1) ** (i // 4), lambda i: (1.0, 2.0, 0.3), 20))  # 4 reversals
    # turn and travel reversals add up: 3 of each in a window is the same stall
    det = TrapDetector(params, r.wmax_radps, r.vmax_mps)
    mixed = [det.update(Mode.MND, 0.3 * (-1) ** (i // 3) if i < 12 else 0.0, (1.0, 2.0, 0.3),
                        v * (-1) ** (i // 2) if i >= 12 else 0.0) for i in range(20)]
    assert mixed[-1]


def test_straight_on_replaces_a_turn_only_with_a_full_speed_stop_distance_free() -> None:
    """The jamb cells beside the chair of ``test_chair_between_jamb_cells_goes_straight_instead_of_turning``
    and a wall across its way: at 0.05 m/s the command's own braking horizon is about 2 cm, so straight on
    would pass a wall 10 cm ahead, tick after tick, until the chair is wedged there. Straight on must be
    free for ``straight_min_m`` (the full-speed stop distance): with the wall 10 cm ahead it is not (the
    chair stops), with the wall beyond that distance it is."""
    r = WHEELCHAIR_ROBOT
    assert straight_min_m(r, P) == pytest.approx(r.vmax_mps * braking_time_s(r.vmax_mps, 0.0, 0.0, r, P))
    xs = np.arange(0.0, 0.1, 0.05) + 0.125
    side = r.width_m / 2.0 + 0.04
    jambs = np.vstack([np.column_stack([xs, np.full(xs.size, side)]),
                       np.column_stack([xs, np.full(xs.size, -side)])])
    ys = np.linspace(-0.3, 0.3, 13)

    def ahead(gap_m: float) -> np.ndarray:
        return np.column_stack([np.full(ys.size, r.front_m + gap_m), ys])

    near = safe_command(0.05, 0.0, 0.05, ahead(0.1), jambs, r, P, cell_m=0.05)
    assert near.rule is not None and near.v_mps <= 0.0  # no forward motion towards the wall
    far = safe_command(0.05, 0.0, 0.05, ahead(straight_min_m(r, P) + 0.1), jambs, r, P, cell_m=0.05)
    assert far.rule is Mode.SAFE_TURN and far.w_radps == 0.0 and far.v_mps == 0.05
    # the wall 10 cm ahead is not touched within the slow command's own horizon: only the new rule stops it
    assert not swept_collision(ahead(0.1), 0.05, 0.0, r, P)


def _arc_touches_by_poses(points: np.ndarray, v: float, vy: float, w: float, t_end: float, robot: RobotConfig,
                          margin: float) -> bool:
    """``arc_touches``'s rule written over arrays: every point at every pose of ``arc_poses``."""
    px, py, th = arc_poses(v, vy, w, t_end, robot)
    dx, dy = points[None, :, 0] - px[:, None], points[None, :, 1] - py[:, None]
    ct, st = dm.cos_a(th)[:, None], dm.sin_a(th)[:, None]
    d = footprint_signed_distance(np.stack([ct * dx + st * dy, -st * dx + ct * dy], axis=-1), robot)
    return bool(np.any((d[1:] <= margin) & (d[1:] < d[:1] - 1e-9)))


@pytest.mark.parametrize("robot", [WHEELCHAIR_ROBOT, XR4000_ROBOT], ids=["rectangle", "circle"])
def test_arc_touches_agrees_with_the_rule_over_every_pose(robot: RobotConfig) -> None:
    """The kernel (reach filter, early exit) decides as the plain rule over all points and poses."""
    rng = np.random.default_rng(5)
    agree = touched = 0
    for _ in range(400):
        pts = rng.normal(0.0, 1.0, (int(rng.integers(1, 40)), 2))
        v, vy = float(rng.normal(0.0, 0.5)), float(rng.normal(0.0, 0.3)) * (robot.drive == "holonomic")
        w, t_end, margin = float(rng.choice([0.0, rng.normal(0.0, 1.0)])), float(rng.uniform(0.05, 2.0)), 0.02
        expected = _arc_touches_by_poses(pts, v, vy, w, t_end, robot, margin)
        agree += arc_touches(pts, v, vy, w, t_end, robot, margin) == expected
        touched += expected
    assert agree == 400
    assert 40 < touched < 360  # both answers are exercised


def test_arc_poses_span_the_horizon_evenly() -> None:
    px, py, th = arc_poses(0.5, 0.0, 0.8, 0.7, WHEELCHAIR_ROBOT)
    assert th[0] == 0.0 and th[-1] == 0.8 * 0.7
    assert np.allclose(np.diff(th), th[-1] / (th.size - 1))
    assert np.allclose(np.hypot(px, py), 2.0 * (0.5 / 0.8) * np.abs(np.sin(th / 2.0)))  # chord of the arc


def _arrive(arrival: GoalArrival, x: float, t_s: float, goal: tuple[float, float] = (10.0, 0.0)) -> bool:
    """The robot at (x, 0) heading +x, the goal ``goal`` in the world, at ``t_s``."""
    return arrival.update(np.array([goal[0] - x, goal[1]]), goal, round(t_s * 1e9))


def test_the_goal_is_reached_within_half_the_tolerance_and_stays_reached_within_it() -> None:
    """Within the 0.3 m tolerance the robot drives on to 0.15 m (a stop on the tolerance's edge hands the
    whole pose error to the task), then the goal stays reached while the estimate jitters within 0.3 m."""
    a = GoalArrival(SupervisorParams())
    assert not _arrive(a, 9.5, 0.0)  # 0.5 m: outside
    assert not _arrive(a, 9.72, 0.2)  # 0.28 m: within the tolerance, still getting closer
    assert not _arrive(a, 9.8, 0.4)
    assert _arrive(a, 9.86, 0.6)  # 0.14 m
    assert _arrive(a, 9.75, 0.8)  # 0.25 m: the pose estimate jumped back, still reached
    assert not _arrive(a, 9.65, 1.0)  # 0.35 m: out of the tolerance, not reached
    assert not _arrive(a, 9.72, 1.2)
    papers = GoalArrival(SupervisorParams(goal_arrive_frac=1.0))
    assert not _arrive(papers, 9.5, 0.0) and _arrive(papers, 9.72, 0.2)  # the papers: the edge


def test_a_goal_the_robot_cannot_get_closer_to_is_reached_after_the_settling_time() -> None:
    """A goal beside an obstacle: the robot stops 0.25 m from it; no 2 cm of progress for 1 s reaches it.
    A goal moved is a new goal."""
    a = GoalArrival(SupervisorParams())
    t = 0.0
    for x in (9.70, 9.74, 9.75, 9.75, 9.751, 9.75):
        assert not _arrive(a, x, t)
        t += 0.2
    assert _arrive(a, 9.75, 1.2)  # 1.0 s after 9.74 m, the last 2 cm of progress (0.26 m)
    assert not _arrive(a, 9.75, 1.4, goal=(10.0, 0.1))  # the goal moved 10 cm: settle again
