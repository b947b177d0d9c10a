"""The functional loop of the multi-loop paper: path manager, trajectory generator and tracking controller.

``PathFollower.step`` runs, every tick, the three blocks of the paper's path following (sections 3.3, Fig. 5):

* **Path manager.** The current subgoal advances when it is *reached*: the rotation centre within
  ``reach_m`` of it and, for forward / reverse subgoals, the heading within ``heading_tol_rad``; for stop
  subgoals also at rest (``|v| <= stop_v_mps``; the speed passed to ``step`` or else the follower's own
  last command). A subgoal is *skipped* (rule, **choice**) when it is a forward or reverse subgoal that is
  not the last one, the robot lies more than ``reach_m`` beyond the line through it perpendicular to its
  driving direction (``(p - g) . u > reach_m``, ``u`` its heading, flipped for reverse) and is closer to
  the next subgoal than this subgoal is. Stop subgoals and the final subgoal are never skipped. A subgoal
  whose cell is not free in the C-space of the grid (``cspace.free_cspace`` with ``inflate_m``) is
  *replaced* by the nearest free cell reachable from the robot cell (4-connected wave of
  ``nf1.nf1_wavefront``; when the robot cell itself is not free, from the cell NF1's escape would run to,
  the nearest free one within ``escape_m``) within ``replace_search_m``, heading and kind kept. The
  replacement stays while it is free and reachable; the original is tested every tick and comes back once
  free (both changes are "replaced" events). A subgoal outside the grid stays as it is.
* **Trajectory generator.** A cubic spiral (curvature a cubic of arc length, Kelly & Nagy 2003) from the
  robot pose to the subgoal: curvature ``kappa0`` at the start (the robot's current curvature, so the
  curvature is continuous when a trajectory is regenerated) and 0 at the subgoal, found by damped Newton on
  the curvature at 1/3 and 2/3 of the length and the length. A solution is accepted when it converged, its
  curvature stays within ``kappa_max`` and its length within ``2.5 d + pi / kappa_max``. Fallbacks, in
  order: the spiral from curvature 0; turn in place towards the subgoal, then a spiral; turn in place
  towards it, then a straight line ending with point stabilisation (which turns to the heading asked).
  Reverse subgoals are driven backwards: everything runs in the *driving frame* (heading + pi), where a
  backward motion is a forward one, and the speed is negated on the way out. The samples (every
  ``sample_m``) carry heading and curvature; a straight extension of ``extend_m`` past the subgoal gives
  the tracker a reference if it overshoots. A subgoal farther than ``horizon_m`` is approached through an
  intermediate pose that far along the straight line to it (heading along the line, not stopped at), so a
  tick's cost does not grow with the distance. Regenerated when the subgoal changes and when the robot is
  farther than ``deviation_m`` from it or past its end, or within ``lookahead_m`` of an intermediate end;
  while turning in place, when the robot is farther than ``deviation_m`` from the trajectory's start
  (pushed, or moved by local navigation: the heading to turn to was computed at the old pose) (event
  "replanned").
* **Tracking controller.** Kanayama et al. (1990) on the nearest trajectory point: ``v = v_r cos e_th +
  k_x e_x``, ``w = v_r (kappa_r + k_y e_y + k_theta sin e_th)``; ``v_r`` is limited by ``vmax_mps``,
  ``wmax_radps / |kappa|`` and a braking profile ``sqrt(2 a d)`` (``a = brake_frac * accel_mps2``) before a
  subgoal the robot stops at (stop subgoals, the final one, and cusps where the driving direction changes).
  Within ``stabilise_m`` of such a subgoal, point stabilisation of Aicardi et al. (1995) in polar
  coordinates takes over, and within ``settle_m`` a turn in place to the heading asked. A command
  beyond ``wmax_radps`` is scaled down with its speed (its curvature is kept). Where the tracking law's
  speed turns against the driving direction (the reference behind the robot) the robot turns in place to
  the trajectory's heading instead: a forward subgoal is never driven to backwards, nor a reverse one
  forwards. A holonomic robot gets vy = 0.

When local navigation takes over (the mode selector), it steers to ``PathFollower.local_target``: the first
trajectory point beyond the look-ahead point that is free in C-space (the look-ahead point may lie on the
obstacle blocking the path, where the footprint cannot go), or the subgoal when there is none. The caller
tells ``step`` when the command executed last tick was not the follower's (``overridden``); the
trajectory is then planned anew from the robot's pose (event "replanned"), as the paper's follower does
once local navigation has deviated the robot (Fig. 7).

Everything is a pure function of the subgoals, the parameters and the sequence of poses and grids.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..geometry import wrap_angle
from ..robot import RobotConfig
from ..types import Pose2D, Subgoal
from .cspace import free_cspace
from .model import RobotCentredGrid
from .nf1 import Nf1Params, nearest_true, nf1_wavefront

__all__ = [
    "FollowCommand",
    "FollowParams",
    "PathFollower",
    "Spiral",
    "Trajectory",
    "aicardi_command",
    "first_free_point",
    "free_point_ahead",
    "is_passed",
    "kanayama_command",
    "plan_trajectory",
    "replacement_point",
    "sample_spiral",
    "solve_spiral",
]


@dataclass(frozen=True, slots=True)
class FollowParams:
    """Path following settings ([navigation.follow]).

    Attributes:
        reach_m: a subgoal is reached within this distance [m].
        heading_tol_rad: ... and (forward / reverse / stop) with the heading within this [rad].
        stop_v_mps: a stop subgoal is reached at rest: |v| at most this [m/s].
        deviation_m: regenerate the trajectory when the robot is farther than this from it [m].
        lookahead_m: ``FollowCommand.target_xy`` lies this far ahead along the trajectory [m].
        lookahead_s: the stack uses ``max(lookahead_m, lookahead_s * vmax_mps)`` as ``lookahead_m`` [s];
            0 (the default): the fixed distance.
        sample_m: spacing of the trajectory samples [m].
        kappa_max: largest curvature a spiral may have [1/m].
        extend_m: straight extension of the trajectory past the subgoal [m].
        stabilise_m: point stabilisation within this distance of a subgoal the robot stops at [m].
        settle_m: ... and within this distance (capped at ``reach_m``, so that a stop subgoal can be
            reached) a turn in place to the heading asked, at rest [m].
        brake_frac: braking before such a subgoal uses this fraction of ``accel_mps2``.
        creep_frac: the tracking reference speed never drops below this fraction of ``vmax_mps``.
        k_x: Kanayama along-track gain [1/s].
        k_y: Kanayama cross-track gain [1/m^2].
        k_theta: Kanayama heading gain [1/m]. With ``w = v (k_y e_y + k_theta e_th)`` the cross-track error
            obeys e'' + k_theta e' + k_y e = 0 in arc length: k_theta = 2 sqrt(k_y) is critically damped,
            whatever the speed, over a length scale 1 / sqrt(k_y) (0.5 m by default).
        k_rho: Aicardi distance gain (gamma) [1/s].
        k_alpha: Aicardi bearing gain (k) [1/s].
        k_phi: Aicardi final-heading gain (h) [-].
        k_turn: turn-in-place gain [1/s].
        turn_tol_rad: a turn in place ends within this heading error [rad].
        replace_search_m: search radius for the replacement of a subgoal inside an obstacle [m].
        horizon_m: planning horizon [m] (**choice**: 6 m, within the default grid's half width): a subgoal
            farther than this is approached through an intermediate pose ``horizon_m`` along the straight
            line to it (heading along the line, not stopped at), replaced by the next one when the robot
            comes within ``lookahead_m`` of it, so the cost per tick does not grow with the distance.
    """

    reach_m: float = 0.2
    heading_tol_rad: float = 0.3
    stop_v_mps: float = 0.05
    deviation_m: float = 0.4
    lookahead_m: float = 1.0
    sample_m: float = 0.05
    kappa_max: float = 2.5
    extend_m: float = 1.0
    stabilise_m: float = 0.5
    settle_m: float = 0.05
    brake_frac: float = 0.5
    creep_frac: float = 0.2
    k_x: float = 1.0
    k_y: float = 4.0
    k_theta: float = 4.0
    k_rho: float = 1.0
    k_alpha: float = 3.0
    k_phi: float = 2.0
    k_turn: float = 2.0
    turn_tol_rad: float = 0.1
    replace_search_m: float = 3.0
    horizon_m: float = 6.0
    lookahead_s: float = 0.0


@dataclass(frozen=True, slots=True, eq=False)
class FollowCommand:
    """What the path follower would command this tick, and what the path manager did.

    Attributes:
        v_mps, w_radps: the tracking controller's command.
        subgoal_index: index of the current subgoal (len(subgoals) once the path is executed).
        done: the final subgoal is reached.
        event: "" or what the path manager did this tick: "reached", "skipped", "replaced", "replanned".
        target_xy: the point (corrected frame) the follower is heading to, ``lookahead_m`` along the
            trajectory (local navigation, when it takes over, aims past it: ``PathFollower.local_target``).
        trajectory_xy: (K, 2) the current smooth trajectory to the subgoal (corrected frame).
        subgoal_xy: the current subgoal's position after replacement (the final one once done).
        mode: what the controller did: "track", "stabilise", "turn" or "idle" (done).
    """

    v_mps: float
    w_radps: float
    subgoal_index: int
    done: bool
    event: str
    target_xy: tuple[float, float]
    trajectory_xy: NDArray[np.float64] = field(repr=False)
    subgoal_xy: tuple[float, float] = (math.nan, math.nan)
    mode: str = "track"


# ---- trajectory generator: cubic spirals ---------------------------------------------------------------

_SIMPSON_N = 64  # intervals of the Simpson rule for the spiral end point (even)
_NEWTON_ITERS = 30
_TOL_M = 1e-4
_TOL_RAD = 1e-4


@dataclass(frozen=True, slots=True)
class Spiral:
    """A cubic spiral from ``start`` (x, y, heading, world): curvature ``k(s) = a + b s + c s^2 + d s^3``
    for s in [0, length]."""

    start: tuple[float, float, float]
    coeffs: tuple[float, float, float, float]
    length: float


def _coeffs(p0: NDArray[np.float64], p1: NDArray[np.float64], p2: NDArray[np.float64],
            p3: NDArray[np.float64], sf: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M,) curvature knots at s = 0, sf/3, 2 sf/3, sf -> (M, 4) polynomial coefficients a, b, c, d."""
    a = p0
    b = -(11.0 * p0 - 18.0 * p1 + 9.0 * p2 - 2.0 * p3) / (2.0 * sf)
    c = 9.0 * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) / (2.0 * sf * sf)
    d = -9.0 * (p0 - 3.0 * p1 + 3.0 * p2 - p3) / (2.0 * sf * sf * sf)
    return np.stack([a, b, c, d], axis=-1)


