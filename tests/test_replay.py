"""``gndreplay run`` end to end: determinism, one command per scan, goals, agreement, bad input."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import PRESETS
from gndreplay.errors import LogFormatError
from gndreplay.geometry import relative
from gndreplay.io import ReadOptions, read_ticks
from gndreplay.replay import Matched, RunOptions, assign_goals, run_log
from gndreplay.report.summary import motion_agreement
from gndreplay.types import Pose2D, Scan, Tick

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
DETERMINISTIC = ("commands.csv", "stages.csv", "trajectory_odom.tum", "trajectory_corrected.tum",
                 "config.toml")


def _matched(xs: list[float], ys: list[float]) -> list[Matched]:
    scan = Scan(t_ns=0, ranges_m=np.ones(3), angles_rad=np.zeros(3), max_range_m=5.0)
    out, s = [], 0.0
    for k, (x, y) in enumerate(zip(xs, ys, strict=True)):
        if k:
            s += math.hypot(x - xs[k - 1], y - ys[k - 1])
        pose = Pose2D(x, y, 0.0)
        out.append(Matched(Tick(k, k, scan, pose), pose, 0.0, False, s))
    return out


def test_goal_ahead_is_interpolated_along_the_corrected_path() -> None:
    xs = [0.1 * k for k in range(101)]  # 10 m straight along x, 0.1 m steps
    pairs = list(assign_goals(_matched(xs, [0.0] * 101), RunOptions(goal_ahead_m=2.55)))
    assert [m.tick.index for m, _ in pairs] == list(range(101))  # every tick once, in order
    assert pairs[0][1] == pytest.approx((2.55, 0.0))
    assert pairs[40][1] == pytest.approx((6.55, 0.0))
    assert pairs[90][1] == pytest.approx((10.0, 0.0))  # near the end: the final pose


def test_goal_ahead_follows_a_corner() -> None:
    xs = [*(0.5 * k for k in range(5)), *([2.0] * 4)]
    ys = [*([0.0] * 5), *(0.5 * k for k in range(1, 5))]
    (first, goal), *_ = assign_goals(_matched(xs, ys), RunOptions(goal_ahead_m=3.0))
    assert first.tick.index == 0 and goal == pytest.approx((2.0, 1.0))


def test_fixed_goal_and_bounded_lookahead() -> None:
    ms = _matched([0.0] * 50, [0.0] * 50)  # standing still: the buffer must not grow past its bound
    pairs = list(assign_goals(ms, RunOptions(goal_ahead_m=5.0, max_lookahead_ticks=10)))
    assert len(pairs) == 50 and all(g == (0.0, 0.0) for _, g in pairs)
    pairs = list(assign_goals(ms, RunOptions(goal_xy=(3.0, -1.0))))
    assert all(g == (3.0, -1.0) for _, g in pairs)


def test_motion_agreement_known_answers() -> None:
    t = np.arange(0.0, 10.0, 0.1)
    poses = np.column_stack([0.3 * t, np.zeros_like(t), np.zeros_like(t)])  # straight at 0.3 m/s
    zero = np.zeros_like(t)
    agree = motion_agreement(t, poses, np.column_stack([np.full_like(t, 0.3), zero, zero]))
    assert agree["heading_err_median_deg"] == pytest.approx(0.0, abs=1e-9)
    assert agree["heading_within_30deg"] == 1.0
    assert agree["speed_mae_mps"] == pytest.approx(0.0, abs=1e-9)
    wrong = motion_agreement(t, poses, np.column_stack([np.full_like(t, 0.1), zero, np.full_like(t, 1.0)]))
    assert wrong["heading_err_median_deg"] == pytest.approx(math.degrees(1.0))
    assert wrong["speed_mae_mps"] == pytest.approx(0.2)


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("runs")
    cfg = PRESETS["wheelchair"]
    a = run_log(SAMPLE, cfg, base / "a", options=RunOptions(until_s=40.0)).out_dir
    b = run_log(SAMPLE, cfg, base / "b", options=RunOptions(until_s=40.0)).out_dir
    return a, b


def test_same_log_and_config_give_byte_identical_outputs(two_runs: tuple[Path, Path]) -> None:
    a, b = two_runs
    for name in DETERMINISTIC:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in two_runs)
    assert sa.pop("latency_ms") and sb.pop("latency_ms")
    assert sa.pop("over_budget").keys() == sb.pop("over_budget").keys()  # wall-clock: counts may differ
    sa.pop("log"), sb.pop("log")
    assert sa == sb


def test_one_command_per_scan(two_runs: tuple[Path, Path]) -> None:
    a, _ = two_runs
    t0 = next(iter(read_ticks(SAMPLE))).t_ns
    scans = sum(1 for tick in read_ticks(SAMPLE) if (tick.t_ns - t0) / 1e9 <= 40.0)
    with open(a / "commands.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == scans > 100
    assert all(math.isfinite(float(r[k])) for r in rows for k in ("v", "vy", "w"))
    tum = (a / "trajectory_corrected.tum").read_text().splitlines()
    assert len([line for line in tum if not line.startswith("#")]) == scans
    summary = json.loads((a / "summary.json").read_text())
    assert summary["ticks"] == scans == sum(summary["modes"].values()) == sum(summary["situations"].values())


def test_scan_matching_beats_raw_odometry_on_the_sample(two_runs: tuple[Path, Path]) -> None:
    """The sample log carries ground truth (TRUEPOS): the corrected trajectory must drift less.

    Compared frame-free: the pose of the last scan in the frame of the first, against the truth's.
    """
    a, _ = two_runs
    ticks = [t for t in read_ticks(SAMPLE) if t.truth is not None]
    truth = {t.t_ns: t.truth.as_array() for t in ticks if t.truth is not None}

    def drift(name: str) -> float:
        rows = [r.split() for r in (a / name).read_text().splitlines() if not r.startswith("#")]
        t = [round(float(r[0]) * 1e9) for r in rows]
        xyq = np.array([[float(r[1]), float(r[2]), 2 * math.atan2(float(r[6]), float(r[7]))] for r in rows])
        key = [min(truth, key=lambda k, ti=ti: abs(k - ti)) for ti in (t[0], t[-1])]
        est = relative(xyq[0], xyq[-1])
        ref = relative(truth[key[0]], truth[key[1]])
        return float(np.hypot(*(est[:2] - ref[:2])))

    odom, corrected = drift("trajectory_odom.tum"), drift("trajectory_corrected.tum")
    assert odom > 0.2  # the simulated wheel slip is there
    assert corrected < 0.5 * odom


def test_every_runs_the_stack_on_every_nth_scan(tmp_path: Path) -> None:
    options = RunOptions(until_s=10.0, every=3)
    out = run_log(SAMPLE, PRESETS["xr4000"], tmp_path / "r", options=options).out_dir
    n_scans = len((out / "trajectory_odom.tum").read_text().splitlines()) - 1
    n_cmds = len((out / "commands.csv").read_text().splitlines()) - 1
    assert n_cmds == math.ceil(n_scans / 3)


def test_bad_log_leaves_no_run_directory(tmp_path: Path) -> None:
    bad = tmp_path / "broken.clf"
    bad.write_bytes(SAMPLE.read_bytes()[:20])  # bz2 bytes under a plain-text name
    with pytest.raises(LogFormatError, match=r"broken\.clf"):
        run_log(bad, PRESETS["wheelchair"], tmp_path / "out" / "broken")
    assert not (tmp_path / "out" / "broken").exists()


def test_error_mid_log_leaves_no_half_written_run(tmp_path: Path) -> None:
    """A corrupt line found after 300 ticks were written (strict mode): the partial run is removed."""
    import bz2

    lines = bz2.decompress(SAMPLE.read_bytes()).decode().splitlines(keepends=True)
    flaser = [i for i, line in enumerate(lines) if line.startswith("FLASER")]
    k = flaser[300]
    lines[k] = lines[k][: len(lines[k]) // 2] + "\n"  # a truncated FLASER line in the middle
    log = tmp_path / "cut.clf"
    log.write_text("".join(lines))
    (tmp_path / "out").mkdir()
    with pytest.raises(LogFormatError, match=rf"cut.clf line {k + 1}"):
        run_log(log, PRESETS["wheelchair"], tmp_path / "out" / "cut", read=ReadOptions(strict=True))
    assert list((tmp_path / "out").iterdir()) == []
    # without --strict the line is skipped, counted and reported
    summary = run_log(log, PRESETS["wheelchair"], tmp_path / "out" / "cut", options=RunOptions(until_s=70.0))
    assert summary.data["read_report"]["malformed"] == 1


def test_cli_run_bad_inputs_exit_2_with_one_line(tmp_path: Path) -> None:
    runner = CliRunner()
    missing = runner.invoke(app, ["run", str(tmp_path / "nope.clf"), "--out", str(tmp_path / "o")])
    assert missing.exit_code == 2
    assert "nope.clf" in missing.stderr and "Traceback" not in missing.output
    assert len(missing.stderr.strip().splitlines()) == 1
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[robot]\nvmax = 1\n")
    bad_cfg = runner.invoke(app, ["run", str(SAMPLE), "--config", str(cfg), "--out", str(tmp_path / "o")])
    assert bad_cfg.exit_code == 2 and "bad.toml: unknown key 'robot.vmax'" in bad_cfg.stderr
    bad_goal = runner.invoke(app, ["run", str(SAMPLE), "--goal", "1;2"])
    assert bad_goal.exit_code == 2 and "expected X,Y" in bad_goal.output
    assert not (tmp_path / "o").exists()


def test_cli_goal_and_goal_ahead_exclude_each_other_and_presets_ignore_case(tmp_path: Path) -> None:
    runner = CliRunner()
    both = runner.invoke(app, ["run", str(SAMPLE), "--goal", "1,2", "--goal-ahead", "3", "--out",
                               str(tmp_path / "o")])
    assert both.exit_code == 2 and "--goal-ahead" in both.output and not (tmp_path / "o").exists()
    upper = runner.invoke(app, ["run", str(SAMPLE), "--preset", "XR4000", "--until", "1", "--no-figures",
                                "--json", "--out", str(tmp_path / "x")])
    assert upper.exit_code == 0, upper.output
    assert json.loads(upper.stdout)["config"]["preset"] == "xr4000"


def test_cli_run_writes_the_run_directory_and_json(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app, ["run", str(SAMPLE), "--until", "8", "--out", str(tmp_path / "r"), "--json", "--no-figures"]
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["ticks"] == len((tmp_path / "r" / "commands.csv").read_text().splitlines()) - 1
    assert {p.name for p in (tmp_path / "r").iterdir()} >= {*DETERMINISTIC, "summary.json", "timing.csv"}


# full runs: both buildings in CARMEN and ROS1 form (ACES CARMEN runs through the CLI with --mcap in
# test_report.py); the ROS2 forms (the same data as the ROS1 bag to 1e-6, as the reader tests assert) for
# their first minute, to keep the suite short
DEV_LOGS = [
    ("carmen/mit-csail.clf.bz2", 1988, None),
    ("rosbag1/mit-csail.sort.bag", 1988, None),
    ("rosbag2/mit-csail.sort.ros2_sqlite3", None, 60.0),
    ("rosbag2/mit-csail.sort.ros2_mcap/mit-csail.sort.ros2_mcap.mcap", None, 60.0),
    ("rosbag1/aces.sort.bag", 7374, None),
]


@pytest.mark.slow
@pytest.mark.parametrize(("rel", "scans", "until"), DEV_LOGS, ids=[r for r, _, _ in DEV_LOGS])
def test_every_dev_log_runs_with_one_command_per_scan(
    datasets: Path, tmp_path: Path, rel: str, scans: int | None, until: float | None
) -> None:
    options = RunOptions(until_s=until)
    summary = run_log(datasets / rel, PRESETS["wheelchair"], tmp_path / "run", options=options)
    if scans is None:
        t0 = next(iter(read_ticks(datasets / rel))).t_ns
        scans = sum(1 for t in read_ticks(datasets / rel) if (t.t_ns - t0) / 1e9 <= until)
    assert summary.ticks == scans
    rows = (summary.out_dir / "commands.csv").read_text().splitlines()
    assert len(rows) == scans + 1
    # the planner finds its way most of the time (the mode column also shows the reflexive loop's
    # overrides, so the planner's own flags are counted)
    failed = sum(1 for row in rows[1:] if "PLANNER_NO_PATH" in row or "GOAL_IN_OBSTACLE" in row)
    assert scans - failed > scans // 2


def test_motion_agreement_of_a_run_shorter_than_the_horizon() -> None:
    t = np.array([0.0, 0.2, 0.4])
    out = motion_agreement(t, np.zeros((3, 3)), np.zeros((3, 3)), horizon_s=1.0)
    assert out == {"horizon_s": 1.0, "ticks_compared": 0}


def test_matcher_warm_up_compiles_what_real_ticks_need() -> None:
    """After the warm-up, the matcher on ticks from the CARMEN reader (writable ranges, shared read-only
    beam angles) needs no new compiled variant: JIT time never shows up as match time (it was 170 ms on
    tick 1). Runs in a fresh interpreter: in this one, earlier tests have compiled every variant already."""
    import subprocess
    import sys

    code = f"""
