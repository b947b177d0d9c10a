"""``gndreplay info`` end to end: tables, JSON, the error boundary (exit 2, one line, no traceback)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from typer.testing import CliRunner

from gndreplay import __version__
from gndreplay.cli import app
from gndreplay.info import log_info
from gndreplay.io.carmen import write_carmen
from gndreplay.io.rosbag import RosbagReader
from gndreplay.types import NS_PER_S, Pose2D, Scan, Tick

runner = CliRunner()


def invoke(*args: str) -> Any:
    return runner.invoke(app, [str(a) for a in args])


def info_json(*args: str) -> dict[str, Any]:
    res = invoke("info", *args, "--json")
    assert res.exit_code == 0, res.stderr
    return json.loads(res.stdout)  # type: ignore[no-any-return]


def assert_clean_error(res: Any, name: str) -> str:
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("gndreplay: error: ") and name in lines[0]
    assert "Traceback" not in res.output
    return str(lines[0])


@pytest.fixture
def carmen_log(tmp_path: Path) -> Path:
    angles = -math.pi / 2 + np.arange(181) * math.pi / 180
    ticks = []
    for i in range(30):
        r = np.full(181, 4.0)
        r[:10] = np.inf
        r[10:15] = np.nan
        t = 1_000 * NS_PER_S + i * 200_000_000
        ticks.append(Tick(i, t, Scan(t, r, angles, 20.0), Pose2D(0.1 * i, 0.0, 0.0)))
    p = tmp_path / "run.clf.gz"
    write_carmen(p, ticks)
    return p


def write_mcap_bag(tmp_path: Path, n: int = 40) -> Path:
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    path = tmp_path / "scans"
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        for i in range(n):
            t = 5 * NS_PER_S + i * 100_000_000
            hdr = T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=t // NS_PER_S, nanosec=t % NS_PER_S), frame_id="l"
            )
            msg = T["sensor_msgs/msg/LaserScan"](
                header=hdr,
                angle_min=-1.0,
                angle_max=1.0,
                angle_increment=0.5,
                time_increment=0.0,
                scan_time=0.1,
                range_min=0.1,
                range_max=10.0,
                ranges=np.array([1, 2, np.nan, 20, 3], np.float32),
                intensities=np.zeros(0, np.float32),
            )
            w.write(c, t, ts.serialize_cdr(msg, "sensor_msgs/msg/LaserScan"))
    return path


# ------------------------------------------------------------------------------------------------------------


def test_version() -> None:
    res = invoke("--version")
    assert res.exit_code == 0 and res.stdout.strip() == f"gndreplay {__version__}"


def test_no_arguments_shows_help() -> None:
    res = invoke()
    assert "info" in res.output and "Usage" in res.output


def test_info_table(carmen_log: Path) -> None:
    res = invoke("info", carmen_log)
    assert res.exit_code == 0, res.stderr
    out = res.stdout
    assert "30 of 181 beams" in out
    assert "180.0 deg" in out
    assert "ODOM (interpolated at scan stamps)" in out
    assert "FLASER" in out and "5.00 Hz" in out  # 30 scans, one every 0.2 s


def test_info_json(carmen_log: Path) -> None:
    d = info_json(carmen_log)
    assert d["format"] == "carmen" and d["scans"] == 30 and d["beams"] == [181]
    assert d["fov_deg"] == pytest.approx(180.0) and d["range_max_m"] == 20.0
    assert d["no_return_fraction"] == pytest.approx(10 / 181)
    assert d["invalid_fraction"] == pytest.approx(5 / 181)
    assert d["duration_s"] == pytest.approx(5.8) and d["start_s"] == pytest.approx(1000.0)
    assert d["sampled"] is False and d["malformed"] == 0 and d["gaps"] == 0
    assert {s["name"]: s["count"] for s in d["streams"]} == {"FLASER": 30, "ODOM": 30, "PARAM": 5}


def test_info_counts_malformed_lines_and_strict_refuses_them(tmp_path: Path, carmen_log: Path) -> None:
    import gzip

    lines = gzip.decompress(carmen_log.read_bytes()).decode().splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if ln.startswith("FLASER")) + 4
    lines[k] = lines[k][: len(lines[k]) // 2] + "\n"
    bad = tmp_path / "bad.clf"
    bad.write_text("".join(lines))
    d = info_json(bad)
    assert d["malformed"] == 1 and d["scans"] == 29
    assert d["malformed_examples"][0].startswith(f"line {k + 1}: FLASER")
    msg = assert_clean_error(invoke("info", bad, "--strict"), "bad.clf")
    assert f"line {k + 1}" in msg


def test_info_on_mcap_reads_the_summary_and_samples_scans(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = write_mcap_bag(tmp_path)
    decoded = []
    original = RosbagReader.decode_scan

    def counting(self: RosbagReader, raw: bytes, t_log: int) -> Any:
        decoded.append(t_log)
        return original(self, raw, t_log)

    def no_streaming(self: RosbagReader) -> Any:
        raise AssertionError("info must not stream the whole bag")

    monkeypatch.setattr(RosbagReader, "decode_scan", counting)
    monkeypatch.setattr(RosbagReader, "ticks", no_streaming)
    info = log_info(bag, sample=8)
    assert info.scans == 40 and info.beams == (5,) and info.stats_scans == 8 and info.sampled
    assert len(decoded) == 8
    assert info.summary_source == "MCAP summary section"
    assert info.invalid_fraction == pytest.approx(0.2) and info.no_return_fraction == pytest.approx(0.2)
    assert info.duration_s == pytest.approx(3.9) and info.odom_source == "none"
    bare = info_json(next(bag.glob("*.mcap")))
    assert (
        bare["format"] == "mcap"
        and bare["scans"] == 40
        and bare["streams"][0]["rate_hz"] == pytest.approx(10.0)
    )


def test_missing_file() -> None:
    assert_clean_error(invoke("info", "/nonexistent/run.clf"), "/nonexistent/run.clf")


def test_unknown_format(tmp_path: Path) -> None:
    p = tmp_path / "data.xyz"
    p.write_text("hello")
    msg = assert_clean_error(invoke("info", p), "data.xyz")
    assert "unknown log format" in msg and "carmen" in msg and "rosbag1" in msg
    msg = assert_clean_error(invoke("info", p, "--format", "bogus"), "data.xyz")
    assert "unknown format 'bogus'; known formats: carmen, rosbag1, rosbag2, mcap" in msg


def test_wrong_topic_lists_candidates(carmen_log: Path) -> None:
    msg = assert_clean_error(invoke("info", carmen_log, "--odom-topic", "/odom"), "run.clf.gz")
    assert "candidates: ODOM, FLASER" in msg


def test_keyboard_interrupt_exits_130(carmen_log: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def interrupted(*a: Any, **k: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr("gndreplay.info.log_info", interrupted)
    res = invoke("info", carmen_log)
    assert res.exit_code == 130 and "interrupted" in res.stderr


# ------------------------------------------------------------------------------------------------------------
# the real logs


@pytest.mark.slow
@pytest.mark.parametrize(
    "rel",
    [
        "carmen/mit-csail.clf.bz2",
        "rosbag1/mit-csail.sort.bag",
        "rosbag2/mit-csail.sort.ros2_sqlite3",
        "rosbag2/mit-csail.sort.ros2_mcap",
        "rosbag2/mit-csail.sort.ros2_mcap/mit-csail.sort.ros2_mcap.mcap",
    ],
)
def test_info_mit_csail_in_all_five_forms(datasets: Path, rel: str) -> None:
    d = info_json(datasets / rel)
    assert d["scans"] == 1988 and d["beams"] == [361]
    assert d["fov_deg"] == pytest.approx(180.0, abs=1e-4)
    assert d["duration_s"] == pytest.approx(424.0, abs=0.1)
    assert d["time_reversals"] == 0 and d["gaps"] == 0
    if rel.endswith(("mcap", ".mcap")):
        assert d["summary_source"] == "MCAP summary section"


@pytest.mark.slow
def test_info_aces_reports_the_file_disorder(datasets: Path) -> None:
    d = info_json(datasets / "carmen/aces.clf.bz2")
    assert d["scans"] == 7374 and d["beams"] == [180]
    assert d["out_of_order"] == 161 and d["time_reversals"] == 0 and d["late_dropped"] == 0
    assert d["range_max_m"] == 50.0
    assert d["gaps"] == 1 and d["max_gap_s"] == pytest.approx(3.03)


@pytest.mark.slow
def test_laserazos_reads_with_a_warning(datasets: Path) -> None:
    res = invoke("info", datasets / "robustness/laserazosSM3.log", "--json")
    assert res.exit_code == 0
    d = json.loads(res.stdout)
    assert d["scans"] == 778 and d["beams"] == [361] and d["index_clock"] is True
    assert d["invalid_fraction"] == pytest.approx(19234 / (778 * 361))
    assert "index clock" in res.stderr and "laserazosSM3.log" in res.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    ("rel", "what"),
    [
        ("robustness/loop5.log", "not a CARMEN log"),
        ("robustness/laser_scan_matcher_demo.bag", "the ROS bag reader (rosbags) refuses it"),
        ("robustness/laser_scan_splitter_demo.bag", "unsupported legacy ROS bag format V1.2"),
    ],
)
def test_robustness_files_exit_2_with_one_line(datasets: Path, rel: str, what: str) -> None:
    msg = assert_clean_error(invoke("info", datasets / rel), Path(rel).name)
    assert what in msg


@pytest.mark.slow
def test_the_installed_entry_point_gives_no_traceback(datasets: Path) -> None:
    bad = datasets / "robustness/laser_scan_matcher_demo.bag"
    proc = subprocess.run(
        [sys.executable, "-c", "from gndreplay.cli import main; main()", "info", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "laser_scan_matcher_demo.bag" in proc.stderr
    assert "Traceback" not in proc.stderr
