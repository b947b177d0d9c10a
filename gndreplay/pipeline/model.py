"""Model builder: the robot-centred ternary occupancy grid of GND and of the wheelchair paper.

The grid is square, world-aligned (never rotated) and follows the robot's position in whole cells. Each scan
is traced with Bresenham from the laser pose: the cells on the way become FREE, the hit cell OCCUPIED, so
every new scan overwrites what it covers and people who walked away disappear (GND Fig. 2) - except where
a ray only grazes an occupied cell or is a dropout between returns (``RobotCentredGrid.integrate``). When
the robot leaves the central control zone the whole array is shifted by an integer number of cells in one
slice copy (new cells UNKNOWN), so no cell is ever resampled. Beside the state, each cell keeps the stamp of
the last scan that saw it (``seen_ns``): behind a front laser a FREE cell is only as good as its age.

Frames and indices: ``cells[row, col]`` with row along world y and col along world x. The grid sits on a
world lattice of pitch ``cell_m``: local cell (row, col) is world lattice cell
(``offset_cells[0] + row``, ``offset_cells[1] + col``) and covers
``[(offset + index) * cell_m, (offset + index + 1) * cell_m)`` on each axis. The offset is an integer,
so a shift preserves every cell's world position exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from ..errors import ConfigError
from ..types import Pose2D, Scan

__all__ = [
    "CLEAR_CORE_CELLS",
    "DROPOUT_MAX_BEAMS",
    "FREE",
    "GRID_200",
    "GRID_400",
    "NEVER_SEEN",
    "OCCUPIED",
    "PROTECT_MAX_CELLS",
    "UNKNOWN",
    "GridParams",
    "IntegrateStats",
    "RobotCentredGrid",
    "shift_cells",
]

UNKNOWN = np.uint8(0)
_T = TypeVar("_T", bound=np.generic)
FREE = np.uint8(1)
OCCUPIED = np.uint8(2)
NEVER_SEEN = np.iinfo(np.int64).min
"""``RobotCentredGrid.seen_ns`` of a cell no scan has traced."""


@dataclass(frozen=True, slots=True)
class GridParams:
    """Size and update rules of the robot-centred grid.

    Attributes:
        size_cells: N, the grid is N x N cells.
        cell_m: cell side [m].
        control_zone_m: side of the central square the robot may move in before the grid is re-centred
            [m]; None means N * cell_m / 4 (**choice**, the papers give no value).
        free_clip_m: a no-return beam clears free space up to min(max_range_m, free_clip_m) [m]
            (**choice**: 8 m; a no-return says nothing certain about far space).
        invalid_clears: whether an invalid (nan) beam also clears free space like a no-return.
            **Choice**, default False: an invalid beam may be a reading below the minimum range, i.e. an
            obstacle touching the sensor, so clearing along it could erase a real obstacle. Logs that
            encode no-return as NaN should be mapped to +inf by their reader, or set this to True.
    """

    size_cells: int = 400
    cell_m: float = 0.05
    control_zone_m: float | None = None
    free_clip_m: float = 8.0
    invalid_clears: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.size_cells, int) or self.size_cells < 4:
            raise ConfigError(f"grid.size_cells must be an int >= 4, got {self.size_cells!r}")
        if not self.cell_m > 0.0:
            raise ConfigError(f"grid.cell_m must be > 0, got {self.cell_m!r}")
        side = self.size_cells * self.cell_m
        if self.control_zone_m is not None and not 0.0 <= self.control_zone_m <= side:
            raise ConfigError(
                f"grid.control_zone_m must be in [0, {side:g}] (the grid side), got {self.control_zone_m!r}"
            )
        if not self.free_clip_m >= 0.0:
            raise ConfigError(f"grid.free_clip_m must be >= 0, got {self.free_clip_m!r}")

    @property
    def side_m(self) -> float:
        """Side of the grid [m]."""
        return self.size_cells * self.cell_m

    @property
    def control_zone_side_m(self) -> float:
        """Resolved control-zone side [m]."""
        return self.side_m / 4.0 if self.control_zone_m is None else self.control_zone_m


GRID_400 = GridParams(400, 0.05)  # wheelchair paper: 20 x 20 m
GRID_200 = GridParams(200, 0.05)  # GND on the XR4000: 10 x 10 m


@dataclass(frozen=True, slots=True)
class IntegrateStats:
    """What one ``integrate`` call did.

    Attributes:
        shifted_cells: (d_row, d_col) the grid moved by before tracing; (0, 0) without re-centring.
        beams_traced: beams that changed the grid (hits and clearing no-return beams inside the grid).
        hits: beams whose hit fell inside the grid and was marked OCCUPIED.
        changed_cells: cells whose code (UNKNOWN / FREE / OCCUPIED) the scan changed (after the shift: cells
            entering the grid start UNKNOWN and count only when the scan sets them).
        digest: ``grid_digest`` of the cells after the scan.
    """

    shifted_cells: tuple[int, int]
    beams_traced: int
    hits: int
    changed_cells: int = 0
    digest: int = 0


def digest_keys(n_bytes: int) -> NDArray[np.uint64]:
    """The per-word keys of ``grid_digest`` for a grid of ``n_bytes`` cells: splitmix64 of the word index,
    made odd (integer arithmetic modulo 2**64: the same on every machine)."""
    z = np.arange(1, (n_bytes + 7) // 8 + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return (z ^ (z >> np.uint64(31))) | np.uint64(1)


@njit(cache=True)
def grid_digest(cells: NDArray[np.uint8], before: NDArray[np.uint8],
                keys: NDArray[np.uint64]) -> tuple[np.uint64, np.uint64]:
    """(cells that differ from ``before``, the digest of ``cells``) in one pass over 8-byte words: the
    digest is sum(word_k * keys[k]) modulo 2**64 over the row-major cell codes read as little-endian
    64-bit words (the last one zero-padded), with ``keys = digest_keys(cells.size)``. Two grids with the
    same digest are the same grid but for a 2**-64 chance; a few microseconds for a 400 x 400 grid."""
    new = cells.reshape(-1)
    old = before.reshape(-1)
    n_words = new.size // 8
    wn = new[: n_words * 8].view(np.uint64)
    wo = old[: n_words * 8].view(np.uint64)
    lows = np.uint64(0x0101010101010101)
    count = np.uint64(0)
    digest = np.uint64(0)
    for k in range(n_words):
        x = wn[k] ^ wo[k]  # a byte of x is non-zero where a cell differs: fold each byte onto its low bit
        x = x | (x >> np.uint64(4))
        x = x | (x >> np.uint64(2))
        x = x | (x >> np.uint64(1))
        count += ((x & lows) * lows) >> np.uint64(56)
        digest += wn[k] * keys[k]
    if new.size > n_words * 8:
        tail = np.uint64(0)
        for j in range(n_words * 8, new.size):
            count += np.uint64(new[j] != old[j])
            tail |= np.uint64(new[j]) << np.uint64(8 * (j - n_words * 8))
        digest += tail * keys[n_words]
    return count, digest


def shift_cells(cells: NDArray[_T], d_row: int, d_col: int, fill: int = int(UNKNOWN)) -> NDArray[_T]:
    """Grid contents after moving the grid origin by (d_row, d_col) cells: ``new[r, c] = old[r + d_row,
    c + d_col]``; cells with no source get ``fill`` (UNKNOWN; NEVER_SEEN for the stamps). One slice copy
    into a fresh array of the same shape and dtype."""
    n_r, n_c = cells.shape
    out = np.full_like(cells, fill)
    if abs(d_row) >= n_r or abs(d_col) >= n_c:
        return out
    out[max(-d_row, 0) : n_r - max(d_row, 0), max(-d_col, 0) : n_c - max(d_col, 0)] = cells[
        max(d_row, 0) : n_r + min(d_row, 0), max(d_col, 0) : n_c + min(d_col, 0)
    ]
    return out


@njit(cache=True)
def _clip_segment(
    x0: float, y0: float, x1: float, y1: float, hi: float
) -> tuple[bool, float, float, float, float, bool]:
    """Liang-Barsky clip of a segment (cell units) to the box [0, hi]^2.

    Returns (visible, x0, y0, x1, y1, end_inside)."""
    dx, dy = x1 - x0, y1 - y0
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0), (dx, hi - x0), (-dy, y0), (dy, hi - y0)):
        if p == 0.0:
            if q < 0.0:
                return False, x0, y0, x1, y1, False
        else:
            t = q / p
            if p < 0.0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
    if t0 > t1:
        return False, x0, y0, x1, y1, False
    return True, x0 + t0 * dx, y0 + t0 * dy, x0 + t1 * dx, y0 + t1 * dy, t1 >= 1.0


DROPOUT_MAX_BEAMS = 2
"""A run of at most this many consecutive beams without a return, with a hit on both sides, is a dropout
(**choice**: dark or specular spots and single-beam glitches are one or two beams wide; a real opening the
robot could use is tens of beams wide at the ranges that matter: 0.85 m at 8 m is 12 beams of 0.5 deg)."""

CLEAR_CORE_CELLS = 0.25
"""A ray clears an OCCUPIED cell only if it passes within this distance [cells] of the cell's centre."""

