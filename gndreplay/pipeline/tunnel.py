"""Tunnel planner of the wheelchair paper (Minguez, Montesano, Montano; section III-B, Fig. 3).

The planner does not compute a path: it decides whether a *tunnel* of free space joins the robot and the
goal, and which course the first part of that tunnel takes (the reactor steers within it). It builds a
graph whose nodes are points in free space and whose arcs are straight tunnels, best-first (A*): expanding
a node places new nodes where the free space seen from it has a discontinuity or where an obstacle ends,
keeps those joined to it by a free tunnel, and the search stops when the goal is accessible from the node
being expanded. No public implementation exists; every choice below is ours and marked **choice**.

Coordinates as in ``nf1`` (which this module shares its goal handling, line-of-sight walk and route
hysteresis with): ``free[row, col]``, row along world y, col along world x; the goal in corner coordinates,
nodes and the polyline in index coordinates (cell centres); angles counter-clockwise from +col towards +row.

Choices:

* **Tunnel = segment in C-space.** The straight tunnel of the robot's width (plus a margin on each side)
  between two nodes is free iff the segment between them stays in free C-space for a disc of radius
  ``inner_radius + margin_m`` (the Minkowski sum of the segment and that disc is the tunnel). Checked
  exactly by ``nf1``'s supercover walk (every cell the segment touches), the same test NF1's string
  pulling uses. The C-space is ``cspace.free_cspace``'s, with the tunnel planner's *own* ``margin_m``
  (default half a cell, 0.025 m): a passage 0.1 m wider than the robot (edge cells 0.1 m farther apart than
  the robot's width) stays open at 5 cm cells, one as wide as the robot or narrower is closed
  (tests/test_tunnel.py, both presets).
* **Discontinuities and obstacle ends are found in C-space**, by casting ``n_rays`` rays (default 360,
  1 deg) from the node against the C-obstacles. A range jump between adjacent rays larger than ``jump_m``
  is a discontinuity (C-obstacles already contain the robot's width, so any opening left in C-space is
  wide enough; the threshold only filters ray-sampling noise along walls); a ray stopped by an obstacle
  beside a ray that reaches the grid border is where "an obstacle ends". A node goes on the far ray (the
  first ray past the corner), ``advance_m`` beyond the near range, or halfway to the far range when that is
  closer. The far ray grazes the corner, so when the tunnel to that point is blocked the ray tilted away
  from the corner by 1, 2 and 4 cells (at the corner's range) is tried, each tilt at most to the middle
  of the bundle of rays past the corner that reach that far. Why the cap: seen from the mouth of a passage
  barely wider than the robot, the rays that thread its C-space channel form a bundle of a few degrees,
  narrower than a one-cell tilt at the corner's range; the uncapped tilt jumped over the bundle onto a
  blocked ray, so no node went through and the search backed out (wheelchair_office_exit, below).
* **Passages are found in the workspace** (the paper's "discontinuity between obstacles", Fig. 3a): the
  same rays continue from their C-space end to the first obstacle cell. Where two adjacent ranges jump by
  more than the tunnel width, the gap runs from the near hit to the closest hit on the far side (within
  180 deg: a door seen from close to its wall spans more than 90 deg); a gap wider than the tunnel and at
  most ``passage_max_m`` wide gets a node in front of it on its
  axis (dilation radius + 2 cells from its waist, the free C-space cell nearest its middle) and one through
  it, as far beyond, joined to the node in front (or to the node that already took that space); passages
  are placed before the C-space nodes of the same expansion. Why: the C-space of a passage barely wider
  than the robot is a one- or two-cell waist that rays from afar almost never thread, and a straight
  tunnel through it must follow its axis. A too narrow passage gets no node (its gap is not
  wider than the tunnel) and, were a node placed, its tunnel would be blocked (Fig. 3a, nodes 2 and 3).
  **Robot in the mouth**: when the robot's own node took the space of the node in front (it stands
  between that point and the waist, maybe a cell or two off the axis), a node goes at its foot on the axis
  whatever the spacing (only for the robot's node, so no cascade), and the node through the passage joins
  it. Why: off the axis no straight tunnel threads a one-cell waist, the front node was refused, and the
  search backed out to a node behind to line up: the course reversed, and with one-cell changes of the
  grid flipped between forwards and backwards from tick to tick; the chair rocked in the door for the
  rest of the run (wheelchair_office_exit: 18 of 20 seeds timed out without this rule).
* **Rays march** in unit steps of their parameter (the samples t = 0, 1, 2, ... cells, each rounded to its
  cell), the C-space ray from the node, the workspace ray on from where the C-space one stopped. Each ray
  reads a per-ray table of flat index offsets (built once per ray count and row length, cached, built by
  ``warm_up_planners``) over a padded copy of the grid whose ring of outside cells ends the ray at the
  border: one addition and one read per sample instead of two roundings and four bound tests, 1.8 times
  faster (thread CPU time, 300 random free cells of a synthetic office), the same samples (nodes are
  integer cells; the 8 rays at 1 deg whose samples could round differently once the node's row or column
  is added, sin or cos = +-1/2, keep the rounding walk).
  Skipping samples by a distance transform (Euclidean, or a chessboard one computed once a search runs
  long) gives the same samples' answer but was slower on 400 x 400 office grids: each skip waits for the
  read before it, whereas unit-step reads pipeline, and the transform costs two passes over the grid
  (``benchmarks/planner.py``).
* **Border nodes**: when no candidate fits past an obstacle end whose far ray leaves the grid (the place a
  little past the corner is C-obstacle), a node goes on the ray's last sample, on the grid border. Why: a
  goal beyond the grid is projected onto the border, and the border column beside a wall parallel to it
  may be the only free C-space there (NF1 walks up it; a node must stand on it for a straight tunnel to
  run along it). Not complete: where the spacing rule already took the strip's foot, it still gets none.
* **"Unless the space is already taken by a node"**: a candidate whose cell lies within ``spacing_m`` of
  any node already in the graph (open or expanded) is dropped. ``spacing_m`` is capped below twice the
  dilation radius so a node never takes space on the other side of a wall (two C-free points on opposite
  sides of a wall are at least that far apart).
* **Priority** f = g + w h: g the length of the node chain from the robot, h the straight distance to the
  goal, w = ``heuristic_weight`` (1: the paper's cost, A*). Ties: the older node. The open list is scanned
  linearly (a few hundred nodes at most).
* **Goal test** on expansion (ALGORITHMS.md section 4): the search stops when the tunnel from the node being
  expanded to the goal cell is free. The robot's own node is expanded first, and when the goal is in sight
  from it nothing else is computed (no ray). The goal cell is resolved as for NF1 (a
  goal outside the grid is projected onto the border, moved to a free border cell nearby); a goal cell
  outside free C-space is GOAL_IN_OBSTACLE.
* **Robot in C-obstacle** (closer to a wall than the dilation radius): as NF1's escape, the search starts
  from the nearest free cell within ``escape_m`` and the chain begins with the straight escape segment.
* **Not reachable**: the open list empties (PLANNER_NO_PATH: no tunnel joins robot and goal, the
  supervisor goes to mND), or ``max_expansions`` nodes were expanded without reaching the goal
  (PLANNER_TIMEOUT: the search gave up; the supervisor treats it like a time-out). A search still going
  after 16 expansions first asks whether the robot's and the goal's cells lie in the same 4-connected
  component of free C-space (two breadth-first floods, one from each end, in turn: about twice the smaller
  component's size in cells) and stops with PLANNER_NO_PATH when they do not: no chain of tunnels could
  join them, and an enclosed goal (or robot) would otherwise cost the exhaustion of every node of the
  robot's region. The node search is not complete at cell level (rays sample directions, nodes keep
  their spacing): NF1 may find a way it misses; the converse cannot happen (a free tunnel chain is a
  4-connected path of free cells).
* **Complete fallback** (``complete``, on by default): when the node search fails although start and goal
  may be connected (its open list ran empty, or it reached ``max_expansions``; not when the connectivity
  check found them apart), the plan is NF1's on the same C-space (4-connected wave, the connectivity
  check's, from the goal cell the search planned to), whose string-pulled waypoints are mutually visible
  through free C-space: a chain of free tunnels, turned into the course as below. The result says so
  (``PlanResult.fallback``). Why: the failing class is a chain of one-cell waists not in line, e.g. two
  tight doors 1 m apart and 0.3 m aside of each other (tests/test_tunnel.py): a node must stand exactly
  where a straight tunnel threads both, which neither the passage nodes (one waist each) nor the rays
  find, and the search exhausted its 338-357 nodes (11 ms) to answer PLANNER_NO_PATH wrongly. The budget
  (150 expansions, about 5 ms) also caps the few long searches that do succeed (the synthetic offices'
  successes needed at most 251, p95 66). ``complete``
  False: the paper's node search alone (PLANNER_NO_PATH / PLANNER_TIMEOUT as above).
* **Route hysteresis** (``hold_route``, on by default; ``TunnelPlanner``): the planner keeps the tunnel it
  returned last (its cells, moved with the grid) while it stays free and is at most 10 % + 0.3 m longer
  than this tick's, NF1's rule and margins (``nf1.keep_route``). Why: into a U through cells not yet seen
  and back out of it are two ways of nearly equal length, and the sparse node search tips from one to the
  other with one-cell changes of the grid; the course flipped between them (u_trap, wheelchair, seed 11).
* **Tunnel and course**: the node chain is string-pulled (from each node, skip to the farthest later node
  whose tunnel is free, so the polyline is made of free tunnels); the course, the paper's "main course of
  the first part of the tunnel", is the bearing of the point ``lookahead_m`` (the stack's
  ``planner.lookahead_m``, 1 m) along the polyline, as NF1's instantaneous direction (``nf1.path_direction``).
  Why not the direction of the first tunnel: the first tunnel may be a step of a cell or two (onto a
  passage's axis, above), whose direction is sideways. The stack puts the reactor's target
  ``lookahead_m`` along the course.

Cost (``benchmarks/planner.py``, one core): a plan is the C-space (about 0.3-0.5 ms on 400 x 400), plus,
unless the goal is in sight, about 30 us per expansion (360 rays, about 60 % of it; the rest the passage and
corner candidates and their tunnels), plus one connectivity check (below 1 ms) in searches longer than 16
expansions, plus NF1's plan (about 1 ms) when the fallback runs: at most about 7 ms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from itertools import pairwise

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from ..geometry import wrap_angle
from ..types import Flag
from .cspace import CSpaceTracker, free_cspace
from .model import FREE, OCCUPIED, UNKNOWN
from .nf1 import (
    Nf1Params,
    _line_cells,
    _visible,
    keep_route,
    nearest_true,
    path_direction,
    resolve_goal,
    shifted_route,
)
from .nf1 import plan as nf1_plan
from .planner import PlanResult, RouteParams

__all__ = ["TunnelParams", "TunnelPlanner", "tunnel_plan", "warm_up_planners"]

# search outcomes of the kernel (_DISCONNECTED: the connectivity check found start and goal apart)
_FOUND, _EXHAUSTED, _BUDGET, _DISCONNECTED = 0, 1, 2, 3
# expansions without the goal before the search asks whether start and goal are connected at all
_CHECK_AFTER = 16
# the course looks this far along the tunnel polyline, and a held tunnel keeps, by every planner's default
_ROUTE = RouteParams()
_LOOKAHEAD_M = _ROUTE.lookahead_m


@dataclass(frozen=True, slots=True)
class TunnelParams:
    """Settings of the tunnel planner (see the module notes for what each choice means).

    Attributes:
        margin_m: added on each side of the robot's width: tunnels are C-space segments for a disc of radius
            inner radius + margin_m [m].
        n_rays: rays cast from a node to find discontinuities (evenly spaced over 360 deg).
        jump_m: range jump between adjacent rays that counts as a discontinuity [m].
        advance_m: a new node goes this far beyond the near side of the discontinuity [m].
        passage_max_m: workspace gaps between two obstacles up to this wide (and wider than the tunnel)
            get a node in front of them on their axis and one through them [m].
        spacing_m: a candidate this close to an existing node is not placed [m]; used capped at twice the
            dilation radius (inner radius + margin_m) minus one cell.
        max_expansions: expansions before the node search gives up (PLANNER_TIMEOUT, or with ``complete``
            the complete fallback).
        heuristic_weight: priority g + heuristic_weight * h; 1 is the paper's A*, larger values expand
            fewer nodes for a longer tunnel.
        escape_m: how far the search may start from the robot cell when the robot stands in C-obstacle [m]
            (as ``Nf1Params.escape_m``).
        border_search_m: a projected goal on a C-obstacle border cell moves to the nearest free border
            cell within this distance [m] (as ``Nf1Params.border_search_m``).
        complete: when the node search fails (open list empty, or ``max_expansions`` reached) although
            the free C-space joins robot and goal, the tunnel polyline is NF1's string-pulled path on the
            same C-space (``PlanResult.fallback``); False: the paper's node search alone.
        hold_route: ``TunnelPlanner`` keeps the tunnel it returned last unless this tick's is clearly
            shorter (NF1's route hysteresis, ``nf1.keep_route``); False: every tick plans afresh, the paper's.
    """

    margin_m: float = 0.025
    n_rays: int = 360
    jump_m: float = 0.4
    advance_m: float = 0.6
    passage_max_m: float = 1.5
    spacing_m: float = 0.5
    max_expansions: int = 150
    heuristic_weight: float = 1.0
    escape_m: float = 0.5
    border_search_m: float = 1.0
    complete: bool = True
    hold_route: bool = True

    def __post_init__(self) -> None:
        for name in ("jump_m", "advance_m", "spacing_m", "passage_max_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("margin_m", "escape_m", "border_search_m"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.n_rays < 8:
            raise ValueError(f"n_rays must be >= 8, got {self.n_rays!r}")
        if not self.heuristic_weight >= 1.0:
            raise ValueError(f"heuristic_weight must be >= 1, got {self.heuristic_weight!r}")
        if self.max_expansions < 1:
            raise ValueError(f"max_expansions must be >= 1, got {self.max_expansions!r}")


# ---------------------------------------------------------------------------------------------------------
# numba kernels


@njit(cache=True)
def _march(
    mask: NDArray[np.bool_], r0: float, c0: float, dr: float, dc: float, t: float
) -> tuple[float, bool]:
    """Walk a ray over the samples t, t + 1, ... while ``mask`` holds; returns the last sample inside and
    whether the grid border stopped it. Unit steps on purpose: skipping samples by a distance transform
    costs the transform (two passes over the grid) and a random read per step of an int array four times
    the mask's size, more than it saves on 400 x 400 grids (``benchmarks/planner.py``)."""
    n_r, n_c = mask.shape
    last = t
    while True:
        ri = math.floor(r0 + t * dr + 0.5)
        ci = math.floor(c0 + t * dc + 0.5)
        if ri < 0 or ri >= n_r or ci < 0 or ci >= n_c:
            return last, True
        if not mask[ri, ci]:
            return last, False
        last = t
        t += 1.0


# bits of the padded grid the rays walk: free C-space, workspace clear; the ring outside the grid is _OUT
_FREE_BIT, _CLEAR_BIT, _OUT = 1, 2, 4


@njit(cache=True)
def _ray_table(
    n_rays: int, stride: int, n_t: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int32], NDArray[np.bool_]]:
    """Directions and samples of the ``n_rays`` rays: (sin, cos, offsets, exact).

    ``offsets[k, t]`` (t < ``n_t``) is the index offset, in a flat grid of row length ``stride``, of
    ``_march``'s sample t of ray k from an integer cell: floor(t sin + 0.5) rows and floor(t cos + 0.5)
    columns, the same rounding as ``_march`` except where t sin or t cos lies within 1e-9 of a half-integer
    (adding the cell's row or column could round the other way); rays with such a sample are flagged
    ``exact`` and walk with ``_march`` itself (at 1 deg: the 8 rays with sin or cos = +-1/2)."""
    dtheta = 2.0 * math.pi / n_rays
    theta = np.arange(n_rays) * dtheta
    sin_t = np.empty(n_rays)
    cos_t = np.empty(n_rays)
    for k in range(n_rays):
        sin_t[k] = dm.sin(theta[k])
        cos_t[k] = dm.cos(theta[k])
    offsets = np.empty((n_rays, n_t), np.int32)
    exact = np.zeros(n_rays, np.bool_)
    for k in range(n_rays):
        for t in range(n_t):
            y = t * sin_t[k] + 0.5
            x = t * cos_t[k] + 0.5
            fy = math.floor(y)
            fx = math.floor(x)
            offsets[k, t] = fy * stride + fx
            if min(y - fy, fy + 1.0 - y) < 1e-9 or min(x - fx, fx + 1.0 - x) < 1e-9:
                exact[k] = True
    return sin_t, cos_t, offsets, exact


