"""Simulated worlds, laser, route following, odometry drift, the office scenario and its CARMEN log."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gndreplay.errors import ConfigError, OutputError
from gndreplay.geometry import compose, relative, wrap_angle
from gndreplay.io import read_ticks
from gndreplay.io.canonical import canonical_bearings, canonical_pose, canonical_stamp
from gndreplay.robot import WHEELCHAIR_ROBOT, RobotConfig
from gndreplay.sim.geometry import Shapes, footprint_clearance, footprint_vertices
from gndreplay.sim.scenario import (
    SCENARIOS,
    DriveParams,
    OdometryNoise,
    SimulatedRun,
    corrupt_odometry,
    follow_route,
    iter_odometry,
    iter_ticks,
    office_scenario,
    run_scenario,
    simulate,
)
from gndreplay.sim.world import (
    LaserModel,
    MovingPolygon,
    SwingingDoor,
    World,
    box,
    cast_rays,
    polygon,
    quantize,
    regular_polygon,
    simulate_ranges,
    wall,
)
from gndreplay.types import Pose2D

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"


@pytest.fixture(scope="module")
def office_run() -> SimulatedRun:
    return run_scenario(office_scenario(), seed=0)


# --------------------------------------------------------------------------------------------- ray casting


def test_perpendicular_wall_at_known_distance() -> None:
    wall_x3 = np.array([[3.0, -5.0, 3.0, 5.0]])
    r = cast_rays([0.0, 0.0], np.array([0.0]), wall_x3, max_range_m=30.0)
    assert r[0] == pytest.approx(3.0, abs=1e-12)


@pytest.mark.parametrize("angle_deg", [-60.0, -30.0, 10.0, 45.0, 70.0])
def test_oblique_hits_follow_the_cosine_law(angle_deg: float) -> None:
    wall_x2 = np.array([[2.0, -10.0, 2.0, 10.0]])
    a = math.radians(angle_deg)
    r = cast_rays([0.0, 0.0], np.array([a]), wall_x2, max_range_m=30.0)
    assert r[0] == pytest.approx(2.0 / math.cos(a), rel=1e-12)


def test_corner_of_a_room_and_the_nearest_segment_wins() -> None:
    room = box(0.0, 0.0, 4.0, 2.0)  # x in [-2, 2], y in [-1, 1]
    corner = math.atan2(1.0, 2.0)
    beams = np.array([corner, 0.0, math.pi / 2, math.pi, -math.pi / 2])
    r = cast_rays([0.0, 0.0], beams, room, max_range_m=30.0)
    np.testing.assert_allclose(r, [math.hypot(2.0, 1.0), 2.0, 1.0, 2.0, 1.0], atol=1e-12)
    # a box in front of the wall hides it
    both = np.vstack([room, box(1.0, 0.0, 0.2, 0.2)])
    assert cast_rays([0.0, 0.0], np.array([0.0]), both, max_range_m=30.0)[0] == pytest.approx(0.9)


def test_max_range_behind_parallel_and_empty_give_no_return() -> None:
    wall_x3 = np.array([[3.0, -5.0, 3.0, 5.0]])
    assert np.isinf(cast_rays([0.0, 0.0], np.array([0.0]), wall_x3, max_range_m=3.0)[0])  # at max: none
    assert cast_rays([0.0, 0.0], np.array([0.0]), wall_x3, max_range_m=3.0001)[0] == pytest.approx(3.0)
    assert np.isinf(cast_rays([0.0, 0.0], np.array([math.pi]), wall_x3, max_range_m=30.0)[0])  # behind
    along = np.array([[1.0, 0.0, 5.0, 0.0]])
    assert np.isinf(cast_rays([0.0, 0.0], np.array([0.0]), along, max_range_m=30.0)[0])  # parallel
    assert np.isinf(cast_rays([0.0, 0.0], np.zeros(3), np.zeros((0, 4)), max_range_m=30.0)).all()


def test_door_gap_lets_rays_through() -> None:
    w = World.from_parts(wall(2.0, -3.0, 2.0, 3.0, gaps=[(2.55, 3.45)]), wall(6.0, -3.0, 6.0, 3.0))
    r = cast_rays([0.0, 0.0], np.array([0.0, math.atan2(1.0, 2.0)]), w.segments, max_range_m=30.0)
    np.testing.assert_allclose(r, [6.0, math.hypot(2.0, 1.0)])


def test_cast_rays_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match=r"segments must have shape \(M, 4\)"):
        cast_rays([0.0, 0.0], np.zeros(2), np.zeros((3, 3)), max_range_m=1.0)
    with pytest.raises(ValueError, match="origin_xy must have shape"):
        cast_rays([0.0, 0.0, 0.0], np.zeros(2), np.zeros((1, 4)), max_range_m=1.0)
    with pytest.raises(ValueError, match="max_range_m must be > 0"):
        cast_rays([0.0, 0.0], np.zeros(2), np.zeros((1, 4)), max_range_m=0.0)
    with pytest.raises(ValueError, match="inside the wall"):
        wall(0.0, 0.0, 1.0, 0.0, gaps=[(0.5, 2.0)])


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: polygon([[0.0, 0.0]]), r"vertices_xy must have shape \(K>=2, 2\)"),
        (lambda: regular_polygon(0.0, 0.0, 1.0, sides=2), "sides must be >= 3"),
        (lambda: World(np.zeros((2, 3))), r"segments must have shape \(M, 4\)"),
        (lambda: LaserModel(n_beams=1), "n_beams must be >= 2"),
        (lambda: LaserModel(dropout_prob=1.0), r"dropout_prob must be in \[0, 1\)"),
        (lambda: LaserModel(range_sigma_m=-0.1), "range_sigma_m must be >= 0"),
        (lambda: corrupt_odometry(np.zeros((3, 2)), 0.01, OdometryNoise(), rng=np.random.default_rng(0)),
         r"truth must have shape \(K>=1, 3\)"),
    ],
)
def test_invalid_arguments_are_named(make: Callable[[], object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()


def test_quantize_gives_short_decimals() -> None:
    x = np.random.default_rng(3).random(1000) * 8.0
    q = quantize(x, 0.001)
    assert np.abs(q - x).max() <= 0.0005 + 1e-12
    assert all(len(repr(float(v))) <= 5 for v in q)
    np.testing.assert_array_equal(quantize(x, 0.0), x)


def test_laser_scan_from_an_offset_pose_in_a_square_room() -> None:
    room = World.from_parts(box(0.0, 0.0, 10.0, 10.0))
    laser = LaserModel(n_beams=181, max_range_m=30.0)
    r = simulate_ranges(room, [1.0, 2.0, math.pi / 2], 0.0, laser)  # facing +y
    np.testing.assert_allclose(laser.angles()[[0, 90, -1]], [-math.pi / 2, 0.0, math.pi / 2], atol=1e-15)
    assert r[90] == pytest.approx(3.0)  # ahead: wall y = 5
    assert r[0] == pytest.approx(4.0)  # right: wall x = 5
    assert r[-1] == pytest.approx(6.0)  # left: wall x = -5


def test_noise_dropouts_and_determinism() -> None:
    room = World.from_parts(box(0.0, 0.0, 6.0, 6.0))
    laser = LaserModel(n_beams=361, max_range_m=30.0, range_sigma_m=0.01, dropout_prob=0.05)
    exact = simulate_ranges(room, [0.0, 0.0, 0.0], 0.0, laser)
    a = simulate_ranges(room, [0.0, 0.0, 0.0], 0.0, laser, rng=np.random.default_rng(7))
    b = simulate_ranges(room, [0.0, 0.0, 0.0], 0.0, laser, rng=np.random.default_rng(7))
    c = simulate_ranges(room, [0.0, 0.0, 0.0], 0.0, laser, rng=np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c, equal_nan=True)
    hit = np.isfinite(a)
    assert 0 < (~hit).sum() < 0.15 * laser.n_beams
    dev = a[hit] - exact[hit]
    assert 0.005 < dev.std() < 0.015 and np.abs(dev).max() < 0.06


# --------------------------------------------------------------------------------------------- dynamics


def test_swinging_door_and_walking_person() -> None:
    door = SwingingDoor((0.0, 0.0), 1.0, 0.0, math.pi / 2, t_start_s=10.0, t_end_s=12.0)
    np.testing.assert_allclose(door.segments_at(0.0), [[0.0, 0.0, 1.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(door.segments_at(11.0)[0, 2:], [math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(door.segments_at(99.0), [[0.0, 0.0, 0.0, 1.0]], atol=1e-12)
    person = MovingPolygon.person([(1.0, 5.0, 0.0), (3.0, 5.0, 2.0)], radius_m=0.2)
    assert person.segments_at(0.5).shape == (0, 4)
    assert person.position_at(2.0) == pytest.approx((5.0, 1.0))
    world = World.from_parts(wall(10.0, -5.0, 10.0, 5.0), dynamic=[person])
    beam = np.array([0.0])
    assert cast_rays([0.0, 1.0], beam, world.segments_at(0.0), max_range_m=30.0)[0] == pytest.approx(10.0)
    assert cast_rays([0.0, 1.0], beam, world.segments_at(2.0), max_range_m=30.0)[0] == pytest.approx(4.8)
    with pytest.raises(ValueError, match="increasing times"):
        MovingPolygon.person([(1.0, 0.0, 0.0), (1.0, 1.0, 0.0)])


def segment_shapes(segments: np.ndarray) -> Shapes:
    """World segments ``(S, 4)`` as bare two-vertex polygons (the closed-loop geometry's form)."""
    segs = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    return Shapes.build([s.reshape(2, 2) for s in segs], list(range(len(segs))), [], [])


def robot_clearance(pose: np.ndarray, robot: RobotConfig, segments: np.ndarray) -> float:
    """Exact clearance of ``robot``'s footprint at ``pose`` to world segments (``sim.geometry``)."""
    rect = robot.shape != "circle"
    local = footprint_vertices(robot.front_m, robot.rear_m, robot.width_m) if rect else None
    return footprint_clearance(pose, local, robot.radius_m, segment_shapes(segments)).distance_m


def test_footprint_clearance_to_world_segments() -> None:
    # the wheelchair facing +y: front at y = front_m, rear at y = -rear_m, sides at x = +-width / 2
    r = WHEELCHAIR_ROBOT
    pose = np.array([0.0, 0.0, math.pi / 2])
    ahead = np.array([[-5.0, r.front_m + 1.0, 5.0, r.front_m + 1.0]])
    behind = np.array([[-5.0, -r.rear_m - 0.25, 5.0, -r.rear_m - 0.25]])
    side = np.array([[r.width_m / 2 + 0.5, -5.0, r.width_m / 2 + 0.5, 5.0]])
    assert robot_clearance(pose, r, ahead) == pytest.approx(1.0, abs=1e-12)
    assert robot_clearance(pose, r, behind) == pytest.approx(0.25, abs=1e-12)
    assert robot_clearance(pose, r, side) == pytest.approx(0.5, abs=1e-12)
    assert robot_clearance(pose, r, np.vstack([ahead, behind, side])) == pytest.approx(0.25, abs=1e-12)
    # a segment crossing the footprint touches it
    assert robot_clearance(pose, r, np.array([[-5.0, 0.1, 5.0, 0.1]])) == 0.0
    assert polygon([[0, 0], [1, 0], [1, 1]], closed=False).shape == (2, 4)


# --------------------------------------------------------------------------------------------- motion


def test_follow_route_respects_limits_and_ends_at_the_goal() -> None:
    p = DriveParams()
    traj = follow_route([np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 2.0]]), np.array([[3.0, 2.0], [1.0, 2.0]])],
                        Pose2D(0.0, 0.0, 0.0), p)
    v, w = traj.cmd[:, 0], traj.cmd[:, 1]
    assert v.max() <= p.vmax_mps + 1e-12 and v.min() >= 0.0 and np.abs(w).max() <= p.wmax_radps + 1e-12
    assert np.abs(np.diff(v)).max() <= p.accel_mps2 * p.dt_s + 1e-12
    assert np.abs(np.diff(w)).max() <= p.ang_accel_radps2 * p.dt_s + 1e-12
    np.testing.assert_allclose(traj.poses[-1, :2], [1.0, 2.0], atol=0.03)
    assert v[-1] == 0.0 and w[-1] == 0.0
    assert np.all(np.diff(traj.t_ns) == 10_000_000)
    # the turn in place at (3, 2) (pi/2 -> pi) happens at rest
    at_corner = np.hypot(traj.poses[:, 0] - 3.0, traj.poses[:, 1] - 2.0) < 0.03
    assert np.ptp(traj.poses[at_corner, 2]) > 1.4
    with pytest.raises(ValueError, match="non-empty sequence"):
        follow_route([], Pose2D(0.0, 0.0, 0.0), p)


