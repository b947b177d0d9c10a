"""Scan matching on synthetic scans with known answers: a room under known motions, a corridor, failures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gndreplay.errors import OutputError, ScanMatchError
from gndreplay.evaluation import Relations
from gndreplay.geometry import compose, inverse, relative
from gndreplay.scanmatch import (
    IdcMatcher,
    IdcParams,
    KissParams,
    Matcher,
    OdomMatcher,
    correct_trajectory,
    interleave_bearings,
    keep_by_travel,
    make_matcher,
    run_scanmatch,
)
from gndreplay.scanmatch import _idc_kernels as kern
from gndreplay.scanmatch.idc import _compose as idc_compose
from gndreplay.types import Pose2D, Scan, Tick

WHEELCHAIR_LASER = Pose2D(0.72, 0.0, 0.0)
ON_AXIS = Pose2D(0.0, 0.0, 0.0)


def _box(cx: float, cy: float, w: float, h: float) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    x0, x1, y0, y1 = cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2
    c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return [(c[i], c[(i + 1) % 4]) for i in range(4)]


def room() -> np.ndarray:
    """A 10 x 7 m room with a few boxes (no symmetry), as (S, 2, 2) wall segments."""
    segs = _box(1.0, 0.5, 10.0, 7.0) + _box(3.0, 1.5, 0.6, 0.4) + _box(-2.0, -1.5, 0.5, 0.5)
    segs += _box(4.0, -2.0, 1.0, 0.3) + _box(-1.5, 2.5, 0.3, 0.8)
    return np.array(segs, dtype=float)


def corridor() -> np.ndarray:
    """Two bare parallel walls 2 m apart, 200 m long: translation along them is unobservable."""
    return np.array([((-100.0, -1.0), (100.0, -1.0)), ((-100.0, 1.0), (100.0, 1.0))])


def cast(segs: np.ndarray, robot: np.ndarray, *, sensor: Pose2D = ON_AXIS, n: int = 361,
         noise_m: float = 0.0, rng: np.random.Generator | None = None, t_ns: int = 0,
         max_range_m: float = 30.0) -> Scan:
    """Ray-cast a 180 deg scan from the laser at robot ∘ sensor (vectorised over beams x segments)."""
    ang = np.linspace(-math.pi / 2, math.pi / 2, n)
    lx, ly, lth = compose(robot, sensor.as_array())
    d = np.stack([np.cos(lth + ang), np.sin(lth + ang)], axis=1)
    a, e = segs[:, 0], segs[:, 1] - segs[:, 0]
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    ox, oy = a[None, :, 0] - lx, a[None, :, 1] - ly
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ox * e[None, :, 1] - oy * e[None, :, 0]) / den
        u = (ox * d[:, None, 1] - oy * d[:, None, 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    r = np.where(hit, t, np.inf).min(axis=1)
    if noise_m and rng is not None:
        r = r + rng.normal(0.0, noise_m, r.shape)
    r = np.where(r >= max_range_m, np.inf, r)
    return Scan(t_ns, r, ang, max_range_m, sensor_pose=sensor)


def motion(dx: float, dy: float, dth_deg: float) -> np.ndarray:
    return np.array([dx, dy, math.radians(dth_deg)])


def pose_error(est: Pose2D, truth: np.ndarray) -> tuple[float, float]:
    """Translational [m] and rotational [deg] error of est w.r.t. truth."""
    e = relative(truth, est.as_array())
    return float(math.hypot(e[0], e[1])), float(abs(math.degrees(e[2])))


START = np.array([2.0, -1.0, 0.3])  # robot pose of the first scan (truth = odometry there)
ODOM0 = np.array([10.0, 5.0, -1.0])  # the odometry frame differs from the world frame


def two_scan_match(segs: np.ndarray, move: np.ndarray, odom_move: np.ndarray, *, noise_m: float = 0.0,
                   sensor: Pose2D = ON_AXIS, params: IdcParams | None = None,
                   start: np.ndarray = START):
    """Match scan 2 (robot moved by ``move``) against scan 1 with odometry reporting ``odom_move``.

    Returns (result, truth of scan 2 in the odometry frame)."""
    rng = np.random.default_rng(7)
    m = IdcMatcher(params)
    first = m.update(cast(segs, start, sensor=sensor, noise_m=noise_m, rng=rng), Pose2D.from_array(ODOM0))
    assert first.ok and first.pose == Pose2D.from_array(ODOM0)
    res = m.update(cast(segs, compose(start, move), sensor=sensor, noise_m=noise_m, rng=rng, t_ns=10**8),
                   Pose2D.from_array(compose(ODOM0, odom_move)))
    return res, compose(ODOM0, move)


# odometry that under-reports: 80 % of the translation, 50 % of the rotation, 3 cm sideways slip
def bad_odometry(m: np.ndarray) -> np.ndarray:
    return np.array([0.8 * m[0], 0.8 * m[1] + 0.03, 0.5 * m[2]])


@pytest.mark.parametrize("noise_m", [0.0, 0.01])
@pytest.mark.parametrize("move", [motion(0.3, 0.0, 0.0), motion(0.0, 0.0, 10.0), motion(0.0, 0.0, -20.0),
                                  motion(0.0, 0.0, 20.0), motion(0.25, -0.1, 15.0), motion(0.2, 0.15, -20.0)],
                         ids=["x30cm", "rot10", "rot-20", "rot20", "both15", "both-20"])
def test_idc_recovers_known_motion(move: np.ndarray, noise_m: float) -> None:
    res, truth = two_scan_match(room(), move, bad_odometry(move), noise_m=noise_m)
    assert res.ok, res.reason
    et, er = pose_error(res.pose, truth)
    assert et < 0.01 and er < 0.2, (et, er)
    assert res.pairs > 300 and res.iterations > 0 and res.residual_m < 0.02 + noise_m


def test_idc_honours_laser_mounting() -> None:
    """The laser 0.72 m ahead of the axle (wheelchair): a pure rotation of the base moves the laser."""
    move = motion(0.1, 0.0, 15.0)
    res, truth = two_scan_match(room(), move, bad_odometry(move), sensor=WHEELCHAIR_LASER, noise_m=0.005)
    assert res.ok, res.reason
    et, er = pose_error(res.pose, truth)
    assert et < 0.01 and er < 0.2, (et, er)


def test_idc_finds_20_deg_from_no_odometry() -> None:
    """IDC's widening window: from a prior that says "no motion" it still finds a 20 deg turn (6 sigmas of
    the odometry's error model: the guard's second opinion near the odometry fits worse: it is believed)."""
    move = motion(0.1, 0.05, 20.0)
    res, truth = two_scan_match(room(), move, np.zeros(3), noise_m=0.01)
    assert res.ok, res.reason
    et, er = pose_error(res.pose, truth)
    assert et < 0.01 and er < 0.2, (et, er)


def test_pure_idc_without_polish_also_converges() -> None:
    move = motion(0.25, -0.1, 15.0)
    params = IdcParams(polish_iterations=0, max_iterations=60, tol_m=1e-5, tol_rad=1e-5)
    res, truth = two_scan_match(room(), move, bad_odometry(move), params=params)
    assert res.ok, res.reason
    et, er = pose_error(res.pose, truth)
    assert et < 0.01 and er < 0.2, (et, er)


def test_corridor_is_reported_degenerate_not_a_confident_answer() -> None:
    move = motion(0.5, 0.0, 0.0)
    odom_move = motion(0.3, 0.0, 0.0)  # odometry 20 cm short: nothing in a bare corridor can tell
    res, _ = two_scan_match(corridor(), move, odom_move, noise_m=0.005, start=np.array([0.0, 0.2, 0.1]))
    assert not res.ok
    assert res.reason.startswith("degenerate geometry")
    # the failed match keeps the odometry increment
    np.testing.assert_allclose(res.pose.as_array(), compose(ODOM0, odom_move), atol=1e-12)


def test_no_returns_fail_and_keep_odometry_increment() -> None:
    m = IdcMatcher()
    m.update(cast(room(), START), Pose2D.from_array(ODOM0))
    empty = Scan(10**8, np.full(361, np.inf), np.linspace(-math.pi / 2, math.pi / 2, 361), 30.0)
    odom = Pose2D.from_array(compose(ODOM0, motion(0.2, 0.0, 5.0)))
    res = m.update(empty, odom)
    assert not res.ok and res.reason.startswith("too few valid beams")
    assert res.pairs == 0 and res.iterations == 0
    np.testing.assert_allclose(res.pose.as_array(), odom.as_array(), atol=1e-12)


def test_failure_then_recovery_keeps_the_chain() -> None:
    """A failed scan keeps the odometry increment; the next scan is corrected from there."""
    segs = room()
    m = IdcMatcher()
    truth = [START, compose(START, motion(0.2, 0, 5)), compose(START, motion(0.4, 0, 8))]
    odo = [ODOM0, compose(ODOM0, motion(0.25, 0, 2)), compose(ODOM0, motion(0.5, 0, 3))]
    m.update(cast(segs, truth[0]), Pose2D.from_array(odo[0]))
    nan_scan = Scan(1, np.full(361, np.nan), np.linspace(-math.pi / 2, math.pi / 2, 361), 30.0)
    r1 = m.update(nan_scan, Pose2D.from_array(odo[1]))
    assert not r1.ok
    np.testing.assert_allclose(r1.pose.as_array(), odo[1], atol=1e-12)
    r2 = m.update(cast(segs, truth[2], t_ns=2), Pose2D.from_array(odo[2]))
    assert r2.ok
    et, er = pose_error(r2.pose, compose(ODOM0, relative(START, truth[2])))
    assert et < 0.01 and er < 0.2


def _drive(segs: np.ndarray, n: int, rng: np.random.Generator) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """A loop in the room: true poses and odometry with 3 % scale error, 2 % heading drift, noise."""
    truth = [START.copy()]
    odom = [ODOM0.copy()]
    for i in range(n):
        step = motion(0.08, 0.0, 6.0 if (i // 10) % 2 == 0 else -2.0)
        truth.append(compose(truth[-1], step))
        noisy = np.array([step[0] * 1.03 + rng.normal(0, 0.005), rng.normal(0, 0.005),
                          step[2] * 1.02 + 0.005 + rng.normal(0, 0.003)])
        odom.append(compose(odom[-1], noisy))
    return truth, odom


def test_idc_sequence_drifts_less_than_odometry() -> None:
    rng = np.random.default_rng(3)
    segs = room()
    truth, odom = _drive(segs, 40, rng)
    m = IdcMatcher()
    est = []
    for i, (tp, op) in enumerate(zip(truth, odom, strict=True)):
        res = m.update(cast(segs, tp, noise_m=0.01, rng=rng, t_ns=i * 10**8), Pose2D.from_array(op))
        assert res.ok, (i, res.reason)
        est.append(res.pose.as_array())
    truth_odom = [compose(ODOM0, relative(START, tp)) for tp in truth]  # truth in the odometry frame
    e_idc = relative(truth_odom[-1], est[-1])
    e_odo = relative(truth_odom[-1], odom[-1])
    assert math.hypot(e_idc[0], e_idc[1]) < 0.02 and abs(math.degrees(e_idc[2])) < 0.3
    assert math.hypot(e_odo[0], e_odo[1]) > 0.1  # the odometry really was off


def test_idc_is_deterministic() -> None:
    segs = room()
    outs = []
    for _ in range(2):
        rng = np.random.default_rng(11)
        truth, odom = _drive(segs, 12, rng)
        m = IdcMatcher()
        outs.append([m.update(cast(segs, tp, noise_m=0.01, rng=rng), Pose2D.from_array(op))
                     for tp, op in zip(truth, odom, strict=True)])
    assert outs[0] == outs[1]


def test_odom_matcher_returns_odometry() -> None:
    m = OdomMatcher()
    p = Pose2D(1.0, 2.0, 0.5)
    res = m.update(cast(room(), START), p)
    assert res.ok and res.pose == p and res.reason == ""


def test_make_matcher_and_protocol() -> None:
    for method, cls_name in [("idc", "IdcMatcher"), ("kiss-icp", "KissIcpMatcher"), ("odom", "OdomMatcher")]:
        m = make_matcher(method, kiss=KissParams(max_num_threads=1))
        assert isinstance(m, Matcher) and type(m).__name__ == cls_name and m.name == method
    with pytest.raises(ScanMatchError, match="unknown matcher 'icp': expected one of odom, idc, kiss-icp"):
        make_matcher("icp")  # type: ignore[arg-type]


def test_kiss_adapter_tracks_a_short_drive() -> None:
    """kiss-icp through the adapter: first pose = odometry, frames and mounting handled (loose bound)."""
    rng = np.random.default_rng(5)
    segs = room()
    truth, odom = _drive(segs, 15, rng)
    m = make_matcher("kiss-icp", kiss=KissParams(voxel_m=0.1, odom_prior=True))
    est = [m.update(cast(segs, tp, sensor=WHEELCHAIR_LASER, rng=rng, noise_m=0.005), Pose2D.from_array(op))
           for tp, op in zip(truth, odom, strict=True)]
    assert est[0].pose == Pose2D.from_array(ODOM0)
    e = relative(compose(ODOM0, relative(START, truth[-1])), est[-1].pose.as_array())
    assert math.hypot(e[0], e[1]) < 0.05 and abs(math.degrees(e[2])) < 1.0
    assert all(r.ok and r.pairs > 0 for r in est)


def _ticks(segs: np.ndarray, truth: list[np.ndarray], odom: list[np.ndarray]) -> list[Tick]:
    rng = np.random.default_rng(2)
    return [Tick(i, 1_000_000_000 + i * 100_000_000, cast(segs, tp, noise_m=0.01, rng=rng,
                                                          t_ns=1_000_000_000 + i * 100_000_000),
                 Pose2D.from_array(op)) for i, (tp, op) in enumerate(zip(truth, odom, strict=True))]


def test_correct_trajectory_and_run_scanmatch(tmp_path: Path) -> None:
    segs = room()
    truth, odom = _drive(segs, 20, np.random.default_rng(4))
    ticks = _ticks(segs, truth, odom)
    traj = correct_trajectory(ticks, IdcMatcher())
    assert traj.t_ns.shape == (21,) and traj.poses.shape == (21, 3) and traj.failures == 0
    assert traj.ms.shape == (21,) and np.all(traj.ms >= 0)
    # relations from the truth: scan 0 -> 20 and consecutive pairs
    pairs = [(0, 20)] + [(i, i + 1) for i in range(20)]
    rel_d = np.array([relative(truth[i], truth[j]) for i, j in pairs])
    t1 = np.array([ticks[i].t_ns for i, _ in pairs])
    t2 = np.array([ticks[j].t_ns for _, j in pairs])
    relations = Relations(t1, t2, rel_d[:, 0], rel_d[:, 1], rel_d[:, 2])
    rows = run_scanmatch(lambda: ticks, ("odom", "idc"), relations=relations, out_dir=tmp_path / "out")
    assert [r.method for r in rows] == ["odom", "idc"]
    odo, idc = rows
    assert odo.relations is not None and idc.relations is not None
    assert idc.relations.matched == 21 and idc.relations.unmatched == 0
    assert idc.relations.trans_mean_m < 0.01 and idc.relations.trans_mean_m < 0.5 * odo.relations.trans_mean_m
    assert idc.failures == 0 and idc.scans == 21 and idc.ms_median > 0
    d = idc.to_dict()
    assert d["method"] == "idc" and d["relations"]["matched"] == 21 and d["tum_path"].endswith("idc.tum")
    first = (tmp_path / "out" / "idc.tum").read_bytes()
    again = run_scanmatch(lambda: ticks, ("idc",), out_dir=tmp_path / "out")  # an earlier run is kept
    assert again[0].tum_path == str(tmp_path / "out-2" / "idc.tum")
    assert (tmp_path / "out-2" / "idc.tum").read_bytes() == first  # byte-identical rerun
    assert (tmp_path / "out" / "idc.tum").read_bytes() == first
    replaced = run_scanmatch(lambda: ticks, ("odom",), out_dir=tmp_path / "out", overwrite=True)
    assert replaced[0].tum_path == str(tmp_path / "out" / "odom.tum")
    assert not (tmp_path / "out" / "idc.tum").exists()
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("the user's")
    with pytest.raises(OutputError, match="not written by gndreplay"):
        run_scanmatch(lambda: ticks, ("odom",), out_dir=tmp_path / "mine")
    lines = first.decode().splitlines()
    assert lines[1].split()[0] == "1.000000000" and len(lines) == 22


# -- kernels --------------------------------------------------------------------------------------------


def test_fast_atan2_accuracy() -> None:
    rng = np.random.default_rng(0)
    special = [(0.0, 1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 0.0), (1e-300, -1.0)]
    for y, x in [*rng.normal(size=(2000, 2)).tolist(), *special]:
        assert abs(kern.fast_atan2(y, x) - math.atan2(y, x)) < 2e-6 or (x == 0.0 and y == 0.0)


def test_render_reference_sees_nearest_wall() -> None:
    """Two keyframes of a wall at x = 2 and a farther wall behind it: the render keeps the near one."""
    ys = np.linspace(-1.0, 1.0, 401)  # 5 mm apart: every 0.25 deg bin holds a point of the near wall
    near = np.column_stack([np.full_like(ys, 2.0), ys])
    far = np.column_stack([np.full_like(ys, 4.0), ys])
    kf = np.stack([near, far])
    ref_x, ref_y, ref_r, _, ok, nxt = kern.render_reference(
        kf, np.array([401, 401]), 0.0, 0.0, 0.0, 1440, 0.05, 40.0, 0.05, 0.2, 0.05, 4)
    assert ok.sum() > 100
    np.testing.assert_allclose(ref_x[ok], 2.0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(ref_x[ok], ref_y[ok]), ref_r[ok])
    assert np.all(nxt[ok][:-1] >= 0)  # one continuous wall
    # seen from (0, 0, pi): the wall is behind, at bearing ~ +-pi
    _, _, _, ref_a2, ok2, _ = kern.render_reference(kf, np.array([401, 401]), 0.0, 0.0, math.pi, 1440, 0.05,
                                                    40.0, 0.05, 0.2, 0.05, 4)
    assert np.all(np.abs(ref_a2[ok2]) > math.radians(150))


def _wall_reference() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A wall at x = 2 from y = -1 to 1 rendered from the origin (one polyline, bearings -26.6..26.6 deg)."""
    ys = np.linspace(-1.0, 1.0, 401)
    kf = np.column_stack([np.full_like(ys, 2.0), ys])[None]
    ref_x, ref_y, _, _, _, nxt = kern.render_reference(kf, np.array([401]), 0.0, 0.0, 0.0, 1440, 0.05, 40.0,
                                                        0.05, 0.2, 0.05, 4)
    return ref_x, ref_y, nxt


