"""C-space: exact distance transform, disc inflation, doors, unknown handling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage as ndi

from gndreplay.pipeline.cspace import CSpaceTracker, free_cspace, obstacle_distance_m, squared_distance_cells
from gndreplay.pipeline.model import FREE, OCCUPIED, UNKNOWN, GridParams, RobotCentredGrid, shift_cells
from gndreplay.types import Pose2D, Scan


def brute_force_distance(occupied: np.ndarray, cell_m: float) -> np.ndarray:
    """Distance from every cell centre to every occupied cell centre, minimum; inf without obstacles."""
    obs = np.argwhere(occupied).astype(np.float64)
    allc = np.argwhere(np.ones_like(occupied)).astype(np.float64)
    if obs.shape[0] == 0:
        return np.full(occupied.shape, np.inf)
    d2 = ((allc[:, None, :] - obs[None, :, :]) ** 2).sum(axis=2).min(axis=1)
    return (np.sqrt(d2) * cell_m).reshape(occupied.shape)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (13, 17), (31, 24)])
@pytest.mark.parametrize("density", [0.0, 0.01, 0.1, 0.6, 1.0])
def test_distance_matches_brute_force(shape: tuple[int, int], density: float) -> None:
    rng = np.random.default_rng(hash((shape, density)) % 2**32)
    occupied = rng.random(shape) < density
    d = obstacle_distance_m(occupied, cell_m=0.05)
    assert d.dtype == np.float32 and d.shape == shape
    np.testing.assert_allclose(d, brute_force_distance(occupied, 0.05), rtol=1e-6)


def test_distance_matches_scipy_on_a_large_grid() -> None:
    rng = np.random.default_rng(7)
    occupied = rng.random((200, 230)) < 0.003
    expected = ndi.distance_transform_edt(~occupied)
    np.testing.assert_allclose(np.sqrt(squared_distance_cells(occupied)), expected, rtol=1e-12)


def test_single_obstacle_distances() -> None:
    occupied = np.zeros((5, 5), dtype=bool)
    occupied[0, 0] = True
    d = obstacle_distance_m(occupied, cell_m=0.1)
    assert d[0, 0] == 0.0
    assert d[0, 3] == pytest.approx(0.3)
    assert d[4, 3] == pytest.approx(0.5)
    assert np.isinf(obstacle_distance_m(np.zeros((3, 4), dtype=bool), cell_m=0.1)).all()


def door_grid(door_m: float, *, cell_m: float = 0.05) -> np.ndarray:
    """A 4 x 4 m free room split by a one-cell wall along row 40 with a door of ``door_m`` in it."""
    n = 80
    cells = np.full((n, n), FREE, dtype=np.uint8)
    cells[40, :] = OCCUPIED
    gap = round(door_m / cell_m)  # free cells between the jambs
    start = (n - gap) // 2
    cells[40, start : start + gap] = FREE
    return cells


def passable(free: np.ndarray) -> bool:
    """True when a free C-space cell below the wall connects (8-neighbours) to one above it."""
    labels, _ = ndi.label(free, structure=np.ones((3, 3)))
    below = set(np.unique(labels[5])) - {0}
    above = set(np.unique(labels[-5])) - {0}
    return bool(below & above)


def test_door_of_90_cm_passes_a_wheelchair_half_width_and_blocks_a_wider_disc() -> None:
    cells = door_grid(0.9)
    assert passable(free_cspace(cells, cell_m=0.05, inflate_m=0.35 + 0.05))
    assert passable(free_cspace(cells, cell_m=0.05, inflate_m=0.35))
    assert not passable(free_cspace(cells, cell_m=0.05, inflate_m=0.5))
    # the wall itself is never free, and free space keeps its distance from the wall: blocked within
    # 0.4 - 0.025 m = 7.5 cells of the wall's centre row 40
    free = free_cspace(cells, cell_m=0.05, inflate_m=0.4)
    assert not free[33:48, :10].any()
    assert free[32, :10].all() and free[48, :10].all()
    assert not passable(free_cspace(door_grid(0.7), cell_m=0.05, inflate_m=0.4))


def test_free_cspace_agrees_with_thresholded_distance() -> None:
    rng = np.random.default_rng(3)
    cells = rng.choice([UNKNOWN, FREE, OCCUPIED], size=(60, 70), p=[0.2, 0.78, 0.02]).astype(np.uint8)
    for inflate in [0.0, 0.05, 0.1, 0.2, 0.35, 0.45, 1.0]:
        for unknown_is_free in [True, False]:
            obstacle = (cells == OCCUPIED) | (~np.bool_(unknown_is_free) & (cells == UNKNOWN))
            d = brute_force_distance(obstacle, 0.05)
            # sub-cell rule: half a cell of the robot's freedom in its cell; exactly at it counts as blocked
            expected = d > max(inflate - 0.025, 0.0) + 1e-9
            got = free_cspace(cells, cell_m=0.05, inflate_m=inflate, unknown_is_free=unknown_is_free)
            np.testing.assert_array_equal(got, expected)


def test_unknown_handling() -> None:
    # a known free pocket of 21 x 21 cells in unknown space, no obstacle at all
    cells = np.full((41, 41), UNKNOWN, dtype=np.uint8)
    cells[10:31, 10:31] = FREE
    assert free_cspace(cells, cell_m=0.05, inflate_m=0.2).all()
    free = free_cspace(cells, cell_m=0.05, inflate_m=0.2, unknown_is_free=False)
    # unknown is an obstacle: only cells more than 3.5 cells (0.2 m - half a cell) from any unknown cell
    expected = np.zeros_like(free)
    expected[13:28, 13:28] = True
    np.testing.assert_array_equal(free, expected)


def test_empty_grids() -> None:
    assert free_cspace(np.zeros((0, 5), dtype=np.uint8), cell_m=0.05, inflate_m=0.3).shape == (0, 5)
    assert obstacle_distance_m(np.zeros((4, 0), dtype=bool), cell_m=0.05).shape == (4, 0)


def test_argument_errors_name_the_argument() -> None:
    with pytest.raises(ValueError, match="grid_cells must be 2-D"):
        free_cspace(np.zeros(5, dtype=np.uint8), cell_m=0.05, inflate_m=0.3)
    with pytest.raises(ValueError, match="inflate_m"):
        free_cspace(np.zeros((5, 5), dtype=np.uint8), cell_m=0.05, inflate_m=-0.1)
    with pytest.raises(ValueError, match="cell_m"):
        obstacle_distance_m(np.zeros((5, 5), dtype=bool), cell_m=0.0)
    with pytest.raises(ValueError, match="obstacle must be a bool array"):
        squared_distance_cells(np.zeros((5, 5), dtype=np.uint8))


def rasterised_door(door_m: float, angle_rad: float, offset: tuple[float, float], *, n: int = 80,
                    cell_m: float = 0.05, wall_m: float = 0.1) -> np.ndarray:
    """An n x n grid whose OCCUPIED cells hold a point of the surface of a wall 0.1 m thick with a door of
    ``door_m`` at the grid centre (shifted by ``offset`` [m], turned by ``angle_rad``): what head-on
    laser hits mark. The wall runs past the grid's edges, so the door is the only way across."""
    pieces = []
    for side in (-1.0, 1.0):
        xs = np.arange(door_m / 2.0, 2.0 * n * cell_m, 0.002) * side
        ys = np.arange(-wall_m / 2.0, wall_m / 2.0, 0.002)
        pieces += [np.column_stack([xs, np.full_like(xs, -wall_m / 2.0)]),
                   np.column_stack([xs, np.full_like(xs, wall_m / 2.0)]),
                   np.column_stack([np.full_like(ys, side * door_m / 2.0), ys])]
    pts = np.vstack(pieces)
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    world = pts @ np.array([[c, s], [-s, c]]) + (n * cell_m / 2.0 + np.asarray(offset))
    rc = np.floor(world[:, ::-1] / cell_m).astype(np.int64)
    rc = rc[((rc >= 0) & (rc < n)).all(axis=1)]
    cells = np.full((n, n), FREE, dtype=np.uint8)
    cells[rc[:, 0], rc[:, 1]] = OCCUPIED
    return cells