def _route_truth() -> np.ndarray:
    """(K, 3) exact unicycle poses at 100 Hz: 4 m along an L with a rounded corner and a turn in place."""
    route = [np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]), np.array([[2.0, 2.0], [0.0, 2.0]])]
    return follow_route(route, Pose2D(0.0, 0.0, 0.0), DriveParams()).poses


def test_odometry_without_errors_reproduces_the_truth() -> None:
    truth = _route_truth()
    perfect = OdometryNoise(left_scale=0.0, right_scale=0.0, wheelbase_scale=0.0,
                            wheel_sigma_m_per_sqrt_m=0.0, slip_bias_sigma_radps=0.0)
    odom = corrupt_odometry(truth, 0.01, perfect, rng=np.random.default_rng(0))
    np.testing.assert_allclose(odom[:, :2], truth[:, :2], atol=1e-6)
    np.testing.assert_allclose(wrap_angle(odom[:, 2] - truth[:, 2]), 0.0, atol=1e-9)


def test_odometry_drift_is_bounded_nonzero_and_seeded() -> None:
    truth = _route_truth()
    noise = OdometryNoise()
    a = corrupt_odometry(truth, 0.01, noise, rng=np.random.default_rng(1))
    b = corrupt_odometry(truth, 0.01, noise, rng=np.random.default_rng(1))
    c = corrupt_odometry(truth, 0.01, noise, rng=np.random.default_rng(2))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(a[0], truth[0])
    err = np.hypot(*(a[:, :2] - truth[:, :2]).T)
    assert 1e-4 < err[-1] < 0.2  # 4 m driven
    # the increments stay close to the true ones: odometry is locally good
    inc_err = relative(a[:-100:100], a[100::100]) - relative(truth[:-100:100], truth[100::100])
    assert np.abs(inc_err[:, :2]).max() < 0.01