def _heading(coeffs: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Heading change theta(s) = a s + b s^2/2 + c s^3/3 + d s^4/4 (coeffs (..., 4), s broadcast)."""
    a, b, c, d = (coeffs[..., i, None] for i in range(4))
    return s * (a + s * (b / 2.0 + s * (c / 3.0 + s * d / 4.0)))


def _curvature(coeffs: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray[np.float64]:
    a, b, c, d = (coeffs[..., i, None] for i in range(4))
    return a + s * (b + s * (c + s * d))


def _simpson_ends(co: NDArray[np.float64], sf: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, 4) coefficients, (M,) lengths -> (M, 3) end pose (x, y, theta) of the spirals from the origin,
    heading 0 (Simpson's rule, vectorised over the M candidates)."""
    u = np.linspace(0.0, 1.0, _SIMPSON_N + 1)
    th = _heading(co, sf[:, None] * u[None, :])
    w = np.ones(_SIMPSON_N + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    w *= 1.0 / (3.0 * _SIMPSON_N)
    return np.column_stack([sf * _weighted_rows(dm.cos_a(th), w), sf * _weighted_rows(dm.sin_a(th), w),
                            th[:, -1]])


def _weighted_rows(a: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    """a @ w for (M, K) a, summed over k in order (BLAS's order depends on the CPU)."""
    acc = a[:, 0] * w[0]
    for k in range(1, w.shape[0]):
        acc = acc + a[:, k] * w[k]
    return acc


def _spiral_ends(q: NDArray[np.float64], k0: float, kf: float) -> NDArray[np.float64]:
    """(M, 3) parameters (p1, p2, sf) -> (M, 3) end pose of the spiral from the origin, heading 0."""
    m = q.shape[0]
    return _simpson_ends(_coeffs(np.full(m, k0), q[:, 0], q[:, 1], np.full(m, kf), q[:, 2]), q[:, 2])


def _guesses(d: float, alpha: float, gt: float, k0: float,
             kf: float) -> list[tuple[float, tuple[float, float]]]:
    """Initial (length, (p1, p2)) for Newton: the small-angle solution about the chord (heading relative to
    the chord from -alpha to gt - alpha, no lateral offset: two linear equations in p1, p2) with the
    length heuristic of Kelly & Nagy, then equal inner knots giving the heading change."""
    out = []
    turn = abs(alpha) + abs(gt - alpha)
    for sf in (d * (1.0 + turn * turn / 8.0), d * (gt * gt / 5.0 + 1.0) + 2.0 * abs(gt) / 5.0):
        # heading about the chord psi(s) = -alpha + theta(s); psi(sf) = gt - alpha, int psi ds = 0
        u = np.linspace(0.0, sf, 33)
        basis = _coeffs(np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0, 0.0]),
                        np.array([0.0, 0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]), np.full(4, sf))
        th = _heading(basis, u)  # (4, 33): theta of each knot's basis spiral
        end = th[:, -1]
        area = np.asarray(np.trapezoid(th, u, axis=1), dtype=np.float64)
        a_mat = np.array([[end[1], end[2]], [area[1], area[2]]])
        rhs = np.array([gt - k0 * end[0] - kf * end[3], alpha * sf - k0 * area[0] - kf * area[3]])
        try:
            p1, p2 = dm.solve(a_mat, rhs)
            out.append((sf, (float(p1), float(p2))))
        except np.linalg.LinAlgError:
            pass
    sf = d * (gt * gt / 5.0 + 1.0) + 2.0 * abs(gt) / 5.0
    p = (8.0 * gt / sf - k0 - kf) / 6.0
    out.append((sf, (p, p)))
    return out


def _norm3(r: NDArray[np.float64]) -> float:
    """Euclidean norm of a 3-vector, summed in order (np.linalg.norm goes through BLAS)."""
    return math.sqrt(float(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]))


