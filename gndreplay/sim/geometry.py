"""Closed-loop world geometry: polygons (thick walls, boxes, outlines) and exact circles, with numba kernels
for ray casting and for the clearance between the robot's footprint and the world.

A world *snapshot* is a :class:`Shapes`: polygon edges grouped per polygon (``poly_off``), circles, and for
each polygon / circle the index of the scenario element it belongs to. A polygon is a closed vertex loop
or, for a map's occupied cells, an :class:`EdgeGroups` group (a region's outer loop and holes). A wall of
thickness ``t`` is the rectangle of half-width ``t / 2`` centred on its segment, not extending past its ends
(``t = 0``: the bare segment, a two-vertex polygon). Every kernel is compiled by :func:`warm_up` before
anything is timed. Large worlds (maps) cull: the clearance measures the edges near the robot first, rays
walk a bucket grid; both give the brute force's results bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm

__all__ = [
    "CULL_MIN_EDGES",
    "NEAR_CELL_M",
    "NEAR_MARGINS_M",
    "EdgeGroups",
    "RayGrid",
    "Shapes",
    "box_vertices",
    "cast",
    "footprint_clearance",
    "footprint_vertices",
    "max_point_speed",
    "ray_grid",
    "wall_vertices",
    "warm_up",
]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
_EPS = 1e-12
#: Clearance culling (:func:`footprint_clearance`): worlds of at least CULL_MIN_EDGES polygon edges measure
#: first the edges within each of NEAR_MARGINS_M in turn of the robot's NEAR_CELL_M square cell (its reach
#: added), then every edge.
CULL_MIN_EDGES = 512
NEAR_CELL_M = 1.0
NEAR_MARGINS_M = (1.0, 4.0)
_NEAR_SLACK_M = 1e-6
_NEAR_CACHE = 4096
#: Ray casting over a bucket grid: an edge is filed in every cell its bounding box grown by _RAY_PAD_M
#: overlaps (far more than the walk's rounding), and a ray stops once its nearest hit is _RAY_SLACK_M
#: before the next cell (far more than the rounding of a computed distance).
_RAY_PAD_M = 1e-6
_RAY_SLACK_M = 1e-6
_RAY_GRID_MAX_SIDE = 1024


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
class EdgeGroups:
    """Polygons given by their edges: group g owns ``edges[off[g]:off[g + 1]]``, the whole boundary of a
    connected region (its closed outer loop and the loops of its holes, in any order), so the even-odd test
    against the group is the region's inside test.

    Attributes:
        edges: ``(E, 4)`` edges ``(x0, y0, x1, y1)``.
        off: ``(G + 1,)`` offsets, ``off[0] == 0`` and ``off[-1] == E``.
    """

    edges: F64
    off: I64

    def __post_init__(self) -> None:
        e = np.ascontiguousarray(self.edges, dtype=np.float64).reshape(-1, 4)
        off = np.asarray(self.off, dtype=np.int64)
        if off.ndim != 1 or len(off) < 1 or off[0] != 0 or off[-1] != len(e) or np.any(np.diff(off) < 0):
            raise ValueError(f"off must rise from 0 to the {len(e)} edges, got {off[:4]}...")
        object.__setattr__(self, "edges", e)
        object.__setattr__(self, "off", off)


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
        index: the culling index of the edges (:meth:`near_edges`), shared by snapshots with the same
            polygons.
    """

    edges: F64
    poly_off: I64
    poly_elem: I64
    circles: F64
    circle_elem: I64
    index: dict[Any, Any] = field(default_factory=dict, repr=False)

    @staticmethod
    def build(polygons: Sequence[F64 | EdgeGroups], poly_elem: Sequence[int],
              circles: list[tuple[float, float, float]], circle_elem: list[int]) -> Shapes:
        """From polygon vertex arrays ``(K_i, 2)`` (closed: the last vertex joins the first) or edge groups,
        one element index per entry, and circles."""
        edges: list[F64] = []
        sizes: list[int] = []
        elems: list[int] = []
        for v, e in zip(polygons, poly_elem, strict=True):
            if isinstance(v, EdgeGroups):
                edges.append(v.edges)
                sizes += np.diff(v.off).tolist()
                elems += [e] * (len(v.off) - 1)
            else:
                edges.append(np.hstack([v, np.roll(v, -1, axis=0)]))
                sizes.append(len(v))
                elems.append(e)
        off = np.zeros(len(sizes) + 1, dtype=np.int64)
        off[1:] = np.cumsum(sizes)
        return Shapes(
            edges=np.ascontiguousarray(np.vstack(edges) if edges else np.zeros((0, 4))),
            poly_off=off,
            poly_elem=np.asarray(elems, dtype=np.int64),
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
                      np.concatenate([self.circle_elem, circle_elem]), self.index)

    def of_elements(self, elements: Sequence[int]) -> Shapes:
        """The polygons and circles of these element indices only."""
        keep = np.isin(self.poly_elem, np.asarray(elements, dtype=np.int64))
        sizes = np.diff(self.poly_off)[keep]
        rows = np.repeat(keep, np.diff(self.poly_off))
        off = np.zeros(len(sizes) + 1, dtype=np.int64)
        off[1:] = np.cumsum(sizes)
        ck = np.isin(self.circle_elem, np.asarray(elements, dtype=np.int64))
        return Shapes(np.ascontiguousarray(self.edges[rows]), off, self.poly_elem[keep],
                      np.ascontiguousarray(self.circles[ck]), self.circle_elem[ck])

    def ray_grid(self) -> RayGrid:
        """The edges' bucket grid for ray casting (:func:`ray_grid`), built once per set of polygons."""
        hit = self.index.get("rays")
        if hit is None:
            hit = self.index["rays"] = ray_grid(self.edges)
        return hit

    def near_edges(self, x: float, y: float, reach_m: float, margin_m: float) -> tuple[I64, F64]:
        """Indices (ascending) of the edges that may lie within ``margin_m`` of a body of radius
        ``reach_m`` about any point of the ``NEAR_CELL_M`` cell holding (x, y), and each polygon's
        (ymin, ymax); cached per cell (see :func:`footprint_clearance`)."""
        ix, iy = math.floor(x / NEAR_CELL_M), math.floor(y / NEAR_CELL_M)
        key = (ix, iy, reach_m, margin_m)
        hit = self.index.get(key)
        if hit is not None:
            return hit
        if "boxes" not in self.index:
            e = self.edges
            lo_x, hi_x = np.minimum(e[:, 0], e[:, 2]), np.maximum(e[:, 0], e[:, 2])
            lo_y, hi_y = np.minimum(e[:, 1], e[:, 3]), np.maximum(e[:, 1], e[:, 3])
            self.index["boxes"] = (lo_x, hi_x, lo_y, hi_y)
            starts = self.poly_off[:-1]
            filled = starts < self.poly_off[1:]
            gy = np.column_stack([np.full(len(starts), np.inf), np.full(len(starts), -np.inf)])
            if filled.any():  # the filled groups' starts increase strictly: each reduces its own edges
                gy[filled, 0] = np.minimum.reduceat(lo_y, starts[filled])
                gy[filled, 1] = np.maximum.reduceat(hi_y, starts[filled])
            self.index["gy"] = np.ascontiguousarray(gy)
        lo_x, hi_x, lo_y, hi_y = self.index["boxes"]
        cx0, cy0 = ix * NEAR_CELL_M, iy * NEAR_CELL_M
        dx = np.maximum(np.maximum(lo_x - (cx0 + NEAR_CELL_M), cx0 - hi_x), 0.0)
        dy = np.maximum(np.maximum(lo_y - (cy0 + NEAR_CELL_M), cy0 - hi_y), 0.0)
        near = np.flatnonzero(np.hypot(dx, dy) <= reach_m + margin_m + _NEAR_SLACK_M).astype(np.int64)
        if len(self.index) > _NEAR_CACHE:
            keep = {k: self.index[k] for k in ("boxes", "gy", "rays") if k in self.index}
            self.index.clear()
            self.index.update(keep)
        out = (near, self.index["gy"])
        self.index[key] = out
        return out