def crosses_door(free: np.ndarray, angle_rad: float) -> bool:
    """True when the free C-space cells 1 m before and 1 m behind the door (along its normal) connect."""
    labels, _ = ndi.label(free, structure=np.ones((3, 3)))
    centre = np.array(free.shape) / 2.0
    normal = np.array([np.cos(angle_rad), -np.sin(angle_rad)]) * 20.0  # (row, col), 20 cells = 1 m
    a, b = (centre + normal).astype(int), (centre - normal).astype(int)
    return bool(labels[a[0], a[1]] != 0 and labels[a[0], a[1]] == labels[b[0], b[1]])


PLACEMENTS = [(dx, dy, a) for dx in (0.0, 0.013, 0.026, 0.049) for dy in (0.0, 0.021, 0.037)
              for a in (0.0, 0.1, 0.39, 0.7854, 1.2, 1.5708)]


@pytest.mark.parametrize(("half_width_m", "margin_m"), [(0.35, 0.05), (0.3, 0.05)], ids=["chair", "xr4000"])
def test_door_of_robot_width_plus_margins_is_open_at_any_offset_and_rotation(
    half_width_m: float, margin_m: float
) -> None:
    """Issue 10: a door 0.05 m wider than the robot's width plus twice the margin stays open (0.85 m for
    the 0.7 m chair), one 0.05 m narrower than that is closed (0.75 m), wherever the grid lines fall."""
    need = 2.0 * (half_width_m + margin_m)
    for dx, dy, angle in PLACEMENTS:
        wide = rasterised_door(need + 0.05, angle, (dx, dy))
        narrow = rasterised_door(need - 0.05, angle, (dx, dy))
        inflate = half_width_m + margin_m
        assert crosses_door(free_cspace(wide, cell_m=0.05, inflate_m=inflate), angle), (dx, dy, angle)
        assert not crosses_door(free_cspace(narrow, cell_m=0.05, inflate_m=inflate), angle), (dx, dy, angle)