def _newton(q: NDArray[np.float64], target: NDArray[np.float64], k0: float,
            kf: float) -> NDArray[np.float64] | None:
    """Damped Newton on (p1, p2, sf) to the end pose ``target``; None when it fails."""

    def residual(qs: NDArray[np.float64]) -> NDArray[np.float64]:
        r = _spiral_ends(qs, k0, kf) - target
        r[:, 2] = wrap_angle(r[:, 2])
        return r

    r = residual(q[None])[0]
    for _ in range(_NEWTON_ITERS):
        if abs(r[0]) < _TOL_M and abs(r[1]) < _TOL_M and abs(r[2]) < _TOL_RAD:
            return q
        h = 1e-6 * np.maximum(1.0, np.abs(q))
        jac = ((residual(q + np.diag(h)) - r) / h[:, None]).T
        try:
            step = dm.solve(jac, -r)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(step)):
            return None
        norm = _norm3(r)
        t = 1.0
        while t >= 1.0 / 64.0:
            qn = q + t * step
            if qn[2] > 0.0:
                rn = residual(qn[None])[0]
                if _norm3(rn) < norm:
                    q, r = qn, rn
                    break
            t *= 0.5
        else:
            return None
    return None


def solve_spiral(start: tuple[float, float, float], goal: tuple[float, float, float], *, kappa0: float = 0.0,
                 kappaf: float = 0.0, kappa_max: float = math.inf) -> Spiral | None:
    """The cubic spiral from ``start`` to ``goal`` (x, y, heading) with end curvatures ``kappa0`` and
    ``kappaf``, or None when Newton does not converge or the solution is not acceptable (curvature above
    ``kappa_max``, length above ``2.5 d + pi / kappa_max``; module notes).

    Unknowns (Kelly & Nagy 2003): the curvature at 1/3 and 2/3 of the length, and the length; damped Newton
    with a finite-difference Jacobian and step halving from each initial guess of ``_guesses`` in turn,
    the first acceptable solution wins.
    """
    x0, y0, t0 = start
    dx, dy = goal[0] - x0, goal[1] - y0
    c, s = dm.cos(t0), dm.sin(t0)
    gx, gy = c * dx + s * dy, -s * dx + c * dy
    gt = float(wrap_angle(goal[2] - t0))
    d = math.hypot(gx, gy)
    if d < 1e-6:
        return None
    target = np.array([gx, gy, gt])
    alpha = dm.atan2(gy, gx)
    for sf0, (p1, p2) in _guesses(d, alpha, gt, kappa0, kappaf):
        q = _newton(np.array([p1, p2, sf0]), target, kappa0, kappaf)
        if q is None or q[2] > 2.5 * d + math.pi / kappa_max:
            continue
        co = _coeffs(np.array([kappa0]), q[:1], q[1:2], np.array([kappaf]), q[2:])[0]
        if float(np.max(np.abs(_curvature(co[None], np.linspace(0.0, q[2], 65))))) <= kappa_max:
            return Spiral(start, (float(co[0]), float(co[1]), float(co[2]), float(co[3])), float(q[2]))
    return None


