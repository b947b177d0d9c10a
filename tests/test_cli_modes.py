"""The navigation mode options of the CLI (--mode, --local, --subgoals, --no-selector) and the audit they
produce: a recorded driver heading straight for a wall, in a ROS bag (Twist commands) and in a CARMEN log
(ODOM tv/rv), is taken over by local navigation before the wall; the takeover is in summary.json,
report.md, commands.csv, fig_modes.png and results.mcap. Bad combinations are one line and exit 2."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import PRESETS
from gndreplay.io.carmen import write_carmen
from gndreplay.pipeline.supervisor import braking_time_s
from gndreplay.report.rundir import read_commands
from gndreplay.types import NS_PER_S, Odometry, Pose2D, Scan, Tick

runner = CliRunner()
T0 = 1_700_000_000 * NS_PER_S
DT = 100_000_000  # 10 Hz
N = 60  # 6 s
V = 0.3  # the driver's forward command [m/s], straight at the wall
WALL_X = 2.6  # a wall across the robot's way [m]: the recorded chair stops 3 cm short of it
ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))


def invoke(*args: Any) -> Any:
    return runner.invoke(app, [str(a) for a in args])


def assert_clean_error(res: Any, *needles: str) -> str:
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("gndreplay: error: ") and all(n in lines[0] for n in needles), lines[0]
    assert "Traceback" not in res.output
    return str(lines[0])


def robot_x(k: int) -> float:
    """The recorded robot obeys its driver: x = V t (it stops 0.1 s short of the log's end)."""
    return V * k * DT / NS_PER_S


def wall_ranges(x: float, max_range: float = 20.0) -> np.ndarray:
    """A laser at the robot's origin facing +x, a wall at WALL_X across every beam ahead."""
    c = np.cos(ANGLES)
    r = np.full(ANGLES.size, np.inf)
    ahead = c > 1e-3
    r[ahead] = (WALL_X - x) / c[ahead]
    r[r >= max_range] = np.inf
    return r


#: Ticks of the wall bag without a driver's command: none yet at the start, then a gap of 7 ticks: the last
#: command (tick 19, 5 ms before it) is older than the stack's 0.5 s command timeout at tick 24 (scan stamp
#: 1 ms after the tick: 0.506 s), so ticks 24-26 have a stale one
NO_CMD_TICKS = (0, 1)
GAP_TICKS = tuple(range(20, 27))
STALE_TICKS = (24, 25, 26)


def write_wall_bag(path: Path, *, commands: bool = True, kind: str = "ros1") -> Path:
    """A bag: /scan (LaserScan), /odom (Odometry) and, with ``commands``, /cmd_vel (Twist in a ROS 1 bag,
    TwistStamped in a ROS 2 MCAP bag: ``kind="mcap"``) except on ``NO_CMD_TICKS`` and ``GAP_TICKS``."""
    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    ser = ts.serialize_ros1 if ros1 else ts.serialize_cdr

    def hdr(t: int, frame: str) -> Any:
        stamp = T["builtin_interfaces/msg/Time"](sec=t // NS_PER_S, nanosec=t % NS_PER_S)
        if ros1:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def v3(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
        return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def twist(v: float) -> Any:
        return T["geometry_msgs/msg/Twist"](linear=v3(x=v), angular=v3())

    cov = np.zeros(36)
    scan_t, odom_t = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
    twist_t = "geometry_msgs/msg/Twist" if ros1 else "geometry_msgs/msg/TwistStamped"
    writer: Any = Writer1(path) if ros1 else Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP)
    with writer as w:
        c_scan = w.add_connection("/scan", scan_t, typestore=ts)
        c_odom = w.add_connection("/odom", odom_t, typestore=ts)
        c_cmd = w.add_connection("/cmd_vel", twist_t, typestore=ts) if commands else None
        for k in range(N):
            t = T0 + k * DT
            if c_cmd is not None and k not in NO_CMD_TICKS + GAP_TICKS:
                tc = t - 5_000_000
                msg = twist(V) if ros1 else T[twist_t](header=hdr(tc, "base_link"), twist=twist(V))
                w.write(c_cmd, tc, ser(msg, twist_t))
            point = T["geometry_msgs/msg/Point"](x=robot_x(k), y=0.0, z=0.0)
            yaw0 = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
            pose = T["geometry_msgs/msg/Pose"](position=point, orientation=yaw0)
            odom = T["nav_msgs/msg/Odometry"](
                header=hdr(t, "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist(V), covariance=cov))
            w.write(c_odom, t, ser(odom, odom_t))
            scan = T[scan_t](
                header=hdr(t, "base_link"), angle_min=float(ANGLES[0]), angle_max=float(ANGLES[-1]),
                angle_increment=float(ANGLES[1] - ANGLES[0]), time_increment=0.0, scan_time=0.1,
                range_min=0.05, range_max=20.0, ranges=wall_ranges(robot_x(k)).astype(np.float32),
                intensities=np.zeros(0, dtype=np.float32))
            w.write(c_scan, t + 1_000_000, ser(scan, scan_t))
    return path


def write_wall_carmen(path: Path, *, tv: float = V) -> Path:
    """The same drive as a CARMEN log: FLASER + ODOM whose tv is the driver's command."""
    ticks = [Tick(k, T0 + k * DT, Scan(T0 + k * DT, wall_ranges(robot_x(k)), ANGLES, 20.0),
                  Pose2D(robot_x(k), 0.0, 0.0)) for k in range(N)]
    odometry = [Odometry(T0 + k * DT - 5_000_000, Pose2D(robot_x(k) - V * 0.005, 0.0, 0.0), tv, 0.0)
                for k in range(N)]
    write_carmen(path, ticks, odometry=odometry)
    return path


def check_takeover(run: Path, *, gaps: bool = False) -> dict[str, Any]:
    """The run's audit shows the driver taken over before the wall, the same in every file; with ``gaps``
    (the bag fixture) the ticks without a command or with a stale one carry their reason, not a takeover."""
    summary = json.loads((run / "summary.json").read_text())
    iv = summary["interventions"]
    assert iv["desired"] == {"teleop": N}
    assert iv["takeovers"], "the driver heading into the wall was never taken over"
    first = iv["takeovers"][0]
    assert first["desired"] == "teleop" and first["active"] == "local" and first["reason"]
    assert iv["takeover_ticks"] == sum(e["ticks"] for e in iv["takeovers"]) == iv["active"]["local"]
    cmds = read_commands(run / "commands.csv")
    taken = cmds.active != cmds.desired
    assert int(taken.sum()) == iv["takeover_ticks"]
    k = int(np.argmax(taken))  # the first takeover tick
    assert first["t_start_s"] == pytest.approx(cmds.t_s[k] - cmds.t_s[0])
    # taken over where the braking horizon says, before contact: the area the command sweeps (V over
    # braking_time_s, plus the reflexive and the selector margins, plus half a cell for the grid) reaches
    # the wall first at tick k (the wheelchair's front edge is front_m ahead of its axle)
    cfg = PRESETS["wheelchair"]
    reach = (V * braking_time_s(V, 0.0, 0.0, cfg.robot, cfg.supervisor) + cfg.supervisor.emergency_margin_m
             + cfg.navigation.selector_margin_m)
    gap = WALL_X - cfg.robot.front_m - np.array([robot_x(i) for i in range(N)])
    assert 0.0 < gap[k] <= reach + 0.5 * cfg.grid.cell_m + 1e-9 and gap[k - 1] > reach - 1e-9
    assert np.all(cmds.v_mps[taken] < V)  # local navigation slowed the robot down
    assert (cmds.takeover[taken] == first["reason"]).any()
    missing, stale = (NO_CMD_TICKS, STALE_TICKS) if gaps else ((), ())
    expected = np.array(["teleop: no command" if k in missing else "teleop: command stale" if k in stale
                         else "" for k in range(N)])
    assert cmds.takeover[~taken].tolist() == expected[~taken].tolist()
    assert not taken[list(missing + stale)].any()  # standing still for want of a command: no takeover
    assert np.all(cmds.v_mps[list(missing + stale)] == 0.0)
    assert (iv["no_command_ticks"], iv["stale_command_ticks"]) == (len(missing), len(stale))
    report = (run / "report.md").read_text()
    section = report.split("## Interventions", 1)[1].split("\n## ", 1)[0]
    assert "| teleop | local | " + first["reason"] + " |" in section
    assert (run / "fig_modes.png").stat().st_size > 0 and "fig_modes.png" in report
    return summary


def test_run_teleop_on_a_bag_with_twist_commands_reports_the_takeover(tmp_path: Path) -> None:
    bag = write_wall_bag(tmp_path / "wall.bag")
    res = invoke("run", bag, "--mode", "teleop", "--goal", "2.5,0", "--out", tmp_path / "run", "--mcap", "-q")
    assert res.exit_code == 0, res.output
    assert "no usable teleop command" not in res.stderr  # 5 of 60 ticks: under the 20 % warning
    check_takeover(tmp_path / "run", gaps=True)
    from rosbags.highlevel import AnyReader

    with AnyReader([tmp_path / "run" / "results.mcap"]) as reader:
        conns = [c for c in reader.connections if c.topic == "/gndreplay/active_mode"]
        active = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages(connections=conns)]
    assert len(active) == N and set(active) == {"teleop", "local"}
    assert active == read_commands(tmp_path / "run" / "commands.csv").active.tolist()


def test_run_teleop_on_a_ros2_mcap_bag_with_twist_stamped_commands(tmp_path: Path) -> None:
    bag = write_wall_bag(tmp_path / "wall2", kind="mcap")
    for log in (bag, next(bag.glob("*.mcap"))):  # the ROS 2 bag folder and its bare MCAP file
        out = tmp_path / f"run-{log.suffix or 'dir'}"
        res = invoke("run", log, "--mode", "teleop", "--goal", "2.5,0", "--out", out, "-q")
        assert res.exit_code == 0, res.output
        check_takeover(out, gaps=True)
        section = (out / "report.md").read_text().split("## Interventions", 1)[1]
        assert ("Ticks without a usable teleop command (the robot stood still): 2 (3.3 %) with none or a "
                "non-finite one, 3 (5.0 %) with a stale one") in section


def test_run_teleop_on_a_carmen_log_with_odom_tv_rv_reports_the_takeover(tmp_path: Path) -> None:
    log = write_wall_carmen(tmp_path / "wall.clf")
    res = invoke("run", log, "--mode", "teleop", "--goal", "2.5,0", "--out", tmp_path / "run", "-q")
    assert res.exit_code == 0, res.output
    summary = check_takeover(tmp_path / "run")
    assert summary["config"]["navigation"]["mode"] == "teleop"


def test_no_selector_leaves_the_driver_alone(tmp_path: Path) -> None:
    log = write_wall_carmen(tmp_path / "wall.clf")
    res = invoke("run", log, "--mode", "teleop", "--no-selector", "--goal", "2.5,0",
                 "--out", tmp_path / "run", "-q", "--no-figures")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["interventions"]["takeovers"] == [] and summary["interventions"]["active"] == {"teleop": N}
    assert summary["config"]["navigation"]["selector"] is False
    cmds = read_commands(tmp_path / "run" / "commands.csv")
    assert np.all(cmds.v_mps[5:] == pytest.approx(V))  # the recorded command, unchanged, into the wall


def test_teleop_needs_recorded_commands(tmp_path: Path) -> None:
    bag = write_wall_bag(tmp_path / "nocmd.bag", commands=False)
    res = invoke("run", bag, "--mode", "teleop", "--out", tmp_path / "a", "-q")
    assert_clean_error(res, "nocmd.bag: no recorded velocity commands (cmd topic / CARMEN ODOM tv,rv); "
                       "--mode teleop needs them")
    zero = write_wall_carmen(tmp_path / "zero.clf", tv=0.0)
    res = invoke("run", zero, "--mode", "teleop", "--out", tmp_path / "b", "-q")
    assert_clean_error(res, "zero.clf: no recorded velocity commands")
    res = invoke("batch", zero, "--mode", "teleop", "--out", tmp_path / "c", "-q", "--no-figures")
    assert res.exit_code == 2 and "no recorded velocity commands" in res.stderr
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_follow_needs_subgoals_and_bad_options_are_one_line(tmp_path: Path) -> None:
    log = write_wall_carmen(tmp_path / "wall.clf")
    assert_clean_error(invoke("run", log, "--mode", "follow", "--out", tmp_path / "a", "-q"),
                       "navigation mode follow needs subgoals: give --subgoals FILE")
    assert_clean_error(invoke("run", log, "--mode", "drive", "--out", tmp_path / "a", "-q"),
                       "--mode: expected one of gnd, teleop, follow, local, got 'drive'")
    assert_clean_error(invoke("run", log, "--local", "left", "--out", tmp_path / "a", "-q"),
                       "--local: expected one of nd, free-space, wall-left, wall-right, contour")
    bad = tmp_path / "bad.txt"
    bad.write_text("1.0 0.0\n")
    res = invoke("run", log, "--mode", "follow", "--subgoals", bad, "--out", tmp_path / "a", "-q")
    assert_clean_error(res, "bad.txt")
    assert_clean_error(invoke("simulate", "u_trap", "--mode", "drive", "--out", tmp_path / "s"), "--mode")
    assert not (tmp_path / "a").exists() and not (tmp_path / "s").exists()


def test_options_a_mode_would_ignore_are_refused(tmp_path: Path) -> None:
    """--subgoals outside mode follow, --local where no local strategy runs: one line, nothing written (not
    silently ignored while summary.json lists them)."""
    log = write_wall_carmen(tmp_path / "wall.clf")
    goals = tmp_path / "goals.txt"
    goals.write_text("1.0 0.0 0.0 stop\n")
    for mode in ("gnd", "teleop", "local"):
        res = invoke("run", log, "--mode", mode, "--subgoals", goals, "--out", tmp_path / "a", "-q")
        assert_clean_error(res, f"--subgoals: only navigation mode follow uses subgoals (mode is {mode})")
    assert_clean_error(invoke("run", log, "--local", "contour", "--out", tmp_path / "a", "-q"),
                       "--local contour: mode gnd runs no local strategy")
    res = invoke("run", log, "--mode", "teleop", "--no-selector", "--local", "wall-left", "--out",
                 tmp_path / "a", "-q")
    assert_clean_error(res, "--local wall-left: mode teleop without the mode selector runs no local strategy")
    assert not (tmp_path / "a").exists()


def test_follow_with_subgoals_records_the_subgoal_per_tick(tmp_path: Path) -> None:
    log = write_wall_carmen(tmp_path / "wall.clf")
    goals = tmp_path / "goals.txt"
    goals.write_text("# x y theta kind\n1.0 0.0 0.0\n1.5 0.0 0.0 stop\n")
    res = invoke("run", log, "--mode", "follow", "--subgoals", goals, "--out", tmp_path / "run", "-q",
                 "--no-figures")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["options"]["subgoals"] == [[1.0, 0.0, 0.0, "forward"], [1.5, 0.0, 0.0, "stop"]]
    assert summary["interventions"]["desired"] == {"follow": N}
    cmds = read_commands(tmp_path / "run" / "commands.csv")
    assert cmds.subgoal.min() >= 0 and np.all(np.diff(cmds.subgoal) >= 0)  # worked through in order
    # the first subgoal (x = 1.0) is reached when the recorded robot (x = 0.03 k) comes within the follower's
    # reach_m of it, not before; then the stop subgoal (x = 1.5, far enough from the wall at 2.6 m that the
    # follower's braking never sweeps near it: no takeover decides when the robot is at rest): the follower
    # brakes for it, and once it stands on it (its own last command at rest: in a replay the recorded robot
    # drives on) the path is done (index 2 = past the last subgoal) with a GOAL stop at v = 0
    reach = PRESETS["wheelchair"].navigation.follow.reach_m
    k1 = int(np.argmax(cmds.subgoal >= 1))
    assert abs(robot_x(k1) - 1.0) <= reach + 0.01 < abs(robot_x(k1 - 1) - 1.0) + 0.03
    k2 = int(np.argmax(cmds.subgoal >= 2))
    assert k2 > k1 and abs(robot_x(k2) - 1.5) <= reach and np.all(cmds.subgoal[k2:] == 2)
    assert np.all(cmds.active[:k2] == "follow")  # the follower alone did it
    assert np.all(cmds.modes[k2:] == "GOAL") and np.all(cmds.v_mps[k2:] == 0.0)
    v = cmds.v_mps[k1:k2]
    assert v[0] == pytest.approx(V) and 0.0 < v[v > 0.0][-1] < V  # slowing down towards the stop


def test_simulate_refuses_subgoals_on_a_scenario_that_does_not_follow(tmp_path: Path) -> None:
    goals = tmp_path / "goals.txt"
    goals.write_text("1.0 0.0 0.0 stop\n")
    res = invoke("simulate", "u_trap", "--subgoals", goals, "--out", tmp_path / "s")
    assert_clean_error(res, "--subgoals: only navigation mode follow uses subgoals (scenario u_trap has "
                       "mode gnd)")
    assert not (tmp_path / "s").exists()
