"""Closed-loop world geometry: polygons (thick walls, boxes, outlines) and exact circles, with numba kernels
for ray casting and for the clearance between the robot's footprint and the world.

A world *snapshot* is a :class:`Shapes`: polygon edges grouped per polygon (``poly_off``), circles, and for
each polygon / circle the index of the scenario element it belongs to. A wall of thickness ``t`` is the
rectangle of half-width ``t / 2`` centred on its segment, not extending past its ends (``t = 0``: the bare
segment, a two-vertex polygon). Every kernel is compiled by :func:`warm_up` before anything is timed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm

__all__ = [
    "Shapes",
    "box_vertices",
    "cast",
    "footprint_clearance",
    "footprint_vertices",
    "max_point_speed",
    "wall_vertices",
    "warm_up",
]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
_EPS = 1e-12


# --------------------------------------------------------------------------------------------- shapes


def wall_vertices(x0: float, y0: float, x1: float, y1: float, thickness_m: float) -> F64:
    """Outline of a wall: the rectangle of ``thickness_m`` centred on the segment (ends not extended), or
    the segment itself (two vertices) when the thickness is 0."""
    if thickness_m <= 0.0:
        return np.array([[x0, y0], [x1, y1]], dtype=np.float64)
    d = np.array([x1 - x0, y1 - y0], dtype=np.float64)
    n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), _EPS) * (thickness_m / 2.0)
    a, b = np.array([x0, y0]), np.array([x1, y1])
    return np.array([a - n, b - n, b + n, a + n], dtype=np.float64)


def box_vertices(cx: float, cy: float, length_m: float, width_m: float, theta_rad: float) -> F64:
    """Corners (counter-clockwise) of a rectangle centred at (cx, cy), ``length_m`` along ``theta_rad``."""
    hx, hy = length_m / 2.0, width_m / 2.0
    local = np.array([[hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]])
    c, s = dm.cos(theta_rad), dm.sin(theta_rad)
    return np.column_stack([cx + c * local[:, 0] - s * local[:, 1], cy + s * local[:, 0] + c * local[:, 1]])


def footprint_vertices(front_m: float, rear_m: float, width_m: float) -> F64:
    """Corners of a rectangular footprint in the robot frame (origin on the driving axle)."""
    hw = width_m / 2.0
    return np.array([[front_m, -hw], [front_m, hw], [-rear_m, hw], [-rear_m, -hw]], dtype=np.float64)


_NO_EDGES = np.zeros((0, 4), dtype=np.float64)
_NO_POLY_OFF = np.zeros(1, dtype=np.int64)
_NO_ELEM = np.zeros(0, dtype=np.int64)
_ELEM0 = np.zeros(1, dtype=np.int64)


@dataclass(frozen=True, slots=True, eq=False)
class Shapes:
    """A world snapshot.

    Attributes:
        edges: ``(E, 4)`` polygon edges ``(x0, y0, x1, y1)``; polygon p owns
            ``edges[poly_off[p]:poly_off[p+1]]``
            (closed: the last edge returns to the first vertex).
        poly_off: ``(P + 1,)`` offsets.
        poly_elem: ``(P,)`` element index of each polygon.
        circles: ``(C, 3)`` ``(cx, cy, r)``.
        circle_elem: ``(C,)`` element index of each circle.
    """

    edges: F64
    poly_off: I64
    poly_elem: I64
    circles: F64
    circle_elem: I64

    @staticmethod
    def build(polygons: list[F64], poly_elem: list[int], circles: list[tuple[float, float, float]],
              circle_elem: list[int]) -> Shapes:
        """From polygon vertex arrays ``(K_i, 2)`` and circles."""
        edges = [np.hstack([v, np.roll(v, -1, axis=0)]) for v in polygons]
        off = np.zeros(len(polygons) + 1, dtype=np.int64)
        off[1:] = np.cumsum([len(v) for v in polygons])
        return Shapes(
            edges=np.ascontiguousarray(np.vstack(edges) if edges else np.zeros((0, 4))),
            poly_off=off,
            poly_elem=np.asarray(poly_elem, dtype=np.int64),
            circles=np.asarray(circles, dtype=np.float64).reshape(-1, 3),
            circle_elem=np.asarray(circle_elem, dtype=np.int64),
        )

    @staticmethod
    def circle(x: float, y: float, r: float) -> Shapes:
        """A single circle (element 0)."""
        return Shapes(_NO_EDGES, _NO_POLY_OFF, _NO_ELEM, np.array([[x, y, r]]), _ELEM0)

    def with_circles(self, circles: F64, circle_elem: I64) -> Shapes:
        """These shapes plus more circles (movers), without rebuilding the polygons."""
        if circles.shape[0] == 0:
            return self
        return Shapes(self.edges, self.poly_off, self.poly_elem, np.vstack([self.circles, circles]),
                      np.concatenate([self.circle_elem, circle_elem]))


# --------------------------------------------------------------------------------------------- kernels


@numba.njit(cache=True)
def ray_kernel(ox: float, oy: float, angles: F64, edges: F64, circles: F64, max_range: float,
                out: F64) -> None:  # pragma: no cover - compiled
    for i in range(angles.shape[0]):
        dx = dm.cos(angles[i])
        dy = dm.sin(angles[i])
        best = math.inf
        for j in range(edges.shape[0]):
            px = edges[j, 0]
            py = edges[j, 1]
            ex = edges[j, 2] - px
            ey = edges[j, 3] - py
            den = dx * ey - dy * ex
            if abs(den) < _EPS:
                continue
            wx = px - ox
            wy = py - oy
            t = (wx * ey - wy * ex) / den
            if t < 0.0 or t >= best:
                continue
            u = (wx * dy - wy * dx) / den
            if 0.0 <= u <= 1.0:
                best = t
        for j in range(circles.shape[0]):
            # |o + t d - c|^2 = r^2, d unit: t^2 - 2 t b + c2 = 0
            cx = circles[j, 0] - ox
            cy = circles[j, 1] - oy
            r = circles[j, 2]
            b = cx * dx + cy * dy
            c2 = cx * cx + cy * cy - r * r
            disc = b * b - c2
            if disc < 0.0:
                continue
            sq = math.sqrt(disc)
            t = b - sq if c2 > 0.0 else b + sq  # from outside: the near root; from inside: the far one
            if 0.0 <= t < best:
                best = t
        out[i] = best if best < max_range else math.inf


@numba.njit(cache=True)
def _point_seg(px: float, py: float, x0: float, y0: float, x1: float,
               y1: float) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Distance from a point to a segment and the closest point on it."""
    ex = x1 - x0
    ey = y1 - y0
    ll = ex * ex + ey * ey
    t = 0.0
    if ll > 0.0:
        t = ((px - x0) * ex + (py - y0) * ey) / ll
        t = min(max(t, 0.0), 1.0)
    qx = x0 + t * ex
    qy = y0 + t * ey
    return math.hypot(px - qx, py - qy), qx, qy


