"""Long runs are readable: the log's recorded command in commands.csv and fig_commands, every episode a
visible mark however short, v and w as their range and mean per pixel column when ticks outnumber pixels,
and the figures of a time window (their own files, listed in the marker; a bad window is one line)."""

from __future__ import annotations

import math
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest

from gndreplay.errors import ConfigError, OutputError
from gndreplay.fsutil import RUN_MARKER, write_marker
from gndreplay.pipeline.nd import Situation
from gndreplay.pipeline.stack import TickResult
from gndreplay.report import FIGURES, build_report, load_run
from gndreplay.report.figures import COLUMNS, WINDOW_FIGURES, figure_commands, figure_modes
from gndreplay.report.plots import MIN_BAND_FRACTION, band_spans, column_envelope
from gndreplay.report.rundir import (
    COMMAND_COLUMNS,
    RunDirError,
    TrajectoryWriter,
    read_commands,
    tick_tables,
    window_run,
    write_summary,
)
from gndreplay.types import Command, Flag, Mode, Pose2D

PERIOD_S = 0.2
T0_NS = 1_700_000_000_000_000_000
LONG = 9000  # 1800 s at 5 Hz: more ticks than pixel columns
OVERRIDES = {17: Mode.EMERGENCY, 1234: Mode.SAFE_TURN, 1236: Mode.SAFE_TURN, 4000: Mode.STALE,
             6100: Mode.SAFE_REVERSE, 7777: Mode.ESCAPE, 8999: Mode.EMERGENCY}  # one tick each


def result(k: int, mode: Mode = Mode.MPND) -> TickResult:
    t_ns = T0_NS + round(k * PERIOD_S * 1e9)
    return TickResult(t_ns=t_ns, pose_corrected=Pose2D(0.01 * k, 0.0, 0.0),
                      command=Command(t_ns, 0.3 * math.cos(0.7 * k), 0.4 * math.sin(1.3 * k)),
                      mode=mode, situation=Situation.HSGR, flags=Flag.NONE, direction_rad=0.0,
                      goal=(5.0, 0.0), path_xy=np.zeros((0, 2)),
                      timings_ms={"match": 1.0, "model": 0.5, "planner": 2.0, "reactor": 0.3})


def logged(k: int) -> Command | None:
    """The log's recorded command: none on every tenth tick."""
    t_ns = T0_NS + round(k * PERIOD_S * 1e9)
    return None if k % 10 == 0 else Command(t_ns, 0.25 + 0.001 * k, -0.125)


def write_run(d: Path, n: int, modes: dict[int, Mode] | None = None) -> Path:
    """A run directory as a replay writes it (commands.csv, timing.csv, trajectories, summary.json,
    marker), from synthetic ticks."""
    d.mkdir(parents=True)
    traj = TrajectoryWriter()
    with tick_tables(d, enforce_budgets=False) as write_tick:
        for k in range(n):
            r = result(k, (modes or {}).get(k, Mode.MPND))
            traj.add(r.t_ns, r.pose_corrected, r.pose_corrected)
            write_tick(r, logged(k))
    traj.write(d)
    write_summary(d, {"ticks": n, "duration_s": (n - 1) * PERIOD_S})
    write_marker(d)
    return d


@pytest.fixture(scope="module")
def long_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_run(tmp_path_factory.mktemp("long") / "run", LONG, OVERRIDES)


# ---- the log's recorded command in commands.csv ----------------------------------------------------------


def test_the_recorded_command_is_written_at_the_end_and_read_back(tmp_path: Path) -> None:
    d = write_run(tmp_path / "run", 12)
    lines = (d / "commands.csv").read_text().splitlines()
    assert lines[0] == ",".join(COMMAND_COLUMNS) and lines[0].endswith(",subgoal,log_v,log_w")
    r = result(1)
    assert lines[2] == (f"1700000000.200000000,{r.command.v_mps:.6f},0.000000,{r.command.w_radps:.6f},"
                        "mpND,HSGR,,gnd,gnd,,-1,0.251000,-0.125000")
    assert lines[1].endswith(",gnd,gnd,,-1,,")  # the log records none: two empty fields
    c = read_commands(d / "commands.csv")
    assert c.log_v_mps[1] == 0.251 and c.log_w_radps[5] == -0.125
    assert np.flatnonzero(np.isnan(c.log_v_mps)).tolist() == [0, 10] == np.flatnonzero(
        np.isnan(c.log_w_radps)).tolist()


