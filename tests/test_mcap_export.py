"""report.mcap_export: results.mcap (and its Foxglove layout) read back with rosbags and with mcap: every
topic with its type and count, the log's own ranges, markers in frames tf provides, the values."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import shutil
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from gndreplay.config import Config
from gndreplay.geometry import compose
from gndreplay.io import open_log
from gndreplay.io.carmen import write_carmen
from gndreplay.io.mcap import read_mcap_summary
from gndreplay.pipeline.model import FREE, OCCUPIED, UNKNOWN, GridParams, RobotCentredGrid
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.replay import RunOptions, run_log
from gndreplay.report import LAYOUT_FILE, McapSink, grid_to_occupancy
from gndreplay.report.decision import decision_geometry
from gndreplay.report.foxglove import layout_topics
from gndreplay.report.mcap_export import (
    ARROW,
    DELETEALL,
    LINE_LIST,
    SPHERE,
    TEXT_VIEW_FACING,
    TOPICS,
    TRIANGLE_LIST,
    Marker,
    decision_markers,
    hits_to_occupancy,
    marker_array_cdr,
    path_status,
    region_labels,
    scan_beams,
)
from gndreplay.report.sinks import default_sinks
from gndreplay.robot import footprint_outline
from gndreplay.types import Command, Flag, Mode, Pose2D, Scan, Tick

PERIOD_NS = 200_000_000  # 5 Hz
T0_NS = 1_700_000_000_123_456_789
N = 53  # 10.4 s
LASER = Pose2D(0.72, -0.05, 0.1)
CFG = Config()
SAMPLE_LOG = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
TS = get_typestore(Stores.ROS2_HUMBLE)


def corrected(k: int) -> Pose2D:
    return Pose2D(0.05 * k, 0.01 * k, 0.02 * k)


def odom(k: int) -> Pose2D:
    return Pose2D(0.05 * k + 1.0, -0.5, 0.02 * k - 0.3)


def tick(k: int) -> Tick:
    angles = np.linspace(-1.5, 1.5, 31)
    ranges = np.full(31, 3.0)
    ranges[4] = np.inf
    scan = Scan(T0_NS + k * PERIOD_NS, ranges, angles, 8.0, sensor_pose=LASER)
    return Tick(k, scan.t_ns, scan, odom(k), cmd=Command(scan.t_ns, 0.2, 0.1) if k % 2 else None)


def result(k: int) -> TickResult:
    p = corrected(k)
    path = np.column_stack([p.x + np.arange(k % 4 + 2) * 0.5, np.full(k % 4 + 2, p.y)])
    t = T0_NS + k * PERIOD_NS
    return TickResult(
        t_ns=t, pose_corrected=p, command=Command(t, 0.01 * k, -0.02 * k),
        mode=Mode.EMERGENCY if k == 7 else Mode.MND if k % 5 == 0 else Mode.MPND,
        situation=Situation.LS2 if k % 3 else Situation.HSWR,
        flags=Flag.PLANNER_NO_PATH | Flag.EMERGENCY_STOP if k == 7 else Flag.NONE, direction_rad=0.1,
        goal=(p.x + 5.0, p.y - 1.0), path_xy=path if k != 7 else np.zeros((0, 2)),
        timings_ms={"match": 1.5, "model": 0.25, "planner": 3.0 + k, "reactor": 0.5},
        desired_mode="teleop", active_mode="local" if 20 <= k < 24 else "teleop",
        takeover_reason="teleop: swept area occupied (scan)" if 20 <= k < 24 else "",
        nd_region=(170, 5), nd_target_xy=(1.0, 0.1),
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


def read_all(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype)))
    return out


def connections(path: Path) -> dict[str, tuple[str, int]]:
    """topic -> (type, message count), as rosbags reads them."""
    with AnyReader([path]) as reader:
        return {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}


def stamp_ns(msg: Any) -> int:
    s = msg.header.stamp
    return int(s.sec) * 10**9 + int(s.nanosec)


def yaw(q: Any) -> float:
    return 2 * math.atan2(q.z, q.w)


# ---- a replay of the sample log (the must-show checks) ---------------------------------------------------


@pytest.fixture(scope="module")
def sample_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """``run sample_logs/office.clf.bz2 --until 20 --mcap``, the sinks as the CLI builds them."""
    out = tmp_path_factory.mktemp("sample") / "run"
    cfg = Config()
    sinks = default_sinks(figures=False, mcap=True, enforce_budgets=False, config=cfg)
    summary = run_log(SAMPLE_LOG, cfg, out, options=RunOptions(until_s=20.0), sinks=sinks)
    return out, summary.ticks


def log_ticks(path: Path, n: int) -> list[Tick]:
    with open_log(path) as reader:
        return list(itertools.islice(reader.ticks(), n))


PER_TICK = ("/tf", "/scan", "/odom", "/gndreplay/odom", "/ground_truth", "/cmd_vel", "/gndreplay/footprint",
            "/gndreplay/goal", "/gndreplay/path", "/gndreplay/path_status", "/gndreplay/decision",
            "/gndreplay/mode", "/gndreplay/situation", "/gndreplay/flags", "/gndreplay/active_mode",
            "/gndreplay/takeover")


def test_rosbags_reads_every_topic_with_its_type_and_count(sample_run: tuple[Path, int]) -> None:
    out, ticks = sample_run
    conns = connections(out / "results.mcap")
    assert ticks == 101  # 20 s at 5 Hz
    assert set(conns) == set(TOPICS)
    assert all(conns[t][0] == TOPICS[t] for t in conns)
    for topic in PER_TICK:
        assert conns[topic][1] == ticks, topic
    recorded = sum(t.cmd is not None for t in log_ticks(SAMPLE_LOG, ticks))
    assert 0 < recorded < ticks and conns["/cmd_vel_recorded"][1] == recorded  # from the first non-zero ODOM
    assert conns["/tf_static"][1] == 1  # base_link -> laser and map -> truth, both at the first tick
    assert conns["/gndreplay/map"][1] == 1
    assert 1 <= conns["/gndreplay/grid"][1] <= ticks
    assert "/gndreplay/timing" not in conns  # wall clock: timing.csv


def test_mcap_library_reads_the_log_ranges_back(sample_run: tuple[Path, int]) -> None:
    out, ticks = sample_run
    with open(out / "results.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and reader.get_header().profile == "ros2"
        channels = {c.id: c for c in summary.channels.values()}
        assert {c.topic for c in channels.values()} == set(TOPICS)
        for c in channels.values():
            schema = summary.schemas[c.schema_id]
            assert (c.message_encoding, schema.encoding, schema.name) == ("cdr", "ros2msg", TOPICS[c.topic])
        counts = {channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
        assert all(counts[t] == ticks for t in PER_TICK)
        scans = [(m.log_time, TS.deserialize_cdr(m.data, "sensor_msgs/msg/LaserScan"))
                 for _, _, m in reader.iter_messages(topics=["/scan"])]
    log = log_ticks(SAMPLE_LOG, ticks)
    assert [t for t, _ in scans] == [t.t_ns for t in log]
    for k in (0, 37, ticks - 1):
        msg, scan = scans[k][1], log[k].scan
        assert msg.header.frame_id == "laser" and stamp_ns(msg) == scan.t_ns
        np.testing.assert_array_equal(msg.ranges, scan.ranges_m.astype(np.float32))
        angles = msg.angle_min + msg.angle_increment * np.arange(msg.ranges.size)
        np.testing.assert_allclose(angles, scan.angles_rad, atol=1e-6)
        assert msg.angle_max == pytest.approx(scan.angles_rad[-1])
        assert (msg.range_min, msg.range_max) == (scan.min_range_m, scan.max_range_m)
    assert np.isinf(scans[0][1].ranges).any()  # no return stays +inf


def tf_frames(msgs: dict[str, list[tuple[int, Any]]]) -> tuple[dict[str, tuple[int, str]],
                                                                dict[int, dict[str, str]]]:
    """(static child -> (first stamp, parent), stamp -> {child: parent} of /tf)."""
    static: dict[str, tuple[int, str]] = {}
    for _, m in msgs["/tf_static"]:
        for e in m.transforms:
            static.setdefault(e.child_frame_id, (stamp_ns(e), e.header.frame_id))
    dynamic: dict[int, dict[str, str]] = {}
    for _, m in msgs["/tf"]:
        for e in m.transforms:
            dynamic.setdefault(stamp_ns(e), {})[e.child_frame_id] = e.header.frame_id
    return static, dynamic


def reaches_map(frame: str, t: int, static: dict[str, tuple[int, str]],
                dynamic: dict[int, dict[str, str]]) -> bool:
    """A transform path from ``frame`` to map at stamp ``t`` (static edges from their stamp on)."""
    for _ in range(8):
        if frame == "map":
            return True
        if frame in dynamic.get(t, {}):
            frame = dynamic[t][frame]
        elif frame in static and static[frame][0] <= t:
            frame = static[frame][1]
        else:
            return False
    return False


def test_every_stamped_message_is_in_a_frame_tf_provides_at_its_stamp(sample_run: tuple[Path, int]) -> None:
    """Markers (and every other stamped message) name a frame with a transform path to map at their header
    stamp, which Foxglove's 3D panel needs to draw them."""
    out, ticks = sample_run
    msgs = read_all(out / "results.mcap")
    static, dynamic = tf_frames(msgs)
    assert {c: p for c, (_, p) in static.items()} == {"laser": "base_link", "truth": "map"}
    checked = 0
    for topic, items in msgs.items():
        for _, m in items:
            if topic == "/gndreplay/decision":
                frames = [(mk.header.frame_id, stamp_ns(mk)) for mk in m.markers if mk.action != DELETEALL]
                assert m.markers[0].action == DELETEALL  # the previous tick's markers go
            elif hasattr(m, "header"):
                frames = [(m.header.frame_id, stamp_ns(m))]
            else:
                continue
            for frame, t in frames:
                assert reaches_map(frame, t, static, dynamic), (topic, frame, t)
                checked += 1
    assert checked > 12 * ticks
    namespaces = {mk.ns for _, m in msgs["/gndreplay/decision"] for mk in m.markers}
    assert {"nd_sectors", "nd_gaps", "security_zone", "swept", "direction", "target"} <= namespaces