def sample_spiral(spiral: Spiral, sample_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                            NDArray[np.float64], NDArray[np.float64]]:
    """Samples every ~``sample_m`` of arc length: (K, 2) points, (K,) heading, (K,) curvature, (K,) arc
    length. Points by cumulative trapezoids, corrected linearly in s so the last point is the exact end
    (the Simpson end point the solver matched); K >= 2."""
    n = max(math.ceil(spiral.length / sample_m), 2)
    s = np.linspace(0.0, spiral.length, n + 1)
    co = np.asarray(spiral.coeffs)[None]
    th = _heading(co, s)[0]
    k = _curvature(co, s)[0]
    ds = np.diff(s)
    cx = np.concatenate([[0.0], np.cumsum(0.5 * (dm.cos_a(th[1:]) + dm.cos_a(th[:-1])) * ds)])
    cy = np.concatenate([[0.0], np.cumsum(0.5 * (dm.sin_a(th[1:]) + dm.sin_a(th[:-1])) * ds)])
    if spiral.length > 0.0:
        end = _simpson_ends(co, np.array([spiral.length]))[0]
        frac = s / spiral.length
        cx = cx + frac * (end[0] - cx[-1])
        cy = cy + frac * (end[1] - cy[-1])
    x0, y0, t0 = spiral.start
    c, si = dm.cos(t0), dm.sin(t0)
    xy = np.column_stack([x0 + c * cx - si * cy, y0 + si * cx + c * cy])
    return xy, np.asarray(wrap_angle(th + t0), dtype=np.float64), k, s


@dataclass(frozen=True, slots=True, eq=False)
class Trajectory:
    """A trajectory in the driving frame (headings of the direction of travel).

    Attributes:
        xy: (K, 2) points [m, world]; heading, kappa, s: (K,) heading of travel [rad], curvature [1/m]
            (of the direction of travel), arc length [m].
        s_goal: arc length of the subgoal (the straight extension lies beyond).
        direction: +1 driven forwards, -1 backwards (v is negated).
        turn_to: heading of travel to turn to in place before tracking, or None.
        stops: the robot comes to rest at the subgoal (braking profile and point stabilisation).
        kind: "spiral", "turn-spiral" or "turn-line" (which rung of the fallbacks).
        partial: the trajectory ends at an intermediate pose within the planning horizon, not at the
            subgoal (``FollowParams.horizon_m``).
    """

    xy: NDArray[np.float64]
    heading: NDArray[np.float64]
    kappa: NDArray[np.float64]
    s: NDArray[np.float64]
    s_goal: float
    direction: int
    turn_to: float | None
    stops: bool
    kind: str
    partial: bool = False

    def goal_end(self) -> int:
        """Number of samples up to the subgoal (the extension excluded)."""
        return int(np.searchsorted(self.s, self.s_goal + 1e-9, side="right"))


def _extend(xy: NDArray[np.float64], heading: NDArray[np.float64], kappa: NDArray[np.float64],
            s: NDArray[np.float64], extend_m: float, sample_m: float) -> tuple[NDArray[np.float64], ...]:
    """Append a straight extension of ``extend_m`` along the last heading."""
    n = max(math.ceil(extend_m / sample_m), 1)
    t = np.linspace(0.0, extend_m, n + 1)[1:]
    h = float(heading[-1])
    ext = xy[-1] + t[:, None] * np.array([dm.cos(h), dm.sin(h)])
    return (np.vstack([xy, ext]), np.concatenate([heading, np.full(n, h)]),
            np.concatenate([kappa, np.zeros(n)]), np.concatenate([s, s[-1] + t]))


def plan_trajectory(pose: Pose2D, goal: Subgoal, params: FollowParams, *, direction: int, stops: bool,
                    kappa0: float = 0.0) -> Trajectory:
    """The trajectory from ``pose`` to ``goal`` (world), driven in ``direction`` (+1 / -1), with the
    fallbacks of the module notes; ``kappa0`` is the current curvature of travel."""
    flip = math.pi if direction < 0 else 0.0
    start = (pose.x, pose.y, float(wrap_angle(pose.theta + flip)))
    end = (goal.x, goal.y, float(wrap_angle(goal.theta + flip)))
    km = params.kappa_max
    kappa0 = float(np.clip(kappa0, -km, km))
    kind, turn_to, spiral = "spiral", None, None
    for k0 in ((kappa0, 0.0) if kappa0 != 0.0 else (0.0,)):
        spiral = solve_spiral(start, end, kappa0=k0, kappa_max=km)
        if spiral is not None:
            break
    if spiral is None:
        d = math.hypot(end[0] - start[0], end[1] - start[1])
        # beside the subgoal already: turn to its heading rather than to a bearing of no meaning
        bearing = dm.atan2(end[1] - start[1], end[0] - start[0]) if d > params.settle_m else end[2]
        turn_to = bearing
        kind = "turn-spiral"
        spiral = solve_spiral((start[0], start[1], bearing), end, kappa_max=km)
        if spiral is None:  # straight line; point stabilisation turns to the heading asked at the end
            kind, stops = "turn-line", True
            spiral = Spiral((start[0], start[1], bearing), (0.0, 0.0, 0.0, 0.0), d)
    xy, heading, kappa, s = sample_spiral(spiral, params.sample_m)
    s_goal = float(s[-1])
    xy, heading, kappa, s = _extend(xy, heading, kappa, s, params.extend_m, params.sample_m)
    return Trajectory(xy, heading, kappa, s, s_goal, 1 if direction >= 0 else -1, turn_to, stops, kind)