def _unseen(*views: tuple[float, float, float, float, float]) -> np.ndarray:
    """unseen_ends of the wall for keyframes (laser x, y, heading, field of view, range limit), the wall
    rendered from the origin."""
    ref_x, ref_y, nxt = _wall_reference()
    kf_view = np.array([kern.view_row(x, y, th, -fov / 2, fov / 2, rmax) for x, y, th, fov, rmax in views])
    return kern.unseen_ends(ref_x, ref_y, nxt, kf_view, np.ones(len(views), dtype=np.int64), 0.0, 0.0, 0.0)


def test_wall_ends_no_keyframe_saw_past_are_marked() -> None:
    """The wall's two ends: unseen when the only keyframe's view ended there (a 53 deg view from the origin
    takes in exactly the wall), seen when a keyframe looked past them (a 180 deg view), or past one of them
    only (a keyframe further up the wall, looking along it), unseen again beyond the keyframe's range."""
    _, _, nxt = _wall_reference()
    chain = np.nonzero(nxt >= 0)[0]
    first, last = chain[0], nxt[chain[-1]]
    narrow = _unseen((0.0, 0.0, 0.0, math.radians(53.2), 30.0))
    assert narrow[first] == 1 and narrow[last] == 2
    assert np.count_nonzero(narrow) == 2  # only the ends
    assert not _unseen((0.0, 0.0, 0.0, math.pi, 30.0)).any()
    assert not _unseen((0.0, 0.0, math.pi, math.radians(330.0), 30.0)).any()  # looking away, 330 deg wide
    assert np.count_nonzero(_unseen((0.0, 0.0, math.pi, math.radians(200.0), 30.0))) == 2
    up = _unseen((0.0, 0.0, 0.0, math.radians(53.2), 30.0), (1.0, 0.5, math.pi / 4, math.radians(60.0), 30.0))
    assert up[first] == 1 and up[last] == 0  # the second keyframe saw past the upper end only
    too_far = _unseen((0.0, 0.0, 0.0, math.pi, 2.0))
    assert too_far[first] == 1 and too_far[last] == 2
    # views are in the map frame and the reference is rendered from (ox, oy, oth): with the origin at x = 1
    # the continuations lie at x = 3, 14.7 deg off the axis of a keyframe at x = -1 (inside its +-17 deg);
    # rendered from the map's origin they would lie at x = 2, 19.3 deg off (outside)
    ref_x, ref_y, nxt2 = _wall_reference()
    view = kern.view_row(-1.0, 0.0, 0.0, -math.radians(17.0), math.radians(17.0), 30.0)[None]
    ones = np.ones(1, dtype=np.int64)
    assert not kern.unseen_ends(ref_x, ref_y, nxt2, view, ones, 1.0, 0.0, 0.0).any()
    assert np.count_nonzero(kern.unseen_ends(ref_x, ref_y, nxt2, view, ones, 0.0, 0.0, 0.0)) == 2


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_turning_on_the_spot_beside_a_wall_does_not_drift(tmp_path: Path, seed: int) -> None:
    """The office log (the bundled sample is seed 0) turns on the spot at a corridor's end with its laser
    0.72 m ahead of the axle: the view sweeps along a wall whose far part no keyframe saw yet. Pairing the
    newly seen wall with the end of the mapped part slid the pose 0.15 m along the wall (sample 45-49 s,
    ATE max 0.10 m, RMSE 0.063 m); scored against the log's ground truth, idc now stays under 5 cm
    everywhere, sampled by distance with interleaved start bearings too (a ROBOTLASER-style log)."""
    from gndreplay.evaluation import trajectory_errors
    from gndreplay.io import read_ticks
    from gndreplay.sim.scenario import simulate

    full = list(read_ticks(simulate("office", seed=seed, out=tmp_path / "o.clf")))
    sparse = interleave_bearings(keep_by_travel(full, 0.2, math.radians(5.0)), math.radians(0.25), 4)
    for ticks in (full, sparse):
        truth = np.array([(t.truth.x, t.truth.y, t.truth.theta) for t in ticks if t.truth is not None])
        err = {}
        for method in ("odom", "idc"):
            traj = correct_trajectory(ticks, make_matcher(method))
            err[method] = trajectory_errors(traj.t_ns, traj.poses, traj.t_ns, truth, alignment="se2")
        assert err["idc"].ate_max_m < (0.05 if ticks is full else 0.06), err["idc"].ate_max_m
        assert err["idc"].ate_rmse_m < 0.5 * err["odom"].ate_rmse_m