PROTECT_MAX_CELLS = 20.0
"""Longest protected tail of a ray [cells] (the grazing limit: incidence angles below asin(sqrt(2) / 20),
about 4 deg, are treated as 4 deg)."""


@njit(cache=True)
def _trace_free(
    cells: NDArray[np.uint8], seen: NDArray[np.int64], stamp: int, c0: int, r0: int, c1: int, r1: int,
    include_end: bool, sx: float, sy: float, ux: float, uy: float, length: float, protect: float,
) -> None:
    """Bresenham (8-connected, all octants) from cell (r0, c0) to (r1, c1): mark FREE, the end cell only
    when ``include_end``, and set ``seen`` of every cell marked (or kept OCCUPIED) to ``stamp``. Both ends
    must be inside the grid.

    A cell already OCCUPIED is cleared only when the ray (from (sx, sy), unit direction (ux, uy), ``length``
    long, all in cells) passes within CLEAR_CORE_CELLS of its centre and the cell is not in the ray's last
    ``protect`` cells (see ``_protected_tail``)."""
    dc = abs(c1 - c0)
    dr = -abs(r1 - r0)
    sc = 1 if c0 < c1 else -1
    sr = 1 if r0 < r1 else -1
    err = dc + dr
    c, r = c0, r0
    while True:
        last = c == c1 and r == r1
        if not last or include_end:
            seen[r, c] = stamp
            if cells[r, c] != 2:
                cells[r, c] = 1
            else:
                qx, qy = c + 0.5 - sx, r + 0.5 - sy
                along = qx * ux + qy * uy
                if abs(qx * uy - qy * ux) <= CLEAR_CORE_CELLS and length - along >= protect:
                    cells[r, c] = 1
        if last:
            return
        e2 = 2 * err
        if e2 >= dr:
            err += dr
            c += sc
        if e2 <= dc:
            err += dc
            r += sr


