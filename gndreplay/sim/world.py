"""A 2D world of line segments, dynamic elements as functions of time, and a simulated 2D laser.

A segment is a row ``(x0, y0, x1, y1)`` [m] in the world frame. Static geometry is one ``(M, 4)`` array;
moving things (a door leaf that swings, a person walking) are small frozen dataclasses implementing
:class:`DynamicElement`: ``segments_at(t_s)`` gives their segments at time ``t_s`` [s, from the start of
the run]. Ray casting is a numba kernel over beams x segments; noise comes in only through an explicit
``np.random.Generator``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from .geometry import ray_kernel

__all__ = [
    "DynamicElement",
    "LaserModel",
    "MovingPolygon",
    "SwingingDoor",
    "World",
    "add_laser_noise",
    "box",
    "cast_rays",
    "polygon",
    "quantize",
    "regular_polygon",
    "simulate_ranges",
    "wall",
]

F64 = NDArray[np.float64]
_NO_SEGMENTS: F64 = np.zeros((0, 4), dtype=np.float64)
_NO_CIRCLES: F64 = np.zeros((0, 3), dtype=np.float64)


# --------------------------------------------------------------------------------------------- building


def polygon(vertices_xy: ArrayLike, *, closed: bool = True) -> F64:
    """Segments along a polyline of ``(K, 2)`` vertices [m]; ``closed`` joins the last vertex to the first.

    Returns:
        ``(K, 4)`` segments if closed, else ``(K - 1, 4)``.

    Raises:
        ValueError: ``vertices_xy`` is not ``(K, 2)`` with K >= 2.
    """
    v = np.asarray(vertices_xy, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 2:
        raise ValueError(f"vertices_xy must have shape (K>=2, 2), got {v.shape}")
    end = np.roll(v, -1, axis=0) if closed else v[1:]
    start = v if closed else v[:-1]
    return np.ascontiguousarray(np.hstack([start, end]))


def box(cx: float, cy: float, length_m: float, width_m: float, *, angle_rad: float = 0.0) -> F64:
    """Sides of a rectangle centred at (cx, cy): ``length_m`` along ``angle_rad``, ``width_m`` across."""
    hx, hy = length_m / 2.0, width_m / 2.0
    corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    c, s = dm.cos(angle_rad), dm.sin(angle_rad)
    return polygon(np.column_stack([cx + c * corners[:, 0] - s * corners[:, 1],
                                    cy + s * corners[:, 0] + c * corners[:, 1]]))


def regular_polygon(cx: float, cy: float, radius_m: float, *, sides: int = 8) -> F64:
    """A regular polygon with ``sides`` vertices on a circle of ``radius_m`` (pillars, bins, people)."""
    if sides < 3:
        raise ValueError(f"sides must be >= 3, got {sides}")
    a = np.arange(sides) * (2.0 * np.pi / sides)
    return polygon(np.column_stack([cx + radius_m * dm.cos_a(a), cy + radius_m * dm.sin_a(a)]))


def wall(x0: float, y0: float, x1: float, y1: float, *, gaps: Sequence[tuple[float, float]] = ()) -> F64:
    """A straight wall from (x0, y0) to (x1, y1) [m] with openings (doors).

    Args:
        gaps: ``(start_m, end_m)`` intervals measured along the wall from (x0, y0), sorted, inside the wall.

    Returns:
        ``(len(gaps) + 1, 4)`` segments (pieces of zero length are dropped).

    Raises:
        ValueError: a gap is empty, overlaps another or lies outside the wall.
    """
    p0 = np.array([x0, y0], dtype=np.float64)
    d = np.array([x1 - x0, y1 - y0], dtype=np.float64)
    length = float(np.hypot(*d))
    u = d / length
    cuts = [0.0]
    for a, b in gaps:
        if not cuts[-1] <= a < b <= length:
            raise ValueError(f"gap ({a}, {b}) must be sorted, non-empty and inside the wall (0, {length})")
        cuts += [a, b]
    cuts.append(length)
    pieces = [(a, b) for a, b in zip(cuts[::2], cuts[1::2], strict=True) if b > a]
    return np.array([[*(p0 + a * u), *(p0 + b * u)] for a, b in pieces], dtype=np.float64).reshape(-1, 4)


# --------------------------------------------------------------------------------------------- dynamics


@runtime_checkable
class DynamicElement(Protocol):
    """Something whose segments depend on time."""

    def segments_at(self, t_s: float) -> F64:
        """``(K, 4)`` segments at ``t_s`` [s since the start of the run]; K may be 0 (not present)."""
        ...


def _ramp(t_s: float, t0_s: float, t1_s: float) -> float:
    """0 before t0, 1 after t1, linear in between (a step at t0 when t1 <= t0)."""
    if t_s <= t0_s:
        return 0.0
    if t_s >= t1_s:
        return 1.0
    return (t_s - t0_s) / (t1_s - t0_s)


@dataclass(frozen=True, slots=True)
class SwingingDoor:
    """A door leaf of ``length_m`` hinged at ``hinge_xy``, turning from ``angle_from_rad`` to ``angle_to_rad``
    (world frame) at constant rate between ``t_start_s`` and ``t_end_s``; still before and after."""

    hinge_xy: tuple[float, float]
    length_m: float
    angle_from_rad: float
    angle_to_rad: float
    t_start_s: float = 0.0
    t_end_s: float = 0.0

    def segments_at(self, t_s: float) -> F64:
        f = _ramp(t_s, self.t_start_s, self.t_end_s)
        a = self.angle_from_rad + f * (self.angle_to_rad - self.angle_from_rad)
        hx, hy = self.hinge_xy
        return np.array([[hx, hy, hx + self.length_m * dm.cos(a), hy + self.length_m * dm.sin(a)]])


@dataclass(frozen=True, slots=True)
class MovingPolygon:
    """A rigid outline (e.g. a person) translated along keyframes, present only from the first to the last.

    Attributes:
        outline: ``(K, 4)`` segments in the element's own frame (centred on its reference point).
        keyframes: ``((t_s, x, y), ...)`` sorted by time; the position is interpolated linearly.
    """

    outline: tuple[tuple[float, float, float, float], ...]
    keyframes: tuple[tuple[float, float, float], ...]

    def __post_init__(self) -> None:
        times = [k[0] for k in self.keyframes]
        if len(times) < 2 or any(b <= a for a, b in itertools.pairwise(times)):
            raise ValueError(f"keyframes must have >= 2 entries with increasing times, got {times}")

    @staticmethod
    def person(keyframes: Sequence[tuple[float, float, float]], *, radius_m: float = 0.22) -> MovingPolygon:
        """A walking person: an octagon of ``radius_m`` moved along ``keyframes`` ``(t_s, x, y)``."""
        outline = regular_polygon(0.0, 0.0, radius_m, sides=8)
        return MovingPolygon(
            outline=tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in outline),
            keyframes=tuple((float(t), float(x), float(y)) for t, x, y in keyframes),
        )

    def position_at(self, t_s: float) -> tuple[float, float] | None:
        """Reference point at ``t_s``, or None outside the keyframes' time span."""
        k = np.asarray(self.keyframes, dtype=np.float64)
        if t_s < k[0, 0] or t_s > k[-1, 0]:
            return None
        return float(np.interp(t_s, k[:, 0], k[:, 1])), float(np.interp(t_s, k[:, 0], k[:, 2]))

    def segments_at(self, t_s: float) -> F64:
        p = self.position_at(t_s)
        if p is None:
            return _NO_SEGMENTS
        return np.asarray(self.outline, dtype=np.float64) + np.array([p[0], p[1], p[0], p[1]])


