"""Trap escape by manoeuvre: a short sequence of arcs and turns that points a rectangular robot where it must
go when it cannot turn where it stands.

The class: a robot whose corners sweep a circle wider than the free space around it (the
1.2 x 0.7 m chair, corners 0.87 m from its axle, in a 1.4 m passage or a T-junction of two) cannot turn in
place. ND+ takes one reactive step at a time: it turns a little, reverses a little, and turns again, and a
turn that needs a reverse arc first, or two, is never found; the chair rocks at the junction until the run
ends. A driver makes a three-point turn. When the trap detector fires, ``plan_manoeuvre`` searches such a
turn: a best-first search (A*) over a lattice of short motion primitives (forward and reverse arcs of a few
curvatures, and turns in place; the state lattice of Pivtoraiko and Kelly, here over a few metres) from the
robot's pose, every primitive's swept footprint checked against the obstacles, until a pose heads within
``heading_tol_rad`` of the wanted direction with room to drive on. The stack then drives the primitives one
by one at escape speed, every tick through the reflexive check, and gives control back to the reactor
when the sequence ends or the check refuses it.

Obstacles are points in the robot frame at the search's start, each with its own margin: the raw scan's
hits (exact) and the cells that bound the grid's known free space (occupied or never seen; a cell is
anywhere within half a cell of its centre): the manoeuvre stays where the robot knows it is free, behind
the laser as well. A point already within its margin of the footprint blocks only a pose nearer than
the footprint has been to it since the primitive began (a wedged robot must be able to move away; the
reflexive check tests each tick's command the same way, ``supervisor.arc_touches``).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .. import detmath as dm
from ..robot import RobotConfig

F64 = NDArray[np.float64]

_SAMPLE_M = 0.02  # largest travel of any footprint point between two checked poses [m]
_XY_BIN_M = 0.05  # the lattice's closed set: poses within 5 cm and 7.5 deg are one state
_TH_BIN_RAD = math.radians(7.5)


@dataclass(frozen=True, slots=True)
class ManoeuvreParams:
    """Constants of the manoeuvre search.

    Attributes:
        step_m: arc length of one forward or reverse primitive [m].
        curvatures: the primitives' curvatures [1/m], each driven forward and in reverse (0: straight).
        turn_rad: rotation of one turn-in-place primitive.
        heading_tol_rad: the manoeuvre ends heading within this of the wanted direction...
        room_m: ... with the footprint free for this much straight travel on, counted from the start
            when the pose lies behind it on its own heading (a straight reverse is no manoeuvre).
        radius_m: the search stays within this of the start (a manoeuvre, not a route).
        max_nodes: expansions before the search gives up (bounds its time: a few ms per hundred).
        switch_cost_s: cost of a change of direction (forward / reverse / in place) [s]; the rest of the
            cost is the time driven at the speeds the stack gives (``Speeds``).
        extra_margin_m: clearance kept beyond each obstacle's own margin (the executed arcs deviate from
            the planned ones by a few centimetres: the reflexive check must not refuse them).
    """

    step_m: float = 0.15
    curvatures: tuple[float, ...] = (0.0, 1.5, -1.5, 3.0, -3.0)
    turn_rad: float = math.radians(15.0)
    heading_tol_rad: float = math.radians(20.0)
    room_m: float = 0.5
    radius_m: float = 1.5
    max_nodes: int = 1500
    switch_cost_s: float = 2.0
    extra_margin_m: float = 0.01


@dataclass(frozen=True, slots=True)
class Speeds:
    """How fast the primitives are driven: forward and reverse [m/s], turn in place [rad/s] (all > 0)."""

    forward_mps: float
    reverse_mps: float
    turn_radps: float

    def twist(self, q: Primitive) -> tuple[float, float]:
        """(v, w) of a primitive driven at these speeds (the arc's curvature kept)."""
        if q.ds_m == 0.0:
            return 0.0, math.copysign(self.turn_radps, q.dth_rad)
        v = self.forward_mps if q.ds_m > 0.0 else -self.reverse_mps
        return v, v * q.dth_rad / q.ds_m

    def duration_s(self, q: Primitive) -> float:
        """Time the primitive takes at these speeds."""
        if q.ds_m == 0.0:
            return abs(q.dth_rad) / self.turn_radps
        return abs(q.ds_m) / (self.forward_mps if q.ds_m > 0.0 else self.reverse_mps)


@dataclass(frozen=True, slots=True)
class Primitive:
    """One step of a manoeuvre: ``ds_m`` signed arc length (0: turn in place), ``dth_rad`` its rotation."""

    ds_m: float
    dth_rad: float


@njit(cache=True)
def _end(x: float, y: float, th: float, ds: float, dth: float) -> tuple[float, float, float]:
    """The pose at the end of the primitive (ds, dth) from (x, y, th) (exact arc; the search and the sweep
    kernel both step with it)."""
    if ds == 0.0:
        lx = ly = 0.0
    elif abs(dth) < 1e-9:
        lx, ly = ds, 0.0
    else:
        lx, ly = ds * dm.sin(dth) / dth, ds * (1.0 - dm.cos(dth)) / dth
    c, s = dm.cos(th), dm.sin(th)
    return x + c * lx - s * ly, y + s * lx + c * ly, th + dth


@njit(cache=True)
def _blocked(px: F64, py: F64, margin: F64, x0: float, y0: float, th0: float, ds: float, dth: float, n: int,
             front: float, rear: float, half_w: float, circle_r: float) -> bool:
    """Whether the footprint, moved from (x0, y0, th0) along the primitive (ds, dth) in n equal steps,
    comes within a point's margin and nearer than it has been since the primitive began (inside its
    margin a point may only recede: the reflexive check, ``supervisor.arc_touches``, refuses a motion
    that brings the footprint nearer a point within its margin than it is at the tick). Only the points
    within reach of the primitive are tested, and at each pose only those within the footprint's
    enclosing circle grown by their margin (the footprint's distance is ``supervisor.
    footprint_signed_distance``'s, written out for the kernel)."""
    outer = circle_r if circle_r > 0.0 else math.hypot(max(front, rear), half_w)
    reach = outer + abs(ds)
    idx = np.empty(px.shape[0], dtype=np.int64)
    m = 0
    for i in range(px.shape[0]):
        r = reach + margin[i]
        if (px[i] - x0) ** 2 + (py[i] - y0) ** 2 <= r * r:
            idx[m] = i
            m += 1
    nearest = np.full(m, np.inf)  # per candidate, the largest distance since the start (inf: out of reach)
    for k in range(n + 1):
        f = k / n
        x, y, th = _end(x0, y0, th0, ds * f, dth * f)
        c = dm.cos(th)
        sn = dm.sin(th)
        for t in range(m):
            i = idx[t]
            dx = px[i] - x
            dy = py[i] - y
            r = outer + margin[i]
            if dx * dx + dy * dy > r * r:
                nearest[t] = np.inf
                continue
            qx = c * dx + sn * dy
            qy = -sn * dx + c * dy
            if circle_r > 0.0:
                d = math.hypot(qx, qy) - circle_r
            else:
                ex = max(qx - front, -rear - qx)
                ey = abs(qy) - half_w
                d = math.hypot(max(ex, 0.0), max(ey, 0.0)) + min(max(ex, ey), 0.0)
            if k == 0:
                nearest[t] = d
            elif d <= margin[i] and d < nearest[t] - 1e-9:
                return True
            else:
                nearest[t] = max(nearest[t], d) if nearest[t] < np.inf else d
    return False


def _steps(ds: float, dth: float, robot: RobotConfig) -> int:
    """Checked poses along a primitive: one per _SAMPLE_M of the farthest footprint point's travel."""
    return max(1, math.ceil((abs(ds) + abs(dth) * robot.outer_radius_m) / _SAMPLE_M))


def plan_manoeuvre(points_xy: F64, margins_m: F64, robot: RobotConfig, want_rad: float,
                   params: ManoeuvreParams, speeds: Speeds) -> tuple[Primitive, ...] | None:
    """The quickest sequence of primitives (up to the lattice's 5 cm / 7.5 deg states) from the robot's
    pose (the origin of ``points_xy``' frame) to one heading within ``heading_tol_rad`` of ``want_rad``
    (robot frame) with ``room_m`` free straight on, plus however far the pose lies behind the start along
    its heading (backing away from what blocks the way on, only to drive back to it, is no end); None when
    there is none within ``radius_m`` and ``max_nodes`` expansions, or when the robot already stands so
    (nothing to manoeuvre). Cost: the time driven at ``speeds``, plus ``switch_cost_s`` per change of
    direction (each one a stop and a start)."""
    p = params
    reach = (p.radius_m + p.step_m + robot.outer_radius_m + p.room_m + p.extra_margin_m
             + float(np.max(margins_m, initial=0.0)))
    near = dm.sqdist(points_xy) <= reach * reach
    pts = np.ascontiguousarray(points_xy[near])
    margin = np.ascontiguousarray(margins_m[near] + p.extra_margin_m)
    px, py = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
    circle = robot.radius_m if robot.shape == "circle" else 0.0
    geo = (robot.front_m, robot.rear_m, robot.width_m / 2.0, circle)
    prims = [Primitive(sign * p.step_m, sign * p.step_m * k) for sign in (1.0, -1.0) for k in p.curvatures]
    prims += [Primitive(0.0, p.turn_rad), Primitive(0.0, -p.turn_rad)]
    # the quickest a radian can be turned: on the sharpest arc forward, or in place (h admissible)
    sharpest = max(abs(k) for k in p.curvatures)
    rate = max(sharpest * speeds.forward_mps, sharpest * speeds.reverse_mps, speeds.turn_radps)

    def blocked(x: float, y: float, th: float, q: Primitive, n: int) -> bool:
        return bool(_blocked(px, py, margin, x, y, th, q.ds_m, q.dth_rad, n, *geo))

    def done(x: float, y: float, th: float) -> bool:
        if abs(math.remainder(th - want_rad, math.tau)) > p.heading_tol_rad:
            return False
        # room_m on from the start, not only from where the robot backed to: a pose behind the start
        # on its own heading sees the straight way the start had, and driving it comes back to the start
        behind = max(0.0, -(x * dm.cos(th) + y * dm.sin(th)))
        room = Primitive(p.room_m + behind, 0.0)
        return not blocked(x, y, th, room, _steps(room.ds_m, 0.0, robot))

    if done(0.0, 0.0, 0.0):
        return None
    steps = [_steps(q.ds_m, q.dth_rad, robot) for q in prims]
    costs = [speeds.duration_s(q) for q in prims]
    # node: (x, y, th, parent index, primitive index, direction: 1 forward, -1 reverse, 0 in place)
    nodes: list[tuple[float, float, float, int, int, int]] = [(0.0, 0.0, 0.0, -1, -1, 2)]
    best: dict[tuple[int, int, int], float] = {(0, 0, 0): 0.0}
    heap: list[tuple[float, float, int]] = [(0.0, 0.0, 0)]
    expanded = 0
    while heap and expanded < p.max_nodes:
        _, g, i = heapq.heappop(heap)
        x, y, th, _, _, way = nodes[i]
        key = _key(x, y, th)
        if g > best.get(key, math.inf):
            continue
        if i and done(x, y, th):
            return _sequence(nodes, i, prims)
        expanded += 1
        for j, q in enumerate(prims):
            x1, y1, th1 = _end(x, y, th, q.ds_m, q.dth_rad)
            if x1 * x1 + y1 * y1 > p.radius_m * p.radius_m:
                continue
            w1 = 0 if q.ds_m == 0.0 else (1 if q.ds_m > 0.0 else -1)
            g1 = g + costs[j] + (p.switch_cost_s if way != 2 and w1 != way else 0.0)
            k1 = _key(x1, y1, th1)
            if g1 >= best.get(k1, math.inf) or blocked(x, y, th, q, steps[j]):
                continue
            best[k1] = g1
            nodes.append((x1, y1, th1, i, j, w1))
            h = max(0.0, abs(math.remainder(th1 - want_rad, math.tau)) - p.heading_tol_rad) / rate
            heapq.heappush(heap, (g1 + h, g1, len(nodes) - 1))
    return None


def _key(x: float, y: float, th: float) -> tuple[int, int, int]:
    """The lattice state of a pose (the search's closed set)."""
    return (round(x / _XY_BIN_M), round(y / _XY_BIN_M),
            round(math.remainder(th, math.tau) / _TH_BIN_RAD))


def _sequence(nodes: list[tuple[float, float, float, int, int, int]], i: int,
              prims: list[Primitive]) -> tuple[Primitive, ...]:
    """The primitives from the root to node ``i``."""
    out: list[Primitive] = []
    while nodes[i][3] >= 0:
        out.append(prims[nodes[i][4]])
        i = nodes[i][3]
    return tuple(reversed(out))


def end_poses(sequence: tuple[Primitive, ...]) -> F64:
    """(N, 3) pose (x, y, theta) at the end of each primitive of ``sequence``, in the frame of its start."""
    out = np.zeros((len(sequence), 3))
    x = y = th = 0.0
    for i, q in enumerate(sequence):
        x, y, th = _end(x, y, th, q.ds_m, q.dth_rad)
        out[i] = (x, y, th)
    return out


def warm_up_manoeuvre() -> None:
    """Compile the sweep kernel before the first timed tick."""
    _end(0.0, 0.0, 0.0, 0.1, 0.1)
    z = np.zeros(1)
    _blocked(z, z + 5.0, z, 0.0, 0.0, 0.0, 0.1, 0.1, 2, 0.8, 0.4, 0.35, 0.0)