def test_layout_shows_the_run_and_references_only_topics_present(sample_run: tuple[Path, int]) -> None:
    out, _ = sample_run
    layout = json.loads((out / LAYOUT_FILE).read_text())
    present = set(connections(out / "results.mcap"))
    assert layout_topics(layout) <= present
    panels = layout["configById"]
    scene = panels["3D!scene"]
    assert scene["followTf"] == "base_link"
    assert {"/scan", "/gndreplay/grid", "/gndreplay/map", "/gndreplay/footprint", "/gndreplay/path",
            "/gndreplay/goal", "/gndreplay/decision", "/ground_truth"} <= set(scene["topics"])
    plots = {p["title"]: {s["label"]: s["value"] for s in p["paths"]} for k, p in panels.items()
             if k.startswith("Plot!")}
    assert plots["v [m/s]"] == {"ours": "/cmd_vel.twist.linear.x",
                                "recorded": "/cmd_vel_recorded.twist.linear.x",
                                "odometry": "/odom.twist.twist.linear.x"}
    assert set(plots["w [rad/s]"]) == {"ours", "recorded", "odometry"}
    states = [s["value"] for s in panels["StateTransitions!states"]["paths"]]
    assert "/gndreplay/mode.data" in states and "/gndreplay/path_status.data" in states
    assert panels["RawMessages!gndreplay_flags"]["topicPath"] == "/gndreplay/flags"

    def ids(node: Any) -> set[str]:
        return {node} if isinstance(node, str) else ids(node["first"]) | ids(node["second"])

    assert ids(layout["layout"]) == set(panels)


