"""Relations metric, SE(2) ATE / RPE against truth (against evo's SE(3) Umeyama when evo is installed), TUM
writer, and the scan matcher's health: known answers, matching by stamp, error messages, round trip."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gndreplay.errors import GndReplayError
from gndreplay.evaluation import (
    FAILURE_CATEGORIES,
    REFUSALS,
    HealthParams,
    align_origin,
    align_se2,
    associate,
    failure_category,
    load_relations,
    matcher_health,
    relation_errors,
    relations_from_trajectory,
    trajectory_errors,
    write_tum,
)
from gndreplay.geometry import compose, inverse, relative

T0 = 1_134_864_629_895_182_000  # a CSAIL-like stamp (ns): floats would lose the last digits


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_load_relations_parses_stamps_exactly(tmp_path: Path) -> None:
    p = _write(tmp_path / "r.relations", "# t1 t2 x y z roll pitch yaw\n\n"
               "1134864645.90321 1134864646.32420 0.31293 0.02935 0.00000  0.00000 0.00000 0.24198\n"
               "90.239599 90.719599 0.422330 -0.000750 0 0 0 0.017260\n")
    rel = load_relations(p)
    assert len(rel) == 2
    assert rel.t1_ns.tolist() == [1_134_864_645_903_210_000, 90_239_599_000]
    assert rel.t2_ns.tolist() == [1_134_864_646_324_200_000, 90_719_599_000]
    np.testing.assert_allclose(rel.dx, [0.31293, 0.422330])
    np.testing.assert_allclose(rel.dy, [0.02935, -0.000750])
    np.testing.assert_allclose(rel.dyaw, [0.24198, 0.017260])


def test_load_relations_errors_name_file_and_line(tmp_path: Path) -> None:
    p = _write(tmp_path / "bad.relations", "1 2 0 0 0 0 0 0\n1 2 0 0 0 0\n")
    with pytest.raises(GndReplayError, match=r"bad\.relations line 2: expected 8 numbers .* found 6"):
        load_relations(p)
    p = _write(tmp_path / "nan.relations", "1 2 x 0 0 0 0 0\n")
    with pytest.raises(GndReplayError, match=r"nan\.relations line 1: not a number"):
        load_relations(p)
    with pytest.raises(GndReplayError, match=r"missing\.relations: relations file not found"):
        load_relations(tmp_path / "missing.relations")


def _relations_file(tmp_path: Path, rows: list[tuple[int, int, float, float, float]]) -> Path:
    lines = [f"{a // 10**9}.{a % 10**9:09d} {b // 10**9}.{b % 10**9:09d} {x!r} {y!r} 0 0 0 {th!r}\n"
             for a, b, x, y, th in rows]
    return _write(tmp_path / "r.relations", "".join(lines))


def test_relation_errors_exact_trajectory_is_zero(tmp_path: Path) -> None:
    t = T0 + np.arange(5, dtype=np.int64) * 200_000_000
    poses = np.array([[0, 0, 0], [1, 0, 0.5], [2, 1, 1.0], [2, 3, 2.5], [0, 3, -3.0]], dtype=float)
    rows = []
    for i, j in [(0, 1), (1, 3), (0, 4), (2, 4)]:
        d = relative(poses[i], poses[j])
        rows.append((int(t[i]), int(t[j]), float(d[0]), float(d[1]), float(d[2])))
    rel = load_relations(_relations_file(tmp_path, rows))
    s = relation_errors(t[::-1], poses[::-1], rel)  # any order
    assert (s.matched, s.unmatched) == (4, 0)
    assert s.trans_max_m < 1e-12 and s.rot_max_deg < 1e-9


def test_relation_errors_known_answer(tmp_path: Path) -> None:
    # estimated: second pose 0.1 m too far ahead and 2 deg over-rotated, in the frame of the first
    t = np.array([T0, T0 + 10**8], dtype=np.int64)
    poses = np.array([[5.0, 5.0, math.pi / 2], [5.0, 6.1, math.pi / 2 + math.radians(2.0)]])
    rel = load_relations(_relations_file(tmp_path, [(T0, T0 + 10**8, 1.0, 0.0, 0.0)]))
    s = relation_errors(t, poses, rel)
    assert s.matched == 1
    assert s.trans_mean_m == pytest.approx(0.1, abs=1e-9)
    assert s.rot_mean_deg == pytest.approx(2.0, abs=1e-9)
    assert s.trans_std_m == 0.0 and s.trans_max_m == pytest.approx(0.1, abs=1e-9)


def test_relation_errors_rotation_wraps(tmp_path: Path) -> None:
    t = np.array([T0, T0 + 10**8], dtype=np.int64)
    poses = np.array([[0.0, 0.0, math.radians(179.0)], [0.0, 0.0, math.radians(-179.0)]])
    rel = load_relations(_relations_file(tmp_path, [(T0, T0 + 10**8, 0.0, 0.0, math.radians(1.0))]))
    assert relation_errors(t, poses, rel).rot_mean_deg == pytest.approx(1.0, abs=1e-6)


def test_relation_errors_stamp_tolerance(tmp_path: Path) -> None:
    t = np.array([T0, T0 + 10**8], dtype=np.int64)
    poses = np.zeros((2, 3))
    rows = [(T0 + 90_000, T0 + 10**8 - 90_000, 0.0, 0.0, 0.0),  # within 1e-4 s
            (T0 + 110_000, T0 + 10**8, 0.0, 0.0, 0.0),  # 1.1e-4 s off: unmatched
            (T0 - 10**9, T0, 0.0, 0.0, 0.0)]  # before the log
    rel = load_relations(_relations_file(tmp_path, rows))
    s = relation_errors(t, poses, rel)
    assert (s.matched, s.unmatched) == (1, 2)
    assert s.index.tolist() == [0]
    assert (relation_errors(t, poses, rel, tol_s=2e-4).matched) == 2


def test_relation_errors_nothing_matched(tmp_path: Path) -> None:
    rel = load_relations(_relations_file(tmp_path, [(T0, T0 + 1, 0.0, 0.0, 0.0)]))
    s = relation_errors(np.array([5], dtype=np.int64), np.zeros((1, 3)), rel)
    assert (s.matched, s.unmatched) == (0, 1) and math.isnan(s.trans_mean_m)
    assert s.to_dict()["unmatched"] == 1


def test_relation_errors_split_by_span(tmp_path: Path) -> None:
    """Local accuracy and drift read apart: each relation counts in the span of |t2 - t1|."""
    t = T0 + np.array([0, 5 * 10**8, 3 * 10**9, 30 * 10**9], dtype=np.int64)
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    rows = [(int(t[0]), int(t[1]), 0.9, 0.0, 0.0),  # 0.5 s: 0.1 m off
            (int(t[1]), int(t[0]), -1.0, 0.0, math.radians(4.0)),  # -0.5 s (any order): 4 deg off
            (int(t[0]), int(t[2]), 2.0, 0.3, 0.0),  # 3 s: 0.3 m off
            (int(t[0]), int(t[3]), 3.0, 0.0, math.radians(-1.0))]  # 30 s: 1 deg off
    s = relation_errors(t, poses, load_relations(_relations_file(tmp_path, rows)))
    near, mid, far = s.by_span
    assert [x.label for x in s.by_span] == ["<1 s", "1-10 s", ">10 s"] and s.span("1-10 s") is mid
    assert (near.count, mid.count, far.count) == (2, 1, 1)
    assert near.trans_mean_m == pytest.approx(0.05) and near.rot_max_deg == pytest.approx(4.0)
    assert mid.trans_mean_m == pytest.approx(0.3) and far.rot_mean_deg == pytest.approx(1.0)
    assert [d["count"] for d in s.to_dict()["by_span"]] == [2, 1, 1]
    none = relation_errors(t[:2], poses[:2], load_relations(_relations_file(tmp_path, rows[:2])))
    assert none.span(">10 s").count == 0 and math.isnan(none.span(">10 s").trans_mean_m)
    with pytest.raises(KeyError):
        s.span("2 s")


def test_relations_from_a_reference_trajectory() -> None:
    """A decimated run scored against the full-rate trajectory: relations between poses 1 and 2 apart; the
    reference trajectory itself scores zero."""
    t = T0 + np.arange(4, dtype=np.int64) * 10**8
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [2.0, 1.0, 1.0], [2.0, 3.0, 2.5]])
    rel = relations_from_trajectory(t, poses, (1, 2))
    assert len(rel) == 3 + 2
    assert rel.t1_ns.tolist() == [*t[:3].tolist(), *t[:2].tolist()]
    np.testing.assert_allclose([rel.dx[0], rel.dy[0], rel.dyaw[0]], relative(poses[0], poses[1]))
    s = relation_errors(t, poses, rel)
    assert s.matched == 5 and s.trans_max_m < 1e-12
    assert len(relations_from_trajectory(t, poses, (10,))) == 0
    with pytest.raises(ValueError, match="steps must be positive"):
        relations_from_trajectory(t, poses, (0,))


def test_relation_errors_shape_error(tmp_path: Path) -> None:
    rel = load_relations(_relations_file(tmp_path, [(T0, T0 + 1, 0.0, 0.0, 0.0)]))
    with pytest.raises(ValueError, match=r"poses must be \(N, 3\)"):
        relation_errors(np.array([T0]), np.zeros((2, 3)), rel)


def test_write_tum_round_trip_full_precision(tmp_path: Path) -> None:
    t = np.array([T0, T0 + 123_456_789, 70_289_900_000], dtype=np.int64)
    poses = np.array([[576.536523, 0.106594, -2.255213], [1e-9, -3.5, math.pi], [0.0, 0.0, 0.1]])
    path = tmp_path / "traj.tum"
    write_tum(path, t, poses)
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    assert lines[0].split()[0] == "1134864629.895182000"
    assert lines[1].split()[0] == "1134864630.018638789"
    data = np.loadtxt(path)
    np.testing.assert_array_equal(data[:, 1:3], poses[:, :2])
    np.testing.assert_array_equal(data[:, 3], 0.0)
    np.testing.assert_allclose(data[:, 4:6], 0.0)
    yaw = 2.0 * np.arctan2(data[:, 6], data[:, 7])
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - poses[:, 2]))), 0.0, atol=1e-12)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["traj.tum"]  # no temporary file left


def test_write_tum_is_deterministic(tmp_path: Path) -> None:
    t = np.array([1, 2], dtype=np.int64)
    poses = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    write_tum(tmp_path / "a.tum", t, poses)
    write_tum(tmp_path / "b.tum", t, poses)
    assert (tmp_path / "a.tum").read_bytes() == (tmp_path / "b.tum").read_bytes()


def test_write_tum_shape_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"poses must be \(N, 3\)"):
        write_tum(tmp_path / "x.tum", np.array([1, 2]), np.zeros((2, 2)))


# ---- SE(2) ATE / RPE against ground truth ---------------------------------------------------------------


def _truth_path(n: int = 200, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A wandering planar path at 10 Hz: stamps [ns] and (n, 3) poses."""
    rng = np.random.default_rng(seed)
    t = T0 + np.arange(n, dtype=np.int64) * 100_000_000
    yaw = np.cumsum(rng.normal(0.0, 0.05, n))
    x = np.cumsum(0.1 * np.cos(yaw))
    y = np.cumsum(0.1 * np.sin(yaw))
    return t, np.column_stack([x, y, yaw])