@pytest.mark.parametrize("width", [7, 11])
def test_a_commands_csv_without_the_recorded_columns_reads_as_nan(tmp_path: Path, width: int) -> None:
    d = write_run(tmp_path / "run", 6)
    rows = [",".join(line.split(",")[:width]) for line in (d / "commands.csv").read_text().splitlines()]
    (d / "commands.csv").write_text("\n".join(rows) + "\n")
    data = load_run(d)
    assert len(data.commands) == 6 and np.all(np.isnan(data.commands.log_v_mps))
    assert np.all(np.isnan(data.commands.log_w_radps)) and data.commands.v_mps[2] == pytest.approx(
        result(2).command.v_mps, abs=1e-6)
    labels = [ln.get_label() for ln in figure_commands(data).axes[0].get_lines()]
    assert not any("recorded" in x for x in labels)  # nothing of the log is drawn


def test_a_malformed_recorded_command_names_the_line(tmp_path: Path) -> None:
    d = write_run(tmp_path / "run", 3)
    text = (d / "commands.csv").read_text().replace(",0.251000,", ",fast,")
    (d / "commands.csv").write_text(text)
    with pytest.raises(RunDirError, match=r"commands.csv line 3: expected 13 fields.*log_v,log_w") as err:
        read_commands(d / "commands.csv")
    assert "\n" not in str(err.value)


def test_the_replay_writes_the_commands_the_log_records(tmp_path: Path) -> None:
    from gndreplay.config import Config
    from gndreplay.io import read_ticks
    from gndreplay.replay import RunOptions, run_log

    log = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
    out = run_log(log, Config(), tmp_path / "office", options=RunOptions(until_s=8.0)).out_dir
    c = read_commands(out / "commands.csv")
    ticks = {t.t_ns: t.cmd for t in read_ticks(log)}
    stamps = [line.split(",")[0].split(".") for line in (out / "commands.csv").read_text().splitlines()[1:]]
    recorded = [ticks[int(sec) * 10**9 + int(ns)] for sec, ns in stamps]  # the exact stamps
    assert len(c) > 30 and sum(cmd is not None for cmd in recorded) > 30
    expect = np.array([np.nan if cmd is None else cmd.v_mps for cmd in recorded])
    assert np.allclose(c.log_v_mps, expect, atol=5e-7, equal_nan=True)
    assert np.allclose(c.log_w_radps, [np.nan if m is None else m.w_radps for m in recorded], atol=5e-7,
                       equal_nan=True)


def test_fig_commands_draws_the_recorded_command_behind_ours(tmp_path: Path) -> None:
    data = load_run(write_run(tmp_path / "run", 50))
    fig = figure_commands(data)
    for ax, ours, theirs in ((fig.axes[0], "v", "v recorded in the log"),
                             (fig.axes[1], "w", "w recorded in the log")):
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        assert lines[theirs].get_zorder() < lines[ours].get_zorder()
        assert lines[theirs].get_color() != lines[ours].get_color()
        assert [t.get_text() for t in ax.get_legend().get_texts()] == [ours, theirs]
        y = lines[theirs].get_ydata()
        assert np.isnan(y[0]) and np.isnan(y[10])  # where the log records none, nothing is drawn
    assert lines["w recorded in the log"].get_ydata()[1] == -0.125


# ---- every episode visible; no solid block -------------------------------------------------------------