# --------------------------------------------------------------------------------------------- kernels


@numba.njit(cache=True)
def _ray_edge(ox: float, oy: float, dx: float, dy: float, edges: F64, j: int,
              best: float) -> float:  # pragma: no cover - compiled
    """``best`` lowered to the distance along the ray (ox, oy) + t (dx, dy) to edge j if it hits closer."""
    px = edges[j, 0]
    py = edges[j, 1]
    ex = edges[j, 2] - px
    ey = edges[j, 3] - py
    den = dx * ey - dy * ex
    if abs(den) < _EPS:
        return best
    wx = px - ox
    wy = py - oy
    t = (wx * ey - wy * ex) / den
    if t < 0.0 or t >= best:
        return best
    u = (wx * dy - wy * dx) / den
    if 0.0 <= u <= 1.0:
        return t
    return best


@numba.njit(cache=True)
def _ray_circles(ox: float, oy: float, dx: float, dy: float, circles: F64,
                 best: float) -> float:  # pragma: no cover - compiled
    """``best`` lowered to the distance along the ray to the nearest circle hit closer."""
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
    return best


@numba.njit(cache=True)
def ray_kernel(ox: float, oy: float, angles: F64, edges: F64, circles: F64, max_range: float,
                out: F64) -> None:  # pragma: no cover - compiled
    for i in range(angles.shape[0]):
        dx = dm.cos(angles[i])
        dy = dm.sin(angles[i])
        best = math.inf
        for j in range(edges.shape[0]):
            best = _ray_edge(ox, oy, dx, dy, edges, j, best)
        best = _ray_circles(ox, oy, dx, dy, circles, best)
        out[i] = best if best < max_range else math.inf