def test_office_odometry_drifts_realistically(office_run: SimulatedRun) -> None:
    err = np.hypot(*(office_run.odom[:, :2] - office_run.truth[:, :2]).T)
    heading = np.abs(wrap_angle(office_run.odom[:, 2] - office_run.truth[:, 2]))
    assert 0.2 < err.max() < 5.0
    assert math.radians(1.0) < heading.max() < math.radians(30.0)


# --------------------------------------------------------------------------------------------- the office


def test_office_run_shape_limits_and_clearance(office_run: SimulatedRun) -> None:
    scn = office_run.scenario
    duration = office_run.t_ns[-1] / 1e9
    assert 60.0 <= duration <= 120.0
    assert office_run.cmd[:, 0].max() <= WHEELCHAIR_ROBOT.vmax_mps + 1e-12
    assert np.abs(office_run.cmd[:, 1]).max() <= WHEELCHAIR_ROBOT.wmax_radps + 1e-12
    # through the narrow door: A|B wall at x = 7, opening y 2.05-2.95 for a 0.7 m wide robot
    crossing = np.argmin(np.abs(office_run.truth[:, 0] - 7.0))
    assert 2.4 < office_run.truth[crossing, 1] < 2.6
    # the footprint never touches the world (static and dynamic), every 0.1 s
    clearance = min(
        robot_clearance(office_run.truth[k], scn.robot, scn.world.segments_at(office_run.t_ns[k] / 1e9))
        for k in range(0, len(office_run.t_ns), 10)
    )
    assert 0.08 < clearance <= 0.1 + 1e-9
    # the person is seen but never close
    person = next(d for d in scn.world.dynamic if isinstance(d, MovingPolygon))
    gaps = [math.dist(p, office_run.truth[k, :2]) for k in range(0, len(office_run.t_ns), 10)
            if (p := person.position_at(office_run.t_ns[k] / 1e9)) is not None]
    assert gaps and min(gaps) > 2.0


