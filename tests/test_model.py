"""Model builder: Bresenham tracing, no-return / invalid beams, laser offset, re-centring, views."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gndreplay.errors import ConfigError
from gndreplay.pipeline.model import (
    DROPOUT_MAX_BEAMS,
    FREE,
    GRID_200,
    GRID_400,
    OCCUPIED,
    UNKNOWN,
    GridParams,
    RobotCentredGrid,
    shift_cells,
)
from gndreplay.types import Pose2D, Scan

AT_AXLE = Pose2D(0.0, 0.0, 0.0)
SMALL = GridParams(size_cells=40, cell_m=0.1)  # 4 x 4 m, control zone 1 m


def make_scan(
    ranges: list[float] | np.ndarray,
    angles: list[float] | np.ndarray,
    *,
    max_range_m: float = 30.0,
    min_range_m: float = 0.0,
    sensor_pose: Pose2D = AT_AXLE,
) -> Scan:
    return Scan(
        t_ns=0,
        ranges_m=np.asarray(ranges, dtype=np.float64),
        angles_rad=np.asarray(angles, dtype=np.float64),
        max_range_m=max_range_m,
        min_range_m=min_range_m,
        sensor_pose=sensor_pose,
    )


def bresenham_ref(c0: int, r0: int, c1: int, r1: int) -> list[tuple[int, int]]:
    """Plain-Python Bresenham returning (row, col) cells from start to end inclusive."""
    out = []
    dc, dr = abs(c1 - c0), -abs(r1 - r0)
    sc, sr = (1 if c0 < c1 else -1), (1 if r0 < r1 else -1)
    err = dc + dr
    while True:
        out.append((r0, c0))
        if (c0, r0) == (c1, r1):
            return out
        e2 = 2 * err
        if e2 >= dr:
            err, c0 = err + dr, c0 + sc
        if e2 <= dc:
            err, r0 = err + dc, r0 + sr


def cells_with(grid: RobotCentredGrid, value: np.uint8) -> set[tuple[int, int]]:
    return {(int(r), int(c)) for r, c in zip(*np.nonzero(grid.cells == value), strict=True)}


# ---- tracing ------------------------------------------------------------------------------------


def test_axis_beam_marks_free_cells_and_the_hit() -> None:
    grid = RobotCentredGrid(SMALL)
    pose = Pose2D(0.05, 0.05, 0.0)  # centre of cell (20, 20)
    assert grid.robot_cell(pose) == (20, 20)
    stats = grid.integrate(make_scan([1.0], [0.0]), pose)  # hit at x = 1.05 -> column 30
    assert (stats.beams_traced, stats.hits, stats.shifted_cells) == (1, 1, (0, 0))
    assert cells_with(grid, FREE) == {(20, c) for c in range(20, 30)}
    assert cells_with(grid, OCCUPIED) == {(20, 30)}
    assert int((grid.cells == UNKNOWN).sum()) == 40 * 40 - 11


@pytest.mark.parametrize("angle", [0.3, 1.0, 2.2, -0.7, -2.9, math.pi / 4])
def test_oblique_beam_follows_bresenham(angle: float) -> None:
    grid = RobotCentredGrid(SMALL)
    pose = Pose2D(0.05, 0.05, 0.0)
    r = 1.5
    grid.integrate(make_scan([r], [angle]), pose)
    end = grid.world_to_cell([[0.05 + r * math.cos(angle), 0.05 + r * math.sin(angle)]])[0]
    line = bresenham_ref(20, 20, int(end[1]), int(end[0]))
    assert cells_with(grid, FREE) == set(line[:-1])
    assert cells_with(grid, OCCUPIED) == {line[-1]}


def test_laser_offset_and_heading_are_honoured() -> None:
    # robot facing +y, laser 0.7 m ahead of the axle: a beam straight ahead starts at y = +0.7
    grid = RobotCentredGrid(SMALL)
    pose = Pose2D(0.05, 0.05, math.pi / 2)
    scan = make_scan([0.5], [0.0], sensor_pose=Pose2D(0.7, 0.0, 0.0))
    grid.integrate(scan, pose)
    assert cells_with(grid, FREE) == {(r, 20) for r in range(27, 32)}
    assert cells_with(grid, OCCUPIED) == {(32, 20)}
    assert grid.cells[20, 20] == UNKNOWN  # the axle cell is not on the ray


def test_no_return_clears_up_to_clip_and_adds_no_obstacle() -> None:
    params = GridParams(size_cells=100, cell_m=0.1, free_clip_m=2.0)
    grid = RobotCentredGrid(params)
    pose = Pose2D(0.05, 0.05, 0.0)  # cell (50, 50)
    stats = grid.integrate(make_scan([np.inf, 40.0], [0.0, math.pi / 2], max_range_m=30.0), pose)
    assert stats.hits == 0 and stats.beams_traced == 2
    assert not (grid.cells == OCCUPIED).any()
    # clears to min(max_range, free_clip) = 2 m: x = 2.05 -> column 70, end cell included
    assert cells_with(grid, FREE) == {(50, c) for c in range(50, 71)} | {(r, 50) for r in range(51, 71)}
    # max range shorter than the clip
    grid = RobotCentredGrid(params)
    grid.integrate(make_scan([np.inf], [0.0], max_range_m=1.0), pose)
    assert cells_with(grid, FREE) == {(50, c) for c in range(50, 61)}


def test_invalid_beams_do_nothing_by_default_and_clear_on_request() -> None:
    scan = make_scan([np.nan, 0.01, -np.inf], [0.0, 1.0, 2.0], min_range_m=0.05)
    grid = RobotCentredGrid(SMALL)
    stats = grid.integrate(scan, Pose2D(0.05, 0.05, 0.0))
    assert stats.beams_traced == 0 and (grid.cells == UNKNOWN).all()
    grid = RobotCentredGrid(GridParams(size_cells=40, cell_m=0.1, free_clip_m=1.0, invalid_clears=True))
    stats = grid.integrate(scan, Pose2D(0.05, 0.05, 0.0))
    assert stats.beams_traced == 3 and stats.hits == 0
    assert not (grid.cells == OCCUPIED).any()
    assert {(20, c) for c in range(20, 31)} <= cells_with(grid, FREE)


def test_hit_is_not_erased_by_another_ray_of_the_same_scan() -> None:
    # two beams on the same bearing: the longer one passes through the shorter one's hit
    grid = RobotCentredGrid(SMALL)
    grid.integrate(make_scan([0.5, 1.0], [0.0, 0.0]), Pose2D(0.05, 0.05, 0.0))
    assert cells_with(grid, OCCUPIED) == {(20, 25), (20, 30)}
    # ... and in the other order
    grid = RobotCentredGrid(SMALL)
    grid.integrate(make_scan([1.0, 0.5], [0.0, 0.0]), Pose2D(0.05, 0.05, 0.0))
    assert cells_with(grid, OCCUPIED) == {(20, 25), (20, 30)}


def test_new_scan_overwrites_what_it_covers() -> None:
    # a person at 0.5 m walks away: the next scan sees the wall at 1 m and clears the old hit
    grid = RobotCentredGrid(SMALL)
    pose = Pose2D(0.05, 0.05, 0.0)
    grid.integrate(make_scan([0.5], [0.0]), pose)
    assert grid.cells[20, 25] == OCCUPIED
    grid.integrate(make_scan([1.0], [0.0]), pose)
    assert grid.cells[20, 25] == FREE and grid.cells[20, 30] == OCCUPIED


def test_rays_are_clipped_at_the_border() -> None:
    grid = RobotCentredGrid(SMALL)
    pose = Pose2D(0.05, 0.05, 0.0)
    stats = grid.integrate(make_scan([25.0, 25.0], [0.0, 0.6]), pose)  # hits far outside the 4 m grid
    assert stats.hits == 0 and stats.beams_traced == 2
    assert not (grid.cells == OCCUPIED).any()
    assert cells_with(grid, FREE) >= {(20, c) for c in range(20, 40)}
    # a hit exactly in the last column is kept
    grid = RobotCentredGrid(SMALL)
    assert grid.integrate(make_scan([1.9], [0.0]), pose).hits == 1  # x = 1.95
    assert grid.cells[20, 39] == OCCUPIED


def test_laser_outside_the_grid_is_clipped_at_entry() -> None:
    # a (silly) 3 m laser offset puts the sensor outside the 4 m grid, looking back at the robot
    grid = RobotCentredGrid(SMALL)
    scan = make_scan([2.0, 0.5], [0.0, 0.0], sensor_pose=Pose2D(3.0, 0.0, math.pi))
    stats = grid.integrate(scan, Pose2D(0.05, 0.05, 0.0))  # laser at x = 3.05, beams towards -x
    assert (stats.beams_traced, stats.hits) == (1, 1)  # the 0.5 m beam never enters the grid
    assert cells_with(grid, FREE) == {(20, c) for c in range(31, 40)}
    assert cells_with(grid, OCCUPIED) == {(20, 30)}


def test_finite_range_at_max_range_is_a_no_return() -> None:
    grid = RobotCentredGrid(SMALL)
    grid.integrate(make_scan([8.0], [0.0], max_range_m=8.0), Pose2D(0.05, 0.05, 0.0))
    assert not (grid.cells == OCCUPIED).any()


def test_mismatched_scan_shapes_raise() -> None:
    """The kernels index ranges and angles by beam without bounds checks: a Scan refuses to exist with
    different lengths."""
    with pytest.raises(ValueError, match="ranges of shape"):
        make_scan([1.0, 2.0], [0.0])


# ---- re-centring --------------------------------------------------------------------------------


def test_shift_cells_moves_contents_and_fills_unknown() -> None:
    rng = np.random.default_rng(1)
    a = rng.integers(1, 3, size=(6, 7)).astype(np.uint8)
    for d_row in range(-7, 8):
        for d_col in range(-8, 9):
            out = shift_cells(a, d_row, d_col)
            for r in range(6):
                for c in range(7):
                    sr, sc = r + d_row, c + d_col
                    expected = a[sr, sc] if 0 <= sr < 6 and 0 <= sc < 7 else UNKNOWN
                    assert out[r, c] == expected


def test_shift_keeps_every_cells_world_position() -> None:
    rng = np.random.default_rng(2)
    grid = RobotCentredGrid(SMALL, centre_xy=(0.05, 0.05))
    grid.cells[:] = rng.integers(1, 3, size=grid.cells.shape).astype(np.uint8)
    before = grid.cells.copy()
    rc = np.argwhere(np.ones_like(before, dtype=bool))
    world_before = grid.cells_to_world(rc)
    # leave the 1 m control zone diagonally (and not by a whole number of cells)
    pose = Pose2D(0.05 + 0.83, 0.05 - 1.27, 0.4)
    stats = grid.integrate(make_scan([], []), pose)
    d_row, d_col = stats.shifted_cells
    assert (d_row, d_col) == (-13, 8)
    assert grid.robot_cell(pose) == (20, 20)
    new_rc = rc - np.array([d_row, d_col])
    inside = grid.contains(new_rc)
    # same world position, bit for bit, and same content
    np.testing.assert_array_equal(grid.cells_to_world(new_rc[inside]), world_before[inside])
    np.testing.assert_array_equal(
        grid.cells[new_rc[inside, 0], new_rc[inside, 1]], before[rc[inside, 0], rc[inside, 1]]
    )
    np.testing.assert_array_equal(grid.world_to_cell(world_before[inside]), new_rc[inside])
    assert int((grid.cells == UNKNOWN).sum()) == 40 * 40 - int(inside.sum())


def test_no_shift_inside_the_control_zone() -> None:
    grid = RobotCentredGrid(SMALL)  # centre cell (20, 20) spans [0, 0.1); zone side 1 m around x = y = 0
    for x, y in [(0.49, 0.0), (-0.5, 0.5), (0.3, -0.45)]:
        assert grid.integrate(make_scan([], []), Pose2D(x, y, 0.0)).shifted_cells == (0, 0)
    assert grid.integrate(make_scan([], []), Pose2D(0.52, 0.0, 0.0)).shifted_cells == (0, 5)
    assert grid.robot_cell(Pose2D(0.52, 0.0, 0.0)) == (20, 20)


def test_far_jump_gives_an_unknown_grid() -> None:
    grid = RobotCentredGrid(SMALL)
    grid.integrate(make_scan([1.0], [0.0]), Pose2D(0.0, 0.0, 0.0))
    stats = grid.integrate(make_scan([], []), Pose2D(100.0, -50.0, 0.0))
    assert stats.shifted_cells == (-500, 1000)
    assert (grid.cells == UNKNOWN).all()


def test_grid_origin_is_on_the_world_lattice() -> None:
    grid = RobotCentredGrid(GRID_200, centre_xy=(1.234, -0.07))
    assert grid.offset_cells == (-2 - 100, 24 - 100)
    assert grid.origin_xy == pytest.approx((-76 * 0.05, -102 * 0.05))
    assert grid.robot_cell(Pose2D(1.234, -0.07, 0.0)) == (100, 100)
    f = grid.world_to_cell_float([[1.234, -0.07]])[0]
    assert f == pytest.approx([100 + (-0.07 / 0.05 + 2), 100 + (1.234 / 0.05 - 24)])
    np.testing.assert_allclose(grid.cells_to_world(np.floor(f)[None, :]), grid.cells_to_world([[100, 100]]))


# ---- views --------------------------------------------------------------------------------------


def test_occupied_points_in_robot_frame() -> None:
    grid = RobotCentredGrid(SMALL)
    grid.cells[20, 30] = OCCUPIED  # centre (1.05, 0.05)
    grid.cells[25, 20] = OCCUPIED  # centre (0.05, 0.55)
    grid.cells[20, 39] = OCCUPIED  # centre (1.95, 0.05): outside a 1.5 m radius
    pose = Pose2D(0.05, 0.05, math.pi / 2)  # facing +y
    pts = grid.occupied_points(pose, 1.5)
    # robot frame: +x = world +y, +y = world -x
    expected = {(0.0, -1.0), (0.5, 0.0)}
    assert {(round(float(x), 9) + 0.0, round(float(y), 9) + 0.0) for x, y in pts} == expected
    assert grid.occupied_points(pose, 0.3).shape == (0, 2)


@pytest.mark.parametrize("seed", range(3))
def test_cell_views_select_every_cell_of_their_rule_within_the_radius(seed: int) -> None:
    """Each view returns exactly the cells its rule names within the radius (row-major, robot frame), also
    where the radius crosses the grid's edge: checked against the rule applied to the whole grid."""
    rng = np.random.default_rng(seed)
    grid = RobotCentredGrid(SMALL)
    n = SMALL.size_cells
    grid.cells[:] = rng.choice(np.array([UNKNOWN, FREE, OCCUPIED], np.uint8), size=(n, n), p=[0.3, 0.5, 0.2])
    grid.seen_ns[:] = rng.integers(0, 100, size=(n, n))
    for pose in (Pose2D(0.3, -0.2, 0.7), Pose2D(0.9, 0.95, -2.5)):  # the second near a corner
        rows, cols = np.mgrid[0:n, 0:n]
        world = grid.cells_to_world(np.column_stack([rows.ravel(), cols.ravel()]))
        d = world - [pose.x, pose.y]
        ct, st = math.cos(pose.theta), math.sin(pose.theta)
        local = np.column_stack([ct * d[:, 0] + st * d[:, 1], -st * d[:, 0] + ct * d[:, 1]])
        inside = np.hypot(d[:, 0], d[:, 1]) <= 0.6
        free = grid.cells == FREE
        beside = np.zeros_like(free)
        beside[1:] |= free[:-1]
        beside[:-1] |= free[1:]
        beside[:, 1:] |= free[:, :-1]
        beside[:, :-1] |= free[:, 1:]
        rules = {
            "occupied": grid.cells == OCCUPIED,
            "unseen": (grid.cells != OCCUPIED) & (grid.seen_ns < 40),
            "border": ~free & beside,
        }
        views = {
            "occupied": grid.occupied_points(pose, 0.6),
            "unseen": grid.unseen_points(pose, 0.6, 40),
            "border": grid.free_border_points(pose, 0.6),
        }
        for name, rule in rules.items():
            want = rule.ravel() & inside
            assert views[name].shape == (int(want.sum()), 2), name
            np.testing.assert_allclose(views[name], local[want], atol=1e-12, err_msg=name)
        _, seen = grid.occupied_points_seen(pose, 0.6)
        np.testing.assert_array_equal(seen, grid.seen_ns.ravel()[(grid.cells == OCCUPIED).ravel() & inside])


