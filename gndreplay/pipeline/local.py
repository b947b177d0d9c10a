"""Local navigation strategies of the multi-loop paper on a robot-centred polar occupancy map.

The multi-loop paper (seeds/002, section 3.2) moves the robot "with no given references" from a radial,
robot-centred occupancy map (its "perception maps", Fig. 4) and a simple strategy: "follow the free space",
"follow the environment on the left/right" or "contour obstacles". It gives no laws for them (they are in its
reference [7]); the laws below are ours, each stated where it is implemented. ND+ (``nd.nd_step``) stays the
default local navigation. Every strategy is an entry of :data:`STRATEGIES`, called alike
(:class:`LocalStrategy`): "nd" through the caller's ND+ (which carries its commitment between ticks), the
others on the polar map (:func:`local_command`, one law each in :data:`POLAR_LAWS`).

Frames and sectors are ND+'s (``nd`` module docstring): robot frame x forward, y left, angles
counter-clockwise in (-pi, pi], origin at the rotation centre; sector ``i`` of ``n`` has its bisector at
``i * 2 pi / n`` (0 ahead, ``n/2`` behind) and covers half a sector either side.

Two questions are asked of the map:

* **free distance** per sector (:attr:`PolarMap.free_m`): along the ray through an obstacle point, the
  distance from the robot's real footprint boundary (rectangle or circle) to the point; the smallest over
  the sector's points. The wall and contour laws read it.
* **travel** along a direction (:func:`travel_m`): how far the footprint can translate before an obstacle
  comes within a margin of it. Each occupied sector is taken as the arc of its nearest point's range
  spanning the whole sector (sampled at the two sector edges and the bisector). The footprint swept along a
  line is convex and contains the origin, so a point farther out on the same ray is never reached first:
  the arc bounds every point of the sector from the inside, up to the arc's sag between samples (at most
  ``r (1 - cos(delta / 4))``, 0.2 mm at 5 m with 2 deg sectors). The price is a travel short of the exact
  one by up to about ``r delta tan(incidence)`` (3 cm for a wall 1.5 m away seen at 30 deg from its normal).
  Speeds and direction choices read it; contour with a target asks it for every sector's direction at once
  (one compiled loop over directions x arc samples, ``_travel_kernel``).

Every command leaves through one speed law (:func:`_limit`), whatever the strategy: the translation speed is
``D / approach_s`` at most, ``D`` the travel in the motion direction of the footprint grown by ``safety_m``
(so it is zero once an obstacle it would approach is within the safety distance, and the robot needs
``approach_s`` at that speed to close the remaining gap), and the turn rate of a rectangle is bounded the
same way by the angle it can rotate before a corner comes within ``safety_m`` of an obstacle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from ..errors import ConfigError, did_you_mean
from ..robot import RobotConfig
from ..types import Flag, Mode
from .nd import NdResult, Situation, drive, robot_boundary_m, sector_angles, sector_of, sectorise, wrap

__all__ = ["LOCAL_STRATEGIES", "POLAR_LAWS", "STRATEGIES", "LocalCommand", "LocalParams", "LocalStrategy",
           "NdCall", "PolarLaw", "PolarMap", "local_command", "polar_map", "travel_m", "warm_up_local"]

F64 = NDArray[np.float64]

_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
# a motion brings a point within the margin closer only if its distance falls by more than this per metre
# travelled (1e-9 rad from parallel): a direction parallel to a wall up to rounding (d = -1e-189 beside a
# point 2.5 cm off the chair's side) slides along it, as supervisor.arc_touches' 1e-9 m tolerance has it
_CLOSER_PER_M = 1e-9


@dataclass(frozen=True, slots=True)
class LocalParams:
    """Local navigation settings ([navigation.local]). Ranges: ``config.RANGES``.

    Attributes:
        strategy: a key of :data:`STRATEGIES`: "nd" (ND+, the default), "free-space", "wall-left",
            "wall-right" or "contour".
        n_sectors: sectors of the polar map over 360 deg (180: 2 deg, as ND+).
        max_range_m: obstacle points farther than this from the rotation centre are ignored; an empty
            sector has free distance ``max_range_m``, and travels are capped there.
        safety_m: the robot does not translate towards an obstacle within this distance of its footprint
            (nor does a rectangle turn towards one). **Choice**: 0.1 m, two 5 cm cells (the
            map's points are cell centres, half a cell inside the obstacle's edge).
        approach_s: speed law: translation speed at most ``travel / approach_s``, travel measured to
            ``safety_m`` (the time to close the gap at that speed); turn rate likewise. **Choice**: 2 s;
            the wheelchair (0.3 m/s) keeps full speed beyond 0.6 m of travel.
        wall_distance_m: wall following: the distance kept between the footprint and the wall.
        contour_distance_m: contour: the distance kept between the footprint and the obstacle.
        contour_side: contour without a target, or when both ways round are equally short: the side the
            obstacle is kept on ("left": the robot goes round it anticlockwise).
        distance_gain_per_m: boundary following: heading correction ``atan(gain * error)`` for a distance
            error [m]. **Choice**: 2.5 /m, tuned on the chair in closed loop (tests/test_local.py): it
            holds a corridor wall within 1.5 cm after settling; the proportional law still orbits a
            convex corner up to ~0.3 m wide of the set distance (a lower gain settles slower and orbits
            wider).
        max_correction_rad: the largest heading correction towards / away from the boundary (the angle at
            which the robot approaches a wall it is far from).
        side_window_rad: wall following looks for the wall on its side between straight ahead (0) and this
            angle from ahead (150 deg: a corner just passed stays in view, the robot behind is ignored).
        free_margin_m: free space: directions are scored by the travel of the footprint grown by this
            margin (keeps the robot off door frames and walls).
        deep_ratio: free space: a direction is "deep" when its travel is at least this fraction of the
            deepest one; runs of deep directions are the free clusters.
        target_weight: free space: a cluster's score (mean depth x angular width) is multiplied by
            ``1 - target_weight * (angle from the preferred direction) / pi``.
        clear_m: contour: the target direction is clear (contouring ends) when the footprint grown by
            ``safety_m`` travels ``min(target distance, clear_m)`` along it.
        side_hysteresis_rad: contour: the two ways round count as equally short within this angle (then
            the caller's ``side_hint``, else ``contour_side``, decides).
        rotation_step_rad: rectangle: resolution of the rotation check (a corner's arc is sampled at this
            step; at 0.87 m, 0.5 deg is 8 mm, well inside ``safety_m``).
    """

    strategy: str = "nd"
    n_sectors: int = 180
    max_range_m: float = 5.0
    safety_m: float = 0.1
    approach_s: float = 2.0
    wall_distance_m: float = 0.5
    contour_distance_m: float = 0.5
    contour_side: Literal["left", "right"] = "left"
    distance_gain_per_m: float = 2.5
    max_correction_rad: float = math.pi / 4.0
    side_window_rad: float = 5.0 * math.pi / 6.0
    free_margin_m: float = 0.2
    deep_ratio: float = 0.8
    target_weight: float = 0.5
    clear_m: float = 2.0
    side_hysteresis_rad: float = 0.2
    rotation_step_rad: float = math.pi / 360.0

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ConfigError(f"strategy: expected one of {', '.join(STRATEGIES)}, got {self.strategy!r}"
                              f"{did_you_mean(self.strategy, STRATEGIES)}")
        if self.contour_side not in ("left", "right"):
            raise ConfigError(f"navigation.local.contour_side must be 'left' or 'right', "
                              f"got {self.contour_side!r}")
        if self.n_sectors < 8:
            raise ConfigError(f"navigation.local.n_sectors must be >= 8, got {self.n_sectors}")
        for name in ("max_range_m", "approach_s", "distance_gain_per_m", "max_correction_rad",
                     "side_window_rad", "deep_ratio", "clear_m", "rotation_step_rad"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"navigation.local.{name} must be > 0, got {getattr(self, name)}")
        for name in ("safety_m", "wall_distance_m", "contour_distance_m", "free_margin_m", "target_weight",
                     "side_hysteresis_rad"):
            if not getattr(self, name) >= 0.0:
                raise ConfigError(f"navigation.local.{name} must be >= 0, got {getattr(self, name)}")


@dataclass(frozen=True, slots=True, eq=False)
class PolarMap:
    """Robot-centred polar occupancy: per sector, the free distance from the footprint boundary [m].

    Attributes:
        angles_rad: (n,) sector bisectors [rad] (``nd.sector_angles``).
        free_m: (n,) per sector, the smallest distance along a ray from the footprint boundary to an
            obstacle point of the sector (0 for a point inside the footprint); ``max_range_m`` when empty.
        free_angle_rad: (n,) the angle of the point giving ``free_m`` (the bisector when empty). None:
            the bisectors.
        range_m: (n,) distance from the rotation centre to the sector's nearest point; inf when empty.
            None: rebuilt as boundary + free distance along the bisector, for sectors below ``max_range_m``.
        max_range_m: the range the map was built with (inf: unknown).
    """

    angles_rad: F64
    free_m: F64
    free_angle_rad: F64 | None = None
    range_m: F64 | None = None
    max_range_m: float = math.inf

    @property
    def occupied(self) -> NDArray[np.bool_]:
        """(n,) True for sectors holding an obstacle point."""
        if self.range_m is not None:
            return np.isfinite(self.range_m)
        return self.free_m < self.max_range_m


@dataclass(frozen=True, slots=True)
class LocalCommand:
    """A local strategy's motion and the direction it chose (robot frame).

    Attributes:
        v_mps: forward velocity (>= 0 for a differential drive).
        vy_mps: lateral velocity (0 for a differential drive).
        w_radps: turn rate, counter-clockwise positive.
        direction_rad: the motion direction the strategy chose, before the speed law.
        side: the side the followed wall / contoured obstacle is kept on: +1 left, -1 right, 0 none (free
            space, or contour heading straight for its target). Pass it back as ``side_hint`` next tick.
        mode: what the command is: Mode.LOCAL for the polar map strategies; ND+ reports Mode.MND, or
            Mode.ROTATE without a free walking area (a turn in place towards the target whose rate the
            caller sets: ``w_radps`` is 0).
        situation: ND+'s situation (Situation.NONE for the others).
        flag: ND+'s flag (REACTOR_NO_REGION); Flag.NONE for the others.
    """

    v_mps: float
    vy_mps: float
    w_radps: float
    direction_rad: float
    side: int = 0
    mode: Mode = Mode.LOCAL
    situation: Situation = Situation.NONE
    flag: Flag = Flag.NONE


# --------------------------------------------------------------------------------------------------
# The map


def _points(obstacles_xy: ArrayLike) -> F64:
    """``obstacles_xy`` as an (M, 2) float array; ValueError for another shape."""
    pts = np.asarray(obstacles_xy, dtype=np.float64)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"obstacles_xy must have shape (M, 2), got shape {pts.shape}")
    return pts


def polar_map(obstacles_xy: NDArray[np.float64], robot: RobotConfig, params: LocalParams) -> PolarMap:
    """The polar occupancy map of obstacle points given in the robot frame.

    Parameters
    ----------
    obstacles_xy : (M, 2) array
        Obstacle points [m] in the robot frame (occupied cell centres); M may be 0. Non-finite rows and
        points beyond ``params.max_range_m`` are ignored.
    robot : RobotConfig
        The footprint (rectangle about the rotation centre, or circle).
    params : LocalParams
        ``n_sectors`` and ``max_range_m``.

    Raises
    ------
    ValueError
        If ``obstacles_xy`` is not (M, 2).
    ConfigError
        If the robot shape is invalid.
    """
    pts = _points(obstacles_xy)
    n, cap = params.n_sectors, params.max_range_m
    bis = sector_angles(n)
    range_m, _ = sectorise(pts, bis, cap)  # nearest point per sector (nd's kernel, same sector rule)
    free = np.full(n, cap)
    free_ang = bis.copy()
    r = np.hypot(pts[:, 0], pts[:, 1])
    keep = r <= cap  # also drops nan / inf rows
    if keep.any():
        p, r = pts[keep], r[keep]
        a = dm.atan2_a(p[:, 1], p[:, 0])
        idx = sector_of(a, n)
        f = np.maximum(r - robot_boundary_m(robot, a), 0.0)
        order = np.lexsort((f, idx))  # by sector, then free distance: the first of each sector is its min
        first = order[np.r_[True, idx[order][1:] != idx[order][:-1]]]
        free[idx[first]] = np.minimum(f[first], cap)
        free_ang[idx[first]] = a[first]
    else:
        robot_boundary_m(robot, bis[:1])  # still reject an invalid robot
    return PolarMap(bis, free, free_ang, range_m, float(cap))


def _arcs(polar: PolarMap, robot: RobotConfig) -> tuple[F64, F64]:
    """(x, y) of each occupied sector's arc, sampled at its two edges and its bisector (robot frame)."""
    occ = polar.occupied
    ang = polar.angles_rad[occ]
    r = polar.range_m[occ] if polar.range_m is not None else robot_boundary_m(robot, ang) + polar.free_m[occ]
    half = math.pi / polar.angles_rad.size
    a = (ang[:, None] + np.array([-half, 0.0, half])).ravel()
    rr = np.repeat(r, 3)
    return rr * dm.cos_a(a), rr * dm.sin_a(a)


# --------------------------------------------------------------------------------------------------
# Travel of the footprint


@njit(cache=True)
def _travel_kernel(px: F64, py: F64, c: F64, s: F64, turn_first: bool, circle: bool, radius: float,
                   front: float, rear: float, hw: float, margin: float) -> F64:  # pragma: no cover (numba)
    """Per direction k (unit vector (c[k], s[k])), the least distance the footprint travels before one of
    the points (px, py) comes within ``margin`` of it; inf if none ever does. ``turn_first``: the points
    are first turned into the frame of a footprint facing the direction, which then moves straight ahead.

    Per point: a point already within the margin blocks (0) only a motion that brings it closer (by more
    than ``_CLOSER_PER_M`` per metre; distance to a convex set along a line is convex, so a motion that does
    not bring it closer never does); a point inside the real footprint blocks every motion. The grown
    rectangle keeps square corners (conservative). Entry / exit times of the line through the grown
    footprint: a quadratic for the circle, two slabs for the rectangle."""
    inf = np.inf
    out = np.full(c.size, inf)
    rad = radius + margin
    for k in range(c.size):
        ck, sk = c[k], s[k]
        best = inf
        for j in range(px.size):
            if turn_first:
                qx = px[j] * ck + py[j] * sk
                qy = py[j] * ck - px[j] * sk
                dx, dy = 1.0, 0.0
            else:
                qx, qy, dx, dy = px[j], py[j], ck, sk
            if circle:
                b = qx * dx + qy * dy
                q2 = qx * qx + qy * qy
                disc = b * b - (q2 - rad * rad)
                root = math.sqrt(max(disc, 0.0))
                t_in, t_out = b - root, b + root
                hit = disc >= 0.0 and t_out >= 0.0
                in_real = q2 <= radius * radius
                closer = b > _CLOSER_PER_M * math.sqrt(q2)
            else:
                if turn_first:  # straight ahead: no y slab to cross
                    t_in, t_out = qx - front - margin, qx + rear + margin
                    hit = abs(qy) <= hw + margin and t_out >= 0.0
                else:
                    t_in, t_out = _slab(qx, dx, -rear - margin, front + margin)
                    ty_in, ty_out = _slab(qy, dy, -hw - margin, hw + margin)
                    t_in, t_out = max(t_in, ty_in), min(t_out, ty_out)
                    hit = t_in <= t_out and t_out >= 0.0
                nx = qx - min(max(qx, -rear), front)
                ny = qy - min(max(qy, -hw), hw)
                in_real = nx == 0.0 and ny == 0.0
                closer = nx * dx + ny * dy > _CLOSER_PER_M * math.hypot(nx, ny)
            if not hit:
                continue
            # within the margin already: blocks only if inside the real footprint or coming closer
            t = (0.0 if in_real or closer else inf) if t_in <= 0.0 else t_in
            if t < best:
                best = t
        out[k] = best
    return out


@njit(cache=True)
def _slab(q: float, d: float, lo: float, hi: float) -> tuple[float, float]:  # pragma: no cover (numba)
    """Entry / exit times of the ray ``q - t d`` through the slab [lo, hi] (+-inf when d = 0)."""
    if d != 0.0:
        t1, t2 = (q - hi) / d, (q - lo) / d
        return min(t1, t2), max(t1, t2)
    if lo <= q <= hi:
        return -np.inf, np.inf
    return np.inf, -np.inf


def travel_m(polar: PolarMap, directions_rad: ArrayLike, robot: RobotConfig, *, margin_m: float = 0.0,
             turn_first: bool = False, reach_m: float = math.inf) -> F64:
    """How far the footprint can translate along each direction before an obstacle of ``polar`` comes
    within ``margin_m`` of it [m] (inf: never; not capped).

    ``turn_first``: the footprint is first turned to face the direction (a differential robot, which
    cannot translate sideways, turns then drives); else it keeps its heading (the current motion, or a
    holonomic base). ``reach_m``: only whether the travel reaches this far matters to the caller; obstacles
    that cannot stop it before (farther than reach + footprint + margin) are skipped, so a result
    ``>= reach_m`` may be inf.
    """
    d = np.atleast_1d(np.asarray(directions_rad, dtype=np.float64))
    px, py = _arcs(polar, robot)
    if math.isfinite(reach_m):
        keep = np.hypot(px, py) <= reach_m + robot.outer_radius_m + margin_m
        px, py = px[keep], py[keep]
    if px.size == 0:
        return np.full(d.shape, np.inf)
    circle = robot.shape == "circle"
    res: F64 = _travel_kernel(px, py, dm.cos_a(d), dm.sin_a(d), turn_first, circle,
                              robot.radius_m if circle else 0.0, 0.0 if circle else robot.front_m,
                              0.0 if circle else robot.rear_m, 0.0 if circle else 0.5 * robot.width_m,
                              float(margin_m))
    return res.reshape(d.shape)


def _turn_limits(polar: PolarMap, robot: RobotConfig, params: LocalParams) -> tuple[float, float]:
    """(largest w > 0, largest |w| for w < 0) the rectangle may turn at: ``(phi - safety_m / r) /
    approach_s``, phi the rotation (sampled every ``rotation_step_rad``, last clear sample) before an arc
    point at range r enters the footprint. A circle turns freely."""
    if robot.shape == "circle":
        return math.inf, math.inf
    px, py = _arcs(polar, robot)
    r = np.hypot(px, py)
    near = r < robot.outer_radius_m
    if not near.any():
        return math.inf, math.inf
    r, a = np.maximum(r[near], 1e-9), dm.atan2_a(py[near], px[near])  # r > 0: the safety angle below
    phi_max = min(math.pi, robot.wmax_radps * params.approach_s + params.safety_m / float(r.min()))
    phi = np.arange(0.0, phi_max + params.rotation_step_rad, params.rotation_step_rad)
    hw = 0.5 * robot.width_m
    limits = []
    for sign in (1.0, -1.0):  # w > 0 turns the obstacles clockwise in the robot frame
        ang = a[:, None] - sign * phi[None, :]
        x, y = r[:, None] * dm.cos_a(ang), r[:, None] * dm.sin_a(ang)
        inside = (x <= robot.front_m) & (x >= -robot.rear_m) & (np.abs(y) <= hw)
        first = np.where(inside.any(axis=1), inside.argmax(axis=1), phi.size)
        clear_phi = phi[np.maximum(first - 1, 0)]
        clear_phi = np.where(first == 0, 0.0, np.where(first == phi.size, np.inf, clear_phi))
        limits.append(max(0.0, float(np.min(clear_phi - params.safety_m / r))) / params.approach_s)
    return limits[0], limits[1]


def _limit(theta: float, polar: PolarMap, robot: RobotConfig, params: LocalParams, side: int,
           ) -> LocalCommand:
    """Drive towards ``theta`` (ND+'s mapping, ``nd.drive``: turn rate proportional to the direction,
    differential speed falling to 0 at +-90 deg) at full speed, then apply the speed law: translation at
    most ``D / approach_s`` with D the travel in the motion direction of the footprint grown by
    ``safety_m`` (0 when an obstacle within ``safety_m`` would come closer), and a rectangle's turn rate at
    most what :func:`_turn_limits` allows."""
    v, vy, w = drive(theta, robot.vmax_mps, robot)
    speed = math.hypot(v, vy)
    if speed > 0.0:
        motion = dm.atan2(vy, v)
        full = robot.vmax_mps * params.approach_s  # travel beyond this allows full speed
        d = float(travel_m(polar, motion, robot, margin_m=params.safety_m, reach_m=full)[0])
        allowed = d / params.approach_s
        if allowed < speed:
            k = allowed / speed
            v, vy = v * k, vy * k
    if w != 0.0:
        w_pos, w_neg = _turn_limits(polar, robot, params)
        w = min(w, w_pos) if w > 0.0 else max(w, -w_neg)
    return LocalCommand(float(v), float(vy), float(w), float(theta), side)


# --------------------------------------------------------------------------------------------------
# Strategies


def _boundary_direction(polar: PolarMap, side: int, distance_m: float, window: NDArray[np.bool_],
                        params: LocalParams) -> float | None:
    """Boundary following (wall and contour): the obstacle nearest the footprint within ``window`` sets
    the boundary; move along its tangent (perpendicular to the point's bearing, the boundary on ``side``)
    turned by ``side * atan(gain * (free - distance_m))``, clamped to ``max_correction_rad``: towards the
    boundary when too far, away when too close. At a convex corner the nearest point falls behind and the
    tangent turns towards the open side; at a concave corner the wall ahead becomes nearest and the tangent
    turns away from it. None when the window holds no obstacle."""
    cand = window & polar.occupied
    if not cand.any():
        return None
    idx = np.flatnonzero(cand)
    i = int(idx[np.argmin(polar.free_m[idx])])
    angles = polar.free_angle_rad if polar.free_angle_rad is not None else polar.angles_rad
    bearing = float(angles[i])
    err = float(polar.free_m[i]) - distance_m
    corr = min(max(dm.atan(params.distance_gain_per_m * err), -params.max_correction_rad),
               params.max_correction_rad)
    return wrap(bearing - side * _HALF_PI + side * corr)


def _side_window(polar: PolarMap, side: int, params: LocalParams) -> NDArray[np.bool_]:
    """Sectors on ``side`` from straight ahead to ``side_window_rad`` (ahead included)."""
    a = side * polar.angles_rad
    window: NDArray[np.bool_] = (a >= -1e-9) & (a <= params.side_window_rad + 1e-9)
    return window


def _wall(polar: PolarMap, side: int, robot: RobotConfig, params: LocalParams) -> LocalCommand:
    """Follow the environment on ``side`` at ``wall_distance_m`` (boundary following over the side
    window); straight ahead while nothing is in view on that side."""
    window = _side_window(polar, side, params)
    theta = _boundary_direction(polar, side, params.wall_distance_m, window, params)
    return _limit(0.0 if theta is None else theta, polar, robot, params, side if theta is not None else 0)


def _wall_left(polar: PolarMap, target: tuple[float, float] | None, robot: RobotConfig,
               params: LocalParams, side_hint: int) -> LocalCommand:
    """Follow the environment on the left (:func:`_wall`); no target."""
    return _wall(polar, 1, robot, params)


def _wall_right(polar: PolarMap, target: tuple[float, float] | None, robot: RobotConfig,
                params: LocalParams, side_hint: int) -> LocalCommand:
    """Follow the environment on the right (:func:`_wall`); no target."""
    return _wall(polar, -1, robot, params)


def _target(target_xy: NDArray[np.float64] | None) -> tuple[float, float] | None:
    """(distance, bearing) of the target, None without one."""
    if target_xy is None:
        return None
    t = np.asarray(target_xy, dtype=np.float64).reshape(-1)
    if t.shape != (2,) or not np.all(np.isfinite(t)):
        raise ValueError(f"target_xy must be two finite numbers or None, got {target_xy!r}")
    return math.hypot(t[0], t[1]), wrap(dm.atan2(t[1], t[0]))


def _contour(polar: PolarMap, target: tuple[float, float] | None, robot: RobotConfig, params: LocalParams,
             side_hint: int) -> LocalCommand:
    """Contour the obstacle that blocks the target direction at ``contour_distance_m``.

    With a target: head straight for it when the footprint grown by ``safety_m`` (turned to face it, for a
    differential robot) travels ``min(distance, clear_m)`` towards it; else go round the obstacle on the
    side where the nearest clear direction deviates less from the target (within ``side_hysteresis_rad``:
    ``side_hint``, else ``contour_side``), following the boundary (:func:`_boundary_direction`) of the
    obstacle nearest the footprint on the side it is kept on (as a rule the one in the way; a nearer wall
    on that side is followed instead). Without a target: follow the boundary of the nearest obstacle in any
    direction, kept on ``contour_side``. Stateless but for ``side_hint``: the paper's local navigation is
    purely reactive.
    """
    turn_first = robot.drive != "holonomic"
    default_side = 1 if params.contour_side == "left" else -1
    all_sectors = np.ones(polar.angles_rad.size, dtype=bool)
    if target is None:
        theta = _boundary_direction(polar, default_side, params.contour_distance_m, all_sectors, params)
        return _limit(0.0 if theta is None else theta, polar, robot, params, default_side)
    dist, bearing = target
    need = min(dist, params.clear_m)
    grow = params.safety_m
    if float(travel_m(polar, bearing, robot, margin_m=grow, turn_first=turn_first, reach_m=need)[0]) >= need:
        return _limit(bearing, polar, robot, params, 0)
    depth = travel_m(polar, polar.angles_rad, robot, margin_m=grow, turn_first=turn_first, reach_m=need)
    clear = depth >= need
    if clear.any():
        ccw = np.mod(polar.angles_rad[clear] - bearing, _TWO_PI)
        dev_left, dev_right = float(ccw.min()), float((np.mod(-ccw, _TWO_PI)).min())
    else:
        dev_left = dev_right = math.inf
    if abs(dev_left - dev_right) <= params.side_hysteresis_rad or dev_left == dev_right:
        side = side_hint if side_hint in (1, -1) else default_side
    else:
        side = -1 if dev_left < dev_right else 1  # going round to the left keeps the obstacle on the right
    window = (side * polar.angles_rad >= -1e-9) & (side * polar.angles_rad <= math.pi)
    theta = _boundary_direction(polar, side, params.contour_distance_m, window, params)
    return _limit(bearing if theta is None else theta, polar, robot, params, side)


def _free_space(polar: PolarMap, target: tuple[float, float] | None, robot: RobotConfig,
                params: LocalParams, side_hint: int) -> LocalCommand:
    """Follow the free space: head for the most open cluster of sectors.

    With a target the robot can reach straight (footprint grown by ``free_margin_m``, turned to face it
    for a differential robot), go to it. Else the free clusters are the runs of sectors whose free distance
    is at least ``deep_ratio`` of the deepest; a cluster the robot does not fit through (gap between its
    two edge points narrower than the robot's width plus twice ``free_margin_m``) is dropped. Each is scored
    by mean free distance x angular width x ``1 - target_weight * (angle from the preferred direction) /
    pi``, the preferred direction being the target's, else straight ahead. In the best cluster the robot
    takes the preferred direction clamped to keep ``width / 2 + free_margin_m`` laterally from the edge
    points (ND+'s way past a gap's corner), or the cluster's middle when nothing is left after the clamp.
    No side is kept (``side_hint`` unused).
    """
    pref = 0.0
    if target is not None:
        dist, pref = target
        turn_first = robot.drive != "holonomic"
        need = min(dist, params.max_range_m)
        reach = float(travel_m(polar, pref, robot, margin_m=params.free_margin_m, turn_first=turn_first,
                               reach_m=need)[0])
        if reach >= need:
            return _limit(pref, polar, robot, params, 0)
    free, ang = polar.free_m, polar.angles_rad
    n = ang.size
    deep = free >= params.deep_ratio * float(free.max())
    if deep.all():
        return _limit(pref, polar, robot, params, 0)
    ranges = polar.range_m if polar.range_m is not None else robot_boundary_m(robot, ang) + free
    half_w = (robot.radius_m if robot.shape == "circle" else 0.5 * robot.width_m) + params.free_margin_m
    step = _TWO_PI / n
    start = int(np.flatnonzero(~deep)[0])  # a run never straddles this sector: no wrap inside a run
    order = (start + np.arange(n)) % n
    edges = np.diff(np.r_[0, deep[order].astype(np.int8), 0])
    firsts, lasts = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    best: tuple[float, float, float, float] | None = None  # lo, width, guard at lo, guard at hi
    best_score = -math.inf
    for f, la in zip(firsts, lasts, strict=True):  # a few clusters: a Python loop over runs, not sectors
        lo = float(ang[order[f]]) - 0.5 * step  # the cluster covers [lo, lo + width] counter-clockwise
        width = float(la - f + 1) * step
        r_lo, r_hi = float(ranges[order[f - 1]]), float(ranges[order[(la + 1) % n]])  # edge obstacles
        gap = math.sqrt(max(r_lo * r_lo + r_hi * r_hi - 2.0 * r_lo * r_hi * dm.cos(width), 0.0))
        if width < math.pi and gap < 2.0 * half_w:
            continue
        off = float(np.mod(pref - lo, _TWO_PI))
        miss = 0.0 if off <= width else min(off - width, _TWO_PI - off)
        score = float(free[order[f:la + 1]].mean()) * width * (1.0 - params.target_weight * miss / math.pi)
        if score > best_score:
            best_score = score
            best = (lo, width, dm.atan2(half_w, r_lo), dm.atan2(half_w, r_hi))
    if best is None:  # nowhere to fit through: the deepest sector (the speed law keeps it safe)
        return _limit(float(ang[int(np.argmax(free))]), polar, robot, params, 0)
    lo, width, g_lo, g_hi = best
    off = float(np.mod(pref - lo, _TWO_PI))
    if off > width:  # outside: measure from the nearer end
        off = width if off - width < _TWO_PI - off else 0.0
    a, b = g_lo, width - g_hi
    theta = wrap(lo + (min(max(off, a), b) if a <= b else 0.5 * width))
    return _limit(_unblock(theta, polar, robot, params), polar, robot, params, 0)


def _unblock(theta: float, polar: PolarMap, robot: RobotConfig, params: LocalParams) -> float:
    """``theta``, or when the footprint grown by ``safety_m`` (turned to face it, for a differential robot)
    cannot travel ``free_margin_m`` along it (a long vehicle whose corner is at a wall: the speed law would
    stop it), the nearest sector bisector within 90 deg of it along which it can; ``theta`` if none."""
    turn_first = robot.drive != "holonomic"
    need, grow = params.free_margin_m, params.safety_m
    if float(travel_m(polar, theta, robot, margin_m=grow, turn_first=turn_first, reach_m=need)[0]) >= need:
        return theta
    dev = np.abs(np.mod(polar.angles_rad - theta + math.pi, _TWO_PI) - math.pi)
    ok = (dev <= _HALF_PI) & (travel_m(polar, polar.angles_rad, robot, margin_m=grow, turn_first=turn_first,
                                       reach_m=need) >= need)
    if not ok.any():
        return theta
    idx = np.flatnonzero(ok)
    return float(polar.angles_rad[idx[np.argmin(dev[idx])]])


PolarLaw = Callable[[PolarMap, tuple[float, float] | None, RobotConfig, LocalParams, int], LocalCommand]
"""A strategy on the polar map: (map, target as (distance, bearing) or None, robot, settings, side hint)."""

POLAR_LAWS: dict[str, PolarLaw] = {
    "free-space": _free_space,
    "wall-left": _wall_left,
    "wall-right": _wall_right,
    "contour": _contour,
}
"""The strategies on the polar map, by name (each also a :data:`STRATEGIES` entry)."""


def local_command(polar: PolarMap, target_xy: NDArray[np.float64] | None, robot: RobotConfig,
                  params: LocalParams, *, side_hint: int = 0) -> LocalCommand:
    """The motion the configured polar map strategy (:data:`POLAR_LAWS`, not "nd") chooses on ``polar``,
    biased towards ``target_xy`` (robot frame) when one is given.

    "free-space" (:func:`_free_space`) and "contour" (:func:`_contour`) use the target; "wall-left" and
    "wall-right" (:func:`_wall`) ignore it. ``side_hint``: the previous command's ``side`` (contour keeps
    going round the same way when both ways are equally short). Every command passes the speed law
    (:func:`_limit`): it never translates towards an obstacle whose travel is below ``safety_m``.

    Raises
    ------
    ValueError
        For a strategy not on the polar map ("nd": ``nd.nd_step``, through :data:`STRATEGIES`), or a
        target that is not two finite numbers.
    """
    target = _target(target_xy)
    s = params.strategy
    law = POLAR_LAWS.get(s)
    if law is None:
        raise ValueError(f"local_command runs the polar map strategies, not {s!r} (ND+: nd.nd_step, through "
                         "STRATEGIES)")
    return law(polar, target, robot, params, side_hint)


NdCall = Callable[[F64, F64], NdResult]
"""ND+ on obstacle points towards a target (both robot frame), with its caller's commitment."""


class LocalStrategy(Protocol):
    """A local navigation strategy (:data:`STRATEGIES`): the command towards ``target_xy`` among the
    obstacle points ``obstacles_xy`` (both robot frame), told the side the previous command kept
    (``side_hint``) and given the caller's ND+ (``nd``)."""

    def __call__(self, obstacles_xy: F64, target_xy: F64, robot: RobotConfig, params: LocalParams, *,
                 side_hint: int, nd: NdCall) -> LocalCommand: ...


def _nd_plus(obstacles_xy: F64, target_xy: F64, robot: RobotConfig, params: LocalParams, *,
             side_hint: int, nd: NdCall) -> LocalCommand:
    """ND+ steering to the target itself (GND's mND); ROTATE towards it without a free walking area
    (REACTOR_NO_REGION), the caller setting the turn rate. No side is kept."""
    r = nd(obstacles_xy, target_xy)
    if r.flag & Flag.REACTOR_NO_REGION:
        return LocalCommand(0.0, 0.0, 0.0, r.direction_rad, 0, Mode.ROTATE, r.situation, r.flag)
    return LocalCommand(r.v_mps, r.vy_mps, r.w_radps, r.direction_rad, 0, Mode.MND, r.situation, r.flag)


def _on_polar_map(obstacles_xy: F64, target_xy: F64, robot: RobotConfig, params: LocalParams, *,
                  side_hint: int, nd: NdCall) -> LocalCommand:
    """A :data:`POLAR_LAWS` strategy: :func:`local_command` on the polar map of the obstacle points."""
    polar = polar_map(obstacles_xy, robot, params)
    return local_command(polar, target_xy, robot, params, side_hint=side_hint)


STRATEGIES: dict[str, LocalStrategy] = {"nd": _nd_plus, **dict.fromkeys(POLAR_LAWS, _on_polar_map)}
"""Local navigation strategies by name (``[navigation.local] strategy``, ``--local``)."""

LOCAL_STRATEGIES: tuple[str, ...] = tuple(STRATEGIES)
"""The strategies' names, "nd" first."""


def warm_up_local(robot: RobotConfig | None = None) -> None:
    """Run every polar map strategy once on a small map: compiles ``nd``'s sector kernel and the travel
    kernel (``_travel_kernel``) before the first tick."""
    rb = robot if robot is not None else RobotConfig()
    pts = np.array([[2.0, 0.0], [0.0, 1.5], [-1.0, -1.0]])
    for s in POLAR_LAWS:
        p = LocalParams(strategy=s)
        local_command(polar_map(pts, rb, p), np.array([3.0, 0.0]), rb, p)