def test_weighted_median() -> None:
    v = np.array([0.0, 1.0, 2.0, 100.0])
    assert kern._weighted_median(v, np.ones(4)) in (1.0, 2.0)
    assert kern._weighted_median(v, np.array([1.0, 1.0, 10.0, 1.0])) == 2.0


def test_pose_helpers_agree_with_geometry() -> None:
    from gndreplay.scanmatch.idc import _compose, _inverse, _pose

    a, b = (1.0, -2.0, 3.0), (-0.5, 0.3, -2.9)
    np.testing.assert_allclose(_compose(a, b), compose(np.array(a), np.array(b)), atol=1e-12)
    np.testing.assert_allclose(_inverse(a), inverse(np.array(a)), atol=1e-12)
    assert _pose((1.0, 2.0, -math.pi)) == Pose2D(1.0, 2.0, math.pi)  # Pose2D's theta is in (-pi, pi]
    np.testing.assert_allclose(_pose(_compose(a, b)).as_array(),
                               Pose2D.from_array(compose(np.array(a), np.array(b))).as_array(), atol=1e-12)


def test_stopping_after_a_fast_turn_in_a_round_hall_does_not_keep_turning() -> None:
    """Odometry repeats after a fast turn: stalled (still turning) or stopped? In a round hall every heading
    matches, so constant velocity alone would keep the estimate turning scan after scan (it did, on ACES);
    matched against "no motion" too, the robot that stopped stays put."""
    a = np.linspace(0.0, 2.0 * math.pi, 49)
    hall = np.stack([np.stack([4 * np.cos(a[:-1]), 4 * np.sin(a[:-1])], 1),
                     np.stack([4 * np.cos(a[1:]), 4 * np.sin(a[1:])], 1)], 1)
    start = np.array([0.3, 0.2, 0.0])
    for turn_deg in (20.0, 45.0, 60.0):
        truth, odo = [start], [ODOM0]
        for i in range(10):  # four fast turning scans, then six standing ones with the same odometry
            step = motion(0.0, 0.0, turn_deg if i < 4 else 0.0)
            truth.append(compose(truth[-1], step))
            odo.append(compose(odo[-1], step))
        m = IdcMatcher()
        for i, (tp, op) in enumerate(zip(truth, odo, strict=True)):
            res = m.update(cast(hall, tp, t_ns=i), Pose2D.from_array(op))
        et, er = pose_error(res.pose, compose(ODOM0, relative(start, truth[-1])))
        assert et < 0.01 and er < 0.2, (turn_deg, et, er)


