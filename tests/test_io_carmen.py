"""CARMEN reader and writer on hand-written logs with known answers; property tests on the parser."""

from __future__ import annotations

import bz2
import gzip
import math
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gndreplay.errors import GndReplayError, LogFormatError
from gndreplay.io import ReadOptions, open_log, read_ticks
from gndreplay.io.canonical import canonical_bearings, canonical_pose, canonical_stamp
from gndreplay.io.carmen import (
    CarmenReader,
    clean_ranges,
    detect_saturation,
    flaser_angles,
    format_time_s,
    parse_time_ns,
    write_carmen,
)
from gndreplay.io.sync import SyncOptions
from gndreplay.types import NS_PER_S, Odometry, Pose2D, Scan, Tick

DEG = math.pi / 180


def log_file(tmp_path: Path, text: str, name: str = "t.clf") -> Path:
    p = tmp_path / name
    data = text.encode()
    if name.endswith(".gz"):
        data = gzip.compress(data)
    elif name.endswith(".bz2"):
        data = bz2.compress(data)
    p.write_bytes(data)
    return p


def flaser(
    t: str,
    ranges: list[float | str],
    odom: tuple[float, float, float] = (0.0, 0.0, 0.0),
    laser: tuple[float, float, float] | None = None,
    trailer: str | None = None,
) -> str:
    lp = laser or odom
    tail = trailer if trailer is not None else f"{t} host 0.0"
    return (
        f"FLASER {len(ranges)} {' '.join(map(str, ranges))} {lp[0]} {lp[1]} {lp[2]} "
        f"{odom[0]} {odom[1]} {odom[2]} {tail}\n"
    )


def odom_line(t: str, x: float, y: float = 0.0, th: float = 0.0) -> str:
    return f"ODOM {x} {y} {th} 0.1 0.2 0.0 {t} host 0.0\n"


# ------------------------------------------------------------------------------------------------------------
# pure helpers


@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("1134864629.895182", 1134864629_895182000),
        ("70.1797", 70_179700000),
        ("12", 12 * NS_PER_S),
        ("-1.5", -1_500_000_000),
        ("0.0000000019", 1),
        ("1e3", 1000 * NS_PER_S),
        ("0", 0),
    ],
)
def test_parse_time_is_exact_for_decimals(text: str, ns: int) -> None:
    assert parse_time_ns(text) == ns


@pytest.mark.parametrize("bad", ["nan", "inf", "host", ""])
def test_parse_time_rejects_non_numbers(bad: str) -> None:
    with pytest.raises(ValueError, match=r"not finite|could not convert"):
        parse_time_ns(bad)


def test_format_time_round_trips() -> None:
    for t in (0, 1, 1134864629_895182000, -1_500_000_000, 123456789):
        assert parse_time_ns(format_time_s(t)) == t


@pytest.mark.parametrize(
    ("n", "step_deg", "last_deg"),
    [
        (181, 1.0, 90.0),
        (180, 1.0, 89.0),
        (361, 0.5, 90.0),
        (360, 0.5, 89.5),
        (401, 0.25, 10.0),
        (5, 45.0, 90.0),
    ],
)
def test_flaser_angles_follow_readlog(n: int, step_deg: float, last_deg: float) -> None:
    a = flaser_angles(n)
    assert a[0] == pytest.approx(-math.pi / 2)
    assert np.diff(a) == pytest.approx(step_deg * DEG)
    assert a[-1] == pytest.approx(last_deg * DEG)


def test_flaser_angles_from_param_fov_and_resolution() -> None:
    a = flaser_angles(241, fov_rad=240 * DEG)
    assert (a[0], a[-1]) == (pytest.approx(-120 * DEG), pytest.approx(120 * DEG))
    b = flaser_angles(11, resolution_rad=2 * DEG)
    assert (b[0], b[-1]) == (pytest.approx(-90 * DEG), pytest.approx(-70 * DEG))