def test_obstacle_cells_are_never_free() -> None:
    cells = np.full((9, 9), FREE, dtype=np.uint8)
    cells[4, 4] = OCCUPIED
    free = free_cspace(cells, cell_m=0.05, inflate_m=0.0)
    assert not free[4, 4] and free.sum() == 80
    free = free_cspace(cells, cell_m=0.05, inflate_m=0.02)  # below half a cell: only the cell itself
    assert not free[4, 4] and free.sum() == 80


def scanned_door(door_m: float, angle_rad: float, offset: tuple[float, float]) -> tuple[np.ndarray, tuple]:
    """The grid a 361-beam laser (1 cm noise) builds approaching a door in a 0.1 m wall (turned by
    ``angle_rad``, centred at ``offset``) from 1.8 to 0.6 m in front of it, weaving sideways; and the cells
    1 m before and 1 m beyond the door."""
    from test_model import raycast  # the ray caster of the model tests

    c, s = np.cos(angle_rad), np.sin(angle_rad)
    along, normal, centre = np.array([c, s]), np.array([-s, c]), np.asarray(offset)
    segs = []
    for side in (-1.0, 1.0):
        x0, x1 = side * door_m / 2.0, side * 6.0
        for (ax, ay), (bx, by) in (((x0, -0.05), (x1, -0.05)), ((x0, 0.05), (x1, 0.05)),
                                   ((x0, -0.05), (x0, 0.05))):
            segs.append([*(centre + ax * along + ay * normal), *(centre + bx * along + by * normal)])
    walls = np.asarray(segs)
    grid = RobotCentredGrid(GridParams(80, 0.05, control_zone_m=4.0), centre_xy=offset)
    beams = np.linspace(-np.pi / 2, np.pi / 2, 361)
    heading = float(np.arctan2(normal[1], normal[0]))
    for k, d in enumerate(np.linspace(-1.8, -0.6, 7)):
        pos = centre + d * normal + 0.15 * np.sin(k) * along
        ranges = raycast((pos[0], pos[1]), beams + heading, walls)
        ranges = ranges + np.random.default_rng(k).normal(0.0, 0.01, ranges.shape)
        grid.integrate(Scan(k, ranges, beams, 30.0), Pose2D(float(pos[0]), float(pos[1]), heading))
    ends = grid.world_to_cell(np.array([centre - normal, centre + normal]))
    return grid.cells, (tuple(ends[0]), tuple(ends[1]))