def test_standing_robot_gets_the_mean_of_its_matches() -> None:
    """Odometry repeats after a robot came to rest (last step 5 mm): every noisy scan measures the same
    pose, and the corrected pose is their running mean, so it settles instead of jumping with each scan's
    noise."""
    segs = room()
    pose = compose(START, motion(0.005, 0.0, 0.2))
    odo = compose(ODOM0, motion(0.005, 0.0, 0.2))
    truth = compose(ODOM0, relative(START, pose))
    spread, final = {}, {}
    for average in (False, True):
        rng = np.random.default_rng(11)
        m = IdcMatcher(IdcParams(average_when_still=average))
        m.update(cast(segs, START, noise_m=0.02, rng=rng), Pose2D.from_array(ODOM0))
        poses = []
        for i in range(31):  # a last small step, then the same odometry pose for 30 noisy scans
            res = m.update(cast(segs, pose, noise_m=0.02, rng=rng, t_ns=i + 1), Pose2D.from_array(odo))
            assert res.ok, res.reason
            poses.append(res.pose.as_array())
        last = np.array(poses[-10:])
        spread[average] = float(np.max(np.hypot(*(last[:, :2] - last[:, :2].mean(axis=0)).T)))
        final[average] = pose_error(res.pose, truth)
    assert spread[True] < 0.3 * spread[False], spread
    assert final[True][0] < 0.005 and final[True][1] < 0.1, final


