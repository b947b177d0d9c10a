"""The trap escape's manoeuvre (issue 10): the 1.2 x 0.7 m chair at a T-junction of two 1.4 m passages,
facing down the side passage and wanted along the main one, cannot turn where it stands; the search finds
a sequence of arcs and turns whose every swept pose stays clear of the walls and ends heading the wanted
way with room to drive on. In closed loop, the chair that has driven into a dead-end side passage gets
out and reaches its goal, which it does not without the manoeuvre."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gndreplay.config import apply_overrides, preset
from gndreplay.geometry import compose, inverse, relative, transform_points
from gndreplay.pipeline.manoeuvre import ManoeuvreParams, Primitive, Speeds, end_poses, plan_manoeuvre
from gndreplay.pipeline.model import FREE, OCCUPIED, GridParams, RobotCentredGrid
from gndreplay.pipeline.supervisor import arc_touches, footprint_signed_distance, safe_command
from gndreplay.robot import WHEELCHAIR_ROBOT
from gndreplay.sim import simulate_scenario
from gndreplay.sim.runner import SimOutcome
from gndreplay.sim.scenario_file import parse_scenario
from gndreplay.types import Mode, Pose2D

CHAIR = WHEELCHAIR_ROBOT
MARGIN = 0.045  # the reflexive loop's for a grid cell: emergency margin + half a 5 cm cell
SPEEDS = Speeds(forward_mps=0.15, reverse_mps=0.09, turn_radps=0.25)  # the stack's for the chair

# main passage y in [-0.7, 0.7] closed at x = 8; side passage x in [3.5, 4.9] going south to a dead end
T_WALLS = {
    "passage_n": [0.0, 0.7, 8.0, 0.7],
    "passage_s1": [0.0, -0.7, 3.5, -0.7],
    "passage_s2": [4.9, -0.7, 8.0, -0.7],
    "passage_e": [8.0, -0.7, 8.0, 0.7],
    "side_w": [3.5, -0.7, 3.5, -4.5],
    "side_e": [4.9, -0.7, 4.9, -4.5],
    "side_end": [3.5, -4.5, 4.9, -4.5],
}


def wall_points(walls: dict[str, list[float]], step: float = 0.02) -> np.ndarray:
    out = []
    for x0, y0, x1, y1 in walls.values():
        n = int(math.hypot(x1 - x0, y1 - y0) / step) + 1
        t = np.linspace(0.0, 1.0, n)
        out.append(np.column_stack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)]))
    return np.vstack(out)


def in_robot_frame(points: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = points - np.array(pose[:2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def swept_clearance(points: np.ndarray, sequence: tuple[Primitive, ...], step: float = 0.005) -> float:
    """Smallest footprint-to-point distance over the manoeuvre, poses every 5 mm / 0.3 deg (independent
    of the search's own sampling: the exact arc by composition of small steps)."""
    worst = math.inf
    pose = np.zeros(3)
    for q in sequence:
        n = max(1, math.ceil(max(abs(q.ds_m) / step, abs(q.dth_rad) / 0.005)))
        for _ in range(n):
            pose = compose(pose, end_poses((Primitive(q.ds_m / n, q.dth_rad / n),))[0])
            local = transform_points(inverse(pose), points)
            worst = min(worst, float(np.min(footprint_signed_distance(local, CHAIR))))
    return worst


@pytest.mark.parametrize("y", [-0.3, -0.2, 0.0])
def test_the_chair_at_a_t_junction_turns_by_a_manoeuvre_that_clears_every_wall(y: float) -> None:
    start = (4.2, y, -math.radians(83.0))  # front in the side passage's mouth, backing out of it
    pts = in_robot_frame(wall_points(T_WALLS), start)
    want = math.remainder(math.pi - start[2], math.tau)  # west, along the main passage
    params = ManoeuvreParams()
    sequence = plan_manoeuvre(pts, np.full(len(pts), MARGIN), CHAIR, want, params, SPEEDS)
    assert sequence is not None and len(sequence) >= 2
    assert swept_clearance(pts, sequence) > MARGIN - 0.005  # the search samples every 2 cm of travel
    end = end_poses(sequence)[-1]
    assert abs(math.remainder(end[2] - want, math.tau)) <= params.heading_tol_rad + 1e-9
    # room to drive on, the way it now heads
    room = transform_points(inverse(end), pts)
    assert not arc_touches(room, 1.0, 0.0, 0.0, params.room_m, CHAIR, MARGIN)
    if y < -0.1:  # the cause: deeper in the mouth, turning where it stands would hit the passage's corner
        assert arc_touches(pts, 0.0, 0.0, -1.0, math.pi / 2, CHAIR, MARGIN)
        assert any(q.ds_m < 0.0 for q in sequence)  # it backs out first


def test_no_manoeuvre_in_a_box_barely_larger_than_the_chair() -> None:
    box = {"n": [-0.5, 0.42, 0.9, 0.42], "s": [-0.5, -0.42, 0.9, -0.42],
           "w": [-0.5, -0.42, -0.5, 0.42], "e": [0.9, -0.42, 0.9, 0.42]}
    pts = wall_points(box)
    margins = np.full(len(pts), MARGIN)
    assert plan_manoeuvre(pts, margins, CHAIR, math.pi / 2, ManoeuvreParams(), SPEEDS) is None


def test_nothing_to_manoeuvre_when_the_chair_already_heads_the_wanted_way_with_room() -> None:
    pts = wall_points({"n": [-2.0, 0.7, 3.0, 0.7], "s": [-2.0, -0.7, 3.0, -0.7]})
    assert plan_manoeuvre(pts, np.full(len(pts), MARGIN), CHAIR, 0.1, ManoeuvreParams(), SPEEDS) is None
    # ... but turned round in the same corridor it has none either: 1.4 m is too narrow for a U-turn
    assert plan_manoeuvre(pts, np.full(len(pts), MARGIN), CHAIR, math.pi, ManoeuvreParams(), SPEEDS) is None


def _dead_end_run(tmp_path: Path, nodes: int, time_limit_s: float) -> SimOutcome:
    """The chair drives into the side passage (the way to its goal, as far as it can see), finds it a
    dead end, and must come out and go round. Localisation by perfect odometry and the exact motion model
    (no drive lag, no slip): the manoeuvre alone."""
    doc = {"name": "t_junction_dead_end", "preset": "wheelchair", "start": [1.0, 0.0, 0.0],
           "goal": [4.2, -6.5], "time_limit": time_limit_s,
           "world": {"walls": {"room_n": [-3.0, 3.0, 10.0, 3.0], "room_s": [-3.0, -8.0, 10.0, -8.0],
                               "room_w": [-3.0, -8.0, -3.0, 3.0], "room_e": [10.0, -8.0, 10.0, 3.0],
                               **T_WALLS}}}
    cfg = apply_overrides(preset("wheelchair"), {"scanmatch": {"method": "odom"},
                                                  "supervisor": {"manoeuvre_nodes": nodes}})
    return simulate_scenario(parse_scenario(doc, "test.yaml"), out_dir=tmp_path / f"run{nodes}", cfg=cfg,
                             seed=0, perfect_odometry=True, figures=False, ideal_dynamics=True)


def test_closed_loop_the_chair_comes_out_of_a_dead_end_side_passage_only_with_the_manoeuvre(
        tmp_path: Path) -> None:
    with_it = _dead_end_run(tmp_path, ManoeuvreParams().max_nodes, 200.0)
    assert with_it.outcome == "success", with_it.outcome
    assert with_it.collision is None
    assert with_it.longest_stall_s <= 10.0
    assert with_it.modes.get("ESCAPE", 0) > 0
    without = _dead_end_run(tmp_path, 0, 90.0)  # the cause: the reactor and the straight escape alone
    assert without.outcome == "timeout"
    assert without.longest_stall_s > 30.0


def test_the_edge_of_known_free_space_is_every_cell_not_free_beside_a_free_one() -> None:
    grid = RobotCentredGrid(GridParams(size_cells=40, cell_m=0.1))
    n0 = 20  # the robot's cell (row and column) at the world origin
    grid.cells[n0 - 1:n0 + 2, n0 - 5:n0 + 6] = FREE  # a 3 x 11 free strip along x, the robot in its middle
    grid.cells[n0 + 2, n0 - 5:n0 + 6] = OCCUPIED  # a wall along its north side; the rest is never seen
    grid.cells[n0 + 3, n0 - 5:n0 + 6] = OCCUPIED  # ... two cells thick: its outer row is not the edge
    pts = grid.free_border_points(Pose2D(0.0, 0.0, math.pi / 2), 2.0)  # robot frame: x is world y
    world = np.column_stack([-pts[:, 1], pts[:, 0]])  # back to the world frame (theta = 90 deg)
    cells = {(round(y / 0.1 - 0.5), round(x / 0.1 - 0.5)) for x, y in world}
    expected = ({(1 + 1, c) for c in range(-5, 6)} | {(-1 - 1, c) for c in range(-5, 6)}
                | {(r, -6) for r in (-1, 0, 1)} | {(r, 6) for r in (-1, 0, 1)})
    assert cells == expected


@pytest.mark.parametrize("start, want_world", [((4.0, -0.2, 0.0), math.pi), ((4.4, 0.2, 0.0), math.pi),
                                               ((4.2, 0.0, math.pi), -math.pi / 2),
                                               ((4.2, -0.3, -math.radians(83.0)), math.pi)])
def test_a_planned_manoeuvre_driven_tick_by_tick_passes_the_reflexive_check(
        start: tuple[float, float, float], want_world: float) -> None:
    """The stack drives the plan at 5 Hz through ``safe_command`` (scan points, the chair's margins),
    accepting only its SAFE_SLOW (the same arc): every tick passes and the chair ends heading the wanted
    way. The check looks a braking horizon ahead, past a primitive's end; a search that cleared each
    primitive only to its end had manoeuvres refused near the end of an arc."""
    cfg = preset("wheelchair")
    robot, sup = cfg.robot, cfg.supervisor
    pts = in_robot_frame(wall_points(T_WALLS), start)
    want = math.remainder(want_world - start[2], math.tau)
    params = ManoeuvreParams()
    sequence = plan_manoeuvre(pts, np.full(len(pts), sup.emergency_margin_m), robot, want, params, SPEEDS)
    assert sequence is not None
    ends, todo = list(end_poses(sequence)), list(sequence)
    pose, dt = np.zeros(3), 0.2
    for _ in range(600):
        while todo:  # the stack's completion rule (Supervisor._manoeuvre_step)
            rest = relative(pose, ends[0])
            left = math.copysign(1.0, todo[0].dth_rad) * rest[2] if todo[0].ds_m == 0.0 else (
                math.copysign(1.0, todo[0].ds_m) * rest[0])
            if left > (math.radians(1.0) if todo[0].ds_m == 0.0 else 0.01):
                break
            todo.pop(0)
            ends.pop(0)
        if not todo:
            break
        v, w = SPEEDS.twist(todo[0])
        safe = safe_command(v, 0.0, w, transform_points(inverse(pose), pts), np.zeros((0, 2)), robot, sup,
                            cell_m=cfg.grid.cell_m)
        assert safe.rule in (None, Mode.SAFE_SLOW), (len(sequence) - len(todo), safe.rule)
        pose = compose(pose, end_poses((Primitive(safe.v_mps * dt, safe.w_radps * dt),))[0])
    assert not todo
    assert abs(math.remainder(pose[2] - want, math.tau)) <= params.heading_tol_rad + math.radians(2.0)


@pytest.mark.parametrize("door_y", [0.15, 0.3, 0.4, -0.4])
@pytest.mark.parametrize("wall_x", [1.0, 1.1])
def test_a_door_off_the_chairs_line_is_lined_up_with_not_only_backed_away_from(door_y: float,
                                                                                wall_x: float) -> None:
    """The chair heads within the tolerance of where it wants to go, through a 0.85 m door in a wall
    0.2-0.3 m ahead of its front, but the door is off its line: driving straight on, a side meets a jamb.
    Backing straight away gives it room_m straight on, yet driving that room brings it back where it
    started (wheelchair_office_exit: two such reverses, the chair stalled 12 s before the cabinet's
    corner beside the door). The manoeuvre must end where the straight way on leads through the door."""
    lo, hi = door_y - 0.425, door_y + 0.425
    pts = wall_points({"below": [wall_x, -3.0, wall_x, lo], "above": [wall_x, hi, wall_x, 3.0]})
    want = math.atan2(door_y, 3.0)  # a point 3 m ahead beyond the door
    params = ManoeuvreParams()
    assert abs(want) <= params.heading_tol_rad  # the heading is not what is wrong
    assert arc_touches(pts, 1.0, 0.0, 0.0, params.room_m, CHAIR, MARGIN)  # the straight way on is blocked
    sequence = plan_manoeuvre(pts, np.full(len(pts), MARGIN), CHAIR, want, params, SPEEDS)
    assert sequence is not None
    assert not all(q.ds_m < 0.0 and q.dth_rad == 0.0 for q in sequence)  # not only a straight reverse
    assert swept_clearance(pts, sequence) > MARGIN - 0.005
    end = end_poses(sequence)[-1]
    assert abs(math.remainder(end[2] - want, math.tau)) <= params.heading_tol_rad + 1e-9
    # straight on from its end, the whole chair passes the door (its rear 0.1 m beyond the wall)
    through = (wall_x + CHAIR.rear_m + 0.1 - end[0]) / math.cos(end[2])
    assert not arc_touches(transform_points(inverse(end), pts), 1.0, 0.0, 0.0, through, CHAIR, MARGIN - 0.01)
