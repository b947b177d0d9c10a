"""The assisted-navigation audit on synthetic ticks: takeovers and reflexive overrides merged into episodes
with their start, duration and reason; summary.json, commands.csv, report.md and fig_modes.png agree."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gndreplay.config import PRESETS
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.replay import RunOptions
from gndreplay.report.markdown import MAX_EPISODE_ROWS, interventions_section
from gndreplay.report.rundir import (
    COMMAND_COLUMNS,
    RunDirError,
    command_row,
    episodes,
    read_commands,
    tick_edges,
)
from gndreplay.report.summary import SummaryRecorder, command_gap_warning, interventions, summarise
from gndreplay.types import REFLEXIVE_MODES, Command, Flag, Mode, Pose2D

T0 = 1_000_000_000_000
DT = 200_000_000  # 5 Hz


def result(k: int, desired: str, active: str, reason: str = "", mode: Mode = Mode.MPND,
           subgoal: int = -1) -> TickResult:
    return TickResult(
        t_ns=T0 + k * DT, pose_corrected=Pose2D(0.1 * k, 0.0, 0.0), command=Command(T0 + k * DT, 0.2, 0.0),
        mode=mode, situation=Situation.HSGR, flags=Flag.NONE, direction_rad=0.0, goal=(5.0, 0.0),
        path_xy=np.zeros((0, 2)), timings_ms={"match": 1.0, "model": 1.0, "planner": 1.0, "reactor": 1.0},
        desired_mode=desired, active_mode=active, takeover_reason=reason, subgoal_index=subgoal)


TAKE = "teleop: swept area occupied (scan)"
GRID = "teleop: swept area occupied (grid)"
# ticks 0-1 teleop, 2-4 taken over (the reason changes inside), 5 teleop with an emergency stop,
# 6-7 taken over again to the end of the run, the last two with SAFE_SLOW then EMERGENCY
SCRIPT = [
    ("teleop", "teleop", "", Mode.MPND),
    ("teleop", "teleop", "", Mode.MPND),
    ("teleop", "local", TAKE, Mode.MPND),
    ("teleop", "local", GRID, Mode.MND),
    ("teleop", "local", TAKE, Mode.MPND),
    ("teleop", "teleop", "", Mode.EMERGENCY),
    ("teleop", "local", GRID, Mode.SAFE_SLOW),
    ("teleop", "local", GRID, Mode.EMERGENCY),
]


def audit() -> dict[str, Any]:
    t = [T0 + k * DT for k in range(len(SCRIPT))]
    desired, active, reasons, modes = (list(c) for c in zip(*SCRIPT, strict=True))
    return interventions(t, desired, active, reasons, [m.value for m in modes])


def test_episodes_are_runs_of_equal_non_empty_keys() -> None:
    assert episodes([]) == []
    assert episodes(["", "", ""]) == []
    assert episodes(["a", "a", "", "a", "b", "b"]) == [(0, 2), (3, 4), (4, 6)]
    assert episodes(["", "x"]) == [(1, 2)]


def test_consecutive_takeover_ticks_are_one_takeover_with_its_duration() -> None:
    iv = audit()
    assert iv["desired"] == {"teleop": 8}
    assert iv["active"] == {"local": 5, "teleop": 3}
    assert iv["takeover_ticks"] == 5
    first, second = iv["takeovers"]
    # ticks 2-4 (a change of reason inside does not split it): from 0.4 s until tick 5 at 1.0 s
    assert first == {"t_start_s": pytest.approx(0.4), "duration_s": pytest.approx(0.6), "ticks": 3,
                     "desired": "teleop", "active": "local", "reason": TAKE}
    # ticks 6-7 run to the end of the run: one tick period past the last tick (tick_edges)
    assert second["t_start_s"] == pytest.approx(1.2) and second["duration_s"] == pytest.approx(0.4)
    assert second["ticks"] == 2 and second["reason"] == GRID


def test_reflexive_overrides_are_episodes_per_rule() -> None:
    iv = audit()
    assert iv["reflexive_ticks"] == 3
    assert [(e["rule"], e["ticks"]) for e in iv["emergencies"]] == [
        ("EMERGENCY", 1), ("SAFE_SLOW", 1), ("EMERGENCY", 1)]
    assert [e["t_start_s"] for e in iv["emergencies"]] == pytest.approx([1.0, 1.2, 1.4])
    # a one-tick EMERGENCY at the end of the run lasts one tick period, like every one-tick episode
    assert [e["duration_s"] for e in iv["emergencies"]] == pytest.approx([0.2, 0.2, 0.2])
    # rounded to the stamps' nanosecond: summary.json says 0.2, not 0.1999999999999993
    assert [repr(e["duration_s"]) for e in iv["emergencies"]] == ["0.2", "0.2", "0.2"]
    assert set(REFLEXIVE_MODES) == {"EMERGENCY", "SAFE_SLOW", "SAFE_TURN", "SAFE_REVERSE", "STALE", "ESCAPE"}


def test_no_intervention_in_a_clean_gnd_run() -> None:
    t = [T0 + k * DT for k in range(4)]
    iv = interventions(t, ["gnd"] * 4, ["gnd"] * 4, [""] * 4, ["mpND", "mND", "ROTATE", "GOAL"])
    assert iv == {"desired": {"gnd": 4}, "active": {"gnd": 4}, "takeover_ticks": 0, "takeovers": [],
                  "reflexive_ticks": 0, "emergencies": [], "no_command_ticks": 0, "stale_command_ticks": 0}
    assert interventions([], [], [], [], [])["takeovers"] == []


def test_summary_and_commands_csv_carry_the_audit(tmp_path: Path) -> None:
    rec = SummaryRecorder()
    rows = [",".join(COMMAND_COLUMNS) + "\n"]
    for k, (d, a, why, mode) in enumerate(SCRIPT):
        r = result(k, d, a, why.replace("(scan)", "(scan, left)"), mode, subgoal=k // 3)
        rec.add(r)
        rows.append(command_row(r, False))
    summary = summarise(rec, PRESETS["wheelchair"], Path("x.clf"), RunOptions(), None)
    iv = summary["interventions"]
    assert iv["takeovers"][0]["reason"] == "teleop: swept area occupied (scan; left)"  # one CSV field
    assert json.loads(json.dumps(summary))["interventions"] == iv  # plain JSON: behaviour only
    (tmp_path / "commands.csv").write_text("".join(rows))
    c = read_commands(tmp_path / "commands.csv")
    assert c.desired.tolist() == ["teleop"] * 8
    assert c.active.tolist() == [a for _, a, _, _ in SCRIPT]
    assert int((c.active != c.desired).sum()) == iv["takeover_ticks"]
    assert c.takeover[2] == "teleop: swept area occupied (scan; left)" and c.takeover[0] == ""
    assert c.subgoal.tolist() == [0, 0, 0, 1, 1, 1, 2, 2]


def test_an_older_commands_csv_reads_as_gnd(tmp_path: Path) -> None:
    p = tmp_path / "commands.csv"
    p.write_text("t,v,vy,w,mode,situation,flags\n1.0,0.1,0.0,0.2,mpND,HSWR,\n")
    c = read_commands(p)
    assert c.desired.tolist() == c.active.tolist() == ["gnd"] and c.takeover.tolist() == [""]
    assert c.subgoal.tolist() == [-1]
    p.write_text(",".join(COMMAND_COLUMNS[:11]) + "\n1.0,0.1,0.0,0.2,mpND,HSWR,,teleop,local,why,x\n")
    with pytest.raises(RunDirError, match=r"commands.csv line 2: expected 11 fields.*subgoal \(an integer\)"):
        read_commands(p)


def test_the_report_section_lists_takeovers_and_emergencies_or_says_none() -> None:
    text = "\n".join(interventions_section(audit(), 8))
    assert f"| 0.40 | 0.60 | 3 | teleop | local | {TAKE} |" in text
    assert "| 1.20 | 0.20 | 1 | SAFE_SLOW |" in text
    assert "| local | 5 | 62.5 % |" in text
    none = "\n".join(interventions_section(interventions([T0], ["gnd"], ["gnd"], [""], ["mpND"]), 1))
    assert "No takeover" in none and "No emergency stop and no reflexive override." in none
    assert "Not recorded" in "\n".join(interventions_section(None, 0))
    many = {"takeovers": [{"t_start_s": float(k), "duration_s": 0.2, "ticks": 1, "desired": "teleop",
                           "active": "local", "reason": "r"} for k in range(MAX_EPISODE_ROWS + 3)]}
    assert "... and 3 more (summary.json lists them all)." in "\n".join(interventions_section(many, 60))


def test_fig_modes_shades_each_takeover_and_bands_each_rule(tmp_path: Path) -> None:
    from gndreplay.report.figures import figure_modes
    from gndreplay.report.rundir import RunData, Timing

    rows = [",".join(COMMAND_COLUMNS) + "\n"]
    rows += [command_row(result(k, d, a, why, mode), False) for k, (d, a, why, mode) in enumerate(SCRIPT)]
    (tmp_path / "commands.csv").write_text("".join(rows))
    c = read_commands(tmp_path / "commands.csv")
    data = RunData(run_dir=tmp_path, commands=c, timing=Timing(t_s=c.t_s, ms={}), traj_odom=np.zeros((0, 4)),
                   traj_corrected=np.zeros((0, 4)), summary={}, maps=None)
    fig = figure_modes(data)
    ax_c, ax_d, ax_a, ax_r = fig.axes[:4]
    spans = sorted((p.get_x(), p.get_x() + p.get_width()) for p in ax_c.patches)
    assert spans == [pytest.approx((0.4, 1.0)), pytest.approx((1.2, 1.6))]  # the last runs one period on
    # the figure and summary.json (hence report.md) share one definition of an episode's span
    iv = audit()
    assert spans == [pytest.approx((e["t_start_s"], e["t_start_s"] + e["duration_s"]))
                     for e in iv["takeovers"]]
    assert "2 takeovers (5 ticks), 3 reflexive overrides (3 ticks)" in ax_c.get_title()
    assert sorted(bars.get_label() for bars in ax_r.collections) == ["EMERGENCY", "SAFE_SLOW"]
    assert sorted(bars.get_label() for bars in ax_a.collections) == ["local", "teleop"]
    assert [bars.get_label() for bars in ax_d.collections] == ["teleop"]


def test_episode_spans_follow_tick_edges_on_irregular_ticks() -> None:
    """Irregular tick periods: every episode spans tick_edges (the figure's bands), the last one the median
    period past its last tick; a single tick lasts 1 s."""
    t = [T0, T0 + 100_000_000, T0 + 300_000_000, T0 + 400_000_000, T0 + 500_000_000]
    modes = ["mpND", "EMERGENCY", "EMERGENCY", "mpND", "STALE"]
    iv = interventions(t, ["gnd"] * 5, ["gnd"] * 5, [""] * 5, modes)
    edges = tick_edges((np.asarray(t) - T0) / 1e9)
    assert edges.tolist() == pytest.approx([0.0, 0.1, 0.3, 0.4, 0.5, 0.6])
    assert [(e["rule"], e["t_start_s"], e["duration_s"]) for e in iv["emergencies"]] == [
        ("EMERGENCY", pytest.approx(0.1), pytest.approx(0.3)),
        ("STALE", pytest.approx(0.5), pytest.approx(0.1)),
    ]
    one = interventions([T0], ["gnd"], ["gnd"], [""], ["EMERGENCY"])["emergencies"]
    assert one == [{"t_start_s": 0.0, "duration_s": 1.0, "ticks": 1, "rule": "EMERGENCY"}]


def test_ticks_without_a_usable_teleop_command_are_counted_and_reported() -> None:
    """The stack records "teleop: no command" / "... not finite" / "... stale" while the desired mode stays
    active (the robot stands still): not takeovers, but counted, shown in report.md and warned about."""
    reasons = ["teleop: no command", "teleop: no command", "", "teleop: command stale",
               "teleop: command not finite", "", "", "", "", ""]
    n = len(reasons)
    t = [T0 + k * DT for k in range(n)]
    iv = interventions(t, ["teleop"] * n, ["teleop"] * n, reasons, ["mpND"] * n)
    assert iv["takeovers"] == [] and iv["takeover_ticks"] == 0
    assert (iv["no_command_ticks"], iv["stale_command_ticks"]) == (3, 1)
    text = "\n".join(interventions_section(iv, n))
    assert ("Ticks without a usable teleop command (the robot stood still): 3 (30.0 %) with none or a "
            "non-finite one, 1 (10.0 %) with a stale one.") in text
    warning = command_gap_warning({"ticks": n, "interventions": iv})
    assert warning == ("4 of 10 ticks (40 %) had no usable teleop command (3 none or not finite, 1 stale): "
                       "the robot stood still on them")
    # at most 20 %: quiet; a run without the counts (an older summary) too
    assert command_gap_warning({"ticks": 20, "interventions": iv}) is None
    assert command_gap_warning({"ticks": 0, "interventions": {}}) is None
    assert "usable teleop command" not in "\n".join(interventions_section(audit(), 8))
