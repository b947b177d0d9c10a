"""Route hysteresis of ``Nf1Planner`` (``RouteParams.route_keep_ratio`` / ``route_keep_m``): the route
returned last is kept while it is free and not clearly worse than this tick's NF1 route."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from gndreplay.pipeline.cspace import free_cspace
from gndreplay.pipeline.model import FREE, OCCUPIED, shift_cells
from gndreplay.pipeline.nf1 import Nf1Params, Nf1Planner, plan, route_cost, step_costs
from gndreplay.pipeline.planner import PlanResult, RouteParams
from gndreplay.types import Flag

CELL_M = 0.05
INFLATE_M = 0.15
HELD = RouteParams()
PURE = RouteParams(route_keep_ratio=0.0, route_keep_m=0.0)
GOAL = (60.5, 150.5)


def block_world() -> NDArray[np.uint8]:
    """A 120 x 200 grid with a block between robot (left) and goal (right): two routes of nearly equal
    length, over the top and under the bottom, the shorter one decided by the robot's row."""
    cells = np.full((120, 200), FREE, dtype=np.uint8)
    cells[40:81, 90:101] = OCCUPIED  # rows 40..80: its middle is row 60, the goal's row
    return cells


def side(res: PlanResult) -> str:
    """Which way round the block the route goes."""
    rows = res.path_cells[(res.path_cells[:, 1] >= 90) & (res.path_cells[:, 1] <= 100), 0]
    return "top" if rows.max() < 60 else "bottom"


def planner(route: RouteParams = HELD) -> Nf1Planner:
    return Nf1Planner(Nf1Params(), cell_m=CELL_M, inflate_m=INFLATE_M, unknown_is_free=True, route=route)


def pure_plan(cells: NDArray[np.uint8], start: tuple[int, int], goal: tuple[float, float]) -> PlanResult:
    free = free_cspace(cells, cell_m=CELL_M, inflate_m=INFLATE_M)
    return plan(free, start, goal, cell_m=CELL_M)


def test_a_slightly_better_route_does_not_replace_the_current_one() -> None:
    cells = block_world()
    held, pure = planner(), planner(PURE)
    first = held.plan(cells, (57, 20), GOAL)
    assert side(first) == "top" and side(pure.plan(cells, (57, 20), GOAL)) == "top"
    # two cells below the middle: the bottom is now a little shorter; pure NF1 switches, the held route stays
    below = pure_plan(cells, (62, 22), GOAL)
    assert side(below) == "bottom" and side(pure.plan(cells, (62, 22), GOAL)) == "bottom"
    kept = held.plan(cells, (62, 22), GOAL)
    assert side(kept) == "top" and kept.ok and kept.flag == Flag.NONE
    assert kept.goal_cell == (60, 150) and tuple(kept.path_cells[0]) == (62, 22)
    assert np.array_equal(kept.waypoints_cells[0], (62, 22)) and kept.n_escape == 0
    free = free_cspace(cells, cell_m=CELL_M, inflate_m=INFLATE_M)
    assert free[kept.path_cells[:, 0], kept.path_cells[:, 1]].all()
    assert kept.length_m > below.length_m  # it is the longer one, within the margin
    assert kept.length_m <= (1.1 * below.length_m + 0.3) + 1e-9
    assert abs(math.remainder(kept.direction_rad - first.direction_rad, math.tau)) < 0.3
    # far below: the bottom is clearly better, the route changes
    assert side(held.plan(cells, (100, 22), GOAL)) == "bottom"


def test_a_blocked_route_is_dropped_at_once() -> None:
    cells = block_world()
    held = planner()
    assert side(held.plan(cells, (57, 20), GOAL)) == "top"
    cells[:40, 95] = OCCUPIED  # a wall closes the way over the top
    res = held.plan(cells, (58, 22), GOAL)
    assert side(res) == "bottom"
    assert res.cost_m == pure_plan(cells, (58, 22), GOAL).cost_m  # this tick's own NF1 plan


def test_the_route_survives_the_grid_recentring() -> None:
    """The grid moves by whole cells (``shift_cells``): robot and goal cell coordinates move with it, and
    the held route is moved the same way, not dropped."""
    cells = block_world()
    held = planner()
    assert side(held.plan(cells, (57, 20), GOAL)) == "top"
    d_row, d_col = 4, 15
    moved = shift_cells(cells, d_row, d_col)
    start, goal = (62 - d_row, 22 - d_col), (GOAL[0] - d_row, GOAL[1] - d_col)
    assert side(pure_plan(moved, start, goal)) == "bottom"
    kept = held.plan(moved, start, goal)
    assert side_shifted(kept, d_col) == "top"


def side_shifted(res: PlanResult, d_col: int) -> str:
    rows = res.path_cells[(res.path_cells[:, 1] >= 90 - d_col) & (res.path_cells[:, 1] <= 100 - d_col), 0]
    return "top" if rows.max() < 60 else "bottom"


