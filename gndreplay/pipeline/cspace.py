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
from typing import TypeAlias

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .model import OCCUPIED, UNKNOWN

__all__ = ["CSpaceTracker", "free_cspace", "obstacle_distance_m", "squared_distance_cells"]


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


def _disc_r2(cell_m: float, inflate_m: float) -> int:
    """Squared disc radius [cells^2] of ``free_cspace``'s rule: a cell is blocked iff an obstacle cell lies
    at dx^2 + dy^2 <= r2 (integers), r2 the floor of the squared effective radius in cells."""
    r_cells = max(inflate_m / cell_m - 0.5, 0.0)
    return math.floor(r_cells * r_cells * (1.0 + 1e-9))


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
    r2 = _disc_r2(cell_m, inflate_m)
    n_k = min(math.isqrt(r2) + 1, grid_cells.shape[0])  # rows farther than the grid's height never count
    half_width = np.array(
        [*(math.isqrt(r2 - k * k) for k in range(n_k)), -(grid_cells.shape[1] + 2)], dtype=np.int64
    )
    if n_k >= np.iinfo(np.int16).max:
        raise ValueError(f"inflate_m {inflate_m!r} spans {n_k} cells, more than {np.iinfo(np.int16).max - 1}")
    cells = np.ascontiguousarray(grid_cells)
    return _free_of_disc(cells, OCCUPIED, UNKNOWN, bool(unknown_is_free), half_width)


@njit(cache=True, inline="always")
def _is_obstacle(v: np.uint8, occupied: np.uint8, unknown: np.uint8, unknown_is_free: bool) -> bool:
    """The grid code ``v`` blocks the disc: OCCUPIED, or UNKNOWN unless unknown space is free."""
    return v == occupied or (not unknown_is_free and v == unknown)


@njit(cache=True)
def _count_discs(
    cells: NDArray[np.uint8], occupied: np.uint8, unknown: np.uint8, unknown_is_free: bool,
    half_width: NDArray[np.int64], counts: NDArray[np.int16],
) -> None:
    """Fill ``counts`` (R + 2P, C + 2P), P = len(half_width) - 1: for each cell of the padded frame, the
    number of obstacle cells of ``cells`` within its disc. Row by row: a prefix sum of the obstacle row gives
    each disc row's window count in O(1) (O((R + 2P) (C + 2P) (2P + 1)) in all)."""
    n_r, n_c = cells.shape
    pad = half_width.shape[0] - 1
    counts[:, :] = 0
    prefix = np.empty(n_c + 1, np.int64)
    for r in range(n_r):
        prefix[0] = 0
        for c in range(n_c):
            ob = _is_obstacle(cells[r, c], occupied, unknown, unknown_is_free)
            prefix[c + 1] = prefix[c] + (1 if ob else 0)
        if prefix[n_c] == 0:
            continue
        for dy in range(-pad, pad + 1):
            h = half_width[abs(dy)]
            row = r + pad + dy
            for j in range(n_c + 2 * pad):
                lo = max(j - pad - h, 0)
                hi = min(j - pad + h, n_c - 1)
                if lo <= hi:
                    counts[row, j] += prefix[hi + 1] - prefix[lo]


@njit(cache=True)
def _add_disc(counts: NDArray[np.int16], free: NDArray[np.bool_], r: int, c: int,
              half_width: NDArray[np.int64], delta: int) -> None:
    """Add ``delta`` over the disc about grid cell (r, c) in the padded frame of ``counts``, and keep
    ``free`` (grid frame: counts 0) in step over the disc's grid cells."""
    pad = half_width.shape[0] - 1
    n_r, n_c = free.shape
    for dy in range(-pad, pad + 1):
        h = half_width[abs(dy)]
        row = r + pad + dy
        inside = 0 <= r + dy < n_r
        for j in range(c + pad - h, c + pad + h + 1):
            n = counts[row, j] + delta
            counts[row, j] = n
            if inside and pad <= j < n_c + pad:
                free[r + dy, j - pad] = n == 0