def test_clean_ranges_marks_no_return_and_invalid() -> None:
    raw = np.array([1.0, 80.0, 81.91, np.nan, -1.0, np.inf, 0.05, 79.99])
    r = clean_ranges(raw, 80.0, 0.1)
    np.testing.assert_array_equal(r, [1.0, np.inf, np.inf, np.nan, np.nan, np.nan, np.nan, 79.99])


def test_saturation_marker_needs_repeats_across_scans() -> None:
    base = np.linspace(1, 20, 10)
    marked = [np.r_[base, 50.0, 50.0] for _ in range(3)]
    assert detect_saturation(marked) == 50.0
    assert detect_saturation([np.r_[base, 50.0]] * 2) is None  # too rare
    assert detect_saturation([np.r_[base, 81.91]] * 10) is None  # beyond the default: default rules
    assert detect_saturation([]) is None


# ------------------------------------------------------------------------------------------------------------
# reading hand-written lines


def test_flaser_known_answer(tmp_path: Path) -> None:
    text = "# comment\nPARAM robot_frontlaser_offset 0.25 host 0\n" + flaser(
        "100.5", [1.0, 81.91, "NaN", -2.0, 3.5], odom=(1.0, 2.0, 0.5)
    )
    with open_log(log_file(tmp_path, text)) as log:
        (tick,) = list(log.ticks())
        assert log.format_name == "carmen"
        assert log.describe().odom_source.startswith("FLASER")
    assert tick.index == 0 and tick.t_ns == 100_500_000_000
    np.testing.assert_array_equal(tick.scan.ranges_m, [1.0, np.inf, np.nan, np.nan, 3.5])
    np.testing.assert_allclose(tick.scan.angles_rad, np.radians([-90, -45, 0, 45, 90]))
    assert tick.scan.max_range_m == 80.0
    assert tick.scan.sensor_pose == Pose2D(0.25, 0.0, 0.0)
    assert tick.odom == Pose2D(1.0, 2.0, 0.5)
    assert tick.truth is None and tick.cmd is None


def test_rlaser_faces_backwards(tmp_path: Path) -> None:
    text = "PARAM robot_rearlaser_offset -0.3 h 0\n" + flaser("1", [1.0, 2.0, 3.0]).replace(
        "FLASER", "RLASER"
    )
    (tick,) = read_ticks(log_file(tmp_path, text))
    assert tick.scan.sensor_pose == canonical_pose(Pose2D(-0.3, 0.0, math.pi))


def test_rawlaser_geometry_comes_from_the_line(tmp_path: Path) -> None:
    line = "RAWLASER1 0 -1.0 2.0 0.5 4.0 0.01 0 5 1.0 2.0 4.5 3.0 NaN 2 0.5 0.6 12.25 host 0.1\n"
    (tick,) = read_ticks(log_file(tmp_path, line))
    np.testing.assert_allclose(tick.scan.angles_rad, [-1.0, -0.5, 0.0, 0.5, 1.0])
    np.testing.assert_array_equal(tick.scan.ranges_m, [1.0, 2.0, np.inf, 3.0, np.nan])
    assert tick.scan.max_range_m == 4.0
    assert tick.t_ns == 12_250_000_000
    assert tick.odom == Pose2D(0.0, 0.0, 0.0)  # RAWLASER carries no odometry and there is no ODOM


def test_robotlaser_mounting_and_odometry_from_the_line(tmp_path: Path) -> None:
    robot = (1.0, 2.0, math.pi / 2)
    laser = (1.0, 2.2, math.pi / 2 + 0.1)  # 0.2 m ahead of the robot, turned 0.1 rad
    line = (
        f"ROBOTLASER1 0 -1.5 3.0 1.0 30.0 0.01 0 4 1 2 3 40 0 "
        f"{' '.join(map(str, laser))} {' '.join(map(str, robot))} 0.3 0.0 0.5 0.2 0.0 7.0 host 0.0\n"
    )
    with open_log(log_file(tmp_path, line)) as log:
        (tick,) = list(log.ticks())
        assert log.describe().scan_stream == "ROBOTLASER1"
    assert tick.scan.sensor_pose.x == pytest.approx(0.2)
    assert tick.scan.sensor_pose.y == pytest.approx(0.0, abs=1e-12)
    assert tick.scan.sensor_pose.theta == pytest.approx(0.1)
    assert tick.odom == canonical_pose(Pose2D(*robot))
    np.testing.assert_array_equal(tick.scan.ranges_m, [1, 2, 3, np.inf])
    np.testing.assert_allclose(tick.scan.angles_rad, [-1.5, -0.5, 0.5, 1.5])


