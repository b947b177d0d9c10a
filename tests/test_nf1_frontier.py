"""NF1 towards a goal beyond the grid (``Nf1Params.frontier_goal``): the wave starts from every free border
cell, and the plan ends on the reachable one with the least detour + straight line to the goal; never a
C-obstacle cell, never a sealed one."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pytest
from numpy.typing import NDArray
from test_nf1 import CELL_M, check_valid, inflate, office

from gndreplay.pipeline.nf1 import Nf1Params, nf1_wavefront, plan, project_goal, reaches_border
from gndreplay.types import Flag

CONNECTIVITIES: tuple[Literal[4, 8], ...] = (4, 8)


def border_mask(shape: tuple[int, int]) -> NDArray[np.bool_]:
    m = np.zeros(shape, dtype=bool)
    m[[0, -1], :] = True
    m[:, [0, -1]] = True
    return m


def scores(
    free: NDArray[np.bool_], start: tuple[int, int], goal: tuple[float, float], connectivity: Literal[4, 8]
) -> NDArray[np.float64]:
    """Brute force, independent of the seeded wave: for every free border cell reachable from the robot,
    the wave distance robot -> cell minus the obstacle-free wave distance, plus the straight lines robot ->
    cell and cell -> goal [cells]; inf elsewhere."""
    d = nf1_wavefront(free, start, connectivity=connectivity).astype(np.float64)
    rr, cc = np.mgrid[: free.shape[0], : free.shape[1]]
    dr, dc = np.abs(rr - start[0]), np.abs(cc - start[1])
    free_len = np.maximum(dr, dc) + (math.sqrt(2) - 1) * np.minimum(dr, dc) if connectivity == 8 else dr + dc
    s = d - free_len + np.hypot(dr, dc) + np.hypot(rr - (goal[0] - 0.5), cc - (goal[1] - 0.5))
    return np.where(border_mask(free.shape) & free & np.isfinite(d), s, np.inf)


@pytest.mark.parametrize("connectivity", CONNECTIVITIES)
def test_open_space_aims_at_the_border_cell_on_the_robot_goal_line(connectivity: Literal[4, 8]) -> None:
    """Without obstacles the frontier cell is the papers' projection, whatever the wave's metric."""
    free = np.ones((100, 100), dtype=bool)
    params = Nf1Params(connectivity=connectivity)
    for goal in ((250.5, 130.5), (-80.5, 10.5), (40.5, -300.5), (51.5, 400.5)):
        res = plan(free, (50, 50), goal, cell_m=CELL_M, params=params)
        check_valid(res, free, (50, 50))
        proj = project_goal((50, 50), goal, free.shape)
        assert res.goal_projected
        assert math.dist(res.goal_cell, proj) <= 1.5, (goal, res.goal_cell, proj)
        bearing = math.atan2(goal[0] - 50.5, goal[1] - 50.5)
        assert abs(math.remainder(res.direction_rad - bearing, math.tau)) < 0.03


@pytest.mark.parametrize("connectivity", CONNECTIVITIES)
def test_projection_in_an_inflated_obstacle_is_never_the_goal(connectivity: Literal[4, 8]) -> None:
    """A wall at the border where the robot-goal line leaves the grid: the papers' projection is in the
    C-obstacle (GOAL_IN_OBSTACLE once the 1 m border search is exhausted); the frontier goal is the best
    free border cell, found by the wave."""
    occ = np.zeros((120, 120), dtype=bool)
    occ[30:90, 110:] = True  # a block 60 cells tall at the right edge, straight ahead of the robot
    free = inflate(occ, 6.0)
    goal = (60.5, 400.5)
    start = (60, 40)
    old = plan(free, start, goal, cell_m=CELL_M, params=Nf1Params(frontier_goal=False,
                                                                  connectivity=connectivity))
    assert old.flag == Flag.GOAL_IN_OBSTACLE and old.goal_projected
    res = plan(free, start, goal, cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    check_valid(res, free, start)
    assert res.goal_projected and free[res.goal_cell] and border_mask(free.shape)[res.goal_cell]
    s = scores(free, start, goal, connectivity)
    assert s[res.goal_cell] == pytest.approx(s.min(), abs=1e-3)


@pytest.mark.parametrize("connectivity", CONNECTIVITIES)
def test_a_sealed_border_pocket_is_passed_over(connectivity: Literal[4, 8]) -> None:
    """The projection falls in a pocket at the border that the robot cannot enter (a U whose mouth is the
    grid edge, closed on the robot's side): the frontier goal is a reachable border cell outside it."""
    occ = np.zeros((100, 100), dtype=bool)
    occ[35, 60:] = occ[65, 60:] = True
    occ[35:66, 60] = True  # pocket rows 36..64, cols 61..99, open only to the grid edge
    free = inflate(occ, 3.0)
    start, goal = (50, 20), (50.5, 300.5)
    assert free[project_goal(start, goal, free.shape)]  # the papers' goal cell is free, but sealed
    old = plan(free, start, goal, cell_m=CELL_M, params=Nf1Params(frontier_goal=False,
                                                                  connectivity=connectivity))
    assert old.flag == Flag.PLANNER_NO_PATH
    res = plan(free, start, goal, cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    check_valid(res, free, start)
    assert not 35 <= res.goal_cell[0] <= 65 and res.goal_cell[1] == 99  # just past the pocket's walls
    s = scores(free, start, goal, connectivity)
    assert s[res.goal_cell] == pytest.approx(s.min(), abs=1e-3)


@pytest.mark.parametrize("connectivity", CONNECTIVITIES)
def test_random_offices_frontier_is_the_best_reachable_free_border_cell(connectivity: Literal[4, 8]) -> None:
    """The class: random offices with doors (the walls' ends open to the border), goals beyond the grid in
    every direction. The plan succeeds exactly when the robot reaches a free border cell (the stack's
    ``reaches_border``), and then ends on a free border cell of least score, never a C-obstacle one."""
    params = Nf1Params(connectivity=connectivity)
    rng = np.random.default_rng(7)
    n_ok = n_fail = 0
    for seed in range(6):
        occ = office(seed, 100)
        occ[[0, -1], :] = occ[:, [0, -1]] = False
        occ[0, rng.integers(0, 100, 30)] = True  # clutter along the edge
        occ[rng.integers(0, 100, 30), -1] = True
        free = inflate(occ, 2.5)
        starts = np.argwhere(free)
        for _ in range(6):
            row, col = starts[rng.integers(len(starts))]
            start = (int(row), int(col))
            ang = rng.uniform(-math.pi, math.pi)
            goal = (50.0 + 400 * math.sin(ang), 50.0 + 400 * math.cos(ang))
            res = plan(free, start, goal, cell_m=CELL_M, params=params)
            assert res.goal_projected
            assert res.ok == reaches_border(free, start)
            if not res.ok:
                assert res.flag == Flag.PLANNER_NO_PATH
                n_fail += 1
                continue
            n_ok += 1
            check_valid(res, free, start)
            assert free[res.goal_cell] and border_mask(free.shape)[res.goal_cell]
            s = scores(free, start, goal, connectivity)
            assert s[res.goal_cell] == pytest.approx(s.min(), abs=1e-3)
    assert n_ok >= 20 and n_fail >= 1  # both kinds occur


def test_enclosed_robot_or_no_free_border_cell_is_no_path() -> None:
    free = np.ones((40, 40), dtype=bool)
    free[10, 10:30] = free[29, 10:30] = free[10:30, 10] = free[10:30, 29] = False
    res = plan(free, (20, 20), (20.5, 200.5), cell_m=CELL_M)
    assert res.flag == Flag.PLANNER_NO_PATH and res.goal_projected and not res.ok
    assert res.goal_cell == project_goal((20, 20), (20.5, 200.5), free.shape)
    sealed = np.zeros((40, 40), dtype=bool)
    sealed[1:-1, 1:-1] = True  # the whole border is C-obstacle
    res = plan(sealed, (20, 20), (20.5, 200.5), cell_m=CELL_M)
    assert res.flag == Flag.PLANNER_NO_PATH and res.goal_projected


def test_robot_in_cspace_obstacle_escapes_towards_the_frontier() -> None:
    free = np.ones((60, 60), dtype=bool)
    free[27:34, 27:34] = False  # robot cell and all its neighbours: the escape runs to the nearest free one
    res = plan(free, (30, 30), (30.5, 300.5), cell_m=CELL_M, params=Nf1Params(escape_m=0.5))
    check_valid(res, free, (30, 30))
    assert res.n_escape > 1 and res.goal_cell[1] == 59


def test_unknown_cost_weighs_the_path_to_the_frontier() -> None:
    """A goal beyond the right edge, a wall with a short way round through never-seen cells and a longer
    one through known free cells: the unknown cost applies on the way to the frontier too."""
    free = np.ones((40, 60), dtype=bool)
    free[3:38, 30] = False
    free[:, 40:] = True
    unknown = np.zeros_like(free)
    unknown[:10, :] = True
    start, goal = (10, 5), (10.5, 400.5)
    pure = plan(free, start, goal, cell_m=0.1, unknown=unknown)
    assert pure.ok and pure.path_cells[:, 0].min() <= 2
    known = plan(free, start, goal, cell_m=0.1, params=Nf1Params(unknown_cost=4.0), unknown=unknown)
    assert known.ok and known.path_cells[:, 0].max() >= 38
    assert not unknown[known.path_cells[:, 0], known.path_cells[:, 1]].any()
