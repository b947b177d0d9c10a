"""What a global planner is to the stack: the ``Planner`` protocol, the ``PlanResult`` it returns every tick
and the ``[planner]`` settings every planner shares (``RouteParams``).

The planners themselves (``nf1.Nf1Planner``, ``tunnel.TunnelPlanner``) implement this module; which one
runs is chosen by name in ``planners.PLANNERS``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..types import Flag

__all__ = ["AvoidMarks", "PlanResult", "Planner", "RouteParams"]


@dataclass(frozen=True, slots=True)
class RouteParams:
    """The ``[planner]`` settings every planner shares: where its course looks, and how long it holds a
    route.

    Attributes:
        lookahead_m: the instantaneous direction points at the point this far along the tightened path
            [m] (GND: "the first metre"); the stack puts the reactor's target this far along it.
        lookahead_s: the look-ahead grows with the robot's top speed: the stack uses
            ``max(lookahead_m, lookahead_s * vmax_mps)`` (``scaled_lookahead_m``). 0 (the default) keeps
            the papers' fixed metre, a slow chair's 2-3 s of travel; a fast base needs more to see a turn
            coming.
        route_keep_ratio, route_keep_m: hysteresis on the route (the planner remembers the route it
            returned): the previous route, followed on from the robot, is kept while every segment of
            it is still free, it still ends at the goal cell (or, for a goal beyond the grid, on a free
            border cell) and its cost is at most ``(1 + route_keep_ratio) * new + route_keep_m`` where
            ``new`` is the cost of this tick's route (both measured the same way: tightened polyline
            length, NF1's steps into UNKNOWN cells weighted by ``Nf1Params.unknown_cost``, plus the
            straight line from a border cell to a goal beyond the grid; ``nf1.keep_route``). A new route
            must be clearly better to replace the current one: two routes of nearly equal cost (round an
            obstacle on either side, through a door or the next one) no longer alternate as cells change
            state. Both 0: the papers' NF1, a pure function of the grid (**choice**: 0.1 and 0.3 m;
            measured: goal_in_obstacle, xr4000, seed 1, the first-metre direction flipped by about 95 deg
            and back on 4 single ticks with both 0, on none with these).
        avoid_cost, avoid_m, avoid_s: what a detected trap teaches the planner (``AvoidMarks``): the first
            ``avoid_m`` of the route the robot was following when the supervisor detected the trap, widened
            by the robot's inner radius, costs ``avoid_cost`` times as much per step for ``avoid_s``
            seconds (NF1; the tunnel planner plans without it). The trap escape alone backs the robot
            off and hands it back to the same route into the same trap: a gap that the planner's disc
            passes but the footprint cannot negotiate (a rectangle between two obstacles 0.1 m wider than
            itself, angled) held it until the time ran out. A soft cost, not an obstacle: a passage that
            is the only way stays on the route when the way round costs more. ``avoid_cost`` 1 turns
            it off (the papers' GND).
    """

    lookahead_m: float = 1.0
    route_keep_ratio: float = 0.1
    route_keep_m: float = 0.3
    lookahead_s: float = 0.0
    avoid_cost: float = 10.0
    avoid_m: float = 2.0
    avoid_s: float = 60.0

    def __post_init__(self) -> None:
        if not self.lookahead_m > 0.0:
            raise ValueError(f"lookahead_m must be > 0, got {self.lookahead_m!r}")
        if not self.lookahead_s >= 0.0:
            raise ValueError(f"lookahead_s must be >= 0, got {self.lookahead_s!r}")
        if not self.route_keep_ratio >= 0.0:
            raise ValueError(f"route_keep_ratio must be >= 0, got {self.route_keep_ratio!r}")
        if not self.route_keep_m >= 0.0:
            raise ValueError(f"route_keep_m must be >= 0, got {self.route_keep_m!r}")
        if not self.avoid_cost >= 1.0:
            raise ValueError(f"avoid_cost must be >= 1, got {self.avoid_cost!r}")
        if not self.avoid_m > 0.0:
            raise ValueError(f"avoid_m must be > 0, got {self.avoid_m!r}")
        if not self.avoid_s > 0.0:
            raise ValueError(f"avoid_s must be > 0, got {self.avoid_s!r}")


@dataclass(frozen=True, slots=True, eq=False)
class PlanResult:
    """Outcome of one planning call, NF1's or the tunnel planner's (``Planner``). A failure is a value:
    ``ok`` False, ``flag`` says why.

    Attributes:
        ok: a path from the robot cell to the goal cell exists.
        flag: Flag.NONE, Flag.GOAL_IN_OBSTACLE or Flag.PLANNER_NO_PATH (the tunnel planner also
            Flag.PLANNER_TIMEOUT when its expansion budget ran out).
        goal_cell: (row, col) of the goal cell planned to: the cell containing the goal, or for a goal
            outside the grid the free border cell chosen (``Nf1Params.frontier_goal``; with it off, the
            projection onto the border, moved to a free border cell nearby, ``border_search_m``); on
            PLANNER_NO_PATH for a goal outside the grid, the projection.
        goal_projected: the goal lay outside the grid (planned to a border cell). With ``frontier_goal``,
            PLANNER_NO_PATH and goal_projected together mean the robot reaches no free border cell
            (``reaches_border`` is False): the goal is unreachable in the model.
        path_cells: (K, 2) int32 (row, col), raw path from the robot cell to the goal cell, consecutive
            cells 8-adjacent (tunnel planner: the chain of graph nodes, robot first, goal last); empty when
            not ok.
        n_escape: how many leading cells of ``path_cells`` may be outside free C-space: 0 when the robot
            cell is free, 1 when it is C-obstacle but the wave reached it from a free neighbour, more when
            the path escapes on a straight segment (see the ``nf1`` module notes).
        waypoints_cells: (M, 2) float64 tightened path in index coordinates (cell centres), robot cell
            first, goal cell last (M >= 2: two equal rows when robot and goal share a cell), consecutive
            waypoints mutually visible through free cells (except on the escape segment); empty when
            not ok.
        direction_rad: instantaneous path direction in the grid/world frame (from the robot cell centre to
            the point ``lookahead_m`` along the tightened path, or to the goal if the path is shorter);
            nan when not ok.
        length_m: length of the tightened path [m]; nan when not ok.
        cost_m: NF1 value of the robot cell (the raw path length the wave measured, to the goal cell;
            tunnel planner: the length of the node chain; a route kept by the route hysteresis: its
            ``route_cost``) [m]; nan when not ok.
        nodes_expanded: search effort: cells the NF1 wave labelled, or nodes the tunnel planner expanded
            (also on failure).
        width_m: width of the free tunnel around ``waypoints_cells`` (tunnel planner: robot width plus
            margins); nan for NF1, whose C-space is a disc model and reports no width.
        fallback: the planner's own search failed where the free C-space joins robot and goal, and the
            path is a complete planner's stand-in (the tunnel planner: NF1's string-pulled path on the
            same C-space, ``TunnelParams.complete``; ``path_cells`` is then NF1's raw path,
            ``nodes_expanded`` still the node search's effort). The stack flags it PLANNER_FALLBACK.
    """

    ok: bool
    flag: Flag
    goal_cell: tuple[int, int]
    goal_projected: bool
    path_cells: NDArray[np.int32]
    n_escape: int
    waypoints_cells: NDArray[np.float64]
    direction_rad: float
    length_m: float
    cost_m: float
    nodes_expanded: int = 0
    width_m: float = math.nan
    fallback: bool = False


class Planner(Protocol):
    """What the stack needs from a planner: built once with its settings and the grid geometry
    (``planners.PLANNERS``), then asked every tick."""

    @property
    def no_path_is_no_border(self) -> bool:
        """Its PLANNER_NO_PATH for a goal beyond the grid already says the robot reaches no free border
        cell (NF1 with ``frontier_goal`` plans to the best reachable one). False: it plans to one border
        cell, and the stack asks the C-space whether the border is reachable at all."""
        ...

    def plan(
        self, grid_cells: NDArray[np.uint8], start_rc: tuple[int, int], goal_rc_float: ArrayLike,
        offset_rc: tuple[int, int] | None = None,
    ) -> PlanResult:
        """Plan on the robot-centred grid (UNKNOWN / FREE / OCCUPIED cells) from the robot cell to the goal
        (corner coordinates, see ``nf1.plan``). ``offset_rc``: the world cell of grid cell (0, 0), given by a
        caller that plans on one grid re-centred by whole cells tick after tick, so the planner may follow
        its C-space incrementally (``cspace.CSpaceTracker``); None computes it afresh. Optional: the stack
        passes it only to planners registered with ``follows_grid`` (``planners.PlannerSpec``).
        A planner registered with ``avoids`` also takes ``avoid``: (H, W) bool, the cells whose steps
        cost ``RouteParams.avoid_cost`` (``AvoidMarks``; None: none)."""
        ...


class AvoidMarks:
    """The routes traps were detected on (``RouteParams.avoid_cost``), held in world cells: each mark is
    the first ``avoid_m`` of the course it followed, widened by ``radius_m``, and lasts ``avoid_s``. The
    stack marks on a tick whose supervisor detected a trap and hands the planner the marks falling in the
    grid (``mask``)."""

    def __init__(self, route: RouteParams, *, cell_m: float, radius_m: float) -> None:
        self.route = route
        self.cell_m = cell_m
        r = max(math.floor(radius_m / cell_m), 0)
        dr, dc = np.mgrid[-r : r + 1, -r : r + 1]
        inside = dr * dr + dc * dc <= r * r
        self._disc = np.column_stack([dr[inside], dc[inside]]).astype(np.int64)
        self._marks: list[tuple[int, NDArray[np.int64]]] = []  # (expiry stamp [ns], world cells)

    def __bool__(self) -> bool:
        return bool(self._marks)

    def mark(self, planned: PlanResult, offset_rc: tuple[int, int], t_ns: int) -> None:
        """Mark the first ``avoid_m`` of a route until ``t_ns + avoid_s``: the tightened path
        (``PlanResult.waypoints_cells``, the course the reactor is given; the raw cells may wander round the
        robot's own C-obstacle cell first), sampled every half cell. ``offset_rc``: the world cell of grid
        cell (0, 0)."""
        wp = np.asarray(planned.waypoints_cells, dtype=np.float64).reshape(-1, 2)
        if wp.shape[0] == 0:
            return
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(wp, axis=0).T))])
        s = np.arange(0.0, min(self.route.avoid_m / self.cell_m, along[-1]) + 0.5, 0.5)
        pts = np.column_stack([np.interp(s, along, wp[:, 0]), np.interp(s, along, wp[:, 1])])
        ahead = np.rint(pts).astype(np.int64) + np.asarray(offset_rc, dtype=np.int64)
        wide = np.unique((ahead[:, None, :] + self._disc[None, :, :]).reshape(-1, 2), axis=0)
        self._marks.append((t_ns + round(self.route.avoid_s * 1e9), wide))

    def mask(self, shape: tuple[int, int], offset_rc: tuple[int, int], t_ns: int) -> NDArray[np.bool_] | None:
        """(rows, cols) bool of the grid whose cell (0, 0) is world cell ``offset_rc``: True on the cells of
        the marks still held at ``t_ns`` (expired ones are dropped); None when there are none."""
        self._marks = [m for m in self._marks if m[0] > t_ns]
        if not self._marks:
            return None
        cells = np.concatenate([m[1] for m in self._marks]) - np.asarray(offset_rc, dtype=np.int64)
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < shape[0]) & (cells[:, 1] >= 0) & (cells[:, 1] < shape[1])
        out = np.zeros(shape, dtype=np.bool_)
        out[cells[inside, 0], cells[inside, 1]] = True
        return out
