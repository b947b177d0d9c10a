"""The format registry: detection from the path, ``--format`` overrides, and their errors."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gndreplay.errors import LogFormatError
from gndreplay.io import LOG_SUFFIXES, READERS, ReadOptions, detect_format, open_log, special_file_kind

LINE = "FLASER 3 1 2 3 0 0 0 0 0 0 1.0 h 0\n"


@pytest.mark.parametrize(
    ("name", "fmt"),
    [
        ("a.clf", "carmen"),
        ("a.log", "carmen"),
        ("a.CLF", "carmen"),
        ("a.clf.gz", "carmen"),
        ("a.log.bz2", "carmen"),
        ("a.bag", "rosbag1"),
        ("a.mcap", "mcap"),
    ],
)
def test_format_from_the_suffix(tmp_path: Path, name: str, fmt: str) -> None:
    p = tmp_path / name
    p.write_bytes(b"")
    assert detect_format(p) == (fmt, p)


def test_registry_covers_every_suffix() -> None:
    assert set(LOG_SUFFIXES.values()) <= set(READERS)
    assert list(READERS) == ["carmen", "rosbag1", "rosbag2", "mcap"]


def test_ros2_folder(tmp_path: Path) -> None:
    (tmp_path / "metadata.yaml").write_text("")
    assert detect_format(tmp_path) == ("rosbag2", tmp_path)
    assert detect_format(tmp_path, "rosbag") == ("rosbag2", tmp_path)
    assert detect_format(tmp_path, "ros2") == ("rosbag2", tmp_path)


def test_format_override_reads_an_odd_suffix(tmp_path: Path) -> None:
    p = tmp_path / "run.txt"
    p.write_text(LINE)
    with pytest.raises(
        LogFormatError,
        match=r"run\.txt: unknown log format \(suffix '\.txt'\); known formats: "
        r"carmen .*use --format",
    ):
        detect_format(p)
    with open_log(p, options=ReadOptions(fmt="carmen")) as log:
        assert len(list(log.ticks())) == 1
    with open_log(p, options=ReadOptions(fmt="CLF")) as log:
        assert log.format_name == "carmen"


@pytest.mark.parametrize(
    ("name", "fmt", "message"),
    [
        ("x.tar.bz2", None, r"x\.tar\.bz2: unknown log format \(compressed \.tar\)"),
        ("x.gz", None, r"x\.gz: unknown log format \(compressed file\)"),
        ("x.clf", "bogus", r"x\.clf: unknown format 'bogus'; known formats: carmen, rosbag1, rosbag2, mcap"),
        ("x.clf", "rosbag", r"x\.clf: not a ROS bag"),
    ],
)
def test_unknown_formats_list_the_known_ones(
    tmp_path: Path, name: str, fmt: str | None, message: str
) -> None:
    p = tmp_path / name
    p.write_text(LINE)
    with pytest.raises(LogFormatError, match=message):
        detect_format(p, fmt)


def test_folder_without_metadata(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match=r"a folder without metadata\.yaml is not a ROS2 bag"):
        detect_format(tmp_path)


def test_missing_path(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match=r"gone\.bag: no such file or directory"):
        open_log(tmp_path / "gone.bag")


def test_a_bag_read_as_carmen_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "b.bag"
    p.write_bytes(b"#ROSBAG V2.0\n\x00\x01\x02" * 20)
    with pytest.raises(LogFormatError, match=r"b\.bag: not a CARMEN log"):
        open_log(p, options=ReadOptions(fmt="carmen"))


# ---- FIFOs, devices and sockets are refused before anything opens them (review F1 bug 11) ----------------


def test_a_fifo_is_refused_by_name_without_being_opened(tmp_path: Path) -> None:
    fifo = tmp_path / "ff.clf"
    os.mkfifo(fifo)
    with pytest.raises(LogFormatError, match=r"ff\.clf: is a FIFO, not a log file"):
        detect_format(fifo)
    with pytest.raises(LogFormatError, match=r"ff\.clf: is a FIFO"):
        open_log(fifo)
    bag = tmp_path / "bag"  # a ROS2 bag folder whose storage file is a FIFO
    bag.mkdir()
    (bag / "metadata.yaml").write_text("")
    os.mkfifo(bag / "bag_0.db3")
    with pytest.raises(LogFormatError, match=r"bag_0\.db3: is a FIFO"):
        open_log(bag)
    assert special_file_kind(fifo) == "a FIFO" and special_file_kind(bag) is None
    assert special_file_kind(Path("/dev/null")) == "a character device"


@pytest.mark.parametrize("command", ["run", "info", "scanmatch"])
def test_a_fifo_on_the_command_line_is_one_error_line_not_a_hang(tmp_path: Path, command: str) -> None:
    fifo = tmp_path / "ff.clf"
    os.mkfifo(fifo)
    code = "from gndreplay.cli import main; main()"
    args = [sys.executable, "-c", code, command, str(fifo)]
    if command == "run":
        args += ["--out", str(tmp_path / "out"), "-q"]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "MPLBACKEND": "Agg"}, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    expected = f"gndreplay: error: {fifo}: is a FIFO, not a log file (never opened)"
    assert proc.stderr.strip().splitlines() == [expected]
    assert not (tmp_path / "out").exists()
