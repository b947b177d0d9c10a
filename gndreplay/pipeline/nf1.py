"""NF1 planner of GND: wavefront navigation function, steepest-descent path, string pulling, direction.

GND (Minguez & Montano) builds Latombe's minima-free navigation function NF1 over the C-space of the grid
every tick, follows its gradient from the robot to the goal, tightens the path and hands the reactor the
*instantaneous path direction*: the main direction of the first metre of the path. This module does that
on a plain boolean C-space array, so it does not depend on how the grid or the C-space were built.

Coordinates. ``free[row, col]`` with row along world y and col along world x (the grid never rotates).
Two continuous conventions meet here, each matching ``model.RobotCentredGrid``:

* the goal comes in *corner* coordinates (``world_to_cell_float``): cell (r, c) spans [r, r + 1) x
  [c, c + 1), so its index is ``floor``;
* waypoints go out in *index* coordinates (``cells_to_world``): (r, c) is the centre of cell (r, c).

Directions are counter-clockwise from the +col (world +x) axis towards +row (world +y), in (-pi, pi].

Choices (the papers are silent):

* 4-connected wave with unit steps (Latombe's NF1, a BFS) by default; 8-connected with diagonal steps of
  sqrt(2) as an option (exact Dijkstra on two FIFO queues, one per step length).
  A diagonal step (wave or descent) needs both orthogonal cells beside it free: the path never squeezes
  between two C-obstacle cells that only touch at a corner.
* Steepest descent over the 8 neighbours: the neighbour with the largest drop per unit length wins (ties:
  orthogonal before diagonal, then -row, +row, -col, +col). With the 4-connected wave a diagonal neighbour two
  steps lower is steeper (2 / sqrt 2) than an orthogonal one, so the raw path is already less jagged.
* The robot cell is seeded free: the wave may label it although it is C-obstacle (the robot stands closer
  to a wall than the inflation radius), but never expands from it. If none of its neighbours is free the
  wave cannot reach it; then the path *escapes* on a straight line to the nearest (Euclidean) cell the
  wave reached within ``escape_m``. Why this is safe: the clearance (distance to the nearest obstacle) is
  1-Lipschitz, the robot centre has clearance >= r (robot inner radius) and a free cell >= rho (inflation
  radius), so a segment shorter than r + rho never touches an obstacle. Keep ``escape_m`` below that.
* Early exit (GND's own suggestion to save time): the wave stops when it pops the robot cell. Every cell
  the descent can visit has a lower value and is therefore already final, so the path is unchanged.
* A goal beyond the grid (GND projects it onto the grid border) is aimed at through the best reachable
  free border cell: one wave from every free border cell, each starting at its straight-line distance to
  the goal plus a correction that measures the path by its detour (``frontier_seeds``), labels the robot
  cell from the best one; then the plain NF1 to that cell. Never a C-obstacle cell, never a sealed one.
* Route hysteresis (``Nf1Planner``): the route returned last is kept while it is free and this tick's
  route is not clearly better (``keep_route``), so near-equal routes do not alternate tick by tick.
* String pulling ("tightened using a recursive algorithm" in GND, no details): greedy, from each anchor
  advance while the segment to the next path cell stays in free cells (supercover walk: every cell the
  segment touches, both side cells at an exact corner crossing); then each interior waypoint slides along
  the raw path to the visible cell that shortens its two segments most (this puts it back on the corner
  the greedy pass overshot), and waypoints whose neighbours see each other are dropped.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from ..geometry import wrap_angle
from ..types import Flag
from .cspace import CSpaceTracker, free_cspace
from .model import UNKNOWN
from .planner import PlanResult, RouteParams

__all__ = [
    "Nf1Params",
    "Nf1Planner",
    "StepCosts",
    "descend",
    "frontier_seeds",
    "keep_route",
    "nearest_true",
    "nf1_wavefront",
    "path_direction",
    "plan",
    "project_goal",
    "resolve_goal",
    "route_cost",
    "shifted_route",
    "step_costs",
    "tighten",
]

DIAG_LEN = math.sqrt(2.0)
"""Length of a diagonal step [cells]."""

_ROUTE = RouteParams()
"""The default ``[planner]`` look-ahead and route hysteresis."""

# Neighbour order: 4 orthogonal (-row, +row, -col, +col), then 4 diagonal.
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)


@dataclass(frozen=True, slots=True)
class Nf1Params:
    """Settings of the NF1 planner (``[planner.nf1]``; its look-ahead and route hysteresis are the
    ``[planner]`` settings every planner shares, ``RouteParams``).

    Attributes:
        connectivity: 4 (Latombe's NF1, unit steps) or 8 (diagonal steps of sqrt(2)) for the wavefront.
            The descent always looks at the 8 neighbours.
        escape_m: how far the path may run straight out of C-obstacle when the robot cell and all its
            neighbours are C-obstacle [m]; 0 disables the escape. Keep it below robot inner radius +
            inflation radius (see the module notes); 0.5 m is safe for both presets.
        frontier_goal: a goal outside the grid is aimed at through the best reachable free border cell
            (the frontier of the robot's model): a wave from every free border cell b, started at the
            straight line from b to the goal plus the straight line robot -> b minus the wave's own
            obstacle-free distance (``frontier_seeds``), labels the robot cell from the cell with the least
            detour + straight lines (in open space: the papers' projection); then the plain NF1 to it.
            Never a C-obstacle cell, never one the robot cannot reach; PLANNER_NO_PATH when the robot
            reaches no free border cell (then it is enclosed in its model). False: the papers' projection
            of the goal onto the border along the robot-goal line (``project_goal``, ``border_search_m``).
        border_search_m: with ``frontier_goal`` False, a goal outside the grid whose border cell is
            C-obstacle moves to the nearest free border cell within this distance [m] (**choice**: the
            border point only stands in for a goal beyond the grid, so a wall or a piece of furniture at
            the border should not make the goal "in an obstacle"); 0 disables the search
            (GOAL_IN_OBSTACLE).
        early_exit: stop the wave when it reaches the robot cell (same path, less work).
        unknown_cost: cost of a step into an UNKNOWN cell relative to a step into a known FREE one, when
            unknown space is free to the planner: above 1 a known route wins over a route through
            never-seen space up to that factor shorter. **Choice**: 1.0, the papers' pure NF1 (unknown =
            free): 2.0 measured worse in closed loop (benchmarks/scenarios.py, 3 seeds: the wheelchair's
            u_trap 100 -> 0 %, the XR4000's gnd_exp1_three_traps 100 -> 0 %; the plan then switches
            between a known and an unseen route as cells get seen, and nothing holds a route yet).
    """

    connectivity: Literal[4, 8] = 4
    escape_m: float = 0.5
    frontier_goal: bool = True
    border_search_m: float = 1.0
    early_exit: bool = True
    unknown_cost: float = 1.0

    def __post_init__(self) -> None:
        if self.connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 4 or 8, got {self.connectivity!r}")
        if not self.escape_m >= 0.0:
            raise ValueError(f"escape_m must be >= 0, got {self.escape_m!r}")
        if not self.border_search_m >= 0.0:
            raise ValueError(f"border_search_m must be >= 0, got {self.border_search_m!r}")
        if not self.unknown_cost >= 1.0:
            raise ValueError(f"unknown_cost must be >= 1, got {self.unknown_cost!r}")


# ---------------------------------------------------------------------------------------------------------
# numba kernels


@njit(cache=True)
def _diag_open(free: NDArray[np.bool_], r: int, c: int, dr: int, dc: int) -> bool:
    """A diagonal step from (r, c) by (dr, dc) is allowed: both orthogonal cells beside it are free."""
    return free[r + dr, c] and free[r, c + dc]


@njit(cache=True)
def _bfs4(
    free: NDArray[np.bool_], goal_r: int, goal_c: int, sink_r: int, sink_c: int, early_exit: bool
) -> NDArray[np.float32]:
    """4-connected wave (Latombe's NF1) as a plain BFS: the first label of a cell is final."""
    h, w = free.shape
    f = free.ravel()
    dist = np.full(h * w, np.inf, dtype=np.float32)
    q = np.empty(h * w, dtype=np.int32)
    sink = sink_r * w + sink_c if sink_r >= 0 else -1
    g = goal_r * w + goal_c
    dist[g] = 0.0
    q[0] = g
    head, tail = 0, 1
    while head < tail:
        i = q[head]
        head += 1
        if i == sink:
            if early_exit:
                break
            if not f[i]:
                continue
        d = dist[i] + np.float32(1.0)
        r = i // w
        c = i - r * w
        for k in range(4):  # written out: a helper call per neighbour costs 10x here
            if k == 0:
                if r == 0:
                    continue
                j = i - w
            elif k == 1:
                if r == h - 1:
                    continue
                j = i + w
            elif k == 2:
                if c == 0:
                    continue
                j = i - 1
            else:
                if c == w - 1:
                    continue
                j = i + 1
            if dist[j] == np.inf and (f[j] or j == sink):
                dist[j] = d
                q[tail] = j
                tail += 1
    return dist.reshape(h, w)


@njit(cache=True)
def _seeded_unit(
    free: NDArray[np.bool_], seeds: NDArray[np.int64], seed_vals: NDArray[np.float32], sink_r: int,
    sink_c: int, early_exit: bool, diagonal: bool,
) -> tuple[NDArray[np.float32], NDArray[np.int32]]:
    """``_dijkstra_seeded`` without costly cells, on three FIFO queues (the sorted seeds, unit steps,
    diagonal steps): the same values and seed labels, 1.3 to 1.8 times as fast on 400 x 400 offices.
    Values are popped in increasing order, so each queue receives its entries in increasing order and the
    smallest head is always the next cell: O(1) per push, no heap. With one seed it is NF1's 8-connected
    wave (``_wave``)."""
    h, w = free.shape
    n = h * w
    f = free.ravel()
    dist = np.full(n, np.inf, dtype=np.float32)
    src = np.full(n, -1, dtype=np.int32)
    done = np.zeros(n, dtype=np.bool_)
    ns = seeds.shape[0]
    cap = 4 * n + 1
    qo = np.empty(cap, dtype=np.int32)
    qok = np.empty(cap, dtype=np.float32)
    qd = np.empty(cap, dtype=np.int32)
    qdk = np.empty(cap, dtype=np.float32)
    for k in range(ns):
        g = seeds[k]
        if seed_vals[k] < dist[g]:
            dist[g] = seed_vals[k]
            src[g] = g
    sink = sink_r * w + sink_c if sink_r >= 0 else -1
    hs, ho, to, hd, td = 0, 0, 0, 0, 0
    one = np.float32(1.0)
    root2 = np.float32(DIAG_LEN)
    nk = 8 if diagonal else 4
    while hs < ns or ho < to or hd < td:
        vs = seed_vals[hs] if hs < ns else np.inf
        vo = qok[ho] if ho < to else np.inf
        vd = qdk[hd] if hd < td else np.inf
        if vs <= vo and vs <= vd:
            i = seeds[hs]
            hs += 1
        elif vo <= vd:
            i = qo[ho]
            ho += 1
        else:
            i = qd[hd]
            hd += 1
        if done[i]:
            continue
        done[i] = True
        if i == sink:
            if early_exit:
                break
            if not f[i]:
                continue
        r = i // w
        c = i - r * w
        d1 = dist[i] + one
        d2 = dist[i] + root2
        for k in range(nk):
            dr = _DR[k]
            dc = _DC[k]
            rr = r + dr
            cc = c + dc
            if rr < 0 or rr >= h or cc < 0 or cc >= w:
                continue
            j = rr * w + cc
            if not (f[j] or j == sink):
                continue
            if k < 4:
                if d1 < dist[j]:
                    dist[j] = d1
                    src[j] = src[i]
                    qo[to] = j
                    qok[to] = d1
                    to += 1
            elif d2 < dist[j] and f[i + dr * w] and f[i + dc]:  # no corner cutting
                dist[j] = d2
                src[j] = src[i]
                qd[td] = j
                qdk[td] = d2
                td += 1
    return dist.reshape(h, w), src.reshape(h, w)


@njit(cache=True)
def _dijkstra_seeded(
    free: NDArray[np.bool_], classes: NDArray[np.uint8], factors: NDArray[np.float64],
    seeds: NDArray[np.int64], seed_vals: NDArray[np.float32], sink_r: int, sink_c: int, early_exit: bool,
    diagonal: bool,
) -> tuple[NDArray[np.float32], NDArray[np.int32]]:
    """Wave from several seed cells, each starting at its own value (``seeds`` flat indices sorted by
    ``seed_vals``), where a step into a cell of class k (``classes``, ``StepCosts``) is ``factors[k]`` times
    as long: exact Dijkstra on 2 K + 1 FIFO queues, one per step length (1, sqrt(2)) x class and the sorted
    seeds. As in ``_seeded_unit`` each queue receives increasing values, so the smallest head is always the
    next cell (no heap). A single seed of value 0 is the plain weighted wave. Returns the values and, for
    each cell, the flat index of the seed whose wave labelled it (-1 where unreached)."""
    h, w = free.shape
    n = h * w
    f = free.ravel()
    u = classes.ravel()
    dist = np.full(n, np.inf, dtype=np.float32)
    src = np.full(n, -1, dtype=np.int32)
    done = np.zeros(n, dtype=np.bool_)
    ns = seeds.shape[0]
    nq = 2 * factors.shape[0] + 1  # the seeds' queue is the last
    cap = max(4 * n + 1, ns)  # a popped cell pushes each of its <= 4 neighbours of one step kind once
    qi = np.empty((nq, cap), dtype=np.int32)
    qv = np.empty((nq, cap), dtype=np.float32)
    head = np.zeros(nq, dtype=np.int64)
    tail = np.zeros(nq, dtype=np.int64)
    steps = np.empty(nq - 1, dtype=np.float32)
    for k in range(factors.shape[0]):
        steps[2 * k] = factors[k]
        steps[2 * k + 1] = DIAG_LEN * factors[k]
    sink = sink_r * w + sink_c if sink_r >= 0 else -1
    for k in range(ns):
        g = seeds[k]
        if seed_vals[k] < dist[g]:
            dist[g] = seed_vals[k]
            src[g] = g
        qi[nq - 1, k] = g
        qv[nq - 1, k] = seed_vals[k]
    tail[nq - 1] = ns
    nk = 8 if diagonal else 4
    while True:
        best = -1
        for k in range(nq):
            if head[k] < tail[k] and (best < 0 or qv[k, head[k]] < qv[best, head[best]]):
                best = k
        if best < 0:
            break
        i = qi[best, head[best]]
        head[best] += 1
        if done[i]:
            continue
        done[i] = True
        if i == sink:
            if early_exit:
                break
            if not f[i]:
                continue
        r = i // w
        c = i - r * w
        for k in range(nk):
            dr = _DR[k]
            dc = _DC[k]
            rr = r + dr
            cc = c + dc
            if rr < 0 or rr >= h or cc < 0 or cc >= w:
                continue
            j = rr * w + cc
            if not (f[j] or j == sink):
                continue
            if k >= 4 and not (f[i + dr * w] and f[i + dc]):  # no corner cutting
                continue
            qk = (1 if k >= 4 else 0) + 2 * np.int64(u[j])
            d = dist[i] + steps[qk]
            if d < dist[j]:
                dist[j] = d
                src[j] = src[i]
                qi[qk, tail[qk]] = j
                qv[qk, tail[qk]] = d
                tail[qk] += 1
    return dist.reshape(h, w), src.reshape(h, w)


@dataclass(frozen=True, slots=True, eq=False)
class StepCosts:
    """What a step into each cell costs, for the weighted wave: a step into a cell of class k costs
    ``factors[k]`` times a step into a plain free cell (class 0, factor 1). Built by ``step_costs``.

    Attributes:
        classes: (H, W) uint8 class of each cell, C-contiguous.
        factors: (K,) float64 factor of each class; factors[0] == 1.
    """

    classes: NDArray[np.uint8]
    factors: NDArray[np.float64]

    def of(self, rows: NDArray[np.integer], cols: NDArray[np.integer]) -> NDArray[np.float64]:
        """The factor of each of these cells."""
        return self.factors[self.classes[rows, cols]]


def step_costs(
    unknown: NDArray[np.bool_] | None, unknown_cost: float, avoid: NDArray[np.bool_] | None = None,
    avoid_cost: float = 1.0,
) -> StepCosts | None:
    """Step costs from two masks: UNKNOWN cells at ``unknown_cost``, cells to avoid (the route the robot was
    trapped on, ``RouteParams.avoid_cost``) at ``avoid_cost``, a cell in both at the product. None when
    every step costs the same (the papers' NF1, the unit-step kernels)."""
    use_u = unknown is not None and unknown_cost != 1.0
    use_a = avoid is not None and avoid_cost != 1.0 and bool(avoid.any())
    if not (use_u or use_a):
        return None
    if use_u and use_a:
        assert unknown is not None and avoid is not None
        classes = unknown.astype(np.uint8) + 2 * avoid.astype(np.uint8)
        factors = [1.0, unknown_cost, avoid_cost, unknown_cost * avoid_cost]
    else:
        mask = unknown if use_u else avoid
        assert mask is not None
        classes = mask.astype(np.uint8)
        factors = [1.0, unknown_cost if use_u else avoid_cost]
    return StepCosts(np.ascontiguousarray(classes), np.array(factors, dtype=np.float64))


def _wave(
    free: NDArray[np.bool_],
    goal_r: int,
    goal_c: int,
    sink_r: int,
    sink_c: int,
    early_exit: bool,
    diagonal: bool,
    costs: StepCosts | None = None,
) -> NDArray[np.float32]:
    """Wavefront from the goal over free cells (C-contiguous ``free``); the sink (robot) cell, if >= 0, may
    be labelled although not free but never expands. With ``costs`` a step into a cell costs its class's
    factor."""
    if costs is not None:
        seed = np.array([goal_r * free.shape[1] + goal_c], dtype=np.int64)
        return _dijkstra_seeded(free, costs.classes, costs.factors, seed, np.zeros(1, dtype=np.float32),
                                sink_r, sink_c, early_exit, diagonal)[0]
    if diagonal:  # exact Dijkstra with steps 1 and sqrt(2), the goal its one seed
        seed = np.array([goal_r * free.shape[1] + goal_c], dtype=np.int64)
        return _seeded_unit(free, seed, np.zeros(1, dtype=np.float32), sink_r, sink_c, early_exit, True)[0]
    return _bfs4(free, goal_r, goal_c, sink_r, sink_c, early_exit)


@njit(cache=True)
def _descend(nf: NDArray[np.float32], free: NDArray[np.bool_], r: int, c: int) -> NDArray[np.int32]:
    """Steepest descent over 8 neighbours from (r, c) to the zero of ``nf``; (0, 2) if (r, c) unreached."""
    h, w = nf.shape
    if not np.isfinite(nf[r, c]):
        return np.empty((0, 2), dtype=np.int32)
    cap = int(nf[r, c] * 1.01) + 3  # every step drops the value by >= 1 (up to float32 rounding)
    out = np.empty((cap, 2), dtype=np.int32)
    out[0, 0] = r
    out[0, 1] = c
    k = 1
    inv_diag = 1.0 / DIAG_LEN
    while nf[r, c] > 0.0 and k < cap:
        v = nf[r, c]
        best = 0.0
        bk = -1
        for q in range(8):
            dr = _DR[q]
            dc = _DC[q]
            rr = r + dr
            cc = c + dc
            if rr < 0 or rr >= h or cc < 0 or cc >= w:
                continue
            vn = nf[rr, cc]
            if not vn < v:  # also rejects inf (unreached)
                continue
            if q >= 4:
                if not _diag_open(free, r, c, dr, dc):
                    continue
                score = (v - vn) * inv_diag
            else:
                score = v - vn
            if score > best + 1e-4:
                best = score
                bk = q
        if bk < 0:  # cannot happen on a wave output; keep the descent total anyway
            break
        r += _DR[bk]
        c += _DC[bk]
        out[k, 0] = r
        out[k, 1] = c
        k += 1
    return out[:k].copy()


@njit(cache=True)
def _visible(free: NDArray[np.bool_], r0: int, c0: int, r1: int, c1: int) -> bool:
    """Every cell the segment from the anchor (r0, c0) to the target (r1, c1) touches is free, the anchor
    cell excepted (it may be the robot cell in C-obstacle).

    Supercover walk between the cell centres (both side cells at an exact corner crossing). The walk is
    symmetric, so two walkers start at both ends and stop where they meet: an obstruction near either end
    is found after a few cells, which is where obstructions of nearly visible segments are.
    """
    if r0 == r1 and c0 == c1:
        return True
    if not free[r1, c1]:
        return False
    nx = abs(c1 - c0)
    ny = abs(r1 - r0)
    sx = 1 if c1 > c0 else -1
    sy = 1 if r1 > r0 else -1
    ra, ca, ax, ay = r0, c0, 0, 0  # walker from the anchor
    rb, cb, bx, by = r1, c1, 0, 0  # walker from the target, moving by (-sy, -sx)
    while ax + bx < nx or ay + by < ny:
        d = (1 + 2 * ax) * ny - (1 + 2 * ay) * nx
        if d == 0:
            if not (free[ra, ca + sx] and free[ra + sy, ca]):
                return False
            ra += sy
            ca += sx
            ax += 1
            ay += 1
        elif d < 0:
            ca += sx
            ax += 1
        else:
            ra += sy
            ay += 1
        if not free[ra, ca]:
            return False
        if ax + bx >= nx and ay + by >= ny:
            break
        d = (1 + 2 * bx) * ny - (1 + 2 * by) * nx
        if d == 0:
            if not (free[rb, cb - sx] and free[rb - sy, cb]):
                return False
            rb -= sy
            cb -= sx
            bx += 1
            by += 1
        elif d < 0:
            cb -= sx
            bx += 1
        else:
            rb -= sy
            by += 1
        if (rb != r0 or cb != c0) and not free[rb, cb]:
            return False
    return True


@njit(cache=True)
def _line_cells(r0: int, c0: int, r1: int, c1: int) -> NDArray[np.int32]:
    """(L, 2) cells on the segment between two cell centres, both ends included, consecutive cells
    8-adjacent (the same walk as ``_visible``)."""
    nx = abs(c1 - c0)
    ny = abs(r1 - r0)
    sx = 1 if c1 > c0 else -1
    sy = 1 if r1 > r0 else -1
    out = np.empty((nx + ny + 1, 2), dtype=np.int32)
    r, c = r0, c0
    out[0, 0] = r
    out[0, 1] = c
    k = 1
    ix, iy = 0, 0
    while ix < nx or iy < ny:
        d = (1 + 2 * ix) * ny - (1 + 2 * iy) * nx
        if d == 0:
            r += sy
            c += sx
            ix += 1
            iy += 1
        elif d < 0:
            c += sx
            ix += 1
        else:
            r += sy
            iy += 1
        out[k, 0] = r
        out[k, 1] = c
        k += 1
    return out[:k].copy()


@njit(cache=True)
def _tighten(path: NDArray[np.int32], free: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Indices into ``path`` of the string-pulled waypoints (first and last included). From each anchor
    the stride along the path doubles while the line of sight holds (O(log K) checks instead of K); the
    point reached is visible, the next cell is not."""
    n = path.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    m = 1
    a = 0
    while a < n - 1:
        j = a + 1  # the next path cell is always reachable
        step = 1  # gallop: double the stride while visible, halve it on a miss, stop on a miss at 1
        while j < n - 1:
            nj = min(j + step, n - 1)
            if _visible(free, path[a, 0], path[a, 1], path[nj, 0], path[nj, 1]):
                j = nj
                step *= 2
            elif step == 1:
                break
            else:
                step //= 2
        keep[m] = j
        m += 1
        a = j
    return _refine(path, free, keep[:m].copy())


@njit(cache=True)
def _hyp(path: NDArray[np.int32], i: int, j: int) -> float:
    return math.hypot(float(path[i, 0] - path[j, 0]), float(path[i, 1] - path[j, 1]))


@njit(cache=True)
def _refine(path: NDArray[np.int32], free: NDArray[np.bool_], keep: NDArray[np.int64]) -> NDArray[np.int64]:
    """Pull each interior waypoint along the raw path (between its neighbours) to the cell that shortens
    the two segments most while both stay visible, then drop waypoints whose neighbours see each other.
    The greedy pass stops where the line of sight first breaks, which can leave a waypoint past a corner;
    this moves it back onto the corner."""
    m = keep.shape[0]
    for _ in range(4):
        changed = False
        for i in range(1, m - 1):
            a = keep[i - 1]
            b = keep[i + 1]
            bj = keep[i]
            best = _hyp(path, a, bj) + _hyp(path, bj, b)
            for j in range(a + 1, b):
                s = _hyp(path, a, j) + _hyp(path, j, b)
                if s >= best - 1e-9:
                    continue
                # the shorter segment first: it is the one an obstruction near the corner blocks
                va = _hyp(path, a, j) <= _hyp(path, j, b)
                if va and not _visible(free, path[a, 0], path[a, 1], path[j, 0], path[j, 1]):
                    continue
                if not _visible(free, path[j, 0], path[j, 1], path[b, 0], path[b, 1]):
                    continue
                if not va and not _visible(free, path[a, 0], path[a, 1], path[j, 0], path[j, 1]):
                    continue
                best = s
                bj = j
            if bj != keep[i]:
                keep[i] = bj
                changed = True
        if not changed:
            break
    out = np.empty(m, dtype=np.int64)
    out[0] = keep[0]
    k = 1
    i = 0
    while i < m - 1:
        j = i + 1
        while j + 1 < m and _visible(
            free, path[keep[i], 0], path[keep[i], 1], path[keep[j + 1], 0], path[keep[j + 1], 1]
        ):
            j += 1
        out[k] = keep[j]
        k += 1
        i = j
    return out[:k].copy()


# ---------------------------------------------------------------------------------------------------------
# public functions


def _as_free(free: ArrayLike) -> NDArray[np.bool_]:
    a = np.asarray(free)
    if a.ndim != 2 or a.dtype != np.bool_:
        raise ValueError(f"free must be a 2-D bool array, got shape {a.shape} dtype {a.dtype}")
    return np.ascontiguousarray(a)


def _check_cell(name: str, rc: tuple[int, int], shape: tuple[int, ...]) -> tuple[int, int]:
    r, c = int(rc[0]), int(rc[1])
    if not (0 <= r < shape[0] and 0 <= c < shape[1]):
        raise ValueError(f"{name} {(r, c)} is outside the grid of shape {shape}")
    return r, c


def project_goal(
    start_rc: tuple[int, int], goal_rc_float: ArrayLike, shape: tuple[int, int]
) -> tuple[int, int]:
    """Goal cell: the cell containing the goal, or, for a goal outside the grid, the border cell where the
    segment from the robot cell centre to the goal leaves the grid.

    Args:
        start_rc: (row, col) robot cell, inside the grid.
        goal_rc_float: (row, col) goal in corner coordinates (cell (r, c) spans [r, r + 1) x [c, c + 1)).
        shape: (rows, cols) of the grid.
    Returns:
        (row, col) of a cell inside the grid.
    Raises:
        ValueError: the goal is not finite or the robot cell is outside the grid.
    """
    h, w = int(shape[0]), int(shape[1])
    r0, c0 = _check_cell("start_rc", start_rc, (h, w))
    g = np.asarray(goal_rc_float, dtype=np.float64).reshape(2)
    if not np.all(np.isfinite(g)):
        raise ValueError(f"goal_rc_float must be finite, got {g.tolist()}")
    gr, gc = math.floor(g[0]), math.floor(g[1])
    if 0 <= gr < h and 0 <= gc < w:
        return gr, gc
    # in index coordinates (centres on integers) clip the segment start -> goal to [0, h-1] x [0, w-1]
    p0 = np.array([r0, c0], dtype=np.float64)
    d = (g - 0.5) - p0
    t = 1.0
    for axis, hi in ((0, h - 1), (1, w - 1)):
        if d[axis] > 0.0:
            t = min(t, (hi - p0[axis]) / d[axis])
        elif d[axis] < 0.0:
            t = min(t, -p0[axis] / d[axis])
    q = p0 + max(t, 0.0) * d
    return int(np.clip(np.rint(q[0]), 0, h - 1)), int(np.clip(np.rint(q[1]), 0, w - 1))


def nf1_wavefront(
    free: ArrayLike,
    goal_rc: tuple[int, int],
    *,
    connectivity: Literal[4, 8] = 4,
    robot_rc: tuple[int, int] | None = None,
    early_exit: bool = False,
) -> NDArray[np.float32]:
    """NF1 navigation function: wavefront distance from the goal cell over free C-space cells.

    Args:
        free: (H, W) bool, True where the robot fits (free C-space).
        goal_rc: (row, col) goal cell, always seeded (``plan`` refuses a goal cell that is not free).
        connectivity: 4 (unit steps, Latombe's NF1) or 8 (diagonal steps of sqrt(2); no corner
            cutting between two C-obstacle cells).
        robot_rc: the robot cell, seeded free: labelled when a neighbour is reached, never expanded.
        early_exit: stop when the robot cell is reached; then only values below the robot's are final
            (all the descent needs), others may be too high or inf.
    Returns:
        (H, W) float32 distance to the goal along the wave [cells]; inf where not reached.
    Raises:
        ValueError: bad shape / dtype, a cell outside the grid, or a bad connectivity.
    """
    f = _as_free(free)
    gr, gc = _check_cell("goal_rc", goal_rc, f.shape)
    sr, sc = (-1, -1) if robot_rc is None else _check_cell("robot_rc", robot_rc, f.shape)
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity!r}")
    return _wave(f, gr, gc, sr, sc, early_exit and robot_rc is not None, connectivity == 8)


def reaches_border(free: ArrayLike, start_rc: tuple[int, int]) -> bool:
    """True when a 4-connected path of free cells leads from ``start_rc`` (seeded even if not free) to a
    cell on the grid border: the robot is not enclosed in the model, a goal beyond the grid may be
    reachable through some border cell."""
    f = _as_free(free)
    r, c = _check_cell("start_rc", start_rc, f.shape)
    reach = np.isfinite(_wave(f, r, c, -1, -1, False, False))
    return bool(reach[0].any() or reach[-1].any() or reach[:, 0].any() or reach[:, -1].any())


def descend(nf: NDArray[np.float32], free: ArrayLike, start_rc: tuple[int, int]) -> NDArray[np.int32]:
    """Steepest-descent path over the 8 neighbours from ``start_rc`` down to the goal (value 0).

    Args:
        nf: (H, W) float32 navigation function from ``nf1_wavefront``.
        free: (H, W) bool free C-space (diagonal steps need both side cells free).
        start_rc: (row, col) start cell.
    Returns:
        (K, 2) int32 (row, col) cells, start first, goal last, consecutive cells 8-adjacent;
        (0, 2) when the start was not reached by the wave.
    """
    f = _as_free(free)
    r, c = _check_cell("start_rc", start_rc, f.shape)
    return _descend(np.ascontiguousarray(nf, dtype=np.float32), f, r, c)


def tighten(path_cells: NDArray[np.int32], free: ArrayLike) -> NDArray[np.int32]:
    """String pulling: the subset of path cells, first and last kept, such that the segment between
    consecutive ones stays in free cells (the first cell of each segment excepted, so a path may start in
    C-obstacle). Greedy line of sight from each anchor, then waypoints slide back onto corners (see the
    module notes).

    Args:
        path_cells: (K, 2) int (row, col), consecutive cells 8-adjacent (K >= 1).
        free: (H, W) bool free C-space.
    Returns:
        (M, 2) int32 (row, col) waypoints, M <= K.
    """
    f = _as_free(free)
    p = np.ascontiguousarray(path_cells, dtype=np.int32)
    if p.shape[0] == 0:
        return p.reshape(0, 2)
    return p[_tighten(p, f)]


def path_direction(waypoints: NDArray[np.float64], lookahead_cells: float) -> float:
    """Bearing [rad, (-pi, pi]] from the first waypoint to the point ``lookahead_cells`` along the
    polyline (its end if shorter); 0.0 for a polyline of zero length.

    Args:
        waypoints: (M, 2) (row, col) polyline, M >= 1.
        lookahead_cells: arc length [cells] > 0.
    """
    w = np.asarray(waypoints, dtype=np.float64)
    seg = np.diff(w, axis=0)
    lens = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(lens)])
    if cum[-1] <= 0.0:
        return 0.0
    s = min(lookahead_cells, float(cum[-1]))
    i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(lens) - 1)
    while lens[i] == 0.0:  # never stop on a zero-length segment
        i -= 1
    p = w[i] + seg[i] * ((s - cum[i]) / lens[i])
    d = p - w[0]
    return float(wrap_angle(dm.atan2(d[0], d[1])))


def _nearest(
    centre: tuple[int, int],
    radius_cells: float,
    shape: tuple[int, ...],
    valid: Callable[[slice, slice, NDArray[np.int64], NDArray[np.int64]], NDArray[np.bool_]],
    key: NDArray[np.float32] | None = None,
) -> tuple[int, int] | None:
    """Nearest cell (Euclidean; ties: lower ``key``, then row-major) within ``radius_cells`` of ``centre``
    where ``valid(rows, cols, rr, cc)`` holds on the window ``[rows, cols]`` with index grids rr, cc."""
    r0, c0 = centre
    k = math.floor(radius_cells)
    if k < 1:
        return None
    rows = slice(max(r0 - k, 0), min(r0 + k + 1, shape[0]))
    cols = slice(max(c0 - k, 0), min(c0 + k + 1, shape[1]))
    rr, cc = np.mgrid[rows, cols]
    d2 = np.square(rr - r0) + np.square(cc - c0)
    ok = valid(rows, cols, rr, cc) & (d2 <= radius_cells * radius_cells)
    if not ok.any():
        return None
    keys = (np.zeros(int(ok.sum())) if key is None else key[rows, cols][ok], d2[ok])
    i = np.lexsort(keys)[0]  # primary key: distance (lexsort sorts by the last key first)
    return int(rr[ok][i]), int(cc[ok][i])


def _escape_target(
    nf: NDArray[np.float32], start: tuple[int, int], radius_cells: float
) -> tuple[int, int] | None:
    """Nearest cell the wave reached (ties: lower NF1) within ``radius_cells`` of the robot cell."""
    return _nearest(start, radius_cells, nf.shape, lambda rs, cs, _rr, _cc: np.isfinite(nf[rs, cs]), nf)


def _free_border_cell(
    free: NDArray[np.bool_], goal: tuple[int, int], radius_cells: float
) -> tuple[int, int] | None:
    """Nearest free cell on the grid border within ``radius_cells`` of the projected goal cell."""
    h, w = free.shape

    def valid(rs: slice, cs: slice, rr: NDArray[np.int64], cc: NDArray[np.int64]) -> NDArray[np.bool_]:
        return free[rs, cs] & ((rr == 0) | (rr == h - 1) | (cc == 0) | (cc == w - 1))

    return _nearest(goal, radius_cells, free.shape, valid)


def nearest_true(
    mask: NDArray[np.bool_], centre: tuple[int, int], radius_cells: float
) -> tuple[int, int] | None:
    """Nearest True cell of ``mask`` (Euclidean, ties row-major) within ``radius_cells`` of ``centre``."""
    return _nearest(centre, radius_cells, mask.shape, lambda rs, cs, _rr, _cc: mask[rs, cs])


def _inside(g: NDArray[np.float64], shape: tuple[int, ...]) -> bool:
    """The goal (corner coordinates) lies in a cell of the grid."""
    return 0 <= math.floor(g[0]) < shape[0] and 0 <= math.floor(g[1]) < shape[1]


def frontier_seeds(
    free: NDArray[np.bool_], start_rc: tuple[int, int], goal_rc_float: NDArray[np.float64], diagonal: bool
) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
    """Seeds of the wave towards a goal beyond the grid: every free border cell b (flat index) with the
    value ``|b - goal| + |robot - b| - m(robot, b)`` [cells], sorted by value, where ``m`` is the wave's
    own obstacle-free distance (4-connected: |dr| + |dc|; 8-connected: octile). The robot's wave value
    is then min over b of the straight line beyond the grid + the straight line robot -> b + the detour
    obstacles force on the wave path (its excess over ``m``): in open space the border cell on the
    robot-goal line (the papers' projection), behind a wall the reachable cell with the least total.
    Measuring the path by its excess, not by the wave's own 4- or 8-connected length, keeps the choice
    from drifting to the cell straight out along a grid axis.

    Args:
        free: (H, W) bool free C-space.
        start_rc: (row, col) robot cell.
        goal_rc_float: (row, col) goal in corner coordinates.
        diagonal: the wave is 8-connected.
    """
    h, w = free.shape
    border = np.zeros((h, w), dtype=np.bool_)
    border[[0, -1], :] = True
    border[:, [0, -1]] = True
    idx = np.flatnonzero(border & free).astype(np.int64)
    rr, cc = np.divmod(idx, w)
    dr, dc = np.abs(rr - start_rc[0]), np.abs(cc - start_rc[1])
    free_len = np.maximum(dr, dc) + (DIAG_LEN - 1.0) * np.minimum(dr, dc) if diagonal else dr + dc
    beyond = np.hypot(rr - (goal_rc_float[0] - 0.5), cc - (goal_rc_float[1] - 0.5))
    value = beyond + np.hypot(dr, dc) - free_len
    order = np.argsort(value, kind="stable")
    return idx[order], value[order].astype(np.float32)


def _frontier_goal(
    free: NDArray[np.bool_], start: tuple[int, int], goal_rc_float: NDArray[np.float64], params: Nf1Params,
    cell_m: float, costs: StepCosts | None,
) -> tuple[int, int] | None:
    """The free border cell to plan to for a goal beyond the grid (``Nf1Params.frontier_goal``): the seed
    of ``frontier_seeds`` whose wave labels the robot cell (or, when the robot cell is C-obstacle, the cell
    NF1's escape runs to); None when no free border cell is reachable."""
    diagonal = params.connectivity == 8
    seeds, values = frontier_seeds(free, start, goal_rc_float, diagonal)
    if seeds.size == 0:
        return None
    if costs is not None:
        nf, src = _dijkstra_seeded(free, costs.classes, costs.factors, seeds, values, start[0], start[1],
                                   params.early_exit, diagonal)
    else:
        nf, src = _seeded_unit(free, seeds, values, start[0], start[1], params.early_exit, diagonal)
    entry: tuple[int, int] | None = start
    if not np.isfinite(nf[start]):
        entry = None if free[start] else _escape_target(nf, start, params.escape_m / cell_m)
    if entry is None:
        return None
    r, c = divmod(int(src[entry]), free.shape[1])
    return r, c


def resolve_goal(
    free: NDArray[np.bool_],
    start: tuple[int, int],
    goal_rc_float: NDArray[np.float64],
    border_search_cells: float,
) -> tuple[tuple[int, int], bool]:
    """The goal cell a planner plans to, and whether the goal lay outside the grid: ``project_goal``, then
    for a projected goal on a C-obstacle border cell the nearest free border cell within
    ``border_search_cells`` (the cell may still be C-obstacle: the caller reports GOAL_IN_OBSTACLE)."""
    g = goal_rc_float
    goal = project_goal(start, g, free.shape)
    projected = not (0 <= math.floor(g[0]) < free.shape[0] and 0 <= math.floor(g[1]) < free.shape[1])
    if projected and not free[goal]:
        goal = _free_border_cell(free, goal, border_search_cells) or goal
    return goal, projected


def _fail(flag: Flag, goal: tuple[int, int], projected: bool) -> PlanResult:
    return PlanResult(
        ok=False, flag=flag, goal_cell=goal, goal_projected=projected,
        path_cells=np.zeros((0, 2), dtype=np.int32), n_escape=0,
        waypoints_cells=np.zeros((0, 2), dtype=np.float64), direction_rad=math.nan, length_m=math.nan,
        cost_m=math.nan
    )


def plan(
    free: ArrayLike,
    start_rc: tuple[int, int],
    goal_rc_float: ArrayLike,
    *,
    cell_m: float,
    params: Nf1Params = Nf1Params(),
    lookahead_m: float = _ROUTE.lookahead_m,
    unknown: ArrayLike | None = None,
    avoid: ArrayLike | None = None,
    avoid_cost: float = 1.0,
) -> PlanResult:
    """Plan from the robot cell to the goal: NF1 wave, steepest descent, string pulling, direction.

    Args:
        free: (H, W) bool free C-space (True where the robot's inner disc fits).
        start_rc: (row, col) robot cell (``RobotCentredGrid.robot_cell``); seeded free.
        goal_rc_float: (row, col) goal in corner coordinates (``RobotCentredGrid.world_to_cell_float``);
            outside the grid the plan goes to the best reachable free border cell (``frontier_goal``),
            or to its projection onto the border along the robot-goal line.
        cell_m: cell side [m].
        params: planner settings.
        lookahead_m: the direction points at the point this far along the tightened path [m] (> 0).
        unknown: (H, W) bool, True on UNKNOWN cells: a step into one costs ``params.unknown_cost`` (None:
            every step into a free cell costs the same, the papers' NF1).
        avoid: (H, W) bool, True on cells to avoid (the route a trap was detected on,
            ``RouteParams.avoid_cost``): a step into one costs ``avoid_cost`` (None: no such cells).
    Returns:
        PlanResult; ``ok`` False with GOAL_IN_OBSTACLE (goal cell not free) or PLANNER_NO_PATH (the wave
        from the goal does not reach the robot, even through the escape; for a goal beyond the grid with
        ``frontier_goal``: no free border cell does).
    Raises:
        ValueError: bad array, robot cell outside the grid, non-finite goal, cell_m <= 0 or
            lookahead_m <= 0.
    """
    f, start, g = _checked(free, start_rc, goal_rc_float, cell_m, lookahead_m)
    masks = {name: None if a is None else _as_free(a) for name, a in (("unknown", unknown), ("avoid", avoid))}
    for name, mask in masks.items():
        if mask is not None and mask.shape != f.shape:
            raise ValueError(f"{name} has shape {mask.shape}, free has {f.shape}")
    costs = step_costs(masks["unknown"], params.unknown_cost, masks["avoid"], avoid_cost)
    return _plan(f, start, g, costs, cell_m=cell_m, params=params, lookahead_m=lookahead_m)


def _checked(
    free: ArrayLike, start_rc: tuple[int, int], goal_rc_float: ArrayLike, cell_m: float, lookahead_m: float
) -> tuple[NDArray[np.bool_], tuple[int, int], NDArray[np.float64]]:
    """``plan``'s inputs checked: the C-contiguous free array, the robot cell, the goal as a (2,) array."""
    if not cell_m > 0.0:
        raise ValueError(f"cell_m must be > 0, got {cell_m!r}")
    if not lookahead_m > 0.0:
        raise ValueError(f"lookahead_m must be > 0, got {lookahead_m!r}")
    f = _as_free(free)
    start = _check_cell("start_rc", start_rc, f.shape)
    g = np.asarray(goal_rc_float, dtype=np.float64).reshape(2)
    if not np.all(np.isfinite(g)):
        raise ValueError(f"goal_rc_float must be finite, got {g.tolist()}")
    return f, start, g


def _plan(
    f: NDArray[np.bool_], start: tuple[int, int], g: NDArray[np.float64], costs: StepCosts | None, *,
    cell_m: float, params: Nf1Params, lookahead_m: float,
) -> PlanResult:
    """``plan`` on checked inputs (``_checked``), with the wave's step costs."""
    diagonal = params.connectivity == 8
    if params.frontier_goal and not _inside(g, f.shape):
        goal_or_none, projected = _frontier_goal(f, start, g, params, cell_m, costs), True
        if goal_or_none is None:
            return _fail(Flag.PLANNER_NO_PATH, project_goal(start, g, f.shape), projected)
        goal = goal_or_none
    else:
        goal, projected = resolve_goal(f, start, g, params.border_search_m / cell_m)
        if not f[goal]:
            return _fail(Flag.GOAL_IN_OBSTACLE, goal, projected)
    nf = _wave(f, goal[0], goal[1], start[0], start[1], params.early_exit, diagonal, costs)
    entry = start
    prefix = np.zeros((0, 2), dtype=np.int32)
    if not np.isfinite(nf[start]):
        target = None if f[start] else _escape_target(nf, start, params.escape_m / cell_m)
        if target is None:
            return _fail(Flag.PLANNER_NO_PATH, goal, projected)
        entry = target
        prefix = _line_cells(start[0], start[1], target[0], target[1])[:-1]
    descent = _descend(nf, f, entry[0], entry[1])
    path = np.concatenate([prefix, descent]) if prefix.shape[0] else descent
    n_escape = prefix.shape[0] if prefix.shape[0] else int(not f[start])

    tight = descent[_tighten(descent, f)].astype(np.float64)
    waypoints = np.concatenate([np.asarray([start], dtype=np.float64), tight]) if prefix.shape[0] else tight
    if waypoints.shape[0] == 1:  # robot and goal share a cell
        waypoints = np.concatenate([waypoints, waypoints])
    seg = np.diff(waypoints, axis=0)
    length_cells = float(np.hypot(seg[:, 0], seg[:, 1]).sum())
    if length_cells > 0.0:
        direction = path_direction(waypoints, lookahead_m / cell_m)
    else:  # same cell: head for the goal point itself
        d = g - 0.5 - np.asarray(start, dtype=np.float64)
        direction = float(wrap_angle(dm.atan2(d[0], d[1])))
    cost_cells = float(nf[entry]) + float(np.hypot(*(np.subtract(entry, start))))
    return PlanResult(
        ok=True, flag=Flag.NONE, goal_cell=goal, goal_projected=projected, path_cells=path, n_escape=n_escape,
        waypoints_cells=waypoints, direction_rad=direction, length_m=length_cells * cell_m,
        cost_m=cost_cells * cell_m, nodes_expanded=int(np.count_nonzero(nf < np.inf))
    )


def route_cost(waypoints: NDArray[np.float64], costs: StepCosts | None = None) -> float:
    """Cost of a polyline of cell centres [cells]: its length, each segment weighted by the mean step
    factor (``StepCosts``) of the n cells it enters (its supercover walk, first cell excepted): the wave's
    step cost, spread along the segment. Routes compared by ``Nf1Planner`` are measured this way, whatever
    the wave's connectivity."""
    w = np.asarray(waypoints, dtype=np.float64)
    seg = np.diff(w, axis=0)
    lens = np.hypot(seg[:, 0], seg[:, 1])
    if costs is None:
        return float(lens.sum())
    cells = np.rint(w).astype(np.int64)
    total = 0.0
    for i, length in enumerate(lens):  # per segment (a handful), not per cell
        line = _line_cells(cells[i, 0], cells[i, 1], cells[i + 1, 0], cells[i + 1, 1])[1:]
        factor = float(costs.of(line[:, 0], line[:, 1]).mean()) if line.shape[0] else 1.0
        total += float(length) * factor
    return total


def _beyond(end: NDArray[np.float64], goal_rc_float: NDArray[np.float64], projected: bool) -> float:
    """Straight line from a route's last cell to a goal beyond the grid [cells] (0 for a goal inside)."""
    return float(np.hypot(*(goal_rc_float - 0.5 - end))) if projected else 0.0


def _rejoin(
    free: NDArray[np.bool_], start: tuple[int, int], route: NDArray[np.int64]
) -> tuple[NDArray[np.int32], NDArray[np.float64]] | None:
    """The held route followed on from the robot cell: a straight line to the route's cell nearest the robot,
    then the rest of the route, string-pulled like a new plan (``_tighten``). Returns its raw cells and its
    waypoints, or None when that line or a cell of the rest is no longer free."""
    i = int(np.argmin(np.square(route - np.asarray(start)).sum(axis=1)))
    r, c = int(route[i, 0]), int(route[i, 1])
    rest = route[i:]
    if not free[rest[:, 0], rest[:, 1]].all() or not _visible(free, start[0], start[1], r, c):
        return None
    raw = np.concatenate([_line_cells(start[0], start[1], r, c)[:-1], rest.astype(np.int32)])
    wp = raw[_tighten(raw, free)].astype(np.float64)
    return raw, (wp if wp.shape[0] >= 2 else np.concatenate([wp, wp]))


def _route_result(
    raw: NDArray[np.int32], waypoints: NDArray[np.float64], cost_cells: float, new: PlanResult,
    lookahead_m: float, cell_m: float,
) -> PlanResult:
    """PlanResult of a held route followed on from the robot (``_rejoin``)."""
    seg = np.diff(waypoints, axis=0)
    return PlanResult(
        ok=True, flag=Flag.NONE, goal_cell=(int(raw[-1, 0]), int(raw[-1, 1])),
        goal_projected=new.goal_projected, path_cells=raw, n_escape=0, waypoints_cells=waypoints,
        direction_rad=path_direction(waypoints, lookahead_m / cell_m),
        length_m=float(np.hypot(seg[:, 0], seg[:, 1]).sum()) * cell_m, cost_m=cost_cells * cell_m,
        nodes_expanded=new.nodes_expanded
    )


def keep_route(
    free: NDArray[np.bool_],
    start: tuple[int, int],
    goal_rc_float: NDArray[np.float64],
    new: PlanResult,
    held: NDArray[np.int64],
    *,
    cell_m: float,
    route: RouteParams,
    costs: StepCosts | None = None,
) -> PlanResult:
    """Route hysteresis: ``new`` (this tick's plan, ok) unless the ``held`` route (its path cells in this
    grid, from the previous plan to the same goal) still holds and is not clearly worse: followed on from
    the robot (``_rejoin``) it is in free cells, it ends on the goal cell (a goal beyond the grid: on a free
    border cell), and its cost (``route_cost`` with the wave's step ``costs`` + the straight line
    beyond the grid) is at most ``(1 + route.route_keep_ratio) * new cost + route.route_keep_m``. Then the
    held route's PlanResult (``cost_m`` its ``route_cost``; the wave's effort in ``nodes_expanded``; its
    direction ``route.lookahead_m`` along it). Also when this tick's plan escapes from a robot cell in
    C-obstacle: a robot at the jamb of a door barely wider than itself stands in C-obstacle, and the
    escape's nearest free cell may lie behind it; the held route through the door is rejoined from the
    robot cell as from any other."""
    h, w = free.shape
    end = held[-1]
    if held.shape[0] < 2 or not free[end[0], end[1]]:
        return new
    if new.goal_projected:
        if not (end[0] in (0, h - 1) or end[1] in (0, w - 1)):
            return new
    elif (int(end[0]), int(end[1])) != new.goal_cell:
        return new
    joined = _rejoin(free, start, held)
    if joined is None:
        return new
    raw, wp = joined
    kept = route_cost(wp, costs) + _beyond(wp[-1], goal_rc_float, new.goal_projected)
    best = route_cost(new.waypoints_cells, costs) + _beyond(
        new.waypoints_cells[-1], goal_rc_float, new.goal_projected)
    if kept > (1.0 + route.route_keep_ratio) * best + route.route_keep_m / cell_m:
        return new
    return _route_result(raw, wp, kept - _beyond(wp[-1], goal_rc_float, new.goal_projected), new,
                         route.lookahead_m, cell_m)


def shifted_route(
    held: tuple[NDArray[np.int64], NDArray[np.float64]] | None, goal: NDArray[np.float64],
    shape: tuple[int, ...],
) -> NDArray[np.int64] | None:
    """A held route (its cells, the goal cell it led to) in this call's grid: the grid re-centres by whole
    cells, which moves the goal's cell coordinates by the same whole numbers; any other change of the goal,
    or a route leaving the grid, drops it (None). Shared by ``Nf1Planner`` and the tunnel planner."""
    if held is None:
        return None
    route, held_goal = held
    shift = goal - held_goal
    step = np.rint(shift)
    if np.abs(shift - step).max() > 1e-6:
        return None
    moved = route + step.astype(np.int64)
    if moved.min() < 0 or moved[:, 0].max() >= shape[0] or moved[:, 1].max() >= shape[1]:
        return None
    return moved


class Nf1Planner:
    """NF1 behind the ``planner.Planner`` protocol: C-space of the grid (a disc of the robot's inner radius
    plus ``margin_m``, ``cspace.free_cspace``), then ``plan``, then the route hysteresis (``keep_route``,
    ``RouteParams.route_keep_ratio`` / ``route_keep_m``): the planner holds the route it returned last, so
    its result is a function of the inputs and that route (both margins 0: of the inputs alone, the papers'
    NF1).

    Args:
        params: NF1 settings.
        cell_m: cell side [m].
        inflate_m: C-space dilation radius [m] (robot inner radius + C-space margin).
        unknown_is_free: plan through UNKNOWN cells.
        route: the look-ahead of the direction and the route hysteresis' margins.
    """

    def __init__(self, params: Nf1Params, *, cell_m: float, inflate_m: float, unknown_is_free: bool,
                 route: RouteParams = _ROUTE) -> None:
        self.params = params
        self.cell_m = cell_m
        self.inflate_m = inflate_m
        self.unknown_is_free = unknown_is_free
        self.route = route
        self._held: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None  # path cells, its goal
        self._cspace = CSpaceTracker(cell_m=cell_m, inflate_m=inflate_m, unknown_is_free=unknown_is_free)

    @property
    def no_path_is_no_border(self) -> bool:
        """With ``frontier_goal`` NF1 plans to the best reachable free border cell: no path to a goal beyond
        the grid means none is reachable."""
        return self.params.frontier_goal

    def reset(self) -> None:
        """Forget the held route (a new run or a new goal; a changed goal is also detected by itself)."""
        self._held = None

    def _held_route(self, goal: NDArray[np.float64], shape: tuple[int, ...]) -> NDArray[np.int64] | None:
        return shifted_route(self._held, goal, shape)

    def plan(
        self, grid_cells: NDArray[np.uint8], start_rc: tuple[int, int], goal_rc_float: ArrayLike,
        offset_rc: tuple[int, int] | None = None, avoid: NDArray[np.bool_] | None = None,
    ) -> PlanResult:
        if offset_rc is None:
            free = free_cspace(grid_cells, cell_m=self.cell_m, inflate_m=self.inflate_m,
                               unknown_is_free=self.unknown_is_free)
        else:
            free = self._cspace.free(grid_cells, offset_rc)
        p = self.params
        weighted = self.unknown_is_free and p.unknown_cost != 1.0
        unknown = (grid_cells == UNKNOWN) if weighted else None
        route = self.route
        free, start, goal = _checked(free, start_rc, goal_rc_float, self.cell_m, route.lookahead_m)
        costs = step_costs(unknown, p.unknown_cost, avoid, route.avoid_cost)  # the wave's and the routes'
        new = _plan(free, start, goal, costs, cell_m=self.cell_m, params=p, lookahead_m=route.lookahead_m)
        held = self._held_route(goal, free.shape)
        self._held = None
        if not new.ok:
            return new
        out = new
        if held is not None and (route.route_keep_ratio > 0.0 or route.route_keep_m > 0.0):
            out = keep_route(free, start, goal, new, held, cell_m=self.cell_m, route=route, costs=costs)
            if out is new and _rejoin(free, start, held) is None:
                # the held route is blocked: keep it if it clears every obstacle by one cell less
                # (hysteresis on the C-space radius, so a door barely wider than the robot that one
                # noisy jamb cell closes for a tick does not send the route round a detour and back)
                loose = free_cspace(grid_cells, cell_m=self.cell_m,
                                    inflate_m=max(self.inflate_m - self.cell_m, 0.0),
                                    unknown_is_free=self.unknown_is_free)
                out = keep_route(loose, start, goal, new, held, cell_m=self.cell_m, route=route, costs=costs)
        if out.n_escape == 0:
            self._held = (out.path_cells.astype(np.int64), goal)
        return out