@numba.njit(cache=True)
def _seg_seg(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float,
             dy: float) -> tuple[float, float, float, float, float]:  # pragma: no cover - compiled
    """Distance between segments AB and CD, the closest point on AB and the one on CD."""
    rx = bx - ax
    ry = by - ay
    sx = dx - cx
    sy = dy - cy
    den = rx * sy - ry * sx
    if abs(den) > _EPS:
        qx = cx - ax
        qy = cy - ay
        t = (qx * sy - qy * sx) / den
        u = (qx * ry - qy * rx) / den
        if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0:
            px = ax + t * rx
            py = ay + t * ry
            return 0.0, px, py, px, py
    d, qx, qy = _point_seg(ax, ay, cx, cy, dx, dy)
    best, p0x, p0y, p1x, p1y = d, ax, ay, qx, qy
    d, qx, qy = _point_seg(bx, by, cx, cy, dx, dy)
    if d < best:
        best, p0x, p0y, p1x, p1y = d, bx, by, qx, qy
    d, qx, qy = _point_seg(cx, cy, ax, ay, bx, by)
    if d < best:
        best, p0x, p0y, p1x, p1y = d, qx, qy, cx, cy
    d, qx, qy = _point_seg(dx, dy, ax, ay, bx, by)
    if d < best:
        best, p0x, p0y, p1x, p1y = d, qx, qy, dx, dy
    return best, p0x, p0y, p1x, p1y


@numba.njit(cache=True)
def _inside(px: float, py: float, edges: F64, lo: int, hi: int) -> bool:  # pragma: no cover - compiled
    """Even-odd test of a point against the closed polygon ``edges[lo:hi]`` (False for fewer than 3)."""
    if hi - lo < 3:
        return False
    inside = False
    for j in range(lo, hi):
        x0 = edges[j, 0]
        y0 = edges[j, 1]
        x1 = edges[j, 2]
        y1 = edges[j, 3]
        if (y0 > py) != (y1 > py):
            xc = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
            if px < xc:
                inside = not inside
    return inside