@numba.njit(cache=True)
def _grid_ray_kernel(ox: float, oy: float, angles: F64, edges: F64, circles: F64, max_range: float,
                     gx0: float, gy0: float, cell: float, nx: int, ny: int, cell_off: I64, cell_edges: I64,
                     out: F64) -> None:  # pragma: no cover - compiled
    """:func:`ray_kernel` walking the bucket grid (:class:`RayGrid`) cell by cell along each ray: the edges
    of the cells crossed, until the nearest hit so far is nearer than the next cell (by ``_RAY_SLACK_M``)
    or the range is exceeded. Each edge's distance is computed as in ``ray_kernel``, and every edge the
    ray can hit first is tested, so the ranges are the same bit for bit."""
    gx1 = gx0 + nx * cell
    gy1 = gy0 + ny * cell
    for i in range(angles.shape[0]):
        dx = dm.cos(angles[i])
        dy = dm.sin(angles[i])
        best = _ray_circles(ox, oy, dx, dy, circles, math.inf)
        # the ray's stretch inside the grid's box: [t0, t1]
        t0 = 0.0
        t1 = max_range + _RAY_SLACK_M
        if dx != 0.0:
            ta = (gx0 - ox) / dx
            tb = (gx1 - ox) / dx
            t0 = max(t0, min(ta, tb))
            t1 = min(t1, max(ta, tb))
        elif not gx0 <= ox <= gx1:
            t1 = -1.0
        if dy != 0.0:
            ta = (gy0 - oy) / dy
            tb = (gy1 - oy) / dy
            t0 = max(t0, min(ta, tb))
            t1 = min(t1, max(ta, tb))
        elif not gy0 <= oy <= gy1:
            t1 = -1.0
        if t0 <= t1:
            ix = min(max(math.floor((ox + t0 * dx - gx0) / cell), 0), nx - 1)
            iy = min(max(math.floor((oy + t0 * dy - gy0) / cell), 0), ny - 1)
            step_x = 1 if dx > 0.0 else -1
            step_y = 1 if dy > 0.0 else -1
            if dx != 0.0:
                nxt = gx0 + (ix + (1 if dx > 0.0 else 0)) * cell
                t_x = (nxt - ox) / dx
                d_x = cell / abs(dx)
            else:
                t_x = math.inf
                d_x = math.inf
            if dy != 0.0:
                nxt = gy0 + (iy + (1 if dy > 0.0 else 0)) * cell
                t_y = (nxt - oy) / dy
                d_y = cell / abs(dy)
            else:
                t_y = math.inf
                d_y = math.inf
            while True:
                c = iy * nx + ix
                for m in range(cell_off[c], cell_off[c + 1]):
                    best = _ray_edge(ox, oy, dx, dy, edges, cell_edges[m], best)
                t_leave = min(t_x, t_y)
                if best < t_leave - _RAY_SLACK_M or t_leave > t1:
                    break
                if t_x < t_y:
                    ix += step_x
                    t_x += d_x
                    if ix < 0 or ix >= nx:
                        break
                else:
                    iy += step_y
                    t_y += d_y
                    if iy < 0 or iy >= ny:
                        break
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
def _edge_range(culled: bool, near: I64, q: int, lo: int, hi: int) -> tuple[int, int]:  # pragma: no cover
    """Where the edges of polygon ``[lo, hi)`` to measure are: ``near[q:q_end]`` when culled (``near``
    ascending), else ``lo:hi`` itself."""
    if not culled:
        return lo, hi
    q_end = q
    while q_end < near.shape[0] and near[q_end] < hi:
        q_end += 1
    return q, q_end