def _project(traj: Trajectory, p: NDArray[np.float64], s_lo: float, s_hi: float) -> tuple[float, float, int]:
    """Nearest point of the trajectory polyline to ``p`` among segments starting in [s_lo, s_hi] (all of
    them when none does): (arc length, distance, segment index). The window is found by bisection and the
    segments in it are vectorised, so the cost does not grow with the trajectory's length."""
    n_seg = traj.s.shape[0] - 1
    i0 = int(np.searchsorted(traj.s, s_lo, side="left"))
    i1 = min(int(np.searchsorted(traj.s, s_hi, side="right")), n_seg)
    if i0 >= i1:
        i0, i1 = 0, n_seg
    sel = np.arange(i0, i1)
    a, b = traj.xy[i0:i1], traj.xy[i0 + 1:i1 + 1]
    ab = b - a
    L2 = dm.sqdist(ab)
    ap = p - a
    t = np.clip((ap[:, 0] * ab[:, 0] + ap[:, 1] * ab[:, 1]) / np.where(L2 > 0.0, L2, 1.0), 0.0, 1.0)
    q = a + t[:, None] * ab
    dist = np.hypot(q[:, 0] - p[0], q[:, 1] - p[1])
    j = int(np.argmin(dist))
    i = int(sel[j])
    s = float(traj.s[i] + t[j] * (traj.s[i + 1] - traj.s[i]))
    return s, float(dist[j]), i


def _at(traj: Trajectory, s: float) -> tuple[float, float, float, float]:
    """(x, y, heading, kappa) on the trajectory at arc length ``s`` (linear interpolation, clamped)."""
    s = min(max(s, float(traj.s[0])), float(traj.s[-1]))
    x = float(np.interp(s, traj.s, traj.xy[:, 0]))
    y = float(np.interp(s, traj.s, traj.xy[:, 1]))
    i = min(int(np.searchsorted(traj.s, s, side="right")) - 1, len(traj.s) - 2)
    f = (s - traj.s[i]) / max(traj.s[i + 1] - traj.s[i], 1e-12)
    h = float(traj.heading[i] + f * wrap_angle(traj.heading[i + 1] - traj.heading[i]))
    k = float(traj.kappa[i] + f * (traj.kappa[i + 1] - traj.kappa[i]))
    return x, y, h, k


# ---- tracking controller ------------------------------------------------------------------------------


def _limit(v: float, w: float, robot: RobotConfig) -> tuple[float, float]:
    """Scale (v, w) down together (the curvature is kept) to |v| <= vmax and |w| <= wmax."""
    f = 1.0
    if abs(v) > robot.vmax_mps:
        f = robot.vmax_mps / abs(v)
    if abs(w) * f > robot.wmax_radps:
        f = robot.wmax_radps / abs(w)
    return v * f, w * f


def kanayama_command(pose_d: tuple[float, float, float], ref: tuple[float, float, float, float], v_ref: float,
                     params: FollowParams) -> tuple[float, float]:
    """Kanayama et al. (1990) tracking law in the driving frame: pose (x, y, heading), reference (x, y,
    heading, curvature) moving at ``v_ref`` -> (v, w) before limits."""
    x, y, th = pose_d
    rx, ry, rth, rk = ref
    c, s = dm.cos(th), dm.sin(th)
    ex = c * (rx - x) + s * (ry - y)
    ey = -s * (rx - x) + c * (ry - y)
    et = float(wrap_angle(rth - th))
    v = v_ref * dm.cos(et) + params.k_x * ex
    w = v_ref * (rk + params.k_y * ey + params.k_theta * dm.sin(et))
    return v, w


def aicardi_command(pose_d: tuple[float, float, float], goal_d: tuple[float, float, float],
                    params: FollowParams) -> tuple[float, float]:
    """Point stabilisation of Aicardi et al. (1995) in polar coordinates (driving frame): e the distance,
    alpha the bearing of the goal from the robot heading, phi the bearing of the line robot -> goal from
    the goal heading; v = gamma e cos(alpha), w = k alpha + gamma cos(alpha) sin(alpha)/alpha (alpha + h phi)
    -> (v, w) before limits."""
    dx, dy = goal_d[0] - pose_d[0], goal_d[1] - pose_d[1]
    e = math.hypot(dx, dy)
    line = dm.atan2(dy, dx)
    alpha = float(wrap_angle(line - pose_d[2]))
    phi = float(wrap_angle(line - goal_d[2]))
    sinc = dm.sin(alpha) / alpha if abs(alpha) > 1e-9 else 1.0
    v = params.k_rho * e * dm.cos(alpha)
    w = params.k_alpha * alpha + params.k_rho * dm.cos(alpha) * sinc * (alpha + params.k_phi * phi)
    return v, w


def is_passed(pose: Pose2D, goal: Subgoal, next_goal: Subgoal, margin_m: float) -> bool:
    """The skip rule (module notes): the robot lies more than ``margin_m`` beyond the line through ``goal``
    perpendicular to its driving direction, and nearer ``next_goal`` than ``goal`` is."""
    h = goal.theta + (math.pi if goal.kind == "reverse" else 0.0)
    beyond = (pose.x - goal.x) * dm.cos(h) + (pose.y - goal.y) * dm.sin(h) > margin_m
    nearer = math.hypot(pose.x - next_goal.x, pose.y - next_goal.y) < math.hypot(goal.x - next_goal.x,
                                                                                  goal.y - next_goal.y)
    return beyond and nearer


