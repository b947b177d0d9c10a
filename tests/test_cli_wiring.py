"""The options of the figures' window, the animation, the event snapshots and results.mcap's grid reach the
library functions that act on them (stand-ins here: this checks the command line, not the drawing)."""

from __future__ import annotations

import sys
import types
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

import gndreplay.report.build
import gndreplay.report.sinks
from gndreplay.cli import app

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
runner = CliRunner()


class Seen:
    """Records the keyword arguments of each call of a stand-in."""

    def __init__(self, result: Any = None) -> None:
        self.calls: list[tuple[tuple[Any, ...], dict[str, Any]]] = []
        self.result = result

    def __call__(self, *args: Any, **kw: Any) -> Any:
        self.calls.append((args, kw))
        return self.result(*args, **kw) if callable(self.result) else self.result


@pytest.fixture
def snapshots_module(monkeypatch: pytest.MonkeyPatch) -> type:
    """A stand-in for ``gndreplay.report.snapshots`` holding ``SnapshotOptions``."""

    class SnapshotOptions:
        def __init__(self, **given: Any) -> None:
            self.__dict__.update(given)

    module = types.ModuleType("gndreplay.report.snapshots")
    module.SnapshotOptions = SnapshotOptions  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "gndreplay.report.snapshots", module)
    return SnapshotOptions


def test_report_draws_the_window_asked_for(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    build = Seen([tmp_path / "fig_commands.png"])
    monkeypatch.setattr(gndreplay.report.build, "build_report", build)
    res = runner.invoke(app, ["report", str(tmp_path), "--from", "600", "--to", "660.5"])
    assert res.exit_code == 0, res.output
    assert build.calls == [((tmp_path,), {"require_marker": True, "t_from": 600.0, "t_to": 660.5})]
    assert res.stdout.strip() == str(tmp_path / "fig_commands.png")


def test_report_animate_writes_the_animation_with_progress(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    def animate(run_dir: Path, out_path: Path, *, on_progress: Any, **kw: Any) -> Path:
        for k in range(1, 21):
            on_progress(k, 20)
        return out_path

    seen = Seen(animate)
    module = types.ModuleType("gndreplay.report.animate")
    module.animate_run = seen  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "gndreplay.report.animate", module)
    res = runner.invoke(app, ["report", str(tmp_path), "--animate", "--from", "10", "--to", "30",
                              "--out", str(tmp_path / "a.gif"), "--progress", "plain"])
    assert res.exit_code == 0, res.output
    (args, kw), = seen.calls
    assert args == (tmp_path, tmp_path / "a.gif") and (kw["t_from"], kw["t_to"]) == (10.0, 30.0)
    assert res.stdout.strip() == str(tmp_path / "a.gif")
    lines = res.stderr.splitlines()
    assert len(lines) == 9, res.stderr
    assert lines[0].startswith(f"gndreplay: {tmp_path.name}: animation: 10 % (2/20 frames)")
    default = runner.invoke(app, ["report", str(tmp_path), "--animate", "--progress", "none"])
    assert default.exit_code == 0 and seen.calls[-1][0] == (tmp_path, tmp_path / "animation.gif")


def test_run_passes_snapshots_the_mcap_grid_and_the_window(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           snapshots_module: type) -> None:
    sinks = Seen([])
    build = Seen([])
    monkeypatch.setattr(gndreplay.report.sinks, "default_sinks", sinks)
    monkeypatch.setattr(gndreplay.report.build, "build_report", build)
    base = ["run", str(SAMPLE), "--until", "2", "-q"]
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "a"), "--mcap", "--mcap-grid", "every",
                              "--from", "0.5", "--to", "1.5"])
    assert res.exit_code == 0, res.output
    kw = sinks.calls[-1][1]
    assert isinstance(kw["snapshots"], snapshots_module) and kw["mcap_grid"] == 1 and kw["mcap"]
    assert build.calls == [((tmp_path / "a",), {"require_marker": True, "t_from": 0.5, "t_to": 1.5})]
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "b"), "--no-snapshots"])
    assert res.exit_code == 0 and sinks.calls[-1][1]["snapshots"] is None
    assert sinks.calls[-1][1]["mcap_grid"] == "change" and len(build.calls) == 1  # no window: no redraw
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "c"), "--no-figures"])
    assert res.exit_code == 0 and sinks.calls[-1][1]["snapshots"] is None  # off with the figures
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "d"), "--no-figures", "--snapshots"])
    assert res.exit_code == 0 and isinstance(sinks.calls[-1][1]["snapshots"], snapshots_module)


@pytest.mark.parametrize(("args", "message"), [
    (["run", "nope.clf", "--no-figures", "--to", "60"], "--from / --to choose the figures' window: not with "
                                                        "--no-figures"),
    (["run", "nope.clf", "--mcap-grid", "evry"], "--mcap-grid: expected one of every, change, got 'evry' "
                                                 "(did you mean 'every'?)"),
    (["run", "nope.clf", "--from", "-1"], "--from: must be from 0 to"),
    (["report", ".", "--out", "a.gif"], "report: --out names the animation's file: give --animate too"),
])
def test_bad_window_or_grid_options_are_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  args: list[str], message: str) -> None:
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and res.stderr.startswith(f"gndreplay: error: {message}"), res.stderr
    assert len(res.stderr.splitlines()) == 1 and list(tmp_path.iterdir()) == []


def test_snapshot_limits_reach_the_sink(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        snapshots_module: type) -> None:
    sinks = Seen([])
    monkeypatch.setattr(gndreplay.report.sinks, "default_sinks", sinks)
    res = runner.invoke(app, ["run", str(SAMPLE), "--until", "2", "-q", "--out", str(tmp_path / "a"),
                              "--snapshot-every", "2.5", "--snapshot-max", "3"])
    assert res.exit_code == 0, res.output
    options = sinks.calls[-1][1]["snapshots"]
    assert isinstance(options, snapshots_module)
    assert (options.min_interval_s, options.max_snapshots) == (2.5, 3)
    bad = runner.invoke(app, ["run", str(SAMPLE), "--snapshot-max", "-1"])
    assert bad.exit_code == 2 and "--snapshot-max: must be from 0 to" in bad.stderr