@numba.njit(cache=True)
def _poly_kernel(fp: F64, edges: F64, poly_off: I64, circles: F64, out: F64) -> None:  # pragma: no cover
    """Clearance of the closed polygon ``fp`` (K, 4 edges) from every shape.

    ``out`` = (distance, kind (0 polygon, 1 circle, -1 none), index, point on fp x, y, point on shape x, y).
    """
    best = math.inf
    kind = -1.0
    idx = -1.0
    fx = fy = sx = sy = math.nan
    k = fp.shape[0]
    for p in range(poly_off.shape[0] - 1):
        lo = poly_off[p]
        hi = poly_off[p + 1]
        for j in range(lo, hi):
            for i in range(k):
                d, ax, ay, bx, by = _seg_seg(fp[i, 0], fp[i, 1], fp[i, 2], fp[i, 3], edges[j, 0], edges[j, 1],
                                             edges[j, 2], edges[j, 3])
                if d < best:
                    best, kind, idx, fx, fy, sx, sy = d, 0.0, float(p), ax, ay, bx, by
        if best > 0.0 and hi > lo:
            if _inside(fp[0, 0], fp[0, 1], edges, lo, hi):
                best, kind, idx, fx, fy, sx, sy = 0.0, 0.0, float(p), fp[0, 0], fp[0, 1], fp[0, 0], fp[0, 1]
            elif _inside(edges[lo, 0], edges[lo, 1], fp, 0, k):
                best, kind, idx = 0.0, 0.0, float(p)
                fx, fy, sx, sy = edges[lo, 0], edges[lo, 1], edges[lo, 0], edges[lo, 1]
    for c in range(circles.shape[0]):
        cx = circles[c, 0]
        cy = circles[c, 1]
        r = circles[c, 2]
        dmin = math.inf
        qx = qy = 0.0
        for i in range(k):
            d, ax, ay = _point_seg(cx, cy, fp[i, 0], fp[i, 1], fp[i, 2], fp[i, 3])
            if d < dmin:
                dmin, qx, qy = d, ax, ay
        if _inside(cx, cy, fp, 0, k):
            dmin = 0.0
            qx, qy = cx, cy
        d = max(dmin - r, 0.0)
        if d < best:
            best, kind, idx, fx, fy = d, 1.0, float(c), qx, qy
            if dmin > 0.0:
                sx = cx + (qx - cx) * r / dmin
                sy = cy + (qy - cy) * r / dmin
            else:
                sx, sy = cx, cy
    out[0] = best
    out[1] = kind
    out[2] = idx
    out[3] = fx
    out[4] = fy
    out[5] = sx
    out[6] = sy


@numba.njit(cache=True)
def _circle_kernel(x: float, y: float, radius: float, edges: F64, poly_off: I64, circles: F64,
                   out: F64) -> None:  # pragma: no cover - compiled
    """Clearance of the disc (x, y, radius) from every shape; ``out`` as in :func:`_poly_kernel`."""
    best = math.inf
    kind = -1.0
    idx = -1.0
    qx = qy = math.nan
    for p in range(poly_off.shape[0] - 1):
        lo = poly_off[p]
        hi = poly_off[p + 1]
        for j in range(lo, hi):
            d, ax, ay = _point_seg(x, y, edges[j, 0], edges[j, 1], edges[j, 2], edges[j, 3])
            if d < best:
                best, kind, idx, qx, qy = d, 0.0, float(p), ax, ay
        if _inside(x, y, edges, lo, hi):
            best, kind, idx, qx, qy = 0.0, 0.0, float(p), x, y
    for c in range(circles.shape[0]):
        d = math.hypot(circles[c, 0] - x, circles[c, 1] - y) - circles[c, 2]
        if d < best:
            best, kind, idx = d, 1.0, float(c)
            dd = math.hypot(circles[c, 0] - x, circles[c, 1] - y)
            if dd > 0.0:
                qx = circles[c, 0] + (x - circles[c, 0]) * circles[c, 2] / dd
                qy = circles[c, 1] + (y - circles[c, 1]) * circles[c, 2] / dd
            else:
                qx, qy = x, y
    d = max(best - radius, 0.0)
    out[0] = d
    out[1] = kind
    out[2] = idx
    if best > 0.0 and math.isfinite(best):
        out[3] = x + (qx - x) * radius / best
        out[4] = y + (qy - y) * radius / best
    else:
        out[3] = qx
        out[4] = qy
    out[5] = qx
    out[6] = qy


