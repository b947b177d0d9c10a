"""``gndreplay info`` end to end: tables, JSON, the error boundary (exit 2, one line, no traceback)."""

from __future__ import annotations

import dataclasses
import json
import math
import re
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
from gndreplay.info import differences, log_info
from gndreplay.io.carmen import write_carmen
from gndreplay.io.clock import fmt_ns
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


def write_mcap_bag(tmp_path: Path, n: int = 40, stamps: list[int] | None = None,
                   angle_mins: tuple[float, ...] = (-1.0,), record_offset_ns: int = 0) -> Path:
    """A ROS 2 MCAP bag of scans alone, stamped 5 s + 0.1 s i (or ``stamps``), scan i starting at
    ``angle_mins[i % len(angle_mins)]``, recorded ``record_offset_ns`` after its stamp."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    path = tmp_path / "scans"
    stamps = stamps if stamps is not None else [5 * NS_PER_S + i * 100_000_000 for i in range(n)]
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        for i, t in enumerate(stamps):
            hdr = T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=t // NS_PER_S, nanosec=t % NS_PER_S), frame_id="l"
            )
            msg = T["sensor_msgs/msg/LaserScan"](
                header=hdr,
                angle_min=angle_mins[i % len(angle_mins)],
                angle_max=1.0,
                angle_increment=0.5,
                time_increment=0.0,
                scan_time=0.1,
                range_min=0.1,
                range_max=10.0,
                ranges=np.array([1, 2, np.nan, 20, 3], np.float32),
                intensities=np.zeros(0, np.float32),
            )
            w.write(c, t + record_offset_ns, ts.serialize_cdr(msg, "sensor_msgs/msg/LaserScan"))
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
    assert "start" in out and "1000.000000 s (1970-01-01 00:16:40.000 UTC)" in out
    assert "scan rate" in out and "5.00 Hz (median period 200.0 ms; average 5.00 Hz)" in out


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
    assert len(decoded) == 16  # each sampled scan and the next one (the start bearings' consecutive pairs)
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


# ------------------------------------------------------------------------------------------------------------
# the scan rate (median period), the dates, a synthetic clock


def jittered(start_ns: int, n: int, period_ns: int, gap_after: int | None = None,
             gap_ns: int = 0) -> list[int]:
    """Stamps one period apart with a recorded clock's jitter (up to +-0.9 ms, deterministic), and a gap."""
    return [start_ns + i * period_ns + (i * 7919 % 19 - 9) * 100_000
            + (gap_ns if gap_after is not None and i > gap_after else 0) for i in range(n)]


def carmen_at(tmp_path: Path, stamps: list[int], name: str = "clock.clf") -> Path:
    angles = -math.pi / 2 + np.arange(181) * math.pi / 180
    ticks = [Tick(i, t, Scan(t, np.full(181, 4.0), angles, 20.0), Pose2D(0.1 * i, 0.0, 0.0))
             for i, t in enumerate(stamps)]
    p = tmp_path / name
    write_carmen(p, ticks)
    return p


def test_the_scan_rate_is_the_median_period_with_the_average_beside_it(tmp_path: Path) -> None:
    """10 Hz with a 20 s gap: count / duration says 3.7 Hz, the median period says what the laser does."""
    start = 1_300_000_000 * NS_PER_S + 123_456_000
    stamps = jittered(start, 120, 100_000_000, gap_after=59, gap_ns=20 * NS_PER_S)
    d = info_json(carmen_at(tmp_path, stamps))
    assert d["scan_period_s"] == pytest.approx(0.1, abs=1e-3)
    assert d["scan_rate_hz"] == pytest.approx(10.0, rel=0.01)
    assert d["average_rate_hz"] == pytest.approx(119 / d["duration_s"]) and d["average_rate_hz"] < 4.0
    scan = next(s for s in d["streams"] if s["role"] == "scan")
    assert scan["rate_hz"] == pytest.approx(d["scan_rate_hz"])
    assert scan["average_hz"] == pytest.approx(d["average_rate_hz"])
    assert d["synthetic_clock"] is False and not any("synthetic" in w for w in d["warnings"])
    assert d["start_utc"] == "2011-03-13T07:06:40.122Z"  # 1.3e9 s + 123.456 ms - 0.9 ms of jitter
    out = runner.invoke(app, ["info", str(carmen_at(tmp_path, stamps))], env={"COLUMNS": "200"}).stdout
    assert re.search(r"scan rate +10\.0\d Hz \(median period 99\.\d ms; average 3\.7\d Hz\)", out), out
    assert "synthetic" not in out