def test_odometry_frozen_while_moving_is_not_taken_for_a_standstill() -> None:
    """Odometry that freezes while the robot keeps moving 3 cm and 2 deg per scan (a lagging driver) must
    not start the standstill averaging, which would hold the estimate back by half the motion: the last
    odometry step was a moving robot's, not one of a robot coming to rest."""
    segs = room()
    truth, odo = [START], [ODOM0]
    for i in range(9):  # three scans with odometry, then six with the odometry frozen
        step = motion(0.03, 0.0, 2.0)
        truth.append(compose(truth[-1], step))
        odo.append(compose(odo[-1], step) if i < 3 else odo[-1])
    m = IdcMatcher()
    rng = np.random.default_rng(5)
    worst = (0.0, 0.0)
    for i, (tp, op) in enumerate(zip(truth, odo, strict=True)):
        res = m.update(cast(segs, tp, noise_m=0.01, rng=rng, t_ns=i), Pose2D.from_array(op))
        et, er = pose_error(res.pose, compose(ODOM0, relative(START, tp)))
        worst = (max(worst[0], et), max(worst[1], er))
    assert worst[0] < 0.01 and worst[1] < 0.3, worst


def symmetric_corridor() -> np.ndarray:
    """A corridor 2.4 m wide and 16 m long, mirror-symmetric about its axis, with a door recess every 3 m on
    both sides: turned in place, its scans look alike at many headings."""
    segs: list[tuple[tuple[float, float], tuple[float, float]]] = []
    for side in (-1.0, 1.0):
        y, x0 = 1.2 * side, -8.0
        for xd in (-5.0, -2.0, 1.0, 4.0, 7.0):
            segs += [((x0, y), (xd - 0.45, y)), ((xd - 0.45, y), (xd - 0.45, y + 0.3 * side)),
                     ((xd - 0.45, y + 0.3 * side), (xd + 0.45, y + 0.3 * side)),
                     ((xd + 0.45, y + 0.3 * side), (xd + 0.45, y))]
            x0 = xd + 0.45
        segs.append(((x0, y), (8.0, y)))
    segs += [((-8.0, -1.2), (-8.0, 1.2)), ((8.0, -1.2), (8.0, 1.2))]
    return np.array(segs)


def _run(segs: np.ndarray, steps: list[np.ndarray], odo_steps: list[np.ndarray],
         params: IdcParams | None = None, start: np.ndarray = START,
         dt_ns: int = 10**8) -> list[tuple[bool, float, float, str]]:
    """Drive ``steps`` (odometry reporting ``odo_steps``) and return per scan (ok, translational error [m],
    rotational error [deg], reason) of the corrected pose against the truth."""
    m = IdcMatcher(params)
    truth, odo = [start], [ODOM0]
    for st, so in zip(steps, odo_steps, strict=True):
        truth.append(compose(truth[-1], st))
        odo.append(compose(odo[-1], so))
    out = []
    for i, (tp, op) in enumerate(zip(truth, odo, strict=True)):
        res = m.update(cast(segs, tp, t_ns=i * dt_ns), Pose2D.from_array(op))
        et, er = pose_error(res.pose, compose(ODOM0, relative(start, tp)))
        out.append((res.ok, et, er, res.reason))
    return out