@numba.njit(cache=True)
def _robot_kernel(x: float, y: float, th: float, local: F64, radius: float, edges: F64, poly_off: I64,
                  circles: F64, out: F64) -> None:  # pragma: no cover - compiled
    """Clearance of the robot at (x, y, th): the polygon ``local`` (robot frame) or, when it has no
    vertex, the disc of ``radius``."""
    k = local.shape[0]
    if k == 0:
        _circle_kernel(x, y, radius, edges, poly_off, circles, out)
        return
    c = dm.cos(th)
    s = dm.sin(th)
    fp = np.empty((k, 4))
    for i in range(k):
        fp[i, 0] = x + c * local[i, 0] - s * local[i, 1]
        fp[i, 1] = y + s * local[i, 0] + c * local[i, 1]
    for i in range(k):
        j = (i + 1) % k
        fp[i, 2] = fp[j, 0]
        fp[i, 3] = fp[j, 1]
    _poly_kernel(fp, edges, poly_off, circles, out)


# --------------------------------------------------------------------------------------------- wrappers


@dataclass(frozen=True, slots=True)
class Clearance:
    """Distance from the robot to the nearest shape, which element, and the closest points.

    Attributes:
        distance_m: 0 when touching or overlapping; inf in an empty world.
        element: index of the scenario element (-1 for none).
        on_robot: closest point on the footprint (world frame).
        on_shape: closest point on the element (world frame).
    """

    distance_m: float
    element: int
    on_robot: tuple[float, float]
    on_shape: tuple[float, float]


def _clearance(out: F64, shapes: Shapes) -> Clearance:
    kind, idx = int(out[1]), int(out[2])
    elem = -1 if kind < 0 else int(shapes.poly_elem[idx] if kind == 0 else shapes.circle_elem[idx])
    return Clearance(float(out[0]), elem, (float(out[3]), float(out[4])), (float(out[5]), float(out[6])))


_NO_VERTICES = np.zeros((0, 2), dtype=np.float64)


def footprint_clearance(pose: ArrayLike, local_vertices: F64 | None, radius_m: float,
                        shapes: Shapes) -> Clearance:
    """Clearance of the robot at ``pose``: a polygon footprint (``local_vertices`` ``(K, 2)`` in the robot
    frame, convex, counter-clockwise) or, when ``local_vertices`` is None, a disc of ``radius_m`` about the
    robot's origin."""
    p = np.asarray(pose, dtype=np.float64)
    out = np.empty(7)
    _robot_kernel(float(p[0]), float(p[1]), float(p[2]),
                  _NO_VERTICES if local_vertices is None else local_vertices, float(radius_m),
                  shapes.edges, shapes.poly_off, shapes.circles, out)
    return _clearance(out, shapes)


def max_point_speed(local_vertices: F64 | None, vx: float, vy: float, w: float) -> float:
    """Largest speed of any point of the footprint under the body twist (vx, vy, w): the speed of a body
    point is constant along a constant-twist arc, and its maximum over a convex footprint is at a vertex.
    A disc turning about its centre sweeps nothing, so only its translation counts."""
    if local_vertices is None:
        return math.hypot(vx, vy)
    px, py = local_vertices[:, 0], local_vertices[:, 1]
    return float(np.max(np.hypot(vx - w * py, vy + w * px)))


def cast(origin_xy: tuple[float, float], angles_rad: F64, shapes: Shapes, max_range_m: float) -> F64:
    """Exact ranges along world bearings to the nearest polygon edge or circle (inf beyond max range)."""
    out = np.empty(angles_rad.shape[0], dtype=np.float64)
    ray_kernel(float(origin_xy[0]), float(origin_xy[1]), np.ascontiguousarray(angles_rad, dtype=np.float64),
                shapes.edges, shapes.circles, float(max_range_m), out)
    return out


def warm_up() -> None:
    """Compile every kernel (before anything is timed)."""
    shapes = Shapes.build([box_vertices(2.0, 0.0, 1.0, 1.0, 0.0)], [0], [(0.0, 3.0, 0.5)], [1])
    cast((0.0, 0.0), np.linspace(-1.0, 1.0, 5), shapes, 10.0)
    footprint_clearance((0.0, 0.0, 0.0), footprint_vertices(0.5, 0.2, 0.4), 0.3, shapes)
    footprint_clearance((0.0, 0.0, 0.0), None, 0.3, shapes)
