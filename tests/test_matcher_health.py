"""The scan matcher's health and its warning (``evaluation.matcher_health``) on real matches: loud where the
IDC matcher hurts or fails (a laser that repeats its last scan while the robot drives on, a bare corridor),
quiet on the dev logs; in ``gndreplay scanmatch``, ``gndreplay run`` (summary.json, report.md, the console)
and the batch thresholds on the ground-truth errors."""

from __future__ import annotations

import bz2
import dataclasses
import itertools
import json
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import PRESETS
from gndreplay.evaluation import HealthParams
from gndreplay.io import open_log, read_ticks
from gndreplay.replay import RunOptions, run_replay
from gndreplay.robot import WHEELCHAIR_ROBOT
from gndreplay.scanmatch import IdcParams, MatcherReport, correct_trajectory, make_matcher, matcher_report
from gndreplay.sim.scenario import DriveParams, Scenario, iter_ticks, run_scenario
from gndreplay.sim.world import World, wall
from gndreplay.types import Pose2D, Tick

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
FROZEN = (10.0, 20.0)  # the stretch of the sample's first 40 s whose scans repeat the first one [s]
SLICE_S = 40.0  # the robot drives 1.5 m every 5 s from 5 s to 30 s, then turns at the corridor
LIMITS = HealthParams()


def _idc(ticks: list[Tick]) -> MatcherReport:
    return matcher_report(correct_trajectory(ticks, make_matcher("idc")))


def _elapsed(ticks: list[Tick], tick: Tick) -> float:
    return (tick.t_ns - ticks[0].t_ns) / 1e9


def first_seconds(log: Path, seconds: float) -> list[Tick]:
    """The ticks of ``log``'s first ``seconds``."""
    with open_log(log) as reader:
        stream = reader.ticks()
        first = next(stream)
        return [first, *itertools.takewhile(lambda t: t.t_ns - first.t_ns <= seconds * 1e9, stream)]


def sample_slice(*, frozen: bool, truth: bool) -> list[Tick]:
    """The sample's first ``SLICE_S`` seconds; ``frozen``: the scans of ``FROZEN`` replaced by the first of
    them (a laser driver that republishes its last scan); without ``truth``: its TRUEPOS dropped."""
    ticks = first_seconds(SAMPLE, SLICE_S)
    out, stale = [], None
    for t in ticks:
        if frozen and FROZEN[0] <= _elapsed(ticks, t) < FROZEN[1]:
            stale = stale or t.scan
            t = dataclasses.replace(t, scan=dataclasses.replace(stale, t_ns=t.t_ns))
        out.append(t if truth else dataclasses.replace(t, truth=None))
    return out


def write_frozen_log(path: Path, *, truth: bool) -> Path:
    """The sample's first ``SLICE_S`` seconds as a CARMEN log whose FLASER ranges over ``FROZEN`` repeat the
    first of them (without ``truth``: no TRUEPOS line)."""
    lines = bz2.decompress(SAMPLE.read_bytes()).decode().splitlines(keepends=True)
    out: list[str] = []
    t0: float | None = None
    stale: list[str] | None = None
    for line in lines:
        tok = line.split()
        if not tok or tok[0] in ("#", "PARAM"):
            out.append(line)
            continue
        t = float(tok[-3])
        t0 = t if t0 is None else t0
        if t - t0 > SLICE_S or (tok[0] == "TRUEPOS" and not truth):
            continue
        if tok[0] == "FLASER" and FROZEN[0] <= t - t0 < FROZEN[1]:
            n = int(tok[1])
            stale = stale or tok[2:2 + n]
            line = " ".join([*tok[:2], *stale, *tok[2 + n:]]) + "\n"
        out.append(line)
    path.write_text("".join(out))
    return path


# -- the bad cases ------------------------------------------------------------------------------------------