@njit(cache=True)
def _protected_tail(
    px: NDArray[np.float64], py: NDArray[np.float64], ok: NDArray[np.bool_], angles: NDArray[np.float64],
    i: int, a: int, b: int, sx: float, sy: float, ux: float, uy: float, length: float,
) -> float:
    """Length [cells] at the end of ray ``i`` (``length`` cells long, direction (ux, uy)) in which it must
    not clear OCCUPIED cells: sqrt(2) / sin(incidence), capped at PROTECT_MAX_CELLS.

    Why: a ray that ends on a surface at incidence angle alpha runs within sqrt(2) cells of it (the farthest
    a cell holding a point of the surface reaches from it) over its last sqrt(2) / sin(alpha) cells; the
    cells it crosses there hold that same surface, seen by earlier scans head-on, and the grazing ray only
    skims them. The surface's direction comes from the hit points of beams ``a`` and ``b`` (the neighbours,
    -1 for none), each used only if it is close enough to lie on the same surface (no farther than a
    surface at the grazing limit would put it); without one the surface is taken as seen head-on."""
    min_sin = math.sqrt(2.0) / PROTECT_MAX_CELLS
    ex, ey = sx + length * ux, sy + length * uy
    tx, ty, n_ok = 0.0, 0.0, 0
    for j, sign in ((a, -1.0), (b, 1.0)):
        if j < 0 or not ok[j]:
            continue
        dx, dy = px[j] - ex, py[j] - ey
        if math.hypot(dx, dy) > length * abs(angles[j] - angles[i]) / min_sin + 1.0:
            continue
        tx += sign * dx
        ty += sign * dy
        n_ok += 1
    norm = math.hypot(tx, ty)
    if n_ok == 0 or norm == 0.0:
        return math.sqrt(2.0)
    sin_a = abs(ux * ty - uy * tx) / norm
    return math.sqrt(2.0) / max(sin_a, min_sin)