@njit(cache=True)
def _ray_state(free: NDArray[np.bool_], clear: NDArray[np.bool_]) -> NDArray[np.uint8]:
    """Flat (R + 2) * (C + 2) grid padded by a ring of _OUT cells, with _FREE_BIT where ``free`` and
    _CLEAR_BIT where ``clear``: a ray's samples move at most one cell per step along each axis, so its
    first sample out of the grid lands on the ring."""
    n_r, n_c = free.shape
    state = np.full((n_r + 2) * (n_c + 2), _OUT, np.uint8)
    for r in range(n_r):
        row = (r + 1) * (n_c + 2) + 1
        for c in range(n_c):
            state[row + c] = _FREE_BIT * free[r, c] + _CLEAR_BIT * clear[r, c]
    return state


@njit(cache=True)
def _march_table(state: NDArray[np.uint8], base: int, offsets: NDArray[np.int32], t: int, bit: int) -> tuple[
    float, bool
]:
    """``_march`` from the cell at flat index ``base`` of the padded grid, while ``bit`` is set, by the
    ray's offsets (an addition and a read per sample instead of two roundings and four bound tests)."""
    last = t
    while True:
        v = state[base + offsets[t]]
        if not v & bit:
            return float(last), v == _OUT
        last = t
        t += 1


