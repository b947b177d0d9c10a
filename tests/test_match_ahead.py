"""Scan matching in a second process (``scanmatch.MatchAhead``): the same results as the sequential run,
the log read exactly as far, the matcher's errors raised in the caller and no process left behind."""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import pytest

from gndreplay.config import PRESETS
from gndreplay.errors import ScanMatchError
from gndreplay.io import read_ticks
from gndreplay.replay import RunOptions, run_log
from gndreplay.scanmatch import MatchAhead, make_matcher, run_scanmatch
from gndreplay.scanmatch.ahead import available

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
BEHAVIOUR = ("commands.csv", "trajectory_odom.tum", "trajectory_corrected.tum", "trajectory_truth.tum",
             "config.toml")
WALL_CLOCK = ("latency_ms", "over_budget")

pytestmark = pytest.mark.skipif(not available(), reason="MatchAhead needs POSIX pipes")


def _summary(run: Path) -> dict[str, object]:
    data = json.loads((run / "summary.json").read_text())
    return {k: v for k, v in data.items() if k not in WALL_CLOCK}


@pytest.mark.parametrize("options", [
    RunOptions(),  # the goal ahead: ticks past the end feed the lookahead
    RunOptions(until_s=12.0),  # stopped early: the log read as far as the sequential run reads it
    RunOptions(goal_xy=(3.0, 1.0), until_s=7.5, every=3),
], ids=["goal-ahead", "until", "fixed-goal-every"])
def test_matching_ahead_gives_the_sequential_run_byte_for_byte(tmp_path: Path, options: RunOptions) -> None:
    cfg = PRESETS["wheelchair"]
    run_log(SAMPLE, cfg, tmp_path / "seq", options=options)
    ahead = RunOptions(**{**{f: getattr(options, f) for f in options.__slots__}, "match_ahead": True})
    run_log(SAMPLE, cfg, tmp_path / "ahead", options=ahead)
    for name in BEHAVIOUR:
        assert (tmp_path / "seq" / name).read_bytes() == (tmp_path / "ahead" / name).read_bytes(), name
    seq, par = _summary(tmp_path / "seq"), _summary(tmp_path / "ahead")
    assert seq["read_report"] == par["read_report"]  # the same records read, warnings included
    assert json.dumps(seq, sort_keys=True) == json.dumps(par, sort_keys=True)


def test_a_matcher_that_cannot_be_built_fails_in_the_caller() -> None:
    with MatchAhead(functools.partial(make_matcher, "no-such-matcher")) as ahead,  \
            pytest.raises(ScanMatchError, match="no-such-matcher"):
        ahead.ready()


def test_the_child_ends_when_the_consumer_stops_early() -> None:
    ticks = read_ticks(SAMPLE)
    ahead = MatchAhead(functools.partial(make_matcher, "idc"), depth=4)
    with pytest.raises(KeyboardInterrupt), ahead:
        proc = ahead._proc
        assert proc is not None
        for k, (tick, res, _ms) in enumerate(ahead.results(ticks)):
            assert res.pose is not None and tick.index == k
            if k == 5:
                raise KeyboardInterrupt  # as Ctrl-C in the middle of a replay
    assert proc.poll() is not None  # ended, not orphaned
    with pytest.raises(ProcessLookupError):
        os.kill(proc.pid, 0)


def test_matchers_side_by_side_give_each_matcher_its_own_pass(tmp_path: Path) -> None:
    """``scanmatch`` with the matchers in parallel (one pass, a process each) writes the trajectories and
    reports the failures of one sequential pass per matcher."""
    rows = {}
    for parallel in (False, True):
        rows[parallel] = run_scanmatch(lambda: read_ticks(SAMPLE), out_dir=tmp_path / str(parallel),
                                       parallel=parallel)
    for seq, par in zip(rows[False], rows[True], strict=True):
        assert seq.method == par.method
        assert Path(seq.tum_path).read_bytes() == Path(par.tum_path).read_bytes()
        assert seq.to_dict()["failures"] == par.to_dict()["failures"]


_FAILING = '''
from gndreplay.scanmatch import make_matcher


class Failing:
    name = "failing"

    def __init__(self):
        self.inner, self.k = make_matcher("odom"), 0

    def update(self, scan, odom):
        self.k += 1
        if self.k == 6:
            raise ValueError("no match at the sixth scan")
        return self.inner.update(scan, odom)


def make():
    return Failing()
'''


@pytest.mark.parametrize("depth", [1, 32])
def test_a_matcher_error_is_raised_at_its_tick_after_the_earlier_results(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, depth: int) -> None:
    """The child ends at its matcher's error while the caller still sends it ticks (a full pipe at depth
    32): the caller gets the results before it, then the matcher's own error, not a broken pipe."""
    (tmp_path / "failing_matcher.py").write_text(_FAILING)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    import failing_matcher  # type: ignore[import-not-found]

    seen = []
    with MatchAhead(failing_matcher.make, depth=depth) as ahead, \
            pytest.raises(ValueError, match="the sixth scan"):
        for tick, _res, _ms in ahead.results(read_ticks(SAMPLE)):
            seen.append(tick.index)
    assert seen == [0, 1, 2, 3, 4]


def test_a_killed_child_is_one_error_in_the_caller() -> None:
    with MatchAhead(functools.partial(make_matcher, "odom")) as ahead, \
            pytest.raises(ScanMatchError, match="ended unexpectedly"):
        for k, _ in enumerate(ahead.results(read_ticks(SAMPLE))):
            if k == 2:
                assert ahead._proc is not None
                ahead._proc.kill()
                ahead._proc.wait()


_CTRL_C = '''
import functools, os, signal, sys, time
from gndreplay.scanmatch import MatchAhead, make_matcher
# Python ignores SIGINT when it started with it ignored (a background job of a non-interactive shell, some
# CI runners): as in a terminal, Ctrl-C raises KeyboardInterrupt here
signal.signal(signal.SIGINT, signal.default_int_handler)
try:
    with MatchAhead(functools.partial(make_matcher, "idc")) as ahead:
        time.sleep(0.1)  # the child is still importing
        os.killpg(0, signal.SIGINT)  # as a terminal's Ctrl-C: the whole foreground process group
        time.sleep(10)
except KeyboardInterrupt:
    print("interrupted", ahead._proc, file=sys.stderr)
'''


def test_ctrl_c_while_the_child_starts_is_heard_by_the_caller_alone() -> None:
    """Ctrl-C reaches the caller only: the child, still importing, prints no traceback of its own."""
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    done = subprocess.run([sys.executable, "-c", _CTRL_C], capture_output=True, text=True, timeout=60,
                          env=env, start_new_session=True)
    assert done.stderr.strip() == "interrupted None", done.stderr


def test_a_make_that_does_not_pickle_fails_on_entry_and_stops_the_child(
        capfd: pytest.CaptureFixture[str]) -> None:
    import pickle

    ahead = MatchAhead(lambda: make_matcher("odom"))
    with pytest.raises((pickle.PicklingError, AttributeError)), ahead:
        pass
    assert ahead._proc is None  # closed: the child waited for
    assert "Traceback" not in capfd.readouterr().err  # the child ended quietly