@njit(cache=True)
def _integrate_kernel(
    cells: NDArray[np.uint8], seen: NDArray[np.int64], stamp: int, ranges: NDArray[np.float64],
    angles: NDArray[np.float64], sx: float, sy: float, sth: float, inv_cell: float, min_range: float,
    max_range: float, clear_range: float, invalid_clears: bool
) -> tuple[int, int]:
    """Trace every beam from the laser at (sx, sy) [cell units, local grid] with heading sth [rad].

    Pass 1 finds the hits and their points; pass 2 clears free space along all rays (with the dropout and
    grazing rules of ``RobotCentredGrid.integrate``); pass 3 marks the hits, so no ray of the same scan can
    erase another ray's hit. Returns (beams_traced, hits)."""
    n = cells.shape[0]
    hi = n * (1.0 - 1e-12)  # floor(hi) == n - 1
    m = ranges.shape[0]
    end_r = np.empty(m, np.int64)
    end_c = np.empty(m, np.int64)
    is_hit = np.zeros(m, np.bool_)
    ok = np.zeros(m, np.bool_)  # beam returned a hit (inside the grid or not)
    px = np.empty(m, np.float64)
    py = np.empty(m, np.float64)
    for i in range(m):
        r = ranges[i]
        if not (math.isnan(r) or r < min_range or r >= max_range or math.isinf(r)):
            ok[i] = True
            a = sth + angles[i]
            px[i] = sx + r * inv_cell * dm.cos(a)
            py[i] = sy + r * inv_cell * dm.sin(a)
    prev_hit = np.empty(m, np.int64)  # nearest hit at or before each beam, -1 for none
    next_hit = np.empty(m, np.int64)  # nearest hit at or after each beam, -1 for none
    last = -1
    for i in range(m):
        if ok[i]:
            last = i
        prev_hit[i] = last
    last = -1
    for i in range(m - 1, -1, -1):
        if ok[i]:
            last = i
        next_hit[i] = last
    traced = 0
    for i in range(m):
        r = ranges[i]
        hit = ok[i]
        on_surface = hit  # the ray ends on a surface: a hit, or a dropout clipped at its neighbours
        a_nb, b_nb = i - 1, (i + 1 if i + 1 < m else -1)
        if math.isnan(r) or r < min_range:
            if not invalid_clears:
                continue
            length = clear_range
        elif hit:
            length = r
        else:  # +inf or a finite no-return marker
            length = clear_range
            a_nb, b_nb = prev_hit[i], next_hit[i]
            if a_nb >= 0 and b_nb >= 0 and b_nb - a_nb - 1 <= DROPOUT_MAX_BEAMS:
                # a dropout: the surface the neighbours see continues behind it; clear only up to the
                # nearer of them and leave the end cell, which may hold that surface
                length = min(length, ranges[a_nb], ranges[b_nb])
                on_surface = True
        if length <= 0.0:
            continue
        a = sth + angles[i]
        ux, uy = dm.cos(a), dm.sin(a)
        len_c = length * inv_cell
        ex = sx + len_c * ux
        ey = sy + len_c * uy
        visible, x0, y0, x1, y1, end_inside = _clip_segment(sx, sy, ex, ey, hi)
        if not visible:
            continue
        c0 = min(max(math.floor(x0), 0), n - 1)
        r0 = min(max(math.floor(y0), 0), n - 1)
        c1 = min(max(math.floor(x1), 0), n - 1)
        r1 = min(max(math.floor(y1), 0), n - 1)
        protect = 0.0
        if on_surface:
            protect = _protected_tail(px, py, ok, angles, i, a_nb, b_nb, sx, sy, ux, uy, len_c)
        hit = hit and end_inside
        _trace_free(cells, seen, stamp, c0, r0, c1, r1, not (on_surface and end_inside), sx, sy, ux, uy,
                    len_c, protect)
        traced += 1
        end_r[i], end_c[i], is_hit[i] = r1, c1, hit
    hits = 0
    for i in range(m):
        if is_hit[i]:
            cells[end_r[i], end_c[i]] = 2
            seen[end_r[i], end_c[i]] = stamp
            hits += 1
    return traced, hits


