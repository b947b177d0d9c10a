"""Tunnel planner (wheelchair paper, Fig. 3) on grids with known answers, for both presets' robots."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from gndreplay.pipeline import tunnel
from gndreplay.pipeline.cspace import free_cspace
from gndreplay.pipeline.model import FREE, OCCUPIED
from gndreplay.pipeline.nf1 import Nf1Params, _visible, plan
from gndreplay.pipeline.tunnel import (
    _CHECK_AFTER,
    TunnelParams,
    TunnelPlanner,
    _cast_rays,
    _ray_state,
    _rays,
    tunnel_plan,
)
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig
from gndreplay.types import Flag

CELL_M = 0.05
N = 240  # 12 m x 12 m, robot cell in the middle
ROBOTS = {"wheelchair": WHEELCHAIR_ROBOT, "xr4000": XR4000_ROBOT}


def to_cell(x: float, y: float) -> tuple[int, int]:
    """World point (robot at the origin) -> (row, col); row along y, col along x."""
    return N // 2 + round(y / CELL_M), N // 2 + round(x / CELL_M)


def goal_rc(x: float, y: float) -> tuple[float, float]:
    r, c = to_cell(x, y)
    return r + 0.5, c + 0.5  # corner coordinates: the centre of the goal cell


def empty() -> np.ndarray:
    return np.full((N, N), FREE, dtype=np.uint8)


def wall(g: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> None:
    """Mark the cells along a segment OCCUPIED (dense sampling: an 8-connected line at least)."""
    n = int(max(abs(x1 - x0), abs(y1 - y0)) / CELL_M * 3) + 2
    for s in np.linspace(0.0, 1.0, n):
        r, c = to_cell(x0 + s * (x1 - x0), y0 + s * (y1 - y0))
        if 0 <= r < N and 0 <= c < N:
            g[r, c] = OCCUPIED


def wall_with_passage(
    g: np.ndarray, x: float, y_lo: float, y_hi: float, centre_y: float, width_m: float
) -> None:
    """A wall along x = const from y_lo to y_hi with a passage whose edge cell centres are ``width_m``
    apart (how a laser marks two surfaces width_m apart), centred on centre_y."""
    c = to_cell(x, 0.0)[1]
    gap = round(width_m / CELL_M)
    lo = to_cell(0.0, centre_y)[0] - gap // 2  # occupied edge cell; the other edge is lo + gap
    r0, r1 = to_cell(0.0, y_lo)[0], to_cell(0.0, y_hi)[0]
    g[r0 : lo + 1, c] = OCCUPIED
    g[lo + gap : r1 + 1, c] = OCCUPIED


def planner(robot: RobotConfig) -> TunnelPlanner:
    return TunnelPlanner(
        TunnelParams(), cell_m=CELL_M, inner_radius_m=robot.inner_radius_m, unknown_is_free=True
    )


def tunnel_is_free(g: np.ndarray, robot: RobotConfig, waypoints: np.ndarray) -> bool:
    free = free_cspace(g, cell_m=CELL_M, inflate_m=robot.inner_radius_m + TunnelParams().margin_m)
    w = waypoints.astype(int)
    return all(_visible(free, *a, *b) for a, b in itertools.pairwise(w))


def crossing_y(waypoints: np.ndarray, x: float) -> list[float]:
    """y [m] where the polyline crosses the vertical line at x."""
    c = to_cell(x, 0.0)[1]
    out = []
    for (r0, c0), (r1, c1) in itertools.pairwise(waypoints):
        if (c0 - c) * (c1 - c) <= 0 and c0 != c1:
            r = r0 + (r1 - r0) * (c - c0) / (c1 - c0)
            out.append((r - N // 2) * CELL_M)
    return out


@pytest.mark.parametrize("name", ROBOTS)
def test_goal_in_sight_is_one_tunnel(name: str) -> None:
    robot = ROBOTS[name]
    res = planner(robot).plan(empty(), to_cell(0, 0), goal_rc(3.0, 1.0))
    assert res.ok and res.flag == Flag.NONE
    assert res.nodes_expanded == 1
    assert res.waypoints_cells.tolist() == [list(to_cell(0, 0)), list(to_cell(3.0, 1.0))]
    assert res.direction_rad == pytest.approx(math.atan2(1.0, 3.0), abs=0.01)
    assert res.width_m == pytest.approx(2 * (robot.inner_radius_m + TunnelParams().margin_m))
    assert res.length_m == pytest.approx(math.hypot(3.0, 1.0), abs=0.05)


@pytest.mark.parametrize("name", ROBOTS)
def test_u_shaped_obstacle_course_points_out_of_the_u(name: str) -> None:
    """Fig. 3b: the robot inside a U whose bottom lies between it and the goal."""
    robot = ROBOTS[name]
    g = empty()
    wall(g, 1.2, -1.5, 1.2, 1.5)  # bottom of the U, between robot and goal
    wall(g, -1.5, -1.5, 1.2, -1.5)
    wall(g, -1.5, 1.5, 1.2, 1.5)
    res = planner(robot).plan(g, to_cell(0, 0), goal_rc(3.5, 0.0))
    assert res.ok
    assert math.cos(res.direction_rad) < -0.5  # backwards, towards the mouth of the U
    assert res.waypoints_cells[-1].tolist() == list(to_cell(3.5, 0.0))
    assert tunnel_is_free(g, robot, res.waypoints_cells)
    # the first tunnel leaves the U through its mouth: its end lies beyond the mouth (x < -1.5)
    assert (res.waypoints_cells[1, 1] - N // 2) * CELL_M < -1.5
    assert not [y for y in crossing_y(res.waypoints_cells, 1.2) if abs(y) <= 1.5]


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize(("extra_m", "taken"), [(-0.1, False), (0.0, False), (0.1, True)])
@pytest.mark.parametrize("robot_xy", [(0.0, 0.0), (0.0, -1.0), (-2.0, 1.0)])
def test_passage_taken_only_when_the_robot_fits(
    name: str, extra_m: float, taken: bool, robot_xy: tuple[float, float]
) -> None:
    """A wall across the way with a passage at y = 0 (the shortest way) and a wide opening beyond y = 2.5:
    a passage robot width + 0.1 m is taken, also seen at an angle from off its axis; a narrower one is not,
    even though it is shorter."""
    robot = ROBOTS[name]
    g = empty()
    wall_with_passage(g, 1.5, -6.0, 2.5, 0.0, 2 * robot.inner_radius_m + extra_m)
    start = to_cell(*robot_xy)
    res = planner(robot).plan(g, start, goal_rc(3.5, 0.0))
    assert res.ok
    assert tunnel_is_free(g, robot, res.waypoints_cells)
    ys = crossing_y(res.waypoints_cells, 1.5)
    assert len(ys) == 1
    if taken:
        assert abs(ys[0]) < 0.3
        first = res.waypoints_cells[1] - res.waypoints_cells[0]
        assert abs(math.atan2(-robot_xy[1], 1.5 - robot_xy[0]) - math.atan2(*first)) < math.radians(15)
    else:
        assert ys[0] > 2.5  # around the wall's end; the course points past it
        assert res.direction_rad > math.atan2(2.5 - robot_xy[1], 1.5 - robot_xy[0])


@pytest.mark.parametrize("name", ROBOTS)
def test_closed_door_turns_the_course_backwards(name: str) -> None:
    """Fig. 3c-d: in a corridor towards a door; when the door closes the course points back to the exit."""
    robot = ROBOTS[name]
    g = empty()
    wall(g, -2.5, -0.8, 2.0, -0.8)
    wall(g, -2.5, 0.8, 2.0, 0.8)
    p = planner(robot)
    opened = p.plan(g, to_cell(0, 0), goal_rc(4.0, 0.0))
    assert opened.ok and abs(opened.direction_rad) < math.radians(10)
    wall(g, 2.0, -0.8, 2.0, 0.8)  # the door closes
    closed = p.plan(g, to_cell(0, 0), goal_rc(4.0, 0.0))
    assert closed.ok
    assert abs(closed.direction_rad) > math.radians(150)  # backwards, along the corridor
    assert tunnel_is_free(g, robot, closed.waypoints_cells)
    assert closed.nodes_expanded > opened.nodes_expanded


@pytest.mark.parametrize("name", ROBOTS)
def test_enclosed_goal_is_not_reachable(name: str) -> None:
    robot = ROBOTS[name]
    g = empty()
    for a, b in [((2.0, -1.0), (4.0, -1.0)), ((4.0, -1.0), (4.0, 1.0)), ((4.0, 1.0), (2.0, 1.0)),
                 ((2.0, 1.0), (2.0, -1.0))]:
        wall(g, *a, *b)
    res = planner(robot).plan(g, to_cell(0, 0), goal_rc(3.0, 0.0))
    assert not res.ok and res.flag == Flag.PLANNER_NO_PATH  # the search ran out of nodes, not of budget
    assert 1 < res.nodes_expanded < TunnelParams().max_expansions
    assert res.waypoints_cells.shape == (0, 2) and math.isnan(res.direction_rad)
    free = free_cspace(g, cell_m=CELL_M, inflate_m=robot.inner_radius_m + TunnelParams().margin_m)
    assert plan(free, to_cell(0, 0), goal_rc(3.0, 0.0), cell_m=CELL_M).flag == Flag.PLANNER_NO_PATH


def clutter(seed: int, n_blocks: int = 25) -> np.ndarray:
    """The grid with ``n_blocks`` random furniture blocks 0.2-2 m a side."""
    rng = np.random.default_rng(seed)
    g = empty()
    for _ in range(n_blocks):
        x, y = rng.uniform(-5.5, 5.5, 2)
        w, h = rng.uniform(0.2, 2.0, 2)
        r0, c0 = to_cell(x, y)
        g[max(r0, 0) : r0 + round(h / CELL_M), max(c0, 0) : c0 + round(w / CELL_M)] = OCCUPIED
    return g


@pytest.mark.parametrize("name", ROBOTS)
def test_goal_cut_off_behind_a_maze_stops_at_the_connectivity_check(name: str) -> None:
    """A serpentine of walls, the goal boxed in at its far end: without the check the search would expand
    every node of the maze; with it, it stops when the check runs, and says what NF1 says. With a door in
    the box the search goes on past the check, as far as it needs, and finds the way."""
    robot = ROBOTS[name]
    g = empty()
    for i, x in enumerate((-4.0, -2.0, 0.0, 2.0)):  # open at the top, then at the bottom, ...
        wall(g, x, -6.0, x, 4.0) if i % 2 == 0 else wall(g, x, -4.0, x, 6.0)
    for a, b in [((3.0, -1.0), (5.0, -1.0)), ((5.0, -1.0), (5.0, 1.0)), ((5.0, 1.0), (3.0, 1.0)),
                 ((3.0, 1.0), (3.0, -1.0))]:
        wall(g, *a, *b)
    start, goal = to_cell(-5.0, -5.0), goal_rc(4.0, 0.0)
    radius = robot.inner_radius_m + TunnelParams().margin_m
    res = tunnel_plan(g, start, goal, cell_m=CELL_M, radius_m=radius)
    assert not res.ok and res.flag == Flag.PLANNER_NO_PATH and res.nodes_expanded == _CHECK_AFTER
    free = free_cspace(g, cell_m=CELL_M, inflate_m=radius)
    assert plan(free, start, goal, cell_m=CELL_M).flag == Flag.PLANNER_NO_PATH
    g[to_cell(0, -0.7)[0] : to_cell(0, 0.7)[0] + 1, to_cell(3.0, 0)[1] - 1 : to_cell(3.0, 0)[1] + 2] = FREE
    opened = tunnel_plan(g, start, goal, cell_m=CELL_M, radius_m=radius)
    assert opened.ok and opened.nodes_expanded > _CHECK_AFTER
    assert tunnel_is_free(g, robot, opened.waypoints_cells)


@pytest.mark.parametrize("name", ROBOTS)
def test_goal_beyond_the_border_reached_along_a_border_strip(name: str) -> None:
    """The goal lies beyond the grid's east border, projected onto it; a wall parallel to the border leaves
    free C-space only in the border column beside it (the projected goal is on that strip, as a goal
    behind a table next to the grid's edge). NF1 goes round the wall's end and up the strip; so must the
    tunnel planner, which needs a node on the border itself (rays there stop at the border, and the regular
    place a little past the wall's end is C-obstacle)."""
    robot = ROBOTS[name]
    radius = robot.inner_radius_m + TunnelParams().margin_m
    r2 = math.floor((radius / CELL_M - 0.5) ** 2 * (1.0 + 1e-9))  # free_cspace's blocked squared radius
    col = N - 1 - (math.isqrt(r2) + 1)  # the wall column whose C-obstacle stops one cell short of the border
    g = empty()
    g[to_cell(0, -3.0)[0] :, col] = OCCUPIED
    free = free_cspace(g, cell_m=CELL_M, inflate_m=radius)
    assert np.flatnonzero(free[N // 2, col:]).tolist() == [N - 1 - col]  # only the border column is free
    goal = goal_rc(30.0, 0.0)
    assert plan(free, to_cell(0, 0), goal, cell_m=CELL_M).ok
    res = tunnel_plan(g, to_cell(0, 0), goal, cell_m=CELL_M, radius_m=radius)
    assert res.ok and res.goal_projected and res.goal_cell == (N // 2, N - 1)
    assert tunnel_is_free(g, robot, res.waypoints_cells)
    assert res.waypoints_cells[-2][1] == N - 1  # the last tunnel runs up the strip


def unit_walk(mask: np.ndarray, r0: float, c0: float, dr: float, dc: float, t: float) -> tuple[float, bool]:
    """Reference ray: every sample t, t + 1, ... (rounded to its cell) until one leaves ``mask`` or the grid;
    the last sample inside, and whether the border stopped it."""
    last = t
    while True:
        r, c = math.floor(r0 + t * dr + 0.5), math.floor(c0 + t * dc + 0.5)
        if not (0 <= r < mask.shape[0] and 0 <= c < mask.shape[1]):
            return last, True
        if not mask[r, c]:
            return last, False
        last, t = t, t + 1.0


@pytest.mark.parametrize("seed", range(2))
def test_rays_stop_where_a_walk_over_every_sample_stops(seed: int) -> None:
    """Both rays of every direction (C-space, then on through the dilation band to the obstacle), also
    those that leave the grid, end on the sample a walk over every sample ends on."""
    g = clutter(seed, n_blocks=40)
    free = free_cspace(g, cell_m=CELL_M, inflate_m=0.4)
    clear = g != OCCUPIED
    sin_t, cos_t, offsets, exact = _rays(360, free.shape)
    assert 0 < exact.sum() <= 8  # the rays with sin or cos = +-1/2 walk with _march; the others by table
    state = _ray_state(free, clear)
    rng = np.random.default_rng(seed)
    cells = np.argwhere(free)
    for r0, c0 in cells[rng.integers(len(cells), size=6)]:
        got = _cast_rays(free, clear, state, int(r0), int(c0), sin_t, cos_t, offsets, exact)
        for k in range(360):
            t, border = unit_walk(free, float(r0), float(c0), sin_t[k], cos_t[k], 0.0)
            ray = (float(r0), float(c0), sin_t[k], cos_t[k])
            w, wborder = (t, True) if border else unit_walk(clear, *ray, t)
            assert (got[0][k], got[1][k], got[2][k], got[3][k]) == (t, border, w, wborder)


def office(seed: int) -> np.ndarray:
    """A random office floor: a lattice of 3 m rooms whose walls have 1 m doors, and furniture."""
    rng = np.random.default_rng(seed)
    g = empty()
    for k in range(30, N - 20, 60):
        for axis in range(2):
            line = np.full(N, OCCUPIED, np.uint8)
            for a in range(-30, N, 60):  # one door between each two crossing walls
                d = max(a + 3 + int(rng.integers(3, 34)), 0)
                line[d : d + 20] = FREE
            if axis == 0:
                g[k : k + 3, :] = np.maximum(g[k : k + 3, :], line)
            else:
                g[:, k : k + 3] = np.maximum(g[:, k : k + 3], line[:, None])
    for _ in range(12):
        r, c = rng.integers(5, N - 25, size=2)
        h, w = rng.integers(6, 20, size=2)
        g[r : r + h, c : c + w] = OCCUPIED
    return g


@pytest.mark.parametrize("name", ROBOTS)
def test_table_rays_give_the_same_searches_as_unit_walks(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Whole plans on random offices (goals 5 m away and beyond the border), searched once with the rays'
    offset tables and once with every ray walking by ``_march`` (all flagged exact): the same outcome, node
    count, node chain, tunnel and course, on searches long enough to matter."""
    radius = ROBOTS[name].inner_radius_m + TunnelParams().margin_m
    runs: dict[bool, list[tuple]] = {}
    for reference in (False, True):
        if reference:
            def all_exact(n_rays: int, shape: tuple[int, ...]) -> tuple:
                sin_t, cos_t, offsets, exact = tunnel._ray_table(n_rays, shape[1] + 2, 2)
                return sin_t, cos_t, offsets, np.ones_like(exact)
            monkeypatch.setattr(tunnel, "_rays", all_exact)
        out = runs.setdefault(reference, [])
        for seed in range(3):
            g = office(seed)
            free = free_cspace(g, cell_m=CELL_M, inflate_m=radius)
            rng = np.random.default_rng(seed)
            cells = np.argwhere(free[N // 4 : 3 * N // 4, N // 4 : 3 * N // 4]) + N // 4
            for r0, c0 in cells[rng.integers(len(cells), size=4)]:
                a = rng.uniform(-math.pi, math.pi)
                for dist in (100.0, 600.0):
                    goal = (r0 + 0.5 + dist * math.sin(a), c0 + 0.5 + dist * math.cos(a))
                    res = tunnel_plan(g, (int(r0), int(c0)), goal, cell_m=CELL_M, radius_m=radius)
                    out.append((res.flag, res.nodes_expanded, res.path_cells.tolist(),
                                res.waypoints_cells.tolist(), res.direction_rad if res.ok else None))
    assert runs[False] == runs[True]
    assert max(r[1] for r in runs[False]) > _CHECK_AFTER  # searches past the connectivity check too


def test_goal_in_obstacle_and_expansion_budget() -> None:
    g = empty()
    wall(g, 2.0, -6.0, 2.0, 6.0)  # a wall across the whole grid: the goal behind it is cut off
    p = planner(WHEELCHAIR_ROBOT)
    assert p.plan(g, to_cell(0, 0), goal_rc(2.0, 0.0)).flag == Flag.GOAL_IN_OBSTACLE
    g2 = empty()
    wall(g2, 1.5, -2.0, 1.5, 2.0)
    pure = TunnelPlanner(TunnelParams(max_expansions=1, complete=False), cell_m=CELL_M, inner_radius_m=0.35,
                         unknown_is_free=True).plan(g2, to_cell(0, 0), goal_rc(3.0, 0.0))
    assert pure.flag == Flag.PLANNER_TIMEOUT and pure.nodes_expanded == 1 and not pure.fallback
    # with the complete fallback the budget ends the node search, not the plan: NF1's path, flagged
    res = TunnelPlanner(TunnelParams(max_expansions=1), cell_m=CELL_M, inner_radius_m=0.35,
                        unknown_is_free=True).plan(g2, to_cell(0, 0), goal_rc(3.0, 0.0))
    assert res.ok and res.fallback and res.nodes_expanded == 1
    assert res.waypoints_cells[0].tolist() == list(to_cell(0, 0))
    assert res.waypoints_cells[-1].tolist() == list(to_cell(3.0, 0.0))
    free = free_cspace(g2, cell_m=CELL_M, inflate_m=0.35 + TunnelParams().margin_m)
    w = res.waypoints_cells.astype(int)
    assert all(_visible(free, *a, *b) for a, b in itertools.pairwise(w))
    full = planner(WHEELCHAIR_ROBOT).plan(g2, to_cell(0, 0), goal_rc(3.0, 0.0))
    assert full.ok and not full.fallback


def test_robot_in_c_obstacle_escapes_first() -> None:
    """The robot 0.2 m from a wall (closer than its half width): the chain starts with an escape segment."""
    g = empty()
    wall(g, -3.0, 0.2, 3.0, 0.2)
    res = planner(WHEELCHAIR_ROBOT).plan(g, to_cell(0, 0), goal_rc(3.0, -1.0))
    assert res.ok and res.n_escape == 1
    assert res.path_cells[0].tolist() == list(to_cell(0, 0))
    first = res.waypoints_cells[1] - res.waypoints_cells[0]
    assert first[0] < 0  # away from the wall (towards -y)
    assert np.hypot(*first) * CELL_M <= TunnelParams().escape_m + 1e-9


def test_goal_outside_the_grid_is_projected() -> None:
    res = planner(XR4000_ROBOT).plan(empty(), to_cell(0, 0), goal_rc(30.0, 0.0))
    assert res.ok and res.goal_projected and res.goal_cell == (N // 2, N - 1)
    assert abs(res.direction_rad) < 1e-9


@pytest.mark.parametrize("seed", range(8))
def test_tunnels_are_free_and_imply_an_nf1_path(seed: int) -> None:
    """Random clutter: every tunnel of a found chain is free in C-space, the chain runs from the robot to
    the goal, and then NF1 (complete on the same C-space) finds a path too."""
    rng = np.random.default_rng(seed)
    g = empty()
    for _ in range(25):
        x, y = rng.uniform(-5.5, 5.5, 2)
        w, h = rng.uniform(0.2, 2.0, 2)
        r0, c0 = to_cell(x, y)
        g[max(r0, 0) : r0 + round(h / CELL_M), max(c0, 0) : c0 + round(w / CELL_M)] = OCCUPIED
    robot = ROBOTS["wheelchair" if seed % 2 else "xr4000"]
    radius = robot.inner_radius_m + TunnelParams().margin_m
    free = free_cspace(g, cell_m=CELL_M, inflate_m=radius)
    cells = np.argwhere(free)
    for _ in range(5):
        s = tuple(cells[rng.integers(len(cells))])
        goal = cells[rng.integers(len(cells))] + 0.5
        res = tunnel_plan(g, s, goal, cell_m=CELL_M, radius_m=radius)
        nf1 = plan(free, s, goal, cell_m=CELL_M, params=Nf1Params())
        assert res.ok == nf1.ok  # complete: the node search, or else its fallback, finds what NF1 finds
        if res.ok:
            assert res.waypoints_cells[0].tolist() == list(s)
            assert res.waypoints_cells[-1].tolist() == np.floor(goal).tolist()
            assert tunnel_is_free(g, robot, res.waypoints_cells)
            assert res.length_m >= math.dist(s, np.floor(goal)) * CELL_M - 1e-9
        else:
            assert res.flag == Flag.PLANNER_NO_PATH


def test_params_are_validated() -> None:
    with pytest.raises(ValueError, match="spacing_m"):
        TunnelParams(spacing_m=0.0)
    with pytest.raises(ValueError, match="n_rays"):
        TunnelParams(n_rays=4)
    with pytest.raises(ValueError, match="grid_cells must be"):
        tunnel_plan(np.ones((5, 5), dtype=bool), (2, 2), (3.5, 3.5), cell_m=CELL_M, radius_m=0.3)
    with pytest.raises(ValueError, match="lookahead_m"):
        tunnel_plan(empty(), (2, 2), (3.5, 3.5), cell_m=CELL_M, radius_m=0.3, lookahead_m=0.0)
    assert dataclasses.replace(TunnelParams(), n_rays=720).n_rays == 720


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("angle_deg", [30, 45, 60])
@pytest.mark.parametrize("extra_m", [0.1, 0.15])
def test_oblique_passage_taken_whenever_nf1_goes_through(name: str, angle_deg: int, extra_m: float) -> None:
    """A passage in a wall at an angle to the cells: where the cells leave it open (NF1 on the same C-space
    goes through), the tunnel goes through it as well."""
    robot = ROBOTS[name]
    a = math.radians(angle_deg)
    ux, uy = -math.sin(a), math.cos(a)  # along the wall
    half = robot.inner_radius_m + extra_m / 2
    g = empty()
    wall(g, 1.5 + ux * half, uy * half, 1.5 + ux * 8, uy * 8)
    wall(g, 1.5 - ux * half, -uy * half, 1.5 - ux * 2.5, -uy * 2.5)
    goal = goal_rc(1.5 + 2 * math.cos(a), 2 * math.sin(a))

    def through(cells_rc: np.ndarray) -> bool:
        xy = (np.asarray(cells_rc, dtype=float) - N // 2) * CELL_M
        dense = np.concatenate([np.linspace(p, q, 20) for p, q in itertools.pairwise(xy)])
        return bool(np.min(np.hypot(dense[:, 1] - 1.5, dense[:, 0])) < 0.2)

    free = free_cspace(g, cell_m=CELL_M, inflate_m=robot.inner_radius_m + TunnelParams().margin_m)
    nf1 = plan(free, to_cell(0, 0), goal, cell_m=CELL_M)
    res = planner(robot).plan(g, to_cell(0, 0), goal)
    assert nf1.ok and res.ok
    assert tunnel_is_free(g, robot, res.waypoints_cells)
    if through(nf1.path_cells):
        assert through(res.waypoints_cells)


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("extra_m", [0.1, 0.15])
def test_robot_in_the_mouth_of_a_tight_passage_goes_through(name: str, extra_m: float) -> None:
    """The robot stands in front of a passage barely wider than it (a door of robot width + 0.1 or 0.15 m,
    whose C-space is a channel a few cells wide), up to 0.6 m before the wall and 3 cells off its axis,
    wherever its cell is free; the goal lies beyond, straight or 2 m aside. Seen from there the door's edges
    span more than 90 deg, no straight tunnel from the robot threads the waist off its axis, and the robot
    took the space of the node in front of the passage: the course still points through (within 60 deg of
    the axis), never back out to line up (the stall of wheelchair_office_exit, Fig. 5). The course is the
    bearing of the point 1 m along the tunnel, so a one-cell step onto the axis does not turn it sideways."""
    robot = ROBOTS[name]
    g = empty()
    wall_with_passage(g, 1.5, -6.0, 6.0, 0.0, 2 * robot.inner_radius_m + extra_m)
    free = free_cspace(g, cell_m=CELL_M, inflate_m=robot.inner_radius_m + TunnelParams().margin_m)
    p = planner(robot)
    n_plans = 0
    for gy, d, dy in itertools.product((-2.0, 0.0, 2.0), np.arange(0.1, 0.65, 0.05), range(-3, 4)):
        r, c = to_cell(1.5 - d, 0.0)
        start = (r + dy, c)
        if not free[start]:
            continue
        p.reset()  # each start is a situation of its own, not the next tick of the last one
        res = p.plan(g, start, goal_rc(4.0, gy))
        n_plans += 1
        assert res.ok, (d, dy, gy)
        assert math.cos(res.direction_rad) > 0.5, (d, dy, gy, math.degrees(res.direction_rad))
        assert tunnel_is_free(g, robot, res.waypoints_cells)
        assert len(crossing_y(res.waypoints_cells, 1.5)) == 1
    assert n_plans >= 100


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("apart_m", [0.9, 1.0, 1.1])
def test_two_one_cell_waists_in_a_row_reach_the_goal(name: str, apart_m: float) -> None:
    """Two parallel walls ``apart_m`` apart, each with a door whose C-space is a one-cell waist, the second
    door 0.3 m aside of the first (the synthetic offices of ``benchmarks/planner.py`` have such pairs): no
    tunnel node lands between the walls where a straight tunnel threads both waists, and the paper's node
    search runs out of nodes (PLANNER_NO_PATH, a wrong answer: NF1 on the same C-space goes through). With
    ``complete`` the plan is NF1's path on the tunnel planner's C-space, flagged, made of free tunnels
    through both doors."""
    robot = ROBOTS[name]
    radius = robot.inner_radius_m + TunnelParams().margin_m
    g = empty()
    gap = 0
    for gap in range(8, 40):  # the door width (edge cell centres apart, in cells) of a one-cell waist
        wall_with_passage(g, 1.5, -6.0, 6.0, 0.0, gap * CELL_M)
        if np.count_nonzero(free_cspace(g, cell_m=CELL_M, inflate_m=radius)[:, to_cell(1.5, 0)[1]]) == 1:
            break
        g = empty()
    wall_with_passage(g, 1.5 + apart_m, -6.0, 6.0, 0.3, gap * CELL_M)
    free = free_cspace(g, cell_m=CELL_M, inflate_m=radius)
    for x in (1.5, 1.5 + apart_m):
        assert np.count_nonzero(free[:, to_cell(x, 0)[1]]) == 1
    start, goal = to_cell(0, 0), goal_rc(1.5 + apart_m + 1.5, 0.3)
    assert plan(free, start, goal, cell_m=CELL_M).ok
    pure = tunnel_plan(g, start, goal, cell_m=CELL_M, radius_m=radius, params=TunnelParams(complete=False))
    assert not pure.ok and pure.flag == Flag.PLANNER_NO_PATH and not pure.fallback  # the search is incomplete
    res = tunnel_plan(g, start, goal, cell_m=CELL_M, radius_m=radius)
    assert res.ok and res.fallback and res.nodes_expanded == pure.nodes_expanded
    assert res.waypoints_cells[0].tolist() == list(start)
    assert res.waypoints_cells[-1].tolist() == list(to_cell(1.5 + apart_m + 1.5, 0.3))
    assert tunnel_is_free(g, robot, res.waypoints_cells)
    for x in (1.5, 1.5 + apart_m):
        assert len(crossing_y(res.waypoints_cells, x)) == 1
    assert res.width_m == pytest.approx(2 * radius) and math.cos(res.direction_rad) > 0.5


@pytest.mark.parametrize("name", ROBOTS)
def test_held_tunnel_kept_until_another_is_clearly_shorter(name: str) -> None:
    """A wall across the way, its two ends nearly as far: the planner holds the tunnel round the end it chose
    (hold_route) while the other way becomes slightly shorter (the planner without the hold flips), and
    leaves it when the other way is clearly shorter; a held tunnel is always made of free tunnels and
    starts at the robot."""
    robot = ROBOTS[name]
    held = planner(robot)
    fresh = TunnelPlanner(TunnelParams(hold_route=False), cell_m=CELL_M, inner_radius_m=robot.inner_radius_m,
                          unknown_is_free=True)
    start, goal = to_cell(0, 0), goal_rc(3.0, 0.0)
    courses = []
    for below in (1.0, 0.8, 0.0):  # the wall's end below the robot's line comes nearer; above: 0.95 m
        g = empty()
        wall(g, 1.5, -below, 1.5, 0.95)
        res, new = held.plan(g, start, goal), fresh.plan(g, start, goal)
        assert res.ok and new.ok and not res.fallback
        assert res.waypoints_cells[0].tolist() == list(start)
        assert tunnel_is_free(g, robot, res.waypoints_cells)
        courses.append((math.sin(res.direction_rad) > 0, math.sin(new.direction_rad) > 0))
    assert courses == [(True, True), (True, False), (False, False)]
    grids = []
    for below in (1.0, 0.8):
        grids.append(empty())
        wall(grids[-1], 1.5, -below, 1.5, 0.95)
    assert math.sin(held.plan(grids[0], start, goal).direction_rad) > 0
    held.reset()
    assert math.sin(held.plan(grids[1], start, goal).direction_rad) < 0  # forgotten: planned afresh