_ESCAPE_M = Nf1Params().escape_m  # NF1's default escape length


def replacement_point(goal_xy: tuple[float, float], pose: Pose2D, grid: RobotCentredGrid, *, inflate_m: float,
                      unknown_is_free: bool, search_m: float,
                      keep_xy: tuple[float, float] | None = None,
                      escape_m: float = _ESCAPE_M) -> tuple[float, float] | None:
    """Where the path manager puts a subgoal given the grid: None when ``goal_xy`` is outside the grid or
    free in C-space (keep it); otherwise ``keep_xy`` if that is a free cell reachable from the robot, else
    the centre of the nearest free reachable cell within ``search_m``, else None (nothing better: keep).

    Reachable: by the 4-connected wave from the robot cell or, when that cell is not free in C-space
    (routine beside a wall for a robot whose inner disc is large), from the cell NF1's escape would run
    to, the nearest free cell within ``escape_m`` (``nf1.plan``: a straight segment that short is safe);
    none there: None."""
    cell_m = grid.params.cell_m
    rc = grid.world_to_cell(np.array(goal_xy))[0]
    if not bool(grid.contains(rc)[0]):
        return None
    r, c = int(rc[0]), int(rc[1])
    k = math.ceil(inflate_m / cell_m) + 1  # the window holds every cell that can block (r, c)
    r0, c0 = max(r - k, 0), max(c - k, 0)
    window = grid.cells[r0:r + k + 1, c0:c + k + 1]
    local = free_cspace(window, cell_m=cell_m, inflate_m=inflate_m, unknown_is_free=unknown_is_free)
    if local[r - r0, c - c0]:
        return None
    free = free_cspace(grid.cells, cell_m=cell_m, inflate_m=inflate_m, unknown_is_free=unknown_is_free)
    robot_rc = grid.robot_cell(pose)
    if not bool(grid.contains(np.array(robot_rc))[0]):
        return None
    if not free[robot_rc]:
        # nf1._escape_target is the nearest cell NF1's wave reached; with no goal wave here every free cell
        # counts, and the nearest free one is what nf1.nearest_true returns (the same nf1._nearest search)
        entry = nearest_true(free, robot_rc, escape_m / cell_m)
        if entry is None:
            return None
        robot_rc = entry
    reach = np.isfinite(nf1_wavefront(free, robot_rc)) & free
    if keep_xy is not None:
        kc = grid.world_to_cell(np.array(keep_xy))[0]
        if bool(grid.contains(kc)[0]) and reach[int(kc[0]), int(kc[1])]:
            return keep_xy
    best = nearest_true(reach, (r, c), search_m / cell_m)
    if best is None:
        return None
    x, y = grid.cells_to_world(np.array([best], dtype=np.int64))[0]
    return float(x), float(y)


def first_free_point(xy: NDArray[np.float64], grid: RobotCentredGrid, *, inflate_m: float,
                     unknown_is_free: bool) -> int | None:
    """Index of the first of the points ``xy`` (K, 2, world) whose cell is free in the C-space of the grid
    (``cspace.free_cspace`` with ``inflate_m``, on a window around the points only), or None. A point
    beyond the grid's edge is unknown to the model: free when ``unknown_is_free``."""
    if xy.shape[0] == 0:
        return None
    rc = grid.world_to_cell(xy)
    inside = grid.contains(rc)
    ok = np.full(xy.shape[0], unknown_is_free)
    if inside.any():
        cell_m = grid.params.cell_m
        k = math.ceil(inflate_m / cell_m) + 1  # the window holds every cell that can block a point
        rin = rc[inside]
        size = grid.cells.shape
        r0, c0 = max(int(rin[:, 0].min()) - k, 0), max(int(rin[:, 1].min()) - k, 0)
        r1, c1 = min(int(rin[:, 0].max()) + k + 1, size[0]), min(int(rin[:, 1].max()) + k + 1, size[1])
        free = free_cspace(grid.cells[r0:r1, c0:c1], cell_m=cell_m, inflate_m=inflate_m,
                           unknown_is_free=unknown_is_free)
        ok[inside] = free[rin[:, 0] - r0, rin[:, 1] - c0]
    hit = np.flatnonzero(ok)
    return int(hit[0]) if hit.size else None


def free_point_ahead(traj: Trajectory, s_from: float, grid: RobotCentredGrid, *, inflate_m: float,
                     unknown_is_free: bool) -> tuple[float, float] | None:
    """The first trajectory sample beyond arc length ``s_from`` and up to the subgoal that is free in the
    C-space of the grid (``first_free_point``), or None."""
    n = traj.goal_end()
    xy = traj.xy[:n][traj.s[:n] > s_from]
    i = first_free_point(xy, grid, inflate_m=inflate_m, unknown_is_free=unknown_is_free)
    if i is None:
        return None
    return float(xy[i, 0]), float(xy[i, 1])


# ---- the follower --------------------------------------------------------------------------------------