@pytest.mark.parametrize("angle", [0.0, 0.3, 0.7854, 1.96, 2.6])
def test_a_scanned_85_cm_door_is_open_for_the_chair_and_a_75_cm_one_closed(angle: float) -> None:
    """The same through the model: hits with noise, grazing rays along the jambs, several scans."""
    for door_m, expected in ((0.85, True), (0.75, False)):
        cells, (a, b) = scanned_door(door_m, angle, (0.013, 0.031))
        free = free_cspace(cells, cell_m=0.05, inflate_m=0.35 + 0.05)
        labels, _ = ndi.label(free, structure=np.ones((3, 3)))
        assert bool(labels[a] != 0 and labels[a] == labels[b]) is expected, door_m


@pytest.mark.parametrize("seed", range(3))
def test_free_cspace_is_the_threshold_of_the_exact_distance_on_random_grids(seed: int) -> None:
    """The disc sweep against the exact transform's threshold (dx^2 + dy^2 <= r2 blocked, r2 the floor of
    the squared effective radius in cells): grids of 1 to 120 cells a side (radii taller than the grid
    among them), every obstacle density, both unknown modes: the same mask, cell for cell."""
    rng = np.random.default_rng(seed)
    for _ in range(40):
        shape = (int(rng.integers(1, 121)), int(rng.integers(1, 121)))
        p = rng.dirichlet([1, 3, 0.5])
        cells = rng.choice([UNKNOWN, FREE, OCCUPIED], size=shape, p=p).astype(np.uint8)
        for inflate in (0.0, 0.03, 0.1, 0.375, 0.425, 1.3, 4.0):
            r2 = np.floor(max(inflate / 0.05 - 0.5, 0.0) ** 2 * (1.0 + 1e-9))
            for unknown_is_free in (True, False):
                obstacle = (cells == OCCUPIED) | (~np.bool_(unknown_is_free) & (cells == UNKNOWN))
                expected = squared_distance_cells(obstacle) > r2
                got = free_cspace(cells, cell_m=0.05, inflate_m=inflate, unknown_is_free=unknown_is_free)
                np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("unknown_is_free", [True, False])
@pytest.mark.parametrize("seed", range(4))
def test_tracker_follows_a_moving_changing_grid_bit_for_bit(seed: int, unknown_is_free: bool) -> None:
    """CSpaceTracker equals free_cspace on every tick of a grid that moves by whole cells (small steps,
    jumps beyond its side, none) while cells change state, for radii from none to wider than the grid, on
    shapes whose byte count is and is not a multiple of eight."""
    rng = np.random.default_rng(seed)
    codes = np.array([UNKNOWN, FREE, OCCUPIED], np.uint8)
    for n_r, n_c, inflate in ((40, 48, 0.4), (23, 37, 0.0), (31, 17, 0.73), (12, 9, 1.2)):
        tracker = CSpaceTracker(cell_m=0.05, inflate_m=inflate, unknown_is_free=unknown_is_free)
        cells = rng.choice(codes, size=(n_r, n_c), p=[0.3, 0.6, 0.1])
        offset = (int(rng.integers(-1000, 1000)), int(rng.integers(-1000, 1000)))
        for _ in range(40):
            move = rng.random()
            if move < 0.3:
                d = (int(rng.integers(-n_r // 3, n_r // 3 + 1)), int(rng.integers(-n_c // 3, n_c // 3 + 1)))
            elif move < 0.35:
                d = (int(rng.integers(n_r, 2 * n_r)), -int(rng.integers(0, n_c)))
            else:
                d = (0, 0)
            cells = shift_cells(cells, *d)
            offset = (offset[0] + d[0], offset[1] + d[1])
            changed = rng.integers(0, cells.size, size=int(rng.integers(0, 25)))
            cells.flat[changed] = rng.choice(codes, size=changed.size)
            expected = free_cspace(cells, cell_m=0.05, inflate_m=inflate, unknown_is_free=unknown_is_free)
            np.testing.assert_array_equal(tracker.free(cells, offset), expected)


def test_tracker_refuses_what_free_cspace_refuses() -> None:
    with pytest.raises(ValueError, match="cell_m"):
        CSpaceTracker(cell_m=0.0, inflate_m=0.3)
    with pytest.raises(ValueError, match="inflate_m"):
        CSpaceTracker(cell_m=0.05, inflate_m=-1.0)
    with pytest.raises(ValueError, match="grid_cells"):
        CSpaceTracker(cell_m=0.05, inflate_m=0.3).free(np.zeros(5, np.uint8), (0, 0))
