"""Progress on stderr: ``run``, ``scanmatch``, ``simulate`` and ``batch`` show it as a live bar on a terminal
(fitting 80 columns) and as a plain line every 10 % when stderr is a file or a pipe (every 10 s while the
total is unknown); ``--progress none`` and ``--quiet`` silence it."""

from __future__ import annotations

import io
import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from rich.console import Console
from typer.testing import CliRunner

from gndreplay import cli
from gndreplay.cli import app

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
runner = CliRunner()
CLOCK = r"\d+:\d\d:\d\d"
LINE = re.compile(rf"gndreplay: (?P<what>.+?): (?P<pct>\d+) % \((?P<detail>[^)]*)\), {CLOCK} elapsed, "
                  rf"ETA {CLOCK}")


def progress_lines(stderr: str) -> list[re.Match[str]]:
    """The plain progress lines of ``stderr``; every other line is the one-time compile notice."""
    lines = stderr.splitlines()
    found = [m for line in lines if (m := LINE.fullmatch(line))]
    others = [line for line in lines if not LINE.fullmatch(line)]
    assert set(others) <= {"gndreplay: compiling (first run only)..."}, others
    return found


def test_run_off_a_terminal_prints_a_line_every_tenth(tmp_path: Path) -> None:
    args = ["run", str(SAMPLE), "--until", "20", "--no-figures", "--out", str(tmp_path / "run")]
    res = runner.invoke(app, args)  # CliRunner's stderr is not a terminal: --progress auto is plain
    assert res.exit_code == 0, res.output
    found = progress_lines(res.stderr)
    assert [int(m["pct"]) for m in found] == [10, 20, 30, 40, 50, 60, 70, 80, 90]
    assert {m["what"] for m in found} == {"office.clf.bz2"}
    assert re.fullmatch(r"\d+ ticks, \d+ s", found[0]["detail"])
    assert "run directory" in res.stdout  # the table still follows on stdout


@pytest.mark.parametrize("silent", [["--progress", "none"], ["--quiet"], ["--json"]])
def test_run_progress_can_be_silenced(tmp_path: Path, silent: list[str]) -> None:
    args = ["run", str(SAMPLE), "--until", "5", "--no-figures", "--out", str(tmp_path / "run"), *silent]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    assert progress_lines(res.stderr) == []


@pytest.mark.parametrize(("flag", "expected"), [
    ("--no-parallel", {"odom", "idc", "kiss-icp"}),  # one pass per matcher
    ("--parallel", {"odom + idc + kiss-icp"}),  # one pass, the matchers side by side
])
def test_scanmatch_shows_each_matcher_pass(tmp_path: Path, flag: str, expected: set[str]) -> None:
    res = runner.invoke(app, ["scanmatch", str(SAMPLE), "--progress", "plain", "--out", str(tmp_path / "sm"),
                              flag])
    assert res.exit_code == 0, res.output
    passes = [m["what"] for m in progress_lines(res.stderr)]
    assert passes and set(passes) == {f"office.clf.bz2: {m}" for m in expected}


def test_simulate_shows_the_scenario_time(tmp_path: Path) -> None:
    args = ["simulate", "u_trap", "--time-limit", "10", "--no-figures", "--progress", "plain",
            "--out", str(tmp_path / "sim")]
    res = runner.invoke(app, args)
    assert res.exit_code in (0, 1), res.output
    assert [int(m["pct"]) for m in progress_lines(res.stderr)] == [10, 20, 30, 40, 50, 60, 70, 80, 90]


def test_batch_counts_its_inputs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import gndreplay.batch
    from gndreplay.batch import BatchResult

    def stand_in(jobs: Any, *, progress: Any, **kw: Any) -> BatchResult:
        for job in jobs:
            progress(SimpleNamespace(name=job.name))
        return BatchResult((), tmp_path, tmp_path / "s.csv", tmp_path / "s.md", None, 0.0)

    monkeypatch.setattr(gndreplay.batch, "run_batch", stand_in)
    res = runner.invoke(app, ["batch", "--scenarios", "enclosed", "--seeds", "0-19", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    found = progress_lines(res.stderr)
    assert [int(m["pct"]) for m in found] == [10, 20, 30, 40, 50, 60, 70, 80, 90]
    assert found[0]["what"] == "batch" and found[0]["detail"] == "2/20 inputs, last enclosed-s1"


def test_without_a_total_a_plain_line_comes_every_ten_seconds(monkeypatch: pytest.MonkeyPatch,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    now = [0.0]
    monkeypatch.setattr(cli.time, "monotonic", lambda: now[0])
    with cli._Progress("plain") as shown:
        shown.start("log.bag", None)
        for k in range(1, 36):
            now[0] = float(k)
            shown.update(k, f"{k} ticks")
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"gndreplay: log.bag: {k} ticks, 0:00:{k:02d} elapsed" for k in (10, 20, 30)]


def test_an_unknown_progress_style_is_one_line_with_a_suggestion() -> None:
    res = runner.invoke(app, ["run", "nope.clf", "--progress", "plian"])
    assert res.exit_code == 2
    assert res.stderr.strip() == ("gndreplay: error: --progress: expected one of auto, plain, none, "
                                  "got 'plian' (did you mean 'plain'?)")


@pytest.mark.parametrize("total", [1800.0, None])
def test_the_live_bar_fits_80_columns(total: float | None) -> None:
    out = io.StringIO()
    bar = cli._progress_bar(Console(file=out, width=80, force_terminal=True, color_system=None))
    now = [0.0]
    bar.get_time = lambda: now[0]  # type: ignore[method-assign]  # 60 units/s, 1200 to go: 20 s
    task = bar.add_task("mit-csail-with-a-long-name.clf.bz2: compiling (first run only)…", total=total,
                        detail="12345 ticks, 1234 s of the log")
    for now[0], done in ((5.0, 300), (10.0, 600)):
        bar.update(task, completed=done)
    bar.console.print(bar.make_tasks_table(bar.tasks))
    line = out.getvalue().rstrip("\n")
    assert "\n" not in line and len(line) <= 80, line
    eta = " 0:00:10 ETA 0:00:20$" if total else " 0:00:10 ETA *$"  # no ETA without a total
    assert re.search(eta, line), line  # the times are never cut
    assert "mit-csail" in line and ("33%" in line or total is None)