def _umeyama_se3(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Independent reference: Umeyama's SE(3) fit (no scale) of (N, 3) points p onto q (SVD)."""
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    u, _, vt = np.linalg.svd((q - mq).T @ (p - mp))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    return r, mq - r @ mp


def test_se2_alignment_recovers_a_known_transform() -> None:
    t, truth = _truth_path()
    known = np.array([3.0, -2.0, 0.7])
    est = compose(known, truth)  # the truth seen from another frame
    inv = inverse(known)
    np.testing.assert_allclose(align_se2(est[:, :2], truth[:, :2]), inv, atol=1e-9)
    e = trajectory_errors(t, est, t, truth)
    assert e.matched == 200 and e.unmatched == 0
    np.testing.assert_allclose(e.transform, inv, atol=1e-9)
    assert e.ate_max_m < 1e-9 and e.ate_rmse_m < 1e-9
    assert e.rpe_trans_max_m < 1e-9 and e.rpe_rot_max_deg < 1e-6
    o = trajectory_errors(t, est, t, truth, alignment="origin")  # first poses put together: also exact
    assert o.ate_max_m < 1e-9


def test_constant_offset_gives_that_ate() -> None:
    t, truth = _truth_path()
    est = truth + np.array([0.3, -0.4, 0.0])  # 0.5 m off everywhere, in the world frame
    unaligned = trajectory_errors(t, est, t, truth, alignment="origin")
    assert unaligned.ate_rmse_m == pytest.approx(0.0, abs=1e-9)  # the first pose absorbs a constant offset
    shifted = est.copy()
    shifted[100:, :2] += [0.3, -0.4]  # half the run another 0.5 m off
    e = trajectory_errors(t, shifted, t, est, alignment="origin")
    assert e.ate_median_m == pytest.approx(0.25) and e.ate_max_m == pytest.approx(0.5)
    assert e.ate_mean_m == pytest.approx(0.25) and e.ate_rmse_m == pytest.approx(math.sqrt(0.125))
    a = trajectory_errors(t, shifted, t, est)  # the least-squares fit can only do better than the origin
    assert a.ate_rmse_m < e.ate_rmse_m
    assert e.rpe_pairs == a.rpe_pairs == 190  # pairs 1 s apart; 10 of them straddle the step
    assert e.rpe_trans_max_m == pytest.approx(0.5) and e.rpe_trans_mean_m == pytest.approx(5.0 / 190)
    assert a.rpe_trans_mean_m == pytest.approx(e.rpe_trans_mean_m) and e.rpe_rot_max_deg < 1e-9


def test_se2_alignment_matches_se3_umeyama_on_planar_data() -> None:
    t, truth = _truth_path(300, seed=5)
    rng = np.random.default_rng(9)
    est = compose([1.5, 0.5, -2.0], truth) + np.column_stack([rng.normal(0, 0.05, (300, 2)), np.zeros(300)])
    r, tr = _umeyama_se3(np.column_stack([est[:, :2], np.zeros(300)]),
                         np.column_stack([truth[:, :2], np.zeros(300)]))
    aligned3 = (r @ np.column_stack([est[:, :2], np.zeros(300)]).T).T + tr
    ate3 = np.linalg.norm(aligned3 - np.column_stack([truth[:, :2], np.zeros(300)]), axis=1)
    e = trajectory_errors(t, est, t, truth)
    assert abs(r[2, 2] - 1.0) < 1e-12  # planar data: SE(3) Umeyama rotates about z only
    assert e.transform[2] == pytest.approx(math.atan2(r[1, 0], r[0, 0]), abs=1e-12)
    np.testing.assert_allclose(e.transform[:2], tr[:2], atol=1e-9)
    assert e.ate_rmse_m == pytest.approx(float(np.sqrt(np.mean(ate3**2))), rel=1e-9)
    assert e.ate_max_m == pytest.approx(float(ate3.max()), rel=1e-9)
    assert e.ate_median_m == pytest.approx(float(np.median(ate3)), rel=1e-9)


def test_association_nearest_within_tolerance() -> None:
    t_ref = np.array([0, 100, 200, 300], dtype=np.int64) * 1_000_000
    t_est = np.array([305, 2, 150, 99], dtype=np.int64) * 1_000_000  # any order; 150 ms is 50 ms from both
    ie, ir = associate(t_est, t_ref, tol_s=0.01)
    assert ie.tolist() == [1, 3, 0] and ir.tolist() == [0, 1, 3]
    e = trajectory_errors(t_est, np.zeros((4, 3)), t_ref, np.zeros((4, 3)))
    assert e.matched == 3 and e.unmatched == 1


def test_rpe_skips_gaps_and_measures_rotation() -> None:
    t = np.concatenate([np.arange(20), 100 + np.arange(20)]).astype(np.int64) * 100_000_000  # 8 s gap
    truth = np.zeros((40, 3))
    est = truth.copy()
    est[:, 2] = np.radians(np.arange(40) * 0.5)  # drifts 0.5 deg a pose, 5 deg a second
    e = trajectory_errors(t, est, t, truth)
    assert e.rpe_pairs == 20  # 10 pairs 1 s apart in each stretch, none across the gap
    assert e.rpe_rot_max_deg == pytest.approx(5.0) and e.rpe_rot_mean_deg == pytest.approx(5.0)


def test_trajectory_errors_empty_and_bad_input() -> None:
    e = trajectory_errors(np.zeros(0, np.int64), np.zeros((0, 3)), [0], [[0.0, 0.0, 0.0]])
    assert e.matched == 0 and math.isnan(e.ate_rmse_m) and e.rpe_pairs == 0
    assert e.to_dict()["ate_rmse_m"] != e.to_dict()["ate_rmse_m"]  # NaN in JSON
    with pytest.raises(ValueError, match="alignment"):
        trajectory_errors([0], [[0, 0, 0]], [0], [[0, 0, 0]], alignment="sim3")
    np.testing.assert_allclose(align_origin([1.0, 0.0, 0.5], [0.0, 0.0, 0.0]),
                               compose([0, 0, 0], [-np.cos(0.5), np.sin(0.5), -0.5]), atol=1e-12)


def test_heading_error_per_pose_after_the_alignment() -> None:
    t, truth = _truth_path()
    est = truth.copy()
    est[:, 2] += math.radians(2.0)  # the positions agree (identity alignment), the heading is 2 deg off
    est[150:, 2] -= math.radians(5.0)  # ... then 3 deg the other way
    e = trajectory_errors(t, est, t, truth)
    np.testing.assert_allclose(e.transform, 0.0, atol=1e-12)
    np.testing.assert_allclose(e.yaw_err_deg[:150], 2.0, atol=1e-9)
    np.testing.assert_allclose(e.yaw_err_deg[150:], -3.0, atol=1e-9)
    assert e.ate_max_m < 1e-12 and e.yaw_err_deg.shape == e.ate_m.shape == e.t_ns.shape


def _evo_trajectory(t: np.ndarray, poses: np.ndarray) -> object:
    from evo.core import trajectory

    half = 0.5 * poses[:, 2]
    quat = np.column_stack([np.cos(half), np.zeros_like(half), np.zeros_like(half), np.sin(half)])  # w x y z
    return trajectory.PoseTrajectory3D(positions_xyz=np.column_stack([poses[:, :2], np.zeros(len(poses))]),
                                       orientations_quat_wxyz=quat, timestamps=t / 1e9)


def test_ate_and_rpe_match_evo_on_planar_data() -> None:
    """evo (the TUM / KITTI evaluation tool) on the same planar trajectories: its SE(3) Umeyama alignment
    (no scale) then APE of the translation, and RPE over 10 poses (1 s at 10 Hz), all pairs."""
    evo_metrics = pytest.importorskip("evo.core.metrics")
    t, truth = _truth_path(300, seed=11)
    rng = np.random.default_rng(12)
    est = compose([2.0, -1.0, 0.8], truth)  # another frame ...
    est[:, :2] += np.cumsum(rng.normal(0.0, 0.01, (300, 2)), axis=0)  # ... with a random walk
    est[:, 2] += np.cumsum(rng.normal(0.0, 0.002, 300))
    ours = trajectory_errors(t, est, t, truth)
    ref, traj = _evo_trajectory(t, truth), _evo_trajectory(t, est)
    rotation, translation, scale = traj.align(ref, correct_scale=False)  # type: ignore[attr-defined]
    assert scale == 1.0 and abs(rotation[2, 2] - 1.0) < 1e-9  # planar: a rotation about z only
    assert ours.transform[2] == pytest.approx(math.atan2(rotation[1, 0], rotation[0, 0]), abs=1e-9)
    np.testing.assert_allclose(ours.transform[:2], translation[:2], atol=1e-9)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, traj))
    stats = ape.get_all_statistics()
    assert ours.ate_rmse_m == pytest.approx(stats["rmse"], rel=1e-9)
    assert ours.ate_max_m == pytest.approx(stats["max"], rel=1e-9)
    assert ours.ate_median_m == pytest.approx(stats["median"], rel=1e-9)
    for relation, ours_rmse in ((evo_metrics.PoseRelation.translation_part, ours.rpe_trans_rmse_m),
                                (evo_metrics.PoseRelation.rotation_angle_deg, ours.rpe_rot_rmse_deg)):
        rpe = evo_metrics.RPE(relation, delta=10, delta_unit=evo_metrics.Unit.frames, all_pairs=True)
        rpe.process_data((_evo_trajectory(t, truth), _evo_trajectory(t, est)))
        assert ours.rpe_pairs == len(rpe.error)
        assert ours_rmse == pytest.approx(rpe.get_statistic(evo_metrics.StatisticsType.rmse), rel=1e-9)


