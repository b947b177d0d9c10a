"""ROS1 / ROS2 (sqlite3, mcap) / bare MCAP reading on small bags written here with the rosbags writers."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gndreplay.errors import LogFormatError
from gndreplay.io import ReadOptions, detect_format, open_log, read_ticks, rosraw
from gndreplay.io.canonical import canonical_stamp
from gndreplay.io.rosbag import RosbagReader, clean_ros_ranges
from gndreplay.types import NS_PER_S, Pose2D

Kind = Literal["ros1", "sqlite3", "mcap"]
KINDS: tuple[Kind, ...] = ("ros1", "sqlite3", "mcap")
T0 = 1_700_000_000 * NS_PER_S + 123_456_789
DT = 100_000_000
BEAMS = 360
A0, INC = -math.pi, 2 * math.pi / BEAMS
V, W = 1.0, 0.5  # the robot drives x = V t, yaw = W t (t in s since T0)
MOUNT = (0.3, 0.05, 0.1)  # base_link -> laser


def typestore(ros1: bool) -> Any:
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # the Noetic store lacks TFMessage
        ts.register(
            get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
        )
    return ts


class Msgs:
    """Planar message builders; t is int ns."""

    def __init__(self, ts: Any, ros1: bool) -> None:
        self.T, self.ros1 = ts.types, ros1

    def __getitem__(self, name: str) -> Any:
        return self.T[name if "/" in name else f"geometry_msgs/msg/{name}"]

    def hdr(self, t: int, frame: str) -> Any:
        stamp = self.T["builtin_interfaces/msg/Time"](sec=t // NS_PER_S, nanosec=t % NS_PER_S)
        return self.T["std_msgs/msg/Header"](**({"seq": 0} if self.ros1 else {}), stamp=stamp, frame_id=frame)

    def v3(self, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
        return self["Vector3"](x=x, y=y, z=z)

    def quat(self, yaw: float) -> Any:
        return self["Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def pose(self, x: float, y: float, yaw: float) -> Any:
        return self["Pose"](position=self["Point"](x=x, y=y, z=0.0), orientation=self.quat(yaw))

    def twist(self, v: float, w: float) -> Any:
        return self["Twist"](linear=self.v3(x=v, y=0.01), angular=self.v3(z=w))

    def tf(self, t: int, *edges: tuple[str, str, float, float, float]) -> Any:
        return self["tf2_msgs/msg/TFMessage"](
            transforms=[
                self["TransformStamped"](
                    header=self.hdr(t, p),
                    child_frame_id=c,
                    transform=self["Transform"](translation=self.v3(x, y), rotation=self.quat(yaw)),
                )
                for p, c, x, y, yaw in edges
            ]
        )

    def odom(self, t: int, x: float, y: float, yaw: float, frame: str = "base_link") -> Any:
        cov = np.zeros(36)
        return self["nav_msgs/msg/Odometry"](
            header=self.hdr(t, "odom"),
            child_frame_id=frame,
            pose=self["PoseWithCovariance"](pose=self.pose(x, y, yaw), covariance=cov),
            twist=self["TwistWithCovariance"](twist=self.twist(V, W), covariance=cov),
        )

    def scan(self, t: int, ranges: np.ndarray, frame: str = "laser") -> Any:
        return self["sensor_msgs/msg/LaserScan"](
            header=self.hdr(t, frame),
            angle_min=A0,
            angle_max=A0 + INC * (len(ranges) - 1),
            angle_increment=INC,
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.1,
            range_max=30.0,
            ranges=np.asarray(ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )


def ranges_for(i: int) -> np.ndarray:
    r = 5.0 + 0.01 * i + 0.001 * np.arange(BEAMS)
    r[:5] = [np.nan, np.inf, 0.05, 35.0, -1.0]
    return r


def robot(t: int) -> tuple[float, float, float]:
    s = (t - T0) / NS_PER_S
    return V * s, 0.0, W * s


@dataclass(frozen=True)
class Spec:
    n: int = 12
    scan_topics: tuple[str, ...] = ("/scan",)
    odom: bool = True
    tf_odom: bool = True
    tf_static: bool = True
    cmd: str | None = None  # "Twist" | "TwistStamped"
    cmd_topics: tuple[str, ...] = ("/cmd_vel",)
    truth: bool = False
    zero_stamps: bool = False
    garbage_at: int | None = None  # index of a /scan message replaced by junk bytes


def write_bag(tmp: Path, kind: Kind, spec: Spec = Spec(), name: str = "fix") -> Path:
    ros1 = kind == "ros1"
    ts = typestore(ros1)
    m = Msgs(ts, ros1)
    ser: Callable[[Any, str], bytes] = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    path = tmp / (f"{name}.bag" if ros1 else name)
    writer: Any = (
        Writer1(path)
        if ros1
        else Writer2(
            path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        )
    )
    scan_t, odom_t = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
    tf_t, twist_t = "tf2_msgs/msg/TFMessage", f"geometry_msgs/msg/{spec.cmd}"
    with writer as w:
        conns: dict[str, Any] = {tp: w.add_connection(tp, scan_t, typestore=ts) for tp in spec.scan_topics}
        if spec.odom:
            conns["/odom"] = w.add_connection("/odom", odom_t, typestore=ts)
        if spec.tf_odom:
            conns["/tf"] = w.add_connection("/tf", tf_t, typestore=ts)
        if spec.tf_static:
            conns["/tf_static"] = w.add_connection("/tf_static", tf_t, typestore=ts)
            w.write(conns["/tf_static"], T0 - DT, ser(m.tf(T0 - DT, ("base_link", "laser", *MOUNT)), tf_t))
        if spec.cmd:
            for tp in spec.cmd_topics:
                conns[tp] = w.add_connection(tp, twist_t, typestore=ts)
        if spec.truth:
            conns["/ground_truth"] = w.add_connection("/ground_truth", odom_t, typestore=ts)
        for k in range(spec.n + 1):  # odometry at T0 - 50 ms + k DT: brackets every scan
            t = T0 - DT // 2 + k * DT
            if spec.odom:
                w.write(conns["/odom"], t + 1_000_000, ser(m.odom(t, *robot(t)), odom_t))
            if spec.tf_odom:
                w.write(conns["/tf"], t + 1_000_000, ser(m.tf(t, ("odom", "base_link", *robot(t))), tf_t))
        for i in range(spec.n):
            t = T0 + i * DT
            stamp = 0 if spec.zero_stamps else t
            for tp in spec.scan_topics:
                raw = ser(m.scan(stamp, ranges_for(i)), scan_t)
                if i == spec.garbage_at:
                    raw = raw[:20]
                w.write(conns[tp], t + 10_000_000, raw)  # log time 10 ms after the stamp
            if spec.cmd == "Twist":
                for tp in spec.cmd_topics:
                    w.write(conns[tp], t + 5_000_000, ser(m.twist(0.1 * i, -0.1 * i), twist_t))
            elif spec.cmd == "TwistStamped":
                msg = m["TwistStamped"](header=m.hdr(t, "base_link"), twist=m.twist(0.1 * i, -0.1 * i))
                w.write(conns[spec.cmd_topics[0]], t + 5_000_000, ser(msg, twist_t))
            if spec.truth:
                x, _, yaw = robot(t)
                w.write(conns["/ground_truth"], t, ser(m.odom(t, 2 * x, 1.0, yaw), odom_t))
    return path


@pytest.fixture(params=KINDS)
def kind(request: pytest.FixtureRequest) -> Kind:
    return request.param  # type: ignore[no-any-return]


# ------------------------------------------------------------------------------------------------------------


def expected_ranges(i: int) -> np.ndarray:
    r = ranges_for(i).astype(np.float32).astype(np.float64)
    r[[0, 2, 4]] = np.nan
    r[[1, 3]] = np.inf
    return r


def check_ticks(ticks: list[Any], n: int) -> None:
    assert len(ticks) == n
    for i, tick in enumerate(ticks):
        assert tick.index == i
        assert tick.t_ns == canonical_stamp(T0 + i * DT)  # the header stamp, not the log time
        np.testing.assert_array_equal(tick.scan.ranges_m, expected_ranges(i))
        np.testing.assert_allclose(tick.scan.angles_rad, A0 + INC * np.arange(BEAMS), atol=1e-6)
        assert (tick.scan.min_range_m, tick.scan.max_range_m) == (pytest.approx(0.1), 30.0)
        x, y, yaw = robot(tick.t_ns)  # on the microsecond clock: within 0.5 us of motion of the stamp's
        assert (tick.odom.x, tick.odom.y, tick.odom.theta) == (
            pytest.approx(x, abs=1e-6),
            pytest.approx(y, abs=1e-12),
            pytest.approx(yaw, abs=1e-6),
        )
        sp = tick.scan.sensor_pose
        assert (sp.x, sp.y, sp.theta) == (
            pytest.approx(MOUNT[0]),
            pytest.approx(MOUNT[1]),
            pytest.approx(MOUNT[2]),
        )


def test_scans_and_odometry_from_an_odometry_topic(tmp_path: Path, kind: Kind) -> None:
    bag = write_bag(tmp_path, kind, Spec(tf_odom=False))
    with open_log(bag) as log:
        ticks = list(log.ticks())
        desc, rep = log.describe(), log.report
        assert log.format_name == ("rosbag1" if kind == "ros1" else "rosbag2")
    check_ticks(ticks, 12)
    assert desc.odom_source == "/odom" and desc.scan_stream == "/scan"
    assert {s.name: s.count for s in desc.streams} == {"/scan": 12, "/odom": 13, "/tf_static": 1}
    assert "tf base_link -> laser" in desc.notes[0]
    assert rep.scans == 12 and rep.scans_without_odom_before == 0 and rep.scans_without_odom_after == 0
    assert all(t.cmd is None and t.truth is None for t in ticks)


def test_odometry_from_tf_only(tmp_path: Path, kind: Kind) -> None:
    bag = write_bag(tmp_path, kind, Spec(odom=False))
    with open_log(bag) as log:
        ticks = list(log.ticks())
        assert log.describe().odom_source == "/tf odom -> base_link"
    check_ticks(ticks, 12)


def test_tf_can_be_chosen_over_an_odometry_topic(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "mcap")
    with open_log(bag, options=ReadOptions(odom_topic="/tf")) as log:
        check_ticks(list(log.ticks()), 12)
        assert log.describe().odom_source.startswith("/tf")


def test_bare_mcap_file_reads_like_the_folder(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "mcap")
    (mcap,) = bag.glob("*.mcap")
    assert detect_format(mcap) == ("mcap", mcap)
    with open_log(mcap) as log:
        assert log.format_name == "mcap"
        check_ticks(list(log.ticks()), 12)


def test_a_db3_inside_a_ros2_bag_opens_the_folder(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "sqlite3")
    (db3,) = bag.glob("*.db3")
    assert detect_format(db3) == ("rosbag2", bag)


def test_twist_commands_use_the_log_time(tmp_path: Path, kind: Kind) -> None:
    ticks = list(read_ticks(write_bag(tmp_path, kind, Spec(cmd="Twist"))))
    assert ticks[0].cmd is None  # the first command is logged 5 ms after the first scan
    for i, tick in enumerate(ticks[1:], start=1):
        assert tick.cmd is not None
        assert (tick.cmd.v_mps, tick.cmd.w_radps, tick.cmd.vy_mps) == (
            pytest.approx(0.1 * (i - 1)),
            pytest.approx(-0.1 * (i - 1)),
            pytest.approx(0.01),
        )


def test_twist_stamped_commands_use_the_header_stamp(tmp_path: Path) -> None:
    ticks = list(read_ticks(write_bag(tmp_path, "ros1", Spec(cmd="TwistStamped"))))
    assert [round(t.cmd.v_mps, 6) for t in ticks] == [round(0.1 * i, 6) for i in range(12)]


def test_ground_truth_topic_is_detected_and_interpolated(tmp_path: Path, kind: Kind) -> None:
    with open_log(write_bag(tmp_path, kind, Spec(truth=True))) as log:
        assert log.describe().truth_stream == "/ground_truth"
        assert log.describe().odom_source == "/odom"
        ticks = list(log.ticks())
    for tick in ticks:
        x, _, yaw = robot(tick.t_ns)
        assert tick.truth == Pose2D(pytest.approx(2 * x, abs=1e-6), 1.0, pytest.approx(yaw, abs=1e-6))


def test_bag_without_odometry_gives_the_identity(tmp_path: Path) -> None:
    with open_log(write_bag(tmp_path, "ros1", Spec(odom=False, tf_odom=False, tf_static=False))) as log:
        assert log.describe().odom_source == "none"
        ticks = list(log.ticks())
    assert all(t.odom == Pose2D(0.0, 0.0, 0.0) for t in ticks)
    assert ticks[0].scan.sensor_pose == Pose2D(0.0, 0.0, 0.0)


def test_zero_header_stamps_fall_back_to_the_log_time(tmp_path: Path) -> None:
    with open_log(write_bag(tmp_path, "sqlite3", Spec(zero_stamps=True))) as log:
        ticks = list(log.ticks())
        rep = log.report
    assert [t.t_ns for t in ticks] == [canonical_stamp(T0 + i * DT + 10_000_000) for i in range(12)]
    assert any("zero header stamp" in w for w in rep.warnings)


def test_ranges_conversion() -> None:
    r = clean_ros_ranges(
        np.array([1.0, np.nan, np.inf, -np.inf, 0.01, 30.0, 29.9, -3.0], np.float32), 0.1, 30.0
    )
    np.testing.assert_array_equal(r, [1.0, np.nan, np.inf, np.nan, np.nan, np.inf, np.float32(29.9), np.nan])
    assert r.dtype == np.float64


def test_raw_header_stamp_matches_the_decoded_one(tmp_path: Path, kind: Kind) -> None:
    with open_log(write_bag(tmp_path, kind)) as log:
        assert isinstance(log, RosbagReader)
        stamps = [log.header_stamp(raw) for _, raw in log.raw_messages("/scan")]
    assert stamps == [T0 + i * DT for i in range(12)]


# ------------------------------------------------------------------------------------------------------------
# topic choice and errors


def test_several_scan_topics_must_be_chosen(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "ros1", Spec(scan_topics=("/front", "/rear")))
    with pytest.raises(
        LogFormatError,
        match=r"several scan topics, choose one: --scan-topic /front, "
        r"--scan-topic /rear",
    ):
        open_log(bag)
    with pytest.raises(LogFormatError, match=r"no scan topic '/nope'; candidates: --scan-topic /front"):
        open_log(bag, options=ReadOptions(scan_topic="/nope"))
    with open_log(bag, options=ReadOptions(scan_topic="/rear")) as log:
        assert log.describe().scan_stream == "/rear"
        assert len(list(log.ticks())) == 12


def test_the_conventional_name_wins_among_several(tmp_path: Path) -> None:
    bag = write_bag(
        tmp_path,
        "mcap",
        Spec(scan_topics=("/scan", "/scan_filtered"), cmd="Twist", cmd_topics=("/cmd_vel", "/teleop")),
    )
    with open_log(bag) as log:
        assert log.describe().scan_stream == "/scan"
        assert log.describe().cmd_stream == "/cmd_vel"


def test_ambiguous_command_topics(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "ros1", Spec(cmd="Twist", cmd_topics=("/a", "/b")))
    with pytest.raises(
        LogFormatError, match=r"several cmd topics, choose one: --cmd-topic /a, --cmd-topic /b"
    ):
        open_log(bag)
    with open_log(bag, options=ReadOptions(cmd_topic="/b")) as log:
        assert log.describe().cmd_stream == "/b"


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        (
            {"odom_topic": "/wheel"},
            r"no odometry topic '/wheel'; candidates: --odom-topic /odom, --odom-topic /tf",
        ),
        ({"cmd_topic": "/cmd"}, r"no cmd topic '/cmd'; candidates: none"),
        ({"truth_topic": "/gt"}, r"no truth topic '/gt'; candidates: none"),
    ],
)
def test_wrong_topics_list_the_candidates(tmp_path: Path, kw: dict[str, str], message: str) -> None:
    with pytest.raises(LogFormatError, match=message):
        open_log(write_bag(tmp_path, "ros1"), options=ReadOptions(**kw))


def test_tf_without_an_odom_transform(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "ros1", Spec(tf_odom=False))
    with pytest.raises(LogFormatError, match=r"no odometry topic '/tf'; candidates: --odom-topic /odom"):
        open_log(bag, options=ReadOptions(odom_topic="/tf"))


def test_bag_without_scans(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "sqlite3", Spec(scan_topics=()))
    with pytest.raises(LogFormatError, match=r"fix: no scans: no sensor_msgs/LaserScan topic in the bag"):
        open_log(bag)


def test_undecodable_message_is_skipped_and_counted_or_strict_error(tmp_path: Path, kind: Kind) -> None:
    bag = write_bag(tmp_path, kind, Spec(garbage_at=3))
    with open_log(bag) as log:
        ticks = list(log.ticks())
        rep = log.report
    assert len(ticks) == 11 and rep.malformed == 1
    assert "on /scan: cannot decode sensor_msgs/msg/LaserScan" in rep.malformed_examples[0]
    with pytest.raises(LogFormatError, match=r"message \d+ on /scan: cannot decode"):
        list(read_ticks(bag, options=ReadOptions(strict=True)))


def test_legacy_bag_is_refused_by_name(tmp_path: Path) -> None:
    p = tmp_path / "old.bag"
    p.write_bytes(b"#ROSRECORD V1.2\nindex_pos=\x00\x00")
    with pytest.raises(LogFormatError, match=r"old\.bag: unsupported legacy ROS bag format V1\.2"):
        open_log(p)


def test_not_a_bag(tmp_path: Path) -> None:
    p = tmp_path / "junk.bag"
    p.write_bytes(b"hello, this is not a bag\n" * 10)
    with pytest.raises(LogFormatError, match=r"junk\.bag: the ROS bag reader \(rosbags\) refuses it"):
        open_log(p)


@pytest.mark.parametrize("kind_", ["ros1", "mcap"])
def test_truncated_bag(tmp_path: Path, kind_: Kind) -> None:
    bag = write_bag(tmp_path, kind_, Spec(n=40))
    target = bag if kind_ == "ros1" else next(bag.glob("*.mcap"))
    data = target.read_bytes()
    target.write_bytes(data[: len(data) // 2])
    with pytest.raises(LogFormatError, match=r"fix(\.bag|\.mcap|): (the ROS bag reader|corrupt)"):
        list(read_ticks(target))


def test_missing_ros2_folder_contents(tmp_path: Path) -> None:
    d = tmp_path / "empty_bag"
    d.mkdir()
    (d / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    with pytest.raises(LogFormatError, match=r"empty_bag: the ROS bag reader \(rosbags\) refuses it"):
        open_log(d)


def test_reader_is_closed_after_a_setup_error(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "ros1", Spec(scan_topics=("/a", "/b")))
    with pytest.raises(LogFormatError):
        RosbagReader(bag)
    with RosbagReader(bag, options=ReadOptions(scan_topic="/a")) as log:  # the file can be opened again
        assert log.describe().scan_stream == "/a"


# ------------------------------------------------------------------------------------------------------------
# the direct decoders agree with rosbags' deserialiser


@pytest.mark.parametrize("ros1", [True, False])
@pytest.mark.parametrize("frame", ["", "l", "base_laser_link"])  # string lengths move the CDR alignment
def test_raw_decoders_match_rosbags(ros1: bool, frame: str) -> None:
    ts = typestore(ros1)
    m = Msgs(ts, ros1)
    ser, de = (ts.serialize_ros1, ts.deserialize_ros1) if ros1 else (ts.serialize_cdr, ts.deserialize_cdr)
    cdr = not ros1
    t = T0 + 987

    scan_t = "sensor_msgs/msg/LaserScan"
    raw = bytes(ser(m.scan(t, ranges_for(3), frame=frame), scan_t))
    f, ref = rosraw.decode_laserscan(raw, cdr), de(raw, scan_t)
    assert (f.stamp_ns, f.frame_id) == (t, frame)
    assert (f.angle_min, f.angle_increment, f.range_min, f.range_max) == (
        ref.angle_min,
        ref.angle_increment,
        ref.range_min,
        ref.range_max,
    )
    np.testing.assert_array_equal(f.ranges, ref.ranges)
    assert rosraw.header_stamp(raw, cdr) == t

    odom_t = "nav_msgs/msg/Odometry"
    raw = bytes(ser(m.odom(t, 1.5, -2.0, 0.7, frame=frame), odom_t))
    o = rosraw.decode_odometry(raw, cdr)
    assert (o.stamp_ns, o.child_frame_id, o.x, o.y, o.vx, o.wz) == (t, frame, 1.5, -2.0, V, W)
    assert rosraw.yaw_of(o.q) == pytest.approx(0.7)

    tf_t = "tf2_msgs/msg/TFMessage"
    raw = bytes(ser(m.tf(t, ("odom", frame, 1.0, 2.0, -3.0), (frame, "x", 0.5, 0.0, 0.1)), tf_t))
    trs = rosraw.decode_tfmessage(raw, cdr)
    assert [(x.parent, x.child, x.x, x.y) for x in trs] == [("odom", frame, 1.0, 2.0), (frame, "x", 0.5, 0.0)]
    assert [round(rosraw.yaw_of(x.q), 9) for x in trs] == [-3.0, 0.1]

    raw = bytes(ser(m.twist(0.4, -0.2), "geometry_msgs/msg/Twist"))
    assert rosraw.decode_twist(raw, cdr, stamped=False) == rosraw.TwistFields(None, 0.4, 0.01, -0.2)
    ps = m["PoseStamped"](header=m.hdr(t, frame), pose=m.pose(3.0, 4.0, 1.0))
    raw = bytes(ser(ps, "geometry_msgs/msg/PoseStamped"))
    p = rosraw.decode_pose_stamped(raw, cdr)
    assert (p.stamp_ns, p.x, p.y, round(rosraw.yaw_of(p.q), 9)) == (t, 3.0, 4.0, 1.0)


def test_truncated_messages_raise_decode_errors() -> None:
    ts = typestore(False)
    raw = bytes(ts.serialize_cdr(Msgs(ts, False).scan(T0, ranges_for(0)), "sensor_msgs/msg/LaserScan"))
    for cut in (3, 10, 20, 60, len(raw) - 8):
        with pytest.raises(rosraw.DECODE_ERRORS):
            rosraw.decode_laserscan(raw[:cut], True)


def test_big_endian_cdr_goes_through_rosbags(tmp_path: Path) -> None:
    ts = typestore(False)
    m = Msgs(ts, False)
    path = tmp_path / "be"
    scan_t, odom_t = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cs, co = (
            w.add_connection("/scan", scan_t, typestore=ts),
            w.add_connection("/odom", odom_t, typestore=ts),
        )
        for k in range(4):
            t = T0 - DT // 2 + k * DT
            w.write(co, t, bytes(ts.serialize_cdr(m.odom(t, *robot(t)), odom_t, little_endian=False)))
        for i in range(3):
            t = T0 + i * DT
            w.write(cs, t + 1, bytes(ts.serialize_cdr(m.scan(t, ranges_for(i)), scan_t, little_endian=False)))
    ticks = list(read_ticks(path))
    assert len(ticks) == 3
    for i, tick in enumerate(ticks):
        np.testing.assert_array_equal(tick.scan.ranges_m, expected_ranges(i))
        assert tick.odom.x == pytest.approx(robot(tick.t_ns)[0], abs=1e-6)


def test_info_counts_an_undecodable_scan_and_strict_refuses_it(tmp_path: Path) -> None:
    from gndreplay.info import log_info

    bag = write_bag(tmp_path, "sqlite3", Spec(garbage_at=3))
    info = log_info(bag)
    assert info.scans == 12 and info.malformed == 1 and info.stats_scans == 11
    assert info.malformed_examples[0].startswith("message 4 on /scan: cannot decode")
    assert (info.scans_without_odom_before, info.scans_without_odom_after) == (0, 0)
    with pytest.raises(LogFormatError, match=r"fix message 4 on /scan: cannot decode"):
        log_info(bag, options=ReadOptions(strict=True))
