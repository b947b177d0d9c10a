"""The challenge score (optimal path on the true world, the navigation-challenge metric) with known answers,
its batch columns, and the random obstacle fields of ``gndreplay scenario generate``."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gndreplay.batch import aggregate_scenarios, metrics_from_result
from gndreplay.batch.report import scenarios_csv, summary_csv, summary_md
from gndreplay.batch.worker import InputResult
from gndreplay.cli import app
from gndreplay.config import preset
from gndreplay.sim.closedloop import static_shapes
from gndreplay.sim.fields import GOAL_AHEAD_M, draw_field, generate_fields
from gndreplay.sim.geometry import Shapes, wall_vertices
from gndreplay.sim.scenario_file import load_scenario, parse_scenario
from gndreplay.sim.score import (
    CELL_M,
    PASSAGE_MAX_M,
    challenge_metric,
    narrowest_passage_m,
    optimal_path,
    optimal_time_s,
)

runner = CliRunner()


def walls(*segments: tuple[float, float, float, float]) -> Shapes:
    polys = [wall_vertices(*s, 0.0) for s in segments]
    return Shapes.build(polys, list(range(len(polys))), [], [])


def test_an_empty_corridor_is_the_straight_line_whatever_its_direction() -> None:
    corridor = walls((-1.0, 1.0, 11.0, 1.0), (-1.0, -1.0, 11.0, -1.0))
    along = optimal_path(corridor, (0.0, 0.0), (10.0, 0.0), 0.3)
    assert along.length_m == pytest.approx(10.0, abs=1e-9)
    slanted = optimal_path(walls(), (0.0, 0.0), (7.0, 3.0), 0.3)  # nothing in the way, any angle
    assert slanted.length_m == pytest.approx(math.hypot(7.0, 3.0), abs=CELL_M)
    assert np.allclose(slanted.waypoints[[0, -1]], [[0.0, 0.0], [7.0, 3.0]])


def detour(start: np.ndarray, goal: np.ndarray, corner: np.ndarray, r: float) -> float:
    """Shortest path from start to goal round a disc of radius r at ``corner`` (passing above it): the two
    tangents and the arc between them."""
    ds, dg = np.hypot(*(start - corner)), np.hypot(*(goal - corner))
    a_s = math.atan2(*(start - corner)[::-1])
    a_g = math.atan2(*(goal - corner)[::-1])
    swept = (a_s - a_g) % (2 * math.pi)  # from the goal's direction counter-clockwise to the start's
    arc = swept - math.acos(r / ds) - math.acos(r / dg)
    return math.sqrt(ds * ds - r * r) + math.sqrt(dg * dg - r * r) + r * arc


def test_a_wall_with_a_gap_costs_the_analytic_detour_within_the_grid_error() -> None:
    # a thin wall across x = 5, open for 2 < y < 4: the disc passes the gap's lower corner (5, 2)
    r = 0.3
    world = walls((5.0, -10.0, 5.0, 2.0), (5.0, 4.0, 5.0, 10.0))
    best = optimal_path(world, (0.0, 0.0), (10.0, 0.0), r)
    expected = detour(np.array([0.0, 0.0]), np.array([10.0, 0.0]), np.array([5.0, 2.0]), r)
    assert expected > 2 * math.hypot(5.0, 2.0)  # the arc round the corner counts
    assert best.length_m == pytest.approx(expected, abs=3 * CELL_M)
    # the wall without its gap: round its end (the world is open); inside a closed room: no path
    shut = walls((5.0, -10.0, 5.0, 10.0))
    round_end = optimal_path(shut, (0.0, 0.0), (10.0, 0.0), r).length_m
    # round the lower end (5, -10): the mirror image of passing above a corner at (5, 10); the grid's error
    # grows with the angle turned round the corner (the arc drawn by cell centres)
    expected = detour(np.array([0.0, 0.0]), np.array([10.0, 0.0]), np.array([5.0, 10.0]), r)
    assert round_end == pytest.approx(expected, abs=4 * CELL_M)
    frame = [(-1.0, -10.0, 11.0, -10.0), (-1.0, 10.0, 11.0, 10.0), (-1.0, -10.0, -1.0, 10.0),
             (11.0, -10.0, 11.0, 10.0)]
    assert optimal_path(walls((5.0, -10.0, 5.0, 10.0), *frame), (0.0, 0.0), (10.0, 0.0), r).length_m is None
    gap_room = walls((5.0, -10.0, 5.0, 2.0), (5.0, 4.0, 5.0, 10.0), *frame)
    in_room = optimal_path(gap_room, (0.0, 0.0), (10.0, 0.0), r).length_m
    assert in_room == pytest.approx(best.length_m, abs=CELL_M)
    assert optimal_path(gap_room, (0.0, 0.0), (10.0, 0.0), 1.05).length_m is None  # too wide for the gap


@pytest.mark.parametrize("gap", [0.5, 0.62, 0.8, 1.13])
def test_the_narrowest_passage_is_the_gap_within_a_cell(gap: float) -> None:
    """A closed room split by a wall with a gap of ``gap`` (the only way) and a wider way round it that a
    second wall closes: the narrowest passage is the gap, to the grid's cell; opened, the way round wins."""
    frame = [(-1.0, -3.0, 11.0, -3.0), (-1.0, 3.0, 11.0, 3.0), (-1.0, -3.0, -1.0, 3.0),
             (11.0, -3.0, 11.0, 3.0)]
    wall = [(5.0, -3.0, 5.0, 1.0), (5.0, 1.0 + gap, 5.0, 3.0)]
    w = narrowest_passage_m(walls(*wall, *frame), (0.0, 0.0), (10.0, 0.0))
    assert w == pytest.approx(gap, abs=1.5 * CELL_M)
    # a second way, 2 m wide, through the wall's lower part: the widest way's narrowest passage is 2 m
    wide = [(5.0, -3.0, 5.0, -2.5), (5.0, -0.5, 5.0, 1.0), (5.0, 1.0 + gap, 5.0, 3.0)]
    assert narrowest_passage_m(walls(*wide, *frame), (0.0, 0.0), (10.0, 0.0)) == pytest.approx(
        2.0, abs=1.5 * CELL_M)
    shut = [(5.0, -3.0, 5.0, 3.0)]
    assert narrowest_passage_m(walls(*shut, *frame), (0.0, 0.0), (10.0, 0.0)) is None
    assert narrowest_passage_m(walls(), (0.0, 0.0), (10.0, 0.0)) == PASSAGE_MAX_M  # open ground


