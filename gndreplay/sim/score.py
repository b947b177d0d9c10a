"""The challenge score of a closed-loop run: the optimal path on the true world and the navigation-challenge
(BARN) metric.

**Optimal path.** The static world at t = 0 (every element present then, door leaves as they stand; no
mover) is rasterised at ``CELL_M``: the cell of every point of every polygon edge (sampled at half a cell)
and every cell whose centre lies in a circle (or holds its centre) is an obstacle. A cell is free where the
robot's inscribed circle about its rotation centre (``RobotConfig.inscribed_radius_m``) fits: the Euclidean
distance transform to the nearest obstacle cell centre is at least that radius. The shortest path between
the start's and the goal's cells is NF1's 8-connected wave with exact diagonal steps, its steepest descent
and its string pulling (:mod:`gndreplay.pipeline.nf1`: ``nf1_wavefront``, ``descend``, ``tighten``), its
ends moved to the exact start and goal; its length in metres is the optimal path length. The grid spans
the world, the start and the goal with ``2 r + 0.5 m`` around them (a world without an outer wall can be
gone round). Errors are of the order of a cell: the clearance of a free cell is that of its centre to an
obstacle cell's centre (within half a cell diagonal of the obstacle's outline). A grid that would exceed
``MAX_CELLS`` gets coarser cells; none coarser than the radius itself (then there is no optimal path).

**Metric.** With OT = optimal length / ``CHALLENGE_SPEED_MPS`` (the challenge's 2 m/s) and T the run's time
to the goal: ``success * OT / clip(T, 2 OT, 8 OT)``: 0 for a failure, at most 0.5 (T at or under 2 OT),
0.125 at or beyond 8 OT. No optimal path (the goal unreachable on the grid): no metric.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..pipeline.cspace import squared_distance_cells
from ..pipeline.nf1 import descend, nf1_wavefront, tighten
from .geometry import Shapes

__all__ = [
    "CELL_M", "CHALLENGE_SPEED_MPS", "MAX_CELLS", "PASSAGE_MAX_M", "OptimalPath", "challenge_metric",
    "narrowest_passage_m", "optimal_path", "optimal_time_s", "rasterise",
]

F64 = NDArray[np.float64]
#: Cell of the optimal-path grid [m].
CELL_M = 0.05
#: Largest optimal-path grid [cells] (a larger world gets coarser cells).
MAX_CELLS = 4_000_000
#: The navigation challenge's reference speed [m/s]: OT = optimal length / this.
CHALLENGE_SPEED_MPS = 2.0
_MARGIN_M = 0.5
#: The widest passage ``narrowest_passage_m`` tells apart [m] (wider ones are reported as this).
PASSAGE_MAX_M = 4.0
_PASSAGE_STEPS = 12  # bisection steps: a 4 m range to 1 mm, far below the grid's cell


@dataclass(frozen=True, slots=True)
class OptimalPath:
    """The shortest path of the inscribed circle from start to goal.

    Attributes:
        length_m: its length [m]; None when the goal cannot be reached on the grid.
        cell_m: the grid's cell [m].
        waypoints: ``(K, 2)`` world x, y from the start to the goal (empty without a path).
    """

    length_m: float | None
    cell_m: float
    waypoints: F64


@njit(cache=True)
def _mark(edges: F64, circles: F64, x0: float, y0: float, cell: float,
          out: NDArray[np.bool_]) -> None:  # pragma: no cover - compiled
    h, w = out.shape
    for j in range(edges.shape[0]):
        ax, ay, bx, by = edges[j, 0], edges[j, 1], edges[j, 2], edges[j, 3]
        n = math.ceil(math.hypot(bx - ax, by - ay) / (0.5 * cell)) + 1
        for k in range(n + 1):
            f = k / n
            c = math.floor((ax + (bx - ax) * f - x0) / cell)
            r = math.floor((ay + (by - ay) * f - y0) / cell)
            if 0 <= r < h and 0 <= c < w:
                out[r, c] = True
    for j in range(circles.shape[0]):
        cx, cy, rad = circles[j, 0], circles[j, 1], circles[j, 2]
        c_lo = max(math.floor((cx - rad - x0) / cell), 0)
        c_hi = min(math.floor((cx + rad - x0) / cell), w - 1)
        r_lo = max(math.floor((cy - rad - y0) / cell), 0)
        r_hi = min(math.floor((cy + rad - y0) / cell), h - 1)
        for r in range(r_lo, r_hi + 1):
            py = y0 + (r + 0.5) * cell - cy
            for c in range(c_lo, c_hi + 1):
                px = x0 + (c + 0.5) * cell - cx
                if px * px + py * py <= rad * rad:
                    out[r, c] = True
        c = math.floor((cx - x0) / cell)
        r = math.floor((cy - y0) / cell)
        if 0 <= r < h and 0 <= c < w:
            out[r, c] = True


def rasterise(shapes: Shapes, origin_xy: tuple[float, float], shape: tuple[int, int], cell_m: float
              ) -> NDArray[np.bool_]:
    """``(rows, cols)`` obstacle mask of ``shapes`` on the grid whose cell (0, 0) starts at ``origin_xy``
    (rows along y): the cells of the polygon edges and the cells whose centre lies in a circle."""
    out = np.zeros(shape, dtype=np.bool_)
    _mark(np.ascontiguousarray(shapes.edges, dtype=np.float64),
          np.ascontiguousarray(shapes.circles, dtype=np.float64),
          float(origin_xy[0]), float(origin_xy[1]), float(cell_m), out)
    return out


def _extent(shapes: Shapes, points: F64) -> tuple[float, float, float, float]:
    xs = [points[:, 0], shapes.edges[:, 0], shapes.edges[:, 2],
          shapes.circles[:, 0] - shapes.circles[:, 2], shapes.circles[:, 0] + shapes.circles[:, 2]]
    ys = [points[:, 1], shapes.edges[:, 1], shapes.edges[:, 3],
          shapes.circles[:, 1] - shapes.circles[:, 2], shapes.circles[:, 1] + shapes.circles[:, 2]]
    x, y = np.concatenate(xs), np.concatenate(ys)
    return float(x.min()), float(y.min()), float(x.max()), float(y.max())


@dataclass(frozen=True, slots=True)
class _Grid:
    """The world rasterised around the start and the goal: obstacle cells, the grid's corner and cell, the
    start's and the goal's cells."""

    obstacle: NDArray[np.bool_]
    x_lo: float
    y_lo: float
    cell: float
    start_rc: tuple[int, int]
    goal_rc: tuple[int, int]


def _grid(shapes: Shapes, ends: F64, radius_m: float, cell_m: float) -> tuple[_Grid | None, float]:
    """The grid of a circle of ``radius_m`` (the world, the start and the goal with ``2 r + 0.5 m`` around)
    and its cell; no grid when it would need cells coarser than the radius."""
    x_lo, y_lo, x_hi, y_hi = _extent(shapes, ends)
    pad = 2.0 * radius_m + _MARGIN_M
    x_lo, y_lo, x_hi, y_hi = x_lo - pad, y_lo - pad, x_hi + pad, y_hi + pad
    cell = max(cell_m, math.sqrt((x_hi - x_lo) * (y_hi - y_lo) / MAX_CELLS))
    if cell > radius_m:
        return None, cell
    shape = (math.ceil((y_hi - y_lo) / cell), math.ceil((x_hi - x_lo) / cell))
    obstacle = rasterise(shapes, (x_lo, y_lo), shape, cell)
    rc = np.floor((ends[:, ::-1] - np.array([y_lo, x_lo])) / cell).astype(np.int64)
    ends_rc = (int(rc[0, 0]), int(rc[0, 1])), (int(rc[1, 0]), int(rc[1, 1]))
    return _Grid(obstacle, x_lo, y_lo, cell, *ends_rc), cell


def optimal_path(shapes: Shapes, start_xy: tuple[float, float], goal_xy: tuple[float, float],
                 radius_m: float, *, cell_m: float = CELL_M) -> OptimalPath:
    """The shortest path of a circle of ``radius_m`` from ``start_xy`` to ``goal_xy`` among ``shapes``
    (see the module docstring)."""
    ends = np.array([start_xy, goal_xy], dtype=np.float64).reshape(2, 2)
    g, cell = _grid(shapes, ends, radius_m, cell_m)
    none = OptimalPath(None, cell, np.zeros((0, 2)))
    if g is None:
        return none
    r_cells = radius_m / cell
    free = squared_distance_cells(g.obstacle) >= r_cells * r_cells
    nf = nf1_wavefront(free, g.goal_rc, connectivity=8, robot_rc=g.start_rc, early_exit=True)
    raw = descend(nf, free, g.start_rc)
    if raw.shape[0] == 0:
        return none
    cells = tighten(raw, free).astype(np.float64)
    xy = np.column_stack([g.x_lo + (cells[:, 1] + 0.5) * cell, g.y_lo + (cells[:, 0] + 0.5) * cell])
    xy[0], xy[-1] = ends[0], ends[1]
    if len(xy) == 1:
        xy = ends
    return OptimalPath(float(np.sum(np.hypot(*np.diff(xy, axis=0).T))), cell, xy)


def narrowest_passage_m(shapes: Shapes, start_xy: tuple[float, float], goal_xy: tuple[float, float], *,
                        max_width_m: float = PASSAGE_MAX_M, cell_m: float = CELL_M) -> float | None:
    """The width of the narrowest passage on the widest way from ``start_xy`` to ``goal_xy``: twice the
    largest radius of a circle that travels between them (the maximin clearance over all paths, by the
    optimal path's grid and its clearance rule, so within about a cell), ``max_width_m`` when a circle that
    wide passes, None when no way is open at all. What a robot's width must fit: a failure to cross a world
    whose narrowest passage is no wider than the robot plus its safety margins is the world's, not the
    stack's. The start's and the goal's own cells count as free."""
    ends = np.array([start_xy, goal_xy], dtype=np.float64).reshape(2, 2)
    g, _ = _grid(shapes, ends, 0.5 * max_width_m, cell_m)
    if g is None:
        return None
    d2 = squared_distance_cells(g.obstacle)

    open_cells = ~g.obstacle

    def passes(r_cells: float) -> bool:
        nf = nf1_wavefront(open_cells & (d2 >= r_cells * r_cells), g.goal_rc, connectivity=8,
                           robot_rc=g.start_rc, early_exit=True)
        return bool(np.isfinite(nf[g.start_rc]))

    lo, hi = 0.0, 0.5 * max_width_m / g.cell
    if passes(hi):
        return max_width_m
    if not passes(lo):
        return None
    for _ in range(_PASSAGE_STEPS):  # bisection on the radius: lo passes, hi does not
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if passes(mid) else (lo, mid)
    return 2.0 * lo * g.cell


def optimal_time_s(length_m: float) -> float:
    """OT: the optimal path at the challenge's reference speed [s]."""
    return length_m / CHALLENGE_SPEED_MPS


def challenge_metric(success: bool, time_s: float | None, optimal_s: float) -> float:
    """``success * OT / clip(T, 2 OT, 8 OT)`` (0 for a failure or without a time; see the module
    docstring)."""
    if not success or time_s is None or optimal_s <= 0.0:
        return 0.0
    return optimal_s / min(max(time_s, 2.0 * optimal_s), 8.0 * optimal_s)