def test_odom_lines_are_interpolated_at_scan_stamps_and_file_order_is_merged(tmp_path: Path) -> None:
    text = (
        odom_line("10.0", 0.0)
        + flaser("10.6", [1, 2, 3], odom=(9, 9, 0))
        + odom_line("11.0", 1.0, 2.0, 0.2)
        + flaser("10.4", [1, 2, 3], odom=(9, 9, 0))
        + odom_line("12.0", 2.0, 2.0, 0.2)
    )
    with open_log(log_file(tmp_path, text)) as log:
        ticks = list(log.ticks())
        rep = log.report
        assert "ODOM" in log.describe().odom_source
    assert [t.t_ns for t in ticks] == [10_400_000_000, 10_600_000_000]
    assert ticks[0].odom.x == pytest.approx(0.4) and ticks[0].odom.y == pytest.approx(0.8)
    assert ticks[1].odom.theta == pytest.approx(0.12)
    assert rep.out_of_order == 1 and rep.time_reversals == 1 and rep.late_dropped == 0
    with open_log(log_file(tmp_path, text), options=ReadOptions(odom_topic="FLASER")) as log:
        assert [t.odom for t in log.ticks()] == [Pose2D(9, 9, 0)] * 2


def test_truepos_is_the_truth(tmp_path: Path) -> None:
    text = "TRUEPOS 0 0 0 0 0 0 1.0 h 0\n" + flaser("1.5", [1, 1, 1]) + "TRUEPOS 2 0 0.2 0 0 0 2.0 h 0\n"
    (tick,) = read_ticks(log_file(tmp_path, text))
    assert tick.truth == Pose2D(1.0, 0.0, pytest.approx(0.1))
    (tick,) = read_ticks(log_file(tmp_path, text), options=ReadOptions(truth_topic="FLASER"))
    assert tick.truth == Pose2D(0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("trailer", "t_ns"),
    [("host 5.5", 5_500_000_000), ("6.25", 6_250_000_000), ("7.0 0 laserazos", 7 * NS_PER_S)],
)
def test_trailer_variants(tmp_path: Path, trailer: str, t_ns: int) -> None:
    text = flaser("", [1, 1, 1], trailer=trailer) * 2
    assert [t.t_ns for t in read_ticks(log_file(tmp_path, text))] == [t_ns, t_ns]


def test_a_trailer_unlike_the_other_lines_is_malformed(tmp_path: Path) -> None:
    text = flaser("1.0", [1, 1, 1]) + flaser("", [1, 1, 1], trailer="host 2.5") + flaser("3.0", [1, 1, 1])
    with open_log(log_file(tmp_path, text)) as log:
        assert [t.t_ns for t in log.ticks()] == [NS_PER_S, 3 * NS_PER_S]
        assert log.report.malformed == 1
        assert "line 2: FLASER declares 3 ranges: 1 field too few" in log.report.malformed_examples[0]


def test_saturation_value_becomes_no_return(tmp_path: Path) -> None:
    text = "".join(flaser(str(i), [1.0, 50.0, 50.0, 3.0]) for i in range(1, 5))
    with open_log(log_file(tmp_path, text)) as log:
        ticks = list(log.ticks())
        assert any("no-return marker 50" in n for n in log.describe().notes)
    np.testing.assert_array_equal(ticks[0].scan.ranges_m, [1.0, np.inf, np.inf, 3.0])
    assert ticks[0].scan.max_range_m == 50.0