# ---- the scan matcher's health --------------------------------------------------------------------------


IDC_REASONS = {  # reasons the IDC matcher gives, and their category
    "too few valid beams: 12 < 40": "too few valid beams",
    "too few pairs: 31 < 40": "too few pairs",
    "residual 0.091 m > 0.08 m": "residual",
    "degenerate geometry: translation unobservable (information 1.2 < 5.0)": "degenerate geometry",
    "correction too far from the prior (odometry stalled)": "correction too far from the prior",
    "unconfirmed match: 0.412 m, 3.1 deg from odometry (2.4 sigma) and no better than the match near "
    "odometry": "unconfirmed match",
    "too few pairs: 12 < 40 after a gap of 12.5 s: map restarted": "too few pairs",
}


def test_failure_categories() -> None:
    for reason, category in IDC_REASONS.items():
        assert failure_category(reason) == category, reason
    assert failure_category("") == "" and failure_category("the laser is on fire") == "other"
    assert set(IDC_REASONS.values()) == set(FAILURE_CATEGORIES) and set(FAILURE_CATEGORIES) >= REFUSALS


def _drive(n: int = 201, v: float = 0.3, rate_hz: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Stamps [ns] and poses of a robot driving straight along x at ``v`` m/s."""
    t = T0 + np.arange(n, dtype=np.int64) * round(1e9 / rate_hz)
    x = v * np.arange(n) / rate_hz
    return t, np.column_stack([x, np.zeros(n), np.zeros(n)])


def test_health_of_a_matcher_that_agrees_with_the_odometry() -> None:
    t, odom = _drive()
    h = matcher_health(t, odom, compose([5.0, 1.0, 0.3], odom), np.ones(201, bool), [""] * 201, matcher="m")
    assert h.failed == h.refused == h.after_gap == 0 and h.reasons == {} and h.steps == 200
    assert h.step_trans_m[2] < 1e-9 and h.window_sigmas < 1e-6 and h.warning is None
    assert h.longest_scans == 0 and h.longest_s == 0.0 and math.isnan(h.longest_start_s)
    assert not h.measured and math.isnan(h.ate_odom_m)


def test_health_counts_failures_by_kind_and_the_longest_stretch() -> None:
    t, odom = _drive(21)
    ok = np.ones(21, bool)
    reasons = [""] * 21
    for k, reason in ((3, "too few pairs: 12 < 40"), (4, "unconfirmed match: 1 m"),
                      (5, "degenerate geometry: x"), (10, "too few pairs: 1 < 40 after a gap of 11.0 s: map"),
                      (20, "correction too far from the prior (odometry stalled)")):
        ok[k], reasons[k] = False, reason
    h = matcher_health(t, odom, odom, ok, reasons)
    assert h.failed == 5 and h.refused == 2 and h.after_gap == 1
    assert h.reasons == {"too few pairs": 2, "correction too far from the prior": 1,
                         "degenerate geometry": 1, "unconfirmed match": 1}
    assert h.longest_scans == 3 and h.longest_start_s == pytest.approx(0.3)
    assert h.longest_s == pytest.approx(0.3)  # scans 3, 4, 5: until the accepted match at 0.6 s
    assert h.steps == 15  # accepted matches after the first scan
    tail = matcher_health(t, odom, odom, np.arange(21) < 15, [""] * 15 + ["too few pairs"] * 6)
    assert tail.longest_scans == 6 and tail.longest_s == pytest.approx(0.6)  # to one period past the end


def test_health_step_disagreement_known_answer() -> None:
    """Per scan the odometry says 30 mm straight on, the matcher 33 mm and a 0.5 deg turn (a 10 % wider
    stride on every 4th scan): the disagreement is that increment against the odometry's."""
    t, odom = _drive(101)
    corrected = [np.zeros(3)]
    for k in range(100):
        corrected.append(compose(corrected[-1], [0.033 if k % 4 else 0.06, 0.0, math.radians(0.5)]))
    h = matcher_health(t, odom, np.array(corrected), np.ones(101, bool), [""] * 101)
    assert h.steps == 100
    assert h.step_rot_deg == pytest.approx((0.5, 0.5, 0.5))
    assert h.step_trans_m[0] == pytest.approx(0.003) and h.step_trans_m[2] == pytest.approx(0.03)
    assert h.step_trans_m[1] == pytest.approx(np.percentile([0.03] * 25 + [0.003] * 75, 95))


def test_health_window_beyond_the_odometry_model_warns_estimated() -> None:
    """The matcher stands still for 10 s while the odometry drives 3 m: the worst 5 s window is 1.5 m off,
    against sigma = 0.1 m + 1.5 m / 6 = 0.35 m (4.3 sigmas)."""
    t, odom = _drive()
    corrected = odom.copy()
    corrected[50:150, 0] = corrected[50, 0]
    corrected[150:, 0] -= corrected[150, 0] - corrected[50, 0]
    h = matcher_health(t, odom, corrected, np.ones(201, bool), [""] * 201, matcher="m")
    assert h.window_trans_m == pytest.approx(1.5) and h.window_sigma_m == pytest.approx(0.35)
    assert h.window_sigmas == pytest.approx(1.5 / 0.35) and 5.0 - 1e-9 <= h.window_start_s <= 10.0 + 1e-9
    assert h.warning is not None and h.warning.startswith("scan matcher m likely hurts: its motion disagreed")
    assert "1.50 m" in h.warning and "4.3 sigmas" in h.warning
    assert h.warning.endswith("(estimated: no ground truth)")
    calm = matcher_health(t, odom, corrected, np.ones(201, bool), [""] * 201,
                          params=HealthParams(max_sigmas=4.5))
    assert calm.warning is None  # the limit is the params'


def test_health_failure_share_warns_estimated() -> None:
    t, odom = _drive(10)
    ok = np.array([True] * 7 + [False] * 3)
    h = matcher_health(t, odom, odom, ok, [""] * 7 + ["degenerate geometry: x"] * 2 + ["too few pairs: 1"])
    assert h.failed_share == pytest.approx(0.3) and h.warning is not None
    assert "3 of 10 matches failed (30 %: degenerate geometry 2, too few pairs 1)" in h.warning
    ok[7] = True
    assert matcher_health(t, odom, odom, ok, [""] * 8 + ["x"] * 2).warning is None  # 20 %: not above


def test_health_with_truth_is_measured_and_decides_alone() -> None:
    t, truth = _drive()
    stuck = truth.copy()
    stuck[50:150, 0] = stuck[50, 0]
    stuck[150:, 0] -= stuck[150, 0] - stuck[50, 0]
    all_ok, none = np.ones(201, bool), [""] * 201
    # exact odometry, a matcher that stood still for 10 s: measured worse, by the ATE of the stuck trajectory
    h = matcher_health(t, truth, stuck, all_ok, none, matcher="m", truth=(t, truth))
    want = trajectory_errors(t, stuck, t, truth).ate_rmse_m
    assert h.measured and h.ate_odom_m == pytest.approx(0.0, abs=1e-12)
    assert h.ate_matcher_m == pytest.approx(want)
    assert h.warning == (f"scan matcher m made the trajectory worse than the odometry: aligned ATE RMSE "
                         f"{want:.3f} m against 0.000 m (+{want:.3f} m; measured against the ground truth)")
    # the same disagreement with odometry that drifted and a matcher that was right: no warning
    h = matcher_health(t, stuck, truth, np.zeros(201, bool), ["too few pairs"] * 201, truth=(t, truth))
    assert h.measured and h.window_sigmas > 4.0 and h.failed_share == 1.0 and h.warning is None
    # within the margin (10 % of the odometry's ATE, at least 2 cm): no warning
    worse = truth.copy()
    worse[:, 1] += 0.015 * np.sin(np.arange(201))
    assert matcher_health(t, truth, worse, all_ok, none, truth=(t, truth)).warning is None


def test_health_bad_input() -> None:
    t, odom = _drive(5)
    with pytest.raises(ValueError, match="one entry per pose"):
        matcher_health(t, odom, odom, np.ones(4, bool), [""] * 5)
    with pytest.raises(ValueError, match="poses must be"):
        matcher_health(t, odom, odom[:4], np.ones(5, bool), [""] * 5)
    empty = matcher_health(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool), [])
    assert empty.scans == 0 and empty.warning is None and math.isnan(empty.window_sigmas)
    assert math.isnan(empty.to_dict()["failed_share"])