def test_fast_turn_in_a_symmetric_corridor_lands_in_the_right_basin() -> None:
    """Odometry that misses a 42 deg turn entirely (stale, as on Intel) puts IDC's start outside its 20 deg
    bearing window; the correlative rotation search over +-45 deg finds the basin first. Without it (the
    cause) the turn is lost and every later scan inherits 42-84 deg of error."""
    steps = [motion(0.2, 0, 0), motion(0.2, 0, 0), motion(0.05, 0, 42), motion(0.05, 0, 42),
             motion(0.2, 0, 0)]
    stale = [motion(0.2, 0, 0), motion(0.2, 0, 0), motion(0.05, 0, 0), motion(0.05, 0, 0), motion(0.2, 0, 0)]
    start = np.array([0.5, 0.1, 0.0])
    fixed = _run(symmetric_corridor(), steps, stale, start=start)
    assert all(ok for ok, *_ in fixed), fixed
    assert max(et for _, et, _, _ in fixed) < 0.01 and max(er for _, _, er, _ in fixed) < 0.5, fixed
    lost = _run(symmetric_corridor(), steps, stale, IdcParams(coarse_window_rad=0.0), start=start)
    assert lost[-1][2] > 30.0, lost


def test_sparse_scans_025_m_20_deg_apart_are_matched() -> None:
    """A log sampled by distance: 0.25 m and 20 deg between scans, odometry 20 % short and turning half as
    much; every scan is matched, none refused, and the pose stays within 2 cm / 0.3 deg."""
    steps = [motion(0.25, 0.0, 20.0 if i % 3 else -20.0) for i in range(12)]
    out = _run(room(), steps, [bad_odometry(s) for s in steps], start=np.array([1.0, 0.5, 0.0]), dt_ns=10**9)
    assert all(ok for ok, *_ in out), [r for r in out if not r[0]]
    assert max(et for _, et, _, _ in out) < 0.02 and max(er for _, _, er, _ in out) < 0.3, out


def _wrong_first_match(m: IdcMatcher, shift: tuple[float, float, float], worse_by: float) -> None:
    """Make the matcher's first match of each scan land ``shift`` (laser frame) off the true pose, with a
    quality (pairs, mean pair distance) equal to the true match's, or worse by ``worse_by`` m per pair: a
    wrong basin that the scan alone cannot tell from the right one. The second opinion (narrow window from
    the odometry's prediction) is left as it is."""
    real = m._match

    def match(px, py, pr, pa, par, laser_prior, incr, win0_rad=None, coarse=True):  # type: ignore[no-untyped-def]
        out = real(px, py, pr, pa, par, laser_prior, incr, win0_rad, coarse)
        if win0_rad is not None or out.reason:
            return out
        wrong = idc_compose(out.laser, shift)
        return out._replace(laser=wrong, residual_m=out.residual_m + worse_by)

    m._match = match  # type: ignore[method-assign]


@pytest.mark.parametrize("worse_by", [0.0, 0.02])
def test_guard_refuses_a_wrong_match_that_odometry_contradicts(worse_by: float) -> None:
    """A match 0.6 m / 25 deg from good odometry is suspicious; the second opinion near the odometry fits as
    well (refused: MATCH_FAILED, odometry increment kept) or better (that match is taken)."""
    m = IdcMatcher()
    m.update(cast(room(), START), Pose2D.from_array(ODOM0))
    _wrong_first_match(m, (0.6, 0.0, math.radians(25.0)), worse_by)
    move = motion(0.2, 0.0, 5.0)
    odom = compose(ODOM0, move)  # exact odometry
    res = m.update(cast(room(), compose(START, move), t_ns=10**8), Pose2D.from_array(odom))
    et, er = pose_error(res.pose, odom)
    if worse_by == 0.0:
        assert not res.ok and res.reason.startswith("unconfirmed match"), res.reason
        np.testing.assert_allclose(res.pose.as_array(), odom, atol=1e-12)
    else:
        assert res.ok, res.reason
        assert et < 0.01 and er < 0.2, (et, er)


def test_guard_believes_a_far_match_the_map_confirms() -> None:
    """Odometry that reports no motion while the robot turned 20 deg (6 sigmas of the error model): the
    second opinion from the odometry's prediction fits worse, so the match is taken, and the learnt scale of
    the odometry's error model grows."""
    m = IdcMatcher()
    m.update(cast(room(), START), Pose2D.from_array(ODOM0))
    move = motion(0.1, 0.0, 20.0)
    res = m.update(cast(room(), compose(START, move), t_ns=10**8), Pose2D.from_array(ODOM0))
    assert res.ok, res.reason
    et, er = pose_error(res.pose, compose(ODOM0, move))
    assert et < 0.01 and er < 0.2
    assert m._odo_scale[1] > 1.0


def test_long_gap_restarts_the_map_when_it_no_longer_fits() -> None:
    """After a gap longer than the map's validity a scan that does not fit the map (the robot was carried
    elsewhere) restarts the map at once, and the next scans match against the new one; a gap where the
    robot stood still keeps the map (a log sampled by distance)."""
    m = IdcMatcher()
    m.update(cast(room(), START, t_ns=0), Pose2D.from_array(ODOM0))
    still = m.update(cast(room(), START, t_ns=30 * 10**9), Pose2D.from_array(ODOM0))
    assert still.ok, still.reason
    hall = symmetric_corridor()
    elsewhere = np.array([0.5, 0.1, 0.0])
    res = m.update(cast(hall, elsewhere, t_ns=60 * 10**9), Pose2D.from_array(ODOM0))
    assert not res.ok and res.reason.endswith("map restarted") and "gap of 30.0 s" in res.reason
    nxt = m.update(cast(hall, compose(elsewhere, motion(0.2, 0.0, 3.0)), t_ns=60 * 10**9 + 10**8),
                   Pose2D.from_array(compose(ODOM0, motion(0.22, 0.0, 2.0))))
    assert nxt.ok, nxt.reason
    et, er = pose_error(nxt.pose, compose(ODOM0, motion(0.2, 0.0, 3.0)))
    assert et < 0.01 and er < 0.2


