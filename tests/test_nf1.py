"""NF1 planner: known answers on synthetic C-spaces (row = y, col = x, directions CCW from +col)."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from gndreplay.pipeline.nf1 import (
    Nf1Params,
    _visible,  # the kernel behind every line-of-sight claim
    descend,
    nf1_wavefront,
    path_direction,
    plan,
    project_goal,
    reaches_border,
    tighten,
)
from gndreplay.pipeline.planner import PlanResult, RouteParams
from gndreplay.types import Flag

CELL_M = 0.05
CONNECTIVITIES: tuple[Literal[4, 8], ...] = (4, 8)


def corner(rc: tuple[float, float]) -> tuple[float, float]:
    """Goal at the centre of cell rc, in the corner coordinates ``plan`` takes."""
    return rc[0] + 0.5, rc[1] + 0.5


def inflate(occupied: NDArray[np.bool_], radius_cells: float) -> NDArray[np.bool_]:
    """Free C-space: cells farther than radius_cells from every occupied cell."""
    return distance_transform_edt(~occupied) > radius_cells


def office(seed: int, n: int = 160) -> NDArray[np.bool_]:
    """Occupied cells of a random office: border, a few walls with doors, clutter blocks."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((n, n), dtype=bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    for _ in range(4):
        k = int(rng.integers(20, n - 20))
        door = int(rng.integers(10, n - 30))
        if rng.random() < 0.5:
            occ[k, :] = True
            occ[k, door : door + 20] = False
        else:
            occ[:, k] = True
            occ[door : door + 20, k] = False
    for _ in range(12):
        r, c = rng.integers(5, n - 10, size=2)
        occ[r : r + int(rng.integers(2, 8)), c : c + int(rng.integers(2, 8))] = True
    return occ


def visible_sampled(free: NDArray[np.bool_], p: NDArray[np.float64], q: NDArray[np.float64]) -> bool:
    """Independent line-of-sight check: dense samples along p -> q (p's own cell excepted)."""
    t = np.linspace(0.0, 1.0, 20 * (int(np.hypot(*(q - p))) + 2))
    pts = p[None, :] + t[:, None] * (q - p)[None, :]
    cells = np.floor(pts + 0.5).astype(int)
    cells = cells[np.any(cells != np.floor(p + 0.5).astype(int), axis=1)]
    return bool(free[cells[:, 0], cells[:, 1]].all())


def check_valid(res: PlanResult, free: NDArray[np.bool_], start: tuple[int, int]) -> None:
    """Every invariant a successful plan must satisfy."""
    assert res.ok and res.flag == Flag.NONE
    path = res.path_cells
    assert path.dtype == np.int32 and path.ndim == 2 and path.shape[1] == 2
    assert tuple(path[0]) == start and tuple(path[-1]) == res.goal_cell
    steps = np.abs(np.diff(path, axis=0))
    assert np.all(steps.max(axis=1) == 1), "consecutive path cells must be 8-adjacent and distinct"
    assert free[path[res.n_escape :, 0], path[res.n_escape :, 1]].all(), "path leaves free C-space"
    diag = np.flatnonzero(steps.sum(axis=1) == 2)
    diag = diag[diag >= res.n_escape]
    a, b = path[diag], path[diag + 1]
    assert free[a[:, 0], b[:, 1]].all() and free[b[:, 0], a[:, 1]].all(), "corner cutting"
    wp = res.waypoints_cells
    assert np.array_equal(wp[0], start) and np.array_equal(wp[-1], res.goal_cell)
    first = 1 if res.n_escape > 1 else 0  # the escape segment runs through C-obstacle by design
    for p, q in zip(wp[first:-1], wp[first + 1 :], strict=True):
        assert visible_sampled(free, p, q), f"waypoints {p} and {q} do not see each other"
    seg = np.diff(wp, axis=0)
    assert res.length_m == pytest.approx(np.hypot(seg[:, 0], seg[:, 1]).sum() * CELL_M)
    assert res.length_m <= res.cost_m * (1 + 1e-5) + 1e-9  # float32 wave values
    assert -math.pi < res.direction_rad <= math.pi


