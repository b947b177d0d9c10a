"""Simulated runs: a robot following a route in a :class:`World`, drifting odometry, and laser ticks.

Pipeline (each step a function, all randomness from one seed):

1. :func:`follow_route`: pure pursuit along polylines under differential-drive limits (stop and turn in
   place between polylines) -> ground-truth poses and the executed velocity commands at a fixed rate.
2. :func:`corrupt_odometry`: wheel odometry from the true increments, with systematic wheel-radius and
   wheel-base errors, per-wheel noise and a slowly varying heading-rate bias (slip).
3. :func:`iter_ticks` / :func:`iter_odometry`: laser scans ray-cast from the true laser pose, and odometry
   records, produced lazily.
4. :func:`simulate`: the above for a named scenario, written to a CARMEN log in one call.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import lfilter

from .. import detmath as dm
from ..errors import ConfigError, OutputError
from ..geometry import compose, wrap_angle
from ..robot import WHEELCHAIR_ROBOT, RobotConfig
from ..types import Command, Odometry, Pose2D, Scan, Tick
from .dynamics import step_toward
from .world import (
    LaserModel,
    MovingPolygon,
    SwingingDoor,
    World,
    box,
    quantize,
    regular_polygon,
    simulate_ranges,
    wall,
)

__all__ = [
    "DEFAULT_T0_NS",
    "MAX_SEED",
    "RECORD_STEP",
    "SAMPLE_LOG",
    "SCENARIOS",
    "DriveParams",
    "OdometryNoise",
    "Scenario",
    "SimulatedRun",
    "Trajectory",
    "carmen_params",
    "check_log_output",
    "check_seed",
    "corrupt_odometry",
    "follow_route",
    "is_own_carmen",
    "iter_odometry",
    "iter_ticks",
    "office_scenario",
    "office_world",
    "run_scenario",
    "sample_log",
    "simulate",
]

F64 = NDArray[np.float64]
NS_PER_S = 1_000_000_000
#: Default start of the log's clock (CARMEN ipc_timestamp of the first record), 2023-11-14T22:13:20Z.
DEFAULT_T0_NS = 1_700_000_000 * NS_PER_S
#: Output names :func:`simulate` accepts (before an optional .gz / .bz2).
CARMEN_SUFFIXES = (".clf", ".log", ".carmen")
#: Records carry poses [m, rad] and velocities rounded to this step, like a logger printing 6 decimals.
RECORD_STEP = 1e-6
#: Largest seed: numpy's SeedSequence takes any integer >= 0; one within int64 prints and stores everywhere.
MAX_SEED = 2**63 - 1


def check_seed(seed: int, where: str = "seed") -> int:
    """``seed`` when it is an integer from 0 to MAX_SEED; ``where`` names it in the error.

    Raises:
        ConfigError: a bool, a non-integer, a negative or a larger seed (one line).
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or not 0 <= seed <= MAX_SEED:
        from ..io.userfile import brief

        raise ConfigError(f"{where}: must be an integer from 0 to 2**63 - 1, got {brief(seed)}")
    return int(seed)


# --------------------------------------------------------------------------------------------- motion


@dataclass(frozen=True, slots=True)
class DriveParams:
    """Route follower: pure pursuit with velocity and acceleration limits of a differential drive.

    Attributes:
        vmax_mps, wmax_radps: velocity limits.
        accel_mps2, ang_accel_radps2: acceleration limits (commands are ramped, so they are smooth).
        lookahead_m: pure-pursuit look-ahead distance along the polyline.
        rotate_enter_rad: heading error to the look-ahead point above which the robot turns in place.
        rotate_exit_rad: heading error below which a turn in place ends.
        goal_tol_m: a polyline is done when less than this remains and the robot has stopped.
        pause_start_s, pause_end_s: time at rest before starting and after arriving.
        dt_s: control period = ground-truth rate.
        max_duration_s: safety stop for the simulation.
    """

    vmax_mps: float = 0.3
    wmax_radps: float = 0.5
    accel_mps2: float = 0.3
    ang_accel_radps2: float = 0.8
    lookahead_m: float = 0.6
    rotate_enter_rad: float = 0.9
    rotate_exit_rad: float = 0.03
    goal_tol_m: float = 0.02
    pause_start_s: float = 1.0
    pause_end_s: float = 1.0
    dt_s: float = 0.01
    max_duration_s: float = 600.0

    @staticmethod
    def for_robot(robot: RobotConfig, **overrides: float) -> DriveParams:
        """Limits from ``robot`` (vmax, wmax), other fields default unless overridden."""
        kw: dict[str, float] = {"vmax_mps": robot.vmax_mps, "wmax_radps": robot.wmax_radps}
        kw.update(overrides)
        return DriveParams(**kw)