def round_hall() -> np.ndarray:
    """A round hall (radius 4 m, 72 wall segments) with three pillars: its wall fits any heading (a match
    at a wrong heading still pairs most points), only the pillars tell the heading."""
    a = np.radians(np.arange(73) * 5.0)
    pts = np.column_stack([4.0 * np.cos(a), 4.0 * np.sin(a)])
    segs = [(tuple(pts[i]), tuple(pts[i + 1])) for i in range(72)]
    segs += _box(2.0, 1.0, 0.4, 0.4) + _box(-1.5, 2.2, 0.6, 0.3) + _box(-1.0, -2.5, 0.3, 0.3)
    return np.array(segs, dtype=float)


@pytest.mark.parametrize(("step_deg", "back"), [(8.0, 5), (6.0, 6)])
def test_stale_scan_in_a_turn_does_not_derail_the_next_ones(step_deg: float, back: int) -> None:
    """A stale record (Intel: a scan repeating the view of ~40 deg earlier, with fresh odometry) in a turn
    in place: the scan is placed where its content was seen, so the next scan's odometry prediction is off
    by that jump. The right match of the next scan is then far from every prior, and a weak match near one
    of them (the wall of a round hall fits any heading) must not win over it: every later scan stays within
    1 cm / 0.5 deg (before the fix they all inherited ~45 deg)."""
    start = np.array([0.3, -0.2, 0.0])
    truth = [start]
    for _ in range(15):
        truth.append(compose(truth[-1], motion(0.0, 0.0, step_deg)))
    m = IdcMatcher()
    out = []
    for i, tp in enumerate(truth):
        seen = truth[i - back] if i == 7 else tp  # scan 7 repeats an earlier view; its odometry is fresh
        res = m.update(cast(round_hall(), seen, t_ns=i * 10**8),
                       Pose2D.from_array(compose(ODOM0, relative(start, tp))))
        out.append((res.ok, *pose_error(res.pose, compose(ODOM0, relative(start, seen)))))
    assert all(ok for ok, *_ in out[8:]), out
    assert max(et for _, et, _ in out[8:]) < 0.01 and max(er for _, _, er in out[8:]) < 0.5, out


def test_good_odometry_narrows_the_rotation_guard_to_2_deg() -> None:
    """A robot whose odometry turns well learns a narrower rotational error model (the guard's 2 sigmas
    down to 2 deg + 10 % of the turn): a match 4 deg off exact odometry that fits no better than the match
    near the odometry is then refused, where a fresh matcher (2 sigmas = 6.7 deg) takes it unchecked. The
    translation model does not narrow."""
    shift = (0.0, 0.0, math.radians(4.0))
    move = motion(0.05, 0.0, 2.0)

    fresh = IdcMatcher()
    fresh.update(cast(room(), START), Pose2D.from_array(ODOM0))
    _wrong_first_match(fresh, shift, 0.0)
    odo_next = compose(ODOM0, move)
    res = fresh.update(cast(room(), compose(START, move), t_ns=10**8), Pose2D.from_array(odo_next))
    assert res.ok and 3.5 < pose_error(res.pose, odo_next)[1] < 4.5, res

    m = IdcMatcher()
    truth, odo = START, ODOM0
    for i in range(150):  # back and forth, exact odometry: corrections near 0
        step = motion(0.03 if i % 2 else -0.03, 0.0, 1.0 if i % 4 < 2 else -1.0)
        truth, odo = compose(truth, step), compose(odo, step)
        assert m.update(cast(room(), truth, t_ns=i * 10**8), Pose2D.from_array(odo)).ok
    assert m._odo_scale[1] == pytest.approx(0.3) and m._odo_scale[0] == 1.0, m._odo_scale
    _wrong_first_match(m, shift, 0.0)
    odo_next = compose(odo, move)
    res = m.update(cast(room(), compose(truth, move), t_ns=150 * 10**8), Pose2D.from_array(odo_next))
    assert not res.ok and res.reason.startswith("unconfirmed match"), res
    et, er = pose_error(res.pose, odo_next)  # the odometry increment kept (after 150 near-exact matches)
    assert et < 1e-3 and er < 0.01, (et, er)


# -- narrow passages (issue 10) ------------------------------------------------------------------------------
# The chair backing out of gnd_exp1_three_traps' side passage lost 0.5 m: its exit had closed after the last
# keyframe, and the overlap fell a few points per scan, so the door (the one surface across the passage)
# never entered the map (fixed: a lasting drop in overlap takes a keyframe). Known defect, held by strict
# xfails (they fail the day they pass): a laser looking down a bare passage whose walls are within about 1 m.
# Surface normals over a few centimetres of such a wall (points 3 mm apart, 1 cm of range noise) tilt by
# 30-60 deg and invent information along it; the match passes the degenerate-geometry gate and the pose
# stays at the newest keyframe's while the robot drives on. A degeneracy test with 25 cm line normals fixes
# these tests but put relations under 1 s of the ACES log up to 5.7 deg off over 16 start scans (issue 11's
# bound is 3 deg), so it is not in.
KNOWN_CORRIDOR_DEFECT = pytest.mark.xfail(strict=True, raises=AssertionError,
                                          reason="known matcher defect: IDC along a bare narrow corridor")


def side_passage(door: float) -> np.ndarray:
    """A 1.4 m side passage leaving a 1.4 m corridor southwards into a big room (gnd_exp1_three_traps); its
    far end (3.8 m down) closed by a door slid ``door`` (0-1) of the way across from its west jamb."""
    segs = [((-3.0, -8.0), (18.0, -8.0)), ((-3.0, 8.0), (18.0, 8.0)), ((-3.0, -8.0), (-3.0, 8.0)),
            ((18.0, -8.0), (18.0, 8.0)), ((3.0, 0.7), (9.0, 0.7)), ((3.0, -0.7), (5.5, -0.7)),
            ((6.9, -0.7), (9.0, -0.7)), ((9.0, -0.7), (9.0, 0.7)), ((5.5, -0.7), (5.5, -4.5)),
            ((6.9, -0.7), (6.9, -4.5))]
    if door > 0.0:
        segs.append(((5.5, -4.5), (5.5 + 1.4 * min(door, 1.0), -4.5)))
    return np.array(segs)


def narrow_corridor() -> np.ndarray:
    """Two bare parallel walls 1.4 m apart (a wheelchair's passage), 200 m long."""
    return np.array([((-100.0, -0.7), (100.0, -0.7)), ((-100.0, 0.7), (100.0, 0.7))])