def test_a_laser_repeating_its_last_scan_makes_idc_hurt_and_the_warning_says_so() -> None:
    """10 s of one repeated scan while the robot drives 3 m: IDC matches each copy to the map and holds the
    pose while the odometry moves on (each step is well inside its odometry guard). Measured: the corrected
    trajectory's aligned ATE far above the odometry's; estimated (no truth): the 5 s window of that
    stretch is beyond the odometry error model."""
    measured = _idc(sample_slice(frozen=True, truth=True)).health
    assert measured is not None and measured.measured
    assert measured.ate_matcher_m > 3.0 * measured.ate_odom_m + LIMITS.worse_margin_m
    assert measured.warning is not None and "worse than the odometry" in measured.warning
    assert f"{measured.ate_matcher_m:.3f} m against {measured.ate_odom_m:.3f} m" in measured.warning
    assert "measured against the ground truth" in measured.warning

    estimated = _idc(sample_slice(frozen=True, truth=False)).health
    assert estimated is not None and not estimated.measured and math.isnan(estimated.ate_odom_m)
    assert estimated.warning is not None and "estimated: no ground truth" in estimated.warning
    assert "disagreed with the odometry" in estimated.warning and "failed" not in estimated.warning
    assert FROZEN[0] - 1.0 <= estimated.window_start_s <= FROZEN[1] - LIMITS.window_s + 1.0
    assert estimated.window_sigmas > LIMITS.max_sigmas
    assert estimated.window_trans_m > 1.0  # the robot drove 1.5 m in the window, the matcher stood
    assert estimated.failed_share < LIMITS.max_failed_share  # not a failing matcher: a wrong one


def test_the_same_slice_with_its_real_scans_is_quiet() -> None:
    for truth in (True, False):
        health = _idc(sample_slice(frozen=False, truth=truth)).health
        assert health is not None and health.warning is None, health
        assert health.measured == truth
        assert health.window_sigmas < 0.5 * LIMITS.max_sigmas
    measured = _idc(sample_slice(frozen=False, truth=True)).health
    assert measured is not None and measured.ate_matcher_m < measured.ate_odom_m


def corridor_ticks() -> list[Tick]:
    """A simulated run (the sample's wheelchair, laser, odometry errors) 20 m down a bare corridor 2 m wide
    and 65 m long: translation along it is unobservable to an 8 m laser."""
    world = World.from_parts(wall(-5.0, -1.0, 60.0, -1.0), wall(-5.0, 1.0, 60.0, 1.0), name="corridor")
    scenario = Scenario(name="corridor", description="a bare corridor", world=world,
                        route=(np.array([[0.0, 0.0], [20.0, 0.0]]),), start=Pose2D(0.0, 0.0, 0.0),
                        drive=DriveParams.for_robot(WHEELCHAIR_ROBOT))
    return list(iter_ticks(run_scenario(scenario, seed=0)))


def test_a_bare_corridor_fails_most_matches_and_the_warning_says_why() -> None:
    ticks = corridor_ticks()
    estimated = _idc([dataclasses.replace(t, truth=None) for t in ticks]).health
    assert estimated is not None and estimated.failed_share > LIMITS.max_failed_share
    assert max(estimated.reasons, key=lambda k: estimated.reasons[k]) == "degenerate geometry"
    assert estimated.warning is not None and "estimated: no ground truth" in estimated.warning
    assert f"{estimated.failed} of {len(ticks)} matches failed" in estimated.warning
    assert "degenerate geometry" in estimated.warning
    assert estimated.longest_s > 5.0 and estimated.longest_scans >= 25
    # with its truth the verdict is measured, and says exactly whether the matcher did worse than odometry
    measured = _idc(ticks).health
    assert measured is not None and measured.measured
    worse = measured.ate_matcher_m - measured.ate_odom_m > max(
        LIMITS.worse_margin_m, LIMITS.worse_margin_rel * measured.ate_odom_m)
    assert (measured.warning is not None) == worse
    assert measured.warning is None or "failed" not in measured.warning  # the measurement decides alone


# -- quiet on the dev logs ----------------------------------------------------------------------------------


def test_quiet_on_mit_csail(datasets: Path) -> None:
    health = _idc(list(read_ticks(datasets / "carmen" / "mit-csail.clf.bz2"))).health
    assert health is not None and health.warning is None, health
    assert health.failed_share < 0.01 and health.window_sigmas < 0.75 * LIMITS.max_sigmas


def test_quiet_on_the_first_400_s_of_aces(datasets: Path) -> None:
    health = _idc(first_seconds(datasets / "carmen" / "aces.clf.bz2", 400.0)).health
    assert health is not None and health.warning is None, health
    assert health.failed == 0 and health.window_sigmas < 0.5 * LIMITS.max_sigmas


def test_quiet_on_the_whole_sample_measured_and_estimated() -> None:
    ticks = list(read_ticks(SAMPLE))
    for with_truth in (True, False):
        health = _idc(ticks if with_truth else [dataclasses.replace(t, truth=None) for t in ticks]).health
        assert health is not None and health.warning is None and health.measured == with_truth