def test_result_json_warns_when_the_robot_does_not_fit_the_way(tmp_path: Path) -> None:
    from gndreplay.config import CliOverrides, configure
    from gndreplay.sim import simulate_scenario

    doc = {"name": "slot", "start": [0.0, 0.0, 0.0], "goal": [6.0, 0.0], "time_limit": 0.5,
           "world": {"walls": {"s": [-1.0, -2.0, 7.0, -2.0], "n": [-1.0, 2.0, 7.0, 2.0],
                               "w": [-1.0, -2.0, -1.0, 2.0], "e": [7.0, -2.0, 7.0, 2.0],
                               "lo": [3.0, -2.0, 3.0, -0.36], "hi": [3.0, 0.36, 3.0, 2.0]}}}
    spec = parse_scenario(doc, "slot.yaml")
    fits = simulate_scenario(spec, out_dir=tmp_path / "xr", figures=False,
                             cfg=configure(preset_name="xr4000", overrides=CliOverrides()))
    tight = simulate_scenario(spec, out_dir=tmp_path / "chair", figures=False,
                              cfg=configure(preset_name="wheelchair", overrides=CliOverrides()))
    assert fits.narrowest_passage_m == pytest.approx(0.72, abs=1.5 * CELL_M) and fits.passage_warning is None
    assert tight.passage_warning is not None and "0.70 m wide" in tight.passage_warning
    res = json.loads((tmp_path / "chair" / "result.json").read_text())
    assert res["passage_warning"] == tight.passage_warning and res["narrowest_passage_m"] == pytest.approx(
        tight.narrowest_passage_m)
    cli = runner.invoke(app, ["simulate", str(_write(tmp_path / "slot.yaml", doc)), "--no-figures", "--out",
                              str(tmp_path / "cli")])
    assert "narrowest passage" in cli.stdout and "warning:" in cli.stderr and "needs 0.74 m" in cli.stderr


def _write(path: Path, doc: dict[str, object]) -> Path:
    import yaml

    path.write_text(yaml.safe_dump(doc))
    return path


def test_the_challenge_metric_edge_cases() -> None:
    ot = optimal_time_s(10.0)
    assert ot == 5.0
    assert challenge_metric(False, 12.0, ot) == 0.0  # a failure
    assert challenge_metric(True, None, ot) == 0.0
    assert challenge_metric(True, 4.0, ot) == 0.5  # faster than 2 OT: clipped, the best score
    assert challenge_metric(True, 20.0, ot) == pytest.approx(0.25)  # between the clips: OT / T
    assert challenge_metric(True, 400.0, ot) == 0.125  # slower than 8 OT: clipped, 1/8