@dataclass(frozen=True, slots=True, eq=False)
class Trajectory:
    """Ground truth at the control rate.

    Attributes:
        t_ns: ``(K,)`` int64 times since the start of the run [ns], step ``dt``.
        poses: ``(K, 3)`` robot (axle) poses in the world frame.
        cmd: ``(K, 2)`` executed commands (v [m/s], w [rad/s]) applied from ``t_ns[k]`` to ``t_ns[k + 1]``.
    """

    t_ns: NDArray[np.int64]
    poses: F64
    cmd: F64


def _polyline_lengths(path: F64) -> F64:
    """Cumulative arc length at each vertex of a ``(P, 2)`` polyline."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])


def _project(path: F64, cum: F64, xy: F64, s_prev: float) -> float:
    """Arc length of the point of ``path`` closest to ``xy``, not behind ``s_prev`` (monotone progress)."""
    a, b = path[:-1], path[1:]
    d = b - a
    ll = np.maximum((d * d).sum(axis=1), 1e-12)
    t = np.clip(((xy - a) * d).sum(axis=1) / ll, 0.0, 1.0)
    dist = np.hypot(*(a + t[:, None] * d - xy).T)
    s = cum[:-1] + t * np.sqrt(ll)
    dist = np.where(s >= s_prev - 1e-9, dist, np.inf)  # never jump backwards along the route
    k = int(np.argmin(dist))
    return max(float(s[k]), s_prev)


def _point_at(path: F64, cum: F64, s: float) -> F64:
    """The point at arc length ``s``; beyond the end, on the extension of the last segment."""
    total = float(cum[-1])
    if s > total:
        d = path[-1] - path[-2]
        return path[-1] + (s - total) * d / max(float(np.hypot(*d)), 1e-12)
    s = max(s, 0.0)
    return np.array([np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])])


def _integrate(pose: F64, v: float, w: float, dt: float) -> F64:
    """Exact unicycle motion with constant (v, w) for ``dt``."""
    x, y, th = pose
    if abs(w) < 1e-9:
        return np.array([x + v * dt * dm.cos(th), y + v * dt * dm.sin(th), th])
    th1 = th + w * dt
    r = v / w
    return np.array([x + r * (dm.sin(th1) - dm.sin(th)), y - r * (dm.cos(th1) - dm.cos(th)),
                     float(wrap_angle(th1))])


def follow_route(route: Sequence[ArrayLike], start: Pose2D, params: DriveParams) -> Trajectory:
    """Drive along each polyline of ``route`` in turn, stopping at its end.

    Inside a polyline the robot tracks it by pure pursuit (corners are rounded); at the start of each
    polyline, or whenever the heading error exceeds ``rotate_enter_rad``, it stops and turns in place.

    Args:
        route: polylines ``(P_i, 2)`` [m]; each should start where the previous one ended.
        start: initial robot pose (at rest).
        params: limits and gains.

    Returns:
        The ground-truth trajectory: ``pause_start_s`` at rest, the drive, ``pause_end_s`` at rest at the
        last vertex.

    Raises:
        ValueError: an empty route, a polyline with fewer than 2 vertices, or the route not finished within
            ``params.max_duration_s``.
    """
    paths = [np.asarray(p, dtype=np.float64) for p in route]
    if not paths or any(p.ndim != 2 or p.shape[0] < 2 or p.shape[1] != 2 for p in paths):
        raise ValueError("route must be a non-empty sequence of (P>=2, 2) polylines")
    dt = params.dt_s
    dv, dw = params.accel_mps2 * dt, params.ang_accel_radps2 * dt
    pose = start.as_array()
    v = w = 0.0
    poses, cmds = [pose], []
    for _ in range(round(params.pause_start_s / dt)):
        cmds.append((0.0, 0.0))
        poses.append(pose)
    max_steps = int(params.max_duration_s / dt)
    for path in paths:
        cum = _polyline_lengths(path)
        total = float(cum[-1])
        s = 0.0
        rotating = True
        while True:
            if len(cmds) >= max_steps:
                raise ValueError(f"route not finished within max_duration_s={params.max_duration_s}")
            s = _project(path, cum, pose[:2], s)
            remaining = total - s
            if remaining < params.goal_tol_m and abs(v) < 1e-6 and abs(w) < 1e-6:
                break
            target = _point_at(path, cum, s + params.lookahead_m)
            to_target = target - pose[:2]
            dist = float(np.hypot(*to_target))
            bearing = dm.atan2(to_target[1], to_target[0])
            alpha = float(wrap_angle(bearing - pose[2])) if dist > 1e-6 else 0.0
            if abs(alpha) > params.rotate_enter_rad:
                rotating = True
            elif rotating and abs(alpha) < params.rotate_exit_rad and abs(w) < dw:
                rotating = False
            if rotating:
                # turn in place, decelerating so as to stop on the target bearing
                v_des = 0.0
                w_des = math.copysign(min(params.wmax_radps,
                                          math.sqrt(2.0 * params.ang_accel_radps2 * abs(alpha))), alpha)
            else:
                kappa = 2.0 * dm.sin(alpha) / max(dist, 1e-6)
                v_des = min(params.vmax_mps, math.sqrt(2.0 * params.accel_mps2 * max(remaining, 0.0)))
                if abs(kappa) > 1e-9:
                    v_des = min(v_des, params.wmax_radps / abs(kappa))
                creep = min(0.02, params.vmax_mps)  # never stall short of the end
                v_des = max(v_des, creep) if remaining > params.goal_tol_m else 0.0
                w_des = v_des * kappa
            v = step_toward(v, v_des, dv)
            w = step_toward(w, w_des, dw)
            if abs(v) < 1e-9:
                v = 0.0
            if abs(w) < 1e-9:
                w = 0.0
            cmds.append((v, w))
            pose = _integrate(pose, v, w, dt)
            poses.append(pose)
    for _ in range(round(params.pause_end_s / dt)):
        cmds.append((0.0, 0.0))
        poses.append(pose)
    cmds.append((0.0, 0.0))
    k = len(poses)
    dt_ns = round(dt * NS_PER_S)
    return Trajectory(np.arange(k, dtype=np.int64) * dt_ns, np.array(poses), np.array(cmds))


# --------------------------------------------------------------------------------------------- odometry


@dataclass(frozen=True, slots=True)
class OdometryNoise:
    """Wheel odometry errors of a differential drive (UMBmark-style systematic errors plus noise).

    Attributes:
        wheelbase_m: distance between the driving wheels [m].
        left_scale, right_scale: relative wheel-radius errors (measured / true - 1).
        wheelbase_scale: relative error of the wheel base used by the odometry (scales rotations).
        wheel_sigma_m_per_sqrt_m: per-wheel travel noise, std = k * sqrt(|wheel travel|).
        slip_bias_sigma_radps: stationary std of the heading-rate bias (slip, uneven floor) [rad/s].
        slip_bias_tau_s: correlation time of that bias (first-order Gauss-Markov) [s].
    """

    wheelbase_m: float = 0.56
    left_scale: float = 0.003
    right_scale: float = 0.0015
    wheelbase_scale: float = 0.01
    wheel_sigma_m_per_sqrt_m: float = 0.002
    slip_bias_sigma_radps: float = 0.0015
    slip_bias_tau_s: float = 20.0


def corrupt_odometry(
    truth: ArrayLike, dt_s: float, noise: OdometryNoise, *, rng: np.random.Generator
) -> F64:
    """Wheel odometry for a true trajectory sampled every ``dt_s``.

    The true increment of each step (arc length ``ds``, rotation ``dth``) is split into wheel travels,
    corrupted, and recombined with the (wrong) wheel base; a Gauss-Markov heading-rate bias is added while
    the robot moves. The odometry frame starts at the first true pose.

    Args:
        truth: ``(K, 3)`` true poses.
        rng: draws exactly ``3 * (K - 1) + 1`` standard normals.

    Returns:
        ``(K, 3)`` odometry poses, ``odom[0] == truth[0]``.
    """
    p = np.asarray(truth, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 1:
        raise ValueError(f"truth must have shape (K>=1, 3), got {p.shape}")
    n = p.shape[0] - 1
    z = rng.standard_normal(3 * n + 1)
    if n == 0:
        return p.copy()
    dth = np.asarray(wrap_angle(np.diff(p[:, 2])))
    mid = p[:-1, 2] + dth / 2.0
    dxy = np.diff(p[:, :2], axis=0)
    ds = dxy[:, 0] * dm.cos_a(mid) + dxy[:, 1] * dm.sin_a(mid)
    b = noise.wheelbase_m
    dl, dr = ds - dth * b / 2.0, ds + dth * b / 2.0
    k = noise.wheel_sigma_m_per_sqrt_m
    dl_m = dl * (1.0 + noise.left_scale) + k * np.sqrt(np.abs(dl)) * z[:n]
    dr_m = dr * (1.0 + noise.right_scale) + k * np.sqrt(np.abs(dr)) * z[n:2 * n]
    # heading-rate bias: b_k = a b_{k-1} + c e_k, stationary std sigma
    a = dm.exp(-dt_s / noise.slip_bias_tau_s)
    c = noise.slip_bias_sigma_radps * math.sqrt(1.0 - a * a)
    b0 = noise.slip_bias_sigma_radps * z[2 * n]
    bias = lfilter([c], [1.0, -a], z[2 * n + 1:], zi=[a * b0])[0]
    moving = (np.abs(dl) + np.abs(dr)) > 1e-9
    ds_o = (dl_m + dr_m) / 2.0
    dth_o = (dr_m - dl_m) / (b * (1.0 + noise.wheelbase_scale)) + bias * dt_s * moving
    th = p[0, 2] + np.concatenate([[0.0], np.cumsum(dth_o)])
    mid_o = th[:-1] + dth_o / 2.0
    x = p[0, 0] + np.concatenate([[0.0], np.cumsum(ds_o * dm.cos_a(mid_o))])
    y = p[0, 1] + np.concatenate([[0.0], np.cumsum(ds_o * dm.sin_a(mid_o))])
    return np.column_stack([x, y, np.asarray(wrap_angle(th))])


# --------------------------------------------------------------------------------------------- scenarios


def _laser_pose(robot: RobotConfig) -> Pose2D:
    return Pose2D(robot.laser_x_m, robot.laser_y_m, robot.laser_theta_rad)


@dataclass(frozen=True, slots=True, eq=False)
class Scenario:
    """Everything needed to simulate a run, except the seed.

    Attributes:
        route: polylines the robot follows in turn, stopping (and turning in place) between them.
        sensor_pose: laser pose in the robot frame.
        scan_period_ns, odom_period_ns: sampling of the laser and of the odometry records (multiples of
            the control period ``drive.dt_s``).
    """

    name: str
    description: str
    world: World
    route: tuple[F64, ...]
    start: Pose2D
    robot: RobotConfig = WHEELCHAIR_ROBOT
    laser: LaserModel = field(default_factory=LaserModel)
    sensor_pose: Pose2D = field(default_factory=lambda: _laser_pose(WHEELCHAIR_ROBOT))
    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    drive: DriveParams = field(default_factory=DriveParams)
    scan_period_ns: int = 200_000_000
    odom_period_ns: int = 50_000_000


def office_world() -> World:
    """An office floor of 22 x 12 m: three rooms south of a 2.2 m corridor, two north of it.

    South rooms A (x 0-7), B (7-14), C (14-22), y 0-5; corridor y 5-7.2; north rooms D (x 0-11) and E
    (11-22), y 7.2-12. A and B connect through a narrow 0.9 m door; B, C, D and E open on the corridor
    through 1.0 m doors. Desks, cabinets, tables, a pillar and open door leaves furnish the rooms. A person
    walks down the corridor into room C, whose door then swings shut.
    """
    half_pi = math.pi / 2.0
    walls = [
        wall(0.0, 0.0, 22.0, 0.0),
        wall(22.0, 0.0, 22.0, 12.0),
        wall(22.0, 12.0, 0.0, 12.0),
        wall(0.0, 12.0, 0.0, 0.0),
        # corridor south wall, doors to A (x 3.0-4.0, closed: no gap), B (10.0-11.0), C (18.0-19.0)
        wall(0.0, 5.0, 22.0, 5.0, gaps=[(10.0, 11.0), (18.0, 19.0)]),
        # corridor north wall, doors to D (4.0-5.0) and E (16.0-17.0)
        wall(0.0, 7.2, 22.0, 7.2, gaps=[(4.0, 5.0), (16.0, 17.0)]),
        # A | B with the narrow door (y 2.05-2.95), B | C solid, D | E solid
        wall(7.0, 0.0, 7.0, 5.0, gaps=[(2.05, 2.95)]),
        wall(14.0, 0.0, 14.0, 5.0),
        wall(11.0, 7.2, 11.0, 12.0),
    ]
    furniture = [
        # room A: two desks on the north wall, a cabinet, a waste bin
        box(1.6, 4.6, 1.6, 0.8), box(4.2, 4.6, 1.6, 0.8), box(6.2, 0.3, 1.2, 0.5),
        regular_polygon(0.5, 0.5, 0.18, sides=8),
        # room B: table, shelves on the east wall, a pillar
        box(8.8, 0.8, 1.8, 0.9), box(13.75, 2.5, 0.4, 3.6), regular_polygon(12.6, 4.0, 0.25, sides=8),
        # room C: desks
        box(16.0, 1.0, 1.6, 0.8), box(20.5, 2.0, 0.8, 1.6),
        # room D: a row of desks
        box(2.0, 11.5, 1.6, 0.8), box(6.0, 11.5, 1.6, 0.8), box(9.5, 9.0, 0.8, 1.6),
        # room E: a meeting table, a cabinet, a plant
        box(18.5, 10.0, 2.0, 0.8), box(12.0, 11.6, 1.4, 0.5), regular_polygon(21.5, 7.7, 0.2, sides=6),
        # open door leaves (hinged on a jamb, standing into the room at 90 degrees)
        np.array([[7.0, 2.95, 7.85, 2.95]]),  # narrow door A|B, opens into B
        np.array([[10.0, 5.0, 10.0, 4.05]]),  # door to B, opens into B
        np.array([[16.0, 7.2, 15.525, 8.023]]),  # door to E, opened 120 degrees into E
        np.array([[4.0, 7.2, 4.0, 8.15]]),  # door to D, opens into D
    ]
    dynamic = (
        # a person walks west along the corridor and turns into room C
        MovingPolygon.person([(55.0, 21.5, 6.5), (57.6, 18.9, 6.3), (59.4, 18.5, 4.6), (61.8, 18.5, 2.2)]),
        # then the door of room C (hinge on its east jamb, open into C) swings shut
        SwingingDoor((19.0, 5.0), 0.95, -half_pi, -math.pi, t_start_s=62.0, t_end_s=64.0),
    )
    return World.from_parts(*walls, *furniture, dynamic=dynamic, name="office")


def office_scenario() -> Scenario:
    """The bundled sample: a wheelchair from room A through the narrow door into B, out to the corridor,
    east along it, into room E and half round its meeting table."""
    route = (
        np.array([[1.2, 2.5], [10.5, 2.5], [10.5, 6.1]]),
        np.array([[10.5, 6.1], [16.5, 6.1]]),
        np.array([[16.5, 6.1], [16.5, 8.8], [20.6, 8.8], [20.6, 11.2], [18.0, 11.2]]),
    )
    return Scenario(
        name="office",
        description=office_scenario.__doc__ or "",
        world=office_world(),
        route=route,
        start=Pose2D(1.2, 2.5, 0.0),
        drive=DriveParams.for_robot(WHEELCHAIR_ROBOT),
    )


SCENARIOS: Mapping[str, Callable[[], Scenario]] = {"office": office_scenario}


# --------------------------------------------------------------------------------------------- runs


@dataclass(frozen=True, slots=True, eq=False)
class SimulatedRun:
    """A scenario's motion and odometry for one seed (the laser is rendered lazily by :func:`iter_ticks`).

    Attributes:
        t_ns: ``(K,)`` int64 times since the start [ns] at the control rate.
        truth: ``(K, 3)`` true robot poses; ``odom``: ``(K, 3)`` odometry poses; ``cmd``: ``(K, 2)`` (v, w).
    """

    scenario: Scenario
    seed: int
    t_ns: NDArray[np.int64]
    truth: F64
    odom: F64
    cmd: F64

    def laser_rng(self) -> np.random.Generator:
        """A fresh generator for the laser noise (same seed -> same stream, independent of the odometry's)."""
        return np.random.default_rng(np.random.SeedSequence(self.seed).spawn(2)[1])


def run_scenario(scenario: Scenario, *, seed: int) -> SimulatedRun:
    """Motion and odometry of ``scenario``; ``seed`` (0 to MAX_SEED) fixes the odometry errors and the laser
    noise."""
    check_seed(seed)
    traj = follow_route(scenario.route, scenario.start, scenario.drive)
    odom_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[0])
    odom = corrupt_odometry(traj.poses, scenario.drive.dt_s, scenario.odometry_noise, rng=odom_rng)
    return SimulatedRun(scenario, seed, traj.t_ns, traj.poses, odom, traj.cmd)


