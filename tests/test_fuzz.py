"""Hostile input: a seeded fuzz run over every log format and every other file a user hands gndreplay
(scenario, config, thresholds, run folder), and one regression test per failure class of the log readers.

Every damaged log must end as LogFormatError (one line naming the file, and the line / message when known),
or be read with the damaged records skipped and counted; never another exception, a hang, a value that can
overflow downstream, or a memory blow-up. ``benchmarks/fuzz.py`` runs the same fuzzer on 10,000+ inputs.
"""

from __future__ import annotations

import bz2
import gzip
import math
import sqlite3
import struct
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import fuzz_files
import fuzzing
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from test_io_carmen import flaser, log_file, odom_line
from test_io_rosbag import DT, T0, Msgs, ranges_for, typestore

from gndreplay.errors import LogFormatError
from gndreplay.info import log_info
from gndreplay.io import ReadOptions, open_log
from gndreplay.io.base import MAX_ABS_TIME_NS

# inputs per format in CI: 490 in about 25 s on a loaded 2-core machine
PER_FORMAT = {"carmen": 100, "carmen.gz": 70, "carmen.bz2": 70, "ros1": 60, "ros2-db3": 40, "ros2-yaml": 50}
PER_FORMAT |= {"ros2-mcap": 40, "mcap": 60}


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> fuzzing.Seeds:
    return fuzzing.Seeds(tmp_path_factory.mktemp("fuzz"))


@pytest.mark.parametrize("fmt", fuzzing.FORMATS)
def test_fuzzed_logs_raise_only_our_error(seeds: fuzzing.Seeds, fmt: str, tmp_path: Path) -> None:
    outcomes = []
    with fuzzing.memory_guard():
        for i in range(PER_FORMAT[fmt]):
            outcomes.append(fuzzing.run_input(fuzzing.make_input(seeds, fmt, i), fmt, i, tmp_path / "in"))
    kinds = Counter(o.kind for o in outcomes)
    bad = [f"#{o.index} {o.kind}: {o.detail}" for o in outcomes if o.kind in ("other", "hang")]
    assert not bad, "\n".join(bad)
    assert kinds["ok"] > 0 and kinds["error"] > 0, kinds  # the mutations neither all break nor all miss
    assert max(o.peak_mb for o in outcomes) < 500


# inputs per kind of user file in CI (the scenario runs 0.6 s of closed loop per input; about 3 % of the
# config mutations leave a valid file, so 240 make one all but certain)
FILE_PER_FORMAT = {"scenario": 40, "config": 240, "thresholds": 80, "rundir": 40}


@pytest.fixture(scope="module")
def file_seeds(tmp_path_factory: pytest.TempPathFactory) -> fuzz_files.FileSeeds:
    return fuzz_files.FileSeeds.make(tmp_path_factory.mktemp("file-seeds"))


@pytest.mark.parametrize("fmt", fuzz_files.FILE_FORMATS)
def test_fuzzed_user_files_raise_only_our_error_and_touch_nothing_outside(
        file_seeds: fuzz_files.FileSeeds, fmt: str, tmp_path: Path) -> None:
    decoy = fuzz_files.make_decoy(tmp_path / "decoy")  # beside "in": where planted links point
    digest = fuzz_files.decoy_digest(decoy)
    outcomes = []
    with fuzzing.memory_guard():
        for i in range(FILE_PER_FORMAT[fmt]):
            seed = fuzz_files.make_file_input(file_seeds, fmt, i)
            outcomes.append(fuzzing.run_input(seed, fmt, i, tmp_path / "in"))
            assert fuzz_files.decoy_digest(decoy) == digest, f"#{i} changed a file outside its folder"
    kinds = Counter(o.kind for o in outcomes)
    bad = [f"#{o.index} {o.kind}: {o.detail}" for o in outcomes if o.kind in ("other", "hang")]
    assert not bad, "\n".join(bad)
    assert kinds["ok"] > 0 and kinds["error"] > 0, kinds
    assert max(o.peak_mb for o in outcomes) < 500


