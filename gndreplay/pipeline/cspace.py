"""C-space from the robot-centred grid: obstacle distance transform and the free configuration space.

The robot is reduced to a disc about its rotation centre (circle: its radius; rectangle: half its width, so
a 0.7 m wheelchair plans through a 0.85 m door with a 0.05 m margin; the reactor and the supervisor's swept
footprint check handle the full shape) plus a margin.

Sub-cell clearance (the rule of ``free_cspace``): an OCCUPIED cell stands for a laser hit somewhere inside
it, and its centre is the unbiased estimate of that hit; the planner picks cells, but the robot stands
anywhere in its cell (the reactor steers in continuous space). A cell is therefore free when a robot
centred up to half a cell from the cell centre clears every obstacle centre by the radius R:
``d_centre + cell/2 > R``. Measured on doors rasterised as every cell holding a point of the jambs' surfaces
(tests/test_cspace.py, 150 random sub-cell offsets and rotations): a door of 2R + 0.05 m is open in all of
them, one of 2R - 0.05 m in none, for both presets (R = 0.40 and 0.35 m), whereas the centre-only rule
``d_centre > R`` closes the 0.85 m door for the 0.7 m chair in 92 % of the placements, and rules with
``R + half a cell diagonal`` (obstacle cells as whole squares) close it always: a 0.05 m slack per door is one
cell, less than the two cells of quantisation such a rule adds.

The exact Euclidean distance transform is Felzenszwalb & Huttenlocher's two-pass algorithm (column sweeps,
then the lower envelope of parabolas per row) compiled with numba. ``free_cspace`` needs only a threshold of
it, which the exact integer disc sweep ``_free_of_disc`` computes with the same result, faster: medians on
400 x 400 grids of 782 to 4522 occupied cells (benchmarks/model.py, a shared 2-core machine) 0.44 to
0.71 ms for the sweep, 0.86 to 6.9 ms for the numba transform and threshold, 9.3 to 19.7 ms for
``scipy.ndimage.distance_transform_edt`` and threshold. The sweep reads the grid codes itself (no obstacle
mask pass) and keeps column distances in int16: 0.39-0.46 ms instead of 0.61-0.64 ms (thread CPU time,
best of 20) on the 400 x 400 synthetic offices of benchmarks/planner.py, the same masks.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .model import OCCUPIED, UNKNOWN

__all__ = ["free_cspace", "obstacle_distance_m", "squared_distance_cells"]


@njit(cache=True)
def _sq_edt(obstacle: NDArray[np.bool_]) -> NDArray[np.float64]:
    """(R, C) bool -> (R, C) squared distance [cells^2] from each cell to the nearest True cell (inf if
    there is none)."""
    n_r, n_c = obstacle.shape
    inf = np.inf
    g = np.empty((n_r, n_c), np.float64)  # 1-D distance along each column
    for c in range(n_c):
        g[0, c] = 0.0 if obstacle[0, c] else inf
    for r in range(1, n_r):
        for c in range(n_c):
            g[r, c] = 0.0 if obstacle[r, c] else g[r - 1, c] + 1.0
    for r in range(n_r - 2, -1, -1):
        for c in range(n_c):
            d = g[r + 1, c] + 1.0
            if d < g[r, c]:
                g[r, c] = d
    out = np.empty((n_r, n_c), np.float64)
    v = np.empty(n_c, np.int64)  # sites (columns) of the lower envelope
    fv = np.empty(n_c, np.float64)  # their squared column distances
    z = np.empty(n_c + 1, np.float64)  # boundaries between envelope parabolas
    for r in range(n_r):
        k = -1
        for q in range(n_c):
            gq = g[r, q]
            if gq == inf:  # no obstacle in this column: not a site
                continue
            fq = gq * gq
            if k < 0:
                k = 0
                v[0], fv[0], z[0], z[1] = q, fq, -inf, inf
                continue
            while True:
                p = v[k]
                s = ((fq + q * q) - (fv[k] + p * p)) / (2.0 * (q - p))
                if s <= z[k]:
                    k -= 1  # z[0] = -inf, so k stays >= 0
                else:
                    break
            k += 1
            v[k], fv[k], z[k], z[k + 1] = q, fq, s, inf
        if k < 0:
            out[r, :] = inf
            continue
        j = 0
        for x in range(n_c):
            while z[j + 1] < x:
                j += 1
            dx = x - v[j]
            out[r, x] = dx * dx + fv[j]
    return out


@njit(cache=True)
def _free_of_disc(
    cells: NDArray[np.uint8], occupied: np.uint8, unknown: np.uint8, unknown_is_free: bool,
    half_width: NDArray[np.int64],
) -> NDArray[np.bool_]:
    """(R, C) grid codes -> (R, C) bool free mask: False where an obstacle cell (``occupied``, and ``unknown``
    unless ``unknown_is_free``) lies within the disc.

    ``half_width[k]`` (k = 0 .. K - 1) is the largest |dx| [cells] with dx^2 + k^2 <= r2, K - 1 the largest
    k with k^2 <= r2 (or R - 1, when smaller: no obstacle of a column is farther), K < 2^15, and
    ``half_width[K]`` a sentinel below -(C + 1). Column sweeps give each cell's vertical distance to the
    nearest obstacle in its column, capped at K (int16: half the memory traffic of int32); each such
    obstacle blocks the run of +-half_width cells around its column in that row, and two running extrema
    per row (left to right, right to left, over the row's half widths looked up once) find the cells
    covered by any run. Exact, O(R * C), integer arithmetic, branch-free."""
    n_r, n_c = cells.shape
    cap = half_width.shape[0] - 1
    g = np.empty((n_r, n_c), np.int16)
    for c in range(n_c):
        v = cells[0, c]
        ob = v == occupied or (not unknown_is_free and v == unknown)
        g[0, c] = 0 if ob else cap
    for r in range(1, n_r):
        for c in range(n_c):
            v = cells[r, c]
            ob = (v == occupied) | ((not unknown_is_free) & (v == unknown))
            g[r, c] = min(g[r - 1, c] + 1, cap) * (1 - np.int16(ob))
    for r in range(n_r - 2, -1, -1):
        for c in range(n_c):
            g[r, c] = min(g[r + 1, c] + 1, g[r, c])
    free = np.empty((n_r, n_c), np.bool_)
    hw = np.empty(n_c, np.int64)
    for r in range(n_r):
        for x in range(n_c):
            hw[x] = half_width[g[r, x]]
        reach = -1  # max over columns c <= x of c + half_width
        for x in range(n_c):
            reach = max(reach, x + hw[x])
            free[r, x] = reach < x
        reach = n_c  # min over columns c >= x of c - half_width
        for x in range(n_c - 1, -1, -1):
            reach = min(reach, x - hw[x])
            free[r, x] = free[r, x] & (reach > x)
    return free


def _check_2d(a: NDArray[np.generic], name: str) -> None:
    if a.ndim != 2:
        raise ValueError(f"{name} must be 2-D, got shape {a.shape}")


def squared_distance_cells(obstacle: NDArray[np.bool_]) -> NDArray[np.float64]:
    """(R, C) bool mask -> (R, C) float64 exact squared Euclidean distance [cells^2] from each cell centre
    to the nearest True cell centre; +inf everywhere when the mask has no True cell."""
    _check_2d(obstacle, "obstacle")
    if obstacle.dtype != np.bool_:
        raise ValueError(f"obstacle must be a bool array, got dtype {obstacle.dtype}")
    if obstacle.size == 0:
        return np.zeros(obstacle.shape, dtype=np.float64)
    return _sq_edt(np.ascontiguousarray(obstacle))


def obstacle_distance_m(occupied: NDArray[np.bool_], *, cell_m: float) -> NDArray[np.float32]:
    """(R, C) bool occupied mask -> (R, C) float32 distance [m] from each cell centre to the nearest
    occupied cell centre (0 on occupied cells, +inf when nothing is occupied)."""
    if not cell_m > 0.0:
        raise ValueError(f"cell_m must be > 0, got {cell_m!r}")
    return (np.sqrt(squared_distance_cells(occupied)) * cell_m).astype(np.float32)


def free_cspace(
    grid_cells: NDArray[np.uint8], *, cell_m: float, inflate_m: float, unknown_is_free: bool = True
) -> NDArray[np.bool_]:
    """(R, C) grid of UNKNOWN / FREE / OCCUPIED -> (R, C) bool, True where a disc of radius ``inflate_m``
    fits with its centre up to half a cell from the cell centre: every obstacle cell centre is strictly
    farther than ``max(inflate_m - cell_m / 2, 0)`` from the cell centre (the sub-cell rule of the module
    docstring; obstacle cells themselves are never free).

    Obstacles are OCCUPIED cells, plus UNKNOWN cells when ``unknown_is_free`` is False (**choice**: by
    default unknown space is free for planning, the environment is discovered as the robot goes). A
    distance exactly equal to ``inflate_m`` counts as blocked (robust to float rounding of the radius)."""
    _check_2d(grid_cells, "grid_cells")
    if not cell_m > 0.0:
        raise ValueError(f"cell_m must be > 0, got {cell_m!r}")
    if not inflate_m >= 0.0:
        raise ValueError(f"inflate_m must be >= 0, got {inflate_m!r}")
    if grid_cells.size == 0:
        return np.zeros(grid_cells.shape, dtype=np.bool_)
    # blocked iff dx^2 + dy^2 <= r2 (integers), r2 = floor of the squared effective radius in cells
    r_cells = max(inflate_m / cell_m - 0.5, 0.0)
    r2 = math.floor(r_cells * r_cells * (1.0 + 1e-9))
    n_k = min(math.isqrt(r2) + 1, grid_cells.shape[0])  # rows farther than the grid's height never count
    half_width = np.array(
        [*(math.isqrt(r2 - k * k) for k in range(n_k)), -(grid_cells.shape[1] + 2)], dtype=np.int64
    )
    if n_k >= np.iinfo(np.int16).max:
        raise ValueError(f"inflate_m {inflate_m!r} spans {n_k} cells, more than {np.iinfo(np.int16).max - 1}")
    cells = np.ascontiguousarray(grid_cells)
    return _free_of_disc(cells, OCCUPIED, UNKNOWN, bool(unknown_is_free), half_width)
