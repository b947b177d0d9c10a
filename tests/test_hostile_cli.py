"""Bad command lines: every refused option value, unknown option or misspelt choice is one line
``gndreplay: error: ...`` on stderr and exit 2 (never typer's boxed panel, never a traceback); numbers are
bounded by their physical range, and a misspelt matcher / preset / planner / mode gets a "did you mean"."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from gndreplay import cli
from gndreplay.cli import app

runner = CliRunner()


def refused(args: list[str], *needles: str) -> str:
    res = runner.invoke(app, args)
    assert res.exit_code == 2, (res.exit_code, res.output, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    line = lines[0]
    assert line.startswith("gndreplay: error: ") and all(n in line for n in needles), line
    assert "Traceback" not in res.output and "╭" not in res.output and len(line) < 450, res.output
    return line


LOG = "nope.clf"  # options are checked before the log is opened


@pytest.mark.parametrize(("args", "needles"), [
    (["run", LOG, "--until", "nan"], ("--until: must be finite, got nan",)),
    (["run", LOG, "--until", "1e300"], ("--until: must be from 0 to 4.5e+09, got 1e+300",)),
    (["run", LOG, "--goal-ahead", "inf"], ("--goal-ahead: must be finite",)),
    (["run", LOG, "--every", "0"], ("--every: must be from 1 to 1e+06, got 0",)),
    (["run", LOG, "--every", "abc"], ("Invalid value for '--every'",)),
    (["run", LOG, "--goal", "nan,0"], ("--goal: X: must be finite, got nan",)),
    (["run", LOG, "--goal", "0,1e300"], ("--goal: Y: must be from -1e+06 to 1e+06, got 1e+300",)),
    (["run", LOG, "--goal", "3 4"], ("--goal: expected X,Y in metres (e.g. 3.5,-1.0), got '3 4'",)),
    (["run", LOG, "--goal", "1,2", "--goal-ahead", "3"], ("--goal and --goal-ahead exclude each other",)),
    (["run", LOG, "--matcher", "icp"],
     ("--matcher: expected one of odom, idc, kiss-icp, got 'icp' (did you mean 'kiss-icp'?)",)),
    (["run", LOG, "--matcher", "x" * 100_000], ("--matcher: expected one of odom, idc, kiss-icp, got 'xxx",)),
    (["run", LOG, "--set", "reactor.securty_m=0.4"],
     ("--set 'reactor.securty_m=0.4': unknown key 'reactor.securty_m' (did you mean 'security_m'?)",)),
    (["run", LOG, "--set", "robot.vmax_mps=-1"],
     ("--set 'robot.vmax_mps=-1': robot.vmax_mps must be in (0, 10]",)),
    (["run", LOG, "--set", "robot.vmax_mps"], ("--set: expected section.key=value",)),
    (["run", LOG, "--set", "navigation.selector=maybe"], ("navigation.selector: expected true or false",)),
    (["simulate", "u_trap", "--set", "reactor.x=1"], ("--set 'reactor.x=1': unknown key 'reactor.x'",)),
    (["batch", LOG, "--set", "grid.cell_m=nan"], ("--set 'grid.cell_m=nan'",)),
    (["run", LOG, "--preset", "wheelchar"],
     ("--preset: expected one of compact, wheelchair, xr4000, got 'wheelchar' "
      "(did you mean 'wheelchair'?)",)),
    (["run", LOG, "--planner", "tunel"], ("--planner: expected one of nf1, tunnel, got 'tunel' "
                                          "(did you mean 'tunnel'?)",)),
    (["run", LOG, "--mode", "gdn"], ("--mode: expected one of gnd, teleop, follow, local, got 'gdn' "
                                     "(did you mean 'gnd'?)",)),
    (["run", LOG, "--goal-ahed", "3"],
     ("No such option: --goal-ahed", "--goal-ahead", "gndreplay run --help")),
    (["scanmatch", LOG, "--matcher", "icp"], ("--matcher: expected one of", "(did you mean 'kiss-icp'?)")),
    (["scanmatch", LOG, "--set", "scanmatch.idc.nope=1"], ("unknown key 'scanmatch.idc.nope'",)),
    (["batch", LOG, "--timeout", "0"], ("--timeout: must be from 0.001 to 4.5e+09, got 0",)),
    (["batch", LOG, "--jobs", "0"], ("--jobs: must be from 1 to 4096, got 0",)),
    (["batch", LOG, "--until", "-1"], ("--until: must be from 0 to",)),
    (["batch", "--scenarios", "u_trap", "--time-limit", "nan"], ("--time-limit: must be finite",)),
    (["simulate", "u_trap", "--seed", "-1"], ("--seed: must be an integer from 0 to 2**63 - 1, got -1",)),
    (["simulate", "u_trap", "--seed", str(2**64)], ("--seed: must be an integer from 0 to 2**63 - 1",)),
    (["simulate", "u_trap", "--time-limit", "inf"], ("--time-limit: must be finite, got inf",)),
    (["simulate", "u_trap", "--time-limit", "1e300"], ("--time-limit: must be from 0.1 to 1e+06",)),
    (["simulate", "u_trap", "--time-limit", "0"], ("--time-limit: must be from 0.1 to 1e+06, got 0",)),
    (["simulate", "u_trap", "--preset", "xr400"], ("(did you mean 'xr4000'?)",)),
    (["simulate", "u_trap", "--planner", "nf"], ("--planner: expected one of nf1, tunnel",)),
    (["simulate", "u_trp"], ("u_trp: no such scenario file or shipped scenario", "(did you mean 'u_trap'?)")),
    (["simulate", "u_trap", "--mode", "folow"], ("(did you mean 'follow'?)",)),
    (["bogus"], ("No such command 'bogus'",)),
    (["simulate", "u_trap", "--seed", "x"], ("Invalid value for '--seed'",)),  # typer's own parameter error
    (["batch", LOG, "--jobs", "two"], ("Invalid value for '--jobs'",)),
    (["info"], ("Missing argument 'log'",)),
    (["run", LOG, "--until"], ("Option '--until' requires an argument",)),
    (["run", LOG, "--json=1"], ("Option '--json' does not take a value",)),
])
def test_a_bad_option_value_is_one_line(tmp_path: Path, monkeypatch: Any, args: list[str],
                                        needles: tuple[str, ...]) -> None:
    monkeypatch.chdir(tmp_path)
    refused(args, *needles)
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_a_log_named_like_an_option_suggests_dot_slash(tmp_path: Path, monkeypatch: Any) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "-dash.clf").write_text("")
    refused(["run", "-dash.clf"], "-dash.clf: a name starting with '-' reads as an option; write ./-dash.clf")
    refused(["info", "-dash.clf", "--json"], "write ./-dash.clf")
    refused(["run", "-q", "-x"], "No such option: -x")  # an option, not a file: no suggestion


def test_the_console_script_reports_one_line_too() -> None:
    main = [sys.executable, "-c", "from gndreplay.cli import main; main()"]
    res = subprocess.run([*main, "run", "--until", "nan"], capture_output=True, text=True, timeout=120,
                         check=False)
    assert res.returncode == 2 and res.stderr == "gndreplay: error: --until: must be finite, got nan\n"


def test_help_and_the_bounds_themselves_still_work(tmp_path: Path) -> None:
    res = runner.invoke(app, ["simulate", "--help"])
    assert res.exit_code == 0 and "--time-limit" in res.output
    assert runner.invoke(app, []).exit_code in (0, 2)  # bare command: the help, as before
    args = ["simulate", "u_trap", "--seed", str(2**63 - 1), "--time-limit", "0.1", "--no-figures", "--json",
            "--out", str(tmp_path / "run")]
    res = runner.invoke(app, args)
    assert res.exit_code in (0, 1), res.output
    assert json.loads(res.stdout)["seed"] == 2**63 - 1


def test_the_option_bounds_are_the_library_bounds() -> None:
    from gndreplay.io.base import MAX_ABS_TIME_NS
    from gndreplay.io.subgoals import MAX_ABS_SUBGOAL_M
    from gndreplay.sim.scenario_file import MAX_TIME_S, MIN_TIME_LIMIT_S

    assert cli._MAX_POSITION_M == MAX_ABS_SUBGOAL_M
    assert cli._MAX_SECONDS == MAX_ABS_TIME_NS / 1e9
    assert cli._MAX_SCENARIO_TIME_S == MAX_TIME_S and MIN_TIME_LIMIT_S == 0.1  # --time-limit: 0.1 to 1e6


def test_a_misspelt_toml_key_or_section_gets_a_suggestion(tmp_path: Path, monkeypatch: Any) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "key.toml").write_text("[reactor]\nsecurty_m = 0.4\n")
    (tmp_path / "section.toml").write_text("[reactr]\nsecurity_m = 0.4\n")
    refused(["run", LOG, "--config", "key.toml"],
            "key.toml: unknown key 'reactor.securty_m' (did you mean 'security_m'?)")
    refused(["scanmatch", LOG, "--config", "section.toml"], "unknown key 'reactr' (did you mean 'reactor'?)")


def test_a_misspelt_log_format_gets_a_suggestion(tmp_path: Path) -> None:
    log = tmp_path / "run.clf"
    log.write_text("")
    refused(["info", str(log), "--format", "carmn"], "unknown format 'carmn'", "(did you mean 'carmen'?)")
    refused(["run", str(log), "--format", "ros-2"], "unknown format 'ros-2'", "(did you mean 'ros2'?)")