def test_office_ticks_sensor_offset_and_geometry(office_run: SimulatedRun) -> None:
    ticks = list(iter_ticks(office_run, t0_ns=0))
    assert len(ticks) == len(office_run.t_ns[::20])
    assert [t.index for t in ticks[:3]] == [0, 1, 2] and ticks[1].t_ns == 200_000_000
    first = ticks[0]
    assert first.scan.sensor_pose == Pose2D(0.72, 0.0, 0.0)
    assert first.scan.ranges_m.shape == (361,) and first.scan.max_range_m == 8.0
    assert first.truth == Pose2D(1.2, 2.5, 0.0) and first.odom == Pose2D(1.2, 2.5, 0.0)
    # the laser is at (1.92, 2.5): straight ahead, through the open narrow door, the B|C wall at x = 14 is
    # beyond 8 m (no return); 15 deg to the right the beam hits the A|B wall at x = 7
    assert np.isinf(first.scan.ranges_m[180])
    assert first.scan.ranges_m[150] == pytest.approx((7.0 - 1.92) / math.cos(math.radians(15.0)), abs=0.05)
    # every scan is consistent with the true laser pose: hits lie on the world's segments
    scn = office_run.scenario
    for tick in ticks[::50]:
        assert tick.truth is not None
        laser_pose = compose(tick.truth.as_array(), tick.scan.sensor_pose.as_array())
        exact = simulate_ranges(scn.world, laser_pose, tick.t_ns / 1e9, scn.laser)  # t0_ns = 0
        both = np.isfinite(exact) & np.isfinite(tick.scan.ranges_m)
        assert both.mean() > 0.8 and np.abs(tick.scan.ranges_m[both] - exact[both]).max() < 0.08
    assert all(t.cmd is not None and t.cmd.v_mps <= 0.3 for t in ticks)
    odo = list(iter_odometry(office_run, t0_ns=0))
    assert len(odo) == len(office_run.t_ns[::5]) and odo[4].t_ns == ticks[1].t_ns


