"""ND+ reactor: sectors, robot shape, canonical scenes with known answers, sign conventions, edge cases.

Every canonical scene runs for the circular holonomic XR4000 and the rectangular differential wheelchair.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from gndreplay.errors import ConfigError
from gndreplay.pipeline.nd import (
    NdParams,
    NdResult,
    Situation,
    nd_step,
    robot_boundary_m,
    sector_angles,
    sector_of,
    security_boundary_m,
)
from gndreplay.robot import WHEELCHAIR_ROBOT, XR4000_ROBOT, RobotConfig
from gndreplay.types import Flag

F64 = NDArray[np.float64]
ROBOTS = [pytest.param(XR4000_ROBOT, id="xr4000"), pytest.param(WHEELCHAIR_ROBOT, id="wheelchair")]
N = 180
DELTA = 2.0 * math.pi / N
DS = NdParams().security_m


# ---------------------------------------------------------------------------------------------- scenes


def wall(p0: tuple[float, float], p1: tuple[float, float], step: float = 0.05) -> F64:
    """Points every ``step`` metres along the segment p0 -> p1 (both ends included)."""
    a, b = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    k = max(2, math.ceil(float(np.linalg.norm(b - a)) / step) + 1)
    return a + np.linspace(0.0, 1.0, k)[:, None] * (b - a)


def arc(radius: float, a0: float, a1: float, step: float = 0.05) -> F64:
    """Points every ~``step`` metres on the arc of ``radius`` from angle a0 to a1 [rad]."""
    k = max(2, math.ceil(radius * abs(a1 - a0) / step) + 1)
    a = np.linspace(a0, a1, k)
    return np.column_stack([radius * np.cos(a), radius * np.sin(a)])


def rotate(points: F64, phi: float) -> F64:
    c, s = math.cos(phi), math.sin(phi)
    return np.asarray(points, dtype=np.float64) @ np.array([[c, s], [-s, c]])


def half_width(robot: RobotConfig) -> float:
    return robot.radius_m if robot.shape == "circle" else 0.5 * robot.width_m


def gap_width(robot: RobotConfig) -> float:
    return 2.0 * half_width(robot)


def assert_finite_command(res: NdResult, robot: RobotConfig) -> None:
    assert all(math.isfinite(x) for x in (res.v_mps, res.vy_mps, res.w_radps))
    assert abs(res.w_radps) <= robot.wmax_radps + 1e-12
    assert math.hypot(res.v_mps, res.vy_mps) <= robot.vmax_mps + 1e-12
    if robot.drive == "differential":  # only the rectangle backs out of a turn it cannot make
        assert res.vy_mps == 0.0 and (res.v_mps >= 0.0 or robot.shape == "rectangle")


# ---------------------------------------------------------------------------------- sectors and shape


def test_sector_mapping_bisectors() -> None:
    ang = sector_angles(N)
    assert ang[0] == 0.0 and ang[N // 4] == math.pi / 2 and ang[N // 2] == math.pi
    assert ang[3 * N // 4] == -math.pi / 2
    assert np.all((ang > -math.pi) & (ang <= math.pi))
    np.testing.assert_array_equal(sector_of(ang, N), np.arange(N))
    assert sector_of(-math.pi, N) == N // 2 and sector_of(math.pi, N) == N // 2
    assert sector_of(np.nextafter(-math.pi, 0.0), N) == N // 2  # sector n/2 straddles the wrap
    assert sector_of(math.radians(1.5), N) == 1 and sector_of(math.radians(-1.5), N) == N - 1


def test_points_on_sector_boundaries_go_counter_clockwise() -> None:
    k = np.arange(-N // 2, N // 2)
    boundaries = (k + 0.5) * DELTA  # includes -pi + delta/2 ... pi - delta/2
    got = sector_of(boundaries, N)
    np.testing.assert_array_equal(got, np.mod(k + 1, N))
    np.testing.assert_array_equal(np.sort(got), np.arange(N))  # every sector exactly once
    assert sector_of(math.pi / 4, N) == 23 and sector_of(-math.pi / 4, N) == N - 22  # 45 deg is a boundary
    # A ring sampled exactly on the boundaries fills every sector: no fake gap, the robot is surrounded.
    ring = 1.5 * np.column_stack([np.cos(boundaries), np.sin(boundaries)])
    res = nd_step(ring, (3.0, 0.0), XR4000_ROBOT)
    assert res.flag == Flag.REACTOR_NO_REGION


def test_robot_boundary_circle_and_rectangle() -> None:
    ang = sector_angles(N)
    np.testing.assert_allclose(robot_boundary_m(XR4000_ROBOT, ang), 0.3)
    e = robot_boundary_m(WHEELCHAIR_ROBOT, np.array([0.0, math.pi, math.pi / 2, -math.pi / 2]))
    np.testing.assert_allclose(e, [0.8, 0.4, 0.35, 0.35])
    corner = math.atan2(0.35, 0.8)
    np.testing.assert_allclose(robot_boundary_m(WHEELCHAIR_ROBOT, [corner, -corner]), math.hypot(0.8, 0.35))
    rear_corner = math.atan2(0.35, -0.4)
    np.testing.assert_allclose(robot_boundary_m(WHEELCHAIR_ROBOT, [rear_corner]), math.hypot(0.4, 0.35))


def test_security_perimeter_tapers_from_front_to_back() -> None:
    a = np.linspace(-math.pi, math.pi, 20001)
    s = security_boundary_m(WHEELCHAIR_ROBOT, a, security_m=DS)
    e = robot_boundary_m(WHEELCHAIR_ROBOT, a)
    ds = s - e
    front_corner = math.hypot(0.8, 0.35)
    assert s[10000] == pytest.approx(front_corner + DS)  # angle 0: arc |front corner| + Ds
    assert ds[0] == pytest.approx(DS / 4) and ds[-1] == pytest.approx(DS / 4)  # behind: Ds/4
    assert ds.min() == pytest.approx(DS / 4)
    np.testing.assert_allclose(s, s[::-1])  # symmetric about the x axis
    assert np.abs(np.diff(s)).max() < 1e-3  # continuous across the five pieces
    # At the side the perimeter lies on the tangent between the Ds/4 and Ds corner circles.
    s_side = float(security_boundary_m(WHEELCHAIR_ROBOT, [math.pi / 2], security_m=DS)[0])
    assert 0.35 + DS / 4 < s_side < 0.35 + DS
    np.testing.assert_allclose(security_boundary_m(XR4000_ROBOT, a, security_m=DS), 0.3 + DS)


# ------------------------------------------------------------------------------------ canonical scenes


@pytest.mark.parametrize("robot", ROBOTS)
def test_free_space_goal_ahead_is_hsgr_full_speed(robot: RobotConfig) -> None:
    res = nd_step(np.zeros((0, 2)), (5.0, 0.0), robot)
    assert res.situation is Situation.HSGR and res.flag == Flag.NONE
    assert res.direction_rad == 0.0
    assert res.v_mps == pytest.approx(robot.vmax_mps) and res.w_radps == 0.0 and res.vy_mps == 0.0
    assert res.region == (0, N - 1) and res.min_clearance_m == math.inf


@pytest.mark.parametrize("robot", ROBOTS)
def test_goal_at_plus_90_turns_left_in_place(robot: RobotConfig) -> None:
    res = nd_step(np.zeros((0, 2)), (0.0, 3.0), robot)
    assert res.situation is Situation.HSGR
    assert res.direction_rad == pytest.approx(math.pi / 2)
    assert res.w_radps == pytest.approx(robot.wmax_radps)
    assert res.v_mps == pytest.approx(0.0, abs=1e-12)
    if robot.drive == "holonomic":
        assert res.vy_mps == pytest.approx(robot.vmax_mps)  # the base also slides left


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("angle", [0.0, math.pi / 4, math.pi / 2, -math.pi / 2, -math.pi / 4, math.pi])
def test_sign_conventions_goal_direction(robot: RobotConfig, angle: float) -> None:
    res = nd_step(np.zeros((0, 2)), (4.0 * math.cos(angle), 4.0 * math.sin(angle)), robot)
    assert math.cos(res.direction_rad - angle) == pytest.approx(1.0)
    clamped = min(max(angle, -math.pi / 2), math.pi / 2)
    assert res.w_radps == pytest.approx(robot.wmax_radps * clamped / (math.pi / 2), abs=1e-12)
    if robot.drive == "differential":
        assert res.v_mps == pytest.approx(robot.vmax_mps * (1.0 - abs(clamped) / (math.pi / 2)), abs=1e-12)
    else:
        assert res.v_mps == pytest.approx(robot.vmax_mps * math.cos(angle), abs=1e-12)
        assert res.vy_mps == pytest.approx(robot.vmax_mps * math.sin(angle), abs=1e-12)


@pytest.mark.parametrize("robot", ROBOTS)
def test_goal_exactly_behind(robot: RobotConfig) -> None:
    res = nd_step(np.zeros((0, 2)), (-3.0, 0.0), robot)
    assert res.situation is Situation.HSGR and res.direction_rad == math.pi
    assert nd_step(np.zeros((0, 2)), (-3.0, -0.0), robot).direction_rad == math.pi  # atan2 gives -pi
    assert res.w_radps == pytest.approx(robot.wmax_radps)  # pi is +pi: turn left
    if robot.drive == "differential":
        assert res.v_mps == 0.0  # turn in place
    else:
        assert res.v_mps == pytest.approx(-robot.vmax_mps) and res.vy_mps == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("robot", ROBOTS)
def test_close_wall_on_the_left_low_safety_turns_right_slower(robot: RobotConfig) -> None:
    y = half_width(robot) + 0.2  # 0.2 m clearance, inside the security distance
    res = nd_step(wall((-6.0, y), (6.0, y)), (5.0, 0.0), robot)
    assert res.situation is Situation.LSG  # dangerous obstacle on one side, goal in the region
    assert res.min_clearance_m == pytest.approx(0.2)
    assert -math.pi / 2 < res.direction_rad < 0.0
    assert res.w_radps < 0.0
    assert 0.0 < res.v_mps < robot.vmax_mps
    if robot.shape == "circle":  # r = 0.2 / 0.5 = 0.4, obstacle at +90 deg: theta = 0.6 * (-90 deg)
        assert res.direction_rad == pytest.approx(-0.6 * math.pi / 2)
        assert math.hypot(res.v_mps, res.vy_mps) == pytest.approx(0.4 * robot.vmax_mps)
    mirrored = nd_step(wall((-6.0, -y), (6.0, -y)), (5.0, 0.0), robot)
    assert mirrored.situation is Situation.LSG
    # mirror image up to sampling: the flat minimum of the clearance ratio may pick a neighbouring sector
    assert mirrored.direction_rad == pytest.approx(-res.direction_rad, abs=math.radians(8.0))
    assert mirrored.w_radps > 0.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_far_wall_is_high_safety(robot: RobotConfig) -> None:
    y = half_width(robot) + 0.8
    res = nd_step(wall((-6.0, y), (6.0, y)), (5.0, 0.0), robot)
    assert res.situation is Situation.HSGR and res.direction_rad == 0.0 and res.v_mps == robot.vmax_mps


@pytest.mark.parametrize("robot", ROBOTS)
def test_corridor_is_ls2_heading_to_the_centre_line(robot: RobotConfig) -> None:
    hw = half_width(robot)
    left, right = hw + 0.2, -(hw + 0.4)  # off-centre to the left: the centre line is on the right
    pts = np.vstack([wall((-6.0, left), (6.0, left)), wall((-6.0, right), (6.0, right))])
    res = nd_step(pts, (5.0, 0.0), robot)
    assert res.situation is Situation.LS2
    assert -math.pi / 2 < res.direction_rad < 0.0 and res.w_radps < 0.0
    assert 0.0 < res.v_mps < robot.vmax_mps
    first, last = res.region or (0, 0)
    assert first > last  # the corridor's free region ahead wraps through sector 0
    if robot.shape == "circle":  # c_l = 0.4, c_r = 0.8: theta = (0.4 - 0.8) / 1.2 * pi/2
        assert res.direction_rad == pytest.approx(-math.pi / 6)
        assert math.hypot(res.v_mps, res.vy_mps) == pytest.approx(0.4 * robot.vmax_mps)
    centred = nd_step(np.vstack([wall((-6.0, hw + 0.3), (6.0, hw + 0.3)),
                                 wall((-6.0, -hw - 0.3), (6.0, -hw - 0.3))]), (5.0, 0.0), robot)
    assert centred.situation is Situation.LS2
    assert centred.direction_rad == pytest.approx(0.0, abs=math.radians(2.0))


@pytest.mark.parametrize(
    ("phi", "expected"),
    [
        (0.0, -math.pi / 6),  # theta_p + (cl - cr)/(cl + cr) * (theta_p + pi/2), cl = 0.4, cr = 0.8
        (math.pi, math.pi - math.pi / 6),  # the same law in the frame turned by pi: the scene turned by pi
        (math.pi / 2, math.pi / 6),  # pi/2 - (1/3) * pi: the law's bounds are the robot's lateral directions
        (-math.pi / 2, -math.pi / 2),  # -pi/2 - (1/3) * 0: at the bound the law gives no deviation
    ],
)
def test_corridor_ls2_law_for_rotated_corridors(phi: float, expected: float) -> None:
    """Circle robot, corridor and goal turned by phi; the closer wall is always on the left of the motion."""
    pts = np.vstack([wall((-6.0, 0.5), (6.0, 0.5)), wall((-6.0, -0.7), (6.0, -0.7))])
    res = nd_step(rotate(pts, phi), (5.0 * math.cos(phi), 5.0 * math.sin(phi)), XR4000_ROBOT)
    assert res.situation is Situation.LS2
    assert math.cos(res.direction_rad - expected) == pytest.approx(1.0)
    assert math.sin(res.direction_rad - expected) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("robot", ROBOTS)
def test_corridor_goal_behind_steers_away_from_the_closer_wall(robot: RobotConfig) -> None:
    hw = half_width(robot)
    pts = np.vstack([wall((-6.0, hw + 0.15), (6.0, hw + 0.15)), wall((-6.0, -hw - 0.4), (6.0, -hw - 0.4))])
    res = nd_step(pts, (-5.0, 0.0), robot)
    assert res.situation is Situation.LS2
    assert -math.pi < res.direction_rad < -math.pi / 2  # backwards and to the right (away from the left wall)


def _wall_ahead_with_gap_on_left(robot: RobotConfig) -> tuple[F64, float]:
    """A wall at x = 3 m, one point per sector bisector from -50 to +18 deg; free beyond. Returns the
    points and the HSWR known answer: the corner (18 deg) plus atan2(W/2 + Ds, r_c)."""
    k = np.arange(-25, 10)
    a = k * DELTA
    pts = np.column_stack([np.full(k.size, 3.0), 3.0 * np.tan(a)])
    r_c = 3.0 / math.cos(a[-1])
    return pts, float(a[-1]) + math.atan2(0.5 * gap_width(robot) + DS, r_c)


@pytest.mark.parametrize("robot", ROBOTS)
def test_wall_ahead_with_gap_on_the_left_is_hswr_turning_left(robot: RobotConfig) -> None:
    pts, expected = _wall_ahead_with_gap_on_left(robot)
    res = nd_step(pts, (6.0, 0.0), robot)
    assert res.situation is Situation.HSWR
    assert res.direction_rad == pytest.approx(expected)
    assert res.w_radps > 0.0 and res.v_mps > 0.0
    assert res.region == (10, N - 26)  # from just left of the wall end, round the back, to its right end


@pytest.mark.parametrize("robot", ROBOTS)
def test_door_in_the_wall_on_the_left_is_hsnr_through_its_middle(robot: RobotConfig) -> None:
    """Wall at x = 3 m with a 2 m door from y = 1 to 3 m: the door is a narrow region (20..44 deg)."""
    res = nd_step(np.vstack([wall((3.0, -4.0), (3.0, 1.0)), wall((3.0, 3.0), (3.0, 4.0))]), (6.0, 0.0), robot)
    assert res.situation is Situation.HSNR and res.region == (10, 22)
    assert res.direction_rad == pytest.approx(16 * DELTA)  # bisector of sectors 10..22
    assert res.w_radps > 0.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_close_obstacle_on_the_right_while_passing_a_gap_is_ls1(robot: RobotConfig) -> None:
    pts, hswr = _wall_ahead_with_gap_on_left(robot)
    y = -(half_width(robot) + 0.25)
    res = nd_step(np.vstack([pts, wall((-0.3, y), (0.3, y))]), (6.0, 0.0), robot)
    assert res.situation is Situation.LS1
    assert hswr < res.direction_rad < math.pi / 2 + 0.1  # pushed further left, away from the obstacle


@pytest.mark.parametrize("robot", ROBOTS)
def test_symmetric_gaps_tie_goes_left(robot: RobotConfig) -> None:
    res = nd_step(wall((3.0, -1.0), (3.0, 1.0)), (6.0, 0.0), robot)
    assert res.situation is Situation.HSWR and res.direction_rad > 0.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_surrounded_is_no_region(robot: RobotConfig) -> None:
    res = nd_step(arc(1.5, -math.pi, math.pi), (3.0, 0.0), robot)
    assert res.situation is Situation.NONE and res.flag == Flag.REACTOR_NO_REGION
    assert math.isnan(res.direction_rad) and res.region is None
    assert (res.v_mps, res.vy_mps, res.w_radps) == (0.0, 0.0, 0.0)
    assert res.min_clearance_m > 0.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_surrounded_with_a_gap_narrower_than_the_robot_is_no_region(robot: RobotConfig) -> None:
    half_gap = 0.5 * 0.5 * gap_width(robot) / 1.5  # half the robot's width, seen from 1.5 m
    res = nd_step(arc(1.5, half_gap, 2.0 * math.pi - half_gap), (3.0, 0.0), robot)
    assert res.flag == Flag.REACTOR_NO_REGION


@pytest.mark.parametrize("robot", ROBOTS)
def test_surrounded_with_a_wide_gap_goes_through_it(robot: RobotConfig) -> None:
    res = nd_step(arc(1.5, 0.6, 2.0 * math.pi - 0.6), (3.0, 0.0), robot)
    assert res.situation is Situation.HSGR and res.direction_rad == pytest.approx(0.0, abs=1e-12)
    # the same gap behind, goal not in it: the region wraps round the back (through sector n/2)
    behind = nd_step(arc(1.5, -math.pi + 0.6, math.pi - 0.6), (0.0, 3.0), robot)
    assert behind.situation in (Situation.HSNR, Situation.HSWR)
    first, last = behind.region or (0, 0)
    assert first < N // 2 < last
    assert abs(behind.direction_rad) > math.pi / 2 and behind.w_radps > 0.0  # turns left, toward the back


def _niche(phi: float) -> F64:
    """Obstacles at 2 m all round, except a 40 deg niche centred on ``phi`` where they are at 4 m; one point
    per sector bisector (so the region is exactly sectors -9..9 about phi)."""
    ang = sector_angles(N)
    rel = np.mod(ang - phi + math.pi, 2.0 * math.pi) - math.pi
    r = np.where(np.abs(rel) < math.radians(19.0), 4.0, 2.0)
    return np.column_stack([r * np.cos(ang), r * np.sin(ang)])


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("phi", [0.0, math.pi / 2, -math.pi / 2, math.pi])
def test_narrow_region_bisector_sign_conventions(robot: RobotConfig, phi: float) -> None:
    goal_a = phi + 1.0  # goal behind the 2 m ring, outside the niche: steer into the niche
    res = nd_step(_niche(phi), (3.0 * math.cos(goal_a), 3.0 * math.sin(goal_a)), robot)
    assert res.situation is Situation.HSNR
    assert math.cos(res.direction_rad - phi) == pytest.approx(1.0)
    centre = int(sector_of(phi, N))
    assert res.region == ((centre - 9) % N, (centre + 9) % N)
    if phi == 0.0:
        assert res.region == (N - 9, 9)  # wraps through sector 0
        assert res.w_radps == 0.0 and res.v_mps == robot.vmax_mps
    elif phi == math.pi:
        assert res.region == (N // 2 - 9, N // 2 + 9)  # straddles the -pi/pi wrap behind
        assert res.direction_rad == math.pi and res.w_radps == pytest.approx(robot.wmax_radps)
    else:
        assert res.w_radps == pytest.approx(math.copysign(robot.wmax_radps, phi))


# ------------------------------------------------------------------------------------------ edge cases


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("empty", [np.zeros((0, 2)), [], np.zeros((0,))], ids=["0x2", "list", "flat"])
def test_empty_obstacle_array(robot: RobotConfig, empty: object) -> None:
    res = nd_step(empty, np.array([2.0, 0.0]), robot)  # type: ignore[arg-type]
    assert res.situation is Situation.HSGR and res.v_mps == robot.vmax_mps


@pytest.mark.parametrize("robot", ROBOTS)
def test_points_beyond_max_range_and_non_finite_rows_are_ignored(robot: RobotConfig) -> None:
    pts = np.vstack([arc(6.0, -math.pi, math.pi), [[np.nan, 1.0], [np.inf, 0.0]]])
    res = nd_step(pts, (8.0, 0.0), robot, NdParams(max_range_m=5.0))
    assert res.situation is Situation.HSGR and res.min_clearance_m == math.inf
    surrounded = nd_step(pts, (8.0, 0.0), robot, NdParams(max_range_m=7.0))
    assert surrounded.flag == Flag.REACTOR_NO_REGION


@pytest.mark.parametrize("robot", ROBOTS)
def test_obstacle_inside_the_footprint(robot: RobotConfig) -> None:
    res = nd_step(np.array([[0.1, 0.1]]), (3.0, 0.0), robot)
    assert res.min_clearance_m < 0.0
    assert res.situation in (Situation.LSG, Situation.LS1)
    assert_finite_command(res, robot)
    if robot.shape == "rectangle":  # no motion into it: slow, or backing off (any forward arc sweeps it)
        assert res.v_mps < 0.1 * robot.vmax_mps
    else:
        assert math.hypot(res.v_mps, res.vy_mps) < 0.1 * robot.vmax_mps


@pytest.mark.parametrize("robot", ROBOTS)
def test_goal_at_the_robot_centre(robot: RobotConfig) -> None:
    res = nd_step(np.zeros((0, 2)), (0.0, 0.0), robot)
    assert res.situation is Situation.HSGR and res.direction_rad == 0.0  # the supervisor owns GOAL_REACHED


@pytest.mark.parametrize("robot", ROBOTS)
def test_random_clutter_never_gives_nan_or_limits_violation(robot: RobotConfig) -> None:
    rng = np.random.default_rng(7)
    seen = set()
    for _ in range(150):
        centres = rng.uniform(-4.0, 4.0, (rng.integers(1, 12), 2))
        pts = np.vstack([c + rng.normal(0.0, 0.15, (40, 2)) for c in centres])
        goal = rng.uniform(-6.0, 6.0, 2)
        res = nd_step(pts, goal, robot)
        seen.add(res.situation)
        assert_finite_command(res, robot)
        if res.flag == Flag.REACTOR_NO_REGION:
            assert res.situation is Situation.NONE and res.region is None
        else:
            assert -math.pi < res.direction_rad <= math.pi and res.region is not None
    assert len(seen) >= 4


def test_invalid_inputs_raise_with_the_argument_name() -> None:
    with pytest.raises(ValueError, match=r"obstacles_xy must have shape \(M, 2\), got shape \(3, 3\)"):
        nd_step(np.zeros((3, 3)), (1.0, 0.0), XR4000_ROBOT)
    with pytest.raises(ValueError, match="goal_xy must be two finite numbers"):
        nd_step(np.zeros((0, 2)), (np.nan, 0.0), XR4000_ROBOT)
    with pytest.raises(ValueError, match="goal_xy must be two finite numbers"):
        nd_step(np.zeros((0, 2)), (1.0, 2.0, 3.0), XR4000_ROBOT)
    with pytest.raises(ConfigError, match="n_sectors must be a multiple of 4"):
        NdParams(n_sectors=90)
    with pytest.raises(ConfigError, match="security_m must be > 0"):
        NdParams(security_m=0.0)
    with pytest.raises(ConfigError, match=r"robot\.shape must be 'circle' or 'rectangle'"):
        nd_step(np.zeros((0, 2)), (1.0, 0.0), RobotConfig(shape="triangle"))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="differ by more than the robot length"):
        nd_step(np.zeros((0, 2)), (1.0, 0.0), WHEELCHAIR_ROBOT, NdParams(security_m=2.0))


def test_other_sector_counts() -> None:
    """144 sectors (the earlier ND code) give the same canonical answers."""
    p = NdParams(n_sectors=144)
    assert nd_step(np.zeros((0, 2)), (0.0, 2.0), WHEELCHAIR_ROBOT, p).w_radps == pytest.approx(0.5)
    pts = np.vstack([wall((-6.0, 0.5), (6.0, 0.5)), wall((-6.0, -0.7), (6.0, -0.7))])
    res = nd_step(pts, (5.0, 0.0), XR4000_ROBOT, p)
    assert res.situation is Situation.LS2 and res.direction_rad == pytest.approx(-math.pi / 6)