@numba.njit(cache=True)
def _may_hold(py: float, gy: F64, p: int, culled: bool) -> bool:  # pragma: no cover - compiled
    """Whether the even-odd test of a point at height ``py`` against polygon p can be True: no edge crosses
    the height outside the polygon's (ymin, ymax) (comparisons only, so the test's result is unchanged)."""
    return not culled or (gy[p, 0] <= py < gy[p, 1])


@numba.njit(cache=True)
def _poly_kernel(fp: F64, edges: F64, poly_off: I64, circles: F64, near: I64, gy: F64, culled: bool,
                 out: F64) -> None:  # pragma: no cover - compiled
    """Clearance of the closed polygon ``fp`` (K, 4 edges) from every shape.

    ``out`` = (distance, kind (0 polygon, 1 circle, -1 none), index, point on fp x, y, point on shape x, y).
    With ``culled``, distances are measured to the edges ``near`` only (the inside tests still see whole
    polygons); see :func:`footprint_clearance` for when that is exact.
    """
    best = math.inf
    kind = -1.0
    idx = -1.0
    fx = fy = sx = sy = math.nan
    k = fp.shape[0]
    q = 0
    for p in range(poly_off.shape[0] - 1):
        lo = poly_off[p]
        hi = poly_off[p + 1]
        a, b = _edge_range(culled, near, q, lo, hi)
        q = b if culled else q
        for m in range(a, b):
            j = near[m] if culled else m
            for i in range(k):
                d, ax, ay, bx, by = _seg_seg(fp[i, 0], fp[i, 1], fp[i, 2], fp[i, 3], edges[j, 0], edges[j, 1],
                                             edges[j, 2], edges[j, 3])
                if d < best:
                    best, kind, idx, fx, fy, sx, sy = d, 0.0, float(p), ax, ay, bx, by
        if best > 0.0 and hi > lo:
            if _may_hold(fp[0, 1], gy, p, culled) and _inside(fp[0, 0], fp[0, 1], edges, lo, hi):
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
def _circle_kernel(x: float, y: float, radius: float, edges: F64, poly_off: I64, circles: F64, near: I64,
                   gy: F64, culled: bool, out: F64) -> None:  # pragma: no cover - compiled
    """Clearance of the disc (x, y, radius) from every shape; ``out`` and ``culled`` as in
    :func:`_poly_kernel`."""
    best = math.inf
    kind = -1.0
    idx = -1.0
    qx = qy = math.nan
    q = 0
    for p in range(poly_off.shape[0] - 1):
        lo = poly_off[p]
        hi = poly_off[p + 1]
        a, b = _edge_range(culled, near, q, lo, hi)
        q = b if culled else q
        for m in range(a, b):
            j = near[m] if culled else m
            d, ax, ay = _point_seg(x, y, edges[j, 0], edges[j, 1], edges[j, 2], edges[j, 3])
            if d < best:
                best, kind, idx, qx, qy = d, 0.0, float(p), ax, ay
        if _may_hold(y, gy, p, culled) and _inside(x, y, edges, lo, hi):
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
                  circles: F64, near: I64, gy: F64, culled: bool, out: F64) -> None:  # pragma: no cover
    """Clearance of the robot at (x, y, th): the polygon ``local`` (robot frame) or, when it has no
    vertex, the disc of ``radius``."""
    k = local.shape[0]
    if k == 0:
        _circle_kernel(x, y, radius, edges, poly_off, circles, near, gy, culled, out)
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
    _poly_kernel(fp, edges, poly_off, circles, near, gy, culled, out)


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
_NO_NEAR = np.zeros(0, dtype=np.int64)
_NO_GY = np.zeros((0, 2), dtype=np.float64)


