"""Local navigation strategies (pipeline/local.py): the polar map against analytic geometry, closed loops
with a kinematic integrator over synthetic walls (no simulator), and the speed law as a property."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gndreplay.errors import ConfigError
from gndreplay.pipeline.local import (
    _CLOSER_PER_M,
    LOCAL_STRATEGIES,
    LocalCommand,
    LocalParams,
    local_command,
    polar_map,
    travel_m,
    warm_up_local,
)
from gndreplay.pipeline.nd import sector_angles
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig

ROBOTS = [pytest.param(WHEELCHAIR_ROBOT, id="wheelchair"), pytest.param(XR4000_ROBOT, id="xr4000")]
Pose = tuple[float, float, float]


# --------------------------------------------------------------------------------------------------
# Helpers: synthetic worlds, exact footprint distance, a unicycle / holonomic integrator


def seg(a: tuple[float, float], b: tuple[float, float], step: float = 0.05) -> np.ndarray:
    """Points every ``step`` along a segment (occupied cell centres of a wall)."""
    pa, pb = np.asarray(a, float), np.asarray(b, float)
    n = max(math.ceil(float(np.linalg.norm(pb - pa)) / step), 1)
    return pa + np.linspace(0.0, 1.0, n + 1)[:, None] * (pb - pa)


def box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.vstack([seg((x0, y0), (x1, y0)), seg((x1, y0), (x1, y1)), seg((x1, y1), (x0, y1)),
                      seg((x0, y1), (x0, y0))])


def to_robot(pts: np.ndarray, pose: Pose) -> np.ndarray:
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    d = pts - np.array([x, y])
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))


def footprint_dist(pr: np.ndarray, robot: RobotConfig) -> np.ndarray:
    """Exact distance of each robot-frame point to the footprint (negative: inside)."""
    if robot.shape == "circle":
        d: np.ndarray = np.hypot(pr[:, 0], pr[:, 1]) - robot.radius_m
        return d
    hw = 0.5 * robot.width_m
    dx = np.maximum(np.maximum(-robot.rear_m - pr[:, 0], pr[:, 0] - robot.front_m), 0.0)
    dy = np.maximum(np.abs(pr[:, 1]) - hw, 0.0)
    out = np.hypot(dx, dy)
    inside = (dx == 0.0) & (dy == 0.0)
    depth = np.minimum(np.minimum(robot.front_m - pr[:, 0], pr[:, 0] + robot.rear_m), hw - np.abs(pr[:, 1]))
    return np.where(inside, -depth, out)


def integrate(pose: Pose, cmd: LocalCommand, dt: float, n: int = 10) -> Iterator[Pose]:
    """Poses along ``dt`` of the command (Euler in ``n`` sub-steps; robot-frame velocities)."""
    x, y, th = pose
    h = dt / n
    for _ in range(n):
        c, s = math.cos(th), math.sin(th)
        x += (cmd.v_mps * c - cmd.vy_mps * s) * h
        y += (cmd.v_mps * s + cmd.vy_mps * c) * h
        th += cmd.w_radps * h
        yield x, y, th


def drive(world: np.ndarray, pose: Pose, robot: RobotConfig, params: LocalParams,
          target: tuple[float, float] | None = None, steps: int = 300, dt: float = 0.2,
          until: Callable[[Pose], bool] | None = None) -> tuple[np.ndarray, float]:
    """Closed loop: map -> command -> motion; returns the poses and the smallest footprint clearance."""
    poses, min_clear, side = [pose], math.inf, 0
    for _ in range(steps):
        pm = polar_map(to_robot(world, pose), robot, params)
        tr = None if target is None else to_robot(np.array([target]), pose)[0]
        cmd = local_command(pm, tr, robot, params, side_hint=side)
        side = cmd.side
        for p in integrate(pose, cmd, dt):
            min_clear = min(min_clear, float(footprint_dist(to_robot(world, p), robot).min()))
            pose = p
        poses.append(pose)
        if until is not None and until(pose):
            break
    return np.array(poses), min_clear


def half_width(robot: RobotConfig) -> float:
    return robot.radius_m if robot.shape == "circle" else 0.5 * robot.width_m


# --------------------------------------------------------------------------------------------------
# The polar map


N = 180
DELTA = 2.0 * math.pi / N


def _ray_point(angle: float, *, x: float | None = None, y: float | None = None) -> list[float]:
    """The point at ``angle`` on the line x = const or y = const."""
    if x is not None:
        return [x, x * math.tan(angle)]
    assert y is not None
    return [y / math.tan(angle), y]


def test_polar_map_rectangle_front_side_and_rear_edges() -> None:
    """Free distance is measured from the rectangle's own edge along each ray: front 0.8, side 0.35,
    rear 0.4 m from the axle (wheelchair)."""
    r = WHEELCHAIR_ROBOT
    p = LocalParams(n_sectors=N)
    a10, a60 = 5 * DELTA, 30 * DELTA  # 10 and 60 deg bisectors
    pts = np.array([[2.0, 0.0], _ray_point(a10, x=2.0), [0.0, 1.5], _ray_point(a60, y=1.5), [-1.0, 0.0]])
    pm = polar_map(pts, r, p)
    assert pm.free_m[0] == pytest.approx(2.0 - r.front_m)
    assert pm.free_m[5] == pytest.approx((2.0 - r.front_m) / math.cos(a10))  # ray through the front edge
    assert pm.free_m[45] == pytest.approx(1.5 - 0.5 * r.width_m)
    assert pm.free_m[30] == pytest.approx((1.5 - 0.5 * r.width_m) / math.sin(a60))  # through the side edge
    assert pm.free_m[90] == pytest.approx(1.0 - r.rear_m)
    assert pm.range_m is not None
    assert pm.range_m[0] == pytest.approx(2.0) and pm.range_m[90] == pytest.approx(1.0)
    empty = np.ones(N, dtype=bool)
    empty[[0, 5, 30, 45, 90]] = False
    assert np.all(pm.free_m[empty] == p.max_range_m) and np.all(np.isinf(pm.range_m[empty]))
    assert np.array_equal(pm.occupied, ~empty)


def test_polar_map_circle() -> None:
    r = XR4000_ROBOT
    a30 = 15 * DELTA
    pm = polar_map(np.array([[2.0, 0.0], _ray_point(a30, x=2.0), [0.0, -1.2]]), r, LocalParams(n_sectors=N))
    assert pm.free_m[0] == pytest.approx(2.0 - r.radius_m)
    assert pm.free_m[15] == pytest.approx(2.0 / math.cos(a30) - r.radius_m)
    assert pm.free_m[135] == pytest.approx(1.2 - r.radius_m)


def test_polar_map_dense_wall_minimum_is_the_perpendicular() -> None:
    """A dense wall ahead: sector 0 holds the front edge's distance and every other sector is farther."""
    wall = seg((2.0, -3.0), (2.0, 3.0), step=0.001)
    for robot, edge in ((WHEELCHAIR_ROBOT, WHEELCHAIR_ROBOT.front_m), (XR4000_ROBOT, XR4000_ROBOT.radius_m)):
        pm = polar_map(wall, robot, LocalParams(n_sectors=N))
        assert pm.free_m[0] == pytest.approx(2.0 - edge, abs=1e-9)
        assert pm.free_m.min() == pm.free_m[0]
        assert not pm.occupied[N // 4] and not pm.occupied[N // 2]


def test_polar_map_wraps_around_behind_and_ignores_bad_rows() -> None:
    """Angles just either side of +-pi fall in the sector behind (n/2); its free distance is the nearer one.
    Non-finite rows and points beyond max_range_m are ignored; a point inside the footprint gives 0."""
    r = XR4000_ROBOT
    p = LocalParams(n_sectors=N, max_range_m=4.0)
    eps = 0.2 * DELTA
    pts = np.array([[2.0 * math.cos(math.pi - eps), 2.0 * math.sin(math.pi - eps)],
                    [1.5 * math.cos(-math.pi + eps), 1.5 * math.sin(-math.pi + eps)],
                    [1.0 * math.cos(-0.49 * DELTA), 1.0 * math.sin(-0.49 * DELTA)],
                    [np.nan, 1.0], [np.inf, 0.0], [4.5, 0.0], [0.1, 0.0]])
    pm = polar_map(pts, r, p)
    assert pm.angles_rad[N // 2] == pytest.approx(math.pi)
    assert pm.free_m[N // 2] == pytest.approx(1.5 - r.radius_m)
    assert pm.free_angle_rad is not None and pm.free_angle_rad[N // 2] == pytest.approx(-math.pi + eps)
    assert pm.free_m[0] == 0.0  # the point inside the footprint; the one at -0.49 sector is farther
    assert int(pm.occupied.sum()) == 2
    assert np.array_equal(pm.angles_rad, sector_angles(N))


def test_bad_inputs() -> None:
    r = WHEELCHAIR_ROBOT
    with pytest.raises(ValueError, match="obstacles_xy"):
        polar_map(np.zeros((3, 3)), r, LocalParams())
    pm = polar_map(np.zeros((0, 2)), r, LocalParams())
    with pytest.raises(ValueError, match=r"nd\.nd_step"):
        local_command(pm, None, r, LocalParams(strategy="nd"))
    with pytest.raises(ValueError, match="target_xy"):
        local_command(pm, np.array([np.nan, 1.0]), r, LocalParams(strategy="contour"))
    with pytest.raises(ConfigError, match=r"navigation\.local\.n_sectors"):
        LocalParams(n_sectors=4)
    with pytest.raises(ConfigError, match=r"navigation\.local\.approach_s"):
        LocalParams(approach_s=0.0)
    with pytest.raises(ConfigError, match=r"strategy: expected one of nd, "):
        LocalParams(strategy="bug2")


@pytest.mark.parametrize("robot", ROBOTS)
def test_empty_map_every_strategy_moves_at_full_speed(robot: RobotConfig) -> None:
    warm_up_local(robot)
    pm = polar_map(np.zeros((0, 2)), robot, LocalParams())
    for s in LOCAL_STRATEGIES[1:]:
        cmd = local_command(pm, None, robot, LocalParams(strategy=s))
        assert math.hypot(cmd.v_mps, cmd.vy_mps) == pytest.approx(robot.vmax_mps), s


def test_travel_of_the_footprint() -> None:
    """Travel along a direction is the sweep of the footprint over the sectors' arcs: never longer than the
    exact value (the chair's front edge is 1.2 m from a wall at x = 2, its side edge 1.15 m from a wall at
    y = 1.5) and short of it by about range x sector width x tan(incidence) at most (3 cm here); grown by
    0.1 m, 0.1 m less; turned to face +y first, the front edge (0.8 m) leads."""
    r = WHEELCHAIR_ROBOT
    pm = polar_map(np.vstack([seg((2.0, -3.0), (2.0, 3.0), 0.001), seg((-3.0, 1.5), (1.9, 1.5), 0.001)]), r,
                   LocalParams())
    t = travel_m(pm, [0.0, math.pi / 2, -math.pi / 2], r)
    assert 1.17 <= t[0] <= 1.2 and 1.12 <= t[1] <= 1.15 and np.isinf(t[2])
    assert 1.07 <= travel_m(pm, 0.0, r, margin_m=0.1)[0] <= 1.1
    assert 0.67 <= travel_m(pm, math.pi / 2, r, turn_first=True)[0] <= 0.7


def _grown_contains(q: np.ndarray, robot: RobotConfig, margin: float) -> np.ndarray:
    """Points (robot frame) inside the footprint grown by ``margin`` (square corners for the rectangle)."""
    if robot.shape == "circle":
        inside: np.ndarray = np.hypot(q[..., 0], q[..., 1]) <= robot.radius_m + margin
        return inside
    hw = 0.5 * robot.width_m + margin
    x = q[..., 0]
    return (x <= robot.front_m + margin) & (x >= -robot.rear_m - margin) & (np.abs(q[..., 1]) <= hw)


def _swept_travel(q: np.ndarray, robot: RobotConfig, margin: float, d: float, turn_first: bool,
                  step: float) -> float:
    """Brute force: the first translation (in ``step`` increments, up to 6 m) along ``d`` at which a point
    enters the grown footprint; a point already inside blocks (0) if it is inside the real footprint or
    the first step brings it closer (by more than the kernel's tolerance), else it is skipped; inf when none
    does."""
    c, s = math.cos(d), math.sin(d)
    if turn_first:  # the footprint faces d, then drives straight ahead
        q = np.column_stack((q[:, 0] * c + q[:, 1] * s, q[:, 1] * c - q[:, 0] * s))
        c, s = 1.0, 0.0
    ts = np.arange(0.0, 6.0, step)
    moved = q[None, :, :] - ts[:, None, None] * np.array([c, s])  # (steps, M, 2)
    inside = _grown_contains(moved, robot, margin)
    dist = footprint_dist(moved.reshape(-1, 2), robot).reshape(moved.shape[:2])
    start = inside[0]
    blocks_now = start & ((dist[0] <= 0.0) | (dist[1] < dist[0] - _CLOSER_PER_M * step))
    if blocks_now.any():
        return 0.0
    later = inside[:, ~start]
    if not later.any():
        return math.inf
    return float(ts[int(np.argmax(later.any(axis=1)))])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(robot=st.sampled_from([WHEELCHAIR_ROBOT, XR4000_ROBOT]),
       pts=st.lists(st.tuples(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5)), min_size=1, max_size=12),
       d=st.floats(-math.pi, math.pi), margin=st.sampled_from([0.0, 0.1]), turn_first=st.booleans())
def test_travel_is_the_first_contact_of_the_swept_footprint(
        robot: RobotConfig, pts: list[tuple[float, float]], d: float, margin: float, turn_first: bool,
) -> None:
    """``travel_m`` (the compiled sweep over the sectors' arcs) against a brute-force sweep of the grown
    footprint over the same arc samples in 1 mm steps: equal to within a step, inf exactly when nothing is
    ever met; the whole direction fan at once gives what one direction at a time gives."""
    from gndreplay.pipeline.local import _arcs

    pm = polar_map(np.array(pts), robot, LocalParams())
    px, py = _arcs(pm, robot)
    step = 1e-3
    brute = _swept_travel(np.column_stack((px, py)), robot, margin, d, turn_first, step)
    got = float(travel_m(pm, d, robot, margin_m=margin, turn_first=turn_first)[0])
    if math.isinf(brute):
        assert math.isinf(got) or got > 6.0 - step
    else:
        assert got <= brute + 1e-9 and got >= brute - step - 1e-9
    fan = np.array([d, d + 1.0, d - 2.0])
    assert np.array_equal(travel_m(pm, fan, robot, margin_m=margin, turn_first=turn_first),
                          np.concatenate([travel_m(pm, x, robot, margin_m=margin, turn_first=turn_first)
                                          for x in fan]))


# --------------------------------------------------------------------------------------------------
# Closed loops (kinematic integrator over synthetic walls)


@pytest.mark.parametrize("robot", ROBOTS)
def test_wall_left_keeps_its_distance_in_a_corridor(robot: RobotConfig) -> None:
    """A 2 m corridor, starting in its middle: the left wall is held at wall_distance_m (+-5 cm once
    settled, from x = 3 m to 10 m) and never touched."""
    p = LocalParams(strategy="wall-left")
    world = np.vstack([seg((-2.0, 1.0), (14.0, 1.0)), seg((-2.0, -1.0), (14.0, -1.0))])
    poses, min_clear = drive(world, (0.0, 0.0, 0.0), robot, p, until=lambda q: q[0] > 10.5)
    assert poses[-1, 0] > 10.5
    gap = 1.0 - poses[:, 1] - half_width(robot)
    settled = (poses[:, 0] >= 3.0) & (poses[:, 0] <= 10.0)
    assert np.all(np.abs(gap[settled] - p.wall_distance_m) < 0.05), gap[settled]
    assert min_clear > p.safety_m


@pytest.mark.parametrize("robot", ROBOTS)
def test_wall_right_turns_round_a_convex_corner(robot: RobotConfig) -> None:
    """A block (x <= 4, y <= -1) on the right: the follower turns right round its corner and goes on down
    its other face at the set distance."""
    p = LocalParams(strategy="wall-right")
    world = np.vstack([seg((-3.0, -1.0), (4.0, -1.0)), seg((4.0, -1.0), (4.0, -8.0))])
    poses, min_clear = drive(world, (0.0, -0.1, 0.0), robot, p, until=lambda q: q[1] < -5.0)
    x, y, th = poses[-1]
    assert y < -5.0
    assert math.remainder(th + math.pi / 2, 2 * math.pi) == pytest.approx(0.0, abs=0.1)
    assert x - 4.0 - half_width(robot) == pytest.approx(p.wall_distance_m, abs=0.05)
    assert min_clear > p.safety_m


@pytest.mark.parametrize("robot", ROBOTS)
def test_wall_right_turns_away_at_a_concave_corner(robot: RobotConfig) -> None:
    """The corridor ends in a wall (x = 4): the right follower turns left and follows it."""
    p = LocalParams(strategy="wall-right")
    world = np.vstack([seg((-3.0, -1.0), (4.0, -1.0)), seg((4.0, -1.0), (4.0, 8.0))])
    poses, min_clear = drive(world, (0.0, -0.1, 0.0), robot, p, until=lambda q: q[1] > 5.0)
    x, y, th = poses[-1]
    assert y > 5.0
    assert math.remainder(th - math.pi / 2, 2 * math.pi) == pytest.approx(0.0, abs=0.1)
    assert 4.0 - x - half_width(robot) == pytest.approx(p.wall_distance_m, abs=0.05)
    assert min_clear > p.safety_m


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("side", ["left", "right"])
def test_contour_goes_round_a_box_to_the_target_behind_it(robot: RobotConfig, side: str) -> None:
    """A 1 x 1 m box straight between the robot and its target: both ways round are equally short, so
    the configured side decides (obstacle on the left: round it anticlockwise, y < 0); the robot reaches the
    target without touching the box."""
    p = LocalParams(strategy="contour", contour_side=side)  # type: ignore[arg-type]
    target = (5.5, 0.0)
    poses, min_clear = drive(box(2.0, -0.5, 3.0, 0.5), (0.0, 0.0, 0.0), robot, p, target=target,
                             until=lambda q: math.hypot(q[0] - target[0], q[1] - target[1]) < 0.2)
    assert math.hypot(poses[-1, 0] - target[0], poses[-1, 1] - target[1]) < 0.2
    beside = (poses[:, 0] > 2.0) & (poses[:, 0] < 3.0)
    assert beside.any()
    sign = -1.0 if side == "left" else 1.0
    assert np.all(sign * poses[beside, 1] > 0.5 + half_width(robot))
    assert min_clear > p.safety_m


@pytest.mark.parametrize("robot", ROBOTS)
def test_contour_takes_the_side_nearer_the_target(robot: RobotConfig) -> None:
    """Target behind the box and to its left: the robot goes round the left (y > 0) whatever contour_side."""
    p = LocalParams(strategy="contour", contour_side="left")
    target = (5.5, 1.5)
    poses, min_clear = drive(box(2.0, -0.5, 3.0, 0.5), (0.0, -0.2, 0.0), robot, p, target=target,
                             until=lambda q: math.hypot(q[0] - target[0], q[1] - target[1]) < 0.2)
    assert math.hypot(poses[-1, 0] - target[0], poses[-1, 1] - target[1]) < 0.2
    beside = (poses[:, 0] > 2.0) & (poses[:, 0] < 3.0)
    assert beside.any() and np.all(poses[beside, 1] > 0.5)
    assert min_clear > p.safety_m


@pytest.mark.parametrize("robot", ROBOTS)
def test_contour_without_target_circles_the_nearest_obstacle(robot: RobotConfig) -> None:
    """No target: the robot goes round a 3 x 2 m box with it on the configured side (right: clockwise),
    keeps going round, and stays at about contour_distance_m from it (median over the orbit within 0.1 m;
    the chair swings wider at the corners)."""
    p = LocalParams(strategy="contour", contour_side="right")
    b = box(2.0, -1.0, 5.0, 1.0)
    poses, min_clear = drive(b, (0.0, 0.0, 0.0), robot, p, steps=250)
    turned = np.unwrap(np.arctan2(poses[:, 1], poses[:, 0] - 3.5))
    assert turned[-1] - turned[0] < -1.2 * math.pi  # clockwise, more than half a turn
    gaps = np.array([footprint_dist(to_robot(b, tuple(q)), robot).min() for q in poses[50:]])
    assert np.median(gaps) == pytest.approx(p.contour_distance_m, abs=0.1)
    assert min_clear > p.safety_m


def _room(door_lo: float, door_hi: float) -> np.ndarray:
    """A 4 x 4 m room (x, y in [-2, 2]) with a door in its wall x = 2 between door_lo and door_hi."""
    return np.vstack([seg((-2, -2), (2, -2)), seg((2, -2), (2, door_lo)), seg((2, door_hi), (2, 2)),
                      seg((2, 2), (-2, 2)), seg((-2, 2), (-2, -2))])


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("start", [(-0.5, -0.5, math.pi / 2), (0.0, 0.0, math.pi), (-1.0, 1.0, -math.pi / 2),
                                   (1.0, -1.2, 0.0)])
def test_free_space_leaves_a_room_through_its_door(robot: RobotConfig, start: Pose) -> None:
    """Without a target, following the free space takes the robot out through a 1.2 m door (the chair is
    0.7 m wide) from any start, without touching."""
    p = LocalParams(strategy="free-space")
    poses, min_clear = drive(_room(-0.2, 1.0), start, robot, p, until=lambda q: q[0] > 3.0)
    assert poses[-1, 0] > 3.0
    assert min_clear > 0.0


def test_free_space_turns_round_in_a_dead_end() -> None:
    """Walls ahead and on both sides, open behind (the cluster straddles the -pi/pi wrap): the chair turns
    in place towards pi."""
    r = WHEELCHAIR_ROBOT
    world = np.vstack([seg((1.3, -0.8), (1.3, 0.8)), seg((-3.0, 0.8), (1.3, 0.8)),
                       seg((-3.0, -0.8), (1.3, -0.8))])
    cmd = local_command(polar_map(world, r, LocalParams()), None, r, LocalParams(strategy="free-space"))
    assert abs(cmd.direction_rad) > 0.9 * math.pi
    assert cmd.v_mps == 0.0 and abs(cmd.w_radps) > 0.0


# --------------------------------------------------------------------------------------------------
# The speed law as a property


def _dist_along(pr: np.ndarray, robot: RobotConfig, dx: float, dy: float, length: float) -> np.ndarray:
    """(steps, M) footprint distance of each point while the footprint translates ``length`` along
    (dx, dy), in 2 mm steps."""
    ts = np.linspace(0.0, length, max(2, math.ceil(length / 0.002) + 1))
    return np.array([footprint_dist(pr - t * np.array([dx, dy]), robot) for t in ts])


@st.composite
def scenes(draw: st.DrawFn) -> tuple[RobotConfig, LocalParams, np.ndarray, np.ndarray | None]:
    robot = draw(st.sampled_from([WHEELCHAIR_ROBOT, XR4000_ROBOT]))
    strategy = draw(st.sampled_from(LOCAL_STRATEGIES[1:]))
    coord = st.floats(-3.0, 3.0, allow_nan=False)
    walls = draw(st.lists(st.tuples(coord, coord, coord, coord), max_size=4))
    loose = draw(st.lists(st.tuples(coord, coord), max_size=30))
    parts = [seg((a, b), (c, d)) for a, b, c, d in walls] + [np.array(loose, float).reshape(-1, 2)]
    pts = np.vstack(parts)
    target = draw(st.one_of(st.none(), st.tuples(coord, coord)))
    params = LocalParams(strategy=strategy)
    return robot, params, pts, None if target is None else np.array(target)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
def test_no_strategy_commands_motion_into_an_obstacle(scene: tuple[RobotConfig, LocalParams, np.ndarray,
                                                                   np.ndarray | None]) -> None:
    """For random walls and points (robot frame) and every strategy:

    * translating at the command's speed for approach_s brings no point closer than safety_m to the
      footprint, unless it was already closer (then it gets no closer);
    * a rectangle turning at the command's rate for approach_s sweeps over no point;
    * one 0.2 s tick of the full command, starting at least safety_m from every point, touches nothing.
    """
    robot, p, pts, target = scene
    cmd = local_command(polar_map(pts, robot, p), target, robot, p)
    assert all(math.isfinite(x) for x in (cmd.v_mps, cmd.vy_mps, cmd.w_radps))
    speed = math.hypot(cmd.v_mps, cmd.vy_mps)
    assert speed <= robot.vmax_mps + 1e-9 and abs(cmd.w_radps) <= robot.wmax_radps + 1e-9
    if robot.drive == "differential":
        assert cmd.vy_mps == 0.0 and cmd.v_mps >= 0.0
    near = pts[np.hypot(pts[:, 0], pts[:, 1]) <= 3.0]
    if near.size == 0:
        return
    d0 = footprint_dist(near, robot)
    if speed > 0.0:
        along = _dist_along(near, robot, cmd.v_mps / speed, cmd.vy_mps / speed, speed * p.approach_s)
        assert np.all(along >= np.minimum(d0, p.safety_m) - 1e-3)
    if robot.shape == "rectangle" and cmd.w_radps != 0.0:
        for phi in np.linspace(0.0, cmd.w_radps * p.approach_s, 200):
            c, s = math.cos(phi), math.sin(phi)
            turned = np.column_stack((c * near[:, 0] + s * near[:, 1], -s * near[:, 0] + c * near[:, 1]))
            assert np.all((footprint_dist(turned, robot) > 0.0) | (d0 <= 0.0))
    if d0.min() >= p.safety_m:
        for q in integrate((0.0, 0.0, 0.0), cmd, 0.2, n=20):
            assert footprint_dist(to_robot(near, q), robot).min() > 0.0