@dataclass(frozen=True, slots=True, eq=False)
class World:
    """Static segments plus dynamic elements.

    Attributes:
        segments: ``(M, 4)`` static segments ``(x0, y0, x1, y1)`` [m] (walls, furniture, open door leaves).
        dynamic: elements whose segments change with time.
        name: a label for reports.
    """

    segments: F64
    dynamic: tuple[DynamicElement, ...] = ()
    name: str = "world"

    def __post_init__(self) -> None:
        s = np.ascontiguousarray(self.segments, dtype=np.float64)
        if s.ndim != 2 or s.shape[1] != 4:
            raise ValueError(f"segments must have shape (M, 4), got {s.shape}")
        s.flags.writeable = False
        object.__setattr__(self, "segments", s)

    @staticmethod
    def from_parts(*parts: ArrayLike, dynamic: Sequence[DynamicElement] = (), name: str = "world") -> World:
        """A world from several ``(K_i, 4)`` segment arrays."""
        segs = [np.asarray(p, dtype=np.float64).reshape(-1, 4) for p in parts]
        return World(np.vstack(segs) if segs else _NO_SEGMENTS, tuple(dynamic), name)

    def segments_at(self, t_s: float) -> F64:
        """All segments present at ``t_s`` [s]: static ones first, then each dynamic element's."""
        if not self.dynamic:
            return self.segments
        return np.ascontiguousarray(np.vstack([self.segments, *(d.segments_at(t_s) for d in self.dynamic)]))

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the static segments [m]."""
        xs, ys = self.segments[:, [0, 2]], self.segments[:, [1, 3]]
        return float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())


# --------------------------------------------------------------------------------------------- ray casting


def cast_rays(origin_xy: ArrayLike, angles_rad: ArrayLike, segments: ArrayLike, *, max_range_m: float) -> F64:
    """Exact ranges from ``origin_xy`` along world-frame bearings to the nearest segment.

    Args:
        origin_xy: ``(2,)`` ray origin [m].
        angles_rad: ``(N,)`` world-frame bearings [rad].
        segments: ``(M, 4)`` segments ``(x0, y0, x1, y1)`` [m]. A ray parallel to a segment does not hit it.
        max_range_m: hits at or beyond this distance are reported as no-return.

    Returns:
        ``(N,)`` float64 ranges [m]; ``+inf`` where nothing is hit closer than ``max_range_m``.

    Raises:
        ValueError: wrong shapes or a non-positive ``max_range_m``.
    """
    o = np.asarray(origin_xy, dtype=np.float64)
    a = np.ascontiguousarray(angles_rad, dtype=np.float64)
    s = np.ascontiguousarray(segments, dtype=np.float64)
    if o.shape != (2,):
        raise ValueError(f"origin_xy must have shape (2,), got {o.shape}")
    if a.ndim != 1:
        raise ValueError(f"angles_rad must be 1-D, got shape {a.shape}")
    if s.ndim != 2 or s.shape[1] != 4:
        raise ValueError(f"segments must have shape (M, 4), got {s.shape}")
    if not max_range_m > 0.0:
        raise ValueError(f"max_range_m must be > 0, got {max_range_m}")
    out = np.empty(a.shape[0], dtype=np.float64)
    ray_kernel(float(o[0]), float(o[1]), a, s, _NO_CIRCLES, float(max_range_m), out)
    return out


# --------------------------------------------------------------------------------------------- the laser


@dataclass(frozen=True, slots=True)
class LaserModel:
    """A SICK LMS-like 2D laser.

    Attributes:
        n_beams: beams over ``fov_rad``, first at ``-fov/2`` (right), last at ``+fov/2`` (left).
        fov_rad: field of view [rad].
        max_range_m: no return at or beyond this range (SICK LMS 200, 8 m / mm mode).
        min_range_m: readings below are invalid (nan).
        range_sigma_m: standard deviation of the Gaussian range noise [m].
        dropout_prob: probability that a beam returns nothing (+inf) although it hits something.
        resolution_m: ranges are rounded to multiples of this (the LMS reports millimetres); 0 = exact.
    """

    n_beams: int = 361
    fov_rad: float = math.pi
    max_range_m: float = 8.0
    min_range_m: float = 0.0
    range_sigma_m: float = 0.01
    dropout_prob: float = 0.002
    resolution_m: float = 0.001

    def __post_init__(self) -> None:
        if self.n_beams < 2:
            raise ValueError(f"n_beams must be >= 2, got {self.n_beams}")
        if not 0.0 <= self.dropout_prob < 1.0:
            raise ValueError(f"dropout_prob must be in [0, 1), got {self.dropout_prob}")
        if self.range_sigma_m < 0.0:
            raise ValueError(f"range_sigma_m must be >= 0, got {self.range_sigma_m}")

    def angles(self) -> F64:
        """``(n_beams,)`` beam bearings in the sensor frame [rad], right to left."""
        return np.linspace(-self.fov_rad / 2.0, self.fov_rad / 2.0, self.n_beams)


def quantize(values: ArrayLike, step: float) -> F64:
    """Round to multiples of ``step`` (0 = unchanged); for ``step = 1/k`` the results are the doubles nearest
    to the decimal values, so they print short (``4.254``, not ``4.2540000000000004``)."""
    v = np.asarray(values, dtype=np.float64)
    if step <= 0.0:
        return v
    k = round(1.0 / step)
    if k >= 1 and math.isclose(k * step, 1.0, rel_tol=1e-12):
        return np.round(v * k) / k
    return np.round(v / step) * step


def simulate_ranges(
    world: World,
    laser_pose: ArrayLike,
    t_s: float,
    laser: LaserModel,
    *,
    rng: np.random.Generator | None = None,
) -> F64:
    """One scan of ``laser`` at ``laser_pose`` (world frame, ``(3,)``) in ``world`` at time ``t_s``.

    Without ``rng`` the ranges are exact. With it, they get Gaussian noise, are rounded to
    ``laser.resolution_m`` and some drop out; each call draws exactly ``2 * n_beams`` numbers (noise, then
    dropouts), so a seeded generator gives the same stream whatever the geometry.

    Returns:
        ``(n_beams,)`` ranges [m]: finite hits, ``+inf`` no return, ``nan`` below ``min_range_m``.
    """
    p = np.asarray(laser_pose, dtype=np.float64)
    exact = cast_rays(p[:2], laser.angles() + p[2], world.segments_at(t_s), max_range_m=laser.max_range_m)
    if rng is None:
        return exact
    return add_laser_noise(exact, laser, rng)


def add_laser_noise(exact: F64, laser: LaserModel, rng: np.random.Generator) -> F64:
    """Exact ranges -> what ``laser`` reports: Gaussian noise, rounding to ``resolution_m``, dropouts,
    no-return at max range, nan below min range. Draws exactly ``2 * n_beams`` numbers (noise, then
    dropouts), so a seeded generator gives the same stream whatever the geometry."""
    noise = rng.standard_normal(laser.n_beams) * laser.range_sigma_m
    drop = rng.random(laser.n_beams) < laser.dropout_prob
    with np.errstate(invalid="ignore"):
        r = exact + noise
        r = quantize(r, laser.resolution_m)
    r[(r >= laser.max_range_m) | drop] = np.inf
    r[r < laser.min_range_m] = np.nan
    return r