from gndreplay.config import PRESETS
from gndreplay.io import read_ticks
from gndreplay.replay import matcher_factory
from gndreplay.scanmatch import _idc_kernels as k, warm_up_matcher

def signatures():
    return {{n: len(o.signatures) for n, o in vars(k).items() if hasattr(o, "signatures")}}

cfg = PRESETS["wheelchair"]
warm_up_matcher(matcher_factory(cfg))
before = signatures()
assert before["scan_points"] and before["match_scan"], before
m = matcher_factory(cfg)()
for tick, _ in zip(read_ticks({str(SAMPLE)!r}), range(5)):
    m.update(tick.scan, tick.odom)
after = signatures()
print("new variants:", {{n: after[n] - before[n] for n in after if after[n] != before[n]}})
raise SystemExit(0 if after == before else 1)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr


def test_cli_shows_a_python_warning_as_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    """A numpy RuntimeWarning reaching the CLI is one ``gndreplay: warning:`` line, no source line."""
    import warnings

    from gndreplay.cli import cli_errors

    @cli_errors
    def command() -> float:
        return float(np.mean(np.zeros(0)))

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert math.isnan(command())
    err = capsys.readouterr().err.splitlines()
    assert err and all(line.startswith("gndreplay: warning: RuntimeWarning: ") for line in err)


