"""Teleoperation input from logs: CARMEN ODOM tv/rv become ``Tick.cmd`` (only when one is non-zero)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gndreplay.errors import LogFormatError
from gndreplay.io import ReadOptions, open_log
from gndreplay.io.carmen import CarmenReader, odom_has_commands

RANGES = "1.0 2.0 3.0 2.0 1.0"


def flaser(t: float, x: float) -> str:
    return f"FLASER 5 {RANGES} {x} 0 0 {x} 0 0 {t:.3f} host 0.0\n"


def odom(t: float, x: float, tv: float, rv: float) -> str:
    return f"ODOM {x} 0 0 {tv} {rv} 0 {t:.3f} host 0.0\n"


def write_log(path: Path, velocities: list[tuple[float, float]]) -> Path:
    """An ODOM line at 0.1 s * k with velocities[k], a FLASER 50 ms after each."""
    lines = []
    for k, (tv, rv) in enumerate(velocities):
        lines.append(odom(100 + 0.1 * k, 0.01 * k, tv, rv))
        lines.append(flaser(100 + 0.1 * k + 0.05, 0.01 * k + 0.005))
    path.write_text("".join(lines))
    return path


def test_odom_tv_rv_become_the_ticks_commands(tmp_path: Path) -> None:
    vel = [(0.1 * (k + 1), -0.05 * k) for k in range(6)]
    with open_log(write_log(tmp_path / "a.clf", vel)) as log:
        ticks = list(log.ticks())
        desc = log.describe()
    assert desc.cmd_stream == "ODOM"
    assert "commands: ODOM tv/rv (ODOM is both the odometry and the command stream)" in desc.notes
    assert len(ticks) == 6
    for k, tick in enumerate(ticks):  # the last ODOM at or before the scan (50 ms before it)
        assert tick.cmd is not None
        assert tick.cmd.t_ns == round((100 + 0.1 * k) * 1e9)
        assert (tick.cmd.v_mps, tick.cmd.w_radps) == pytest.approx(vel[k])


def test_all_zero_tv_rv_are_no_commands(tmp_path: Path) -> None:
    p = write_log(tmp_path / "z.clf", [(0.0, 0.0)] * 5)
    with open_log(p) as log:
        assert all(t.cmd is None for t in log.ticks())
        desc = log.describe()
    assert desc.cmd_stream is None
    assert "ODOM tv/rv are all zero: no recorded velocity commands" in desc.notes
    with pytest.raises(LogFormatError, match=r"z\.clf: no command stream 'ODOM': every ODOM tv and rv is 0"):
        CarmenReader(p, options=ReadOptions(cmd_topic="ODOM"))


def test_commands_start_at_the_first_non_zero_velocity(tmp_path: Path) -> None:
    """Zeros before the first non-zero tv/rv are no command; from it on every ODOM line is one (a zero then
    is a recorded stop)."""
    vel = [(0.0, 0.0)] * 3 + [(0.2, 0.0), (0.0, 0.0), (0.0, 0.1)]
    with open_log(write_log(tmp_path / "a.clf", vel)) as log:
        cmds = [t.cmd for t in log.ticks()]
    assert cmds[:3] == [None, None, None]
    assert [(c.v_mps, c.w_radps) for c in cmds[3:] if c is not None] == [(0.2, 0.0), (0.0, 0.0), (0.0, 0.1)]


def test_non_zero_velocities_after_the_head_are_found(tmp_path: Path) -> None:
    """The head (50 scans) is all zero: a scan of the ODOM lines, or a complete pass, finds the later tv;
    the ticks are the same whichever way it was found (the pass never looks ahead)."""
    vel = [(0.0, 0.0)] * 80 + [(0.2, 0.0)] * 3
    p = write_log(tmp_path / "late.clf", vel)
    assert odom_has_commands(p)
    with open_log(p) as log:
        desc = log.describe()  # describe never reads ahead: not known yet
        assert desc.cmd_stream is None
        assert "ODOM tv/rv: not known before the log is read" in desc.notes
        assert log.records_commands()  # asked before a pass: the scan of the ODOM lines
        assert log.describe().cmd_stream == "ODOM"
        first = [t.cmd for t in log.ticks()]
    with open_log(p) as log:
        second = [t.cmd for t in log.ticks()]
        assert log.describe().cmd_stream == "ODOM"  # known from the pass
    assert first == second
    assert first[79] is None
    assert [(c.v_mps, c.w_radps) for c in first[80:] if c is not None] == [(0.2, 0.0)] * 3


def test_cmd_topic_odom_is_accepted_and_other_names_are_refused(tmp_path: Path) -> None:
    p = write_log(tmp_path / "a.clf", [(0.3, 0.1)] * 3)
    with CarmenReader(p, options=ReadOptions(cmd_topic="ODOM")) as log:
        assert [t.cmd.v_mps for t in log.ticks() if t.cmd is not None] == [0.3] * 3
    with pytest.raises(LogFormatError, match=r"no command stream '/cmd_vel'.*tv/rv \(candidates: ODOM\)"):
        CarmenReader(p, options=ReadOptions(cmd_topic="/cmd_vel"))
    no_odom = tmp_path / "n.clf"
    no_odom.write_text(flaser(1.0, 0.0))
    with pytest.raises(LogFormatError, match=r"no command stream 'ODOM'.*\(candidates: none\)"):
        CarmenReader(no_odom, options=ReadOptions(cmd_topic="ODOM"))


def test_commands_with_the_odometry_embedded_in_flaser(tmp_path: Path) -> None:
    """odom_topic=FLASER takes the pose from the scan line; ODOM still gives the commands."""
    p = write_log(tmp_path / "a.clf", [(0.2, 0.1)] * 4)
    with open_log(p, options=ReadOptions(odom_topic="FLASER")) as log:
        ticks = list(log.ticks())
        assert log.describe().cmd_stream == "ODOM"
    assert all(t.cmd is not None and t.cmd.v_mps == pytest.approx(0.2) for t in ticks)
    assert ticks[1].odom.x == pytest.approx(0.015)  # the FLASER triple, not the ODOM pose


def test_the_sample_log_records_velocities() -> None:
    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
    with open_log(sample) as log:
        assert log.describe().cmd_stream == "ODOM"
        moving = [t.cmd for _, t in zip(range(200), log.ticks(), strict=False)
                  if t.cmd is not None and (t.cmd.v_mps or t.cmd.w_radps)]
    assert moving and all(math.isfinite(c.v_mps) for c in moving)


def test_odom_lines_starting_after_the_head_are_commands(tmp_path: Path) -> None:
    """Scans first, ODOM only after the head: no ODOM in the head settles nothing; the ODOM lines are read
    as commands (and found by ``records_commands`` before a pass)."""
    lines = [flaser(100 + 0.1 * k, 0.0) for k in range(200)]
    for k in range(200, 260):
        lines += [odom(100 + 0.1 * k, 0.01 * k, 0.3, 0.1), flaser(100 + 0.1 * k + 0.05, 0.01 * k)]
    p = tmp_path / "late_odom.clf"
    p.write_text("".join(lines))
    with open_log(p) as log:
        assert log.describe().cmd_stream is None  # not known before reading ahead
        assert log.records_commands()
        assert log.describe().cmd_stream == "ODOM"
        ticks = list(log.ticks())
    cmds = [t.cmd for t in ticks]
    assert cmds[:200] == [None] * 200
    assert all(c is not None and (c.v_mps, c.w_radps) == (0.3, 0.1) for c in cmds[200:])
    with open_log(p) as log:  # without asking first: the pass reads them all the same
        assert sum(t.cmd is not None for t in log.ticks()) == 60
        assert log.describe().cmd_stream == "ODOM"


def test_a_corrupt_log_is_not_said_to_have_no_commands(tmp_path: Path) -> None:
    """The scan of the ODOM lines meets corrupt compressed data before any non-zero tv/rv: the log's
    one-line error (naming the last line read), not "no recorded velocity commands"."""
    import gzip
    import random

    rng = random.Random(0)  # noisy ranges: the scans compress poorly, so the cut lands among them
    text = "".join(f"FLASER 5 {' '.join(f'{rng.uniform(1, 3):.4f}' for _ in range(5))} 0 0 0 0 0 0 "
                   f"{100 + 0.1 * k:.3f} host 0.0\n" for k in range(5000))
    text += "".join(odom(700 + 0.1 * k, 0.0, 0.3, 0.0) for k in range(10))
    data = gzip.compress(text.encode())
    p = tmp_path / "cut.clf.gz"
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(LogFormatError, match=r"cut\.clf\.gz: truncated or corrupt data after line \d+"):
        odom_has_commands(p)
    with open_log(p) as log, pytest.raises(LogFormatError, match="truncated or corrupt data after line"):
        log.records_commands()


def test_strict_does_not_stop_on_a_bad_odom_line_used_for_nothing(tmp_path: Path) -> None:
    """Odometry from the FLASER lines: a malformed ODOM line (read for its commands only) is counted and
    skipped, even in strict mode; a malformed scan line still stops a strict run."""
    lines = [odom(100 + 0.1 * k, 0.0, 0.2, 0.0) + flaser(100 + 0.1 * k + 0.05, 0.0) for k in range(5)]
    lines[2] = "ODOM 0 0 0 fast 0 0 100.200 host 0.0\n" + flaser(100.25, 0.0)
    p = tmp_path / "bad_odom.clf"
    p.write_text("".join(lines))
    with open_log(p, options=ReadOptions(odom_topic="FLASER", strict=True)) as log:
        ticks = list(log.ticks())
        assert log.report.malformed == 1
    assert len(ticks) == 5 and ticks[2].cmd is not None and ticks[2].cmd.t_ns == round(100.1 * 1e9)
    strict, message = ReadOptions(strict=True), r"bad_odom\.clf line 5: ODOM"
    with open_log(p, options=strict) as log, pytest.raises(LogFormatError, match=message):
        list(log.ticks())  # ODOM is the odometry here: strict stops on it


def test_describe_says_when_odom_is_both_odometry_and_commands(tmp_path: Path) -> None:
    with open_log(write_log(tmp_path / "a.clf", [(0.2, 0.0)] * 3)) as log:
        desc = log.describe()
    assert desc.cmd_stream == "ODOM" and desc.odom_source.startswith("ODOM")
    assert "commands: ODOM tv/rv (ODOM is both the odometry and the command stream)" in desc.notes
    embedded = ReadOptions(odom_topic="FLASER")
    with open_log(write_log(tmp_path / "b.clf", [(0.2, 0.0)] * 3), options=embedded) as log:
        assert "commands: ODOM tv/rv" in log.describe().notes  # the scan lines give the odometry


BASE = {"name": "t", "start": [0, 0, 0], "time_limit": 5, "world": {"walls": {"n": [-2, 3, 13, 3]}}}


@pytest.mark.parametrize(("extra", "what"), [
    ({"mode": "teleop", "goal": [1, 0], "teleop": {"commands": [[0, 1e300, -1e300], [1, 0, 0]]}},
     r"teleop\.commands\[0\]\[1\]: must be from -100 to 100, got 1e\+300"),
    ({"mode": "teleop", "goal": [1, 0], "teleop": {"commands": [[0, 0.1, 0], [1e300, 0, 0]]}},
     r"teleop\.commands\[1\]\[0\]: must be from 0 to 1e\+06, got 1e\+300"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1e300, 0]], "speed": 0.3}}},
     r"teleop\.track\.points\[1\]\[0\]: must be from -1e\+06 to 1e\+06"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1e-300, 0]], "speed": 0.3}}},
     r"teleop\.track\.points: two consecutive points are closer than 0\.001 m"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1, 0]], "speed": 1e300}}},
     r"teleop\.track\.speed: must be from 0 to 100"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1, 0]], "speed": 0.3, "lookahead": 1e300}}},
     r"teleop\.track\.lookahead: must be from 0 to 100"),
    ({"mode": "follow", "goal": [1e300, 0], "subgoals": [[1, 0, 0, "stop"]]},
     r"goal\[0\]: must be from -1e\+06 to 1e\+06"),
    ({"mode": "follow", "subgoals": [[1, 0, 1e300, "stop"]]},
     r"subgoals\[0\]\[2\]: must be from -1000 to 1000, got 1e\+300"),
    ({"start": [0, 0, 1e300], "goal": [1, 0]}, r"start\[2\]: must be from -1000 to 1000"),
])
def test_scenario_navigation_values_are_bounded(extra: dict[str, object], what: str) -> None:
    """1e300 in a scenario's teleop script, track, goal or subgoal is one line naming file and key (it
    used to give RuntimeWarnings and NaN commands)."""
    from gndreplay.errors import ConfigError
    from gndreplay.sim.scenario_file import parse_scenario

    with pytest.raises(ConfigError, match=r"^run\.yaml: " + what) as e:
        parse_scenario({**BASE, **extra}, "run.yaml")
    assert "\n" not in str(e.value)
    ok = {"mode": "teleop",
          "teleop": {"track": {"points": [[0, 0], [1, 0]], "speed": 100.0, "lookahead": 100}}}
    assert parse_scenario({**BASE, **ok}, "run.yaml").teleop is not None  # the bounds themselves are fine
