"""Path following: cubic spirals, the path manager and the tracking controller in closed loop with a plain
unicycle integrator (acceleration-limited, no simulator) on empty or synthetic grids."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import cast

import numpy as np
import pytest

from gndreplay.geometry import wrap_angle
from gndreplay.pipeline.cspace import free_cspace
from gndreplay.pipeline.follow import (
    FollowCommand,
    FollowParams,
    PathFollower,
    free_point_ahead,
    is_passed,
    plan_trajectory,
    replacement_point,
    sample_spiral,
    solve_spiral,
)
from gndreplay.pipeline.model import FREE, OCCUPIED, GridParams, RobotCentredGrid
from gndreplay.pipeline.nf1 import Nf1Params, nearest_true, nf1_wavefront
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig
from gndreplay.types import Pose2D, Subgoal, SubgoalKind

DT = 0.1
ROBOTS = pytest.mark.parametrize("robot", [WHEELCHAIR_ROBOT, XR4000_ROBOT], ids=["wheelchair", "xr4000"])
PARAMS = FollowParams()


def empty_grid(centre: tuple[float, float] = (0.0, 0.0)) -> RobotCentredGrid:
    return RobotCentredGrid(GridParams(size_cells=400, cell_m=0.05), centre)


@dataclass
class Run:
    """A closed-loop run: the pose, measured speeds and command of every tick."""

    poses: list[Pose2D] = field(default_factory=list)
    v: list[float] = field(default_factory=list)
    cmds: list[FollowCommand] = field(default_factory=list)

    def events(self, name: str) -> list[int]:
        return [k for k, c in enumerate(self.cmds) if c.event == name]


def drive(follower: PathFollower, pose: Pose2D, grid: RobotCentredGrid, robot: RobotConfig, *,
          t_max_s: float = 90.0, push: tuple[int, float, float] | None = None,
          on_tick: Callable[[int, RobotCentredGrid], None] | None = None) -> Run:
    """Integrate the follower's commands on a unicycle whose v and w follow the command within the
    robot's acceleration limits; ``push`` = (tick, dx, dy) displaces the robot once; ``on_tick(k, grid)``
    edits the grid before tick k."""
    run = Run()
    v = w = 0.0
    for k in range(int(t_max_s / DT)):
        if on_tick is not None:
            on_tick(k, grid)
        if push is not None and k == push[0]:
            pose = Pose2D(pose.x + push[1], pose.y + push[2], pose.theta)
        cmd = follower.step(pose, grid, v_mps=v, w_radps=w)
        run.poses.append(pose)
        run.v.append(v)
        run.cmds.append(cmd)
        if cmd.done:
            break
        assert abs(cmd.v_mps) <= robot.vmax_mps + 1e-9 and abs(cmd.w_radps) <= robot.wmax_radps + 1e-9
        v += float(np.clip(cmd.v_mps - v, -robot.accel_mps2 * DT, robot.accel_mps2 * DT))
        w += float(np.clip(cmd.w_radps - w, -robot.alpha_radps2 * DT, robot.alpha_radps2 * DT))
        th = pose.theta + 0.5 * w * DT
        pose = Pose2D(pose.x + v * DT * math.cos(th), pose.y + v * DT * math.sin(th), pose.theta + w * DT)
    return run


def heading_error(pose: Pose2D, goal: Subgoal) -> float:
    return abs(float(wrap_angle(pose.theta - goal.theta)))


# ---- trajectory generator ------------------------------------------------------------------------------


def test_spiral_reaches_the_goal_pose_with_the_end_curvatures() -> None:
    rng = np.random.default_rng(3)
    solved = 0
    for _ in range(60):
        r, b, th = rng.uniform(0.8, 5.0), rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8)
        start = (float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)), float(rng.uniform(-math.pi, math.pi)))
        c, s = math.cos(start[2]), math.sin(start[2])
        gx, gy = r * math.cos(b), r * math.sin(b)
        goal = (start[0] + c * gx - s * gy, start[1] + s * gx + c * gy, start[2] + th)
        k0 = float(rng.uniform(-0.5, 0.5))
        sp = solve_spiral(start, goal, kappa0=k0, kappa_max=PARAMS.kappa_max)
        if sp is None:
            continue
        solved += 1
        xy, heading, kappa, arc = sample_spiral(sp, 0.05)
        assert np.allclose(xy[0], start[:2]) and np.allclose(xy[-1], goal[:2], atol=1e-3)
        assert abs(float(wrap_angle(heading[-1] - goal[2]))) < 1e-3
        assert kappa[0] == pytest.approx(k0, abs=1e-9) and kappa[-1] == pytest.approx(0.0, abs=1e-9)
        # the samples are spaced by their arc length and the heading is the direction of travel
        step = np.diff(xy, axis=0)
        assert np.allclose(np.hypot(step[:, 0], step[:, 1]), np.diff(arc), rtol=0.01)
        chord = np.arctan2(step[:, 1], step[:, 0])
        mid = heading[:-1] + 0.5 * np.asarray(wrap_angle(heading[1:] - heading[:-1]))
        assert np.max(np.abs(np.asarray(wrap_angle(chord - mid)))) < 0.01
        assert sp.length < 2.5 * r + math.pi / PARAMS.kappa_max
    assert solved >= 50  # moderate turns ahead of the robot are solved by a spiral, not a fallback


def test_trajectory_curvature_is_continuous() -> None:
    pose = Pose2D(0.0, 0.0, 0.3)
    for goal, k0 in [(Subgoal(4.0, 2.0, 1.2), 0.4), (Subgoal(3.0, -1.0, -0.5), -0.2),
                     (Subgoal(-3.0, 0.5, 0.0, "reverse"), 0.0)]:
        traj = plan_trajectory(pose, goal, PARAMS, direction=-1 if goal.kind == "reverse" else 1,
                               stops=False, kappa0=k0)
        assert traj.kind == "spiral"
        assert traj.kappa[0] == pytest.approx(k0)
        # |dkappa| between samples is |kappa'| * sample_m, kappa' (sharpness) below 3 / m^2 on these moderate
        # turns; a jump (arc after a line: 1 / radius at once) would be ten times that. The straight
        # extension starts at the spiral's end curvature 0.
        dk = np.abs(np.diff(traj.kappa))
        assert dk.max() < 3.0 * PARAMS.sample_m, dk.max()
        dh = np.abs(np.asarray(wrap_angle(np.diff(traj.heading))))
        assert dh.max() < PARAMS.kappa_max * PARAMS.sample_m * 1.01


def test_reverse_trajectory_runs_backwards() -> None:
    traj = plan_trajectory(Pose2D(0.0, 0.0, 0.0), Subgoal(-2.0, 0.5, 0.0, "reverse"), PARAMS, direction=-1,
                           stops=False)
    assert traj.direction == -1 and traj.turn_to is None
    assert traj.heading[0] == pytest.approx(math.pi)  # travel points behind the robot
    assert np.all(np.diff(traj.xy[traj.s <= traj.s_goal, 0]) < 0.0)


def test_fallback_turns_towards_a_subgoal_beside_the_robot() -> None:
    traj = plan_trajectory(Pose2D(0.0, 0.0, 0.0), Subgoal(0.0, 0.5, 0.0), PARAMS, direction=1, stops=False)
    assert traj.kind in ("turn-spiral", "turn-line")
    assert traj.turn_to == pytest.approx(math.pi / 2)
    assert np.allclose(traj.xy[traj.s <= traj.s_goal][-1], (0.0, 0.5), atol=1e-3)


# ---- closed loop ---------------------------------------------------------------------------------------


@ROBOTS
def test_forward_subgoals_reached_with_the_heading_asked(robot: RobotConfig) -> None:
    subgoals = [Subgoal(3.0, 0.0, 0.0), Subgoal(5.0, 2.0, math.pi / 2), Subgoal(3.5, 4.0, math.pi),
                Subgoal(1.0, 3.0, -2.0)]
    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot)
    reached = run.events("reached")
    assert len(reached) == len(subgoals) and run.cmds[-1].done
    assert not run.events("skipped") and not run.events("replanned")
    for i, k in enumerate(reached):
        pose, goal = run.poses[k], subgoals[i]
        assert run.cmds[k].subgoal_index == i + 1
        assert math.hypot(pose.x - goal.x, pose.y - goal.y) <= PARAMS.reach_m
        assert heading_error(pose, goal) <= PARAMS.heading_tol_rad
    # passing through intermediate subgoals without stopping
    assert all(run.v[k] > 0.5 * robot.vmax_mps for k in reached[:-1])
    last = run.cmds[-1]
    assert last.v_mps == 0.0 and last.w_radps == 0.0 and last.subgoal_index == len(subgoals)
    assert last.trajectory_xy.shape == (0, 2)


@ROBOTS
def test_stop_subgoals_end_at_rest_with_the_heading_asked(robot: RobotConfig) -> None:
    subgoals = [Subgoal(2.5, 1.0, math.pi / 2, "stop"), Subgoal(4.0, 3.0, 0.0, "stop")]
    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot)
    reached = run.events("reached")
    assert len(reached) == 2 and run.cmds[-1].done
    for i, k in enumerate(reached):
        pose, goal = run.poses[k], subgoals[i]
        assert abs(run.v[k]) <= PARAMS.stop_v_mps
        assert math.hypot(pose.x - goal.x, pose.y - goal.y) <= PARAMS.settle_m + 0.02
        assert heading_error(pose, goal) <= PARAMS.heading_tol_rad
    # it slowed down before the first stop within the braking deceleration
    k = reached[0]
    decel = -np.diff(np.array(run.v[:k + 1])) / DT
    assert decel.max() <= robot.accel_mps2 + 1e-9
    assert "stabilise" in {c.mode for c in run.cmds[:k]}


@ROBOTS
def test_reverse_subgoal_reached_driving_backwards(robot: RobotConfig) -> None:
    subgoals = [Subgoal(2.0, 0.0, 0.0, "stop"), Subgoal(0.0, 1.0, 0.0, "reverse"), Subgoal(1.0, 2.5, 1.2)]
    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot)
    reached = run.events("reached")
    assert len(reached) == 3 and run.cmds[-1].done
    seg = range(reached[0] + 1, reached[1] + 1)
    moving = [run.v[k] for k in seg if abs(run.v[k]) > 0.02]
    assert moving and max(moving) < 0.0  # the whole reverse leg is driven backwards
    pose = run.poses[reached[1]]
    assert math.hypot(pose.x, pose.y - 1.0) <= PARAMS.reach_m
    assert heading_error(pose, subgoals[1]) <= PARAMS.heading_tol_rad
    # brakes out of the reverse motion, then forwards to the last subgoal and never backwards again
    after = np.array(run.v[reached[1]:reached[2] + 1])
    first_fwd = int(np.argmax(after > 0.0))
    assert first_fwd > 0 and np.all(np.diff(after[:first_fwd + 1]) > 0.0)
    assert after[first_fwd:].min() > -0.02


def test_passed_subgoal_is_skipped() -> None:
    robot = XR4000_ROBOT
    # the robot already stands 1 m past the first subgoal, on the way to the second
    subgoals = [Subgoal(-1.0, 0.3, 0.0), Subgoal(3.0, 0.0, 0.0)]
    assert is_passed(Pose2D(0.0, 0.0, 0.0), subgoals[0], subgoals[1], PARAMS.reach_m)
    assert not is_passed(Pose2D(-1.1, 0.0, 0.0), subgoals[0], subgoals[1], PARAMS.reach_m)
    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot)
    assert run.cmds[0].event == "skipped" and run.cmds[0].subgoal_index == 1
    assert run.cmds[0].v_mps > 0.0  # straight on, no turning back
    assert run.cmds[-1].done and len(run.events("reached")) == 1
    assert min(p.x for p in run.poses) >= -0.05
    # a stop subgoal is never skipped: the robot comes back for it
    f = PathFollower([Subgoal(-1.0, 0.3, 0.0, "stop"), Subgoal(3.0, 0.0, 0.0)], PARAMS, robot,
                     inflate_m=robot.inner_radius_m)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot)
    assert not run.events("skipped") and len(run.events("reached")) == 2


def _block(grid: RobotCentredGrid, x0: float, x1: float, y0: float, y1: float,
           state: np.uint8 = OCCUPIED) -> None:
    (r0, c0), (r1, c1) = grid.world_to_cell(np.array([[x0, y0], [x1, y1]]))
    grid.cells[r0:r1 + 1, c0:c1 + 1] = state


def test_subgoal_inside_an_obstacle_is_replaced_by_a_reachable_free_point() -> None:
    robot = XR4000_ROBOT
    grid = empty_grid()
    # a closed ring (x 1.5..4.5, y -1.5..1.5) around a solid block holding the subgoal at (3, 0): the free
    # pocket inside the ring is nearer the subgoal than any free point outside, but not reachable
    _block(grid, 1.5, 4.5, -1.5, -1.4)
    _block(grid, 1.5, 4.5, 1.4, 1.5)
    _block(grid, 1.5, 1.6, -1.5, 1.5)
    _block(grid, 4.4, 4.5, -1.5, 1.5)
    _block(grid, 2.6, 3.4, -0.4, 0.4)
    free = free_cspace(grid.cells, cell_m=0.05, inflate_m=robot.inner_radius_m)
    goal_rc = tuple(int(v) for v in grid.world_to_cell(np.array([3.0, 0.0]))[0])
    assert not free[goal_rc]
    naive = nearest_true(free, (goal_rc[0], goal_rc[1]), 60.0)
    assert naive is not None
    nx, ny = grid.cells_to_world(np.array([naive]))[0]
    assert 1.6 < nx < 4.4 and abs(ny) < 1.4  # the plain nearest free cell is in the enclosed pocket

    subgoals = [Subgoal(3.0, 0.0, 0.0)]
    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    cmd = f.step(Pose2D(0.0, 0.0, 0.0), grid)
    assert cmd.event == "replaced" and cmd.subgoal_index == 0
    x, y = cmd.subgoal_xy
    assert not (1.5 <= x <= 4.5 and -1.5 <= y <= 1.5)  # outside the ring
    rc = tuple(int(v) for v in grid.world_to_cell(np.array([x, y]))[0])
    reach = np.isfinite(nf1_wavefront(free, grid.robot_cell(Pose2D(0.0, 0.0, 0.0))))
    assert free[rc] and reach[rc]
    # the nearest such point: no reachable free cell is nearer the subgoal
    rr, cc = np.nonzero(reach & free)
    pts = grid.cells_to_world(np.column_stack([rr, cc]))
    assert math.hypot(x - 3.0, y) <= np.hypot(pts[:, 0] - 3.0, pts[:, 1]).min() + 1e-9
    assert np.allclose(cmd.trajectory_xy[-1], (x, y), atol=1e-3)
    # the follower then reaches the replacement
    run = drive(f, Pose2D(0.0, 0.0, 0.0), grid, robot)
    assert run.cmds[-1].done and len(run.events("reached")) == 1


def test_obstacle_appearing_on_a_subgoal_then_leaving() -> None:
    robot = XR4000_ROBOT
    subgoals = [Subgoal(4.0, 0.0, 0.0), Subgoal(4.0, 3.0, math.pi / 2, "stop")]

    def person(k: int, grid: RobotCentredGrid) -> None:  # stands on the first subgoal for ticks 10 to 29
        if k in (10, 30):
            _block(grid, 3.7, 4.3, -0.3, 0.3, OCCUPIED if k == 10 else FREE)

    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot, on_tick=person)
    assert run.events("replaced") == [10, 30]
    moved = run.cmds[10].subgoal_xy
    assert math.hypot(moved[0] - 4.0, moved[1]) > 0.3 + robot.inner_radius_m - 0.05  # outside the person
    assert all(c.subgoal_xy == moved for c in run.cmds[10:30])
    assert run.cmds[30].subgoal_xy == (4.0, 0.0)  # the original is back once free
    k = run.events("reached")[0]
    assert math.hypot(run.poses[k].x - 4.0, run.poses[k].y) <= PARAMS.reach_m
    assert run.cmds[-1].done


def test_subgoal_outside_the_grid_is_kept() -> None:
    robot = XR4000_ROBOT
    grid = empty_grid()
    far = Subgoal(30.0, 0.0, 0.0)
    f = PathFollower([far], PARAMS, robot, inflate_m=robot.inner_radius_m)
    cmd = f.step(Pose2D(0.0, 0.0, 0.0), grid)
    assert cmd.event == "" and cmd.subgoal_xy == (30.0, 0.0)
    assert math.hypot(*cmd.target_xy) == pytest.approx(PARAMS.lookahead_m, abs=0.02)


@ROBOTS
def test_push_off_the_trajectory_replans(robot: RobotConfig) -> None:
    subgoals = [Subgoal(5.0, 0.0, 0.0, "stop")]
    f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
    push_tick = 40
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot, push=(push_tick, 0.0, 0.8))
    assert run.events("replanned") == [push_tick]
    cmd, pose = run.cmds[push_tick], run.poses[push_tick]
    assert np.allclose(cmd.trajectory_xy[0], (pose.x, pose.y))  # the new trajectory starts at the robot
    assert run.cmds[-1].done
    end = run.poses[-1]
    assert math.hypot(end.x - 5.0, end.y) <= PARAMS.reach_m


def test_deterministic() -> None:
    robot = WHEELCHAIR_ROBOT
    subgoals = [Subgoal(2.0, 1.0, 0.5), Subgoal(0.0, 2.0, 0.0, "reverse"), Subgoal(1.0, 3.0, 0.0, "stop")]
    runs = [drive(PathFollower(subgoals, PARAMS, robot, inflate_m=0.35), Pose2D(0.0, 0.0, 0.0), empty_grid(),
                  robot) for _ in range(2)]
    a, b = ([(c.v_mps, c.w_radps, c.event, c.subgoal_index) for c in r.cmds] for r in runs)
    assert a == b and runs[0].cmds[-1].done


def test_no_subgoals_is_done() -> None:
    f = PathFollower([], PARAMS, XR4000_ROBOT, inflate_m=0.3)
    cmd = f.step(Pose2D(0.0, 0.0, 0.0), empty_grid())
    assert cmd.done and cmd.v_mps == 0.0 and cmd.w_radps == 0.0 and cmd.subgoal_index == 0


def test_new_trajectory_starts_with_the_curvature_of_the_motion() -> None:
    robot = XR4000_ROBOT
    f = PathFollower([Subgoal(4.0, 1.0, 0.0)], PARAMS, robot, inflate_m=0.3)
    cmd = f.step(Pose2D(0.0, 0.0, 0.0), empty_grid(), v_mps=0.4, w_radps=0.2)
    assert f.trajectory is not None and f.trajectory.kappa[0] == pytest.approx(0.5)
    # target: lookahead_m along the trajectory from the robot
    traj = cmd.trajectory_xy
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(traj, axis=0).T))])
    k = int(np.argmin(np.hypot(traj[:, 0] - cmd.target_xy[0], traj[:, 1] - cmd.target_xy[1])))
    assert arc[k] == pytest.approx(PARAMS.lookahead_m, abs=PARAMS.sample_m)
    # the follower's command continues that turn rather than jerking the other way
    assert cmd.w_radps > 0.0


def test_windowed_obstacle_test_agrees_with_the_full_cspace() -> None:
    rng = np.random.default_rng(5)
    robot = Pose2D(0.0, 0.0, 0.0)
    for _ in range(20):
        grid = empty_grid()
        cells = grid.world_to_cell(rng.uniform(-4.0, 4.0, size=(60, 2)))
        grid.cells[cells[:, 0], cells[:, 1]] = OCCUPIED
        inflate = float(rng.uniform(0.2, 0.5))
        free = free_cspace(grid.cells, cell_m=0.05, inflate_m=inflate)
        start = grid.robot_cell(robot)
        if not free[start]:  # the wave starts where NF1's escape would take the robot
            start = nearest_true(free, start, Nf1Params().escape_m / 0.05)
        if start is None:
            continue
        reach = np.isfinite(nf1_wavefront(free, start)) & free
        for xy in rng.uniform(-4.0, 4.0, size=(25, 2)):
            r, c = grid.world_to_cell(xy)[0]
            got = replacement_point((float(xy[0]), float(xy[1])), robot, grid, inflate_m=inflate,
                                    unknown_is_free=True, search_m=3.0)
            if free[r, c]:
                assert got is None
            else:  # blocked: replaced whenever a reachable free cell lies within the search radius
                assert (got is not None) == (nearest_true(reach, (int(r), int(c)), 60.0) is not None)
                if got is not None:
                    rr, cc = grid.world_to_cell(np.array(got))[0]
                    assert reach[rr, cc]


@pytest.mark.parametrize("seed", range(4))
def test_random_routes_are_executed(seed: int) -> None:
    """Random routes of four subgoals of random kinds and headings, 3 m apart on average: every one is
    executed (reached or, for a passed forward/reverse one, skipped), each reach meets its conditions."""
    rng = np.random.default_rng(100 + seed)
    robot = (WHEELCHAIR_ROBOT, XR4000_ROBOT)[seed % 2]
    xy = np.cumsum(rng.uniform(-3.0, 3.0, size=(4, 2)), axis=0)
    kinds = rng.choice(["forward", "forward", "stop", "reverse"], size=4)
    subgoals = [Subgoal(float(x), float(y), float(rng.uniform(-math.pi, math.pi)), cast(SubgoalKind, str(k)))
                for (x, y), k in zip(xy, kinds, strict=True)]
    run = drive(PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m), Pose2D(0.0, 0.0, 0.0),
                empty_grid(), robot, t_max_s=200.0)
    assert run.cmds[-1].done
    assert len(run.events("replanned")) <= 3
    for k in run.events("reached"):
        goal, pose = subgoals[run.cmds[k].subgoal_index - 1], run.poses[k]
        assert math.hypot(pose.x - goal.x, pose.y - goal.y) <= PARAMS.reach_m
        assert heading_error(pose, goal) <= PARAMS.heading_tol_rad
        assert goal.kind != "stop" or abs(run.v[k]) <= PARAMS.stop_v_mps
    for k in run.events("skipped"):
        assert subgoals[run.cmds[k].subgoal_index - 1].kind != "stop"


@pytest.mark.parametrize("wall_y", [None, 0.6, 0.45, 0.3])
def test_blocked_subgoal_replaced_when_the_robot_cell_is_not_free(wall_y: float | None) -> None:
    """Beside a wall the robot cell is often not free in the C-space of a large robot: the wave then starts
    from the cell NF1's escape would run to, and the blocked subgoal is still replaced by a reachable
    free point."""
    robot = WHEELCHAIR_ROBOT
    inflate = robot.inner_radius_m + 0.05
    grid = empty_grid()
    grid.cells[:] = FREE
    _block(grid, 3.0, 3.4, -0.2, 0.2)  # on the subgoal (3.2, 0)
    if wall_y is not None:
        _block(grid, -2.0, 2.0, wall_y, wall_y + 0.1)
    free = free_cspace(grid.cells, cell_m=0.05, inflate_m=inflate)
    start = grid.robot_cell(Pose2D(0.0, 0.0, 0.0))
    if wall_y is not None and wall_y < inflate:
        assert not free[start]  # the case under test
    got = replacement_point((3.2, 0.0), Pose2D(0.0, 0.0, 0.0), grid, inflate_m=inflate, unknown_is_free=True,
                            search_m=3.0)
    assert got is not None
    rc = tuple(int(v) for v in grid.world_to_cell(np.array(got))[0])
    entry = start if free[start] else nearest_true(free, start, Nf1Params().escape_m / 0.05)
    assert entry is not None
    assert free[rc] and np.isfinite(nf1_wavefront(free, entry)[rc])
    assert math.hypot(got[0] - 3.2, got[1]) < 0.2 + inflate + 0.1  # next to the obstacle


def test_robot_enclosed_beyond_the_escape_length_keeps_the_subgoal() -> None:
    grid = empty_grid()
    grid.cells[:] = FREE
    _block(grid, 3.0, 3.4, -0.2, 0.2)
    _block(grid, -0.1, 0.1, -0.1, 0.1)  # an obstacle on the robot: no free cell within the escape length
    got = replacement_point((3.2, 0.0), Pose2D(0.0, 0.0, 0.0), grid, inflate_m=0.6, unknown_is_free=True,
                            search_m=3.0, escape_m=0.3)
    assert got is None


@ROBOTS
def test_displaced_while_turning_in_place_replans(robot: RobotConfig) -> None:
    """Turning in place towards a subgoal, the robot is moved (a push, local navigation): the turn's
    heading was computed at the old pose, so the follower replans rather than finishing that turn."""
    f = PathFollower([Subgoal(0.0, 1.0, math.pi / 2, "stop")], PARAMS, robot, inflate_m=0.4)
    grid = empty_grid()
    cmd = f.step(Pose2D(0.0, 0.0, 0.0), grid)
    assert cmd.mode == "turn" and cmd.w_radps > 0.0  # the subgoal is to the left
    for dx, dy in ((0.0, 3.0), (PARAMS.deviation_m + 0.05, 0.0)):
        moved = Pose2D(dx, dy, 0.0)
        cmd = f.step(moved, grid)
        assert cmd.event == "replanned"
        assert f.trajectory is not None and np.allclose(f.trajectory.xy[0], (dx, dy))
    assert cmd.w_radps > 0.0 and cmd.mode == "turn"  # still to the left of (0.45, 0)
    moved = Pose2D(0.0, 3.0, 0.0)
    cmd = f.step(moved, grid)
    assert cmd.event == "replanned" and cmd.w_radps < 0.0  # now to the right: the turn reverses
    # a displacement within the tolerance keeps the turn
    cmd = f.step(Pose2D(0.0, 3.0 + 0.5 * PARAMS.deviation_m, -0.1), grid)
    assert cmd.event == "" and cmd.mode == "turn"


@pytest.mark.parametrize("distance_m", [20.0, 5_000.0, 50_000.0])
def test_far_subgoal_is_planned_within_the_horizon(distance_m: float) -> None:
    """The cost of a tick does not grow with the distance to the subgoal: the trajectory ends within the
    planning horizon, on the straight line to the subgoal, heading along it."""
    params = FollowParams(horizon_m=4.0)
    robot = XR4000_ROBOT
    f = PathFollower([Subgoal(distance_m, distance_m, 0.0)], params, robot, inflate_m=0.3)
    cmd = f.step(Pose2D(0.0, 0.0, 0.0), empty_grid())
    traj = f.trajectory
    assert traj is not None and traj.partial
    longest = 2.5 * params.horizon_m + math.pi / params.kappa_max  # the solver's acceptance bound
    assert traj.xy.shape[0] <= (longest + params.extend_m) / params.sample_m + 3
    end = cmd.trajectory_xy[-1]
    assert math.hypot(*end) == pytest.approx(params.horizon_m, abs=1e-3)
    assert math.atan2(end[1], end[0]) == pytest.approx(math.pi / 4, abs=1e-6)
    assert traj.heading[traj.goal_end() - 1] == pytest.approx(math.pi / 4, abs=1e-3)


@ROBOTS
def test_subgoal_beyond_the_horizon_is_reached_with_the_heading_asked(robot: RobotConfig) -> None:
    params = FollowParams(horizon_m=2.0)
    goal = Subgoal(6.0, 2.0, -math.pi / 2, "stop")
    f = PathFollower([goal], params, robot, inflate_m=0.3)
    run = drive(f, Pose2D(0.0, 0.0, 0.0), empty_grid(), robot)
    assert run.cmds[-1].done
    assert len(run.events("replanned")) >= 2  # the horizon moved on with the robot
    k = len(run.cmds) - 1
    end = run.poses[k]
    assert math.hypot(end.x - goal.x, end.y - goal.y) <= params.reach_m
    assert heading_error(end, goal) <= params.heading_tol_rad and abs(run.v[k]) <= params.stop_v_mps


def test_local_target_is_the_first_free_point_past_the_obstacle() -> None:
    """Local navigation, taking over from the follower, aims past the obstacle on the trajectory (the
    follower's look-ahead point lies on it, where the footprint cannot go); nothing free: the subgoal."""
    robot = WHEELCHAIR_ROBOT
    inflate = robot.inner_radius_m + 0.05
    grid = empty_grid()
    grid.cells[:] = FREE
    _block(grid, 1.6, 2.0, -0.2, 0.2)  # a box on the straight path to (5, 0)
    f = PathFollower([Subgoal(5.0, 0.0, 0.0, "stop")], PARAMS, robot, inflate_m=inflate)
    cmd = f.step(Pose2D(0.5, 0.0, 0.0), grid)
    tx, ty = f.local_target(grid)
    free = free_cspace(grid.cells, cell_m=0.05, inflate_m=inflate)
    rc = tuple(int(v) for v in grid.world_to_cell(np.array([tx, ty]))[0])
    assert free[rc]
    assert tx > 2.0 + inflate - 0.1 and abs(ty) < 0.05  # beyond the box, on the path
    look = tuple(int(v) for v in grid.world_to_cell(np.array(cmd.target_xy))[0])
    assert not free[look]  # the look-ahead point itself is blocked
    # every trajectory point between the look-ahead point and the target is blocked
    traj = f.trajectory
    assert traj is not None
    s_t = traj.s[int(np.argmin(np.hypot(traj.xy[:, 0] - tx, traj.xy[:, 1] - ty)))]
    between = traj.xy[(traj.s > f._s + PARAMS.lookahead_m) & (traj.s < s_t)]
    cells = grid.world_to_cell(between)
    assert not free[cells[:, 0], cells[:, 1]].any()
    # a wall across the whole path: nothing free ahead, the subgoal is the target
    _block(grid, 1.6, 6.5, -0.2, 0.2)
    assert free_point_ahead(traj, f._s + PARAMS.lookahead_m, grid, inflate_m=inflate,
                            unknown_is_free=True) is None
    assert f.local_target(grid) == (5.0, 0.0)


@ROBOTS
@pytest.mark.parametrize("heading", [1.2, 1.75, 2.5, math.pi, -1.75])
def test_tracking_never_drives_a_forward_subgoal_backwards(robot: RobotConfig, heading: float) -> None:
    """Turned away from its trajectory (by 69 deg to 180 deg) within the deviation tolerance, the robot
    does not back towards the reference (the Kanayama law's speed is negative there): it turns in place
    to the trajectory's heading (at once the shorter way, and at all when facing exactly backwards)."""
    f = PathFollower([Subgoal(6.0, 0.0, 0.0)], PARAMS, robot, inflate_m=robot.inner_radius_m)
    grid = empty_grid()
    f.step(Pose2D(0.0, 0.0, 0.0), grid)
    side = math.copysign(0.3, heading)
    cmd = f.step(Pose2D(1.0, side, heading), grid)
    assert cmd.event == "" and cmd.v_mps == 0.0 and cmd.mode == "turn"
    assert cmd.w_radps != 0.0
    if abs(heading) < math.pi:  # facing exactly backwards, either way round is as short
        assert math.copysign(1.0, cmd.w_radps) == -math.copysign(1.0, heading)


@ROBOTS
def test_taken_over_the_follower_plans_anew_from_where_it_was_left(robot: RobotConfig) -> None:
    """Path following along a straight route; local navigation (simulated: ``overridden``) turns the
    robot 50 deg left and 0.25 m aside, within the deviation tolerance. Told so, the follower plans a new
    trajectory from that pose (it starts at the robot, along its heading) and its command carries on along
    the new heading instead of turning hard back to the old line; not told, it keeps the old trajectory and
    turns back. Either way the route ends at the final subgoal."""
    subgoals = [Subgoal(8.0, 0.0, 0.0, "stop")]
    grid = empty_grid()
    results = {}
    for told in (True, False):
        f = PathFollower(subgoals, PARAMS, robot, inflate_m=robot.inner_radius_m)
        for k in range(10):  # tracking along x at speed
            f.step(Pose2D(0.03 * k, 0.0, 0.0), grid, v_mps=robot.vmax_mps, w_radps=0.0)
        pose = Pose2D(0.5, 0.25, math.radians(50.0))
        cmd = f.step(pose, grid, v_mps=0.1, w_radps=0.3, overridden=told)
        results[told] = cmd
        if told:
            assert cmd.event == "replanned"
            assert np.allclose(cmd.trajectory_xy[0], (pose.x, pose.y))
            first = cmd.trajectory_xy[1] - cmd.trajectory_xy[0]
            assert abs(math.atan2(first[1], first[0]) - pose.theta) < 0.05
        else:
            assert cmd.event == ""
        run = drive(f, pose, grid, robot)
        assert run.cmds[-1].done
        end = run.poses[-1]
        assert math.hypot(end.x - 8.0, end.y) <= PARAMS.reach_m
    assert results[True].w_radps > results[False].w_radps  # the old line lies to the right
    assert results[True].v_mps > 0.0
