"""The reflexive loop's blind side rule: space a front laser saw free some time ago, and no longer sees, is
not free for translation towards it (a mover may have walked in since)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gndreplay.config import PRESETS
from gndreplay.pipeline.model import FREE, NEVER_SEEN, UNKNOWN, GridParams, RobotCentredGrid
from gndreplay.pipeline.stack import NavigationStack
from gndreplay.pipeline.supervisor import (
    Mode,
    SupervisorParams,
    arc_touches,
    blind_points,
    braking_time_s,
    safe_command,
    safety_reach_m,
)
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig
from gndreplay.types import Command, Pose2D, Scan

P = SupervisorParams()
CELL = 0.05
ANGLES = np.linspace(-math.pi / 2, math.pi / 2, 361)  # the presets' 180 deg front laser
FOV = (float(ANGLES[0]), float(ANGLES[-1]))
S = 1_000_000_000  # ns per s
MOVER = (-0.33, -0.60)  # world: a person of radius 0.25 m behind right, 0.13 m from the robot's edge


def _scan(t_s: float) -> Scan:
    """An open room: every beam returns from 4 m (nothing near the robot); laser at the rotation centre."""
    return Scan(t_ns=round(t_s * S), ranges_m=np.full(ANGLES.size, 4.0), angles_rad=ANGLES, max_range_m=8.0)


def _mover_points() -> np.ndarray:
    """The mover's outline (world = robot frame here: the robot stands at the origin facing +x)."""
    a = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
    return np.column_stack([MOVER[0] + 0.25 * np.cos(a), MOVER[1] + 0.25 * np.sin(a)])


def _grid_looked_back(age_s: float) -> tuple[RobotCentredGrid, Scan]:
    """The robot at the origin looked backwards (facing -x) ``age_s`` before now, then turned to face +x:
    the half behind it is FREE in the grid, last seen ``age_s`` ago; now's scan covers the half ahead. The
    mover stepped in behind after the look: neither the grid nor the scan holds it."""
    grid = RobotCentredGrid(GridParams(120, CELL))
    grid.integrate(_scan(10.0 - age_s), Pose2D(0.0, 0.0, math.pi))
    now = _scan(10.0)
    grid.integrate(now, Pose2D(0.0, 0.0, 0.0))
    return grid, now


def _check(grid: RobotCentredGrid, scan: Scan, v: float, vy: float, w: float, *, blind: bool = True,
           robot: RobotConfig = XR4000_ROBOT):
    """``safe_command`` as the stack's reflexive loop calls it (scan hits and occupied cells: none near;
    the laser at ``robot``'s mounting, facing ahead)."""
    pose = Pose2D(0.0, 0.0, 0.0)
    reach = safety_reach_m(robot, P, CELL)
    since = scan.t_ns - round(P.blind_memory_s * S)

    def blind_xy() -> np.ndarray:
        return blind_points(grid.unseen_points(pose, reach, since), robot, (robot.laser_x_m, 0.0, 0.0), FOV)

    def unknown_xy() -> np.ndarray:
        return grid.cell_points(pose, reach, UNKNOWN)

    return safe_command(v, vy, w, np.zeros((0, 2)), grid.occupied_points(pose, reach), robot, P, cell_m=CELL,
                        unknown_xy=unknown_xy, blind_xy=blind_xy if blind else None, view_rad=FOV)


def _hits_mover(v: float, vy: float, w: float) -> bool:
    """The command, held then braked as the safety check assumes, would bring the robot into the mover."""
    t = braking_time_s(v, vy, w, XR4000_ROBOT, P)
    return arc_touches(_mover_points(), v, vy, w, t, XR4000_ROBOT, 0.0)


def test_stale_blind_space_is_not_free_for_backing_into_it() -> None:
    """The exp2 collision class: a holonomic base backing and side-stepping into space it saw free 3 s
    ago, where a mover now stands. Without the rule the command goes out and reaches the mover; with it
    the base turns in place towards where it was going (turn first) and touches nothing."""
    grid, scan = _grid_looked_back(3.0)
    cell = grid.world_to_cell(np.array([MOVER]))[0]
    assert grid.cells[cell[0], cell[1]] == FREE  # the grid says free where the mover stands
    v, vy, w = -0.22, -0.40, -1.57  # issue 10's command at 57.8 s
    assert _hits_mover(v, vy, w)
    assert _check(grid, scan, v, vy, w, blind=False).rule is None  # the old check had nothing to stop for
    out = _check(grid, scan, v, vy, w)
    assert out.rule is Mode.SAFE_TURN and out.v_mps == 0.0 and out.vy_mps == 0.0 and out.looking
    assert out.w_radps < 0.0  # towards the travel direction (back right), the reactor's own turn direction
    assert not _hits_mover(out.v_mps, out.vy_mps, out.w_radps)
    back = _check(grid, scan, -0.4, 0.0, 0.0)  # straight back, pointing exactly away: either way round
    assert back.rule is Mode.SAFE_TURN and back.v_mps == 0.0 and back.w_radps != 0.0


