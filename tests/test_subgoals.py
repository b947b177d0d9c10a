"""Subgoal files and rows: parsing and one-line errors naming the file and line."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from gndreplay.errors import ConfigError
from gndreplay.io.subgoals import MAX_SUBGOAL_FILE_BYTES, load_subgoals, subgoals_from_rows
from gndreplay.types import Subgoal


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "route.txt"
    p.write_text(text)
    return p


def test_good_file(tmp_path: Path) -> None:
    p = write(tmp_path, "# x y theta kind\n\n1 2 0.5\n  3.5 -4 -1.57 stop  # rest here\n"
                        "5e0 6 3.14159 reverse\n7 8 0 forward\n")
    assert load_subgoals(p) == (
        Subgoal(1.0, 2.0, 0.5, "forward"),
        Subgoal(3.5, -4.0, -1.57, "stop"),
        Subgoal(5.0, 6.0, 3.14159, "reverse"),
        Subgoal(7.0, 8.0, 0.0, "forward"),
    )


@pytest.mark.parametrize(("line", "what"), [
    ("1 2", "3 or 4 fields"),
    ("1 2 3 stop extra", "3 or 4 fields"),
    ("1 two 3", "y must be a number"),
    ("1 2 nan", "theta must be finite"),
    ("inf 2 0", "x must be finite"),
    ("2e6 0 0", "|x| must be <= 1e+06"),
    ("0 -1000001 0", "|y| must be <= 1e+06"),
    ("1 2 0 backwards", "kind must be one of stop, forward, reverse"),
    ("1 2 1e300", "|theta| must be <= 1000 rad"),
    ("1 2 -1001", "|theta| must be <= 1000 rad"),
])
def test_bad_line_names_file_and_line(tmp_path: Path, line: str, what: str) -> None:
    p = write(tmp_path, f"# route\n0 0 0\n\n{line}\n5 5 0\n")
    with pytest.raises(ConfigError) as e:
        load_subgoals(p)
    msg = str(e.value)
    assert msg.startswith(f"{p} line 4: ")
    assert what in msg
    assert "\n" not in msg


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n   # and another\n"])
def test_empty_file(tmp_path: Path, text: str) -> None:
    p = write(tmp_path, text)
    with pytest.raises(ConfigError, match="no subgoal in the file") as e:
        load_subgoals(p)
    assert str(e.value).startswith(str(p))


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="subgoal file not found"):
        load_subgoals(tmp_path / "missing.txt")
    with pytest.raises(ConfigError, match="is a folder, not a subgoal file"):
        load_subgoals(tmp_path)
    binary = tmp_path / "bin.txt"
    binary.write_bytes(b"\xff\xfe\x00 1 2 3\n")
    with pytest.raises(ConfigError, match=r"bin\.txt: line 1: not UTF-8 text \(byte 0: 0xff\)"):
        load_subgoals(binary)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_fifo_is_refused_without_opening_it(tmp_path: Path) -> None:
    """Reading a FIFO with no writer would block for ever: refused from its kind, never opened."""
    fifo = tmp_path / "goals.fifo"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError) as e:
        load_subgoals(fifo)
    assert str(e.value) == f"{fifo}: is a FIFO, not a subgoal file (never opened)"


def test_a_file_above_the_size_cap_is_refused_before_reading(tmp_path: Path) -> None:
    big = tmp_path / "big.txt"
    big.write_text("0 0 0\n" * (MAX_SUBGOAL_FILE_BYTES // 6 + 1))
    with pytest.raises(ConfigError, match=r"big\.txt: \d+ bytes, more than the 1 MB a subgoal file may have"):
        load_subgoals(big)
    ok = tmp_path / "ok.txt"
    ok.write_text("0 0 0\n" * (MAX_SUBGOAL_FILE_BYTES // 6 - 1))  # just under the cap: read
    assert len(load_subgoals(ok)) == MAX_SUBGOAL_FILE_BYTES // 6 - 1


def test_rows_share_the_validation() -> None:
    assert subgoals_from_rows([[1, 2, 0], [3, 4, math.pi, "stop"]], "s.yaml: subgoals") == (
        Subgoal(1.0, 2.0, 0.0), Subgoal(3.0, 4.0, math.pi, "stop"))
    for rows, msg in [
        ([], r"s.yaml: subgoals: expected a non-empty list"),
        ({"x": 1}, r"s.yaml: subgoals: expected a non-empty list"),
        ([[1, 2, 0], 5], r"s.yaml: subgoals\[1\]: expected a list"),
        ([[1, 2, True]], r"s.yaml: subgoals\[0\]: theta must be a number"),
        ([[1, 2, 0, "sideways"]], r"s.yaml: subgoals\[0\]: kind must be one of"),
        ([[1, 2, 0], [1, float("nan"), 0]], r"s.yaml: subgoals\[1\]: y must be finite"),
        ([[1, 2, 1e300]], r"s.yaml: subgoals\[0\]: \|theta\| must be <= 1000 rad"),
        ([[1, 2]], r"s.yaml: subgoals\[0\]: expected 'x y theta \[kind\]'"),
    ]:
        with pytest.raises(ConfigError, match=msg):
            subgoals_from_rows(rows, "s.yaml: subgoals")