def test_presets_and_validation() -> None:
    assert (GRID_400.size_cells, GRID_400.cell_m, GRID_400.side_m) == (400, 0.05, 20.0)
    assert (GRID_200.size_cells, GRID_200.cell_m) == (200, 0.05)
    assert GRID_400.control_zone_side_m == 5.0
    assert GridParams(control_zone_m=2.0).control_zone_side_m == 2.0
    with pytest.raises(ConfigError, match=r"grid\.cell_m"):
        GridParams(cell_m=0.0)
    with pytest.raises(ConfigError, match=r"grid\.size_cells"):
        GridParams(size_cells=2)
    with pytest.raises(ConfigError, match=r"grid\.control_zone_m"):
        GridParams(size_cells=100, cell_m=0.05, control_zone_m=6.0)
    with pytest.raises(ConfigError, match=r"grid\.free_clip_m"):
        GridParams(free_clip_m=-1.0)


# ---- dropouts and grazing rays ------------------------------------------------------------------


def raycast(origin: tuple[float, float], angles: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """(N,) ranges from ``origin`` along ``angles`` to the nearest of the (S, 4) segments, inf if none."""
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)[:, None, :]
    p, e = segs[None, :, :2], (segs[:, 2:] - segs[:, :2])[None]
    w = p - np.asarray(origin)
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
    hit = (den != 0) & (t > 0) & (u >= 0) & (u <= 1)
    return np.where(hit, t, np.inf).min(axis=1)