def test_every_one_tick_override_of_a_long_run_gets_a_visible_band(long_run: Path) -> None:
    c = load_run(long_run).commands
    t = c.t_s - c.t_s[0]
    span = t[-1] - t[0]
    min_width = MIN_BAND_FRACTION * span
    assert min_width > 20 * PERIOD_S  # without a minimum, a one-tick band is a twentieth of that
    rules = np.where(c.modes == "mpND", "", c.modes)
    bands = band_spans(t, rules, min_width=min_width)
    marks = bands.labels != ""
    assert np.count_nonzero(marks) == len(OVERRIDES)  # 1234 and 1236 are two episodes
    assert np.all(bands.width[marks] >= min_width) and np.all(bands.widened[marks])
    for k, x0, w in zip(sorted(OVERRIDES), bands.x0[marks], bands.width[marks], strict=True):
        assert x0 <= t[k] and t[k] + PERIOD_S <= x0 + w + 1e-9  # the mark covers its tick, centred on it
        assert x0 + w / 2 == pytest.approx(t[k] + PERIOD_S / 2)
    plain = band_spans(t, rules)  # without a minimum: the tick's own span
    assert np.allclose(plain.width[plain.labels != ""], PERIOD_S) and not np.any(plain.widened)
    long_runs = ~bands.widened
    assert np.allclose(bands.width[long_runs], plain.width[long_runs])  # long episodes keep their span


def test_fig_modes_draws_each_override_at_least_the_minimum_width_on_top(long_run: Path) -> None:
    fig = figure_modes(load_run(long_run))
    ax_r = fig.axes[3]
    x0, x1 = ax_r.get_xlim()
    bars = [(p.vertices[:, 0].min(), p.vertices[:, 0].max(), coll.get_zorder())
            for coll in ax_r.collections for p in coll.get_paths()]
    assert len(bars) == len(OVERRIDES)
    assert all(b - a >= 0.99 * MIN_BAND_FRACTION * (x1 - x0) for a, b, _ in bars)
    assert all(z > 1.0 for _, _, z in bars)  # widened bands lie above the ordinary ones
    assert "7 reflexive overrides (7 ticks)" in fig.axes[0].get_title()
    legend = fig.legends[-1]
    assert [t.get_text() for t in legend.get_texts()] == ["SAFE_TURN", "SAFE_REVERSE", "EMERGENCY", "STALE",
                                                         "ESCAPE"]  # the colour table's order


def test_column_envelope_is_the_range_and_mean_the_step_line_shows() -> None:
    t = np.array([0.0, 0.5, 0.9, 1.1, 3.7, 3.8, 5.2, 5.9])
    y = np.array([1.0, -2.0, np.nan, 4.0, 0.5, -1.0, 2.0, 3.0])
    x, lo, hi, mean = column_envelope(t, y, span=(0.0, 7.0), columns=7)
    assert x.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    # NaN is no value (column 1 starts with it held); an empty column holds the value before it (2, 4, 6);
    # a column starts with the value held into it (3 with 4.0, 5 with -1.0)
    assert lo.tolist() == [-2.0, 4.0, 4.0, -1.0, -1.0, -1.0, 3.0]
    assert hi.tolist() == [1.0, 4.0, 4.0, 4.0, -1.0, 3.0, 3.0]
    assert mean.tolist() == [-0.5, 4.0, 4.0, -0.25, -1.0, 2.5, 3.0]
    _, lo, _, _ = column_envelope(t + 2.0, y, span=(0.0, 9.0), columns=9)
    assert np.isnan(lo[:2]).all() and lo[2] == -2.0  # nothing before the first tick


def test_a_long_run_is_drawn_per_pixel_column_a_short_one_per_tick(long_run: Path, tmp_path: Path) -> None:
    from matplotlib.collections import PolyCollection

    ax_v = figure_commands(load_run(long_run)).axes[0]
    v = next(ln for ln in ax_v.get_lines() if ln.get_label() == "v")
    assert LONG > COLUMNS and len(v.get_xdata()) <= 2 * (COLUMNS + 1)  # a step line per column
    assert any(isinstance(c, PolyCollection) for c in ax_v.collections)  # the range, shaded
    x = np.asarray(v.get_xdata())
    assert np.all(np.diff(x) >= 0) and x[0] <= 0.0 and x[-1] >= (LONG - 1) * PERIOD_S
    ax_v = figure_commands(load_run(write_run(tmp_path / "short", 200))).axes[0]
    v = next(ln for ln in ax_v.get_lines() if ln.get_label() == "v")
    assert np.allclose(v.get_ydata(), load_run(tmp_path / "short").commands.v_mps)  # every tick
    assert not any(isinstance(c, PolyCollection) for c in ax_v.collections)