def _every(run: SimulatedRun, period_ns: int) -> int:
    step = int(run.t_ns[1] - run.t_ns[0]) if len(run.t_ns) > 1 else period_ns
    if period_ns % step:
        raise ValueError(f"period {period_ns} ns is not a multiple of the control period {step} ns")
    return period_ns // step


def iter_ticks(run: SimulatedRun, *, t0_ns: int = DEFAULT_T0_NS) -> Iterator[Tick]:
    """Laser ticks every ``scan_period_ns``, ray-cast from the true laser pose, with odometry, command, truth.

    Times are ``t0_ns`` plus the time since the start; poses and commands are rounded to ``RECORD_STEP``.
    Deterministic: iterating twice gives the same ticks.
    """
    scn = run.scenario
    every = _every(run, scn.scan_period_ns)
    rng = run.laser_rng()
    angles = scn.laser.angles()
    sensor = scn.sensor_pose.as_array()
    truth = quantize(run.truth, RECORD_STEP)
    odom = quantize(run.odom, RECORD_STEP)
    cmd = quantize(run.cmd, RECORD_STEP)
    for index, k in enumerate(range(0, len(run.t_ns), every)):
        t_ns = t0_ns + int(run.t_ns[k])
        ranges = simulate_ranges(scn.world, compose(run.truth[k], sensor), run.t_ns[k] / NS_PER_S, scn.laser,
                                 rng=rng)
        scan = Scan(t_ns, ranges, angles, scn.laser.max_range_m, scn.laser.min_range_m, scn.sensor_pose)
        yield Tick(
            index=index,
            t_ns=t_ns,
            scan=scan,
            odom=Pose2D.from_array(odom[k]),
            cmd=Command(t_ns, float(cmd[k, 0]), float(cmd[k, 1])),
            truth=Pose2D.from_array(truth[k]),
        )


