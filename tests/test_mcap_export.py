"""report.mcap_export: results.mcap written by McapSink reads back with rosbags, with the right values."""

from __future__ import annotations

import dataclasses
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from gndreplay.geometry import compose
from gndreplay.io.mcap import read_mcap_summary
from gndreplay.pipeline.model import FREE, OCCUPIED, UNKNOWN, GridParams, RobotCentredGrid
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.report import McapSink, grid_to_occupancy
from gndreplay.types import Command, Flag, Mode, Pose2D, Scan, Tick

PERIOD_NS = 200_000_000  # 5 Hz
T0_NS = 1_700_000_000_123_456_789
N = 53  # 10.4 s
LASER = Pose2D(0.72, -0.05, 0.1)


def corrected(k: int) -> Pose2D:
    return Pose2D(0.05 * k, 0.01 * k, 0.02 * k)


def odom(k: int) -> Pose2D:
    return Pose2D(0.05 * k + 1.0, -0.5, 0.02 * k - 0.3)


def tick(k: int) -> Tick:
    angles = np.linspace(-1.5, 1.5, 31)
    scan = Scan(T0_NS + k * PERIOD_NS, np.full(31, 3.0), angles, 8.0, sensor_pose=LASER)
    return Tick(k, scan.t_ns, scan, odom(k))


def result(k: int) -> TickResult:
    p = corrected(k)
    path = np.column_stack([p.x + np.arange(k % 4 + 2) * 0.5, np.full(k % 4 + 2, p.y)])
    t = T0_NS + k * PERIOD_NS
    return TickResult(
        t_ns=t, pose_corrected=p, command=Command(t, 0.01 * k, -0.02 * k),
        mode=Mode.MND if k % 5 == 0 else Mode.MPND, situation=Situation.LS2 if k % 3 else Situation.HSWR,
        flags=Flag.PLANNER_NO_PATH | Flag.EMERGENCY_STOP if k == 7 else Flag.NONE, direction_rad=0.1,
        goal=(p.x + 5.0, p.y - 1.0), path_xy=path,
        timings_ms={"match": 1.5, "model": 0.25, "planner": 3.0 + k, "reactor": 0.5},
        desired_mode="teleop", active_mode="local" if 20 <= k < 24 else "teleop",
        takeover_reason="teleop: swept area occupied (scan)" if 20 <= k < 24 else "",
    )


def grid_at(k: int) -> RobotCentredGrid:
    g = RobotCentredGrid(GridParams(size_cells=12, cell_m=0.25), centre_xy=(corrected(k).x, corrected(k).y))
    g.cells[:, :4] = FREE
    g.cells[2, :] = OCCUPIED
    g.cells[3, 5] = OCCUPIED
    return g


def write(run_dir: Path, sink: McapSink, n: int = N) -> None:
    for k in range(n):
        sink.add_scan(tick(k), corrected(k))
        sink.add_result(tick(k), result(k), grid_at(k))
    sink.finish(run_dir)


@pytest.fixture(scope="module")
def mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("mcap")
    staging = d / "staging"
    staging.mkdir()
    write(d, McapSink(staging_dir=staging))
    assert list(staging.iterdir()) == []  # the staged bag folder is gone
    return d / "results.mcap"


def read_all(path: Path) -> dict[str, list[tuple[int, object]]]:
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path]) as reader:
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype)))
    return out


def stamp_ns(msg: object) -> int:
    s = msg.header.stamp  # type: ignore[attr-defined]
    return s.sec * 10**9 + s.nanosec