def test_a_generated_clock_is_a_warning_in_the_table_and_the_json(carmen_log: Path) -> None:
    """The fixture's stamps are 1000 s + 0.2 s i, exactly: a simulator's or a converter's clock."""
    d = info_json(carmen_log)
    assert d["synthetic_clock"] is True
    expected = "synthetic clock: all 30 scan stamps are exactly 0.2 s apart from a round start (1000 s)"
    assert any(w.startswith(expected) for w in d["warnings"]) and d["clock_warning"].startswith(expected)
    assert d["start_utc"] == "1970-01-01T00:16:40.000Z" and d["end_utc"] == "1970-01-01T00:16:45.800Z"
    out = runner.invoke(app, ["info", str(carmen_log)], env={"COLUMNS": "300"}).stdout
    assert f"clock                   {expected}" in out


def test_periodic_stamps_from_a_start_that_is_not_round_are_not_flagged(tmp_path: Path) -> None:
    periodic = [1000 * NS_PER_S + 123_457 + i * 200_000_000 for i in range(30)]
    assert info_json(carmen_at(tmp_path, periodic))["synthetic_clock"] is False
    two = [1000 * NS_PER_S, 1000 * NS_PER_S + 200_000_000]  # too few to say
    assert info_json(carmen_at(tmp_path, two, "two.clf"))["synthetic_clock"] is False


def test_a_bag_gets_the_median_rate_the_dates_and_the_clock_warning(tmp_path: Path) -> None:
    start = 1_700_000_000 * NS_PER_S + 5_000_000
    stamps = jittered(start, 40, 100_000_000, gap_after=19, gap_ns=10 * NS_PER_S)
    recorded = write_mcap_bag(tmp_path / "rec", stamps=stamps)
    d = info_json(recorded)
    assert d["scan_rate_hz"] == pytest.approx(10.0, rel=0.01) and d["average_rate_hz"] < 3.0
    assert d["streams"][0]["rate_hz"] == pytest.approx(d["scan_rate_hz"]) and d["synthetic_clock"] is False
    assert d["start_utc"] == "2023-11-14T22:13:20.004Z"
    generated = info_json(write_mcap_bag(tmp_path / "gen"))  # 5 s + 0.1 s i
    assert generated["synthetic_clock"] is True and generated["scan_rate_hz"] == pytest.approx(10.0)
    assert "exactly 0.1 s apart from a round start (5 s)" in generated["clock_warning"]


def test_a_bag_from_the_reader_tests_is_periodic_but_recorded(tmp_path: Path) -> None:
    from test_io_rosbag import T0, write_bag

    d = info_json(write_bag(tmp_path, "ros1"))  # exactly 0.1 s apart, from T0 = ... .123456789 s
    assert d["synthetic_clock"] is False and d["scan_rate_hz"] == pytest.approx(10.0)
    assert d["start_s"] == pytest.approx(T0 / NS_PER_S) and d["start_utc"] == "2023-11-14T22:13:20.123Z"


def robotlaser_log(path: Path, starts_deg: tuple[float, ...], n: int = 40) -> Path:
    """ROBOTLASER1 scans of 181 beams 1 deg apart, scan i starting at ``starts_deg[i % len(starts_deg)]``."""
    lines = []
    for i in range(n):
        start, t = math.radians(starts_deg[i % len(starts_deg)]), 100.0 + 0.2 * i + 1e-5 * (i % 3)
        pose = f"{0.1 * i} 0.0 0.0"
        lines.append(f"ROBOTLASER1 0 {start!r} {math.pi!r} {math.radians(1.0)!r} 30.0 0.01 0 181 "
                     f"{' '.join(['4.0'] * 181)} 0 {pose} {pose} 0.1 0.0 0.5 0.2 0.0 {t:.6f} host {t:.6f}\n")
    path.write_text("".join(lines))
    return path


def test_interleaved_start_bearings_are_reported(tmp_path: Path) -> None:
    """A scanner that shifts its start by a quarter degree each scan (four interleaved bearing sets)."""
    starts = (-90.0, -89.75, -89.5, -89.25)
    d = info_json(robotlaser_log(tmp_path / "inter.clf", starts))
    assert d["interleaved"] is True and d["start_pairs"] == 39 and d["start_changes"] == 39
    assert d["start_angles_deg"] == pytest.approx(list(starts), abs=1e-3) and d["uneven_scans"] == 0
    out = runner.invoke(app, ["info", str(tmp_path / "inter.clf")], env={"COLUMNS": "300"}).stdout
    assert ("beam geometry           interleaved: 4 start bearings (-90.000, -89.750, -89.500, -89.250 deg), "
            "different in 39 of 39 consecutive scan pairs; evenly spaced") in out
    steady = info_json(robotlaser_log(tmp_path / "steady.clf", (-90.0,)))
    assert steady["interleaved"] is False and steady["start_changes"] == 0
    assert steady["start_angles_deg"] == pytest.approx([-90.0])