def iter_odometry(run: SimulatedRun, *, t0_ns: int = DEFAULT_T0_NS) -> Iterator[Odometry]:
    """Odometry records every ``odom_period_ns`` (rounded to ``RECORD_STEP``); the twist carries the
    commanded (v, w)."""
    every = _every(run, run.scenario.odom_period_ns)
    odom = quantize(run.odom[::every], RECORD_STEP)
    cmd = quantize(run.cmd[::every], RECORD_STEP)
    for t_ns, pose, (v, w) in zip(run.t_ns[::every], odom, cmd, strict=True):
        yield Odometry(t0_ns + int(t_ns), Pose2D.from_array(pose), float(v), float(w))


def carmen_params(scenario: Scenario, *, seed: int) -> dict[str, str]:
    """PARAM entries describing the robot and the run's provenance.

    ``write_carmen`` adds the laser mounting (``robot_frontlaser_offset`` ...) and range limits itself,
    from the ticks' scans.
    """
    robot = scenario.robot
    return {
        "robot_length": f"{robot.front_m + robot.rear_m:g}",
        "robot_width": f"{robot.width_m:g}",
        "robot_max_t_vel": f"{robot.vmax_mps:g}",
        "robot_max_r_vel": f"{robot.wmax_radps:g}",
        "gndreplay_scenario": scenario.name,
        "gndreplay_seed": str(seed),
    }