GRID_5CM = GridParams(size_cells=200, cell_m=0.05, control_zone_m=10.0)  # 10 x 10 m, never re-centred
BEAMS = np.linspace(-math.pi / 2, math.pi / 2, 361)  # 0.5 deg


def scan_of(pose: Pose2D, segs: np.ndarray, beams: np.ndarray = BEAMS) -> Scan:
    return make_scan(raycast((pose.x, pose.y), beams + pose.theta, segs), beams, max_range_m=30.0)


def test_isolated_dropouts_do_not_clear_through_a_wall() -> None:
    wall = np.array([[2.013, -5.0, 2.013, 5.0]])  # seen head-on, in the cells of x in [2.0, 2.05)
    pose = Pose2D(0.01, 0.02, 0.0)
    scan = scan_of(pose, wall)
    ranges = scan.ranges_m.copy()
    ranges[[60, 150, 151, 240, 242, 300, 301]] = np.inf  # single and double dropouts
    grid = RobotCentredGrid(GRID_5CM)
    grid.integrate(make_scan(ranges, BEAMS, max_range_m=30.0), pose)
    x_cells = grid.cells_to_world(np.argwhere(grid.cells == FREE))[:, 0]
    assert x_cells.size and x_cells.max() < 2.05  # no cell wholly behind the wall is cleared
    # the dropouts' own bearings still clear up to the wall (at x = 1.8 m, before it)
    for k in (60, 150, 240, 300):
        near = grid.world_to_cell([[1.8, 0.02 + 1.8 * math.tan(BEAMS[k])]])[0]
        assert grid.cells[near[0], near[1]] == FREE