@njit(cache=True)
def _cast_rays(
    free: NDArray[np.bool_], clear: NDArray[np.bool_], state: NDArray[np.uint8], r0: int, c0: int,
    sin_t: NDArray[np.float64], cos_t: NDArray[np.float64], offsets: NDArray[np.int32],
    exact: NDArray[np.bool_],
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.bool_]]:
    """Range [cells] of each ray from the cell (r0, c0) to its last sample in free C-space and, continuing
    from there, to its last sample clear of obstacles, and for each whether the grid border stopped it.
    Rays flagged ``exact`` walk with ``_march``, the others by their offsets over ``state`` (the padded grid
    of ``_ray_state``): the same samples."""
    n = sin_t.shape[0]
    rng = np.empty(n, np.float64)
    border = np.zeros(n, np.bool_)
    wrng = np.empty(n, np.float64)
    wborder = np.zeros(n, np.bool_)
    base = (r0 + 1) * (free.shape[1] + 2) + c0 + 1
    for k in range(n):
        if exact[k]:
            rng[k], border[k] = _march(free, float(r0), float(c0), sin_t[k], cos_t[k], 0.0)
        else:
            rng[k], border[k] = _march_table(state, base, offsets[k], 0, _FREE_BIT)
        if border[k]:
            wrng[k], wborder[k] = rng[k], True
        elif exact[k]:
            wrng[k], wborder[k] = _march(clear, float(r0), float(c0), sin_t[k], cos_t[k], rng[k])
        else:
            wrng[k], wborder[k] = _march_table(state, base, offsets[k], int(rng[k]), _CLEAR_BIT)
    return rng, border, wrng, wborder