class RobotCentredGrid:
    """The robot-centred grid: the only state the model builder carries between ticks.

    Attributes:
        params: the grid parameters.
        cells: (N, N) uint8 of UNKNOWN / FREE / OCCUPIED, ``cells[row, col]``, row along world y.
            Re-centring replaces the array: read ``grid.cells`` again after each ``integrate``.
        seen_ns: (N, N) int64, the time stamp of the last scan whose rays crossed or ended in each cell
            (NEVER_SEEN if none): how old the grid's word on a cell is. A cell behind a front laser keeps
            the state it had when the laser last saw it; the reflexive loop uses the stamp not to trust
            old FREE cells there (``unseen_points``, ``supervisor.safe_command``).
    """

    def __init__(self, params: GridParams = GRID_400, centre_xy: tuple[float, float] = (0.0, 0.0)) -> None:
        """Create an all-UNKNOWN grid centred (to the cell) on ``centre_xy`` [m, world]."""
        self.params = params
        n = params.size_cells
        self.cells: NDArray[np.uint8] = np.full((n, n), UNKNOWN, dtype=np.uint8)
        self.seen_ns: NDArray[np.int64] = np.full((n, n), NEVER_SEEN, dtype=np.int64)
        self._off_row, self._off_col = self._centred_offset(centre_xy[0], centre_xy[1])
        # the cells before a scan (``integrate``'s changed_cells), reused, and the digest's keys
        self._before: NDArray[np.uint8] = np.empty((n, n), dtype=np.uint8)
        self._digest_keys = digest_keys(n * n)

    # ---- geometry -------------------------------------------------------------------------------

    @property
    def offset_cells(self) -> tuple[int, int]:
        """(row, col) world-lattice index of local cell (0, 0)."""
        return self._off_row, self._off_col

    @property
    def origin_xy(self) -> tuple[float, float]:
        """World position [m] of the outer corner of cell (0, 0) (its minimum x and y)."""
        c = self.params.cell_m
        return self._off_col * c, self._off_row * c

    def _centred_offset(self, x: float, y: float) -> tuple[int, int]:
        """Offset that puts world point (x, y) in local cell (N // 2, N // 2)."""
        c, half = self.params.cell_m, self.params.size_cells // 2
        return math.floor(y / c) - half, math.floor(x / c) - half

    def world_to_cell_float(self, xy: ArrayLike) -> NDArray[np.float64]:
        """(M, 2) world points [m] -> (M, 2) continuous (row, col) in cell units: cell (r, c) spans
        [r, r + 1) x [c, c + 1), its centre is (r + 0.5, c + 0.5). Not bounds-checked."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        c = self.params.cell_m  # divide (not multiply by 1/c) so floor() agrees with world_to_cell
        return np.column_stack([p[:, 1] / c - self._off_row, p[:, 0] / c - self._off_col])

    def world_to_cell(self, xy: ArrayLike) -> NDArray[np.int64]:
        """(M, 2) world points [m] -> (M, 2) int (row, col) of the cells containing them (may lie outside
        the grid: see ``contains``)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        c = self.params.cell_m
        rows = np.floor(p[:, 1] / c).astype(np.int64) - self._off_row
        cols = np.floor(p[:, 0] / c).astype(np.int64) - self._off_col
        return np.column_stack([rows, cols])

    def cells_to_world(self, rc: ArrayLike) -> NDArray[np.float64]:
        """(M, 2) (row, col) cell indices (int or float) -> (M, 2) world (x, y) [m] of the cell centres;
        the integer lattice index is formed first so a cell's position is exact and shift-invariant."""
        a = np.asarray(rc).reshape(-1, 2)
        c = self.params.cell_m
        if np.issubdtype(a.dtype, np.integer):
            return np.column_stack([(a[:, 1] + self._off_col + 0.5) * c, (a[:, 0] + self._off_row + 0.5) * c])
        a = a.astype(np.float64)
        return np.column_stack([(a[:, 1] + (self._off_col + 0.5)) * c, (a[:, 0] + (self._off_row + 0.5)) * c])

    def contains(self, rc: ArrayLike) -> NDArray[np.bool_]:
        """(M,) mask of (row, col) indices inside the grid."""
        a = np.asarray(rc).reshape(-1, 2)
        n = self.params.size_cells
        return (a[:, 0] >= 0) & (a[:, 0] < n) & (a[:, 1] >= 0) & (a[:, 1] < n)

    def robot_cell(self, robot_pose: Pose2D) -> tuple[int, int]:
        """(row, col) of the cell containing the robot's rotation centre."""
        c = self.params.cell_m
        return math.floor(robot_pose.y / c) - self._off_row, math.floor(robot_pose.x / c) - self._off_col

    # ---- update ---------------------------------------------------------------------------------

    def recentre(self, robot_pose: Pose2D) -> tuple[int, int]:
        """If the robot is outside the control zone, shift the grid so it sits in the centre cell.

        Returns the (d_row, d_col) shift applied, (0, 0) when the robot is inside the zone."""
        p = self.params
        half_zone = 0.5 * p.control_zone_side_m / p.cell_m
        centre = 0.5 * p.size_cells
        u = robot_pose.x / p.cell_m - self._off_col
        v = robot_pose.y / p.cell_m - self._off_row
        if abs(u - centre) <= half_zone and abs(v - centre) <= half_zone:
            return 0, 0
        off_row, off_col = self._centred_offset(robot_pose.x, robot_pose.y)
        d_row, d_col = off_row - self._off_row, off_col - self._off_col
        self.cells = shift_cells(self.cells, d_row, d_col)
        self.seen_ns = shift_cells(self.seen_ns, d_row, d_col, int(NEVER_SEEN))
        self._off_row, self._off_col = off_row, off_col
        return d_row, d_col

    def integrate(self, scan: Scan, robot_pose: Pose2D) -> IntegrateStats:
        """Re-centre if needed, then trace ``scan`` from the laser pose ``robot_pose ∘ scan.sensor_pose``.

        Hits (finite ranges in [min_range_m, max_range_m)) clear the ray and mark the hit cell OCCUPIED;
        no-return beams (+inf or >= max_range_m) clear up to min(max_range_m, free_clip_m) and add no
        obstacle; invalid beams (nan or < min_range_m) are skipped unless ``params.invalid_clears``.
        Rays are clipped at the grid border; a hit outside the grid adds no obstacle.

        Two rules keep a wall from being erased by rays that say nothing about it:

        - Dropouts: a no-return beam in a run of at most DROPOUT_MAX_BEAMS beams without a return, with hits
          on both sides, clears only up to the nearer of those two hits, end cell excluded. For a surface
          continuous between the two hit points the missing return lies no nearer than about the nearer
          of them (the chord between two points at a beam step of a fraction of a degree), so this clears
          only what the dropout certainly saw; without the rule a black or shiny spot on a wall clears a
          free ray through the wall for free_clip_m metres. Longer runs are openings and clear as before.
        - Grazing: an OCCUPIED cell holds a hit somewhere inside it. A ray clears it only if it passes
          within CLEAR_CORE_CELLS of its centre (a ray through the cell's rim leaves most of it unobserved)
          and not within the tail of a ray that ends on a surface, sqrt(2) / sin(incidence) cells long
          (see ``_protected_tail``), where the ray runs within a cell of that very surface. A wall seen
          head-on thus survives later rays along it; an obstacle that left is still cleared by the rays
          through it (the first rule needs a ray within a quarter cell of the cell centre: with 0.5 deg
          beams and 5 cm cells, about one per scan at 3 m, one every other scan at 6 m)."""
        shift = self.recentre(robot_pose)
        p = self.params
        sp = scan.sensor_pose
        ct, st = dm.cos(robot_pose.theta), dm.sin(robot_pose.theta)
        lx = robot_pose.x + ct * sp.x - st * sp.y
        ly = robot_pose.y + st * sp.x + ct * sp.y
        inv = 1.0 / p.cell_m
        max_range = float(scan.max_range_m) if scan.max_range_m > 0.0 else math.inf  # nan/0: no limit
        ranges = np.ascontiguousarray(scan.ranges_m, dtype=np.float64)
        angles = np.ascontiguousarray(scan.angles_rad, dtype=np.float64)
        np.copyto(self._before, self.cells)
        # equal 1-D shapes: checked when the Scan was built
        traced, hits = _integrate_kernel(
            self.cells,
            self.seen_ns,
            int(scan.t_ns),
            ranges,
            angles,
            lx / p.cell_m - self._off_col,
            ly / p.cell_m - self._off_row,
            robot_pose.theta + sp.theta,
            inv,
            float(scan.min_range_m),
            max_range,
            min(max_range, p.free_clip_m),
            p.invalid_clears,
        )
        changed, digest = grid_digest(self.cells, self._before, self._digest_keys)
        return IntegrateStats(shifted_cells=shift, beams_traced=int(traced), hits=int(hits),
                              changed_cells=int(changed), digest=int(digest))

    # ---- views ----------------------------------------------------------------------------------

    def occupied_points(self, robot_pose: Pose2D, radius_m: float) -> NDArray[np.float64]:
        """(K, 2) centres of OCCUPIED cells within ``radius_m`` of the robot, in the ROBOT frame [m].

        The reactor's memory: obstacles seen by earlier scans stay available while the grid keeps them.
        Order is row-major over the grid (deterministic)."""
        return self.cell_points(robot_pose, radius_m, OCCUPIED)

    def cell_points(self, robot_pose: Pose2D, radius_m: float, state: np.uint8) -> NDArray[np.float64]:
        """(K, 2) centres of the cells in ``state`` (UNKNOWN / FREE / OCCUPIED) whose centre is within
        ``radius_m`` of the robot, in the ROBOT frame [m], row-major order. Cells beyond the grid's edge
        are not returned (they are unknown, but the grid does not hold them)."""
        return self._points(robot_pose, radius_m, state, None)[0]

    def unseen_points(self, robot_pose: Pose2D, radius_m: float, since_ns: int) -> NDArray[np.float64]:
        """(K, 2) centres of the cells not OCCUPIED that no scan has seen since ``since_ns`` (UNKNOWN, and
        FREE cells last traced before it), within ``radius_m`` of the robot, ROBOT frame [m], row-major.

        Where the grid's FREE is old news: a mover may have walked in since (the reflexive loop's blind
        side rule, ``supervisor.safe_command``)."""
        return self._points(robot_pose, radius_m, None, since_ns)[0]

    def free_border_points(self, robot_pose: Pose2D, radius_m: float) -> NDArray[np.float64]:
        """(K, 2) centres of the cells not FREE (OCCUPIED or UNKNOWN) beside a FREE cell (4-neighbours)
        within ``radius_m`` of the robot, ROBOT frame [m], row-major: the edge of the known free space,
        all a motion that must stay in it can meet (the trap escape's manoeuvre, ``manoeuvre``)."""
        return self._points(robot_pose, radius_m, None, None, border=True)[0]

    def occupied_points_seen(self, robot_pose: Pose2D,
                             radius_m: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """``occupied_points`` with the stamp of the scan that last saw each cell (NEVER_SEEN: none):
        how old the pose that placed it is (the reflexive loop's pose doubt,
        ``Supervisor._doubted_points``)."""
        return self._points(robot_pose, radius_m, OCCUPIED, None)

    def _points(self, robot_pose: Pose2D, radius_m: float, state: np.uint8 | None,
                since_ns: int | None, border: bool = False) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Robot-frame centres within ``radius_m`` of the cells in ``state``, or (``since_ns``) of the
        cells not OCCUPIED and not seen since then, or (``border``) of the cells not FREE beside a FREE
        one, and their seen stamps."""
        p = self.params
        n, c = p.size_cells, p.cell_m
        row, col = self.robot_cell(robot_pose)
        h = math.ceil(radius_m / c) + 1
        r0, r1 = max(row - h, 0), min(row + h + 1, n)
        c0, c1 = max(col - h, 0), min(col + h + 1, n)
        if r0 >= r1 or c0 >= c1:
            return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
        kind = _BORDER if border else _STATE if since_ns is None else _UNSEEN
        return _window_points(
            self.cells, self.seen_ns, r0, r1, c0, c1, r0 + self._off_row, c0 + self._off_col, c,
            robot_pose.x, robot_pose.y, radius_m, dm.cos(robot_pose.theta), dm.sin(robot_pose.theta), kind,
            np.uint8(0 if state is None else state), np.int64(0 if since_ns is None else since_ns),
        )


_STATE, _UNSEEN, _BORDER = 0, 1, 2  # the cell selections of ``_window_points``


@njit(cache=True)
def _window_points(
    cells: NDArray[np.uint8], seen: NDArray[np.int64], r0: int, r1: int, c0: int, c1: int, row0: int,
    col0: int, cell_m: float, x: float, y: float, radius_m: float, ct: float, st: float, kind: int,
    state: np.uint8, since_ns: np.int64,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The selected cells of the window [r0, r1) x [c0, c1) (world lattice index of its first cell: row0,
    col0) whose centre lies within ``radius_m`` of (x, y): their centres in the robot frame (heading cos
    ``ct``, sin ``st``) and seen stamps, row-major."""
    r2 = radius_m * radius_m
    n_c = cells.shape[1]
    index = np.empty((r1 - r0) * (c1 - c0), np.int64)
    n = 0
    for r in range(r0, r1):
        dy = ((r - r0) + row0 + 0.5) * cell_m - y
        for c in range(c0, c1):
            v = cells[r, c]
            if kind == _STATE:
                take = v == state
            elif kind == _UNSEEN:
                take = v != OCCUPIED and seen[r, c] < since_ns
            else:  # not FREE beside a FREE cell of the window (4-neighbours)
                take = v != FREE and (
                    (r > r0 and cells[r - 1, c] == FREE) or (r + 1 < r1 and cells[r + 1, c] == FREE)
                    or (c > c0 and cells[r, c - 1] == FREE) or (c + 1 < c1 and cells[r, c + 1] == FREE))
            if take:
                dx = ((c - c0) + col0 + 0.5) * cell_m - x
                if dx * dx + dy * dy <= r2:
                    index[n] = r * n_c + c
                    n += 1
    pts = np.empty((n, 2), np.float64)
    stamps = np.empty(n, np.int64)
    for k in range(n):
        r, c = index[k] // n_c, index[k] % n_c
        dy = ((r - r0) + row0 + 0.5) * cell_m - y
        dx = ((c - c0) + col0 + 0.5) * cell_m - x
        pts[k, 0] = ct * dx + st * dy
        pts[k, 1] = -st * dx + ct * dy
        stamps[k] = seen[r, c]
    return pts, stamps
