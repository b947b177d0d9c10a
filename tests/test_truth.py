"""Ground truth in the run directory: trajectory_truth.tum, summary.json's truth section, report.md's table
and fig_model's truth line, on the sample log (CARMEN TRUEPOS) and the same log with its truth removed."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from gndreplay.config import PRESETS
from gndreplay.evaluation import read_tum, trajectory_errors
from gndreplay.io import open_log
from gndreplay.replay import RunOptions, run_log, run_replay
from gndreplay.report import load_run
from gndreplay.report.figures import (
    build_figures,
    figure_error,
    figure_model,
    figure_names,
    truth_errors,
    truth_on_corrected,
)
from gndreplay.report.markdown import render_report
from gndreplay.report.rundir import (
    CORRECTED_TRAJECTORY_FILE,
    ODOM_TRAJECTORY_FILE,
    TRUTH_TRAJECTORY_FILE,
    TrajectoryWriter,
    window_run,
)
from gndreplay.report.summary import truth_section
from gndreplay.types import Pose2D

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
SHORT = RunOptions(until_s=8.0)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path]]:
    """The first 8 s of the sample, with and without its TRUEPOS."""
    base = tmp_path_factory.mktemp("truth")
    cfg = PRESETS["wheelchair"]
    with_truth = run_log(SAMPLE, cfg, base / "with", options=SHORT).out_dir
    with open_log(SAMPLE) as reader:
        ticks = (dataclasses.replace(t, truth=None) for t in reader.ticks())
        without = run_replay(ticks, cfg, base / "without", log=SAMPLE, options=SHORT).out_dir
    yield with_truth, without


def test_truth_file_holds_the_logs_truepos(runs: tuple[Path, Path]) -> None:
    run, _ = runs
    t_ns, truth = read_tum(run / TRUTH_TRAJECTORY_FILE)
    t_corr, _ = read_tum(run / CORRECTED_TRAJECTORY_FILE)
    assert t_ns.size == t_corr.size > 30 and np.array_equal(t_ns, t_corr)  # a truth pose at every scan
    with open_log(SAMPLE) as reader:
        first = next(iter(reader.ticks()))
    assert first.truth is not None
    np.testing.assert_allclose(truth[0], first.truth.as_array(), atol=1e-12)


def test_summary_truth_section_scores_both_trajectories(runs: tuple[Path, Path]) -> None:
    run, _ = runs
    data = load_run(run)
    truth = data.summary["truth"]
    assert truth["poses"] == data.traj_truth.shape[0]
    t_ref, ref = read_tum(run / TRUTH_TRAJECTORY_FILE)
    for name, file in (("odom", ODOM_TRAJECTORY_FILE), ("corrected", CORRECTED_TRAJECTORY_FILE)):
        t, poses = read_tum(run / file)
        for label, how in (("aligned", "se2"), ("unaligned", "origin")):
            want = trajectory_errors(t, poses, t_ref, ref, alignment=how)
            got = truth[name][label]
            assert got["matched"] == t.size and got["unmatched"] == 0
            assert got["ate_rmse_m"] == pytest.approx(want.ate_rmse_m, rel=1e-9, abs=1e-12)
            assert got["rpe_pairs"] > 0
        assert truth[name]["aligned"]["ate_rmse_m"] <= truth[name]["unaligned"]["ate_rmse_m"] + 1e-12
    text = render_report(data, figures=())
    assert "## Ground truth" in text
    ate = truth["corrected"]["aligned"]["ate_rmse_m"]
    assert f"| corrected | aligned | {t_ref.size} | {ate:.3f} |" in text


def test_no_truth_no_file_and_null_section(runs: tuple[Path, Path]) -> None:
    with_truth, run = runs
    assert not (run / TRUTH_TRAJECTORY_FILE).exists()
    for f in (ODOM_TRAJECTORY_FILE, CORRECTED_TRAJECTORY_FILE, "commands.csv"):  # the truth changes nothing
        assert (run / f).read_bytes() == (with_truth / f).read_bytes()
    data = load_run(run)
    assert data.traj_truth is None and data.summary["truth"] is None
    assert "Ground truth" not in render_report(data, figures=())
    assert truth_on_corrected(data) is None


def test_fig_model_draws_the_truth_on_the_corrected_start(runs: tuple[Path, Path]) -> None:
    run, _ = runs
    data = load_run(run)
    truth = truth_on_corrected(data)
    assert truth is not None
    np.testing.assert_allclose(truth[0, 1:], data.traj_corrected[0, 1:], atol=1e-9)
    fig = figure_model(data)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert "ground truth" in labels
    part = window_run(data, 2.0, 5.0)
    assert part.traj_truth is not None and 0 < part.traj_truth.shape[0] < data.traj_truth.shape[0]


def test_fig_error_draws_both_aligned_errors_and_the_failed_matches(runs: tuple[Path, Path],
                                                                   tmp_path: Path) -> None:
    run, without = runs
    data = load_run(run)
    errors = truth_errors(data)
    assert errors is not None and set(errors) == {"odometry", "corrected"}
    truth = data.summary["truth"]
    for name, key in (("odometry", "odom"), ("corrected", "corrected")):
        assert errors[name].ate_rmse_m == pytest.approx(truth[key]["aligned"]["ate_rmse_m"], rel=1e-9)
        assert errors[name].matched == data.traj_truth.shape[0]
    fig = figure_error(data)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    c = errors["corrected"]
    assert f"corrected (RMSE {c.ate_rmse_m:.3f} m, max {c.ate_max_m:.3f} m)" in labels
    assert any(x.startswith("raw odometry (RMSE") for x in labels)
    failed = data.summary["flags"]["MATCH_FAILED"]
    assert f"{failed} of {len(data.commands)} ticks MATCH_FAILED" in fig.axes[0].get_title()
    assert [p.name for p in build_figures(data, tmp_path)] == list(figure_names(None, truth=True))
    assert (tmp_path / "fig_error.png").is_file()
    blind = load_run(without)
    assert truth_errors(blind) is None and "fig_error.png" not in figure_names(None, truth=False)


def test_trajectory_writer_truth_only_where_given() -> None:
    w = TrajectoryWriter()
    p = Pose2D(1.0, 2.0, 0.5)
    w.add(10, p, p)
    w.add(20, p, p, Pose2D(3.0, 4.0, -0.5))
    arrays = w.arrays()
    t, truth = arrays[TRUTH_TRAJECTORY_FILE]
    assert t.tolist() == [20] and truth.tolist() == [[3.0, 4.0, -0.5]]
    assert arrays[ODOM_TRAJECTORY_FILE][0].tolist() == [10, 20]
    section = truth_section(arrays)
    assert section is not None and section["poses"] == 1
    assert section["odom"]["unaligned"]["ate_max_m"] == pytest.approx(0.0, abs=1e-12)
    assert math.isnan(section["odom"]["aligned"]["rpe_trans_rmse_m"])  # one pose: no 1 s pair
    empty = TrajectoryWriter()
    empty.add(10, p, p)
    assert TRUTH_TRAJECTORY_FILE not in empty.arrays() and truth_section(empty.arrays()) is None


def test_closed_loop_run_writes_the_world_pose_as_truth(tmp_path: Path) -> None:
    from gndreplay.sim.runner import simulate_scenario

    out = simulate_scenario("u_trap", out_dir=tmp_path / "run", seed=0, time_limit_s=2.0, figures=False)
    t_ns, truth = read_tum(out.out_dir / TRUTH_TRAJECTORY_FILE)
    t_odom, _ = read_tum(out.out_dir / ODOM_TRAJECTORY_FILE)
    assert np.array_equal(t_ns, t_odom) and t_ns.size > 5
    summary = load_run(out.out_dir).summary
    section = summary["truth"]
    assert section["poses"] == truth.shape[0] and section["corrected"]["aligned"]["matched"] == t_ns.size
    assert section["odom"]["unaligned"]["ate_max_m"] < 0.1  # 2 s of simulated odometry drift
    health = summary["matcher_health"]  # the closed loop's matcher, measured against the world pose
    assert health["verdict"] == "measured" and health["scans"] == t_ns.size and health["warning"] is None