def test_param_max_range_wins(tmp_path: Path) -> None:
    text = "PARAM laser_front_laser_max_range 30 h 0\n" + flaser("1", [1.0, 30.0, 40.0])
    (tick,) = read_ticks(log_file(tmp_path, text))
    np.testing.assert_array_equal(tick.scan.ranges_m, [1.0, np.inf, np.inf])


def test_all_zero_stamps_get_an_index_clock_and_a_warning(tmp_path: Path) -> None:
    text = "".join(flaser("0", [1, 2, 3], trailer="0 0 name") for _ in range(3))
    with open_log(log_file(tmp_path, text)) as log:
        ticks = list(log.ticks())
        rep = log.report
    assert [t.t_ns for t in ticks] == [100_000_000, 200_000_000, 300_000_000]
    assert rep.index_clock
    assert any("index clock" in w for w in rep.warnings)


@pytest.mark.parametrize("suffix", [".clf", ".clf.gz", ".clf.bz2", ".log"])
def test_compressed_and_plain_read_the_same(tmp_path: Path, suffix: str) -> None:
    text = flaser("1.0", [1, 2, 3]) + flaser("2.0", [4, 5, 6])
    ticks = list(read_ticks(log_file(tmp_path, text, "x" + suffix)))
    assert [t.scan.ranges_m.tolist() for t in ticks] == [[1, 2, 3], [4, 5, 6]]


# ------------------------------------------------------------------------------------------------------------
# malformed input and errors


def test_malformed_line_in_the_middle_is_skipped_and_counted(tmp_path: Path) -> None:
    text = (
        flaser("1.0", [1, 2, 3])
        + "FLASER 5 1 2 3 0 0 0 0 0 0 2.0\n"
        + "FLASER 3 1 x 3 0 0 0 0 0 0 3 h 0\n"
        + "\x01\x02 garbage\n"
        + flaser("4.0", [1, 2, 3])
    )
    with open_log(log_file(tmp_path, text)) as log:
        ticks = list(log.ticks())
        rep = log.report
    assert len(ticks) == 2
    assert rep.malformed == 3
    assert rep.malformed_examples[0].startswith("line 2: FLASER declares 5 ranges")
    assert rep.malformed_examples[1] == "line 3: FLASER ranges are not numeric"
    assert rep.malformed_examples[2].startswith("line 4: not a CARMEN record")


def test_strict_turns_a_malformed_line_into_an_error(tmp_path: Path) -> None:
    text = flaser("1.0", [1, 2, 3]) + "FLASER 3 1 2 3 0 0 0 0 0 0\n" + flaser("4.0", [1, 2, 3])
    with pytest.raises(LogFormatError, match=r"t\.clf line 2: FLASER declares 3 ranges: line ends early"):
        list(read_ticks(log_file(tmp_path, text), options=ReadOptions(strict=True)))


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("FLASER 3 1 2 3 0 0 0 0 0 0 1 h 0 9 9", "unexpected extra fields"),
        ("FLASER -3 1 2 3 0 0 0 0 0 0 1 h 0", "count -3 out of range"),
        ("FLASER x 1 2 3 0 0 0 0 0 0 1 h 0", "count missing or not an integer"),
        ("FLASER 3 1 2 3 0 0 nan 0 0 0 1 h 0", "pose is not finite"),
        ("FLASER 3 1 2 3 0 0 0 0 0 0 host", "no timestamp"),
        ("ODOM 1 2 3 0 0 0", "line ends early"),
        ("ODOM 1 2 x 0 0 0 1 h 0", "odometry is not numeric"),
        ("TRUEPOS 1 2 3 0 0 0", "line ends early"),
        ("PARAM onlyname", "needs a name and a value"),
        ("RAWLASER1 0 -1 2 0.5 4 0.01 0 5 1 2 3", "declares 5 ranges: line ends early"),
        ("RAWLASER1 0 -1 2 0.5 4 0.01 0 3 1 2 3 -1 1 h 0", "remission count -1 out of range"),
    ],
)
def test_each_malformed_line_kind_names_the_problem(tmp_path: Path, line: str, message: str) -> None:
    name = line.split()[0]
    good = (
        flaser("5.0", [1, 2, 3]) if name != "RAWLASER1" else "RAWLASER1 0 -1 2 1 4 0.01 0 3 1 2 3 0 5 h 0\n"
    )
    text = good + "TRUEPOS 0 0 0 0 0 0 0.5 h 0\n" + "ODOM 0 0 0 0 0 0 0.5 h 0\n" + line + "\n"
    with pytest.raises(LogFormatError, match=f"line 4: .*{message}"):
        list(read_ticks(log_file(tmp_path, text), options=ReadOptions(strict=True)))