def footprint_clearance(pose: ArrayLike, local_vertices: F64 | None, radius_m: float, shapes: Shapes, *,
                        cull: bool | None = None) -> Clearance:
    """Clearance of the robot at ``pose``: a polygon footprint (``local_vertices`` ``(K, 2)`` in the robot
    frame, convex, counter-clockwise) or, when ``local_vertices`` is None, a disc of ``radius_m`` about the
    robot's origin.

    ``cull`` (default: worlds of at least ``CULL_MIN_EDGES`` edges) first measures only the edges near the
    robot's cell (:meth:`Shapes.near_edges`), within each of ``NEAR_MARGINS_M`` in turn: an edge left out is
    farther than the margin from the footprint, so an answer within the margin is the whole world's, bit for
    bit (the same first shape at the same distance); a larger one is measured again with the next margin,
    and at last over every edge.
    """
    p = np.asarray(pose, dtype=np.float64)
    x, y, th = float(p[0]), float(p[1]), float(p[2])
    local = _NO_VERTICES if local_vertices is None else local_vertices
    out = np.empty(7)
    if cull if cull is not None else shapes.edges.shape[0] >= CULL_MIN_EDGES:
        reach = float(radius_m) if local_vertices is None else float(np.max(np.hypot(*local.T)))
        for margin in NEAR_MARGINS_M:
            near, gy = shapes.near_edges(x, y, reach, margin)
            _robot_kernel(x, y, th, local, float(radius_m), shapes.edges, shapes.poly_off, shapes.circles,
                          near, gy, True, out)
            if out[0] <= margin:
                return _clearance(out, shapes)
    _robot_kernel(x, y, th, local, float(radius_m), shapes.edges, shapes.poly_off, shapes.circles, _NO_NEAR,
                  _NO_GY, False, out)
    return _clearance(out, shapes)


def max_point_speed(local_vertices: F64 | None, vx: float, vy: float, w: float) -> float:
    """Largest speed of any point of the footprint under the body twist (vx, vy, w): the speed of a body
    point is constant along a constant-twist arc, and its maximum over a convex footprint is at a vertex.
    A disc turning about its centre sweeps nothing, so only its translation counts."""
    if local_vertices is None:
        return math.hypot(vx, vy)
    px, py = local_vertices[:, 0], local_vertices[:, 1]
    return float(np.max(np.hypot(vx - w * py, vy + w * px)))