class PathFollower:
    """Tracks a list of subgoals; state: the current subgoal (and its replacement), its trajectory, the
    progress along it, the last command."""

    def __init__(self, subgoals: Sequence[Subgoal], params: FollowParams, robot: RobotConfig, *,
                 inflate_m: float, unknown_is_free: bool = True, escape_m: float = _ESCAPE_M) -> None:
        self.subgoals = list(subgoals)
        self.escape_m = escape_m
        self.params = params
        self.robot = robot
        self.inflate_m = inflate_m
        self.unknown_is_free = unknown_is_free
        self.index = 0
        self.trajectory: Trajectory | None = None
        self._goal: Subgoal | None = None  # the current subgoal after replacement
        self._replaced_xy: tuple[float, float] | None = None
        self._s = 0.0  # progress along the trajectory [m]
        self._turning = False
        self._last_v = 0.0
        self._last_w = 0.0

    @property
    def done(self) -> bool:
        return self.index >= len(self.subgoals)

    def _direction(self, i: int) -> int:
        return -1 if self.subgoals[i].kind == "reverse" else 1

    def _stops_at(self, i: int) -> bool:
        """The robot comes to rest at subgoal i: stop subgoals, the final one, and cusps."""
        return (self.subgoals[i].kind == "stop" or i == len(self.subgoals) - 1
                or self._direction(i + 1) != self._direction(i))

    def _reached(self, pose: Pose2D, goal: Subgoal, v_mps: float) -> bool:
        p = self.params
        if math.hypot(pose.x - goal.x, pose.y - goal.y) > p.reach_m:
            return False
        if abs(float(wrap_angle(pose.theta - goal.theta))) > p.heading_tol_rad:
            return False
        return goal.kind != "stop" or abs(v_mps) <= p.stop_v_mps

    def _replace(self, pose: Pose2D, grid: RobotCentredGrid) -> bool:
        """Update the current subgoal's replacement; True when its position changed."""
        orig = self.subgoals[self.index]
        new = replacement_point((orig.x, orig.y), pose, grid, inflate_m=self.inflate_m,
                                unknown_is_free=self.unknown_is_free, search_m=self.params.replace_search_m,
                                keep_xy=self._replaced_xy, escape_m=self.escape_m)
        changed = new != self._replaced_xy
        self._replaced_xy = new
        self._goal = orig if new is None else Subgoal(new[0], new[1], orig.theta, orig.kind)
        return changed

    def _plan(self, pose: Pose2D, v: float, w: float) -> None:
        """A new trajectory to the current subgoal, starting with the curvature of the motion (v, w) when
        the robot moves in the subgoal's driving direction; to an intermediate pose on the straight line
        to it when it lies beyond the planning horizon (``FollowParams.horizon_m``)."""
        assert self._goal is not None
        d = self._direction(self.index)
        kappa0 = 0.0
        if abs(v) > 1e-3 and (v > 0) == (d > 0):
            kappa0 = d * w / v  # curvature of travel in the driving frame
        goal, stops, partial = self._goal, self._stops_at(self.index), False
        dx, dy = goal.x - pose.x, goal.y - pose.y
        dist = math.hypot(dx, dy)
        if dist > self.params.horizon_m:
            f = self.params.horizon_m / dist
            line = dm.atan2(dy, dx) + (math.pi if d < 0 else 0.0)  # the robot's heading along the line
            goal = Subgoal(pose.x + f * dx, pose.y + f * dy, float(wrap_angle(line)), goal.kind)
            stops, partial = False, True
        traj = plan_trajectory(pose, goal, self.params, direction=d, stops=stops, kappa0=kappa0)
        self.trajectory = dataclasses.replace(traj, partial=True) if partial else traj
        self._s = 0.0
        self._turning = self.trajectory.turn_to is not None

    def _advance(self, pose: Pose2D, v_mps: float) -> str:
        """Reached / skipped: move to the next subgoal (one per tick)."""
        assert self._goal is not None
        if self._reached(pose, self._goal, v_mps):
            event = "reached"
        elif (self.index < len(self.subgoals) - 1 and self._goal.kind != "stop"
              and is_passed(pose, self._goal, self.subgoals[self.index + 1], self.params.reach_m)):
            event = "skipped"
        else:
            return ""
        self.index += 1
        self._goal, self._replaced_xy, self.trajectory = None, None, None
        return event

    def _idle(self, event: str) -> FollowCommand:
        last = self.subgoals[-1] if self.subgoals else None
        xy = (math.nan, math.nan) if last is None else (last.x, last.y)
        self._last_v = self._last_w = 0.0
        return FollowCommand(0.0, 0.0, len(self.subgoals), True, event, xy, np.zeros((0, 2)), xy, "idle")

    def step(self, pose: Pose2D, grid: RobotCentredGrid, *, v_mps: float | None = None,
             w_radps: float | None = None, overridden: bool = False) -> FollowCommand:
        """The follower's command at ``pose`` (corrected frame) with the current model.

        ``v_mps``, ``w_radps``: the robot's current motion (odometry twist or the command executed last
        tick), for the at-rest test of stop subgoals and the start curvature of a new trajectory; None or
        nan: the follower's own previous command stands for them (right only while it is in control).
        ``overridden``: the command executed last tick was not the follower's (local navigation had taken
        over, or the reflexive loop replaced it). The trajectory is then planned anew from ``pose``: the
        paper's path follower, given control back, executes "a newly planned smooth trajectory" (Fig. 7)
        rather than steering back onto the old one, which runs through the obstacle local navigation was
        avoiding (turned back towards it, the follower's command is taken over again at the next tick)."""
        if self.done:
            return self._idle("")
        speed = v_mps if v_mps is not None and math.isfinite(v_mps) else self._last_v
        motion = (self._last_v, self._last_w)  # (v, w) for the start curvature: both measured, or neither
        if w_radps is not None and math.isfinite(w_radps) and v_mps is not None and math.isfinite(v_mps):
            motion = (v_mps, w_radps)
        events: list[str] = []
        if self._goal is None:
            self._goal = self.subgoals[self.index]
        event = self._advance(pose, speed)
        if event:
            events.append(event)
            if self.done:
                return self._idle(event)
            self._goal = self.subgoals[self.index]
        if self._replace(pose, grid):
            events.append("replaced")
            self.trajectory = None
        if self.trajectory is None:
            self._plan(pose, *motion)
        elif overridden:  # the paper's Fig. 6 and 7: a new trajectory from where the others left the robot
            self._plan(pose, *motion)
            events.append("replanned")
        traj = self.trajectory
        assert traj is not None and self._goal is not None
        p = np.array([pose.x, pose.y])
        s, dist, _ = _project(traj, p, self._s - 0.5, self._s + 2.0 + self.params.deviation_m)
        if self._replan_due(traj, p, s, dist):
            self._plan(pose, *motion)
            events.append("replanned")
            traj = self.trajectory
            assert traj is not None
            s, dist, _ = _project(traj, p, 0.0, 2.0 + self.params.deviation_m)
        self._s = s
        v, w, mode = self._control(pose, traj, s)
        self._last_v, self._last_w = v, w
        tx, ty, _, _ = _at(traj, min(s + self.params.lookahead_m, traj.s_goal))
        return FollowCommand(
            v_mps=v, w_radps=w, subgoal_index=self.index, done=False,
            event=events[0] if events else "", target_xy=(tx, ty),
            trajectory_xy=traj.xy[:traj.goal_end()], subgoal_xy=(self._goal.x, self._goal.y),
            mode=mode,
        )

    def _replan_due(self, traj: Trajectory, p: NDArray[np.float64], s: float, dist: float) -> bool:
        """Regenerate the trajectory: turning in place, when the robot is farther than ``deviation_m`` from
        the trajectory's start (pushed, or moved by local navigation: the turn's heading was computed at
        the old pose); otherwise farther than ``deviation_m`` from the trajectory, past its end, or, for a
        trajectory ending within the planning horizon, within ``lookahead_m`` of that end."""
        dev = self.params.deviation_m
        if self._turning:
            return math.hypot(p[0] - traj.xy[0, 0], p[1] - traj.xy[0, 1]) > dev
        if dist > dev or s >= float(traj.s[-1]) - 1e-9:
            return True
        return traj.partial and s >= traj.s_goal - min(self.params.lookahead_m, 0.5 * traj.s_goal)

    def local_target(self, grid: RobotCentredGrid) -> tuple[float, float]:
        """Where local navigation should steer when it takes over from path following (corrected frame):
        the first trajectory point beyond the look-ahead point that is free in the C-space of ``grid``
        (the look-ahead point itself may lie on the obstacle that blocks the path, where the footprint
        cannot go); none: the current subgoal (after replacement). Call after ``step``."""
        traj, goal = self.trajectory, self._goal
        if self.done or goal is None:
            last = self.subgoals[-1] if self.subgoals else Subgoal(math.nan, math.nan, 0.0)
            return last.x, last.y
        if traj is not None:
            xy = free_point_ahead(traj, self._s + self.params.lookahead_m, grid, inflate_m=self.inflate_m,
                                  unknown_is_free=self.unknown_is_free)
            if xy is not None:
                return xy
        return goal.x, goal.y

    def _control(self, pose: Pose2D, traj: Trajectory, s: float) -> tuple[float, float, str]:
        """(v, w, mode): turn in place, point stabilisation or trajectory tracking, in the driving frame."""
        assert self._goal is not None
        p, robot = self.params, self.robot
        flip = math.pi if traj.direction < 0 else 0.0
        th = float(wrap_angle(pose.theta + flip))
        if self._turning and traj.turn_to is not None:
            err = float(wrap_angle(traj.turn_to - th))
            if abs(err) > p.turn_tol_rad:
                return 0.0, float(np.clip(p.k_turn * err, -robot.wmax_radps, robot.wmax_radps)), "turn"
            self._turning = False
        g = self._goal
        e = math.hypot(g.x - pose.x, g.y - pose.y)
        a_brake = p.brake_frac * robot.accel_mps2
        if traj.stops and e <= max(p.stabilise_m, p.settle_m):
            if e <= min(p.settle_m, p.reach_m):
                err = float(wrap_angle(g.theta - pose.theta))
                return 0.0, float(np.clip(p.k_turn * err, -robot.wmax_radps, robot.wmax_radps)), "turn"
            v, w = aicardi_command((pose.x, pose.y, th), (g.x, g.y, float(wrap_angle(g.theta + flip))), p)
            cap = min(robot.vmax_mps, math.sqrt(2.0 * a_brake * e))
            if abs(v) > cap:
                w *= cap / abs(v)
                v = math.copysign(cap, v)
            v, w = _limit(v, w, robot)
            return traj.direction * v, w, "stabilise"
        ref = _at(traj, s)
        v_ref = robot.vmax_mps
        if abs(ref[3]) > 1e-9:
            v_ref = min(v_ref, robot.wmax_radps / abs(ref[3]))
        if traj.stops:
            v_ref = min(v_ref, math.sqrt(2.0 * a_brake * max(traj.s_goal - s, 0.0)))
        v_ref = max(v_ref, p.creep_frac * robot.vmax_mps)
        v, w = kanayama_command((pose.x, pose.y, th), ref, v_ref, p)
        if v < 0.0:
            # the reference lies behind the robot (heading error near or beyond 90 deg, pushed or turned
            # by another module): the law would drive against the subgoal's kind (a forward subgoal
            # backwards, into space the laser has not seen). Turn in place to the trajectory's heading
            err = float(wrap_angle(ref[2] - th))
            return 0.0, float(np.clip(p.k_turn * err, -robot.wmax_radps, robot.wmax_radps)), "turn"
        v, w = _limit(v, w, robot)
        return traj.direction * v, w, "track"