def test_a_new_goal_or_the_pure_setting_plans_afresh() -> None:
    cells = block_world()
    held = planner()
    held.plan(cells, (57, 20), GOAL)
    new_goal = (GOAL[0] + 0.3, GOAL[1])  # not a whole-cell move: a different goal, not a re-centred grid
    assert side(held.plan(cells, (62, 22), new_goal)) == "bottom"
    held.reset()
    assert side(held.plan(cells, (62, 22), GOAL)) == "bottom"
    pure = planner(PURE)  # both margins 0: every call equals the stateless ``plan``
    for start in ((57, 20), (62, 22), (59, 30), (61, 40)):
        a, b = pure.plan(cells, start, GOAL), pure_plan(cells, start, GOAL)
        assert np.array_equal(a.waypoints_cells, b.waypoints_cells) and a.cost_m == b.cost_m


def test_held_route_to_a_goal_beyond_the_grid() -> None:
    """A goal beyond the right edge: the held route ends on a free border cell and its cost includes the
    straight line from there to the goal."""
    cells = block_world()
    goal = (60.5, 600.5)
    held, pure = planner(), planner(PURE)
    assert side(held.plan(cells, (57, 20), goal)) == "top"
    assert side(pure.plan(cells, (62, 22), goal)) == "bottom"
    kept = held.plan(cells, (62, 22), goal)
    assert side(kept) == "top" and kept.goal_projected and kept.goal_cell[1] == 199


def test_same_inputs_same_outputs() -> None:
    """The result is a function of the inputs and the held route: two planners fed the same sequence agree."""
    cells = block_world()
    seq = [(57, 20), (62, 22), (64, 30), (70, 35), (75, 40), (100, 40)]
    a, b = planner(), planner()
    for start in seq:
        ra, rb = a.plan(cells, start, GOAL), b.plan(cells, start, GOAL)
        assert np.array_equal(ra.waypoints_cells, rb.waypoints_cells) and ra.direction_rad == rb.direction_rad


def test_route_cost_weights_unknown_cells() -> None:
    wp = np.array([[0.0, 0.0], [0.0, 10.0]])
    unknown = np.zeros((1, 11), dtype=bool)
    assert route_cost(wp) == pytest.approx(10.0)
    unknown[0, 6:11] = True  # the last 5 of the 10 cells entered
    assert route_cost(wp, step_costs(unknown, 3.0)) == pytest.approx(10.0 * (1 + 2.0 * 0.5))
    assert step_costs(unknown, 1.0) is None


def test_route_cost_weights_avoided_cells_and_both_at_the_product() -> None:
    wp = np.array([[0.0, 0.0], [0.0, 10.0]])
    unknown = np.zeros((1, 11), dtype=bool)
    avoid = np.zeros((1, 11), dtype=bool)
    unknown[0, 6:11] = True  # the last 5 of the 10 cells entered
    avoid[0, 9:11] = True  # the last 2, both also unknown
    costs = step_costs(unknown, 3.0, avoid, 10.0)
    assert costs is not None
    # 5 plain cells, 3 unknown at 3, 2 unknown and avoided at 30: the mean factor over the 10 entered
    assert route_cost(wp, costs) == pytest.approx(10.0 * (5 * 1 + 3 * 3 + 2 * 30) / 10)
    only_avoid = step_costs(None, 3.0, avoid, 10.0)
    assert only_avoid is not None
    assert route_cost(wp, only_avoid) == pytest.approx(10.0 * (8 + 2 * 10) / 10)
    assert step_costs(unknown, 1.0, np.zeros_like(avoid), 10.0) is None  # nothing to avoid


def test_bad_margins() -> None:
    with pytest.raises(ValueError, match="route_keep_ratio"):
        RouteParams(route_keep_ratio=-0.1)
    with pytest.raises(ValueError, match="route_keep_m"):
        RouteParams(route_keep_m=-1.0)


def test_the_held_route_through_a_door_is_kept_from_a_robot_cell_in_c_obstacle() -> None:
    """A door whose C-space is one cell wide; a noisy hit extends a jamb by one cell, which closes the
    door in the C-space (not one cell less: the route hysteresis on the C-space radius keeps the route
    through it), while the robot stands beside that jamb, its own cell C-obstacle (its plan escapes to a
    free neighbour). The held route is rejoined from the robot cell as from any other: the way round the
    wall's far end (a detour of some 5 m) is not taken."""
    cells = np.full((60, 80), FREE, dtype=np.uint8)
    cells[30, :71] = OCCUPIED
    cells[30, 20:25] = FREE  # the door: jambs at columns 19 and 25, C-space free on column 22 only
    goal = (45.5, 22.5)
    p = planner()
    first = p.plan(cells, (20, 22), goal)
    assert first.ok and first.direction_rad == pytest.approx(math.pi / 2, abs=0.05)  # through the door
    noisy = cells.copy()
    noisy[30, 20] = OCCUPIED
    strict = free_cspace(noisy, cell_m=CELL_M, inflate_m=INFLATE_M)
    assert not strict[29, 22] and not strict[30, 22]  # the robot cell C-obstacle, the door shut
    afresh = plan(strict, (29, 22), goal, cell_m=CELL_M)
    assert afresh.ok and afresh.n_escape == 1 and afresh.length_m > 5.0  # round the wall's far end
    kept = p.plan(noisy, (29, 22), goal)
    assert kept.ok and kept.length_m < 1.5 and kept.direction_rad == pytest.approx(math.pi / 2, abs=0.1)
