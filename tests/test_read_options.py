"""One ReadOptions through every reader, the laser-mounting fallback and its source, one suffix table."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from test_io_carmen import flaser, log_file, odom_line
from test_io_rosbag import MOUNT, Kind, Spec, write_bag
from typer.testing import CliRunner

import gndreplay.io as gio
from gndreplay.batch.jobs import find_logs, input_stem
from gndreplay.cli import _log_stem, app
from gndreplay.errors import ConfigError, LogFormatError
from gndreplay.info import log_info, summary_rows
from gndreplay.io import (
    LOG_SUFFIXES,
    READERS,
    ReadOptions,
    detect_format,
    log_stem,
    log_suffix,
    open_log,
    read_ticks,
)
from gndreplay.io.canonical import canonical_pose
from gndreplay.io.carmen import CarmenReader
from gndreplay.io.rosbag import RosbagReader
from gndreplay.io.sync import SyncOptions
from gndreplay.types import NS_PER_S, Pose2D

FALLBACK = (0.5, -0.1, 0.25)
RANGES: list[float | str] = [1.0, 2.0, 3.0]


def carmen_log(tmp_path: Path, params: str = "", name: str = "t.clf", n: int = 3) -> Path:
    text = params + "".join(odom_line(f"{i}.05", 0.1 * i) + flaser(f"{i}.1", RANGES) for i in range(n))
    return log_file(tmp_path, text, name)


# ------------------------------------------------------------------------------------------------------------
# the options reach every reader


def test_carmen_reader_takes_its_streams_strictness_and_sync_from_the_options(tmp_path: Path) -> None:
    p = carmen_log(tmp_path)
    with CarmenReader(p, options=ReadOptions(odom_topic="FLASER", truth_topic="FLASER")) as log:
        desc = log.describe()
    assert desc.odom_source.startswith("FLASER") and desc.truth_stream == "FLASER"
    bad = log_file(tmp_path, flaser("1.0", RANGES) + "FLASER 3 1 2\n" + flaser("2.0", RANGES), "bad.clf")
    assert open_log(bad).report.malformed == 0  # counted only once read
    assert len(list(read_ticks(bad))) == 2
    with pytest.raises(LogFormatError, match=r"bad\.clf line 2"):
        list(read_ticks(bad, options=ReadOptions(strict=True)))
    late = log_file(tmp_path, "".join(flaser(f"{i}.0", RANGES) for i in (1, 2, 3)) + flaser("1.5", RANGES),
                    "late.clf")
    tight = ReadOptions(sync=SyncOptions(reorder_window_ns=NS_PER_S // 10))
    with open_log(late, options=tight) as log:
        assert len(list(log.ticks())) == 3 and log.report.late_dropped == 1


def test_rosbag_reader_takes_its_topics_and_strictness_from_the_options(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "ros1", Spec(scan_topics=("/a", "/b"), garbage_at=2))
    with pytest.raises(LogFormatError, match="several scan topics"):
        RosbagReader(bag)
    with RosbagReader(bag, options=ReadOptions(scan_topic="/b", odom_topic="/tf")) as log:
        assert log.scan_topic == "/b" and log.describe().odom_source == "/tf odom -> base_link"
    with pytest.raises(LogFormatError, match="cannot decode"):
        list(read_ticks(bag, options=ReadOptions(scan_topic="/a", strict=True)))


def test_the_format_comes_from_the_options(tmp_path: Path) -> None:
    p = log_file(tmp_path, flaser("1.0", RANGES), "scan.txt")
    with pytest.raises(LogFormatError, match="unknown log format"):
        open_log(p)
    with open_log(p, options=ReadOptions(fmt="carmen")) as log:
        assert log.format_name == "carmen"
    assert log_info(p, options=ReadOptions(fmt="carmen")).format == "carmen"


def test_every_registered_reader_takes_the_options(tmp_path: Path) -> None:
    p = carmen_log(tmp_path)
    opts = ReadOptions(default_sensor_pose=FALLBACK)
    with READERS["carmen"](p, options=opts) as log:
        assert log.report.sensor_pose_source == "config default"
    bag = write_bag(tmp_path, "ros1", Spec(tf_static=False))
    with READERS["rosbag1"](bag, options=opts) as log:
        assert log.report.sensor_pose_source == "config default"


def test_log_info_takes_the_options(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "sqlite3", Spec(scan_topics=("/a", "/b")))
    info = log_info(bag, options=ReadOptions(scan_topic="/b", sync=SyncOptions(gap_ns=NS_PER_S // 20)))
    assert info.gap_threshold_s == pytest.approx(0.05) and info.gaps == 11
    assert next(s for s in info.streams if s.name == "/b").role == "scan"


@pytest.mark.parametrize("bad", [(1.0, 2.0), (math.nan, 0.0, 0.0), (1e9, 0.0, 0.0), ("a", 0.0, 0.0)])
def test_a_bad_default_sensor_pose_is_refused(bad: tuple[float, ...]) -> None:
    with pytest.raises(ConfigError, match="default sensor pose"):
        ReadOptions(default_sensor_pose=bad)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------------------
# the mounting fallback and its source


def first_scan_pose(path: Path, options: ReadOptions | None = None) -> tuple[Pose2D, str]:
    with open_log(path, options=options or ReadOptions()) as log:
        ticks = list(log.ticks())
        return ticks[0].scan.sensor_pose, log.report.to_dict()["sensor_pose_source"]


def test_carmen_log_without_mounting_takes_the_fallback(tmp_path: Path) -> None:
    p = carmen_log(tmp_path)
    assert first_scan_pose(p) == (Pose2D(0.0, 0.0, 0.0), "none")
    fallback = ReadOptions(default_sensor_pose=FALLBACK)
    assert first_scan_pose(p, fallback) == (Pose2D(*FALLBACK), "config default")
    wrapped = ReadOptions(default_sensor_pose=(0.0, 0.0, 3 * math.pi / 2))
    assert first_scan_pose(p, wrapped)[0].theta == pytest.approx(-math.pi / 2)


@pytest.mark.parametrize("param", ["robot_frontlaser_offset 0.0", "robot_frontlaser_side_offset 0.2",
                                   "robot_frontlaser_angular_offset 0.1"])
def test_carmen_log_with_a_mounting_param_keeps_it(tmp_path: Path, param: str) -> None:
    p = carmen_log(tmp_path, f"PARAM {param} host 0\n")
    value = float(param.split()[1])
    expected = Pose2D(0.0, value if "side" in param else 0.0, value if "angular" in param else 0.0)
    assert first_scan_pose(p, ReadOptions(default_sensor_pose=FALLBACK)) == (expected, "log")


def test_carmen_rear_and_robotlaser_mountings(tmp_path: Path) -> None:
    rlaser = "".join(flaser(f"{i}.0", RANGES).replace("FLASER", "RLASER") for i in range(3))
    rear = log_file(tmp_path, rlaser, "rear.clf")
    assert first_scan_pose(rear) == (canonical_pose(Pose2D(0.0, 0.0, math.pi)), "none")
    assert first_scan_pose(rear, ReadOptions(default_sensor_pose=FALLBACK))[1] == "config default"
    header = "ROBOTLASER1 0 -1.5708 3.1416 1.5708 8.0 0.01 0 3 1 2 3 0"
    poses = "0.2 0.0 0.0 0.0 0.0 0.0 0 0 0 0 0"  # laser pose, robot pose, then five unused fields
    robot = "".join(f"{header} {poses} {i}.0 h {i}\n" for i in range(3))
    p = log_file(tmp_path, robot, "robot.clf")
    pose, source = first_scan_pose(p, ReadOptions(default_sensor_pose=FALLBACK))
    assert source == "log" and pose == Pose2D(pytest.approx(0.2), 0.0, 0.0)


def test_carmen_param_after_the_head_changes_the_source_mid_log(tmp_path: Path) -> None:
    head = "".join(flaser(f"{i}.0", RANGES) for i in range(1, 61))
    tail = "PARAM robot_frontlaser_offset 0.3 host 0\n" + flaser("61.0", RANGES)
    p = log_file(tmp_path, head + tail, "late_param.clf")
    with open_log(p, options=ReadOptions(default_sensor_pose=FALLBACK)) as log:
        ticks = list(log.ticks())
        assert log.report.sensor_pose_source == "config default then log"
    assert ticks[0].scan.sensor_pose == Pose2D(*FALLBACK)
    assert ticks[-1].scan.sensor_pose == Pose2D(0.3, 0.0, 0.0)


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_bag_without_a_laser_transform_takes_the_fallback(tmp_path: Path, kind: Kind) -> None:
    bare = write_bag(tmp_path, kind, Spec(tf_static=False), name="bare")
    assert first_scan_pose(bare) == (Pose2D(0.0, 0.0, 0.0), "none")
    with open_log(bare, options=ReadOptions(default_sensor_pose=FALLBACK)) as log:
        note = log.describe().notes[0]
        pose = next(iter(log.ticks())).scan.sensor_pose
        assert log.report.sensor_pose_source == "config default"
    assert pose == Pose2D(*FALLBACK) and "from the configuration (no transform base_link -> laser" in note
    mounted = write_bag(tmp_path, kind, name="mounted")
    pose, source = first_scan_pose(mounted, ReadOptions(default_sensor_pose=FALLBACK))
    assert source == "tf" and pose == Pose2D(*(pytest.approx(v) for v in MOUNT))


def test_the_robots_mounting_is_the_fallback_only_when_the_configuration_asks(tmp_path: Path) -> None:
    """``[robot] mounting_fallback``: a replay of a log without mounting takes the robot's laser pose,
    recorded as "config default"; without it the log reads with the identity ("none"). scanmatch takes the
    same setting."""
    p = carmen_log(tmp_path, n=8)
    runner = CliRunner()
    sources = []
    for k, extra in enumerate(([], ["--set", "robot.mounting_fallback=true"])):
        out = tmp_path / f"run{k}"
        res = runner.invoke(app, ["run", str(p), "--no-figures", "--quiet", "--out", str(out), *extra])
        assert res.exit_code == 0, res.output
        sources.append(json.loads((out / "summary.json").read_text())["read_report"]["sensor_pose_source"])
        sm = runner.invoke(app, ["scanmatch", str(p), "--matcher", "odom", "--out", str(tmp_path / f"sm{k}"),
                                 *extra])
        assert sm.exit_code == 0, sm.output
    assert sources == ["none", "config default"]
    assert "mounting_fallback = true" in (tmp_path / "run1" / "config.toml").read_text()


def test_info_shows_the_source_of_the_laser_pose(tmp_path: Path) -> None:
    p = carmen_log(tmp_path)
    info = log_info(p, options=ReadOptions(default_sensor_pose=FALLBACK))
    assert info.laser_pose == pytest.approx(FALLBACK) and info.laser_pose_source == "config default"
    assert ("laser pose from", "config default") in summary_rows(info)
    bag = log_info(write_bag(tmp_path, "mcap", Spec(tf_static=False)),
                   options=ReadOptions(default_sensor_pose=FALLBACK))
    assert bag.laser_pose == pytest.approx(FALLBACK)
    assert bag.to_dict()["laser_pose_source"] == "config default"
    out = CliRunner().invoke(app, ["info", str(p)], env={"COLUMNS": "200"})
    assert out.exit_code == 0, out.output
    assert any(line.split()[:4] == ["laser", "pose", "from", "none"] for line in out.output.splitlines())


# ------------------------------------------------------------------------------------------------------------
# one suffix table


@pytest.mark.parametrize(
    ("name", "suffix", "stem"),
    [
        ("mit-csail.clf.bz2", ".clf.bz2", "mit-csail"),
        ("a.log.gz", ".log.gz", "a"),
        ("Run.CLF", ".clf", "Run"),
        ("x.bag", ".bag", "x"),
        ("y.mcap", ".mcap", "y"),
        ("z.carmen", ".carmen", "z"),
        ("b.bag.gz", None, "b.bag.gz"),
        ("c.gz", None, "c.gz"),
        ("notes.txt", None, "notes.txt"),
        (".clf", None, ".clf"),
        (".hidden.bag", ".bag", ".hidden"),
    ],
)
def test_log_suffix_and_stem(name: str, suffix: str | None, stem: str) -> None:
    assert log_suffix(name) == suffix and log_stem(name) == stem


def test_every_suffix_in_the_table_is_found_detected_and_stripped(tmp_path: Path) -> None:
    for suffix, fmt in LOG_SUFFIXES.items():
        (tmp_path / f"log{suffix}").write_bytes(b"")
        assert detect_format(tmp_path / f"log{suffix}")[0] == fmt
    (tmp_path / "more.clf.bz2").write_bytes(b"")
    (tmp_path / "notes.txt").write_bytes(b"")
    found = [p.name for p in find_logs(tmp_path)]
    assert found == sorted([f"log{s}" for s in LOG_SUFFIXES] + ["more.clf.bz2"])
    assert {input_stem(tmp_path / n) for n in found} == {"log", "more"}
    assert {_log_stem(tmp_path / n) for n in found} == {"log", "more"}


def test_discovery_guessing_and_output_names_share_the_table(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    p = log_file(tmp_path, flaser("1.0", RANGES), "scan.xyz")
    assert find_logs(tmp_path) == [] and _log_stem(p) == "scan.xyz"
    monkeypatch.setattr(gio, "LOG_SUFFIXES", {**LOG_SUFFIXES, ".xyz": "carmen"})
    assert find_logs(tmp_path) == [p] and _log_stem(p) == "scan" and input_stem(p) == "scan"
    assert detect_format(p) == ("carmen", p)
    assert detect_format(log_file(tmp_path, flaser("1.0", RANGES), "scan.xyz.gz"))[0] == "carmen"
