"""Records are a pure function of log + config (issue 12, item 4).

- Wall-clock budget flags never reach commands.csv (they go to timing.csv) unless ``enforce_budgets`` let
  them change a command: with budgets so small that every tick is over them, commands.csv is still
  byte-identical to a run with generous budgets.
- Two runs beside a CPU hog give byte-identical commands.csv and stages.csv.
- ``--until`` does not change earlier ticks (the goal lookahead reads past it).
- One timestamp string per tick in commands.csv, timing.csv, stages.csv and the TUM trajectories.
"""

from __future__ import annotations

import csv
import dataclasses
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from gndreplay.config import PRESETS, Config
from gndreplay.replay import RunOptions, run_log
from gndreplay.report import load_run

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
FORTY = RunOptions(until_s=40.0)
BUDGETS = ("budget_match_s", "budget_model_s", "budget_planner_s", "budget_reactor_s")


def with_budgets(cfg: Config, seconds: float, *, enforce: bool = False) -> Config:
    sup = dataclasses.replace(cfg.supervisor, enforce_budgets=enforce)
    for name in BUDGETS:
        sup = dataclasses.replace(sup, **{name: seconds})  # type: ignore[arg-type]
    return dataclasses.replace(cfg, supervisor=sup)


def rows(path: Path) -> list[list[str]]:
    with open(path, newline="") as f:
        return list(csv.reader(f))


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("det")
    cfg = PRESETS["wheelchair"]
    return {
        "generous": run_log(SAMPLE, with_budgets(cfg, 60.0), base / "g", options=FORTY).out_dir,
        "tiny": run_log(SAMPLE, with_budgets(cfg, 1e-9), base / "t", options=FORTY).out_dir,
        "enforced": run_log(SAMPLE, with_budgets(cfg, 1e-9, enforce=True), base / "e", options=FORTY).out_dir,
        "short": run_log(SAMPLE, cfg, base / "s", options=RunOptions(until_s=15.0)).out_dir,
        "long": run_log(SAMPLE, cfg, base / "l", options=RunOptions(until_s=40.0)).out_dir,
    }


def test_budget_flags_live_in_timing_csv_not_in_commands_csv(runs: dict[str, Path]) -> None:
    g, t = runs["generous"], runs["tiny"]
    for name in ("commands.csv", "stages.csv"):
        assert (g / name).read_bytes() == (t / name).read_bytes(), name
    assert "OVER_BUDGET" not in (t / "commands.csv").read_text()
    timing = rows(t / "timing.csv")
    assert timing[0][-1] == "flags"
    assert all("PLANNER_OVER_BUDGET" in r[-1].split("|") for r in timing[1:])  # every tick was over
    over = load_run(t).timing.over_budget
    assert over["PLANNER_OVER_BUDGET"].all() and over["REACTOR_OVER_BUDGET"].all()
    summary = load_run(t).summary
    assert "PLANNER_OVER_BUDGET" not in summary["flags"]
    assert summary["over_budget"]["PLANNER_OVER_BUDGET"] == summary["ticks"]


def test_enforced_budgets_are_recorded_where_they_change_commands(runs: dict[str, Path]) -> None:
    e = rows(runs["enforced"] / "commands.csv")
    assert all("PLANNER_OVER_BUDGET" in r[6] and "PLANNER_TIMEOUT" in r[6] for r in e[1:])
    assert all(float(r[1]) == 0.0 for r in e[1:])  # the reactor over budget stops the vehicle


def test_until_does_not_change_earlier_ticks(runs: dict[str, Path]) -> None:
    short, long = runs["short"], runs["long"]
    for name in ("commands.csv", "stages.csv", "trajectory_corrected.tum", "trajectory_odom.tum"):
        a = (short / name).read_text().splitlines()
        b = (long / name).read_text().splitlines()
        assert len(b) > len(a) > 50
        assert a == b[: len(a)], name


def test_one_timestamp_string_per_tick_in_every_file(runs: dict[str, Path]) -> None:
    d = runs["long"]
    cmd = [r[0] for r in rows(d / "commands.csv")[1:]]
    tim = [r[0] for r in rows(d / "timing.csv")[1:]]
    stg = [r[0] for r in rows(d / "stages.csv")[1:]]
    tum = [line.split()[0] for line in (d / "trajectory_corrected.tum").read_text().splitlines()[1:]]
    assert cmd == tim == stg == tum  # every = 1: one tick per scan, joinable on the time string
    assert all(len(s.split(".")[1]) == 9 for s in cmd)


@pytest.fixture
def cpu_hog() -> Iterator[None]:
    """A busy-loop process beside the test (the machine is loaded: timings vary, records must not)."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        proc.kill()
        proc.wait()


def test_two_runs_under_cpu_load_give_identical_commands(tmp_path: Path, cpu_hog: None) -> None:
    cfg = PRESETS["wheelchair"]
    a = run_log(SAMPLE, cfg, tmp_path / "a", options=RunOptions(until_s=30.0)).out_dir
    b = run_log(SAMPLE, cfg, tmp_path / "b", options=RunOptions(until_s=30.0)).out_dir
    for name in ("commands.csv", "stages.csv", "trajectory_corrected.tum", "trajectory_odom.tum"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