@njit(cache=True)
def _update_discs(
    cells: NDArray[np.uint8], occupied: np.uint8, unknown: np.uint8, unknown_is_free: bool,
    half_width: NDArray[np.int64], d_row: int, d_col: int,
    counts: NDArray[np.int16], prev: NDArray[np.uint8], free: NDArray[np.bool_],
    counts_out: NDArray[np.int16], prev_out: NDArray[np.uint8], free_out: NDArray[np.bool_],
) -> None:
    """One tick of ``CSpaceTracker`` after the grid moved its origin by (d_row, d_col) cells (|d| < its
    side; new cell (r, c) is old cell (r + d_row, c + d_col)) and its contents changed from ``prev``.
    Obstacles that left the grid leave the old ``counts``; the counts move into ``counts_out`` (cells new
    to the padded frame are farther than the disc from every remaining obstacle: 0) and ``free_out`` is
    read off them; then each cell whose obstacle state differs from the moved ``prev`` adds or removes its
    disc, keeping ``free_out`` in step; ``prev_out`` becomes ``cells``."""
    n_r, n_c = cells.shape
    pad = half_width.shape[0] - 1
    for r in range(n_r):
        row_gone = r - d_row < 0 or r - d_row >= n_r
        for c in range(n_c):
            if _is_obstacle(prev[r, c], occupied, unknown, unknown_is_free) and (
                    row_gone or c - d_col < 0 or c - d_col >= n_c):
                _add_disc(counts, free, r, c, half_width, -1)
    h_r, h_c = n_r + 2 * pad, n_c + 2 * pad
    for i in range(h_r):
        src_i = i + d_row
        for j in range(h_c):
            src_j = j + d_col
            inside = 0 <= src_i < h_r and 0 <= src_j < h_c
            counts_out[i, j] = counts[src_i, src_j] if inside else 0
    for r in range(n_r):
        for c in range(n_c):
            free_out[r, c] = counts_out[r + pad, c + pad] == 0
    for r in range(n_r):
        src_r = r + d_row
        for c in range(n_c):
            v = cells[r, c]
            ob = _is_obstacle(v, occupied, unknown, unknown_is_free)
            src_c = c + d_col
            was = False
            if 0 <= src_r < n_r and 0 <= src_c < n_c:
                was = _is_obstacle(prev[src_r, src_c], occupied, unknown, unknown_is_free)
            if ob != was:
                _add_disc(counts_out, free_out, r, c, half_width, 1 if ob else -1)
            prev_out[r, c] = v