def test_message_counts_match_the_ticks(mcap: Path) -> None:
    with AnyReader([mcap]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
    for topic in ("/tf", "/gndreplay/odom", "/cmd_vel", "/gndreplay/path", "/gndreplay/goal",
                  "/gndreplay/timing", "/gndreplay/mode", "/gndreplay/situation", "/gndreplay/flags",
                  "/gndreplay/active_mode", "/gndreplay/takeover"):
        assert counts[topic] == N, topic
    assert types["/gndreplay/active_mode"] == "std_msgs/msg/String"
    assert counts["/gndreplay/grid"] == 11  # 10.4 s at 1 Hz: t = 0, 1, ..., 10
    assert counts["/tf_static"] == 1
    assert types["/cmd_vel"] == "geometry_msgs/msg/TwistStamped"
    assert types["/gndreplay/grid"] == "nav_msgs/msg/OccupancyGrid"
    summary = read_mcap_summary(mcap)
    assert summary.compression == ("zstd",)
    assert summary.start_ns == T0_NS and summary.end_ns == T0_NS + (N - 1) * PERIOD_NS


def test_values_decode(mcap: Path) -> None:
    msgs = read_all(mcap)
    k = 7
    t_log, od = msgs["/gndreplay/odom"][k]
    assert t_log == stamp_ns(od) == T0_NS + k * PERIOD_NS
    assert od.header.frame_id == "map" and od.child_frame_id == "base_link"
    assert (od.pose.pose.position.x, od.pose.pose.position.y) == pytest.approx((0.35, 0.07))
    q = od.pose.pose.orientation
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(0.14)
    assert od.twist.twist.linear.x == pytest.approx(0.07) and od.twist.twist.angular.z == pytest.approx(-0.14)
    _, cmd = msgs["/cmd_vel"][k]
    assert cmd.header.frame_id == "base_link" and cmd.twist.linear.x == pytest.approx(0.07)
    assert msgs["/gndreplay/flags"][k][1].data == "PLANNER_NO_PATH|EMERGENCY_STOP"
    assert msgs["/gndreplay/mode"][5][1].data == "mND" and msgs["/gndreplay/situation"][3][1].data == "HSWR"
    active = [(t, m.data) for t, m in msgs["/gndreplay/active_mode"]]
    assert active == [(T0_NS + j * PERIOD_NS, result(j).active_mode) for j in range(N)]
    assert [j for j, (_, m) in enumerate(msgs["/gndreplay/takeover"]) if m.data] == [20, 21, 22, 23]
    assert msgs["/gndreplay/takeover"][20][1].data == "teleop: swept area occupied (scan)"
    timing = msgs["/gndreplay/timing"][k][1]
    assert timing.data.tolist() == [1.5, 0.25, 10.0, 0.5]
    assert timing.layout.dim[0].label == "match,model,planner,reactor"
    _, goal = msgs["/gndreplay/goal"][k]
    assert (goal.point.x, goal.point.y) == pytest.approx((5.35, -0.93))
    _, path = msgs["/gndreplay/path"][k]
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in path.poses])
    assert path.header.frame_id == "map" and np.allclose(xy, result(k).path_xy)


def test_tf_chain_gives_the_corrected_pose(mcap: Path) -> None:
    msgs = read_all(mcap)
    _, static = msgs["/tf_static"][0]
    (s,) = static.transforms
    assert (s.header.frame_id, s.child_frame_id) == ("base_link", "laser")
    assert (s.transform.translation.x, s.transform.translation.y) == pytest.approx((0.72, -0.05))
    for k in (0, 20, N - 1):
        _, tf = msgs["/tf"][k]
        edges = {(e.header.frame_id, e.child_frame_id): e.transform for e in tf.transforms}
        assert set(edges) == {("map", "odom"), ("odom", "base_link")}

        def pose(tr: object) -> np.ndarray:
            r = tr.rotation  # type: ignore[attr-defined]
            return np.array([tr.translation.x, tr.translation.y, 2 * math.atan2(r.z, r.w)])  # type: ignore[attr-defined]

        assert pose(edges[("odom", "base_link")]) == pytest.approx(odom(k).as_array())
        chained = compose(pose(edges[("map", "odom")]), pose(edges[("odom", "base_link")]))
        assert chained == pytest.approx(corrected(k).as_array(), abs=1e-9)