def test_a_log_without_ground_truth_or_commands_has_neither_topic(tmp_path: Path) -> None:
    """The sample's first 30 scans rewritten without TRUEPOS and with zero ODOM velocities: no
    /ground_truth, no /cmd_vel_recorded, no map -> truth, and the layout does not mention them."""
    log = tmp_path / "bare.clf"
    write_carmen(log, [dataclasses.replace(t, truth=None, cmd=None) for t in log_ticks(SAMPLE_LOG, 30)])
    sinks = default_sinks(figures=False, mcap=True, config=CFG)
    ticks = run_log(log, Config(), tmp_path / "run", options=RunOptions(), sinks=sinks).ticks
    conns = connections(tmp_path / "run" / "results.mcap")
    assert set(TOPICS) - set(conns) == {"/ground_truth", "/cmd_vel_recorded"}
    assert conns["/scan"][1] == ticks == 30 and conns["/tf_static"][1] == 1
    layout = json.loads((tmp_path / "run" / LAYOUT_FILE).read_text())
    assert layout_topics(layout) <= set(conns)
    text = json.dumps(layout)
    assert "/ground_truth" not in text and "/cmd_vel_recorded" not in text


# ---- the sink on synthetic ticks: values ----------------------------------------------------------------


@pytest.fixture(scope="module")
def mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("mcap")
    staging = d / "staging"
    staging.mkdir()
    write(d, McapSink(CFG, grid_every=5, staging_dir=staging))
    assert list(staging.iterdir()) == []  # the staged bag folder is gone
    return d / "results.mcap"


