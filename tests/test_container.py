"""The same recording in two containers replays alike: a CARMEN log and a ROS bag written from the same data
(stamps through float seconds, headings through quaternions, ranges and bearings at float32, as converters
write them) give identical ticks; the MIT CSAIL log and its four bag conversions give the same corrected
trajectory and the same commands; ``info --against`` names what the ACES bag changed."""

from __future__ import annotations

import csv
import json
import math
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.io import open_log, read_ticks
from gndreplay.io.carmen import write_carmen
from gndreplay.scanmatch import CorrectedTrajectory, correct_trajectory, make_matcher
from gndreplay.types import NS_PER_S, Odometry, Pose2D, Scan, Tick

runner = CliRunner()

# ---------------------------------------------------------------------------------------------------------
# a synthetic pair: a CARMEN log and the bag a converter would write from it

T0 = 1_134_864_629 * NS_PER_S + 895_182_000  # on CARMEN's microsecond clock, as every stamp below
N_SCANS, BEAMS = 60, 181
MOUNT = Pose2D(0.12, -0.03, 0.02)
BEARINGS = -math.pi / 2 + np.arange(BEAMS) * math.radians(1.0)  # readlog.c's geometry for 181 beams


def recording() -> tuple[list[Tick], list[Odometry]]:
    """Scans (ranges in mm, some no-return and invalid beams, jittered stamps) and odometry at twice their
    rate, off their stamps (so the readers interpolate), from a robot driving a curve."""
    rng = np.random.default_rng(7)
    ticks = []
    for i in range(N_SCANS):
        t = T0 + i * 200_000_000 + int(rng.integers(-3000, 3000)) * 1000
        r = np.round(rng.uniform(0.4, 30.0, BEAMS), 3)
        r[rng.integers(0, BEAMS, 5)] = np.inf
        r[rng.integers(0, BEAMS, 2)] = np.nan
        ticks.append(Tick(i, t, Scan(t, r, BEARINGS, 50.0, 0.0, MOUNT), Pose2D(0.0, 0.0, 0.0)))
    odometry = []
    for k in range(2 * N_SCANS + 2):
        t = T0 - 50_000_000 + k * 100_000_000 + 37_000
        s = (t - T0) / NS_PER_S
        pose = Pose2D(round(0.4 * s + 1.234567, 6), round(0.05 * s * s - 2.5, 6),
                      round(math.remainder(0.3 * s + 2.9, 2 * math.pi), 6))
        odometry.append(Odometry(t, pose))
    return ticks, odometry


def via_float_seconds(t_ns: int) -> tuple[int, int]:
    """A stamp as a converter writes it: float seconds, then (sec, nanosec) rounded (``Time.from_sec``)."""
    f = float(t_ns) / 1e9
    sec = int(f)
    return sec, round((f - sec) * 1e9)


def write_converted_bag(path: Path, ticks: list[Tick], odometry: list[Odometry],
                        angle_increment: float | None = None) -> Path:
    """The recording as a ROS 1 bag: LaserScan (float32 ranges, bearings' start and step), Odometry and the
    mounting on /tf_static with quaternion headings, stamps through float seconds, each message recorded a few
    ms after its stamp. ``angle_increment`` replaces the scans' beam step (a converter's own geometry)."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    scan_t, odom_t, tf_t = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"

    def hdr(t: int, frame: str) -> Any:
        sec, nsec = via_float_seconds(t)
        return T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                        frame_id=frame)

    def v3(x: float = 0.0, y: float = 0.0) -> Any:
        return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0)

    def quat(yaw: float) -> Any:
        return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    mount = T[tf_t](transforms=[T["geometry_msgs/msg/TransformStamped"](
        header=hdr(T0 - NS_PER_S, "base_link"), child_frame_id="laser",
        transform=T["geometry_msgs/msg/Transform"](translation=v3(MOUNT.x, MOUNT.y),
                                                   rotation=quat(MOUNT.theta)))])
    cov = np.zeros(36)
    messages: list[tuple[int, str, Any, str]] = [(T0 - NS_PER_S, "/tf_static", mount, tf_t)]
    for o in odometry:
        p = o.pose
        msg = T[odom_t](
            header=hdr(o.t_ns, "odom"), child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=p.x, y=p.y, z=0.0), orientation=quat(p.theta)),
                covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=v3(), angular=v3()), covariance=cov))
        messages.append((o.t_ns + 2_000_000, "/odom", msg, odom_t))
    step = BEARINGS[1] - BEARINGS[0] if angle_increment is None else angle_increment
    for tick in ticks:
        msg = T[scan_t](
            header=hdr(tick.t_ns, "laser"), angle_min=float(np.float32(BEARINGS[0])),
            angle_max=float(np.float32(BEARINGS[0] + step * (BEAMS - 1))),
            angle_increment=float(np.float32(step)),
            time_increment=0.0, scan_time=0.2, range_min=0.0, range_max=50.0,
            ranges=tick.scan.ranges_m.astype(np.float32), intensities=np.zeros(0, dtype=np.float32))
        messages.append((tick.t_ns + 5_000_000, "/scan", msg, scan_t))
    with Writer(path) as w:
        conns = {topic: w.add_connection(topic, msgtype, typestore=ts)
                 for topic, msgtype in (("/tf_static", tf_t), ("/odom", odom_t), ("/scan", scan_t))}
        for t, topic, msg, msgtype in sorted(messages, key=lambda m: m[0]):
            w.write(conns[topic], t, ts.serialize_ros1(msg, msgtype))
    return path


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(the CARMEN log, the converted bag) of :func:`recording`."""
    tmp = tmp_path_factory.mktemp("pair")
    ticks, odometry = recording()
    write_carmen(tmp / "run.clf", ticks, odometry=odometry)
    return tmp / "run.clf", write_converted_bag(tmp / "run.bag", ticks, odometry)


