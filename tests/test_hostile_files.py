"""Hostile user files: configs, thresholds, relations, TUM trajectories, a run folder read back by
``report``, and ROS scans with too many beams.

Each must end as one line naming the file (and the key, member or message), a GndReplayError the CLI maps
to exit code 2, or be skipped and counted (a malformed message), never a traceback, a hang or unbounded
memory. Every input is generated here, small.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import resource
import threading
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from test_io_rosbag import DT, T0, Msgs, ranges_for, robot, typestore

from gndreplay.batch.thresholds import THRESHOLD_KEYS, limit_bound, load_thresholds
from gndreplay.config import load_config
from gndreplay.errors import ConfigError, GndReplayError, LogFormatError
from gndreplay.evaluation import load_relations, read_tum
from gndreplay.io import ReadOptions, open_log, read_ticks
from gndreplay.io.base import MAX_BEAMS
from gndreplay.report.maps import HitRaster, save_maps
from gndreplay.report.rundir import COMMAND_COLUMNS, RunDirError, load_run

BIG = "9" * 401  # beyond a float
LONG = "9" * 4000  # within Python's int <-> str limit, far beyond a float
DEEP = 5000


def one_line(err: BaseException, path: Path, *names: str) -> str:
    """The error text, checked: one short line naming ``path`` and each of ``names``."""
    msg = str(err)
    assert "\n" not in msg and len(msg) < 1500, msg[:1600]
    assert str(path) in msg, msg
    for name in names:
        assert name in msg, msg
    return msg


@contextlib.contextmanager
def memory_cap(extra_bytes: int = 1 << 30) -> Iterator[None]:
    """Cap the address space at its current size + ``extra_bytes``: an unbounded read ends as MemoryError
    (a test failure) instead of taking the shared machine down."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/status") as f:
        vm_kb = next(int(line.split()[1]) for line in f if line.startswith("VmSize:"))
    cap = vm_kb * 1024 + extra_bytes
    resource.setrlimit(resource.RLIMIT_AS, (cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def refused_without_blocking(call: Callable[[], Any], fifo: Path) -> BaseException | None:
    """What ``call`` raised, run in a thread; fails the test when it blocks on ``fifo`` (opening the FIFO's
    write end then frees the reader, so the test never hangs)."""
    box: dict[str, BaseException] = {}

    def run() -> None:
        try:
            call()
        except BaseException as err:
            box["err"] = err

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(5.0)
    if th.is_alive():
        with contextlib.suppress(OSError):
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        th.join(5.0)
        pytest.fail(f"blocked reading the FIFO {fifo}")
    return box.get("err")


def write(path: Path, text: str | bytes) -> Path:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


# ---------------------------------------------------------------- config files


@pytest.mark.parametrize(
    ("text", "names"),
    [
        (f"[robot]\nvmax_mps = {BIG}\n", ("robot.vmax_mps", "(0, 10]", "an integer of")),
        (f"[robot]\nvmax_mps = -{LONG}\n", ("robot.vmax_mps", "an integer of")),
        (f"[grid]\nsize_cells = {BIG}\n", ("grid.size_cells", "[4, 4000]")),
        (f"[grid]\nsize_cells = {LONG}\n", ("grid.size_cells",)),
        (f"[planner.nf1]\nconnectivity = {LONG}\n", ("planner.nf1.connectivity", "expected one of 4, 8")),
        (f"[robot]\nshape = '{'x' * 100_000}'\n", ("robot.shape",)),
        (f"[robot]\nvmax_mps = '{'x' * 100_000}'\n", ("robot.vmax_mps", "expected a number")),
        ("[robot]\nvmax_mps = " + "[" * DEEP + "]" * DEEP + "\n", ("nested more than",)),
        ("robot = " + "{ a = " * DEEP + "1" + " }" * DEEP + "\n", ("nested more than",)),
        (f"preset = '{'w' * 100_000}'\n", ("unknown preset",)),
    ],
)
def test_hostile_config_values_are_one_line(tmp_path: Path, text: str, names: tuple[str, ...]) -> None:
    p = write(tmp_path / "cfg.toml", text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    one_line(e.value, p, *names)


def test_a_config_that_is_not_utf8_names_the_line(tmp_path: Path) -> None:
    p = write(tmp_path / "cfg.toml", b"[robot]\nvmax_mps = 0.2 # caf\xe9\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    one_line(e.value, p, "line 2", "not UTF-8")


def test_range_errors_keep_their_text(tmp_path: Path) -> None:
    """A number out of range reads as before: the key, the range with its open or closed ends, the value
    as the setting would hold it."""
    p = write(tmp_path / "cfg.toml", "[robot]\nvmax_mps = 11\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{p}: robot.vmax_mps must be in (0, 10], got 11.0"
    p = write(tmp_path / "cfg.toml", "[laser]\nbeams = 100001\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{p}: laser.beams must be in [2, {MAX_BEAMS}], got 100001"


# ---------------------------------------------------------------- thresholds files


@pytest.mark.parametrize(
    ("text", "names"),
    [
        (f"[thresholds]\nmin_ticks = {BIG}\n", ("[thresholds] min_ticks", "count of", "integer of")),
        (f"[thresholds]\nreactor_p99_ms = -{BIG}\n", ("reactor_p99_ms must be a non-negative number",)),
        (f"[thresholds]\nreactor_p99_ms = {LONG}\n", ("reactor_p99_ms must be at most 3.6e+06 ms",)),
        ("[thresholds]\nreactor_p99_ms = 1e300\n", ("reactor_p99_ms must be at most", "1e+300")),
        ("[thresholds]\nmatch_rot_err_max_deg = 720\n", ("match_rot_err_max_deg must be at most 180 deg",)),
        ("[thresholds]\nmin_success = 2\n", ("min_success must be 0 or 1",)),
        ('[inputs."x"]\ngoal = [nan, 0.0]\n', ("[inputs.'x'] goal[0]", "finite")),
        ('[inputs."x"]\ngoal = [0.0, inf]\n', ("[inputs.'x'] goal[1]", "finite")),
        (f'[inputs."x"]\ngoal = [0.0, {BIG}]\n', ("[inputs.'x'] goal[1]", "an integer of")),
        ('[inputs."x"]\ngoal = [1e300, 0.0]\n', ("[inputs.'x'] goal[0]", "1e+300")),
        (f"[thresholds]\nreactor_p99_ms = '{'x' * 100_000}'\n", ("reactor_p99_ms must be a non-negative",)),
        (f"[thresholds]\n{'k' * 100_000} = 1\n", ("unknown key",)),
        ("[thresholds]\nmin_ticks = " + "[" * DEEP + "]" * DEEP + "\n", ("nested more than",)),
        ("x = " + "{ a = " * DEEP + "1" + " }" * DEEP + "\n", ("nested more than",)),
        (b"[thresholds]\nmin_ticks = 1 # \xff\n", ("line 2", "not UTF-8")),
    ],
)
def test_hostile_thresholds_are_one_line(tmp_path: Path, text: str | bytes, names: tuple[str, ...]) -> None:
    p = write(tmp_path / "limits.toml", text)
    with pytest.raises(ConfigError) as e:
        load_thresholds(p)
    one_line(e.value, p, *names)


def test_every_threshold_key_has_a_physical_bound() -> None:
    for key in THRESHOLD_KEYS:
        hi, _ = limit_bound(key)
        assert 0.0 < hi < math.inf, key


def test_defaults_and_usual_limits_are_within_their_bounds(tmp_path: Path) -> None:
    p = write(tmp_path / "limits.toml", (
        "[thresholds]\nreactor_p99_ms = 50.0\nmin_ticks = 100\nemergency_stops = 0\nmin_success_rate = 0.8\n"
        "match_rot_err_max_deg = 5\nmin_clearance_m = 0.05\ntime_to_goal_s = 600\nlocal_ticks_pct = 40\n"
        '[inputs."x"]\ngoal = [-999999.0, 12]\n'))
    th = load_thresholds(p)
    assert th.limits["min_ticks"] == 100 and isinstance(th.limits["min_ticks"], int)
    assert th.inputs[0].goal_xy == (-999999.0, 12.0)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_thresholds_fifo_is_refused_without_opening_it(tmp_path: Path) -> None:
    fifo = tmp_path / "limits.toml"
    os.mkfifo(fifo)
    err = refused_without_blocking(lambda: load_thresholds(fifo), fifo)
    assert isinstance(err, ConfigError)
    one_line(err, fifo, "is a FIFO", "thresholds file")


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_dev_zero_as_thresholds_is_refused_without_reading_it() -> None:
    with memory_cap(256 << 20), pytest.raises(ConfigError) as e:
        load_thresholds("/dev/zero")
    one_line(e.value, Path("/dev/zero"), "character device")


def test_a_relations_rule_names_a_fifo_and_a_name_too_long(tmp_path: Path) -> None:
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "r.fifo")
        p = write(tmp_path / "limits.toml", '[inputs."x"]\nrelations = "r.fifo"\n')
        with pytest.raises(ConfigError) as e:
            load_thresholds(p)
        one_line(e.value, p, "[inputs.'x']", "is a FIFO")
    p = write(tmp_path / "limits.toml", f'[inputs."x"]\nrelations = "{"r" * 5000}"\n')
    with pytest.raises(ConfigError) as e:
        load_thresholds(p)
    assert str(e.value).startswith(f"{p}: [inputs.'x'] ") and "\n" not in str(e.value)


# ---------------------------------------------------------------- relations and TUM files


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
@pytest.mark.parametrize("reader", [load_relations, read_tum])
def test_relations_and_trajectories_refuse_a_fifo(tmp_path: Path, reader: Callable[[Path], Any]) -> None:
    fifo = tmp_path / "in.fifo"
    os.mkfifo(fifo)
    err = refused_without_blocking(lambda: reader(fifo), fifo)
    assert isinstance(err, GndReplayError)
    one_line(err, fifo, "is a FIFO")


@pytest.mark.parametrize("reader", [load_relations, read_tum])
def test_relations_and_trajectories_that_are_not_utf8_name_the_line(
    tmp_path: Path, reader: Callable[[Path], Any]
) -> None:
    p = write(tmp_path / "in.txt", b"# head\n1.0 2.0 0 0 0 0 0 1 \xff\n")
    with pytest.raises(GndReplayError) as e:
        reader(p)
    one_line(e.value, p, "line 2", "not UTF-8")


@pytest.mark.parametrize(
    ("reader", "name"), [(load_relations, "MAX_RELATIONS_BYTES"), (read_tum, "MAX_TUM_BYTES")]
)
def test_relations_and_trajectories_are_bounded(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, reader: Callable[[Path], Any], name: str
) -> None:
    monkeypatch.setattr(f"gndreplay.evaluation.{name}", 100)
    p = write(tmp_path / "in.txt", "1.0 2.0 0 0 0 0 0 1\n" * 10)
    with pytest.raises(GndReplayError) as e:
        reader(p)
    one_line(e.value, p, "more than the 100 bytes")


@pytest.mark.parametrize(
    ("line", "why"),
    [
        (f"{LONG} 2.0 0 0 0 0 0 1", "out of range"),  # a stamp beyond int64 ns
        (f"1.0 2.0 {'x' * 100_000} 0 0 0 0 1", "could not convert"),  # float() quotes the whole token
    ],
)
def test_a_bad_relations_line_is_one_short_line(tmp_path: Path, line: str, why: str) -> None:
    p = write(tmp_path / "r.relations", line + "\n")
    with pytest.raises(GndReplayError) as e:
        load_relations(p)
    one_line(e.value, p, "line 1", why)
    p = write(tmp_path / "t.tum", line + "\n")
    with pytest.raises(GndReplayError) as e:
        read_tum(p)
    one_line(e.value, p, "line 1", why)


# ---------------------------------------------------------------- a run folder given to `report`


def run_folder(tmp_path: Path) -> Path:
    """The smallest run folder ``load_run`` reads: headers only, an empty summary and small maps."""
    d = tmp_path / "run"
    d.mkdir()
    (d / "commands.csv").write_text(",".join(COMMAND_COLUMNS) + "\n")
    (d / "timing.csv").write_text("t,match_ms,model_ms,planner_ms,reactor_ms,total_ms\n")
    for name in ("trajectory_odom.tum", "trajectory_corrected.tum"):
        (d / name).write_text("# timestamp tx ty tz qx qy qz qw\n1.0 0.5 0.0 0.0 0.0 0.0 0.0 1.0\n")
    (d / "summary.json").write_text("{}")
    raster = HitRaster(0.05)
    raster.add(np.array([[1.0, 2.0], [1.5, 2.5]]))
    save_maps(d / "maps.npz", raster, raster, None, scans=1)
    return d


def test_the_smallest_run_folder_reads(tmp_path: Path) -> None:
    data = load_run(run_folder(tmp_path))
    assert data.maps is not None and data.maps.scans == 1 and data.maps.corrected_hits.sum() == 2
    assert data.traj_odom.shape == (1, 4) and data.summary == {}


def test_a_deeply_nested_summary_is_one_run_dir_error(tmp_path: Path) -> None:
    d = run_folder(tmp_path)
    (d / "summary.json").write_text('{"a": ' + "[" * 200_000 + "]" * 200_000 + "}")
    with pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / "summary.json", "nested more than")


@pytest.mark.parametrize("name", ["commands.csv", "timing.csv", "trajectory_odom.tum", "summary.json"])
def test_a_run_file_that_is_not_utf8_is_one_run_dir_error(tmp_path: Path, name: str) -> None:
    d = run_folder(tmp_path)
    (d / name).write_bytes((d / name).read_bytes() + b"\xff\xfe\n")
    with pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / name, "not UTF-8")


def npz(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name + ".npy", data)
    return path


def npy(a: Any) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(a), allow_pickle=False)
    return buf.getvalue()


def npy_header(shape: tuple[int, ...], descr: str, data: bytes = b"") -> bytes:
    """A .npy member declaring ``shape`` and ``descr`` followed by ``data`` (too short on purpose)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": shape})
    return buf.getvalue() + data


def maps_members(d: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(d / "maps.npz") as zf:
        return {i.filename.removesuffix(".npy"): zf.read(i) for i in zf.infolist()}


@pytest.mark.parametrize(
    ("member", "data", "why"),
    [
        ("format_version", npy(np.array([1, 1])), "shape (2,)"),
        ("cell_m", npy(np.array(["0.05"])), "cell_m"),
        ("cell_m", npy(np.float64("nan")), "finite and > 0"),
        ("corrected_origin_xy", npy(np.array([np.inf, 0.0])), "finite"),
        ("raw_hits", npy(np.zeros((2, 2, 2), dtype=np.uint16)), "shape (2, 2, 2)"),
        ("raw_hits", b"not an array at all", "raw_hits"),
        ("raw_hits", npy(np.zeros((3, 3), dtype=np.uint16))[:-5], "raw_hits"),  # data cut short
        ("corrected_hits", npy_header((60_000, 60_000), "<u2", b"\0" * 64), "corrected_hits"),
        ("corrected_hits", npy_header((-60_000, -60_000), "<u2"), "corrected_hits"),
        ("corrected_hits", npy_header((2, 2), "|O"), "corrected_hits"),
    ],
)
def test_a_damaged_maps_member_is_one_run_dir_error(
    tmp_path: Path, member: str, data: bytes, why: str
) -> None:
    d = run_folder(tmp_path)
    npz(d / "maps.npz", maps_members(d) | {member: data})
    with memory_cap(), pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / "maps.npz", repr(member) if why == member else why)


def test_a_maps_archive_missing_a_member_or_damaged_is_one_run_dir_error(tmp_path: Path) -> None:
    d = run_folder(tmp_path)
    members = maps_members(d)
    npz(d / "maps.npz", {k: v for k, v in members.items() if k != "cell_m"})
    with pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / "maps.npz", "'cell_m' missing")
    data = bytearray((d / "maps.npz").read_bytes())
    data[100:140] = b"\xa5" * 40  # inside the first member's compressed data
    (d / "maps.npz").write_bytes(bytes(data))
    with pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / "maps.npz")
    (d / "maps.npz").write_bytes(b"PK\x03\x04" + b"\0" * 100)
    with pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / "maps.npz", "not a maps archive")


def test_maps_declaring_a_huge_grid_snapshot_are_refused_before_loading(tmp_path: Path) -> None:
    d = run_folder(tmp_path)
    snap = {k: npy(v) for k, v in {
        "grid_origin_xy": np.zeros(2), "grid_cell_m": np.float64(0.05), "grid_t_s": np.float64(0.0),
        "grid_elapsed_s": np.float64(0.0), "grid_tick": np.int64(0), "grid_pose": np.zeros(3),
        "grid_goal_xy": np.zeros(2), "grid_path_xy": np.zeros((0, 2)), "grid_mode": np.str_("gnd"),
        "grid_situation": np.str_("HSGR"), "grid_flags": np.str_(""),
    }.items()}
    npz(d / "maps.npz", maps_members(d) | snap | {"grid_cells": npy_header((40_000, 40_000), "|u1")})
    with memory_cap(), pytest.raises(RunDirError) as e:
        load_run(d)
    one_line(e.value, d / "maps.npz", "'grid_cells'", "MB")


# ---------------------------------------------------------------- ROS scans with too many beams


def scan_msg(m: Msgs, t: int, n: int) -> Any:
    """A LaserScan of ``n`` beams over one turn (bearings stay in range whatever n)."""
    return m["sensor_msgs/msg/LaserScan"](
        header=m.hdr(t, "laser"), angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / n,
        time_increment=0.0, scan_time=0.1, range_min=0.1, range_max=30.0,
        ranges=np.full(n, 5.0, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))


def write_bag(tmp: Path, kind: str, big_at: int, *, n: int = 6, little_endian: bool = True) -> Path:
    """A bag of ``n`` scans of 360 beams with odometry, scan ``big_at`` having MAX_BEAMS + 1 beams."""
    ros1 = kind == "ros1"
    ts = typestore(ros1)
    m = Msgs(ts, ros1)

    def ser(msg: Any, msgtype: str) -> bytes:
        if ros1:
            return bytes(ts.serialize_ros1(msg, msgtype))
        return bytes(ts.serialize_cdr(msg, msgtype, little_endian=little_endian))

    path = tmp / ("big.bag" if ros1 else "big")
    writer: Any = Writer1(path) if ros1 else Writer2(
        path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3)
    scan_t, odom_t = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
    with writer as w:
        cs = w.add_connection("/scan", scan_t, typestore=ts)
        co = w.add_connection("/odom", odom_t, typestore=ts)
        for k in range(n + 1):
            t = T0 - DT // 2 + k * DT
            w.write(co, t, ser(m.odom(t, *robot(t)), odom_t))
        for i in range(n):
            t = T0 + i * DT
            msg = scan_msg(m, t, MAX_BEAMS + 1) if i == big_at else m.scan(t, ranges_for(i))
            w.write(cs, t + 1_000_000, ser(msg, scan_t))
    return path


@pytest.mark.parametrize(
    ("kind", "big_at", "little_endian"),
    [("ros1", 2, True), ("sqlite3", 2, True), ("mcap", 0, True), ("mcap", 3, False)],
)
def test_a_scan_with_too_many_beams_is_a_malformed_message(
    tmp_path: Path, kind: str, big_at: int, little_endian: bool
) -> None:
    """Skipped and counted (an error with --strict), also as the first scan (whose frame still gives the
    laser mounting) and in big-endian CDR (read through rosbags)."""
    bag = write_bag(tmp_path, kind, big_at, little_endian=little_endian)
    with open_log(bag) as log:
        ticks = list(log.ticks())
        report = log.report
    assert len(ticks) == 5 and all(t.scan.ranges_m.size == 360 for t in ticks)
    assert report.malformed == 1
    assert f"on /scan: cannot decode sensor_msgs/msg/LaserScan: ValueError: {MAX_BEAMS + 1} beams, more " \
           f"than the {MAX_BEAMS}" in report.malformed_examples[0]
    with pytest.raises(LogFormatError, match=rf"message \d+ on /scan: .*{MAX_BEAMS + 1} beams"):
        list(read_ticks(bag, options=ReadOptions(strict=True)))


def test_a_bag_whose_every_scan_has_too_many_beams_says_why_it_has_no_scans(tmp_path: Path) -> None:
    bag = write_bag(tmp_path, "mcap", 0, n=1)
    with pytest.raises(LogFormatError) as e:
        list(read_ticks(bag))
    one_line(e.value, bag, "no scans on /scan (1 malformed messages skipped", f"{MAX_BEAMS + 1} beams")


def test_info_counts_a_scan_with_too_many_beams(tmp_path: Path) -> None:
    from gndreplay.info import log_info

    info = log_info(write_bag(tmp_path, "sqlite3", 1))
    assert info.malformed == 1 and f"{MAX_BEAMS + 1} beams" in info.malformed_examples[0]