def test_a_real_opening_still_clears() -> None:
    # the same wall with a 1 m gap: 12+ consecutive no-returns, the space behind the gap is seen free
    walls = np.array([[2.0, -5.0, 2.0, -0.5], [2.0, 0.5, 2.0, 5.0]])
    pose = Pose2D(0.01, 0.02, 0.0)
    grid = RobotCentredGrid(GRID_5CM)
    scan = scan_of(pose, walls)
    assert int(np.isinf(scan.ranges_m).sum()) > DROPOUT_MAX_BEAMS
    grid.integrate(scan, pose)
    assert grid.cells[grid.world_to_cell([[4.0, 0.0]])[0, 0], grid.world_to_cell([[4.0, 0.0]])[0, 1]] == FREE
    # ... and so does a run one beam longer than a dropout
    wall = np.array([[2.0, -5.0, 2.0, 5.0]])
    ranges = scan_of(pose, wall).ranges_m.copy()
    ranges[180 : 181 + DROPOUT_MAX_BEAMS] = np.inf
    grid = RobotCentredGrid(GRID_5CM)
    grid.integrate(make_scan(ranges, BEAMS, max_range_m=30.0), pose)
    behind = grid.world_to_cell([[3.0, 0.02]])[0]
    assert grid.cells[behind[0], behind[1]] == FREE