def test_interleaved_start_bearings_in_a_sampled_bag(tmp_path: Path) -> None:
    """A bag's sample decodes each sampled scan with the next one, so alternation shows at any sampling."""
    bag = write_mcap_bag(tmp_path / "alt", n=40, angle_mins=(-1.0, -0.75))
    d = log_info(bag, sample=10)  # every 4th scan: the sampled ones alone all start at -1.0
    assert d.interleaved and d.start_pairs == 10 and d.start_changes == 10
    assert d.start_angles_deg == pytest.approx((math.degrees(-1.0), math.degrees(-0.75)))
    full = log_info(bag)
    assert full.start_pairs == 39 and full.start_changes == 39 and full.stats_scans == 40
    one = log_info(write_mcap_bag(tmp_path / "one"), sample=10)
    assert not one.interleaved and one.start_changes == 0 and one.stats_scans == 10


def test_header_stamps_far_from_the_record_times_are_reported(tmp_path: Path) -> None:
    """A converter recording on its own clock: the offset is in the JSON always, in the table when large."""
    late = write_mcap_bag(tmp_path / "late", record_offset_ns=3600 * NS_PER_S)
    d = info_json(late)
    assert d["record_offset_s"] == -3600.0 and d["record_offset_max_s"] == -3600.0
    out = runner.invoke(app, ["info", str(late)], env={"COLUMNS": "300"}).stdout
    assert re.search(r"header vs record time +scan header stamps 3600\.000 s before the bag's record times "
                     r"\(median; largest -3600\.000 s\)", out), out
    same = write_mcap_bag(tmp_path / "same")
    assert info_json(same)["record_offset_s"] == 0.0
    assert "header vs record time" not in runner.invoke(app, ["info", str(same)]).stdout
    carmen = robotlaser_log(tmp_path / "c.clf", (-90.0,))
    assert info_json(carmen)["record_offset_s"] is None


def test_differences_name_what_two_containers_disagree_on(tmp_path: Path) -> None:
    base = log_info(robotlaser_log(tmp_path / "a.clf", (-90.0,)))
    assert differences(base, base) == []
    other = log_info(robotlaser_log(tmp_path / "b.clf", (-90.0, -89.75)))
    assert [str(d) for d in differences(base, other)] == ["interleaved start bearings: no against yes"]
    shifted = dataclasses.replace(base, start_ns=base.start_ns + 1500, resolution_deg=1.0056, range_min_m=0.3,
                                  laser_pose=(0.2, 0.0, math.pi), laser_pose_source="tf")
    found = differences(base, shifted)
    assert [str(d) for d in found] == [
        "beam step: 1.0000 deg against 1.0056 deg",
        "range min: 0 m against 0.3 m",
        "laser pose in robot: (0 m, 0 m, 0 deg) from log against (0.2 m, 0 m, 180 deg) from tf",
        f"first scan stamp: {fmt_ns(base.start_ns)} s against {fmt_ns(base.start_ns + 1500)} s",
    ]
    assert "later" in found[-1].effect and "0.0000015 s" in found[-1].effect
    # the base log's returns are all 4 m: a minimum of 0.3 m invalidates none of them
    assert [d.affects_replay for d in found] == [True, False, True, True]
    shorter = dataclasses.replace(shifted, range_min_m=5.0)
    assert next(d for d in differences(base, shorter) if d.what == "range min").affects_replay


def test_differences_between_the_aces_file_and_its_bags(datasets: Path) -> None:
    """The bags of ACES space its 180 beams over 180 deg (pi / 179 apart), CARMEN's readlog.c 1 deg apart."""
    clf = log_info(datasets / "carmen" / "aces.clf.bz2")
    assert [str(d) for d in differences(clf, log_info(datasets / "rosbag1" / "aces.sort.bag"))] == [
        "last bearing: 89.0000 deg against 90.0000 deg",
        "beam step: 1.0000 deg against 1.0056 deg",
        "range min: 0 m against 0.3 m",
    ]
    synthetic = [str(d) for d in differences(clf, log_info(datasets / "rosbag1" / "aces.clf2bag.bag"))]
    assert synthetic[-2:] == ["first scan stamp: 70.2899 s against 1000000000 s",
                              "scan clock: recorded against generated"]