@pytest.mark.parametrize(("v", "vy", "w"), [(0.4, 0.0, 0.0), (0.3, 0.2, 0.5), (0.0, 0.0, 1.5)])
def test_motion_within_the_field_of_view_or_turning_is_unchanged(v: float, vy: float, w: float) -> None:
    """Ahead the scan refreshes the grid every tick; a turn in place of a circular base sweeps nothing."""
    grid, scan = _grid_looked_back(3.0)
    assert _check(grid, scan, v, vy, w).rule is None


def test_space_seen_recently_stays_free() -> None:
    """Not a ban on backing up: blind space the laser saw within blind_memory_s is trusted."""
    grid, scan = _grid_looked_back(0.5 * P.blind_memory_s)
    assert _check(grid, scan, -0.22, -0.40, -1.57).rule is None


@pytest.mark.parametrize(("age_s", "v", "w", "out"), [
    (3.0, -0.3, 0.2, (-0.09, 0.06, Mode.SAFE_SLOW)),  # stale: slowed to a creep, the same arc
    (3.0, -0.09, 0.0, (-0.09, 0.0, None)),  # already creeping
    (0.5, -0.3, 0.2, (-0.3, 0.2, None)),  # seen within blind_memory_s
])
def test_differential_reverse_into_stale_space_creeps(age_s: float, v: float, w: float,
                                                       out: tuple[float, float, Mode | None]) -> None:
    """The chair cannot look behind it (turning in place keeps its rear out of a front laser's view, a
    dead end leaves no room to turn round): its reverse into space seen free long ago is slowed to
    escape_v_frac * vmax, not forbidden; into space seen lately it is unchanged."""
    grid, scan = _grid_looked_back(age_s)
    got = _check(grid, scan, v, 0.0, w, robot=WHEELCHAIR_ROBOT)
    assert (got.v_mps, got.w_radps, got.rule) == pytest.approx(out)
    assert _check(grid, scan, 0.3, 0.0, 0.2, robot=WHEELCHAIR_ROBOT).rule is None  # ahead: in view


def test_blind_points_are_out_of_view_and_outside_the_footprint() -> None:
    pts = np.array([[1.0, 0.0], [-1.0, 0.0], [-0.1, 0.0], [0.0, -0.8], [-0.5, 0.5]])
    out = blind_points(pts, XR4000_ROBOT, (0.0, 0.0, 0.0), FOV)
    assert out.tolist() == [[-1.0, 0.0], [-0.5, 0.5]]  # ahead / on the view's edge / under the robot: not
    # the chair's laser 0.72 m ahead of the axle: beside the chair is blind, ahead of the laser is not
    chair = blind_points(np.array([[0.0, 0.6], [1.0, 0.6]]), WHEELCHAIR_ROBOT, (0.72, 0.0, 0.0), FOV)
    assert chair.tolist() == [[0.0, 0.6]]
    assert blind_points(pts, XR4000_ROBOT, (0.0, 0.0, 0.0), (-math.pi, math.pi)).shape == (0, 2)


def test_grid_stamps_follow_the_scans_and_the_shift() -> None:
    """Every cell a ray crosses or ends in gets the scan's stamp; a re-centring shift moves the stamps with
    the cells and the new cells are NEVER_SEEN; ``unseen_points`` returns the old ones."""
    grid, _ = _grid_looked_back(3.0)
    behind = grid.world_to_cell(np.array([[-1.0, 0.0], [1.0, 0.0]]))
    assert grid.seen_ns[behind[0, 0], behind[0, 1]] == 7 * S
    assert grid.seen_ns[behind[1, 0], behind[1, 1]] == 10 * S
    old = grid.unseen_points(Pose2D(0.0, 0.0, 0.0), 1.0, 9 * S)
    assert old.shape[0] > 0 and np.all(old[:, 0] < 0.05)  # the half behind (and the centre column)
    grid.recentre(Pose2D(2.0, 0.0, 0.0))  # beyond the control zone: shift by 40 cells
    moved = grid.world_to_cell(np.array([[-1.0, 0.0]]))[0]
    assert grid.seen_ns[moved[0], moved[1]] == 7 * S
    assert grid.seen_ns[grid.params.size_cells // 2, -1] == NEVER_SEEN


def test_stack_replaces_a_teleop_reverse_into_stale_space() -> None:
    """End to end through the stack's reflexive loop, in teleoperation: the driver backs the XR4000 into
    space seen 3 s ago (replaced: turn first), then drives ahead (unchanged)."""
    cfg = PRESETS["xr4000"]
    params = dataclasses.replace(cfg.stack_params(), nav_mode="teleop")
    stack = NavigationStack(params)
    goal = (5.0, 0.0)

    def step(t: float, th: float, cmd: Command | None = None):
        pose = Pose2D(0.0, 0.0, th)
        return stack.step(_scan(t), pose, goal, cmd=cmd)

    for k, t in enumerate((7.0, 7.5, 8.0, 8.5, 9.0, 9.5)):  # looking back, then turning round (no command)
        step(t, math.pi * (1.0 - k / 5.0))
    back = step(10.0, 0.0, Command(10 * S, -0.4, 0.0))
    assert back.mode is Mode.SAFE_TURN and back.command.v_mps == 0.0 and back.command.vy_mps == 0.0
    assert back.command.w_radps != 0.0
    ahead = step(10.1, 0.0, Command(10 * S, 0.4, 0.0))
    assert ahead.mode is Mode.TELEOP and ahead.command.v_mps == 0.4