def test_the_model_is_the_matchers_own() -> None:
    """The defaults of the odometry error model are the IDC matcher's; a configured one is followed."""
    assert HealthParams.from_odometry(IdcParams()) == HealthParams()
    wide = HealthParams.from_odometry(IdcParams(odo_sigma_m=0.5))
    assert wide.sigma_m == 0.5 and wide.sigma_rel == HealthParams().sigma_rel


# -- the commands -------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def frozen_logs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path]]:
    base = tmp_path_factory.mktemp("frozen")
    yield write_frozen_log(base / "frozen.clf", truth=True), write_frozen_log(base / "frozen-notruth.clf",
                                                                               truth=False)


def test_scanmatch_prints_the_truth_columns_the_health_and_the_warning(
        frozen_logs: tuple[Path, Path], tmp_path: Path) -> None:
    with_truth, without = frozen_logs
    runner = CliRunner()
    table = runner.invoke(app, ["scanmatch", str(with_truth), "--matcher", "all", "--out",
                                str(tmp_path / "t"), "--progress", "none"])
    assert table.exit_code == 0, table.output
    for col in ("ATE RMSE (m)", "ATE max", "RPE (m)", "RPE (deg)", "scan matcher health", "verdict"):
        assert col in table.stdout, col
    warnings = [x for x in table.stderr.splitlines() if x.startswith("gndreplay: warning: scan matcher")]
    # both scan matchers follow the repeated scan; the odometry does not warn about itself
    assert [w.split()[4] for w in warnings] == ["idc", "kiss-icp"], warnings
    assert all("made the trajectory worse than the odometry" in w for w in warnings)
    data = runner.invoke(app, ["scanmatch", str(with_truth), "--out", str(tmp_path / "j"), "--json"])
    rows = {r["method"]: r for r in json.loads(data.stdout)}
    assert rows["odom"]["health"]["warning"] is None and rows["odom"]["health"]["failed"] == 0
    assert rows["idc"]["truth"]["ate_rmse_m"] == pytest.approx(rows["idc"]["health"]["ate_matcher_m"])
    assert rows["idc"]["truth"]["ate_rmse_m"] > 3.0 * rows["odom"]["truth"]["ate_rmse_m"]
    assert rows["idc"]["health"]["verdict"] == "measured"
    blind = runner.invoke(app, ["scanmatch", str(without), "--matcher", "idc", "--out", str(tmp_path / "b"),
                                "--progress", "none"])
    assert blind.exit_code == 0 and "ATE RMSE" not in blind.stdout
    assert "scan matcher idc likely hurts: its motion disagreed with the odometry" in blind.stderr


def test_run_writes_the_health_and_warns(frozen_logs: tuple[Path, Path], tmp_path: Path) -> None:
    with_truth, _ = frozen_logs
    result = CliRunner().invoke(app, ["run", str(with_truth), "--out", str(tmp_path / "run"), "--quiet"])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    health = summary["matcher_health"]
    assert health["verdict"] == "measured" and health["scans"] == summary["truth"]["poses"]
    assert health["ate_matcher_m"] == pytest.approx(summary["truth"]["corrected"]["aligned"]["ate_rmse_m"])
    assert health["ate_odom_m"] == pytest.approx(summary["truth"]["odom"]["aligned"]["ate_rmse_m"])
    assert f"gndreplay: warning: {health['warning']}" in result.stderr
    report = (tmp_path / "run" / "report.md").read_text()
    assert f"> **Warning:** {health['warning']}" in report
    assert "| failed matches, every scan |" in report and "](fig_error.png)" in report
    assert (tmp_path / "run" / "fig_error.png").is_file()


def test_a_quiet_run_and_every_scan_counted(tmp_path: Path) -> None:
    """The sample's first 40 s replayed with the stack on every 3rd scan: no warning, the health counts every
    scan (the MATCH_FAILED flags only the stack's ticks), the report says so."""
    ticks = sample_slice(frozen=False, truth=True)
    run = run_replay(iter(ticks), PRESETS["wheelchair"], tmp_path / "quiet", log=SAMPLE,
                     options=RunOptions(every=3))
    health = run.data["matcher_health"]
    assert health["warning"] is None and health["scans"] == len(ticks)
    assert run.ticks == math.ceil(len(ticks) / 3)
    assert health["matcher"] == "idc" and health["verdict"] == "measured"
    assert health["failed"] == sum(health["reasons"].values())