def test_message_counts_match_the_ticks(mcap: Path) -> None:
    conns = connections(mcap)
    for topic in set(PER_TICK) - {"/ground_truth"}:
        assert conns[topic] == (TOPICS[topic], N), topic
    assert "/ground_truth" not in conns
    assert conns["/cmd_vel_recorded"][1] == N // 2  # the odd ticks have a recorded command
    assert conns["/gndreplay/grid"][1] == 11  # ticks 0, 5, ..., 50
    assert conns["/tf_static"][1] == 1 and conns["/gndreplay/map"][1] == 1
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
    assert yaw(od.pose.pose.orientation) == pytest.approx(0.14)
    # the twist: the motion since the previous tick, in the robot frame
    step = np.array([0.05, 0.01])
    c, s = math.cos(0.12), math.sin(0.12)
    body = np.array([c * step[0] + s * step[1], -s * step[0] + c * step[1]])
    assert (od.twist.twist.linear.x, od.twist.twist.linear.y) == pytest.approx(tuple(body / 0.2), abs=1e-9)
    assert od.twist.twist.angular.z == pytest.approx(0.1)
    _, measured = msgs["/odom"][k]
    assert measured.header.frame_id == "odom" and measured.pose.pose.position.x == pytest.approx(1.35)
    assert measured.twist.twist.linear.x == pytest.approx(0.25 * math.cos(0.18), abs=1e-9)
    assert msgs["/odom"][0][1].twist.twist.linear.x == 0.0
    _, cmd = msgs["/cmd_vel"][k]
    assert cmd.header.frame_id == "base_link" and cmd.twist.linear.x == pytest.approx(0.07)
    assert cmd.twist.angular.z == pytest.approx(-0.14)
    _, rec = msgs["/cmd_vel_recorded"][3]  # tick 7
    assert stamp_ns(rec) == T0_NS + k * PERIOD_NS and (rec.twist.linear.x, rec.twist.angular.z) == (0.2, 0.1)
    assert msgs["/gndreplay/flags"][k][1].data == "PLANNER_NO_PATH|EMERGENCY_STOP"
    assert msgs["/gndreplay/path_status"][k][1].data == "PLANNER_NO_PATH"
    assert msgs["/gndreplay/path_status"][k + 1][1].data == "ok"
    assert msgs["/gndreplay/mode"][5][1].data == "mND" and msgs["/gndreplay/situation"][3][1].data == "HSWR"
    active = [(t, m.data) for t, m in msgs["/gndreplay/active_mode"]]
    assert active == [(T0_NS + j * PERIOD_NS, result(j).active_mode) for j in range(N)]
    assert [j for j, (_, m) in enumerate(msgs["/gndreplay/takeover"]) if m.data] == [20, 21, 22, 23]
    _, goal = msgs["/gndreplay/goal"][k]
    assert goal.header.frame_id == "map" and (goal.pose.position.x, goal.pose.position.y) == pytest.approx(
        (5.35, -0.93))
    _, path = msgs["/gndreplay/path"][k + 1]
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in path.poses])
    assert path.header.frame_id == "map" and np.allclose(xy, result(k + 1).path_xy)
    _, fp = msgs["/gndreplay/footprint"][k]
    pts = np.array([[p.x, p.y] for p in fp.polygon.points])
    assert fp.header.frame_id == "base_link" and np.allclose(pts, footprint_outline(CFG.robot))
    _, scan = msgs["/scan"][k]
    assert scan.ranges[4] == np.inf and scan.angle_increment == pytest.approx(0.1)


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

        def pose(tr: Any) -> np.ndarray:
            return np.array([tr.translation.x, tr.translation.y, yaw(tr.rotation)])

        assert pose(edges[("odom", "base_link")]) == pytest.approx(odom(k).as_array())
        chained = compose(pose(edges[("map", "odom")]), pose(edges[("odom", "base_link")]))
        assert chained == pytest.approx(corrected(k).as_array(), abs=1e-9)