def test_office_ticks_are_deterministic(office_run: SimulatedRun) -> None:
    a = [t.scan.ranges_m for t in iter_ticks(office_run)][:40]
    b = [t.scan.ranges_m for t in iter_ticks(run_scenario(office_scenario(), seed=0))][:40]
    c = [t.scan.ranges_m for t in iter_ticks(run_scenario(office_scenario(), seed=1))][:40]
    np.testing.assert_array_equal(np.array(a), np.array(b))
    assert not np.array_equal(np.array(a), np.array(c))


def test_simulate_rejects_unknown_scenario(tmp_path: Path) -> None:
    assert "office" in SCENARIOS
    with pytest.raises(ConfigError, match="unknown scenario 'mars'"):
        simulate("mars", seed=0, out=tmp_path / "x.clf")
    with pytest.raises(ConfigError, match="simulated logs are written as CARMEN"):
        simulate("office", seed=0, out=tmp_path / "x.mcap")
    with pytest.raises(ConfigError, match="simulated logs are written as CARMEN"):
        simulate("office", seed=0, out=tmp_path / "x.bz2")


# --------------------------------------------------------------------------------------------- the CARMEN log


def test_simulated_log_is_byte_identical_and_reads_back(tmp_path: Path, office_run: SimulatedRun) -> None:
    a = simulate("office", seed=0, out=tmp_path / "a.clf.bz2")
    b = simulate("office", seed=0, out=tmp_path / "b.clf.bz2")
    c = simulate("office", seed=1, out=tmp_path / "c.clf.bz2")
    assert a.read_bytes() == b.read_bytes() != c.read_bytes()
    written = list(iter_ticks(office_run))
    read = list(read_ticks(a))
    assert len(read) == len(written) == 570
    for w, r in zip(written, read, strict=True):
        # what is read is what was written in the readers' one representation (io.canonical)
        assert r.t_ns == canonical_stamp(w.t_ns)
        assert r.scan.sensor_pose == Pose2D(0.72, 0.0, 0.0) and r.scan.max_range_m == 8.0
        np.testing.assert_array_equal(r.scan.angles_rad, canonical_bearings(w.scan.angles_rad))
        # ranges are millimetres in the simulator and written in full: they come back at float32, +inf too
        np.testing.assert_array_equal(r.scan.ranges_m, w.scan.ranges_m.astype(np.float32))
        assert r.truth == canonical_pose(w.truth) and r.odom == canonical_pose(w.odom)