def is_own_carmen(path: Path) -> bool:
    """``path`` is a CARMEN log gndreplay wrote: its first line (decompressed by content) is the header
    ``write_carmen`` puts there."""
    import bz2
    import gzip

    from ..io.carmen import CARMEN_HEADER

    try:
        with open(path, "rb") as f:
            magic = f.read(3)
        opener: Any = bz2.open if magic == b"BZh" else gzip.open if magic[:2] == b"\x1f\x8b" else open
        with opener(path, "rb") as f:
            first = f.readline(len(CARMEN_HEADER) + 2)
    except (OSError, EOFError, ValueError):
        return False
    return first.rstrip(b"\r\n") == CARMEN_HEADER.encode()


def check_log_output(out: Path, *, overwrite: bool = False) -> None:
    """Refuse to write a simulated log over a folder, over any existing file without ``overwrite``, and
    over a file gndreplay did not write even with it.

    Raises:
        OutputError: one line naming ``out``.
    """
    out = Path(out)
    if out.is_dir():
        raise OutputError(f"{out}: is a folder; --out names the log file to write")
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise OutputError(f"{out}: already exists (--overwrite replaces a log gndreplay wrote)")
        if out.is_symlink() or not out.is_file() or not is_own_carmen(out):
            raise OutputError(f"{out}: exists and is not a CARMEN log written by gndreplay; not replacing it")