def test_straight_corridor_direction_along_it() -> None:
    free = np.zeros((40, 200), dtype=bool)
    free[15:25, :] = True
    res = plan(free, (20, 10), corner((20, 190)), cell_m=CELL_M)
    check_valid(res, free, (20, 10))
    assert res.direction_rad == pytest.approx(0.0, abs=1e-12)
    assert res.length_m == pytest.approx(180 * CELL_M)
    assert res.waypoints_cells.shape == (2, 2)


@pytest.mark.parametrize(
    ("goal", "expected"),
    [((50, 95), 0.0), ((95, 50), math.pi / 2), ((5, 50), -math.pi / 2), ((50, 5), math.pi)],
)
@pytest.mark.parametrize("connectivity", [4, 8])
def test_direction_conventions(goal: tuple[int, int], expected: float, connectivity: Literal[4, 8]) -> None:
    free = np.ones((100, 100), dtype=bool)
    res = plan(free, (50, 50), corner(goal), cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    check_valid(res, free, (50, 50))
    assert res.direction_rad == pytest.approx(expected, abs=1e-12)  # +pi, never -pi


def u_trap() -> tuple[NDArray[np.bool_], tuple[int, int], tuple[int, int]]:
    """A U open to the west (-col) with the robot inside and the goal east of its closed side."""
    occ = np.zeros((120, 160), dtype=bool)
    occ[30:91, 100:104] = True  # bottom of the U, between robot and goal
    occ[30:34, 30:104] = True  # arms
    occ[87:91, 30:104] = True
    return inflate(occ, 4.0), (60, 90), (60, 140)


@pytest.mark.parametrize("connectivity", [4, 8])
def test_u_shape_direction_points_out_of_the_u(connectivity: Literal[4, 8]) -> None:
    free, start, goal = u_trap()
    res = plan(free, start, corner(goal), cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    check_valid(res, free, start)
    # The goal lies straight ahead (+col); the first metre leads back west, towards the opening.
    assert math.cos(res.direction_rad) < -0.9
    # The path leaves the U through its opening (col < 30) before going round an arm.
    assert res.path_cells[:, 1].min() < 30
    assert np.any(res.path_cells[:, 0] < 30) != np.any(res.path_cells[:, 0] > 90)


def test_goal_in_obstacle() -> None:
    free, start, _ = u_trap()
    res = plan(free, start, corner((60, 101)), cell_m=CELL_M)
    assert not res.ok and res.flag == Flag.GOAL_IN_OBSTACLE
    assert res.goal_cell == (60, 101)
    assert res.path_cells.shape == (0, 2) and res.waypoints_cells.shape == (0, 2)
    assert math.isnan(res.direction_rad) and math.isnan(res.length_m)


def test_goal_in_inflated_margin_is_in_obstacle() -> None:
    free, start, _ = u_trap()
    res = plan(free, start, corner((60, 97)), cell_m=CELL_M)  # 3 cells from the wall, inflation 4
    assert res.flag == Flag.GOAL_IN_OBSTACLE


@pytest.mark.parametrize("connectivity", [4, 8])
def test_enclosed_robot_has_no_path(connectivity: Literal[4, 8]) -> None:
    occ = np.zeros((100, 100), dtype=bool)
    occ[40:60, 40] = occ[40:60, 59] = True
    occ[40, 40:60] = occ[59, 40:60] = True
    free = inflate(occ, 2.0)
    res = plan(free, (50, 50), corner((90, 90)), cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    assert not res.ok and res.flag == Flag.PLANNER_NO_PATH
    assert math.isnan(res.direction_rad)
    # and the other way round: goal inside, robot outside
    res = plan(free, (90, 90), corner((50, 50)), cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    assert res.flag == Flag.PLANNER_NO_PATH


def test_wavefront_known_values() -> None:
    free = np.ones((30, 40), dtype=bool)
    rr, cc = np.mgrid[0:30, 0:40]
    dr, dc = np.abs(rr - 7), np.abs(cc - 11)
    nf4 = nf1_wavefront(free, (7, 11), connectivity=4)
    assert nf4.dtype == np.float32
    np.testing.assert_array_equal(nf4, dr + dc)  # Manhattan distance
    nf8 = nf1_wavefront(free, (7, 11), connectivity=8)
    octile = np.maximum(dr, dc) + (np.sqrt(2) - 1) * np.minimum(dr, dc)
    np.testing.assert_allclose(nf8, octile, rtol=1e-5)


def test_wavefront_walls_unreached_and_no_corner_cutting() -> None:
    free = np.ones((10, 10), dtype=bool)
    free[:, 5] = False
    nf = nf1_wavefront(free, (0, 0), connectivity=8)
    assert np.isinf(nf[:, 5:]).all() and np.isfinite(nf[:, :5]).all()
    # two C-obstacle cells touching at a corner block the diagonal between them
    free = np.ones((3, 3), dtype=bool)
    free[0, 1] = free[1, 0] = False
    free[0, 2] = free[2, 0] = False
    nf = nf1_wavefront(free, (0, 0), connectivity=8)
    assert np.isinf(nf[1, 1])


def test_path_cells_free_and_waypoints_visible_in_offices() -> None:
    for seed in range(12):
        free = inflate(office(seed), 3.0)
        cells = np.argwhere(free)
        rng = np.random.default_rng(100 + seed)
        for _ in range(4):
            s, g = cells[rng.choice(len(cells), size=2, replace=False)]
            start = (int(s[0]), int(s[1]))
            for conn in CONNECTIVITIES:
                res = plan(free, start, corner(tuple(g)), cell_m=CELL_M, params=Nf1Params(connectivity=conn))
                if res.ok:
                    check_valid(res, free, start)
                    assert res.n_escape == 0
                else:
                    assert res.flag == Flag.PLANNER_NO_PATH
                    nf = nf1_wavefront(free, (int(g[0]), int(g[1])), connectivity=conn)
                    assert np.isinf(nf[start])


def test_early_exit_gives_the_same_path() -> None:
    free = inflate(office(3), 3.0)
    cells = np.argwhere(free)
    rng = np.random.default_rng(7)
    for _ in range(10):
        s, g = cells[rng.choice(len(cells), size=2, replace=False)]
        start = (int(s[0]), int(s[1]))
        for conn in CONNECTIVITIES:
            a = plan(free, start, corner(tuple(g)), cell_m=CELL_M, params=Nf1Params(connectivity=conn))
            b = plan(
                free,
                start,
                corner(tuple(g)),
                cell_m=CELL_M,
                params=Nf1Params(connectivity=conn, early_exit=False),
            )
            assert a.flag == b.flag
            np.testing.assert_array_equal(a.path_cells, b.path_cells)
            np.testing.assert_array_equal(a.waypoints_cells, b.waypoints_cells)


def test_four_and_eight_connectivity_around_a_wall() -> None:
    free = np.ones((100, 100), dtype=bool)
    free[30:70, 58:63] = False
    r4 = plan(free, (50, 50), corner((50, 90)), cell_m=CELL_M, params=Nf1Params(connectivity=4))
    r8 = plan(free, (50, 50), corner((50, 90)), cell_m=CELL_M, params=Nf1Params(connectivity=8))
    for r in (r4, r8):
        check_valid(r, free, (50, 50))
        # taut path: round one end of the wall, via the corners (29 or 70, 57..63)
        assert len(r.waypoints_cells) == 4
        assert abs(r.direction_rad) == pytest.approx(math.atan2(20, 7), abs=0.08)
    assert r4.cost_m == pytest.approx((20 + 20 + 40) * CELL_M)  # Manhattan length round the wall end
    assert r8.cost_m < r4.cost_m


def test_tighten_open_staircase_to_a_segment() -> None:
    free = np.ones((30, 30), dtype=bool)
    nf = nf1_wavefront(free, (25, 20))
    path = descend(nf, free, (2, 3))
    assert len(path) == int(nf[2, 3]) - 17 + 1  # 4-connected wave, 17 diagonal steps taken
    np.testing.assert_array_equal(tighten(path, free), [[2, 3], [25, 20]])


def touched_cells(r0: int, c0: int, r1: int, c1: int) -> list[tuple[int, int]]:
    """Brute force, exact in integers: cells whose closed square the segment between centres meets."""
    p, q = np.array([2 * r0, 2 * c0]), np.array([2 * r1, 2 * c1])
    d = q - p
    out = []
    for r in range(min(r0, r1), max(r0, r1) + 1):
        for c in range(min(c0, c1), max(c0, c1) + 1):
            side = [
                d[0] * (y - p[1]) - d[1] * (x - p[0])
                for x in (2 * r - 1, 2 * r + 1)
                for y in (2 * c - 1, 2 * c + 1)
            ]
            if min(side) <= 0 <= max(side):
                out.append((r, c))
    return out


def test_line_of_sight_is_the_exact_supercover() -> None:
    rng = np.random.default_rng(5)
    for _ in range(800):
        free = rng.random((10, 10)) > 0.08
        r0, c0, r1, c1 = (int(v) for v in rng.integers(0, 10, size=4))
        expected = all(free[cell] for cell in touched_cells(r0, c0, r1, c1) if cell != (r0, c0))
        assert _visible(free, r0, c0, r1, c1) == expected, (r0, c0, r1, c1)
    # a segment through a lattice corner touches both side cells
    free = np.ones((3, 3), dtype=bool)
    free[0, 1] = False
    assert not _visible(free, 0, 0, 1, 1) and _visible(free, 0, 0, 2, 0)


def test_descent_from_unreached_cell_is_empty() -> None:
    free = np.ones((5, 5), dtype=bool)
    free[:, 2] = False
    nf = nf1_wavefront(free, (0, 0))
    assert descend(nf, free, (0, 4)).shape == (0, 2)


def test_goal_outside_is_projected_onto_border_along_the_line() -> None:
    free = np.ones((100, 100), dtype=bool)
    start = (50, 50)
    assert project_goal(start, (50.5, 300.5), (100, 100)) == (50, 99)
    assert project_goal(start, (-100.2, 50.7), (100, 100)) == (0, 50)
    g = (250.5, 130.5)  # centre index (250, 130): the line leaves the grid at row 99, col 50 + 80 * 49/200
    assert project_goal(start, g, (100, 100)) == (99, 70)
    res = plan(free, start, g, cell_m=CELL_M)
    check_valid(res, free, start)
    assert res.goal_projected and res.goal_cell == (99, 70)
    assert res.direction_rad == pytest.approx(math.atan2(200, 80), abs=0.02)
    inside = plan(free, start, (10.9, 20.1), cell_m=CELL_M)
    assert not inside.goal_projected and inside.goal_cell == (10, 20)


PROJECT = Nf1Params(frontier_goal=False)  # the papers' projection of a goal beyond the grid


def test_projected_goal_behind_wall_is_in_obstacle() -> None:
    free = np.ones((100, 100), dtype=bool)
    free[:, 95:] = False
    res = plan(free, (50, 50), (50.5, 500.5), cell_m=CELL_M, params=PROJECT)
    assert res.flag == Flag.GOAL_IN_OBSTACLE and res.goal_projected and res.goal_cell == (50, 99)


def test_robot_cell_in_cspace_obstacle_next_to_free_cells() -> None:
    free = np.ones((60, 60), dtype=bool)
    free[30, 30] = False  # only the robot cell
    res = plan(free, (30, 30), corner((30, 50)), cell_m=CELL_M)
    check_valid(res, free, (30, 30))
    assert res.n_escape == 1 and res.direction_rad == pytest.approx(0.0)


@pytest.mark.parametrize("connectivity", [4, 8])
def test_robot_deep_in_cspace_obstacle_escapes_on_its_own_side(connectivity: Literal[4, 8]) -> None:
    occ = np.zeros((100, 100), dtype=bool)
    occ[:, 50] = True  # a thin wall with a door at the top
    occ[0:12, 50] = False
    free = inflate(occ, 6.0)
    start = (60, 47)  # 3 cells west of the wall: C-obstacle, and so are all its neighbours
    assert not free[59:62, 46:49].any()
    res = plan(free, start, corner((60, 80)), cell_m=CELL_M, params=Nf1Params(connectivity=connectivity))
    check_valid(res, free, start)
    assert res.n_escape > 1
    esc = res.path_cells[: res.n_escape + 1]
    assert np.all(esc[:, 1] <= 47) and tuple(esc[-1]) == (60, 43)  # nearest free cell, west
    # the first metre: 4 cells away from the wall, then along it towards the door (-row)
    assert math.cos(res.direction_rad) < -0.1 and math.sin(res.direction_rad) < -0.9
    through = res.path_cells[res.path_cells[:, 1] == 50]
    assert np.all(through[:, 0] < 12)  # crosses the wall only at the door
    # escape disabled, or too short to reach free space: no path
    no = plan(free, start, corner((60, 80)), cell_m=CELL_M, params=Nf1Params(escape_m=0.0))
    assert no.flag == Flag.PLANNER_NO_PATH
    no = plan(free, start, corner((60, 80)), cell_m=CELL_M, params=Nf1Params(escape_m=0.15))
    assert no.flag == Flag.PLANNER_NO_PATH


def test_goal_in_robot_cell() -> None:
    free = np.ones((20, 20), dtype=bool)
    res = plan(free, (10, 10), (10.5, 10.9), cell_m=CELL_M)
    assert res.ok and res.path_cells.shape == (1, 2) and res.length_m == 0.0
    assert res.direction_rad == pytest.approx(math.atan2(0.0, 0.4))


def test_lookahead_point_along_polyline() -> None:
    wp = np.array([[0.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    assert path_direction(wp, 15.0) == pytest.approx(math.atan2(5.0, 10.0))
    assert path_direction(wp, 5.0) == pytest.approx(0.0)
    assert path_direction(wp, 100.0) == pytest.approx(math.pi / 4)
    free = np.ones((100, 100), dtype=bool)
    free[20:80, 60:70] = False  # wall 10 cells east of the robot; go round its south end (row < 20)
    res = plan(free, (50, 50), corner((50, 90)), cell_m=CELL_M, lookahead_m=0.5)
    check_valid(res, free, (50, 50))
    first = res.waypoints_cells[1] - res.waypoints_cells[0]
    assert res.direction_rad == pytest.approx(math.atan2(first[0], first[1]))


def test_bad_arguments() -> None:
    free = np.ones((10, 10), dtype=bool)
    with pytest.raises(ValueError, match="connectivity must be 4 or 8"):
        Nf1Params(connectivity=6)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="lookahead_m must be > 0"):
        RouteParams(lookahead_m=0.0)
    with pytest.raises(ValueError, match="lookahead_m must be > 0"):
        plan(free, (1, 1), (5.0, 5.0), cell_m=CELL_M, lookahead_m=0.0)
    with pytest.raises(ValueError, match="escape_m must be >= 0"):
        Nf1Params(escape_m=-1.0)
    with pytest.raises(ValueError, match="border_search_m must be >= 0"):
        Nf1Params(border_search_m=-1.0)
    with pytest.raises(ValueError, match=r"free must be a 2-D bool array, got shape \(10, 10\) dtype uint8"):
        plan(free.astype(np.uint8), (1, 1), (5.0, 5.0), cell_m=CELL_M)
    with pytest.raises(ValueError, match=r"start_rc \(10, 1\) is outside the grid of shape \(10, 10\)"):
        plan(free, (10, 1), (5.0, 5.0), cell_m=CELL_M)
    with pytest.raises(ValueError, match="goal_rc_float must be finite"):
        plan(free, (1, 1), (math.nan, 5.0), cell_m=CELL_M)
    with pytest.raises(ValueError, match="cell_m must be > 0"):
        plan(free, (1, 1), (5.0, 5.0), cell_m=0.0)
    with pytest.raises(ValueError, match="connectivity must be 4 or 8"):
        nf1_wavefront(free, (1, 1), connectivity=6)  # type: ignore[arg-type]


def test_projected_goal_on_blocked_border_moves_to_nearest_free_border_cell() -> None:
    free = np.ones((100, 100), dtype=bool)
    free[45:56, 97:] = False  # furniture at the border where the robot-goal line leaves the grid
    res = plan(free, (50, 50), (50.5, 500.5), cell_m=CELL_M, params=PROJECT)
    check_valid(res, free, (50, 50))
    assert res.goal_projected and res.goal_cell == (44, 99)  # 6 cells up or down: the tie goes to row-major
    off = plan(free, (50, 50), (50.5, 500.5), cell_m=CELL_M,
               params=Nf1Params(frontier_goal=False, border_search_m=0.0))
    assert off.flag == Flag.GOAL_IN_OBSTACLE and off.goal_cell == (50, 99)
    inside = plan(free, (50, 50), (50.5, 98.5), cell_m=CELL_M)  # inside the grid: never moved
    assert inside.flag == Flag.GOAL_IN_OBSTACLE and inside.goal_cell == (50, 98)


@pytest.mark.parametrize("connectivity", [4, 8])
def test_unknown_cost_prefers_a_known_route(connectivity: Literal[4, 8]) -> None:
    """A wall with a short way round through never-seen cells (top) and a longer one through known free
    cells (bottom): the papers' NF1 (unknown_cost 1) takes the short unknown way, a high enough unknown
    cost the known one; the wave values are the weighted lengths."""
    free = np.ones((40, 60), dtype=bool)
    free[3:38, 20] = False
    unknown = np.zeros_like(free)
    unknown[:10, :] = True
    start, goal = (10, 5), (10.5, 40.5)
    pure = plan(free, start, goal, cell_m=0.1, params=Nf1Params(connectivity=connectivity, unknown_cost=1.0),
                unknown=unknown)
    assert pure.ok and pure.path_cells[:, 0].max() <= 10  # over the top, through the unknown
    same = plan(free, start, goal, cell_m=0.1, params=Nf1Params(connectivity=connectivity))
    assert same.cost_m == pytest.approx(pure.cost_m)  # without the mask: the same, pure NF1
    known = plan(free, start, goal, cell_m=0.1, params=Nf1Params(connectivity=connectivity, unknown_cost=4.0),
                 unknown=unknown)
    assert known.ok and known.path_cells[:, 0].max() >= 38  # round the bottom, known free all the way
    assert not unknown[known.path_cells[:, 0], known.path_cells[:, 1]].any()
    assert known.cost_m > pure.cost_m and known.length_m > pure.length_m


def test_unknown_cost_weights_each_step_into_an_unknown_cell() -> None:
    free = np.ones((1, 10), dtype=bool)
    unknown = np.zeros_like(free)
    unknown[0, 3:6] = True  # three unknown cells between start and goal
    r = plan(free, (0, 0), (0.5, 9.5), cell_m=1.0, params=Nf1Params(unknown_cost=3.0), unknown=unknown)
    assert r.cost_m == pytest.approx(6 * 1.0 + 3 * 3.0)
    with pytest.raises(ValueError, match="unknown_cost"):
        Nf1Params(unknown_cost=0.5)
    with pytest.raises(ValueError, match="shape"):
        plan(free, (0, 0), (0.5, 9.5), cell_m=1.0, unknown=np.zeros((2, 10), dtype=bool))


def test_reaches_border_tells_an_enclosed_robot() -> None:
    free = np.ones((20, 20), dtype=bool)
    free[5, 5:15] = free[14, 5:15] = free[5:15, 5] = free[5:15, 14] = False  # a closed ring
    assert not reaches_border(free, (10, 10))
    assert reaches_border(free, (2, 2))
    free[5, 9] = True  # a one-cell gap in the ring
    assert reaches_border(free, (10, 10))
    free[10, 10] = False  # the robot cell itself need not be free
    assert reaches_border(free, (10, 10))