def test_result_json_carries_the_score_of_the_run(tmp_path: Path) -> None:
    from gndreplay.sim import simulate_scenario

    out = simulate_scenario("gnd_fig2_person_crossing", out_dir=tmp_path / "r", seed=0, time_limit_s=1.0,
                            figures=False)
    res = json.loads((out.out_dir / "result.json").read_text())
    assert res["ideal_dynamics"] is False
    assert res["optimal_path_m"] >= math.hypot(res["goal"][0] - res["start"][0],
                                               res["goal"][1] - res["start"][1]) - 1e-9
    assert res["optimal_time_s"] == res["optimal_path_m"] / 2.0
    assert res["outcome"] == "timeout" and res["challenge_metric"] == 0.0


def row(name: str, seed: int, outcome: str, metric: float | None) -> InputResult:
    result = {"outcome": outcome, "end_time_s": 30.0,
              "time_to_goal_s": 30.0 if outcome == "success" else None, "path_length_m": 12.0,
              "optimal_path_m": None if metric is None else 10.0, "challenge_metric": metric}
    return InputResult(f"{name}-s{seed}", f"/s/{name}.yaml", "pass", metrics=metrics_from_result(result, {}),
                       group=name, seed=seed, outcome=outcome)


def test_batch_rows_and_aggregates_carry_the_challenge_metric() -> None:
    rows = [row("field", 0, "success", 0.25), row("field", 1, "collision", 0.0),
            row("shut", 0, "timeout", None)]
    assert rows[0].metrics["challenge_metric"] == 0.25 and rows[0].metrics["optimal_path_m"] == 10.0
    assert "challenge_metric" not in rows[2].metrics  # no optimal path: no metric
    field, shut = aggregate_scenarios(rows)
    assert field.metrics["mean_challenge_metric"] == 0.125  # the collision counts 0
    assert "mean_challenge_metric" not in shut.metrics
    summary = list(csv.DictReader(summary_csv(rows).splitlines()))
    assert [(r["optimal_path_m"], r["challenge_metric"]) for r in summary] == [
        ("10.0000", "0.2500"), ("10.0000", "0.0000"), ("", "")]
    per = list(csv.DictReader(scenarios_csv([field, shut]).splitlines()))
    assert [r["mean_challenge_metric"] for r in per] == ["0.1250", ""]
    md = summary_md(rows, [field, shut])
    assert "| optimal m | challenge |" in md and "| 0.1250 |" in md


# ---------------------------------------------------------------- obstacle fields


def test_fields_are_deterministic_per_seed_and_passable(tmp_path: Path) -> None:
    robot = preset("xr4000").robot
    a = draw_field(5, 0, robot)
    assert np.array_equal(a.occupied, draw_field(5, 0, robot).occupied)
    assert not np.array_equal(a.occupied, draw_field(6, 0, robot).occupied)
    _, files = generate_fields(tmp_path / "f", count=2, seed=5, robot=robot, preset_name="xr4000")
    _, files2 = generate_fields(tmp_path / "g", count=3, seed=5, robot=robot, preset_name="xr4000")
    assert [f.read_bytes() for f in files] == [f.read_bytes() for f in files2[:2]]  # whatever the count
    for f in files:
        spec = load_scenario(f)
        assert spec.goal == (GOAL_AHEAD_M, 0.0) and all(e.kind in ("wall", "circle") for e in spec.elements)
        shapes = static_shapes(spec.elements, 0.0, np.zeros(len(spec.elements)))
        best = optimal_path(shapes, spec.start[:2], spec.goal, robot.inscribed_radius_m)
        assert best.length_m is not None and best.length_m >= GOAL_AHEAD_M
        # its cylinders really are in the robot's way somewhere: a circle twice as wide does not pass
        assert optimal_path(shapes, spec.start[:2], spec.goal, 2 * robot.inscribed_radius_m + 0.3).length_m \
            is None


def test_scenario_generate_writes_files_simulate_reads_and_refuses_a_foreign_folder(tmp_path: Path) -> None:
    res = runner.invoke(app, ["scenario", "generate", str(tmp_path / "fields"), "-n", "1", "--seed", "2",
                              "--preset", "xr4000"])
    assert res.exit_code == 0, res.output
    field = tmp_path / "fields" / "field_000.yaml"
    sim = runner.invoke(app, ["simulate", str(field), "--time-limit", "1", "--no-figures", "--json",
                              "--out", str(tmp_path / "run")])
    assert sim.exit_code in (0, 1), sim.output  # it ran (a 1 s run times out)
    assert json.loads(sim.stdout.splitlines()[-1])["scenario"] == "field_2_000"
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    res = runner.invoke(app, ["scenario", "generate", str(mine), "-n", "1"])
    assert res.exit_code == 2 and "not written by gndreplay" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and (mine / "notes.txt").read_text() == "keep"