@pytest.mark.parametrize("wall_y", [0.6, 0.612, 0.637])  # the surface at 0, 1/4 and 3/4 of a cell
def test_grazing_rays_do_not_erase_a_wall_seen_head_on(wall_y: float) -> None:
    # a corridor wall, seen head-on while driving beside it, then along it from its end
    walls = np.array([[-5.0, wall_y, 5.0, wall_y], [4.5, -5.0, 4.5, 5.0]])
    grid = RobotCentredGrid(GRID_5CM)
    for x in np.arange(-1.5, 3.01, 0.25):
        pose = Pose2D(float(x), 0.013, math.pi / 2)
        grid.integrate(scan_of(pose, walls, np.linspace(-0.5, 0.5, 121)), pose)
    wall_cells = np.argwhere(grid.cells == OCCUPIED)
    wall_cells = wall_cells[np.abs(grid.cells_to_world(wall_cells)[:, 0] - 0.75) < 2.0]  # x in [-1.25, 2.75]
    assert len(wall_cells) >= 80
    for x in np.arange(-2.0, -0.99, 0.1):  # driving along the corridor, 0.25 to 0.6 m from the wall
        pose = Pose2D(float(x), 0.35 - 0.2 * (x + 2.0), 0.02 * (x + 2.0))
        grid.integrate(scan_of(pose, walls), pose)
    kept = grid.cells[wall_cells[:, 0], wall_cells[:, 1]] == OCCUPIED
    assert kept.mean() >= 0.95, kept.mean()
    # the wall still has no hole a robot could notice: no two consecutive columns without an obstacle
    cols = np.unique(wall_cells[kept, 1])
    assert np.diff(cols).max() <= 1, np.diff(cols).max()