def test_occupancy_grid_geometry_and_values(mcap: Path) -> None:
    msgs = read_all(mcap)
    stamps = [stamp_ns(m) for _, m in msgs["/gndreplay/grid"]]
    assert stamps == [T0_NS + k * 5 * PERIOD_NS for k in range(11)]
    _, g = msgs["/gndreplay/grid"][2]  # tick 10
    ref = grid_at(10)
    assert g.header.frame_id == "map"
    assert (g.info.width, g.info.height) == (12, 12) and g.info.resolution == pytest.approx(0.25)
    assert (g.info.origin.position.x, g.info.origin.position.y) == pytest.approx(ref.origin_xy)
    data = g.data.reshape(12, 12)  # row-major, row 0 at the origin (minimum y)
    assert data.dtype == np.int8
    assert np.all(data[2] == 100) and data[3, 5] == 100 and data[3, 0] == 0 and data[5, 8] == -1


def test_grid_to_occupancy_mapping() -> None:
    cells = np.array([[UNKNOWN, FREE], [OCCUPIED, FREE]], dtype=np.uint8)
    assert grid_to_occupancy(cells).tolist() == [-1, 0, 100, 0]
    with pytest.raises(ValueError, match="cells must be 2-D"):
        grid_to_occupancy(np.full((2, 2), 3, dtype=np.uint8))


def test_grid_period_and_path_period(tmp_path: Path) -> None:
    write(tmp_path, McapSink(grid_every_s=0.0, path_every_s=2.0, compress=False), n=21)
    with AnyReader([tmp_path / "results.mcap"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/gndreplay/grid"] == 21 and counts["/gndreplay/path"] == 3  # t = 0, 2, 4 s
    assert read_mcap_summary(tmp_path / "results.mcap").compression == ("",)


def test_close_without_finish_removes_the_staging_dir(tmp_path: Path) -> None:
    with McapSink(staging_dir=tmp_path) as sink:
        sink.add_result(tick(0), result(0), grid_at(0))
        assert len(list(tmp_path.iterdir())) == 1
    assert list(tmp_path.iterdir()) == []


def test_empty_run_writes_a_readable_file(tmp_path: Path) -> None:
    McapSink().finish(tmp_path)
    with AnyReader([tmp_path / "results.mcap"]) as reader:
        assert sum(c.msgcount for c in reader.connections) == 0


def test_started_sink_stages_inside_the_run_staging_dir(tmp_path: Path) -> None:
    """run_replay calls start(staging, target): the bag folder lives there (nothing in $TMPDIR), and an
    abort after the staging directory is gone does not raise."""
    staging = tmp_path / "staging"
    staging.mkdir()
    sink = McapSink()
    sink.start(staging, tmp_path / "run")
    sink.add_result(tick(0), result(0), grid_at(0))
    assert [p.name.startswith("gndreplay-mcap-") for p in staging.iterdir()] == [True]
    shutil.rmtree(staging)
    sink.abort()


def test_flags_topic_leaves_out_wall_clock_budget_flags_unless_enforced(tmp_path: Path) -> None:
    """/gndreplay/flags records what commands.csv records (``rundir.recorded_flags``): the *_OVER_BUDGET
    flags depend on the machine's speed, so without enforce_budgets they are left out (timing.csv has
    them)."""
    over = Flag.REACTOR_OVER_BUDGET | Flag.PLANNER_OVER_BUDGET | Flag.EMERGENCY_STOP
    for enforce, expected in ((False, "EMERGENCY_STOP"),
                              (True, "EMERGENCY_STOP|PLANNER_OVER_BUDGET|REACTOR_OVER_BUDGET")):
        d = tmp_path / f"e{int(enforce)}"
        d.mkdir()
        sink = McapSink(staging_dir=d, enforce_budgets=enforce)
        sink.add_scan(tick(1), corrected(1))
        sink.add_result(tick(1), dataclasses.replace(result(1), flags=over), grid_at(1))
        sink.finish(d)
        data = read_all(d / "results.mcap")["/gndreplay/flags"][0][1].data
        assert data == expected
