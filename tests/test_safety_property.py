"""Safety property of the multi-loop stack (issue 14): for random scans, grids, teleoperation commands,
subgoals, desired modes (teleop, follow, local) and local strategies (nd, free-space, wall-left,
wall-right, contour), every command that leaves the stack (mode selector on) is either a stop or its
footprint, swept along the commanded arc over the braking horizon, touches no scan hit and no occupied
cell, with the supervisor's margins and its notion of touching (``supervisor.swept_collision``: within
emergency_margin_m and closer than now; an occupied cell that holds a hit of the current scan is that hit,
any other occupied cell is grown by half a cell, ``supervisor.unconfirmed_cells``).

Growing *every* occupied cell by half a cell does not hold: a cell that holds a hit is checked through the
hit by ``safe_command`` (a deliberate choice of the supervisor, for doors), so a command may pass within
half a cell of such a cell's centre while it stays clear of the hit itself."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gndreplay.config import PRESETS
from gndreplay.geometry import transform_points
from gndreplay.pipeline.model import FREE, OCCUPIED
from gndreplay.pipeline.stack import NavigationStack, TickResult
from gndreplay.pipeline.supervisor import swept_collision, unconfirmed_cells
from gndreplay.types import Command, Pose2D, Scan, Subgoal

BEAMS = 48  # all around: obstacles beside and behind the robot too (a 360 deg laser)
ANGLES = np.linspace(-math.pi, math.pi, BEAMS, endpoint=False)
PRESET_NAMES = sorted(PRESETS)
MODES = ("teleop", "follow", "local")
STRATEGIES = ("nd", "free-space", "wall-left", "wall-right", "contour")


def _touches(r: TickResult, stack: NavigationStack, scan: Scan, pose: Pose2D) -> str:
    """"" when the command is a stop or sweeps clear, else what it touches."""
    c = r.command
    if (c.v_mps, c.vy_mps, c.w_radps) == (0.0, 0.0, 0.0):
        return ""
    p = stack.params
    hits = transform_points(scan.sensor_pose.as_array(), scan.points())
    cells = stack.grid.occupied_points(pose, 50.0)  # every occupied cell of the grid the stack used
    cells = unconfirmed_cells(cells, hits, p.grid.cell_m)
    if swept_collision(hits, c.v_mps, c.w_radps, p.robot, p.supervisor, vy_mps=c.vy_mps):
        return "scan"
    if swept_collision(cells, c.v_mps, c.w_radps, p.robot, p.supervisor, vy_mps=c.vy_mps,
                       grow_m=0.5 * p.grid.cell_m):
        return "grid"
    # the literal reading for the cells: no overlap with an unconfirmed cell's whole square (its
    # circumscribed disc, no margin), which the check above implies while emergency_margin_m is at least
    # (sqrt(2) - 1) / 2 of a cell; asserted so that the two cannot drift apart
    bare = dataclasses.replace(p.supervisor, emergency_margin_m=0.0)
    if swept_collision(cells, c.v_mps, c.w_radps, p.robot, bare, vy_mps=c.vy_mps,
                       grow_m=0.5 * math.sqrt(2.0) * p.grid.cell_m):
        return "grid square"
    return ""


ranges_st = st.lists(st.one_of(st.just(math.inf), st.floats(0.05, 3.0)), min_size=BEAMS, max_size=BEAMS)
cells_st = st.lists(st.tuples(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5)), max_size=40)
unit_st = st.floats(-1.5, 1.5)  # command components as fractions of the limits (beyond them too)
subgoal_st = st.builds(Subgoal, st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-math.pi, math.pi),
                       st.sampled_from(("forward", "reverse", "stop")))


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(
    name=st.sampled_from(PRESET_NAMES),
    mode=st.sampled_from(MODES),
    strategy=st.sampled_from(STRATEGIES),
    subgoal=subgoal_st,
    ranges=ranges_st,
    cells=cells_st,
    known=st.booleans(),
    theta=st.floats(-math.pi, math.pi),
    v=unit_st,
    vy=unit_st,
    w=unit_st,
)
def test_no_command_leaving_the_stack_sweeps_into_an_obstacle(
    name: str, mode: str, strategy: str, subgoal: Subgoal, ranges: list[float],
    cells: list[tuple[float, float]], known: bool, theta: float, v: float, vy: float, w: float,
) -> None:
    cfg = PRESETS[name]
    robot = cfg.robot
    base = cfg.stack_params()
    local = dataclasses.replace(base.local, strategy=strategy)
    params = dataclasses.replace(base, nav_mode=mode, local=local)
    pose = Pose2D(0.3, -0.2, theta)
    # the follower's subgoal relative to the robot, so that it lies within the random obstacles
    subgoals = (Subgoal(pose.x + subgoal.x, pose.y + subgoal.y, subgoal.theta, subgoal.kind),)
    stack = NavigationStack(params, subgoals if mode == "follow" else ())
    # the grid before the scans: all FREE (the short reverse is possible) or UNKNOWN, plus random cells
    # occupied around the robot, the memory of obstacles out of the laser's view
    if known:
        stack.grid.cells[:] = FREE
    if cells:
        xy = np.array(cells) + np.array([pose.x, pose.y])
        rc = stack.grid.world_to_cell(xy)
        stack.grid.cells[rc[:, 0], rc[:, 1]] = OCCUPIED
    sensor = Pose2D(robot.laser_x_m, robot.laser_y_m, robot.laser_theta_rad)
    scan_ranges = np.array(ranges)
    for k in range(2):  # a second tick: the grid holds the first scan, the trap detector has a history
        t = 1_000_000_000 + k * 200_000_000
        cmd = Command(t, v * robot.vmax_mps, w * robot.wmax_radps, vy * robot.vmax_mps)
        scan = Scan(t_ns=t, ranges_m=scan_ranges, angles_rad=ANGLES, max_range_m=8.0, sensor_pose=sensor)
        r = stack.step(scan, pose, (5.0, 0.0), cmd=cmd)
        assert r.desired_mode == mode
        assert _touches(r, stack, scan, pose) == "", (r.mode, r.active_mode, r.command)