def test_an_obstacle_that_left_is_still_cleared_by_rays_through_it() -> None:
    # a person 1.5 m ahead, seen by a fan of beams, walks away; the wall at 3 m is then seen through
    person = np.array([[1.5, -0.2, 1.5, 0.2]])
    wall = np.array([[3.0, -5.0, 3.0, 5.0]])
    pose = Pose2D(0.01, 0.02, 0.0)
    grid = RobotCentredGrid(GRID_5CM)
    grid.integrate(scan_of(pose, np.vstack([person, wall])), pose)
    person_cells = grid.world_to_cell([[1.5 + 0.001, y] for y in np.linspace(-0.15, 0.15, 7)])
    assert (grid.cells[person_cells[:, 0], person_cells[:, 1]] == OCCUPIED).all()
    grid.integrate(scan_of(pose, wall), pose)
    assert (grid.cells[person_cells[:, 0], person_cells[:, 1]] == FREE).all()


@pytest.mark.parametrize("n", [1, 7, 9, 40, 401])
def test_grid_digest_counts_changed_cells_and_tells_grids_apart(n: int) -> None:
    """grid_digest's count is the number of differing cells, for any size (a tail shorter than a word
    included); its digest changes when any one cell changes and is a function of the cells alone."""
    from gndreplay.pipeline.model import digest_keys, grid_digest

    rng = np.random.default_rng(n)
    keys = digest_keys(n * n)
    a = rng.integers(0, 3, size=(n, n)).astype(np.uint8)
    b = a.copy()
    flip = rng.choice(n * n, size=min(5, n * n), replace=False)
    b.reshape(-1)[flip] = (b.reshape(-1)[flip] + 1) % 3
    count, digest_b = grid_digest(b, a, keys)
    assert int(count) == int(np.count_nonzero(a != b))
    assert grid_digest(a, b, keys)[1] == grid_digest(a, a.copy(), keys)[1] != digest_b
    for k in range(n * n):  # every single-cell change moves the digest
        c = a.copy()
        c.reshape(-1)[k] = (c.reshape(-1)[k] + 1) % 3
        assert grid_digest(c, a, keys)[0] == 1 and grid_digest(c, a, keys)[1] != grid_digest(a, a, keys)[1]
        if k > 50:
            break