def test_ground_truth_frame_starts_on_the_corrected_pose(tmp_path: Path) -> None:
    sink = McapSink(CFG, staging_dir=tmp_path)
    for k in range(4):
        t = dataclasses.replace(tick(k), truth=Pose2D(10.0 + 0.05 * k, 20.0, 1.0 + 0.02 * k))
        sink.add_result(t, result(k), grid_at(k))
    sink.finish(tmp_path)
    msgs = read_all(tmp_path / "results.mcap")
    edges = {e.child_frame_id: e for e in msgs["/tf_static"][0][1].transforms}
    tr = edges["truth"].transform
    map_truth = np.array([tr.translation.x, tr.translation.y, yaw(tr.rotation)])
    _, first = msgs["/ground_truth"][0]
    assert first.header.frame_id == "truth"
    p = first.pose
    assert compose(map_truth, [p.position.x, p.position.y, yaw(p.orientation)]) == pytest.approx(
        corrected(0).as_array(), abs=1e-9)


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


def test_accumulated_map_holds_every_scan_hit_and_shows_from_the_first_tick(mcap: Path) -> None:
    msgs = read_all(mcap)
    ((t, m),) = msgs["/gndreplay/map"]
    assert t == stamp_ns(m) == T0_NS and m.header.frame_id == "map"
    assert m.info.resolution == pytest.approx(0.05)
    data = m.data.reshape(m.info.height, m.info.width)
    hit = data >= 0
    assert hit.any() and set(np.unique(data[hit]).tolist()) <= {25, 50, 75, 100}
    # each scan's hits (3 m from the laser) land in hit cells of the map
    k = 30
    laser = compose(corrected(k).as_array(), LASER.as_array())
    a = laser[2] + np.linspace(-1.5, 1.5, 31)[[0, 30]]
    for x, y in zip(laser[0] + 3.0 * np.cos(a), laser[1] + 3.0 * np.sin(a), strict=True):
        col = int((x - m.info.origin.position.x) // 0.05)
        row = int((y - m.info.origin.position.y) // 0.05)
        assert data[row - 1:row + 2, col - 1:col + 2].max() > 0


def test_hits_to_occupancy_mapping() -> None:
    assert hits_to_occupancy(np.array([[0, 1], [3, 9]], dtype=np.uint32)).tolist() == [-1, 25, 75, 100]


def test_grid_to_occupancy_mapping() -> None:
    cells = np.array([[UNKNOWN, FREE], [OCCUPIED, FREE]], dtype=np.uint8)
    assert grid_to_occupancy(cells).tolist() == [-1, 0, 100, 0]
    with pytest.raises(ValueError, match="cells must be 2-D"):
        grid_to_occupancy(np.full((2, 2), 3, dtype=np.uint8))


def test_grid_on_change_and_path_period(tmp_path: Path) -> None:
    sink = McapSink(path_every_s=2.0, compress=False)
    for k in range(21):
        g = grid_at(0)
        g.cells[7, k // 4] = OCCUPIED  # the grid changes every 4th tick
        sink.add_result(tick(k), result(k), g)
    sink.finish(tmp_path)
    conns = connections(tmp_path / "results.mcap")
    assert conns["/gndreplay/grid"][1] == 6 and conns["/gndreplay/path"][1] == 3  # t = 0, 2, 4 s
    assert "/gndreplay/decision" not in conns and "/gndreplay/footprint" not in conns  # no stack settings
    assert read_mcap_summary(tmp_path / "results.mcap").compression == ("",)
    with pytest.raises(ValueError, match="grid_every"):
        McapSink(grid_every=0)


def test_close_without_finish_removes_the_staging_dir(tmp_path: Path) -> None:
    with McapSink(staging_dir=tmp_path) as sink:
        sink.add_result(tick(0), result(0), grid_at(0))
        assert len(list(tmp_path.iterdir())) == 1
    assert list(tmp_path.iterdir()) == []


def test_empty_run_writes_a_readable_file_and_layout(tmp_path: Path) -> None:
    McapSink().finish(tmp_path)
    assert connections(tmp_path / "results.mcap") == {}
    layout = json.loads((tmp_path / LAYOUT_FILE).read_text())
    assert layout_topics(layout) == set() and layout["layout"] == "3D!scene"


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
    them); by default the stack settings say."""
    over = Flag.REACTOR_OVER_BUDGET | Flag.PLANNER_OVER_BUDGET | Flag.EMERGENCY_STOP
    enforced = dataclasses.replace(CFG, supervisor=dataclasses.replace(CFG.supervisor, enforce_budgets=True))
    for name, sink, expected in (
        ("off", McapSink(enforce_budgets=False), "EMERGENCY_STOP"),
        ("on", McapSink(enforce_budgets=True), "EMERGENCY_STOP|PLANNER_OVER_BUDGET|REACTOR_OVER_BUDGET"),
        ("config", McapSink(enforced), "EMERGENCY_STOP|PLANNER_OVER_BUDGET|REACTOR_OVER_BUDGET"),
    ):
        d = tmp_path / name
        d.mkdir()
        sink.add_result(tick(1), dataclasses.replace(result(1), flags=over), grid_at(1))
        sink.finish(d)
        assert read_all(d / "results.mcap")["/gndreplay/flags"][0][1].data == expected


def test_memory_stays_flat_with_the_log_length(tmp_path: Path) -> None:
    """A stream: four times the ticks do not raise the peak of what the sink allocates (the writer keeps one
    chunk of about 1 MB in memory)."""
    peaks = []
    for n in (100, 400):
        sink = McapSink(CFG, grid_every=1)
        tracemalloc.start()
        for k in range(n):
            sink.add_result(tick(k), result(k), grid_at(k))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        sink.close()
    assert peaks[1] < 1.25 * peaks[0] + (256 << 10), peaks


# ---- the pieces -----------------------------------------------------------------------------------------


def _rosbags_marker_array(t_ns: int, frame: str, markers: list[Marker]) -> bytes:
    T = TS.types
    sec, nsec = divmod(t_ns, 10**9)

    def hdr(s: int, n: int, f: str) -> Any:
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=s, nanosec=n), frame_id=f)

    def point(x: float, y: float, z: float) -> Any:
        return T["geometry_msgs/msg/Point"](x=x, y=y, z=z)

    def rgba(r: float, g: float, b: float, a: float) -> Any:
        return T["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a)

    identity = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    out = [T["visualization_msgs/msg/Marker"](
        header=hdr(sec, nsec, frame), ns=m.ns, id=0, type=m.type, action=m.action,
        pose=T["geometry_msgs/msg/Pose"](position=point(*m.position), orientation=identity),
        scale=T["geometry_msgs/msg/Vector3"](x=m.scale[0], y=m.scale[1], z=m.scale[2]), color=rgba(*m.color),
        lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
        points=[point(*p) for p in m.points.tolist()],
        colors=[] if m.colors is None else [rgba(*c) for c in m.colors.astype(float).tolist()],
        texture_resource="", texture=T["sensor_msgs/msg/CompressedImage"](
            header=hdr(0, 0, ""), format="", data=np.zeros(0, dtype=np.uint8)),
        uv_coordinates=[], text=m.text, mesh_resource="",
        mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8)),
        mesh_use_embedded_materials=False) for m in markers]
    msg = T["visualization_msgs/msg/MarkerArray"](markers=out)
    return bytes(TS.serialize_cdr(msg, "visualization_msgs/msg/MarkerArray"))


@pytest.mark.parametrize(("frame", "text"),
                         [("base_link", ""), ("ab", "E"), ("abc", "SAFE_SLOW"), ("odom", "abc")])
def test_marker_array_bytes_are_rosbags_own(frame: str, text: str) -> None:
    """The MarkerArray encoded from arrays is byte for byte what rosbags serialises (string lengths moving
    the 8-byte alignment of the poses and points around)."""
    rng = np.random.default_rng(1)
    markers = [
        Marker("", ARROW, action=DELETEALL),
        Marker("x", TRIANGLE_LIST, rng.random((6, 3)), rng.random((6, 4)).astype(np.float32)),
        Marker("yy", LINE_LIST, rng.random((3, 3)), color=(0.1, 0.2, 0.3, 0.4), scale=(0.05, 0.0, 0.0)),
        Marker("rule", TEXT_VIEW_FACING, text=text, position=(1.0, 2.0, 3.0)),
        Marker("zzz", SPHERE, position=(0.5, 0.25, 0.0), scale=(0.1, 0.2, 0.3)),
    ]
    t = T0_NS + 3
    assert marker_array_cdr(t, frame, markers) == _rosbags_marker_array(t, frame, markers)


def markers_of(k: int) -> dict[str, Marker]:
    diagram, sweep = decision_geometry(grid_at(k), corrected(k), result(k).command, CFG)
    return {m.ns: m for m in decision_markers(result(k), diagram, sweep, CFG.robot, CFG.reactor.max_range_m)}


def test_decision_markers_draw_the_chosen_region_gaps_and_rule() -> None:
    diagram, sweep = decision_geometry(grid_at(7), corrected(7), result(7).command, CFG)
    n = CFG.reactor.n_sectors
    markers = markers_of(7)
    wedges = markers["nd_sectors"]
    assert wedges.type == TRIANGLE_LIST and wedges.points.shape == (3 * n, 3)
    assert wedges.colors is not None and wedges.colors.shape == (3 * n, 4)
    chosen = diagram.region_mask((170, 5))  # through the wrap
    assert chosen.sum() == 16
    sector_colors = wedges.colors[::3]
    calm = chosen & (diagram.dist_m > diagram.security_m)
    assert calm.any() and np.allclose(sector_colors[calm], sector_colors[calm][0])
    assert sector_colors[calm][0, 1] > sector_colors[calm][0, 0]  # green
    assert not np.isclose(sector_colors[~chosen], sector_colors[calm][0]).all(axis=1).any()
    assert markers["nd_gaps"].points.shape == (2 * int(diagram.gaps.sum()), 3)
    assert markers["rule"].text == "EMERGENCY"
    swept = markers["swept"]
    assert swept.color[0] > swept.color[1]  # red: a reflexive rule replaced the command
    outline = footprint_outline(CFG.robot)
    assert sweep.shape[0] > 1 and swept.points.shape == (min(sweep.shape[0], 6) * 2 * len(outline), 3)
    np.testing.assert_allclose(swept.points[: 2 * len(outline): 2, :2], outline, atol=1e-3)  # the first: now
    assert markers["direction"].points[1, :2] == pytest.approx([math.cos(0.1), math.sin(0.1)], abs=1e-3)
    assert markers["target"].position[:2] == (1.0, 0.1)
    xy = wedges.points[:, :2] * 1024
    assert np.all(xy == np.rint(xy))  # drawn to 1/1024 m
    assert "rule" not in markers_of(8)
    assert markers_of(0)["swept"].points.shape == (0, 3)  # a still command sweeps nothing


def test_region_labels_split_at_gaps_and_join_across_the_wrap() -> None:
    gaps = np.zeros(8, dtype=bool)
    gaps[[1, 4]] = True  # gaps between 1|2 and 4|5: regions {2, 3, 4} and {5, 6, 7, 0, 1}
    assert region_labels(gaps).tolist() == [0, 0, 1, 1, 1, 0, 0, 0]
    gaps[7] = True
    assert region_labels(gaps).tolist() == [0, 0, 1, 1, 1, 2, 2, 2]
    assert region_labels(np.zeros(4, dtype=bool)).tolist() == [0, 0, 0, 0]


def test_scan_beams_keep_even_beams_and_place_uneven_ones_on_a_lattice() -> None:
    a = np.linspace(-1.0, 1.0, 5)
    r = np.array([1.0, np.inf, np.nan, 2.0, 3.0])
    a0, a1, inc, out = scan_beams(a, r)
    assert (a0, a1, inc) == (-1.0, 1.0, 0.5) and out.dtype == np.float32
    np.testing.assert_array_equal(out, r.astype(np.float32))
    assert scan_beams(a[::-1], r)[2] == -0.5  # clockwise
    # a gap (a beam missing) and two beams in one slot: the lattice of the median spacing
    angles = np.array([0.0, 0.1, 0.3, 0.4, 0.401])
    a0, a1, inc, out = scan_beams(angles, np.array([1.0, np.nan, 2.0, 5.0, 4.0]))
    assert (a0, inc, a1) == (0.0, pytest.approx(0.401 / 4), pytest.approx(0.401))  # 5 slots over the span
    np.testing.assert_array_equal(out, np.array([1.0, np.nan, np.nan, 2.0, 4.0], dtype=np.float32))


def test_path_status_says_why_there_is_no_path() -> None:
    empty = dataclasses.replace(result(8), path_xy=np.zeros((0, 2)))
    assert path_status(result(8)) == "ok"
    assert path_status(dataclasses.replace(empty, flags=Flag.GOAL_IN_OBSTACLE | Flag.EMERGENCY_STOP)) == \
        "GOAL_IN_OBSTACLE"
    assert path_status(empty) == "no planner (teleop)"
    assert path_status(dataclasses.replace(empty, desired_mode="gnd")) == "no path"


def test_a_closed_loop_run_writes_results_mcap_the_animation_reads(tmp_path: Path) -> None:
    """``simulate --mcap``: a scenario run has results.mcap with the scan, the decision and a layout; its
    animation (``report --animate``) has one frame per tick of the window."""
    from PIL import Image
    from typer.testing import CliRunner

    from gndreplay.cli import app

    out = tmp_path / "fig3"
    args = ["simulate", "gnd_fig3_passage_closes", "--preset", "xr4000", "--time-limit", "4", "--mcap",
            "--no-figures", "--progress", "none", "--out", str(out)]
    res = CliRunner().invoke(app, args)
    assert res.exit_code in (0, 1), res.output  # a 4 s time limit ends it before the goal
    with AnyReader([out / "results.mcap"]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
    assert topics["/scan"] == "sensor_msgs/msg/LaserScan"
    assert topics["/gndreplay/decision"] == "visualization_msgs/msg/MarkerArray"
    assert layout_topics(json.loads((out / LAYOUT_FILE).read_text())) <= set(topics)
    ticks = len((out / "commands.csv").read_text().splitlines()) - 1
    res = CliRunner().invoke(app, ["report", str(out), "--animate", "--progress", "none"])
    assert res.exit_code == 0, res.output
    with Image.open(out / "animation.gif") as gif:
        assert gif.n_frames == ticks