@njit(cache=True)
def _connected(free: NDArray[np.bool_], ar: int, ac: int, br: int, bc: int) -> bool:
    """Cells a and b (both free) are joined by a 4-connected path of free cells. Two breadth-first floods,
    one from each end, advance in turn: they meet when a path exists, and otherwise the flood of the
    smaller component runs dry, after about twice its size in cells."""
    n_r, n_c = free.shape
    label = np.zeros(n_r * n_c, np.int8)
    qa = np.empty(n_r * n_c, np.int32)
    qb = np.empty(n_r * n_c, np.int32)
    label[ar * n_c + ac] = 1
    label[br * n_c + bc] = 2
    qa[0] = ar * n_c + ac
    qb[0] = br * n_c + bc
    heads = np.zeros(2, np.int64)
    tails = np.ones(2, np.int64)
    while True:
        for side in range(2):
            q = qa if side == 0 else qb
            if heads[side] == tails[side]:
                return False
            i = q[heads[side]]
            heads[side] += 1
            r, c = i // n_c, i % n_c
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                rr, cc = r + dr, c + dc
                if rr < 0 or rr >= n_r or cc < 0 or cc >= n_c or not free[rr, cc]:
                    continue
                j = rr * n_c + cc
                if label[j] == 0:
                    label[j] = side + 1
                    q[tails[side]] = j
                    tails[side] += 1
                elif label[j] != side + 1:
                    return True


@njit(cache=True)
def _stamp(taken: NDArray[np.bool_], r: int, c: int, rad: int) -> None:
    """Mark the disc of radius ``rad`` [cells] around (r, c) as taken."""
    n_r, n_c = taken.shape
    for dr in range(-rad, rad + 1):
        rr = r + dr
        if rr < 0 or rr >= n_r:
            continue
        half = int(math.sqrt(rad * rad - dr * dr))
        for cc in range(max(c - half, 0), min(c + half + 1, n_c)):
            taken[rr, cc] = True


@njit(cache=True)
def _try_add(
    free: NDArray[np.bool_], taken: NDArray[np.bool_], nr: NDArray[np.int32], nc: NDArray[np.int32],
    parent: NDArray[np.int32], g: NDArray[np.float64], f: NDArray[np.float64], n: int, par: int,
    rr: int, cc: int, goal_r: int, goal_c: int, spacing: int, hw: float, spaced: bool = True,
) -> int:
    """Add node (rr, cc) under ``par`` if it is in the grid, free, not taken (unless ``spaced`` is False)
    and joined to ``par`` by a free tunnel; returns the new node count (``n`` unchanged when it was not
    added)."""
    if rr < 0 or rr >= free.shape[0] or cc < 0 or cc >= free.shape[1] or n >= nr.shape[0]:
        return n
    if (spaced and taken[rr, cc]) or not free[rr, cc] or not _visible(free, nr[par], nc[par], rr, cc):
        return n
    nr[n] = rr
    nc[n] = cc
    parent[n] = par
    g[n] = g[par] + math.hypot(rr - nr[par], cc - nc[par])
    f[n] = g[n] + hw * math.hypot(goal_r - rr, goal_c - cc)
    _stamp(taken, rr, cc, spacing)
    return n + 1


@njit(cache=True)
def _nearest_node(nr: NDArray[np.int32], nc: NDArray[np.int32], n: int, r: int, c: int) -> int:
    """Index of the node nearest (r, c) among the first ``n`` (ties: the oldest)."""
    best, bd = 0, np.inf
    for i in range(n):
        d = (nr[i] - r) ** 2 + (nc[i] - c) ** 2
        if d < bd:
            best, bd = i, d
    return best


@njit(cache=True)
def _away(near: int, far: int) -> int:
    """+-1: the ray index step from ``near`` towards ``far`` (adjacent, modulo the ray count)."""
    step = far - near
    if step > 1:
        return -1
    if step < -1:
        return 1
    return step