@njit(cache=True)
def _changed_discs(
    cells: NDArray[np.uint8], cells_words: NDArray[np.uint64], occupied: np.uint8, unknown: np.uint8,
    unknown_is_free: bool, half_width: NDArray[np.int64],
    counts: NDArray[np.int16], prev: NDArray[np.uint8], prev_words: NDArray[np.uint64],
    free: NDArray[np.bool_],
) -> None:
    """One tick of ``CSpaceTracker`` on a grid that did not move: the cells that differ from ``prev`` (found
    eight at a time through the uint64 views ``*_words`` of the same bytes) add or remove their disc where
    their obstacle state changed, in place; ``prev`` becomes ``cells``."""
    n_c = cells.shape[1]
    flat, prev_flat = cells.ravel(), prev.ravel()
    for w in range(cells_words.shape[0]):
        if cells_words[w] == prev_words[w]:
            continue
        for k in range(w * 8, min(w * 8 + 8, flat.shape[0])):
            v, old = flat[k], prev_flat[k]
            if v == old:
                continue
            ob = _is_obstacle(v, occupied, unknown, unknown_is_free)
            was = _is_obstacle(old, occupied, unknown, unknown_is_free)
            if ob != was:
                _add_disc(counts, free, k // n_c, k % n_c, half_width, 1 if ob else -1)
            prev_flat[k] = v


_I16: TypeAlias = NDArray[np.int16]
_U8: TypeAlias = NDArray[np.uint8]
_Bool: TypeAlias = NDArray[np.bool_]


class CSpaceTracker:
    """``free_cspace`` of one grid followed from tick to tick: the robot-centred grid moves by whole cells
    and a scan changes few of its cells, so the tracker keeps, for every cell of the grid padded by the disc
    radius, how many obstacle cells lie within its disc, and updates only the discs of the cells whose
    obstacle state changed (and of the obstacles that left the grid). The result is ``free_cspace``'s, bit
    for bit (tests/test_cspace.py); a first call, a new shape or a jump of a whole grid side counts afresh.

    Args: as ``free_cspace``'s. Discs wider than ``MAX_PAD`` cells are computed afresh every call (their
    counts would overflow int16 and their disc updates cost more than the sweep).
    """

    MAX_PAD = 64

    def __init__(self, *, cell_m: float, inflate_m: float, unknown_is_free: bool = True) -> None:
        if not cell_m > 0.0:
            raise ValueError(f"cell_m must be > 0, got {cell_m!r}")
        if not inflate_m >= 0.0:
            raise ValueError(f"inflate_m must be >= 0, got {inflate_m!r}")
        self.cell_m, self.inflate_m, self.unknown_is_free = cell_m, inflate_m, bool(unknown_is_free)
        r2 = _disc_r2(cell_m, inflate_m)
        pad = math.isqrt(r2)
        self._half_width = np.array([math.isqrt(r2 - k * k) for k in range(pad + 1)], dtype=np.int64)
        # (counts, the last grid's codes padded to whole uint64 words, free, offset) of the last call, and
        # the arrays a move writes into
        self._state: tuple[_I16, _U8, _Bool, tuple[int, int]] | None = None
        self._spare: tuple[_I16, _U8, _Bool] | None = None

    def free(self, grid_cells: NDArray[np.uint8], offset_rc: tuple[int, int]) -> NDArray[np.bool_]:
        """(R, C) grid codes whose cell (0, 0) is world cell ``offset_rc`` -> (R, C) bool free C-space. The
        array is the tracker's own, valid (and not to be written) until its next call."""
        _check_2d(grid_cells, "grid_cells")
        pad = self._half_width.shape[0] - 1
        n_r, n_c = grid_cells.shape
        if pad > self.MAX_PAD or grid_cells.size == 0:
            return free_cspace(grid_cells, cell_m=self.cell_m, inflate_m=self.inflate_m,
                               unknown_is_free=self.unknown_is_free)
        cells = np.ascontiguousarray(grid_cells)
        state = self._state
        shape = (n_r + 2 * pad, n_c + 2 * pad)
        d_row = d_col = 0
        if state is not None:
            d_row, d_col = offset_rc[0] - state[3][0], offset_rc[1] - state[3][1]
        if state is None or state[0].shape != shape or abs(d_row) >= n_r or abs(d_col) >= n_c:
            counts = np.empty(shape, np.int16)
            _count_discs(cells, OCCUPIED, UNKNOWN, self.unknown_is_free, self._half_width, counts)
            free = counts[pad : pad + n_r, pad : pad + n_c] == 0
            prev = np.zeros(_words(cells.size) * 8, np.uint8)
            prev[: cells.size] = cells.ravel()
            self._state, self._spare = (counts, prev, free, offset_rc), None
            return free
        counts, prev, free, _ = state
        if d_row == 0 and d_col == 0:
            flat = cells.reshape(-1)
            if flat.size != prev.size or flat.ctypes.data % 8:
                flat = np.zeros_like(prev)
                flat[: cells.size] = cells.ravel()
            _changed_discs(cells, flat.view(np.uint64), OCCUPIED, UNKNOWN, self.unknown_is_free,
                           self._half_width, counts, prev[: cells.size].reshape(n_r, n_c),
                           prev.view(np.uint64), free)
            return free
        out = self._spare if self._spare is not None else (
            np.empty_like(counts), np.zeros_like(prev), np.empty_like(free))
        self._spare = (counts, prev, free)
        _update_discs(cells, OCCUPIED, UNKNOWN, self.unknown_is_free, self._half_width, d_row, d_col,
                      counts, prev[: cells.size].reshape(n_r, n_c), free,
                      out[0], out[1][: cells.size].reshape(n_r, n_c), out[2])
        self._state = (*out, offset_rc)
        return out[2]


def _words(n: int) -> int:
    """uint64 words holding n bytes."""
    return (n + 7) // 8