def test_the_fuzzer_is_a_pure_function_of_its_seed(seeds: fuzzing.Seeds) -> None:
    for fmt in ("carmen.bz2", "ros2-yaml", "mcap"):
        a, b = fuzzing.make_input(seeds, fmt, 7), fuzzing.make_input(seeds, fmt, 7)
        assert a == b and a != fuzzing.make_input(seeds, fmt, 8)


def test_the_contract_check_catches_an_overflowing_value(tmp_path: Path) -> None:
    (tick,) = list(open_log(log_file(tmp_path, flaser("1.0", [1, 2, 3]))).ticks())
    fuzzing.check_tick(tick)
    with pytest.raises(AssertionError, match="odom"):
        fuzzing.check_tick(type(tick)(0, tick.t_ns, tick.scan, type(tick.odom)(1e308, 0.0, 0.0)))


# ------------------------------------------------------------------------------------------------------------
# helpers


def read_all(path: Path, *, strict: bool = False) -> tuple[int, Any]:
    """(ticks, read report) of a full pass, then ``log_info`` too (the CLI's two paths)."""
    with open_log(path, options=ReadOptions(strict=strict)) as log:
        ticks = list(log.ticks())
        for tick in ticks:
            fuzzing.check_tick(tick)
        report = log.report
    log_info(path, options=ReadOptions(strict=strict))
    return len(ticks), report


def assert_our_error(path: Path, match: str = "", *, strict: bool = False) -> str:
    with pytest.raises(LogFormatError, match=match) as err:
        read_all(path, strict=strict)
    text = str(err.value)
    assert "\n" not in text and path.name in text
    return text


# ------------------------------------------------------------------------------------------------------------
# CARMEN

GOOD = "".join(odom_line(f"{i}.05", 0.1 * i) + flaser(f"{i}.1", [1.5, 2.0, 3.0]) for i in range(1, 5))


@pytest.mark.parametrize(
    ("line", "why"),
    [
        (flaser("1e300", [1, 2, 3]), "out of range"),
        (flaser("99999999999999999999999", [1, 2, 3]), "out of range"),
        (flaser("2.5", [1, 2, 3], odom=(1e308, 0.0, 0.0)), "not finite or out of range"),
        (flaser("2.5", [1, 2, 3]).replace(" 0.0 0.0 0.0 2.5", " 0.0 0.0 nan 2.5"), "not finite"),
        ("ODOM 1e300 0 0 0 0 0 2.5 host 0.0\n", "not finite or out of range"),
        ("ODOM 0 0 inf 0 0 0 2.5 host 0.0\n", "not finite"),
        ("ODOM 0 0 0 1e9 0 0 2.5 host 0.0\n", "velocity"),
        ("TRUEPOS 0 -1e7 0 0 0 0 2.5 host 0.0\n", "out of range"),
        ("RAWLASER1 0 -1 2 1e300 4 0.01 0 3 1 2 3 0 2.5 h 0\n", "bearings"),
        ("RAWLASER1 0 -1 2 0.5 1e300 0.01 0 3 1 2 3 0 2.5 h 0\n", "max range"),
    ],
)
def test_absurd_carmen_values_are_malformed_lines(tmp_path: Path, line: str, why: str) -> None:
    p = log_file(tmp_path, GOOD + line)
    if line.startswith("RAWLASER"):  # a RAWLASER stream of its own
        p = log_file(tmp_path, "RAWLASER1 0 -1 2 0.5 4 0.01 0 3 1 2 3 0 1.5 h 0\n" + line)
    n, report = read_all(p)
    assert n >= 1 and report.malformed == 1
    assert "line " in report.malformed_examples[0] and why in report.malformed_examples[0]
    assert_our_error(p, f"line {9 if not line.startswith('RAWLASER') else 2}: .*{why}", strict=True)


