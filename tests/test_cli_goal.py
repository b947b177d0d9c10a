"""A fixed goal the grid never held (farther than its half side from every pose of the corrected
trajectory, e.g. outside the log's whole extent) is a warning naming the goal and the distance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.pipeline.model import GridParams
from gndreplay.replay import far_goal_warning

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
ALONG_X = np.column_stack([np.linspace(0.0, 20.0, 201), np.zeros(201)])  # 0 to 20 m along x
GRID = GridParams()  # 400 cells of 5 cm: 10 m half side


def test_a_goal_within_the_grid_of_some_pose_is_quiet() -> None:
    assert far_goal_warning((5.0, 3.0), ALONG_X, GRID) is None
    assert far_goal_warning((30.0, 0.0), ALONG_X, GRID) is None  # exactly the half side beyond the end
    assert far_goal_warning((-3.0, -9.0), ALONG_X, GRID) is None


def test_a_goal_beyond_every_pose_names_itself_and_the_distance() -> None:
    line = far_goal_warning((40.0, 0.0), ALONG_X, GRID)
    assert line is not None and line.startswith("goal (40, 0) is 20.0 m from the nearest pose")
    assert "beyond the grid's half side (10 m)" in line
    assert far_goal_warning((10.0, 12.0), ALONG_X, GRID) is not None  # beside the path, off every grid


def test_the_reach_is_the_grid_of_the_configuration() -> None:
    small = GridParams(size_cells=100, cell_m=0.05)  # 2.5 m half side
    assert far_goal_warning((10.0, 3.0), ALONG_X, small) is not None
    assert far_goal_warning((10.0, 2.0), ALONG_X, small) is None


def test_no_trajectory_no_warning() -> None:
    assert far_goal_warning((1e6, 1e6), np.zeros((0, 2)), GRID) is None


def test_run_warns_about_a_goal_outside_the_log(tmp_path: Path) -> None:
    runner = CliRunner()
    base = ["run", str(SAMPLE), "--until", "5", "--no-figures", "-q"]
    far = runner.invoke(app, [*base, "--goal", "1000,1000", "--out", str(tmp_path / "far")])
    assert far.exit_code == 0, far.output
    warnings = [line for line in far.stderr.splitlines() if line.startswith("gndreplay: warning: ")]
    assert len(warnings) == 1 and "goal (1000, 1000) is 14" in warnings[0], far.stderr
    near = runner.invoke(app, [*base, "--goal", "2,0", "--out", str(tmp_path / "near")])
    assert near.exit_code == 0 and "warning" not in near.stderr, near.stderr