def simulate(scenario: str, *, seed: int, out: Path, t0_ns: int = DEFAULT_T0_NS,
             overwrite: bool = False) -> Path:
    """Simulate the named scenario and write it as a CARMEN log (``.bz2`` / ``.gz`` compress by suffix).

    Args:
        scenario: a key of :data:`SCENARIOS`.
        seed: fixes every random draw: the same seed gives a byte-identical log.
        out: the log to write.
        t0_ns: time of the first record [ns].
        overwrite: replace ``out`` if it is a CARMEN log gndreplay wrote (see :func:`check_log_output`).

    Returns:
        ``out``.

    Raises:
        ConfigError: unknown scenario, a seed out of range (:func:`check_seed`), or ``out`` not named like a
            CARMEN log (``.clf``/``.log``/``.carmen``, optionally ``.gz``/``.bz2``).
        OutputError: ``out`` is a folder, exists (without ``overwrite``) or is not gndreplay's.
    """
    if scenario not in SCENARIOS:
        from ..io.userfile import brief

        raise ConfigError(f"unknown scenario {brief(scenario)}; expected one of {sorted(SCENARIOS)}")
    check_seed(seed)
    out = Path(out)
    suffixes = [x.lower() for x in out.suffixes[-2:]]
    inner = suffixes[-2] if len(suffixes) == 2 and suffixes[-1] in (".gz", ".bz2") else (suffixes or [""])[-1]
    if inner not in CARMEN_SUFFIXES:
        raise ConfigError(f"{out}: simulated logs are written as CARMEN; name them "
                         f"{'/'.join(CARMEN_SUFFIXES)} (optionally + .gz/.bz2)")
    check_log_output(out, overwrite=overwrite)
    from ..io import write_carmen  # io is imported only when writing

    scn = SCENARIOS[scenario]()
    run = run_scenario(scn, seed=seed)
    write_carmen(out, iter_ticks(run, t0_ns=t0_ns), odometry=iter_odometry(run, t0_ns=t0_ns),
                 params=carmen_params(scn, seed=seed))
    return out


#: The bundled sample log of a source tree (``gndreplay simulate office --seed 0`` writes it).
SAMPLE_LOG = Path(__file__).resolve().parents[2] / "sample_logs" / "office.clf.bz2"


def sample_log() -> Path:
    """The bundled sample log; on an installation without the source tree beside it, the same log
    simulated (seed 0, byte-identical) into the user's cache once."""
    if SAMPLE_LOG.is_file():
        return SAMPLE_LOG
    cache = Path.home() / ".cache" / "gndreplay" / SAMPLE_LOG.name
    if not cache.is_file():
        cache.parent.mkdir(parents=True, exist_ok=True)
        simulate("office", seed=0, out=cache)
    return cache