@pytest.mark.parametrize(
    ("ranges", "message"), [([1, 2, 3, 4], "1 unexpected extra field"), ([1, 2], "1 field too few")]
)
def test_a_flaser_line_with_a_range_too_many_or_too_few_is_malformed(
    tmp_path: Path, ranges: list[float], message: str
) -> None:
    wrong = flaser("2.5", ranges).replace(f"FLASER {len(ranges)} ", "FLASER 3 ")
    p = log_file(tmp_path, flaser("1.0", [1, 2, 3]) + wrong + flaser("3.0", [1, 2, 3]))
    with open_log(p) as log:
        assert [t.t_ns / 1e9 for t in log.ticks()] == [1.0, 3.0]  # not read with its fields shifted
        assert log.report.malformed == 1
        assert f"line 2: FLASER declares 3 ranges: {message}" in log.report.malformed_examples[0]
    assert_our_error(p, f"line 2: FLASER declares 3 ranges: {message}", strict=True)


def corrupt_gzip() -> bytes:
    """A gzip member whose deflate data is damaged past the first lines (zlib.error, not OSError)."""
    data = bytearray(gzip.compress((GOOD * 200).encode(), mtime=0))
    data[len(data) // 2 : len(data) // 2 + 8] = b"\xff" * 8
    return bytes(data)


@pytest.mark.parametrize(
    ("name", "data"),
    [
        ("z.clf.gz", corrupt_gzip()),
        ("t.clf.gz", gzip.compress(GOOD.encode())[:-30]),  # EOFError
        ("b.clf.gz", b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\xff" + b"\xff" * 40),  # invalid block type
        ("b.clf.bz2", b"BZh91AY&SY" + b"\x00" * 40),  # bz2 OSError
        ("t.clf.bz2", bz2.compress((GOOD * 50).encode())[:-50]),
    ],
)
def test_every_decompression_error_is_ours(tmp_path: Path, name: str, data: bytes) -> None:
    p = tmp_path / name
    p.write_bytes(data)
    assert_our_error(p, "truncated or corrupt data|not a CARMEN log")


def test_a_zero_bomb_is_refused_at_once_with_bounded_memory(tmp_path: Path) -> None:
    data = bz2.compress(b"\0" * (100 << 20))  # about a hundred bytes on disk
    assert len(data) < 1000
    out = fuzzing.run_input(fuzzing.Seed({"z.clf.bz2": data}, "z.clf.bz2"), "carmen.bz2", 0, tmp_path / "in")
    assert out.kind == "error" and "line longer than 4 MB" in out.detail, out
    assert out.peak_mb < 100 and out.seconds < 5


def test_an_over_long_line_is_skipped_and_counted(tmp_path: Path) -> None:
    text = flaser("1.0", [1, 2, 3]) + "FLASER 3 " + "1 " * (3 << 20) + "\n" + flaser("2.0", [1, 2, 3])
    p = log_file(tmp_path, text, "long.clf.gz")
    n, report = read_all(p)
    assert (
        n == 2 and report.malformed == 1 and "line 2: line longer than 4 MB" in report.malformed_examples[0]
    )


def test_the_head_scan_keeps_a_bounded_amount_of_text(tmp_path: Path) -> None:
    from gndreplay.io import carmen

    line = "PARAM x " + "y" * (3 << 20) + " h 0\n"  # 3 MB lines: the head stops keeping them at 16 MB
    p = log_file(tmp_path, flaser("1.0", [1, 2, 3]) + line * 12 + flaser("2.0", [1, 2, 3]), "big.clf.gz")
    _, opened = carmen._peek(p)
    try:
        assert sum(len(ln) for _, ln in opened.lines) <= carmen._HEAD_BYTES + (4 << 20)
    finally:
        opened.fh.close()
    assert read_all(p)[0] == 2


# ------------------------------------------------------------------------------------------------------------
# ROS bags: absurd values in valid messages


def write_values_bag(tmp: Path, kind: str, bad: dict[str, Any]) -> Path:
    """A bag of 4 scans with odometry and commands; message 2 of a topic gets the values in ``bad``."""
    ros1 = kind == "ros1"
    ts = typestore(ros1)
    m = Msgs(ts, ros1)
    ser = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    path = tmp / ("v.bag" if ros1 else "v")
    writer: Any = Writer1(path) if ros1 else Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP)
    st, ot, ct = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "geometry_msgs/msg/Twist"
    with writer as w:
        cs, co, cc = (
            w.add_connection(tp, t, typestore=ts)
            for tp, t in (("/scan", st), ("/odom", ot), ("/cmd_vel", ct))
        )
        for k in range(6):
            t = T0 - DT // 2 + k * DT
            x = bad.get("odom_x", 0.1 * k) if k == 2 else 0.1 * k
            yaw = bad.get("odom_yaw", 0.0) if k == 2 else 0.0
            w.write(co, t, ser(m.odom(t, x, 0.0, yaw), ot))
        for i in range(4):
            t = T0 + i * DT
            msg = m.scan(t, ranges_for(i)[:30])
            if i == 2:
                for field in ("range_max", "angle_increment", "angle_min"):
                    if field in bad:
                        setattr(msg, field, bad[field])
            w.write(cs, t + 10_000_000, ser(msg, st))
            v = bad.get("cmd_v", 0.1) if i == 2 else 0.1
            w.write(
                cc, bad.get("log_t", t + 5_000_000) if i == 2 else t + 5_000_000, ser(m.twist(v, 0.0), ct)
            )
    return path


ABSURD = [
    ({"odom_x": 1e308}, "/odom", "odometry pose"),
    ({"odom_x": math.nan}, "/odom", "odometry pose"),
    ({"odom_yaw": math.nan}, "/odom", "odometry pose"),
    ({"range_max": 1e30}, "/scan", "range_max"),
    ({"angle_increment": math.nan}, "/scan", "bearings"),
    ({"angle_min": 1e30}, "/scan", "bearings"),
    ({"cmd_v": math.inf}, "/cmd_vel", "command"),
]


@pytest.mark.parametrize(
    ("kind", "bad", "topic", "why"),
    [("ros1", *case) for case in ABSURD]
    + [("mcap", *case) for case in ABSURD]
    + [("mcap", {"log_t": 2**63 - 1}, "/cmd_vel", "timestamp")],  # a ROS1 time (uint32 s) cannot be that late
)
def test_absurd_ros_values_are_malformed_messages(
    tmp_path: Path, kind: str, bad: dict[str, Any], topic: str, why: str
) -> None:
    p = write_values_bag(tmp_path, kind, bad)
    n, report = read_all(p)
    assert (
        report.malformed == 1
        and topic in report.malformed_examples[0]
        and why in report.malformed_examples[0]
    )
    assert n >= 3
    assert_our_error(p, f"message .* on {topic}: .*{why}", strict=True)


# ------------------------------------------------------------------------------------------------------------
# ROS bags: damaged containers (the reader library's exceptions)


def chunk_data(data: bytes) -> tuple[int, int]:
    """Offset and length of the (compressed) records of the first MCAP chunk."""
    pos = 8
    while pos < len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        body = pos + 9
        if op == 0x06:  # Chunk: start, end, uncompressed size, crc, compression, records
            p = body + 28
            p += 4 + struct.unpack_from("<I", data, p)[0]
            return p + 8, struct.unpack_from("<Q", data, p)[0]
        pos = body + length
    raise AssertionError("no chunk")


@pytest.fixture(scope="module")
def mcap_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    tmp = tmp_path_factory.mktemp("mcap")
    fuzzing._write_ros(tmp / "b", "mcap", None)
    (inner,) = (tmp / "b").glob("*.mcap")
    out = {}
    for comp in ("NONE", "LZ4", "ZSTD"):
        fuzzing._rechunk_mcap(inner, tmp / f"{comp}.mcap", comp)
        out[comp] = (tmp / f"{comp}.mcap").read_bytes()
    return out


@pytest.mark.parametrize("comp", ["LZ4", "ZSTD"])
def test_a_corrupt_compressed_mcap_chunk_is_our_error(
    tmp_path: Path, mcap_files: dict[str, bytes], comp: str
) -> None:
    data = bytearray(mcap_files[comp])
    start, length = chunk_data(bytes(data))
    data[start + length // 2 : start + length // 2 + 16] = b"\xa5" * 16
    p = tmp_path / "c.mcap"
    p.write_bytes(bytes(data))
    assert_our_error(p, "corrupt or truncated|refuses it")


@pytest.mark.parametrize("length", [2**62, 2**40, 2**64 - 1])
def test_a_corrupt_mcap_record_length_is_our_error(
    tmp_path: Path, mcap_files: dict[str, bytes], length: int
) -> None:
    data = bytearray(mcap_files["NONE"])
    data[9:17] = struct.pack("<Q", length)  # the Header record's length
    p = tmp_path / "l.mcap"
    p.write_bytes(bytes(data))
    with fuzzing.memory_guard():
        assert_our_error(p, "refuses it")


@pytest.fixture
def sqlite_bag(tmp_path: Path) -> Iterator[Path]:
    d = tmp_path / "s"
    fuzzing._write_ros(d, "sqlite3", None)
    yield d


def test_a_truncated_sqlite3_bag_is_our_error_mid_stream(sqlite_bag: Path) -> None:
    (db,) = sqlite_bag.glob("*.db3")
    data = db.read_bytes()
    db.write_bytes(data[: len(data) - 2048])  # the last page cut: CorruptError once messages are read
    assert_our_error(sqlite_bag, "corrupt or truncated|refuses it")


def test_a_damaged_sqlite3_bag_is_our_error_at_open(sqlite_bag: Path) -> None:
    (db,) = sqlite_bag.glob("*.db3")
    data = bytearray(db.read_bytes())
    data[4096:8192] = bytes(4096)
    db.write_bytes(bytes(data))
    assert_our_error(sqlite_bag, "refuses it")


def test_a_corrupt_zstd_message_is_our_error(tmp_path: Path) -> None:
    d = tmp_path / "z"
    fuzzing._write_ros(d, "sqlite3", None, "MESSAGE")
    (db,) = d.glob("*.db3")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = ? WHERE id = 20", (b"\x28\xb5\x2f\xfd" + b"\x11" * 40,))
    con.close()
    assert_our_error(d, "after message .*ZstdError")


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (("message_count: 6", "message_count: {a: 1}"), "metadata.yaml: topic /scan: message_count"),
        (("name: /scan", "name: 1e300"), "metadata.yaml: topic 1: name"),
        (("type: sensor_msgs/msg/LaserScan", "type: {x: 1}"), "metadata.yaml: topic 1: .* must be text"),
        (("version: 9", "version: abc"), "Invalid bag metadata"),
        (("relative_file_paths:\n  - s.db3", "relative_file_paths: 5"), "Invalid bag metadata"),
        (("  duration:\n    nanoseconds: 6", "  duration:\n    nanoseconds: x6"), "TypeError"),
        (("storage_identifier: sqlite3", "storage_identifier: [1]"), "Invalid bag metadata"),
    ],
)
def test_wrong_metadata_yaml_values_are_named(sqlite_bag: Path, edit: tuple[str, str], key: str) -> None:
    meta = sqlite_bag / "metadata.yaml"
    text = meta.read_text()
    assert edit[0] in text
    meta.write_text(text.replace(edit[0], edit[1], 1))
    assert_our_error(sqlite_bag, key)


def test_the_time_bound_leaves_room_for_stamp_differences() -> None:
    assert np.iinfo(np.int64).max > 2 * MAX_ABS_TIME_NS


def test_the_boundary_checks() -> None:
    from gndreplay.io.base import check_bearings, check_pose, check_speed, check_time

    assert check_time(-MAX_ABS_TIME_NS) == -MAX_ABS_TIME_NS
    assert check_pose(1.0, -2.0, 3 * math.pi).theta == pytest.approx(math.pi)
    assert math.isnan(check_speed(math.nan, "v", allow_nan=True))
    check_bearings(-math.pi, 2 * math.pi / 359, 360)
    for call in (
        lambda: check_time(MAX_ABS_TIME_NS + 1),
        lambda: check_pose(math.nan, 0.0, 0.0),
        lambda: check_pose(0.0, 1e6, 0.0),
        lambda: check_pose(0.0, 0.0, math.inf),
        lambda: check_speed(math.nan, "v"),
        lambda: check_speed(-1e4, "v"),
        lambda: check_bearings(0.0, math.nan, 2),
        lambda: check_bearings(0.0, 1.0, 100),
    ):
        with pytest.raises(ValueError, match=r"out of range|not finite"):
            call()