@njit(cache=True)
def _search(
    free: NDArray[np.bool_], clear: NDArray[np.bool_], start_r: int, start_c: int, g0: float,
    goal_r: int, goal_c: int, n_rays: int, rho: float, jump: float, advance: float, passage_max: float,
    spacing: int, max_expansions: int, hw: float, check_after: int, sin_t: NDArray[np.float64],
    cos_t: NDArray[np.float64], offsets: NDArray[np.int32], exact: NDArray[np.bool_],
) -> tuple[int, int, int, NDArray[np.int32], NDArray[np.int32], NDArray[np.int32], NDArray[np.float64], int]:
    """A* over free-space nodes from (start_r, start_c) (chain length ``g0`` already travelled) to the goal
    cell; ``free`` is the C-space, ``clear`` the workspace (not an obstacle), lengths in cells. Returns
    (status, n_expanded, goal_parent, node rows, node cols, parents, g, n): the goal is accessible from node
    ``goal_parent`` when status is _FOUND. After ``check_after`` expansions without the goal, a search
    whose start and goal cells lie in different components of the free C-space stops (_DISCONNECTED: no
    chain of tunnels can join them, whatever the rays would still find); _EXHAUSTED: the open list ran
    empty, _BUDGET: ``max_expansions`` nodes were expanded."""
    cap = min(max_expansions * (n_rays + 1) + 1, free.shape[0] * free.shape[1] + 1)
    nr = np.empty(cap, np.int32)
    nc = np.empty(cap, np.int32)
    parent = np.empty(cap, np.int32)
    g = np.empty(cap, np.float64)
    f = np.empty(cap, np.float64)
    closed = np.zeros(cap, np.bool_)
    taken = np.zeros(free.shape, np.bool_)
    dtheta = 2.0 * math.pi / n_rays
    # the passage search's bound: the distance from a point at range 1 on a ray to a ray (j + 1) steps away,
    # sin of the angle up to 90 deg, then 1 (the nearest point of the other ray is the origin)
    sin_j = np.empty(n_rays // 2)
    for j in range(n_rays // 2):
        sin_j[j] = dm.sin(min((j + 1) * dtheta, 0.5 * math.pi))
    nr[0] = start_r
    nc[0] = start_c
    parent[0] = -1
    g[0] = g0
    f[0] = g0 + hw * math.hypot(goal_r - start_r, goal_c - start_c)
    n = 1
    if _visible(free, start_r, start_c, goal_r, goal_c):  # the goal in sight: no ray needed
        return _FOUND, 1, 0, nr, nc, parent, g, n
    _stamp(taken, start_r, start_c, spacing)
    state = _ray_state(free, clear)
    n_expanded = 0
    width = 2.0 * rho
    while True:
        best = -1
        bf = np.inf
        for i in range(n):
            if not closed[i] and f[i] < bf:
                bf = f[i]
                best = i
        if best < 0:
            return _EXHAUSTED, n_expanded, -1, nr, nc, parent, g, n
        if n_expanded >= max_expansions:
            return _BUDGET, n_expanded, -1, nr, nc, parent, g, n
        if n_expanded == check_after and not _connected(free, start_r, start_c, goal_r, goal_c):
            return _DISCONNECTED, n_expanded, -1, nr, nc, parent, g, n
        closed[best] = True
        n_expanded += 1
        r0 = int(nr[best])
        c0 = int(nc[best])
        if _visible(free, r0, c0, goal_r, goal_c):
            return _FOUND, n_expanded, best, nr, nc, parent, g, n
        rng, border, wr, wb = _cast_rays(free, clear, state, r0, c0, sin_t, cos_t, offsets, exact)
        # workspace gaps between two obstacles, wider than the robot: a node in front of the passage, on
        # its axis, and one through it (a straight tunnel through a tight passage must follow its axis);
        # first, so that the space in front of a passage goes to its axis node
        for k in range(n_rays):
            k1 = (k + 1) % n_rays
            if wb[k] and wb[k1]:
                continue
            if wb[k] != wb[k1]:
                near, far = (k1, k) if wb[k] else (k, k1)
            elif abs(wr[k] - wr[k1]) > width:
                near, far = (k, k1) if wr[k] < wr[k1] else (k1, k)
            else:
                continue
            step = _away(near, far)
            a_r = r0 + (wr[near] + 1.0) * sin_t[near]  # the obstacle the near ray hit
            a_c = c0 + (wr[near] + 1.0) * cos_t[near]
            w = np.inf
            w2 = np.inf
            b_r = 0.0
            b_c = 0.0
            reach = wr[near] + 1.0
            # the other side: the hit beyond the gap closest to it, up to 180 deg away (a door seen from
            # its mouth spans more than 90 deg)
            for j in range(n_rays // 2):
                if reach * sin_j[j] > passage_max:
                    break  # every later ray passes farther than passage_max from the near hit
                kk = (far + j * step) % n_rays
                if wb[kk]:
                    continue
                p_r = r0 + (wr[kk] + 1.0) * sin_t[kk]
                p_c = c0 + (wr[kk] + 1.0) * cos_t[kk]
                if (p_r - a_r) ** 2 + (p_c - a_c) ** 2 >= w2:
                    continue  # certainly not closer (w2 exceeds w^2 by far more than rounding)
                dd = math.hypot(p_r - a_r, p_c - a_c)
                if dd < w:
                    w, b_r, b_c = dd, p_r, p_c
                    w2 = w * w * (1.0 + 1e-9)
            if not width < w <= passage_max:
                continue
            m_r = 0.5 * (a_r + b_r)
            m_c = 0.5 * (a_c + b_c)
            mi = math.floor(m_r + 0.5)
            mj = math.floor(m_c + 0.5)
            if not (0 <= mi < free.shape[0] and 0 <= mj < free.shape[1]) or not clear[mi, mj]:
                continue  # not open between its sides (a wall seen at a grazing angle)
            best_d = np.inf  # snap to the waist: the free C-space cell nearest the middle (hits are +-1 cell)
            wi, wj = -1, -1
            for ii in range(max(mi - 3, 0), min(mi + 4, free.shape[0])):
                for jj in range(max(mj - 3, 0), min(mj + 4, free.shape[1])):
                    dd = (ii - m_r) ** 2 + (jj - m_c) ** 2
                    if free[ii, jj] and dd < best_d:
                        best_d, wi, wj = dd, ii, jj
            if wi < 0:
                continue  # closed in C-space: the robot does not fit
            m_r, m_c = float(wi), float(wj)
            u_r = -(b_c - a_c) / w  # unit normal of the gap, towards the expanded node
            u_c = (b_r - a_r) / w
            if u_r * (r0 - m_r) + u_c * (c0 - m_c) < 0.0:
                u_r, u_c = -u_r, -u_c
            off = rho + 2.0
            q_r = math.floor(m_r + off * u_r + 0.5)
            q_c = math.floor(m_c + off * u_c + 0.5)
            t_r = math.floor(m_r - off * u_r + 0.5)
            t_c = math.floor(m_c - off * u_c + 0.5)
            m = _try_add(free, taken, nr, nc, parent, g, f, n, best, q_r, q_c, goal_r, goal_c, spacing, hw)
            s_ax = u_r * (r0 - m_r) + u_c * (c0 - m_c)  # how far the expanded node stands in front of it
            if m == n and best == 0 and s_ax > 0.0 and (q_r - r0) ** 2 + (q_c - c0) ** 2 <= spacing * spacing:
                # no front node because the search's root took its space: the robot stands in the passage's
                # mouth, maybe off the axis, where no straight tunnel threads a tight waist; a node at its
                # foot on the axis, whatever the spacing (else the search backs out to line up: the course
                # reverses)
                p_r = math.floor(m_r + s_ax * u_r + 0.5)
                p_c = math.floor(m_c + s_ax * u_c + 0.5)
                if p_r != r0 or p_c != c0:
                    m = _try_add(free, taken, nr, nc, parent, g, f, n, best, p_r, p_c, goal_r, goal_c,
                                 spacing, hw, False)
            if m == n and not (0 <= t_r < free.shape[0] and 0 <= t_c < free.shape[1]
                               and free[t_r, t_c] and not taken[t_r, t_c]):
                continue  # no node through the passage whatever its parent (spares the nearest-node scan)
            via = n if m > n else _nearest_node(nr, nc, n, q_r, q_c)  # the node in front of the passage
            n = _try_add(free, taken, nr, nc, parent, g, f, m, via, t_r, t_c, goal_r, goal_c, spacing, hw)
        # C-space discontinuities and obstacle ends: a node just past the corner, on the far side
        for k in range(n_rays):
            k1 = (k + 1) % n_rays
            if border[k] and border[k1]:
                continue
            if border[k] != border[k1]:  # an obstacle ends
                near, far = (k1, k) if border[k] else (k, k1)
            elif abs(rng[k] - rng[k1]) > jump:  # a discontinuity
                near, far = (k, k1) if rng[k] < rng[k1] else (k1, k)
            else:
                continue
            d = min(rng[near] + advance, 0.5 * (rng[near] + rng[far]))
            step = _away(near, far)
            prev = -1
            n_before = n
            # the rays past the corner that reach d: a tilt stays within their bundle, at most to its middle
            # (a channel narrower than the tilt, e.g. a door barely wider than the robot seen from its mouth,
            # is threaded by its middle ray, not jumped over)
            max_tilt = math.floor(dm.atan2(4.0, max(rng[near], 1.0)) / dtheta + 0.5)
            run = 1
            while run <= 2 * max_tilt and rng[(far + step * run) % n_rays] >= d:
                run += 1
            for lateral in (0.0, 1.0, 2.0, 4.0):  # the far ray grazes the corner: tilt away by a few cells
                tilt = math.floor(dm.atan2(lateral, max(rng[near], 1.0)) / dtheta + 0.5)
                tilt = min(tilt, (run - 1) // 2)
                kk = (far + step * tilt) % n_rays
                if kk == prev:
                    continue
                prev = kk
                if rng[kk] < d:
                    break
                rr = math.floor(r0 + d * sin_t[kk] + 0.5)
                cc = math.floor(c0 + d * cos_t[kk] + 0.5)
                if 0 <= rr < free.shape[0] and 0 <= cc < free.shape[1] and taken[rr, cc]:
                    break
                m = _try_add(free, taken, nr, nc, parent, g, f, n, best, rr, cc, goal_r, goal_c, spacing, hw)
                if m > n:
                    n = m
                    break
            if n == n_before and border[far]:  # no room short of the border: a node on the border itself
                rr = math.floor(r0 + rng[far] * sin_t[far] + 0.5)
                cc = math.floor(c0 + rng[far] * cos_t[far] + 0.5)
                n = _try_add(free, taken, nr, nc, parent, g, f, n, best, rr, cc, goal_r, goal_c, spacing, hw)

@njit(cache=True)
def _string_pull(free: NDArray[np.bool_], chain: NDArray[np.int32], first_free: bool) -> NDArray[np.int64]:
    """Indices of the chain kept: from each kept node, the farthest later node whose tunnel is free. The
    escape segment (robot cell in C-obstacle: ``first_free`` False) is kept as it is."""
    m = chain.shape[0]
    keep = np.empty(m, np.int64)
    keep[0] = 0
    k = 1
    i = 0
    if not first_free and m > 1:
        keep[1] = 1
        k = 2
        i = 1
    while i < m - 1:
        j = m - 1
        while j > i + 1 and not _visible(free, chain[i, 0], chain[i, 1], chain[j, 0], chain[j, 1]):
            j -= 1
        keep[k] = j
        k += 1
        i = j
    return keep[:k].copy()


# ray tables by (ray count, padded row length), for rays of up to their length in samples (grown on demand)
_TABLES: dict[
    tuple[int, int], tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int32], NDArray[np.bool_]]
] = {}


def _rays(
    n_rays: int, shape: tuple[int, ...]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int32], NDArray[np.bool_]]:
    """``_ray_table`` for a grid of ``shape`` (a ray from a cell leaves it within the diagonal plus one
    sample), cached: one table serves every plan on grids of that row length."""
    key = (n_rays, shape[1] + 2)
    n_t = math.ceil(math.hypot(shape[0], shape[1])) + 2
    table = _TABLES.get(key)
    if table is None or table[2].shape[1] < n_t:
        table = _ray_table(n_rays, key[1], n_t)
        for a in table:
            a.flags.writeable = False
        _TABLES[key] = table
    return table


# ---------------------------------------------------------------------------------------------------------
# public functions


def _result(
    ok: bool, flag: Flag, goal: tuple[int, int], projected: bool, *, expanded: int, width_m: float,
    chain: NDArray[np.int32] | None = None, n_escape: int = 0, waypoints: NDArray[np.float64] | None = None,
    direction: float = math.nan, length_m: float = math.nan, cost_m: float = math.nan,
) -> PlanResult:
    return PlanResult(
        ok=ok, flag=flag, goal_cell=goal, goal_projected=projected,
        path_cells=np.zeros((0, 2), np.int32) if chain is None else chain, n_escape=n_escape,
        waypoints_cells=np.zeros((0, 2), np.float64) if waypoints is None else waypoints,
        direction_rad=direction, length_m=length_m, cost_m=cost_m, nodes_expanded=expanded, width_m=width_m
    )


def _complete(
    free: NDArray[np.bool_], start: tuple[int, int], goal: tuple[int, int], projected: bool, expanded: int,
    width_m: float, cell_m: float, params: TunnelParams, lookahead_m: float,
) -> PlanResult:
    """The complete fallback: NF1 (4-connected wave, as the connectivity check, from the goal cell the
    node search planned to; its own escape when the robot is in C-obstacle) on the same C-space. Its
    string-pulled waypoints are mutually visible through free C-space: a chain of free tunnels."""
    nf1 = Nf1Params(connectivity=4, escape_m=params.escape_m, frontier_goal=False)
    nf = nf1_plan(free, start, (goal[0] + 0.5, goal[1] + 0.5), cell_m=cell_m, params=nf1,
                  lookahead_m=lookahead_m)
    if not nf.ok:
        return _result(False, Flag.PLANNER_NO_PATH, goal, projected, expanded=expanded, width_m=width_m)
    return PlanResult(
        ok=True, flag=Flag.NONE, goal_cell=goal, goal_projected=projected, path_cells=nf.path_cells,
        n_escape=nf.n_escape, waypoints_cells=nf.waypoints_cells, direction_rad=nf.direction_rad,
        length_m=nf.length_m, cost_m=nf.cost_m, nodes_expanded=expanded, width_m=width_m, fallback=True
    )


def tunnel_plan(
    grid_cells: NDArray[np.uint8],
    start_rc: tuple[int, int],
    goal_rc_float: ArrayLike,
    *,
    cell_m: float,
    radius_m: float,
    unknown_is_free: bool = True,
    params: TunnelParams = TunnelParams(),
    lookahead_m: float = _LOOKAHEAD_M,
) -> PlanResult:
    """Search a chain of free tunnels from the robot cell to the goal (see the module notes).

    Args:
        grid_cells: (H, W) grid of UNKNOWN / FREE / OCCUPIED cells.
        start_rc: (row, col) robot cell.
        goal_rc_float: (row, col) goal in corner coordinates; outside the grid it is projected onto the
            border along the robot-goal line.
        cell_m: cell side [m].
        radius_m: the C-space dilation radius [m] (robot inner radius + margin); the tunnel width is twice
            it.
        unknown_is_free: UNKNOWN cells are free (else obstacles), as for NF1's C-space.
        params: planner settings.
        lookahead_m: the course looks this far along the tunnel polyline [m] (> 0).
    Returns:
        PlanResult: ``waypoints_cells`` the string-pulled tunnel polyline (robot cell first, goal cell
        last), ``direction_rad`` the course (bearing of the point ``lookahead_m`` along it), ``width_m`` the
        tunnel width, ``nodes_expanded``, ``fallback`` (the polyline is NF1's, ``params.complete``);
        ``ok`` False with GOAL_IN_OBSTACLE, PLANNER_NO_PATH (no tunnel joins robot and goal) or, without
        ``params.complete``, PLANNER_TIMEOUT (``max_expansions`` reached).
    Raises:
        ValueError: bad grid, robot cell outside the grid, non-finite goal, cell_m <= 0, radius_m < 0 or
            lookahead_m <= 0.
    """
    f, clear = _spaces(grid_cells, cell_m, radius_m, unknown_is_free, lookahead_m)
    return _plan_on(f, clear, start_rc, goal_rc_float, cell_m=cell_m, radius_m=radius_m, params=params,
                    lookahead_m=lookahead_m)


def _spaces(
    grid_cells: NDArray[np.uint8], cell_m: float, radius_m: float, unknown_is_free: bool, lookahead_m: float,
    free: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """``tunnel_plan``'s checks, then the free C-space (``free`` when the caller has it) and the workspace
    cells clear of obstacles."""
    if not cell_m > 0.0:
        raise ValueError(f"cell_m must be > 0, got {cell_m!r}")
    if not lookahead_m > 0.0:
        raise ValueError(f"lookahead_m must be > 0, got {lookahead_m!r}")
    cells = np.asarray(grid_cells)
    if cells.ndim != 2 or cells.dtype != np.uint8:
        raise ValueError(f"grid_cells must be a 2-D uint8 array, got shape {cells.shape} dtype {cells.dtype}")
    if free is None:
        free = free_cspace(cells, cell_m=cell_m, inflate_m=radius_m, unknown_is_free=unknown_is_free)
    clear = cells != OCCUPIED
    if not unknown_is_free:
        clear &= cells != UNKNOWN
    return free, clear


def _plan_on(
    f: NDArray[np.bool_], clear: NDArray[np.bool_], start_rc: tuple[int, int], goal_rc_float: ArrayLike, *,
    cell_m: float, radius_m: float, params: TunnelParams, lookahead_m: float,
) -> PlanResult:
    """``tunnel_plan`` on its C-space ``f`` and clear cells ``clear`` (``_spaces``)."""
    start = (int(start_rc[0]), int(start_rc[1]))
    if not (0 <= start[0] < f.shape[0] and 0 <= start[1] < f.shape[1]):
        raise ValueError(f"start_rc {start} is outside the grid of shape {f.shape}")
    g = np.asarray(goal_rc_float, dtype=np.float64).reshape(2)
    width_m = 2.0 * radius_m
    goal, projected = resolve_goal(f, start, g, params.border_search_m / cell_m)
    if not f[goal]:
        return _result(False, Flag.GOAL_IN_OBSTACLE, goal, projected, expanded=0, width_m=width_m)

    root = start
    if not f[start]:
        escape = nearest_true(f, start, params.escape_m / cell_m)
        if escape is None:
            return _result(False, Flag.PLANNER_NO_PATH, goal, projected, expanded=0, width_m=width_m)
        root = escape
    g0 = math.hypot(root[0] - start[0], root[1] - start[1])
    status, expanded, last, nr, nc, parent, gs, _ = _search(
        f, clear, root[0], root[1], g0, goal[0], goal[1], params.n_rays, radius_m / cell_m,
        params.jump_m / cell_m, params.advance_m / cell_m, params.passage_max_m / cell_m,
        max(min(int(params.spacing_m / cell_m), int(2.0 * radius_m / cell_m) - 1), 1), params.max_expansions,
        params.heuristic_weight, _CHECK_AFTER, *_rays(params.n_rays, f.shape),
    )
    if status != _FOUND:
        if params.complete and status != _DISCONNECTED:
            return _complete(f, start, goal, projected, expanded, width_m, cell_m, params, lookahead_m)
        flag = Flag.PLANNER_TIMEOUT if status == _BUDGET else Flag.PLANNER_NO_PATH
        return _result(False, flag, goal, projected, expanded=expanded, width_m=width_m)

    idx = [last]
    while parent[idx[-1]] >= 0:
        idx.append(int(parent[idx[-1]]))
    nodes = np.stack([nr[idx[::-1]], nc[idx[::-1]]], axis=1)
    prefix = [start] if root != start else []
    chain = np.asarray([*prefix, *map(tuple, nodes), goal], dtype=np.int32)
    n_escape = 1 if prefix else int(not f[start])
    waypoints = chain[_string_pull(f, chain, not prefix)].astype(np.float64)
    cost_cells = float(gs[last]) + math.hypot(goal[0] - nr[last], goal[1] - nc[last])
    seg = np.diff(waypoints, axis=0)
    length_cells = float(np.hypot(seg[:, 0], seg[:, 1]).sum())
    if length_cells > 0.0:
        direction = path_direction(waypoints, lookahead_m / cell_m)
    else:  # robot and goal share a cell (two equal waypoints): head for the goal point itself
        d = g - 0.5 - np.asarray(start, dtype=np.float64)
        direction = float(wrap_angle(dm.atan2(d[0], d[1])))
    return _result(
        True, Flag.NONE, goal, projected, expanded=expanded, width_m=width_m, chain=chain,
        n_escape=n_escape, waypoints=waypoints, direction=direction, length_m=length_cells * cell_m,
        cost_m=cost_cells * cell_m,
    )


def _dense(waypoints: NDArray[np.float64]) -> NDArray[np.int64]:
    """The cells a polyline of cell centres walks through (supercover of each segment), first to last."""
    w = waypoints.astype(np.int64)
    parts = [_line_cells(int(a[0]), int(a[1]), int(b[0]), int(b[1]))[1:] for a, b in pairwise(w)]
    return np.concatenate([w[:1], *parts]).astype(np.int64)


class TunnelPlanner:
    """The tunnel planner behind the ``planner.Planner`` protocol: ``tunnel_plan`` on its own C-space (a
    disc of the robot's inner radius plus ``params.margin_m``), then, with ``params.hold_route``, NF1's route
    hysteresis (``nf1.keep_route``, its margins from ``route``: the tunnel returned last is kept, followed on
    from the robot and string-pulled, while its cells stay free and it is at most 10 % + 0.3 m longer than
    this tick's, by default; lengths only, UNKNOWN cells cost as free ones, as in the node search). Why:
    two ways of nearly equal length (into a U through unseen cells, or back out) and a sparse node search
    that one-cell changes of the grid tip from one to the other; the course flipped between them from tick
    to tick (u_trap, wheelchair). The result is a function of the inputs and the held tunnel.

    Args:
        params: tunnel planner settings.
        cell_m: cell side [m].
        inner_radius_m: the robot's inner radius (half its width for a rectangle) [m].
        unknown_is_free: plan through UNKNOWN cells.
        route: the course is the bearing of the point ``route.lookahead_m`` along the tunnel polyline [m];
            the held tunnel keeps by ``route.route_keep_ratio`` / ``route_keep_m`` (the stack's
            ``[planner]`` settings, as NF1's, so both planners look and hold alike).
    """

    no_path_is_no_border = False
    """It plans to one border cell for a goal beyond the grid (``planner.Planner``)."""

    def __init__(
        self, params: TunnelParams, *, cell_m: float, inner_radius_m: float, unknown_is_free: bool,
        route: RouteParams = _ROUTE,
    ) -> None:
        self.params = params
        self.cell_m = cell_m
        self.radius_m = inner_radius_m + params.margin_m
        self.unknown_is_free = unknown_is_free
        self.lookahead_m = route.lookahead_m
        self.route = route
        self._held: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None  # route cells, its goal
        self._cspace = CSpaceTracker(cell_m=cell_m, inflate_m=self.radius_m, unknown_is_free=unknown_is_free)

    def reset(self) -> None:
        """Forget the held tunnel (a new run or a new goal; a changed goal is also detected by itself)."""
        self._held = None

    def plan(
        self, grid_cells: NDArray[np.uint8], start_rc: tuple[int, int], goal_rc_float: ArrayLike,
        offset_rc: tuple[int, int] | None = None,
    ) -> PlanResult:
        free = None if offset_rc is None else self._cspace.free(grid_cells, offset_rc)
        f, clear = _spaces(grid_cells, self.cell_m, self.radius_m, self.unknown_is_free, self.lookahead_m,
                           free)
        new = _plan_on(f, clear, start_rc, goal_rc_float, cell_m=self.cell_m, radius_m=self.radius_m,
                       params=self.params, lookahead_m=self.lookahead_m)
        goal = np.asarray(goal_rc_float, dtype=np.float64).reshape(2)
        held = shifted_route(self._held, goal, f.shape)
        self._held = None
        if not new.ok or not self.params.hold_route:
            return new
        out = new
        if held is not None:
            start = (int(start_rc[0]), int(start_rc[1]))
            kept = keep_route(f, start, goal, new, held, cell_m=self.cell_m, route=self.route)
            if kept is not new:
                out = PlanResult(
                    ok=True, flag=Flag.NONE, goal_cell=kept.goal_cell, goal_projected=kept.goal_projected,
                    path_cells=kept.path_cells, n_escape=0, waypoints_cells=kept.waypoints_cells,
                    direction_rad=kept.direction_rad, length_m=kept.length_m, cost_m=kept.cost_m,
                    nodes_expanded=new.nodes_expanded, width_m=new.width_m, fallback=new.fallback,
                )
        if out.n_escape == 0:
            self._held = (_dense(out.waypoints_cells), goal)
        return out


def warm_up_planners(params: TunnelParams = TunnelParams(), size_cells: int = 400) -> None:
    """Compile (or load from the numba cache) the tunnel planner's kernels before the first timed tick:
    a goal in sight, a search around a wall with a passage, an enclosed goal, a robot in C-obstacle, a held
    tunnel and the complete fallback (NF1's kernels); and build the ray table of ``size_cells`` x
    ``size_cells`` grids."""
    _rays(params.n_rays, (size_cells, size_cells))
    cells = np.full((60, 60), FREE, dtype=np.uint8)
    cells[5:25, 30] = OCCUPIED
    cells[40:55, 30] = OCCUPIED
    planner = TunnelPlanner(params, cell_m=0.05, inner_radius_m=0.3, unknown_is_free=True)
    for start, goal in (((30, 10), (30.5, 20.5)), ((20, 10), (30.5, 50.5)), ((20, 29), (20.5, 50.5)),
                        ((21, 28), (20.5, 50.5))):  # the last one again a tick later: the held tunnel
        planner.plan(cells, start, goal)
    once = TunnelPlanner(replace(params, max_expansions=1, complete=True), cell_m=0.05, inner_radius_m=0.3,
                         unknown_is_free=True)
    once.plan(cells, (20, 10), (30.5, 50.5))
    cells[40, 40:56] = cells[55, 40:56] = OCCUPIED
    cells[40:56, 40] = cells[40:56, 55] = OCCUPIED
    planner.plan(cells, (30, 10), (47.5, 47.5))