def test_not_a_carmen_log(tmp_path: Path) -> None:
    p = log_file(tmp_path, "Odometry 1 2 3\nLaser 3 1 2 3\n", "loop.log")
    with pytest.raises(LogFormatError, match=r"loop\.log: not a CARMEN log .*'Odometry'"):
        open_log(p)


def test_empty_log(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match=r"e\.clf: not a CARMEN log .*no records"):
        open_log(log_file(tmp_path, "# only a comment\n", "e.clf"))


def test_log_without_scans(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match=r"o\.clf: no scans: no laser message"):
        open_log(log_file(tmp_path, odom_line("1", 0.0), "o.clf"))


def test_scans_that_are_all_malformed_give_no_scans(tmp_path: Path) -> None:
    text = "FLASER 3 1 2 0 0 0 0 0 0\n" * 3
    with pytest.raises(LogFormatError, match=r"no scans \(FLASER lines\) in the log"):
        list(read_ticks(log_file(tmp_path, text)))


def test_missing_file_via_the_reader(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match=r"nope\.clf: cannot open"):
        CarmenReader(tmp_path / "nope.clf")


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"scan_topic": "LASER9"}, r"'LASER9' is not a CARMEN laser message; candidates: FLASER"),
        ({"scan_topic": "RLASER"}, r"no scans \(RLASER lines\)"),
        ({"odom_topic": "ODOM"}, r"no odometry stream 'ODOM'; candidates: FLASER"),
        ({"cmd_topic": "/cmd_vel"}, r"no command stream '/cmd_vel'"),
        ({"truth_topic": "TRUEPOS"}, r"no ground-truth stream 'TRUEPOS'; candidates: FLASER"),
    ],
)
def test_wrong_streams_list_the_candidates(tmp_path: Path, kw: dict[str, str], message: str) -> None:
    p = log_file(tmp_path, flaser("1", [1, 2, 3]))
    with pytest.raises(LogFormatError, match=message):
        list(read_ticks(p, options=ReadOptions(**kw)))


@pytest.mark.parametrize("suffix", [".clf.bz2", ".clf.gz"])
def test_truncated_compressed_log_is_an_error(tmp_path: Path, suffix: str) -> None:
    text = "".join(flaser(f"{i}.0", list(np.linspace(1, 9, 181).round(2))) for i in range(1, 200))
    p = log_file(tmp_path, text, "cut" + suffix)
    data = p.read_bytes()
    p.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(LogFormatError, match=r"cut\.clf\.(bz2|gz): truncated or corrupt data after line \d+"):
        list(read_ticks(p))