def _worst_error(segs_at: list[np.ndarray], start: np.ndarray, steps: list[np.ndarray]) -> float:
    """The chair (laser 0.72 m ahead) from ``start`` along ``steps`` (one scan each, 5 scans/s, the world
    ``segs_at[i]`` at scan i), 1 cm of range noise, exact odometry: the worst translational error [m]."""
    rng = np.random.default_rng(5)
    m = IdcMatcher()
    tp, worst = start, 0.0
    for i, segs in enumerate(segs_at):
        if i:
            tp = compose(tp, steps[i - 1])
        odo = compose(ODOM0, relative(start, tp))
        scan = cast(segs, tp, sensor=WHEELCHAIR_LASER, t_ns=i * 2 * 10**8, noise_m=0.01, rng=rng,
                    max_range_m=32.0)
        worst = max(worst, pose_error(m.update(scan, Pose2D.from_array(odo)).pose, odo)[0])
    return worst


def test_backing_out_of_a_passage_whose_end_closed_follows_the_odometry() -> None:
    """The chair creeps into the side passage, its exit slides shut over 1.4 s, the chair stops and backs
    out 0.72 m. The map must take in the door, though the chair moved too little for a keyframe and the pairs
    fell a few at a time (keyframes on a drop against the previous match alone: 0.37 m lost)."""
    steps = [motion(0.02, 0, 0)] * 12 + [motion(0, 0, 0)] * 3 + [motion(-0.036, 0, 0)] * 20
    worlds = [side_passage((i - 7) / 7.0) for i in range(len(steps) + 1)]
    assert _worst_error(worlds, np.array([6.2, -0.3, math.radians(-84.0)]), steps) < 0.05


@KNOWN_CORRIDOR_DEFECT
@pytest.mark.parametrize("step_m", [0.036, -0.036])
def test_a_narrow_corridor_keeps_the_odometry_along_it(step_m: float) -> None:
    """30 scans 3.6 cm apart between bare walls 0.7 m from the laser, either way (HEAD: about 1 m lost
    over 1.08 m): the scan can tell nothing along the corridor, so the odometry's motion must stand."""
    steps = [motion(step_m, 0, 0)] * 30
    assert _worst_error([narrow_corridor()] * 31, np.array([0.0, 0.1, 0.0]), steps) < 0.02


def test_a_lasting_change_of_view_enters_the_map_and_a_one_scan_dip_does_not() -> None:
    """A robot standing still: a person (0.8 m wide, 2 m ahead) in view for one scan leaves the map alone (a
    single match pairing fewer points is as often a poorer fit); in view for three scans in a row, the map
    takes the new view in, though no scan paired fewer than 80 % of the previous one's points."""
    def keyframes(m: IdcMatcher) -> int:
        return int(np.count_nonzero(m._kf_n))

    person = np.array(_box(2.0, -1.0, 0.3, 0.8), dtype=float)
    with_person = np.concatenate([room(), person])
    m = IdcMatcher()
    still = Pose2D(0.0, 0.0, 0.0)
    scans = [room()] * 3 + [with_person] + [room()] * 3 + [with_person] * 3
    counts, pairs, ok = [], [], []
    for i, segs in enumerate(scans):
        res = m.update(cast(segs, np.zeros(3), t_ns=i * 10**8), still)
        counts.append(keyframes(m))
        pairs.append(res.pairs)
        ok.append(res.ok)
    assert all(ok), (ok, pairs)
    assert 0.8 * pairs[2] < pairs[3] < IdcParams().keyframe_pair_ratio * pairs[2], pairs
    assert counts[:9] == [1] * 9, counts  # one scan with the person, then two more: the map unchanged
    assert counts[9] == 2, counts  # the third scan in a row with the person enters the map


def _unmapped_near_laser(m: IdcMatcher, scan: Scan, odom: np.ndarray, within_m: float = 1.5) -> float:
    """The farthest any return within ``within_m`` of the laser lies from the matcher's map (both in the
    corrected frame, which exact odometry makes the odometry's; the scan placed at ``odom``)."""
    kf = np.vstack([m._kf_xy[i, : m._kf_n[i]] for i in range(m._kf_n.shape[0]) if m._kf_n[i]])
    near = np.isfinite(scan.ranges_m) & (scan.ranges_m <= within_m)
    r, a = scan.ranges_m[near], scan.angles_rad[near]
    lx, ly, lth = compose(odom, scan.sensor_pose.as_array())
    pts = np.column_stack([lx + r * np.cos(lth + a), ly + r * np.sin(lth + a)])
    d = np.sqrt(((pts[:, None, :] - kf[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
    return float(d.max())


@pytest.mark.parametrize("back_m", [0.3, 0.45, 0.6])
def test_backing_up_puts_the_walls_beside_the_laser_into_the_map(back_m: float) -> None:
    """A laser that sees no further back than sideways (180 deg, at the chair's front) uncovers, as the chair
    backs up, the walls beside it that no keyframe saw; they are the closest returns and pull a match
    hardest (gnd_exp1_three_traps, chair, seed 3: 0.5 m of a side wall unmapped after backing out of the
    closed side passage, a match slid 0.2 m into the passage and the goal was missed by 0.5 m). Backing up
    along the passage, no return within 1.5 m of the laser lies further than keyframe_back_m from the map
    it is matched against (without the rule, keyframes only every 0.5 m: 0.24 m at each distance here)."""
    start = np.array([6.2, -0.9, math.radians(-88.0)])  # in the side passage, facing its closed end
    m = IdcMatcher()
    tp = start
    worst = 0.0
    for i in range(round(back_m / 0.015) + 1):
        if i:
            tp = compose(tp, motion(-0.015, 0.0, 0.0))
        odo = compose(ODOM0, relative(start, tp))
        scan = cast(side_passage(1.0), tp, sensor=WHEELCHAIR_LASER, t_ns=i * 2 * 10**8)
        if i:
            worst = max(worst, _unmapped_near_laser(m, scan, odo))
        res = m.update(scan, Pose2D.from_array(odo))
        assert res.ok, (i, res.reason)
    assert worst <= IdcParams().keyframe_back_m + 0.02, worst  # no keyframe when backing: 0.24 m