def cast(origin_xy: tuple[float, float], angles_rad: F64, shapes: Shapes, max_range_m: float, *,
         grid: bool | None = None) -> F64:
    """Exact ranges along world bearings to the nearest polygon edge or circle (inf beyond max range).
    With ``grid`` (default: worlds of at least ``CULL_MIN_EDGES`` edges) the rays walk the edges' bucket
    grid (:meth:`Shapes.ray_grid`): the same ranges, bit for bit."""
    out = np.empty(angles_rad.shape[0], dtype=np.float64)
    a = np.ascontiguousarray(angles_rad, dtype=np.float64)
    ox, oy = float(origin_xy[0]), float(origin_xy[1])
    if shapes.edges.shape[0] and (grid if grid is not None else shapes.edges.shape[0] >= CULL_MIN_EDGES):
        g = shapes.ray_grid()
        _grid_ray_kernel(ox, oy, a, shapes.edges, shapes.circles, float(max_range_m), g.x0, g.y0, g.cell,
                         g.nx, g.ny, g.cell_off, g.cell_edges, out)
    else:
        ray_kernel(ox, oy, a, shapes.edges, shapes.circles, float(max_range_m), out)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class RayGrid:
    """A bucket grid of edges for ray casting: square cells of ``cell`` [m] from (x0, y0), ``nx`` x ``ny``;
    cell ``iy * nx + ix`` holds ``cell_edges[cell_off[c]:cell_off[c + 1]]``: every edge whose bounding box,
    grown by ``_RAY_PAD_M``, overlaps the cell."""

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    cell_off: I64
    cell_edges: I64


def ray_grid(edges: F64) -> RayGrid:
    """The bucket grid of ``edges`` (``(E >= 1, 4)``): cells of about one edge each, at most
    ``_RAY_GRID_MAX_SIDE`` a side."""
    lo_x = np.minimum(edges[:, 0], edges[:, 2]) - _RAY_PAD_M
    hi_x = np.maximum(edges[:, 0], edges[:, 2]) + _RAY_PAD_M
    lo_y = np.minimum(edges[:, 1], edges[:, 3]) - _RAY_PAD_M
    hi_y = np.maximum(edges[:, 1], edges[:, 3]) + _RAY_PAD_M
    x0, y0 = float(lo_x.min()), float(lo_y.min())
    w, h = float(hi_x.max()) - x0, float(hi_y.max()) - y0
    cell = max(math.sqrt(w * h / edges.shape[0]), max(w, h) / _RAY_GRID_MAX_SIDE, 1e-3)
    nx, ny = max(math.ceil(w / cell), 1), max(math.ceil(h / cell), 1)
    ix0 = np.clip(np.floor((lo_x - x0) / cell).astype(np.int64), 0, nx - 1)
    ix1 = np.clip(np.floor((hi_x - x0) / cell).astype(np.int64), 0, nx - 1)
    iy0 = np.clip(np.floor((lo_y - y0) / cell).astype(np.int64), 0, ny - 1)
    iy1 = np.clip(np.floor((hi_y - y0) / cell).astype(np.int64), 0, ny - 1)
    wide = ix1 - ix0 + 1
    counts = wide * (iy1 - iy0 + 1)
    edge = np.repeat(np.arange(edges.shape[0], dtype=np.int64), counts)
    k = np.arange(edge.shape[0], dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    cid = (iy0[edge] + k // wide[edge]) * nx + ix0[edge] + k % wide[edge]
    order = np.argsort(cid, kind="stable")
    off = np.zeros(nx * ny + 1, dtype=np.int64)
    off[1:] = np.cumsum(np.bincount(cid, minlength=nx * ny))
    return RayGrid(x0, y0, cell, nx, ny, off, np.ascontiguousarray(edge[order]))


def warm_up() -> None:
    """Compile every kernel (before anything is timed)."""
    shapes = Shapes.build([box_vertices(2.0, 0.0, 1.0, 1.0, 0.0)], [0], [(0.0, 3.0, 0.5)], [1])
    for fast in (False, True):
        cast((0.0, 0.0), np.linspace(-1.0, 1.0, 5), shapes, 10.0, grid=fast)
        footprint_clearance((0.0, 0.0, 0.0), footprint_vertices(0.5, 0.2, 0.4), 0.3, shapes, cull=fast)
        footprint_clearance((0.0, 0.0, 0.0), None, 0.3, shapes, cull=fast)