# ---- time windows ------------------------------------------------------------------------------------------


def test_window_figures_are_their_own_files_listed_in_the_marker(long_run: Path, tmp_path: Path) -> None:
    d = tmp_path / "run"
    d.mkdir()
    for p in long_run.iterdir():
        (d / p.name).write_bytes(p.read_bytes())
    written = build_report(d, t_from=240, t_to=250.5, require_marker=True)
    names = [p.name for p in written]
    assert names == [n.replace(".png", "_240-250.5.png") for n in WINDOW_FIGURES]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in written)
    assert not any((d / n).exists() for n in [*FIGURES, "report.md"])  # the whole run's are not drawn
    listed = (d / RUN_MARKER).read_text().splitlines()
    assert set(names) <= set(listed)
    again = build_report(d, t_from=240, t_to=250.5)  # its own files, redrawn
    assert [p.read_bytes() for p in again] == [p.read_bytes() for p in written]
    assert build_report(d, t_from=1790)[0].name == "fig_commands_1790-1799.8.png"  # clipped to the end
    (d / "fig_modes_10-20.png").write_bytes(b"mine")
    with pytest.raises(OutputError, match=r"fig_modes_10-20\.png: exists and was not written by gndreplay"):
        build_report(d, t_from=10, t_to=20)
    assert (d / "fig_modes_10-20.png").read_bytes() == b"mine"
    assert not (d / "fig_commands_10-20.png").exists()  # refused before anything was drawn


def test_a_window_draws_its_stretch_on_the_runs_time_axis(long_run: Path) -> None:
    data = window_run(load_run(long_run), 600.0, 660.0)
    assert data.window is not None and data.window.tag == "600-660"
    assert len(data.commands) == 301 and data.commands.t_s[0] - load_run(long_run).commands.t_s[0] == 600.0
    for fig in (figure_commands(data), figure_modes(data)):
        assert fig.axes[0].get_xlim() == (600.0, 660.0)
        assert "from 600 to 660 s" in fig.axes[0].get_title()
    v = next(ln for ln in figure_commands(data).axes[0].get_lines() if ln.get_label() == "v")
    assert len(v.get_xdata()) == 301  # few ticks: the step line of every tick


@pytest.mark.parametrize(
    ("t_from", "t_to", "match"),
    [
        (300.0, 300.0, r"window 300-300 s is empty \(from must be before to\)"),
        (500.0, 100.0, r"window 500-100 s is empty"),
        (2000.0, None, r"window 2000-end s is outside the run"),
        (-5.0, 10.0, r"window -5-10 s starts before the run"),
        (float("nan"), None, r"must be finite"),
    ],
)
def test_a_bad_window_is_one_line_naming_the_run_and_its_span(long_run: Path, t_from: float,
                                                               t_to: float | None, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as err:
        build_report(long_run, t_from=t_from, t_to=t_to)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{long_run}: window ")
    assert msg.endswith(f"; {long_run} spans 0-1799.8 s since its first tick")
    assert not any(long_run.glob("fig_*_*.png"))


def test_episodes_and_windows_share_the_tick_spans(long_run: Path) -> None:
    """A window cut through an episode keeps the ticks inside it, and each tick its own span."""
    data = window_run(load_run(long_run), 246.5, 247.5)
    t = data.commands.t_s - load_run(long_run).commands.t_s[0]
    assert [round(x, 1) for x in t] == [246.6, 246.8, 247.0, 247.2, 247.4]
    assert data.commands.modes.tolist() == ["mpND", "SAFE_TURN", "mpND", "SAFE_TURN", "mpND"]
    assert all(b - a == pytest.approx(PERIOD_S) for a, b in pairwise(t))
