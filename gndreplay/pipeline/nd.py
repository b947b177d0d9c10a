"""ND+ reactor (Nearness Diagram navigation, ND+ form) for a circular or rectangular robot.

One call, :func:`nd_step`, turns obstacle points around the robot (taken from the occupancy grid, which is
the reactor's memory, not only the last scan) and a goal into a motion direction, a situation and a velocity
command. The steps and laws follow ALGORITHMS.md section 5, checked against the authors' released ND+ code
(J. Minguez, J. Osuna, "nd.c", as shipped in the Player ``nd`` driver); the differences are listed below.

Frames and sectors
    Robot frame: x forward, y left, angles counter-clockwise, 0 ahead, wrapped to (-pi, pi]; the origin is
    the rotation centre (the driving axle of a differential robot). With ``n`` sectors of width
    ``delta = 2 pi / n``, sector ``i`` covers the angles ``[(i - 1/2) delta, (i + 1/2) delta)`` (mod 2 pi)
    and its bisector is ``i * delta`` wrapped: sector 0 is straight ahead, ``n/4`` is +pi/2 (left), ``n/2``
    is pi (behind, its interval straddles the -pi/pi wrap) and ``3n/4`` is -pi/2 (right). Indices increase
    counter-clockwise. A point exactly on a boundary goes to the counter-clockwise sector. A region
    ``(first, last)`` runs counter-clockwise from ``first`` (its right end) to ``last`` (its left end); it
    wraps through sector 0 (a region straight ahead) when ``first > last``.

Per sector i: ``d_i`` the distance to the closest obstacle point (inf: no point closer than
``max_range_m``), ``E_i`` the distance from the origin to the robot boundary along the bisector,
``S_i`` the distance to the security perimeter (``ds_i = S_i - E_i``: security distance beyond the
boundary). An obstacle is dangerous when ``d_i <= S_i``; its clearance ratio is ``(d_i - E_i) / ds_i``.

Steps (ALGORITHMS.md section 5, ND+ code)
    1. Sectors: the closest point of each sector (distance and its own angle), moved out to at least
       ``E_i + contact_m``. Gaps: sectors i, i+1 with exactly one free, or distances differing by >= W
       (robot width, or diameter for a circle). A gap's rising side is its farther (or free) side.
    2. Free walking area: if the goal is in view (its sector free, or the goal nearer than the obstacle
       there) and navigable, the goal's region; else the gaps in order of angular distance from the goal
       sector (the nearer of left / right first, left on ties), each tested for navigability toward its
       sub-goal (midpoint of its two points; far out along their bisector when one side is free); the
       first navigable one selects the region on its rising side. None: ``Flag.REACTOR_NO_REGION``.
       The navigability test uses the closest point of each sector, as the code does.
    3. Situation: dangerous obstacles are split left / right of the region direction (goal or sub-goal).
       None: HSGR (goal region), HSWR (region wider than smax), HSNR. One side: LSG (goal region) or LS1.
       Both: LS2.
    4. Direction: HSGR goal; HSNR region bisector; HSWR ``a_c -/+ atan2(W/2 + Ds, r_c)`` past the gap's
       near point (the corner), into the region; LS1/LSG ``r theta_p + (1 - r) theta_b`` with theta_p the
       HS direction and theta_b away from the closest dangerous obstacle, r its clearance ratio; LS2
       ``theta_p + (cl - cr)/(cl + cr) (theta_p + pi/2)`` if cl <= cr else ``... (pi/2 - theta_p)``.
    5. Speed ``v_ND = vmax * min(c_left, c_right)`` (1 for a side without dangerous obstacles), then the
       mapping to the base (:func:`drive`).

Differences from ALGORITHMS.md / the released code, and why
    * LS2 uses the documented law when the region direction theta_p is ahead (|theta_p| <= pi/2). For a
      region behind, the law (written with the robot's lateral directions +-pi/2 as bounds) would steer
      toward the closer obstacle, so it is applied in the frame turned by pi (the robot's back as front).
    * Left/right of the region direction is decided on the wrapped difference ``wrap(a - theta_p) >= 0``;
      the code compares raw angles, which misclassifies obstacles across the +-pi wrap.
    * The LS1/LSG blend is clamped to +-(pi - 0.01) when it leaves (-pi, pi], keeping the turning side;
      the code's negative clamp ``-(pi + 0.01)`` wraps to the wrong side.
    * The goal is tested for navigability whenever it is in view (the code skips the test when there are
      fewer than two discontinuities), and a region with one discontinuity uses its rising side (the code
      always takes the same side because of a pointer-for-value slip).
    * ``E_i`` of a rectangle is the exact rectangle about the rotation centre (the code replaces the front
      edge by the circle through the front corners). The security perimeter is the code's: ``Ds/4`` behind
      the rear edge, circles of ``Ds/4`` and ``Ds`` about the rear and front corners joined by their
      tangent, and in front the circle of radius ``|front corner| + Ds`` about the rotation centre (what
      the front corners sweep when the vehicle turns, plus Ds). So ``ds`` is ``Ds/4`` behind and
      ``Ds + |front corner| - front`` straight ahead. A circle has ``ds = Ds`` all round (code).
    * Commitment: given the previous tick's choice (``NdMemory``, held by the caller), the
      region through the discontinuity whose sub-goal is within ``commit_rad / 2`` of last tick's is kept
      while navigable and at most ``commit_rad`` farther from the goal than the search's pick. Choosing
      afresh, a robot facing the middle of a wide obstacle with its goal behind it swapped the two ways
      round each tick as it turned and dithered in place.
    * Not ported (the supervisor owns them): the code's front emergency stop, and the rectangular robot's
      rear "cutting" correction, which needs the previous velocities.

Rectangular differential chair (a simple stand-in for the shape / kinematics abstraction
of the wheelchair paper's reference [18]; the circle and the holonomic base are unchanged)
    * Passages: while the region direction is ahead, when a left / right pair of obstacle points narrower
      than W + 2 Ds lies on the way (the region direction crosses it) or around the body, the direction
      pursues the passage axis (``_passage_axis``, ``_follow_axis``): the axle reaches the axis, and the
      body lies along it, before the front reaches the jambs; ND+'s laws steer the axle only, which
      enters a door crooked. A region behind keeps ND+'s direction: the chair backs out (below). So does
      a goal in view nearer than the front edge (the target within the chair's own length): pursuing the
      axis there drives the axle along the passage past a goal beside it, then (the goal now behind)
      back, for minutes (gnd_exp2_people_room: the goal 0.32 m abeam, between a wall and a person waiting
      for the chair); ND+'s law turns the axle to it. Along the axis the speed is at least
      ``_PASSAGE_V_FRAC * vmax``: ND+'s law scales it with the side clearance over Ds, which in a door
      barely wider than the chair is a crawl the scorecard counts as a stall (wheelchair_office_exit:
      0.02 m/s for 10 s in its 0.85 m door); the footprint sweeps below keep it off the jambs.
    * Staged approach (``_stage_direction``): from the side (a corridor along the wall with the door) the
      axis pursuit converges too late: the axle reached the axis with the front already at the jambs,
      angled, and every correction swung a corner into a jamb (a door 0.15 m wider than the chair,
      approached along its wall: traps until the time ran out). Off the axis, the chair first heads for
      the staging point on the axis where a turn in place sweeps free of the wall, then turns in place to
      the pursuit direction (within ``_ALIGN_RAD``, the turn rate falling with the error) and drives in.
      Not between walls already (a corridor): there it only pursues the axis.
    * Motion law: the command is the first admissible arc of ``_admissible_drive`` (the law's arc, wider
      arcs with the same final heading, the turn in place, straight on, a small correction in place,
      reversing while turning, straight back), admissible when the real footprint swept along it does not
      approach an obstacle point: a turn whose corners would sweep a wall is not commanded. Reversing
      (v < 0) happens only there; the reflexive check then also requires the swept cells behind to be
      known FREE.
    * A chair reaching a narrow door a few centimetres off its axis (or a few degrees crooked) with its
      front at the jambs needs a correction of a few degrees that no forward arc can make: the law's
      gentle arc sweeps a front corner into the jamb. The turn in place is skipped for corrections below
      ``_SWEEP_MIN_TURN_RAD`` (it would dither in open space), so the chair crept on the unchecked law,
      backed straight off once nothing forward could go ``_STEP_M``, and came back, tick after tick
      (wheelchair_office_exit's 0.85 m door: 6-10 s stalls there in all 20 seeds). When nothing forward is
      admissible, the small correction in place comes before reversing, if the turn sweeps free and
      straight on is free once turned; a turn that does not open the way is not made (it would only be
      undone next tick). It and the turn while reversing slow with the error (``_ALIGN_GAIN``): at half of
      wmax a 2 deg correction overshot to the other side each tick, and the chair rocked between creeping
      forward and reversing at the jambs.
    * ``min_clearance_m`` is the exact distance to the footprint.
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .. import detmath as dm
from ..errors import ConfigError
from ..geometry import transform_points
from ..robot import RobotConfig
from ..types import Flag
from .supervisor import arc_touches, footprint_distance_at, kernel_points

__all__ = [
    "NdDiagram",
    "NdMemory",
    "NdParams",
    "NdResult",
    "Situation",
    "drive",
    "nd_diagram",
    "nd_step",
    "robot_boundary_m",
    "sector_angles",
    "sector_of",
    "sectorise",
    "security_boundary_m",
    "wrap",
]

F64 = NDArray[np.float64]

_FAR_M = 1e6  # distance of the sub-goal through a discontinuity whose far side is free (the code's)
_HALF_PI = 0.5 * math.pi
_LS_CLAMP = math.pi - 0.01
_SECTOR_OFFSET = 0.5 + 1e-9  # round to the nearest bisector; a boundary goes counter-clockwise
# the rectangle's admissible arcs (choices): clearance kept from the obstacle points (grid cell centres:
# half a 5 cm cell; more would close a 0.85 m door to the 0.7 m chair, the reflexive check keeps the
# safety margin), travel checked along an arc, and the reversing speed (the supervisor's escape speed)
_SWEEP_MARGIN_M = 0.025
_SWEEP_MIN_M = 0.3
_SWEEP_MAX_M = 1.5
_SWEEP_MIN_TURN_RAD = 0.3
_SWEEP_STRAIGHT_M = 1.0
_STEP_M = 0.05
_REVERSE_FRAC = 0.3
# least speed along a passage axis, a fraction of vmax: ND+'s v = vmax * min(c_left, c_right) falls to the
# side clearance / Ds, 0.02 m/s in a 0.85 m door for the 0.7 m chair (0.2 m in 10 s: a stall); the sweep
# of the footprint along the arc (``_admissible_drive``) and the reflexive check keep the chair off the jambs
_PASSAGE_V_FRAC = 0.25
# the staged approach to a narrow passage (``_stage_direction``): the staging point lies the front corners'
# swing radius plus _STAGE_CLEAR_M before the passage (a turn in place there sweeps free of its wall); the
# chair heads for it while more than _STAGE_OFF_M off the axis, and aligns in place within _ALIGN_RAD
_STAGE_CLEAR_M = 0.1
_STAGE_NEAR_M = 0.1
_STAGE_OFF_M = 0.1
_ALIGN_RAD = 0.02
_ALIGN_GAIN = 2.0


class Situation(enum.Enum):
    """ND+ navigational situations (decision tree of ALGORITHMS.md section 5); NONE when no region."""

    LS1 = "LS1"  # low safety, dangerous obstacles on one side, goal not in the region
    LSG = "LSG"  # low safety, dangerous obstacles on one side, goal in the region
    LS2 = "LS2"  # low safety, dangerous obstacles on both sides
    HSGR = "HSGR"  # high safety, goal in the region
    HSWR = "HSWR"  # high safety, wide region (> smax)
    HSNR = "HSNR"  # high safety, narrow region
    NONE = "NONE"  # no navigable region (Flag.REACTOR_NO_REGION)


@dataclass(frozen=True, slots=True)
class NdParams:
    """ND+ settings.

    Attributes:
        n_sectors: number of sectors (180 = 2 deg each, the ND+ code); a multiple of 4, so that 0, +-pi/2
            and pi are sector bisectors.
        security_m: security distance Ds [m] (the ND+ code's ``dsmax``, 0.5 m default).
        security_time_s: Ds grows with the robot's top speed: the stack's reactor uses
            ``security_m + security_time_s * vmax_mps`` (``scaled_security_m``) [s]. 0 (the default) keeps
            the code's fixed Ds, tuned for bases of at most about 0.5 m/s.
        security_rear_ratio: rectangle only: security distance behind the rear edge as a fraction of Ds
            (the code's ``dsmin = dsmax / 4``).
        max_range_m: obstacle points farther than this [m] are ignored; a sector with none is free.
            **Choice**: 5 m, the half-size of GND's 10 x 10 m grid.
        smax_rad: regions wider than this [rad] are "wide" (HSWR; LS1 passes the corner), else narrow.
        gap_m: width [m] a discontinuity must open and the navigability tunnel must keep free; ``None``
            uses the robot's width (rectangle) or diameter (circle), as the code does.
        contact_m: a point inside the robot boundary is moved out to ``E_i + contact_m`` [m] (code: 1 cm).
        commit_rad: commitment (**choice**): with the previous tick's choice given
            (``NdMemory``), the region through the discontinuity whose sub-goal lies within
            ``commit_rad / 2`` of the previous sub-goal is kept while navigable, unless the region the
            search would pick is nearer the goal by more than ``commit_rad`` (angular distance from the goal
            sector to the discontinuity). 0 disables it.
    """

    n_sectors: int = 180
    security_m: float = 0.5
    security_rear_ratio: float = 0.25
    max_range_m: float = 5.0
    smax_rad: float = _HALF_PI
    gap_m: float | None = None
    contact_m: float = 0.01
    commit_rad: float = 0.25 * math.pi
    security_time_s: float = 0.0

    def __post_init__(self) -> None:
        if self.n_sectors < 8 or self.n_sectors % 4:
            raise ConfigError(f"reactor.n_sectors must be a multiple of 4 and >= 8, got {self.n_sectors}")
        if not self.security_m > 0.0:
            raise ConfigError(f"reactor.security_m must be > 0, got {self.security_m}")
        if not 0.0 < self.security_rear_ratio <= 1.0:
            raise ConfigError(
                f"reactor.security_rear_ratio must be in (0, 1], got {self.security_rear_ratio}"
            )
        if not self.max_range_m > 0.0:
            raise ConfigError(f"reactor.max_range_m must be > 0, got {self.max_range_m}")
        if not 0.0 < self.smax_rad < 2.0 * math.pi:
            raise ConfigError(f"reactor.smax_rad must be in (0, 2 pi), got {self.smax_rad}")
        if self.gap_m is not None and not self.gap_m > 0.0:
            raise ConfigError(f"reactor.gap_m must be > 0 or None, got {self.gap_m}")
        if not self.contact_m > 0.0:
            raise ConfigError(f"reactor.contact_m must be > 0, got {self.contact_m}")
        if not 0.0 <= self.commit_rad <= math.pi:
            raise ConfigError(f"reactor.commit_rad must be in [0, pi], got {self.commit_rad}")
        if not self.security_time_s >= 0.0:
            raise ConfigError(f"reactor.security_time_s must be >= 0, got {self.security_time_s}")


@dataclass(frozen=True, slots=True)
class NdMemory:
    """The choice ND+ made last tick, passed back in for commitment (``NdParams.commit_rad``); nd_step stays
    a pure function, the caller holds it.

    Attributes:
        subgoal_rad: direction [rad] of the sub-goal of the region chosen through a discontinuity, in the
            robot frame of the tick it is passed to (the caller turns it by the robot's rotation since).
    """

    subgoal_rad: float


@dataclass(frozen=True, slots=True)
class NdResult:
    """What ND+ decided for one step.

    Attributes:
        situation: the situation (``Situation.NONE`` when no region).
        flag: ``Flag.NONE``, or ``Flag.REACTOR_NO_REGION`` when no navigable region exists.
        direction_rad: motion direction in the robot frame, (-pi, pi]; nan when no region.
        v_mps: forward velocity [m/s]; >= 0 for a differential drive, except the rectangle backing out
            of a turn it cannot make (``_admissible_drive``).
        vy_mps: lateral velocity [m/s] (holonomic base only, else 0).
        w_radps: turn rate [rad/s], counter-clockwise positive.
        region: (first, last) sectors of the selected region, counter-clockwise; None when no region.
        min_clearance_m: smallest exact distance from an obstacle point (within max_range_m) to the real
            footprint [m] (negative: inside it); inf without obstacles.
        memory: the choice to pass to the next tick (a region through a discontinuity); None for the goal's
            own region or no region.
    """

    situation: Situation
    flag: Flag
    direction_rad: float
    v_mps: float
    vy_mps: float
    w_radps: float
    region: tuple[int, int] | None
    min_clearance_m: float
    memory: NdMemory | None = None


# --------------------------------------------------------------------------------------------------
# Sectors and robot shape


def sector_angles(n_sectors: int) -> F64:
    """(n,) sector bisectors [rad], sector i at ``i * 2 pi / n`` wrapped to (-pi, pi] (0 ahead, n/2 = pi)."""
    i = np.arange(n_sectors, dtype=np.float64)
    frac = 2.0 * i / n_sectors  # exact for the multiples of n/4
    return np.pi * np.where(frac > 1.0, frac - 2.0, frac)


def sector_of(angles_rad: ArrayLike, n_sectors: int) -> NDArray[np.intp]:
    """Sector index of each angle [rad]; a boundary angle (within 1e-9 sector) goes counter-clockwise."""
    a = np.asarray(angles_rad, dtype=np.float64)
    k = np.floor(a * (n_sectors / (2.0 * np.pi)) + _SECTOR_OFFSET).astype(np.intp)
    return np.mod(k, n_sectors)


def _check_robot(robot: RobotConfig) -> None:
    if robot.shape == "circle":
        if not robot.radius_m > 0.0:
            raise ConfigError(f"robot.radius_m must be > 0, got {robot.radius_m}")
    elif robot.shape == "rectangle":
        if not (robot.width_m > 0.0 and robot.front_m > 0.0 and robot.rear_m > 0.0):
            raise ConfigError(
                "robot.width_m, front_m and rear_m must be > 0 for a rectangle, got "
                f"{robot.width_m}, {robot.front_m}, {robot.rear_m}"
            )
    else:
        raise ConfigError(f"robot.shape must be 'circle' or 'rectangle', got {robot.shape!r}")


def robot_boundary_m(robot: RobotConfig, sector_angles_rad: ArrayLike) -> F64:
    """E: distance [m] from the rotation centre to the robot boundary along each angle.

    Circle: ``radius_m``. Rectangle: the exact ray / rectangle intersection with the rectangle spanning
    ``[-rear_m, front_m] x [-width_m/2, width_m/2]`` about the rotation centre.
    """
    _check_robot(robot)
    a = np.asarray(sector_angles_rad, dtype=np.float64)
    if robot.shape == "circle":
        return np.full(a.shape, float(robot.radius_m))
    c, s = dm.cos_a(a), np.abs(dm.sin_a(a))
    big = np.inf
    along = np.where(c > 0.0, robot.front_m, robot.rear_m)
    ex = np.divide(along, np.abs(c), out=np.full(a.shape, big), where=np.abs(c) > 1e-12)
    ey = np.divide(0.5 * robot.width_m, s, out=np.full(a.shape, big), where=s > 1e-12)
    e: F64 = np.minimum(ex, ey)
    return e


def security_boundary_m(robot: RobotConfig, sector_angles_rad: ArrayLike, *, security_m: float,
                        rear_ratio: float = 0.25) -> F64:
    """S: distance [m] from the rotation centre to the security perimeter along each angle.

    Circle: ``radius_m + security_m``. Rectangle (ND+ code, ``InicializarDS``): with ``Ds = security_m``
    and ``ds = rear_ratio * Ds``, per |angle| from behind to ahead: the line ``ds`` behind the rear edge,
    the circle of radius ``ds`` about the rear corner, the tangent to the circle of radius ``Ds`` about the
    front corner, that circle, and the arc of radius ``|front corner| + Ds`` about the rotation centre.

    Raises:
        ConfigError: when ``Ds - ds`` is not smaller than the robot's length (no tangent exists).
    """
    _check_robot(robot)
    a = np.abs(np.asarray(sector_angles_rad, dtype=np.float64))
    if robot.shape == "circle":
        return np.full(a.shape, float(robot.radius_m) + security_m)
    ds_max, ds_min = float(security_m), float(security_m) * rear_ratio
    hw, front, rear = 0.5 * robot.width_m, robot.front_m, robot.rear_m
    length = front + rear
    b = ds_max - ds_min
    if b >= length:
        raise ConfigError(f"security distances {ds_max} / {ds_min} m differ by more than the robot length")
    cos_t, sin_t = math.sqrt(length * length - b * b) / length, b / length
    p1x, p1y = -rear, hw  # rear-left corner
    p2x, p2y = front, hw  # front-left corner
    q1x, q1y = p1x - ds_min, p1y
    q2x, q2y = p1x - ds_min * sin_t, p1y + ds_min * cos_t
    q3x, q3y = p2x - ds_max * sin_t, p2y + ds_max * cos_t
    r_front = math.hypot(p2x, p2y) + ds_max
    lim1, lim2 = dm.atan2(q1y, q1x), dm.atan2(q2y, q2x)
    lim3, lim4 = dm.atan2(q3y, q3x), dm.atan2(p2y, p2x)
    c, s = dm.cos_a(a), dm.sin_a(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = q1x / c  # the line behind
        t = p1x * c + p1y * s
        r2 = t + np.sqrt(np.maximum(t * t - (p1x * p1x + p1y * p1y - ds_min * ds_min), 0.0))
        bx, by = q3x - q2x, q3y - q2y
        r3 = (bx * q2y - by * q2x) / (bx * s - by * c)  # the tangent line through q2, q3
        t = p2x * c + p2y * s
        r4 = t + np.sqrt(np.maximum(t * t - (p2x * p2x + p2y * p2y - ds_max * ds_max), 0.0))
    return np.select([a >= lim1, a >= lim2, a >= lim3, a >= lim4], [r1, r2, r3, r4], default=r_front)


@dataclass(frozen=True, slots=True)
class _Geometry:
    angles: F64  # sector bisectors
    boundary: F64  # E
    security: F64  # S
    gap_m: float  # W


@functools.lru_cache(maxsize=32)
def _geometry(robot: RobotConfig, params: NdParams) -> _Geometry:
    """Per-sector constants for a robot and settings (cached: both are frozen; arrays read-only)."""
    ang = sector_angles(params.n_sectors)
    e = robot_boundary_m(robot, ang)
    s = security_boundary_m(robot, ang, security_m=params.security_m, rear_ratio=params.security_rear_ratio)
    if params.gap_m is not None:
        gap = params.gap_m
    else:
        gap = 2.0 * robot.radius_m if robot.shape == "circle" else robot.width_m
    for arr in (ang, e, s):
        arr.setflags(write=False)
    return _Geometry(ang, e, s, float(gap))


# --------------------------------------------------------------------------------------------------
# Steps


def wrap(a: float) -> float:
    """Wrap a scalar angle to (-pi, pi]."""
    w = (a + math.pi) % (2.0 * math.pi) - math.pi
    return math.pi if w <= -math.pi else w


@njit(cache=True)
def _sectorise_kernel(points: F64, scale: float, max_range_m: float, dist: F64, ang: F64) -> None:
    """Fill ``dist`` (inf on entry) and ``ang`` (bisectors on entry) with the closest point per sector.

    Same sector rule as :func:`sector_of`; non-finite points and points beyond ``max_range_m`` are skipped.
    """
    n = dist.size
    max2 = max_range_m * max_range_m
    for k in range(points.shape[0]):
        x, y = points[k, 0], points[k, 1]
        r2 = x * x + y * y
        if not r2 <= max2:  # also skips nan / inf
            continue
        a = dm.atan2(y, x)
        i = math.floor(a * scale + _SECTOR_OFFSET) % n
        if r2 < dist[i]:
            dist[i] = r2
            ang[i] = a
    for i in range(n):
        if dist[i] < np.inf:
            dist[i] = math.sqrt(dist[i])


@njit(cache=True)
def _nd_sectors(points: F64, scale: float, max_range_m: float, boundary: F64, contact_m: float, gap_m: float,
                circle: bool, radius: float, front: float, rear: float, half_w: float, dist: F64, ang: F64,
                gaps: NDArray[np.bool_], px: F64, py: F64) -> tuple[float, int]:
    """ND+'s sectors in one pass: ``_sectorise_kernel`` into ``dist`` / ``ang`` (inf / bisectors on entry);
    each occupied sector's distance moved out to at least ``boundary + contact_m``; ``gaps[i]`` True where
    sectors i and i+1 (mod n) are separated by a gap (exactly one side free, or both occupied with
    distances differing by at least ``gap_m``: the robot fits through the jump); the occupied sectors'
    points (x, y) in sector order into ``px`` / ``py``. Returns the smallest exact distance from a point
    within ``max_range_m`` to the footprint (``NdResult.min_clearance_m``, not along the sector bisectors:
    at a rectangle's corner the two differ by centimetres; inf without one) and the number of occupied
    sectors."""
    _sectorise_kernel(points, scale, max_range_m, dist, ang)
    max2 = max_range_m * max_range_m
    clearance = np.inf
    for k in range(points.shape[0]):
        x, y = points[k, 0], points[k, 1]
        if x * x + y * y <= max2:
            d = footprint_distance_at(x, y, circle, radius, front, rear, half_w)
            if d < clearance:
                clearance = d
    n = dist.size
    m = 0
    for i in range(n):
        if dist[i] < np.inf:
            lo = boundary[i] + contact_m
            if not dist[i] >= lo:
                dist[i] = lo
            px[m] = dist[i] * dm.cos(ang[i])
            py[m] = dist[i] * dm.sin(ang[i])
            m += 1
    for i in range(n):
        a, b = dist[i], dist[(i + 1) % n]
        free_a, free_b = a == np.inf, b == np.inf
        gaps[i] = free_a != free_b or (not free_a and not free_b and abs(a - b) >= gap_m)
    return clearance, m


def _sectors(pts: F64, geo: _Geometry, robot: RobotConfig,
             params: NdParams) -> tuple[F64, F64, NDArray[np.bool_], F64, F64, float]:
    """(dist, ang, gaps, px, py, min_clearance) of ``_nd_sectors`` for ``nd_step`` and ``nd_diagram``."""
    n = geo.angles.size
    dist = np.full(n, np.inf)
    ang = geo.angles.copy()
    gaps = np.empty(n, dtype=np.bool_)
    px, py = np.empty(n), np.empty(n)
    clearance, m = _nd_sectors(kernel_points(pts), n / (2.0 * np.pi), params.max_range_m, geo.boundary,
                               params.contact_m, geo.gap_m, robot.shape == "circle", robot.radius_m,
                               robot.front_m, robot.rear_m, robot.width_m / 2.0, dist, ang, gaps, px, py)
    return dist, ang, gaps, px[:m], py[:m], clearance


def sectorise(points: F64, bisectors: F64, max_range_m: float) -> tuple[F64, F64]:
    """Per sector the distance and angle of the closest point (inf / bisector when none within range)."""
    n = bisectors.size
    dist = np.full(n, np.inf)
    ang = bisectors.copy()
    if points.shape[0]:
        _sectorise_kernel(np.ascontiguousarray(points), n / (2.0 * np.pi), max_range_m, dist, ang)
    return dist, ang


@njit(cache=True)
def _navigable(px: F64, py: F64, goal_r: float, goal_a: float, gap_m: float) -> bool:
    """Navigability test: can a robot of width ``gap_m`` reach the sub-goal at (goal_r, goal_a)?

    In the frame turned so the sub-goal lies on +x at ``goal_r``, only points with 0 <= x < goal_r and
    |y| <= gap_m count; unreachable if one is within gap_m/2 of the sub-goal, or if a point on the left
    (y > 0) and one on the right (y <= 0) are closer than gap_m to each other.
    """
    c, s = dm.cos(goal_a), dm.sin(goal_a)
    m = px.size
    xs = np.empty(m)
    ys = np.empty(m)
    cnt = 0
    half2 = 0.25 * gap_m * gap_m
    for k in range(m):
        x = c * px[k] + s * py[k]
        y = c * py[k] - s * px[k]
        if x < 0.0 or x >= goal_r or abs(y) > gap_m:
            continue
        if (x - goal_r) * (x - goal_r) + y * y < half2:
            return False
        xs[cnt] = x
        ys[cnt] = y
        cnt += 1
    gap2 = gap_m * gap_m
    for i in range(cnt):
        if ys[i] > 0.0:
            for j in range(cnt):
                if ys[j] <= 0.0:
                    dx, dy = xs[i] - xs[j], ys[i] - ys[j]
                    if dx * dx + dy * dy < gap2:
                        return False
    return True


class _Kind(enum.Enum):
    GOAL = 0  # the goal itself is the sub-goal
    FIRST_EDGE = 1  # through the discontinuity at the region's clockwise end (corner: first - 1)
    LAST_EDGE = 2  # through the discontinuity at the region's counter-clockwise end (corner: last + 1)


@dataclass(frozen=True, slots=True)
class _Region:
    first: int
    last: int
    kind: _Kind
    direction_rad: float  # direction of the sub-goal
    corner: int  # sector of the discontinuity's near point (-1 for GOAL)


def _select_region(dist: F64, ang: F64, bisectors: F64, gaps: NDArray[np.bool_], px: F64, py: F64,
                   goal_r: float, goal_a: float, gap_m: float, prev_rad: float | None = None,
                   commit_rad: float = 0.0) -> _Region | None:
    """Free walking area: the goal's region if the goal is in view and navigable, else the first
    navigable discontinuity found searching outward from the goal sector, alternating left and right
    (the closer first, left on ties); the region is the one on the discontinuity's rising (far) side.

    Commitment: with ``prev_rad`` (last tick's sub-goal direction), a navigable discontinuity whose
    sub-goal lies within ``commit_rad / 2`` of it and which is at most ``commit_rad`` farther from the goal
    than the first navigable one is taken instead: the region does not change side each time the goal's
    bearing crosses the middle between two gaps (a goal held by a driver who counter-steers, a robot
    turning in place between two ways round an obstacle). ``gaps``: the discontinuities (boundary k lies
    between sectors k and k+1); ``px``, ``py``: the occupied sectors' points (``_nd_sectors``)."""
    n = dist.size
    g = math.floor(goal_a * (n / (2.0 * np.pi)) + _SECTOR_OFFSET) % n  # ``sector_of``
    in_view = dist[g] == np.inf or goal_r <= dist[g]
    bounds = np.flatnonzero(gaps)
    if bounds.size == 0:
        if in_view and _navigable(px, py, goal_r, goal_a, gap_m):
            return _Region(0, n - 1, _Kind.GOAL, goal_a, -1)
        return None
    dl = (bounds - g) % n  # sectors from the goal counter-clockwise to the boundary's near side
    dr = (g - bounds - 1) % n  # ... and clockwise
    if in_view:
        b_last, b_first = int(bounds[np.argmin(dl)]), int(bounds[np.argmin(dr)])
        first, last = (b_first + 1) % n, b_last
        rising = dist[first] > dist[(first - 1) % n] or dist[last] > dist[(last + 1) % n]
        if not rising:  # the goal sits in front of a nearer obstacle: an "artificial" one-sector region
            first = last = g
        if _navigable(px, py, goal_r, goal_a, gap_m):
            return _Region(first, last, _Kind.GOAL, goal_a, -1)
    near_goal = np.minimum(dl, dr)
    order = np.lexsort((dl > dr, near_goal))
    nb = bounds.size
    best: _Region | None = None
    limit = 0
    for m in order:
        if best is not None and near_goal[m] > limit:
            break
        i = int(bounds[m])
        j = (i + 1) % n
        far, near = (j, i) if dist[j] > dist[i] else (i, j)
        if np.isinf(dist[far]):
            a_sub = ang[near] + 0.5 * wrap(float(bisectors[far] - ang[near]))
            r_sub = dist[near] + _FAR_M
        else:
            x = 0.5 * (dist[i] * dm.cos(ang[i]) + dist[j] * dm.cos(ang[j]))
            y = 0.5 * (dist[i] * dm.sin(ang[i]) + dist[j] * dm.sin(ang[j]))
            a_sub, r_sub = dm.atan2(y, x), math.hypot(x, y)
        a_sub = wrap(float(a_sub))
        kept = prev_rad is not None and abs(wrap(a_sub - prev_rad)) <= 0.5 * commit_rad
        if best is not None and not kept:
            continue
        if not _navigable(px, py, float(r_sub), a_sub, gap_m):
            continue
        if far == j:  # region counter-clockwise of the boundary: starts at j
            region = _Region(j, int(bounds[(m + 1) % nb]), _Kind.FIRST_EDGE, a_sub, i)
        else:
            region = _Region((int(bounds[(m - 1) % nb]) + 1) % n, i, _Kind.LAST_EDGE, a_sub, j)
        if kept or prev_rad is None or commit_rad <= 0.0:
            return region
        best = region  # the search's choice; look on for last tick's within commit_rad farther
        limit = int(near_goal[m]) + int(commit_rad / (2.0 * math.pi / n))
    return best


def _ls2_direction(theta_p: float, c_left: float, c_right: float) -> float:
    """LS2 law (ALGORITHMS.md): centre between the closest left and right dangerous obstacles.

    theta = theta_p + (cl - cr)/(cl + cr) * (theta_p + pi/2) if cl <= cr, else
    theta_p + (cl - cr)/(cl + cr) * (pi/2 - theta_p). Written for a region ahead; for |theta_p| > pi/2 it is
    applied in the frame turned by pi so that it still steers away from the closer side.
    """
    behind = abs(theta_p) > _HALF_PI
    tp = wrap(theta_p - math.pi) if behind else theta_p
    k = (c_left - c_right) / (c_left + c_right) if c_left + c_right > 0.0 else 0.0
    th = tp + k * (tp + _HALF_PI) if c_left <= c_right else tp + k * (_HALF_PI - tp)
    return wrap(th + math.pi) if behind else wrap(th)


def _blend_away(theta_p: float, obstacle_a: float, ratio: float) -> float:
    """LS1 / LSG law: r * theta_p + (1 - r) * theta_b, theta_b pointing away from the obstacle (unwrapped
    next to theta_p); clamped to +-(pi - 0.01) if it leaves (-pi, pi], keeping the turning side."""
    theta_b = wrap(obstacle_a + math.pi - theta_p) + theta_p
    th = ratio * theta_p + (1.0 - ratio) * theta_b
    if th > math.pi:
        th = _LS_CLAMP
    elif th < -math.pi:
        th = -_LS_CLAMP
    return wrap(th)


def _passage_axis(dist: F64, ang: F64, left_side: NDArray[np.bool_], beta: float, *, min_width_m: float,
                  max_width_m: float, reach_m: float, behind_m: float,
                  front_m: float) -> tuple[float, float, float, float] | None:
    """The narrowest passage the robot is going through: the closest pair of a left and a right occupied
    sector point (``left_side``: left of the region direction; both within ``reach_m`` of the rotation
    centre), at least ``min_width_m`` (the robot's width: a narrower slot beside it is not its way) and
    narrower than ``max_width_m``, whose segment the ray along the region direction ``beta`` crosses ahead of
    the rotation centre (or at most ``behind_m`` behind it), or the robot's own axis crosses between
    ``behind_m`` behind and ``front_m`` ahead of the rotation centre (the body is in the passage: it leaves
    along the axis before turning). A pair on the way must have the ray cross its segment, and behind the
    rotation centre only a pair around the body counts: where the way turns just beyond a door, the ray
    crosses a side wall behind the axle, and two points along that wall were taken for the passage on some
    ticks (the direction flipped between the door's axis ahead and the wall's normal, backing up:
    wheelchair_office_exit).

    Returns (cx, cy, nx, ny): the pair's midpoint and the passage axis, the unit normal of the pair's line
    oriented along ``beta``; None without such a pair. For a door these are the jambs; in a corridor any
    pair across it (the narrowest is the perpendicular one), whose axis runs along the corridor."""
    out = np.empty(4)
    if not _passage_kernel(dist, ang, left_side, beta, min_width_m, max_width_m, reach_m, behind_m, front_m,
                           out):
        return None
    return float(out[0]), float(out[1]), float(out[2]), float(out[3])


@njit(cache=True, error_model="numpy")
def _passage_kernel(dist: F64, ang: F64, left_side: NDArray[np.bool_], beta: float, min_width_m: float,
                    max_width_m: float, reach_m: float, behind_m: float, front_m: float, out: F64) -> bool:
    """``_passage_axis`` into ``out`` (cx, cy, nx, ny); False: no passage. Pairs in (left, right) sector
    order, the first of equal widths kept; IEEE division (a zero denominator's pair is no passage)."""
    n = dist.size
    lx, ly, rx, ry = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    nl = nr = 0
    for i in range(n):
        if dist[i] < np.inf and dist[i] <= reach_m:
            x, y = dist[i] * dm.cos(ang[i]), dist[i] * dm.sin(ang[i])
            if left_side[i]:
                lx[nl], ly[nl] = x, y
                nl += 1
            else:
                rx[nr], ry[nr] = x, y
                nr += 1
    if nl == 0 or nr == 0:
        return False
    bx, by = dm.cos(beta), dm.sin(beta)
    min2 = min_width_m * min_width_m
    best, ba, bb = np.inf, 0, 0
    for a in range(nl):
        for b in range(nr):
            ex, ey = lx[a] - rx[b], ly[a] - ry[b]
            w2 = ex * ex + ey * ey
            if not w2 >= min2 or not w2 < best:
                continue
            num = rx[b] * ey - ry[b] * ex
            den = bx * ey - by * ex  # the beta ray meets the line r + s (l - r) at t = num / den
            t = num / den
            seg = ((t * bx - rx[b]) * ex + (t * by - ry[b]) * ey) / w2  # where on the pair's segment
            straddles = ly[a] > 0.0 and ry[b] < 0.0  # one point each side of the body
            on_way = abs(den) > 1e-12 and seg >= 0.0 and seg <= 1.0 and (
                t >= 0.0 or (t > -behind_m and straddles))
            t_body = num / ey  # the same along the robot's own axis (b = +x)
            in_body = straddles and abs(ey) > 1e-12 and t_body > -behind_m and t_body < front_m
            if on_way or in_body:
                best, ba, bb = w2, a, b
    width = math.sqrt(best)
    if not width < max_width_m:  # also: no pair on the way (inf)
        return False
    ux, uy = (lx[ba] - rx[bb]) / width, (ly[ba] - ry[bb]) / width
    nx, ny = uy, -ux  # the left point's side turned clockwise: the axis through the pair
    if nx * bx + ny * by < 0.0:
        nx, ny = -nx, -ny
    out[0], out[1], out[2], out[3] = 0.5 * (lx[ba] + rx[bb]), 0.5 * (ly[ba] + ry[bb]), nx, ny
    return True


def _follow_axis(axis: tuple[float, float, float, float], lookahead_m: float) -> float:
    """Direction to the point ``lookahead_m`` along the passage axis past the rotation centre's projection
    on it (pure pursuit of the axis line).

    The rectangular chair's motion law in a passage: ND+'s LS2 law centres the rotation centre between the
    closest obstacles, which for a chair whose front is 0.8 m ahead of its axle means entering a door
    crooked and offset (the front is in, the axle still outside and off-centre), where every correction
    swings a corner into a jamb. Pursuing the axis line brings the axle onto it, and the body along it,
    before the front reaches the jambs (the lateral offset decays over about one lookahead of travel)."""
    cx, cy, nx, ny = axis
    along = -(cx * nx + cy * ny)  # the rotation centre's coordinate along the axis, from the midpoint
    tx, ty = cx + (along + lookahead_m) * nx, cy + (along + lookahead_m) * ny
    return wrap(dm.atan2(ty, tx))


def _stage_direction(axis: tuple[float, float, float, float], robot: RobotConfig, dist: F64, ang: F64,
                     half_width_m: float) -> tuple[float, bool]:
    """The rectangular chair's direction towards a narrow passage, and whether to align in place first.

    Pursuing the axis line alone (``_follow_axis``) converges over about one look-ahead of travel: from the
    side (a corridor along the wall with the door) the axle reaches the axis with the front already at the
    jambs, angled, and every correction swings a corner into a jamb. So the approach is staged: the staging
    point lies on the axis where a turn in place sweeps free of the passage's wall (the front corners'
    swing radius plus ``_STAGE_CLEAR_M`` before the pair's midpoint). Farther than the look-ahead before
    it, or on the axis, the axis is pursued as before; off the axis within that reach, the chair heads for
    the staging point itself; from there (or on the axis), before the front reaches the passage, it turns
    in place to the pursuit direction when that is more than ``_ALIGN_RAD`` off, then drives on it.
    A robot already between walls (an obstacle point beside its body within ``half_width_m`` of the axis:
    a corridor, whose pairs all have this axis) only pursues it: stopping to align there would dither."""
    cx, cy, nx, ny = axis
    along = -(cx * nx + cy * ny)  # the rotation centre along the axis, from the pair's midpoint
    lateral = cx * ny - cy * nx  # ... and across it
    seen = np.isfinite(dist)
    qx, qy = dist[seen] * dm.cos_a(ang[seen]) - cx, dist[seen] * dm.sin_a(ang[seen]) - cy
    qa, qb = qx * nx + qy * ny, qy * nx - qx * ny
    if np.any((qa >= along - robot.rear_m) & (qa <= along + robot.front_m) & (np.abs(qb) < half_width_m)):
        return _follow_axis(axis, robot.front_m), False
    hw = 0.5 * robot.width_m
    stage = math.sqrt(robot.front_m * robot.front_m + hw * hw) + _STAGE_CLEAR_M
    lookahead = robot.front_m
    depth = max(along, -stage)  # the staging point, or the axis abreast of a robot already nearer
    if -stage - lookahead <= along < -robot.front_m and abs(lateral) > _STAGE_OFF_M and math.hypot(
            depth - along, lateral) > _STAGE_NEAR_M:
        tx, ty = cx + depth * nx, cy + depth * ny
        return wrap(dm.atan2(ty, tx)), False
    theta = _follow_axis(axis, lookahead)
    return theta, -stage - lookahead <= along < -robot.front_m and abs(theta) > _ALIGN_RAD


def drive(theta: float, v_nd: float, robot: RobotConfig) -> tuple[float, float, float]:
    """(v, vy, w) for the base.

    Differential (the paper law): theta clamped to [-pi/2, pi/2], w = wmax * theta / (pi/2),
    v = v_ND * (1 - |theta| / (pi/2)); a direction at or beyond +-pi/2 gives a turn in place.
    Holonomic (**choice**): translate along theta at v_ND, (vx, vy) = v_ND (cos, sin) theta, and turn the
    front (the laser) toward the motion with the same law, w = wmax * clamp(theta, +-pi/2) / (pi/2).
    """
    tc = min(max(theta, -_HALF_PI), _HALF_PI)
    w = robot.wmax_radps * tc / _HALF_PI
    if robot.drive == "holonomic":
        return v_nd * dm.cos(theta), v_nd * dm.sin(theta), w
    return v_nd * (1.0 - abs(tc) / _HALF_PI), 0.0, w


def _admissible_drive(theta: float, v_nd: float, robot: RobotConfig, points: F64, *,
                      align_first: bool = False) -> tuple[float, float]:
    """(v, w) for the rectangular differential chair: the first admissible of a list of arcs.

    An arc is admissible when the real footprint, moved along it until the chair faces ``theta`` (the
    whole turn ND+ asks for, however gentle the arc; at least ``_SWEEP_MIN_M`` of travel, at most
    ``_SWEEP_MAX_M``), does not come within ``_SWEEP_MARGIN_M`` of an obstacle point it approaches
    (``arc_touches``). Candidates in order: the paper law for theta, for theta/2 and theta/4 (wider
    arcs, the same final heading), the turn in place towards theta (not for a correction smaller than
    ``_SWEEP_MIN_TURN_RAD``), straight on when theta is ahead
    (free for ``_SWEEP_STRAIGHT_M``: room to go on until the turn fits, as in a corridor before a side
    opening), the turn in place for a small correction only now, when nothing forward fits, and only if
    straight on is free once turned (``_blocked_after_turn``), then reversing (``_REVERSE_FRAC`` of vmax,
    ``_SWEEP_MIN_M``) while turning the front
    towards theta (a multi-point turn), then straight back; reversing only when theta is behind or
    nothing forward can go even ``_STEP_M`` (``_blocked_now``). This is the
    shape / kinematics abstraction in its simplest form: the turn a rectangle cannot make here (its
    corners would sweep a jamb or a wall) is not commanded; it drives on until it can, or backs out.
    Nothing admissible: the paper law, left to the reflexive check. ``align_first``: the turn in place
    towards theta comes first, whatever its size (the staged approach to a passage, ``_stage_direction``)."""
    law_v, _, law_w = drive(theta, v_nd, robot)
    if points.shape[0] == 0:
        return law_v, law_w
    turn = abs(min(max(theta, -math.pi), math.pi))
    sign = 1.0 if theta >= 0.0 else -1.0
    w_turn = 0.5 * robot.wmax_radps
    # aligning: the turn rate falls with the error (half of it in 0.25 s), so a small one is not overshot
    w_align = sign * min(w_turn, _ALIGN_GAIN * turn)
    candidates: list[tuple[float, float, bool]] = [(0.0, w_align, True)] if align_first else []
    candidates.append((law_v, law_w, False))
    for f in (0.5, 0.25):
        v, _, w = drive(theta * f, v_nd, robot)
        candidates.append((v, w, True))
    v_back = -_REVERSE_FRAC * robot.vmax_mps
    if turn >= _SWEEP_MIN_TURN_RAD:  # a turn in place for a small correction would only dither
        candidates.append((0.0, sign * w_turn, True))
    if turn <= _HALF_PI:  # straight on serves only a direction ahead
        candidates.append((v_nd, 0.0, True))
    small_turn = 0.0 < turn < _SWEEP_MIN_TURN_RAD
    if small_turn:  # a small correction in place: only when nothing forward fits, and it opens the way
        candidates.append((0.0, w_align, True))
    if turn > _HALF_PI or _blocked_now(points, law_v, law_w, v_nd, robot):
        candidates.extend([(v_back, w_align, True), (v_back, 0.0, True)])
    for v, w, whole in candidates:
        if v == 0.0 and w == 0.0:
            continue
        if v < 0.0:  # reversing: a short stretch of travel
            t_end = _SWEEP_MIN_M / abs(v)
        elif w == 0.0:  # straight on instead of the turn: only with room to go on until the turn fits
            t_end = (_SWEEP_STRAIGHT_M if whole else _SWEEP_MIN_M) / v
        elif v == 0.0:  # in place: the whole turn
            t_end = turn / abs(w)
        elif whole:  # a wider arc: it must make the whole turn, within the travel bound
            t_end = min(max(turn / abs(w), _SWEEP_MIN_M / v), _SWEEP_MAX_M / v)
        else:  # the law's own arc: its turn or a short stretch, whichever ends first
            t_end = min(turn / abs(w), _SWEEP_MIN_M / v)
        if arc_touches(points, v, 0.0, w, t_end, robot, _SWEEP_MARGIN_M):
            continue
        if v == 0.0 and small_turn and _blocked_after_turn(points, theta, v_nd, robot):
            continue
        return v, w
    return law_v, law_w


def _blocked_after_turn(points: F64, theta: float, v_nd: float, robot: RobotConfig) -> bool:
    """True when the chair, once turned in place to face ``theta``, could not go straight on for
    ``_SWEEP_MIN_M``. A small correction in place that does not open the way forward is followed by the
    same correction back (the direction swings across 0 as the chair turns): a turn that never turns;
    backing off (``_blocked_now``) serves it better."""
    if v_nd <= 0.0:
        return True
    turned = transform_points((0.0, 0.0, -theta), points)  # the points in the frame facing theta
    return arc_touches(turned, v_nd, 0.0, 0.0, _SWEEP_MIN_M / v_nd, robot, _SWEEP_MARGIN_M)


def _blocked_now(points: F64, law_v: float, law_w: float, v_nd: float, robot: RobotConfig) -> bool:
    """True when neither the law's arc nor straight on can go even ``_STEP_M``: reversing with a
    direction ahead only then; a chair that reversed while it could still creep forward would come back
    to the same spot next tick and oscillate there."""
    for v, w in ((law_v, law_w), (v_nd, 0.0)):
        if v <= 0.0:
            continue
        if not arc_touches(points, v, 0.0, w, _STEP_M / v, robot, _SWEEP_MARGIN_M):
            return False
    return True


@dataclass(frozen=True, slots=True)
class NdDiagram:
    """What ND+ sees around the robot, for drawing a decision (``nd_diagram``); robot frame.

    Attributes:
        bisectors_rad: (n,) sector bisectors.
        dist_m: (n,) distance to the closest obstacle point per sector, as ND+ uses it (inf: free).
        gaps: (n,) True where a gap (discontinuity) lies between sector i and i+1 (mod n).
        boundary_m: (n,) distance to the robot's boundary per sector.
        security_m: (n,) distance to the security perimeter per sector (the security zone's edge).
    """

    bisectors_rad: F64
    dist_m: F64
    gaps: NDArray[np.bool_]
    boundary_m: F64
    security_m: F64

    def region_mask(self, region: tuple[int, int] | None) -> NDArray[np.bool_]:
        """(n,) True for the sectors of ``region`` ((first, last), counter-clockwise, wrapping)."""
        n = self.bisectors_rad.size
        mask = np.zeros(n, dtype=bool)
        if region is not None:
            first, last = region
            mask[np.arange(first, first + (last - first) % n + 1) % n] = True
        return mask


def nd_diagram(obstacles_xy: ArrayLike, robot: RobotConfig, params: NdParams = NdParams()) -> NdDiagram:
    """The sectors, gaps and security zone ND+ works on for these obstacle points (robot frame): the same
    sectorisation and gap rule as ``nd_step``, computed apart so that a tick is drawn only when asked."""
    pts = np.asarray(obstacles_xy, dtype=np.float64).reshape(-1, 2)
    geo = _geometry(robot, params)
    dist, _, gaps, _, _, _ = _sectors(pts, geo, robot, params)
    return NdDiagram(geo.angles, dist, gaps, geo.boundary, geo.security)


def nd_step(obstacles_xy: ArrayLike, goal_xy: ArrayLike, robot: RobotConfig,
            params: NdParams = NdParams(), prev: NdMemory | None = None) -> NdResult:
    """One ND+ step: sectors, gaps, regions, free walking area, situation, direction and command.

    Parameters
    ----------
    obstacles_xy : (M, 2) array
        Obstacle points [m] in the robot frame (occupied grid cells around the robot); M may be 0.
        Non-finite rows and points beyond ``params.max_range_m`` are ignored.
    goal_xy : (2,) array
        The goal (or the planner's sub-goal) [m] in the robot frame.
    robot : RobotConfig
        Shape (circle / rectangle about the rotation centre), drive and velocity limits.
    params : NdParams
        Reactor settings.
    prev : NdMemory, optional
        The previous tick's ``NdResult.memory`` turned into this tick's robot frame (commitment to the
        chosen region, ``NdParams.commit_rad``); None: choose afresh.

    Returns
    -------
    NdResult
        Situation, direction, command and selected region. Without a navigable region: situation NONE,
        ``Flag.REACTOR_NO_REGION``, direction nan and a zero command (never NaN).

    Raises
    ------
    ValueError
        If ``obstacles_xy`` is not (M, 2) or ``goal_xy`` is not two finite numbers.
    ConfigError
        If the robot shape or the security distances are invalid.
    """
    pts = np.asarray(obstacles_xy, dtype=np.float64)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"obstacles_xy must have shape (M, 2), got shape {pts.shape}")
    goal = np.asarray(goal_xy, dtype=np.float64).reshape(-1)
    if goal.shape != (2,) or not np.all(np.isfinite(goal)):
        raise ValueError(f"goal_xy must be two finite numbers, got {goal_xy!r}")

    geo = _geometry(robot, params)
    n = params.n_sectors
    dist, ang, gaps, px, py, min_clearance = _sectors(pts, geo, robot, params)
    occ = np.isfinite(dist)

    goal_r, goal_a = math.hypot(goal[0], goal[1]), wrap(dm.atan2(goal[1], goal[0]))  # -0.0 y: pi
    region = _select_region(dist, ang, geo.angles, gaps, px, py, goal_r, goal_a, geo.gap_m,
                            None if prev is None else prev.subgoal_rad, params.commit_rad)
    if region is None:
        return NdResult(Situation.NONE, Flag.REACTOR_NO_REGION, math.nan, 0.0, 0.0, 0.0, None, min_clearance)

    # Dangerous obstacles, split left / right of the region direction; closest = smallest ratio.
    beta = region.direction_rad
    ds = geo.security - geo.boundary
    danger = occ & (dist <= geo.security)
    ratio = np.clip((dist - geo.boundary) / ds, 0.0, 1.0)
    rel = np.mod(ang - beta + math.pi, 2.0 * math.pi) - math.pi  # in [-pi, pi); -pi counts as left
    left_side = (rel >= 0.0) | (rel <= -math.pi)
    obs_l = _closest(danger & left_side, ratio)
    obs_r = _closest(danger & ~left_side, ratio)
    c_l = float(ratio[obs_l]) if obs_l >= 0 else 1.0
    c_r = float(ratio[obs_r]) if obs_r >= 0 else 1.0

    span = (region.last - region.first) % n
    wide = span * (2.0 * math.pi / n) > params.smax_rad
    if region.kind is _Kind.GOAL:
        theta_p = beta
    elif wide:  # pass the discontinuity's corner at (r_c, a_c), towards the inside of the region
        off = dm.atan2(0.5 * geo.gap_m + params.security_m, float(dist[region.corner]))
        a_c = float(ang[region.corner])
        theta_p = wrap(a_c + off if region.kind is _Kind.FIRST_EDGE else a_c - off)
    else:  # bisector of the region
        theta_p = wrap((region.first + 0.5 * span) * (2.0 * math.pi / n))

    if obs_l < 0 and obs_r < 0:
        if region.kind is _Kind.GOAL:
            situation = Situation.HSGR
        else:
            situation = Situation.HSWR if wide else Situation.HSNR
        theta = theta_p
    elif obs_l >= 0 and obs_r >= 0:
        situation = Situation.LS2
        theta = _ls2_direction(beta, c_l, c_r)
    else:
        situation = Situation.LSG if region.kind is _Kind.GOAL else Situation.LS1
        obs = obs_l if obs_l >= 0 else obs_r
        theta = _blend_away(theta_p, float(ang[obs]), float(ratio[obs]))

    axis: tuple[float, float, float, float] | None = None
    align = False
    if robot.shape == "rectangle" and robot.drive == "differential" and abs(beta) <= _HALF_PI and (
            region.kind is not _Kind.GOAL or goal_r > robot.front_m):  # a goal within reach: steer to it
        axis = _passage_axis(dist, ang, left_side, beta,
                             min_width_m=geo.gap_m, max_width_m=geo.gap_m + 2.0 * params.security_m,
                             reach_m=robot.front_m + robot.rear_m + params.security_m,
                             behind_m=robot.rear_m + 0.5 * params.security_m, front_m=robot.front_m)
        if axis is not None:
            theta, align = _stage_direction(axis, robot, dist, ang, 0.5 * geo.gap_m + params.security_m)
    v_nd = robot.vmax_mps * min(c_l, c_r)
    if axis is not None:  # along a passage the swept-footprint checks, not the side clearance, bound it
        v_nd = max(v_nd, _PASSAGE_V_FRAC * robot.vmax_mps)
    if robot.shape == "rectangle" and robot.drive == "differential":
        v, w = _admissible_drive(theta, v_nd, robot, pts, align_first=align)
        vy = 0.0
    else:
        v, vy, w = drive(theta, v_nd, robot)
    memory = None if region.kind is _Kind.GOAL else NdMemory(region.direction_rad)
    return NdResult(situation, Flag.NONE, theta, v, vy, w, (region.first, region.last), min_clearance, memory)


def _closest(mask: NDArray[np.bool_], ratio: F64) -> int:
    """Index of the smallest ratio under mask, -1 if none."""
    if not mask.any():
        return -1
    return int(np.flatnonzero(mask)[np.argmin(ratio[mask])])