def test_run_progress_says_compiling_once_and_takes_its_total_from_the_log(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Off a terminal the warm-up says one compile notice (cold numba cache); style "none" (--progress none,
    --quiet, --json) silences it. The total is --until, or the log's duration when its format knows it."""
    from types import SimpleNamespace

    from gndreplay.cli import _LogProgress, _Progress

    with _Progress("plain") as shown:
        p = _LogProgress(shown, "log", until_s=None)
        p.on_stage("warm-up")
        p.on_compile("plan")
        p.on_compile("nd_step")
        p.on_open(SimpleNamespace(start_ns=0, end_ns=90 * 10**9, streams=(), scan_stream="x"))
        assert p.total == 90.0 and p.compiled == 2
    assert capsys.readouterr().err.splitlines() == ["gndreplay: compiling (first run only)..."]
    with _Progress("none") as shown:
        p = _LogProgress(shown, "log", until_s=30.0)
        p.on_compile("plan")
        p.on_open(SimpleNamespace(start_ns=0, end_ns=90 * 10**9, streams=(), scan_stream="x"))
        assert p.total == 30.0
    assert capsys.readouterr().err == ""


def test_carmen_progress_follows_the_share_of_the_file_read(tmp_path: Path) -> None:
    """A CARMEN log does not say its length: the bar follows the share of the file read (the compressed
    file for .gz/.bz2, in steps of their blocks), rising steadily to the end, with a total of 100 %."""
    import bz2

    from gndreplay.cli import _LogProgress, _Progress
    from gndreplay.io import open_log

    plain = tmp_path / "office.clf"
    plain.write_bytes(bz2.decompress(SAMPLE.read_bytes()))
    with open_log(plain) as reader:
        desc = reader.describe()
        assert desc.start_ns is None and desc.end_ns is None
        with _Progress("plain") as shown:
            p = _LogProgress(shown, "log", until_s=None)
            p.on_open(reader)
            assert (p.total, p.unit) == (100.0, "%")
        seen = [reader.fraction_read() for k, _ in enumerate(reader.ticks()) if k % 50 == 0]
    fractions = [f for f in seen if f is not None]
    assert len(fractions) == len(seen) > 10
    assert fractions == sorted(fractions) and fractions[0] < 0.2 and fractions[-1] > 0.95
    assert len(set(fractions)) >= len(fractions) - 1  # it moves with the pass, not in one jump