def test_a_carmen_log_and_its_converted_bag_read_as_the_same_ticks(pair: tuple[Path, Path]) -> None:
    clf, bag = pair
    ticks, _ = recording()
    # the conversion moved stamps off the microsecond clock by tens of ns; the readers bring them back
    assert any(s * NS_PER_S + ns != t.t_ns for t in ticks for s, ns in [via_float_seconds(t.t_ns)])
    a, b = list(read_ticks(clf)), list(read_ticks(bag))
    assert len(a) == len(b) == N_SCANS
    for x, y, original in zip(a, b, ticks, strict=True):
        assert x.t_ns == y.t_ns == original.t_ns
        np.testing.assert_array_equal(x.scan.ranges_m, y.scan.ranges_m)  # nan where nan, inf where inf
        np.testing.assert_array_equal(x.scan.angles_rad, y.scan.angles_rad)
        assert x.odom == y.odom and x.scan.sensor_pose == y.scan.sensor_pose == MOUNT
        assert (x.scan.min_range_m, x.scan.max_range_m) == (y.scan.min_range_m, y.scan.max_range_m)
    assert np.isinf(a[0].scan.ranges_m).any() and np.isnan(a[0].scan.ranges_m).any()
    # odometry was interpolated between samples, not copied from one
    assert a[3].odom.x not in {o.pose.x for o in recording()[1]}


def test_info_against_finds_no_difference_in_a_faithful_conversion(pair: tuple[Path, Path]) -> None:
    clf, bag = pair
    res = runner.invoke(app, ["info", str(clf), "--against", str(bag)])
    assert res.exit_code == 0, res.output
    assert res.stdout.rstrip().endswith(f"against {bag} (rosbag1): no difference in what a replay reads")
    d = json.loads(runner.invoke(app, ["info", str(clf), "--against", str(bag), "--json"]).stdout)
    assert d["scans"] == N_SCANS
    assert d["against"] == {"path": str(bag), "format": "rosbag1", "replay_differs": False, "differences": []}


def test_info_against_names_a_converters_own_beam_step(pair: tuple[Path, Path], tmp_path: Path) -> None:
    """A converter spacing the 181 beams over 181 degrees instead of 180."""
    clf, _ = pair
    ticks, odometry = recording()
    bag = write_converted_bag(tmp_path / "wide.bag", ticks, odometry, angle_increment=math.radians(181 / 180))
    res = runner.invoke(app, ["info", str(clf), "--against", str(bag)], env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    at = lines.index(f"against {bag} (rosbag1): 2 differences in what a replay reads (this log's value "
                     "against the other's)")
    assert lines[at + 1].startswith("  last bearing: 90.0000 deg against 91.0000 deg; the last beam points "
                                    "1.00 deg apart")
    assert lines[at + 2].startswith("  beam step: 1.0000 deg against 1.0056 deg; the bearings are up to 1.00 "
                                    "deg apart (at the last beam)")
    assert "corrected trajectories will differ" in lines[at + 2] and len(lines) == at + 3


def test_info_against_an_unreadable_log_is_one_line_exit_2(pair: tuple[Path, Path], tmp_path: Path) -> None:
    clf, _ = pair
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)))
    for other in (junk, tmp_path / "missing.bag"):
        res = runner.invoke(app, ["info", str(clf), "--against", str(other)])
        assert res.exit_code == 2
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gndreplay: error: ") and str(other) in lines[0]
        assert "Traceback" not in res.output and res.stdout == ""


# ---------------------------------------------------------------------------------------------------------
# the real logs