@pytest.mark.parametrize("suffix", [".clf.bz2", ".clf.gz"])
def test_a_truncated_compressed_log_is_read_to_its_last_whole_line(tmp_path: Path, suffix: str) -> None:
    """Every line that decompresses before the cut is read: the error names the last of them."""
    rng = np.random.default_rng(3)
    text = "".join(flaser(f"{i}.0", list(rng.uniform(1, 9, 181).round(3))) for i in range(1, 1500)).encode()
    data = bz2.compress(text, 1) if suffix == ".clf.bz2" else gzip.compress(text)  # bz2: 100 kB blocks
    cut = data[: len(data) * 2 // 3]
    unpacked = bz2.BZ2Decompressor().decompress(cut) if suffix == ".clf.bz2" else \
        zlib.decompressobj(31).decompress(cut)
    whole = unpacked.count(b"\n")
    assert 0 < whole < 1499
    p = tmp_path / ("cut" + suffix)
    p.write_bytes(cut)
    message = rf"cut\.clf\.(bz2|gz): truncated or corrupt data after line {whole}:"
    with pytest.raises(LogFormatError, match=message):
        list(read_ticks(p))


def test_record_beyond_the_reorder_window_is_dropped_and_counted(tmp_path: Path) -> None:
    text = "".join(flaser(f"{i}.0", [1, 1, 1]) for i in (1, 2, 3, 4, 5)) + flaser("1.5", [2, 2, 2])
    options = ReadOptions(sync=SyncOptions(reorder_window_ns=NS_PER_S))
    with open_log(log_file(tmp_path, text), options=options) as log:
        assert [t.t_ns // 10**8 for t in log.ticks()] == [10, 20, 30, 40, 50]
        assert log.report.late_dropped == 1


# ------------------------------------------------------------------------------------------------------------
# writer


MOUNT = Pose2D(0.2, 0.01, 0.05)


def make_ticks(
    n: int = 20,
    beams: int = 361,
    *,
    truth: bool = True,
    t0: int = 1_700_000_000_123_456_789,
    sensor: Pose2D = MOUNT,
) -> list[Tick]:
    rng = np.random.default_rng(1)
    angles = flaser_angles(beams)
    ticks = []
    for i in range(n):
        r = rng.uniform(0.3, 29.0, beams)
        r[::17] = np.inf
        r[5::23] = np.nan
        t = t0 + i * 100_000_000 + int(rng.integers(0, 1000))
        pose = Pose2D(0.1 * i, -0.05 * i, float(np.angle(np.exp(1j * (3.0 + 0.1 * i)))))
        ticks.append(
            Tick(
                i,
                t,
                Scan(t, r, angles, 30.0, 0.1, sensor),
                pose,
                truth=Pose2D(0.1 * i + 0.01, 0.0, 0.02 * i) if truth else None,
            )
        )
    return ticks


def assert_same_ticks(a: list[Tick], b: list[Tick]) -> None:
    """``b`` (read back) is ``a`` in the readers' one representation (io.canonical)."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert (x.index, canonical_stamp(x.t_ns)) == (y.index, y.t_ns)
        np.testing.assert_array_equal(x.scan.ranges_m.astype(np.float32), y.scan.ranges_m)
        np.testing.assert_allclose(canonical_bearings(x.scan.angles_rad), y.scan.angles_rad, rtol=0,
                                   atol=1e-12)
        assert (x.scan.max_range_m, x.scan.min_range_m) == (y.scan.max_range_m, y.scan.min_range_m)
        assert x.scan.sensor_pose == y.scan.sensor_pose
        assert canonical_pose(x.odom) == y.odom
        assert (canonical_pose(x.truth) if x.truth else None) == y.truth


@pytest.mark.parametrize(("suffix", "beams"), [(".clf", 361), (".clf.gz", 181), (".clf.bz2", 361)])
def test_writer_round_trips_exactly(tmp_path: Path, suffix: str, beams: int) -> None:
    ticks = make_ticks(beams=beams)
    p = tmp_path / f"sim{suffix}"
    write_carmen(p, ticks, params={"robot_name": "sim"})
    with open_log(p) as log:
        back = list(log.ticks())
        assert log.report.malformed == 0
        assert log.report.scans_without_odom_after == 0
    assert_same_ticks(ticks, back)
    assert list(tmp_path.iterdir()) == [p]  # no temporary file left behind


def test_writer_lines_are_what_carmen_tools_expect(tmp_path: Path) -> None:
    ticks = make_ticks(n=2, beams=181)
    p = tmp_path / "s.clf"
    write_carmen(p, ticks, decimals=2, hostname="sim")
    lines = p.read_text().splitlines()
    params = [ln for ln in lines if ln.startswith("PARAM")]
    assert "PARAM robot_frontlaser_offset 0.2 sim 0" in params
    fl = next(ln.split() for ln in lines if ln.startswith("FLASER"))
    assert fl[1] == "181" and len(fl) == 2 + 181 + 6 + 3
    assert fl[1 + 18] == "30.00"  # the no-return beam 17 is written as the max range
    laser = Pose2D(*map(float, fl[183:186]))
    expect = ticks[0].odom.compose(ticks[0].scan.sensor_pose)
    assert laser.x == pytest.approx(expect.x, abs=0.006) and laser.theta == pytest.approx(
        expect.theta, abs=0.006
    )
    assert fl[-3] == format_time_s(ticks[0].t_ns) and fl[-2] == "sim"


def test_writer_merges_a_separate_odometry_stream(tmp_path: Path) -> None:
    ticks = make_ticks(n=5, truth=False)
    odometry = [
        Odometry(ticks[0].t_ns - 50_000_000 + k * 50_000_000, Pose2D(0.01 * k, 0.0, 0.0), 0.2, 0.0)
        for k in range(12)
    ]
    p = tmp_path / "o.clf"
    write_carmen(p, ticks, odometry=odometry)
    kinds = [ln.split()[0] for ln in p.read_text().splitlines() if not ln.startswith(("#", "PARAM"))]
    assert kinds.count("ODOM") == 12 and kinds.count("FLASER") == 5
    back = list(read_ticks(p))
    t_odo = np.array([canonical_stamp(o.t_ns) for o in odometry], dtype=float)
    for tick in back:
        assert tick.odom.x == pytest.approx(np.interp(tick.t_ns, t_odo, [o.pose.x for o in odometry]))


def test_writer_uses_fov_params_for_centred_non_readlog_geometry(tmp_path: Path) -> None:
    angles = np.radians(np.linspace(-120, 120, 241))
    t = 5 * NS_PER_S
    tick = Tick(0, t, Scan(t, np.full(241, 2.0), angles, 8.0), Pose2D(0, 0, 0))
    p = tmp_path / "hok.clf"
    write_carmen(p, [tick])
    (back,) = read_ticks(p)
    np.testing.assert_allclose(back.scan.angles_rad, canonical_bearings(angles), atol=1e-12)


def test_writer_refuses_what_flaser_cannot_express(tmp_path: Path) -> None:
    t = NS_PER_S
    bad = Tick(0, t, Scan(t, np.ones(4), np.array([-1.0, 0.0, 0.5, 1.0]), 8.0), Pose2D(0, 0, 0))
    with pytest.raises(LogFormatError, match="cannot write the scan as CARMEN FLASER: 4 bearings"):
        write_carmen(tmp_path / "bad.clf", [bad])
    with pytest.raises(LogFormatError, match="cannot write a 1-beam scan"):
        write_carmen(
            tmp_path / "one.clf", [Tick(0, t, Scan(t, np.ones(1), np.zeros(1), 8.0), Pose2D(0, 0, 0))]
        )
    assert not list(tmp_path.iterdir())


def test_writer_refuses_a_changing_laser_and_leaves_no_file(tmp_path: Path) -> None:
    ticks = make_ticks(n=3)
    t = ticks[2]
    ticks[2] = Tick(2, t.t_ns, Scan(t.t_ns, t.scan.ranges_m, t.scan.angles_rad, 40.0), t.odom)
    with pytest.raises(LogFormatError, match=r"tick 2: the laser .* differs from the first tick's"):
        write_carmen(tmp_path / "x.clf.bz2", ticks)
    assert not list(tmp_path.iterdir())


def test_writer_refuses_params_with_spaces(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match="PARAM 'a b'"):
        write_carmen(tmp_path / "p.clf", make_ticks(n=1), params={"a b": "1"})


def test_writer_with_no_ticks_writes_params_only(tmp_path: Path) -> None:
    p = tmp_path / "empty.clf"
    write_carmen(p, [], params={"k": "v"})
    assert "PARAM k v gndreplay 0" in p.read_text()
    with pytest.raises(LogFormatError, match="no scans"):
        open_log(p)


# ------------------------------------------------------------------------------------------------------------
# property tests

finite = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)
ranges_st = st.lists(st.floats(min_value=0.0, max_value=79.99, allow_nan=False), min_size=2, max_size=40)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    ranges=ranges_st,
    pose=st.tuples(finite, finite, st.floats(-3.14, 3.14)),
    t=st.integers(min_value=0, max_value=4 * 10**18),
)
def test_random_valid_flaser_lines_round_trip(
    tmp_path: Path, ranges: list[float], pose: tuple[float, float, float], t: int
) -> None:
    t = t or 1
    line = flaser(format_time_s(t), [repr(r) for r in ranges], odom=pose)
    (tick,) = read_ticks(log_file(tmp_path, line, "h.clf"))
    assert tick.t_ns == canonical_stamp(t)
    np.testing.assert_array_equal(tick.scan.ranges_m, np.asarray(ranges, dtype=np.float32))
    assert tick.odom == canonical_pose(Pose2D(*pose))
    assert tick.scan.angles_rad.size == len(ranges)


VALID = (
    "PARAM robot_frontlaser_offset 0.1 h 0\n"
    + "".join(
        odom_line(f"{i}.05", 0.1 * i)
        + flaser(f"{i}.1", [1.5, 2.25, 3.0, 81.91, 4.0], odom=(0.1 * i, 0.0, 0.0))
        for i in range(1, 9)
    )
).encode()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    edits=st.lists(st.tuples(st.integers(0, len(VALID) - 1), st.integers(0, 255)), max_size=12),
    cut=st.integers(0, len(VALID)),
    suffix=st.sampled_from([".clf", ".clf.gz", ".clf.bz2"]),
    strict=st.booleans(),
)
def test_corruption_or_truncation_raises_only_our_error(
    tmp_path: Path, edits: list[tuple[int, int]], cut: int, suffix: str, strict: bool
) -> None:
    data = bytearray(VALID)
    for pos, byte in edits:
        data[pos] = byte
    data = data[:cut]
    raw = bytes(data)
    if suffix == ".clf.gz":
        raw = gzip.compress(raw)
    elif suffix == ".clf.bz2":
        raw = bz2.compress(raw)
    p = tmp_path / f"c{suffix}"
    p.write_bytes(raw)
    try:
        with open_log(p, options=ReadOptions(strict=strict)) as log:
            for tick in log.ticks():
                assert tick.scan.ranges_m.shape == tick.scan.angles_rad.shape
    except GndReplayError as err:
        assert isinstance(err, LogFormatError)
        assert "c.clf" in str(err)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(10, 2000), flips=st.lists(st.integers(0, 10**6), max_size=5))
def test_damaged_compressed_streams_raise_only_our_error(tmp_path: Path, cut: int, flips: list[int]) -> None:
    data = bytearray(bz2.compress(VALID * 3))
    for f in flips:
        data[f % len(data)] ^= 0x5A
    p = tmp_path / "d.clf.bz2"
    p.write_bytes(bytes(data[:cut]))
    try:
        for _ in read_ticks(p):
            pass
    except LogFormatError as err:
        assert "d.clf.bz2" in str(err)


def test_memory_does_not_grow_with_log_length(tmp_path: Path) -> None:
    import tracemalloc

    def peak(n: int) -> int:
        p = tmp_path / f"long{n}.clf.gz"
        write_carmen(p, make_ticks(n=n, beams=181, truth=False), decimals=2)
        tracemalloc.start()
        try:
            count = sum(1 for _ in read_ticks(p))
            return tracemalloc.get_traced_memory()[1] if count == n else -1
        finally:
            tracemalloc.stop()

    short, long = peak(200), peak(2000)
    assert short > 0 and long > 0
    assert long < 1.5 * short + 200_000  # 10x the scans, about the same peak (holding them: +2.6 MB)