def test_bundled_sample_log_matches_the_generator(tmp_path: Path) -> None:
    assert SAMPLE.stat().st_size < 1_000_000
    fresh = simulate("office", seed=0, out=tmp_path / SAMPLE.name)
    assert fresh.read_bytes() == SAMPLE.read_bytes(), "regenerate with scripts/make_sample_logs.py"
    read = list(read_ticks(SAMPLE))
    assert len(read) == 570 and all(t.truth is not None for t in read)


# --------------------------------------------------------------------------------------------- output safety


def test_simulate_refuses_an_existing_file_and_a_folder_before_any_work(tmp_path: Path) -> None:
    precious = tmp_path / "office.clf.bz2"
    precious.write_text("precious\n")
    with pytest.raises(OutputError, match=r"office\.clf\.bz2: already exists"):
        simulate("office", seed=0, out=precious)
    # --overwrite replaces only a log gndreplay wrote
    with pytest.raises(OutputError, match="not a CARMEN log written by gndreplay"):
        simulate("office", seed=0, out=precious, overwrite=True)
    assert precious.read_text() == "precious\n"
    (tmp_path / "d.clf").mkdir()
    for overwrite in (False, True):
        with pytest.raises(OutputError, match=r"d\.clf: is a folder"):
            simulate("office", seed=0, out=tmp_path / "d.clf", overwrite=overwrite)
    assert list((tmp_path / "d.clf").iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.clf", "office.clf.bz2"]  # no temporary left


def test_simulate_overwrite_replaces_its_own_log_with_the_sample(tmp_path: Path) -> None:
    import bz2

    own = tmp_path / SAMPLE.name
    own.write_bytes(bz2.compress(b"# CARMEN log written by gndreplay\nODOM 0 0 0 0 0 0 1 h 1\n"))
    fresh = simulate("office", seed=0, out=own, overwrite=True)
    assert fresh.read_bytes() == SAMPLE.read_bytes()
    from typer.testing import CliRunner

    from gndreplay.cli import app

    r = CliRunner().invoke(app, ["simulate", "office", "--out", str(own)])  # no --overwrite: refused
    assert r.exit_code == 2 and "already exists" in r.stderr and "Traceback" not in r.output