CSAIL = "carmen/mit-csail.clf.bz2"


@pytest.fixture(scope="module")
def csail_idc(datasets: Path) -> CorrectedTrajectory:
    """IDC over the whole CARMEN file (the matcher is online: its first k poses are those of a k-scan run)."""
    return correct_trajectory(read_ticks(datasets / CSAIL), make_matcher("idc"))


@pytest.mark.parametrize(
    ("bag", "scans"),
    [("rosbag1/mit-csail.sort.bag", None), ("rosbag2/mit-csail.sort.ros2_mcap", None),
     ("rosbag1/mit-csail.orig.bag", 500), ("rosbag2/mit-csail.sort.ros2_sqlite3", 500)],
)
def test_csail_bags_give_the_carmen_files_corrected_trajectory(
    datasets: Path, csail_idc: CorrectedTrajectory, bag: str, scans: int | None
) -> None:
    with open_log(datasets / bag) as log:
        got = correct_trajectory(islice(log.ticks(), scans), make_matcher("idc"))
    n = got.t_ns.size
    assert n == (csail_idc.t_ns.size if scans is None else scans)
    ref = csail_idc
    np.testing.assert_array_equal(got.t_ns, ref.t_ns[:n])
    assert np.max(np.hypot(*(got.poses[:, :2] - ref.poses[:n, :2]).T)) < 1e-3
    turn = np.remainder(got.poses[:, 2] - ref.poses[:n, 2] + math.pi, 2 * math.pi) - math.pi
    assert np.max(np.abs(turn)) < 1e-3
    # the matcher corrected the odometry (metres by the end), so agreeing is not agreeing on the odometry
    assert np.max(np.hypot(*(ref.poses[:n, :2] - ref.odom[:n, :2]).T)) > 0.5


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_csail_carmen_and_bag_replay_to_the_same_commands(datasets: Path, tmp_path: Path) -> None:
    outs = []
    for name, log in (("clf", CSAIL), ("bag", "rosbag1/mit-csail.orig.bag")):
        out = tmp_path / name
        res = runner.invoke(app, ["run", str(datasets / log), "--until", "60", "--goal-ahead", "3",
                                  "--no-figures", "-q", "--out", str(out)])
        assert res.exit_code == 0, res.output
        outs.append(out)
    clf, bag = (read_csv(o / "commands.csv") for o in outs)
    assert len(clf) > 200
    # neither container records velocity commands, so the log_v, log_w columns are empty in both
    assert {(r["log_v"], r["log_w"]) for r in clf + bag} == {("", "")}
    assert len({r["mode"] for r in clf}) > 2 and any(float(r["v"]) != 0.0 for r in clf)
    for f in ("commands.csv", "trajectory_corrected.tum", "trajectory_odom.tum"):
        assert (outs[0] / f).read_bytes() == (outs[1] / f).read_bytes(), f
    assert all(r["t"].endswith("000") for r in clf)  # the microsecond clock


def test_info_against_names_what_the_aces_bag_changed(datasets: Path) -> None:
    clf, bag = datasets / "carmen/aces.clf.bz2", datasets / "rosbag1/aces.sort.bag"
    res = runner.invoke(app, ["info", str(clf), "--against", str(bag), "--json"])
    assert res.exit_code == 0, res.output
    against = json.loads(res.stdout)["against"]
    assert against["replay_differs"] is True
    found = {d["what"]: d for d in against["differences"]}
    assert set(found) == {"last bearing", "beam step", "range min"}
    assert (found["beam step"]["this"], found["beam step"]["other"]) == ("1.0000 deg", "1.0056 deg")
    assert found["beam step"]["affects_replay"] is True
    # the bag's 0.3 m minimum invalidates nothing: ACES has no return under 0.31 m
    assert (found["range min"]["this"], found["range min"]["other"]) == ("0 m", "0.3 m")
    assert found["range min"]["affects_replay"] is False
    text = runner.invoke(app, ["info", str(clf), "--against", str(bag)], env={"COLUMNS": "300"})
    assert text.exit_code == 0
    assert "  beam step: 1.0000 deg against 1.0056 deg; the bearings are up to 1.00 deg apart" in text.stdout
    assert ("  without effect: range min: 0 m against 0.3 m; no return in this log is shorter than 0.3 m"
            in text.stdout)


def test_info_against_finds_no_difference_between_csail_and_its_bag(datasets: Path) -> None:
    bag = datasets / "rosbag2/mit-csail.sort.ros2_mcap"
    res = runner.invoke(app, ["info", str(datasets / CSAIL), "--against", str(bag)], env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    assert f"against {bag} (rosbag2): no difference in what a replay reads" in res.stdout
