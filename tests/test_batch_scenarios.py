"""gndreplay batch with closed-loop scenarios: seeds, scenario inputs beside logs, the scores of a run,
thresholds on runs and on a scenario over its seeds, the reports, and real closed-loop runs in workers."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from gndreplay.batch import (
    DEFAULT_LIMITS,
    InputResult,
    Job,
    SimOptions,
    Task,
    Thresholds,
    aggregate_scenarios,
    execute,
    expand_inputs,
    junit_xml,
    load_thresholds,
    make_tasks,
    metrics_from_result,
    parse_seeds,
    run_batch,
    scenarios_csv,
    summary_md,
)
from gndreplay.batch.metrics import outcome_note
from gndreplay.config import CliOverrides
from gndreplay.errors import ConfigError
from gndreplay.sim.runner import parse_latency

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_LOG = ROOT / "sample_logs" / "office.clf.bz2"
SHIPPED = ROOT / "gndreplay" / "sim" / "scenarios"

#: A small xr4000 world: a 6 x 4 m room, the goal 3 m ahead (the runs here end on a short time limit).
ROOM_XR4000 = """\
name: room
preset: xr4000
start: [1.0, 2.0, 0.0]
goal: [4.0, 2.0]
time_limit: 30
world:
  walls:
    south: [0, 0, 6, 0]
    north: [0, 4, 6, 4]
    west: [0, 0, 0, 4]
    east: [6, 0, 6, 4]
"""


def write(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return p


# ---------------------------------------------------------------- seeds and inputs


def test_parse_seeds_ranges_lists_and_mixes_in_the_order_given() -> None:
    assert parse_seeds("1-20") == tuple(range(1, 21))
    assert parse_seeds("1,3,5") == (1, 3, 5)
    assert parse_seeds(" 7 , 0-2,10") == (7, 0, 1, 2, 10)
    assert parse_seeds("4-4") == (4,)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"seeds: '' in '' is not a seed or a range \(expected non-negative integers like 1-20"),
        ("a", r"seeds: 'a' in 'a' is not a seed or a range"),
        ("-1", r"seeds: '-1' in '-1' is not a seed"),
        ("1,,2", r"seeds: '' in '1,,2' is not a seed"),
        ("1.5", r"seeds: '1.5' in '1.5' is not a seed"),
        ("1-2-3", r"seeds: '1-2-3' in '1-2-3' is not a seed"),
        ("5-1", r"seeds: range '5-1' in '5-1' goes down \(write 1-5\)"),
        ("1-3,2", r"seeds: '1-3,2' gives seed 2 more than once"),
        ("0-10000", r"seeds: '0-10000' gives more than 10000 seeds"),
    ],
)
def test_parse_seeds_errors_name_the_part_and_the_form_expected(text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_seeds(text)


def test_scenarios_expand_to_one_job_per_seed_after_the_inputs_given(tmp_path: Path) -> None:
    log = write(tmp_path, "run.clf", "")
    room = write(tmp_path, "worlds/room.yaml", ROOM_XR4000)
    jobs = expand_inputs([log, room], scenarios=["u_trap,enclosed"], seeds=(3, 1))
    assert [(j.name, j.kind, j.group, j.seed, j.scenario) for j in jobs] == [
        ("run", "log", "", 0, ""),
        ("room-s3", "scenario", "room", 3, ""),
        ("room-s1", "scenario", "room", 1, ""),
        ("u_trap-s3", "scenario", "u_trap", 3, "u_trap"),
        ("u_trap-s1", "scenario", "u_trap", 1, "u_trap"),
        ("enclosed-s3", "scenario", "enclosed", 3, "enclosed"),
        ("enclosed-s1", "scenario", "enclosed", 1, "enclosed"),
    ]
    assert jobs[1].path == room and jobs[3].path.resolve() == (SHIPPED / "u_trap.yaml").resolve()
    # default seed 0; 'all' is every shipped scenario once, in name order, even when named again
    every = expand_inputs([], scenarios=["all", "u_trap"])
    assert [j.name for j in every] == [f"{p.stem}-s0" for p in sorted(SHIPPED.glob("*.yaml"))]


def test_scenario_names_are_unique_beside_a_shipped_one_of_the_same_name_and_logs(tmp_path: Path) -> None:
    mine = write(tmp_path, "mine/u_trap.yaml", ROOM_XR4000)
    clash = write(tmp_path, "u_trap-s1.clf", "")  # a log named like a scenario run
    jobs = expand_inputs([mine, clash], scenarios=["u_trap"], seeds=(1,))
    assert [(j.name, j.group) for j in jobs] == [
        ("mine-u_trap-s1", "mine-u_trap"),
        ("u_trap-s1", ""),
        ("scenarios-u_trap-s1", "scenarios-u_trap"),
    ]


def test_a_bad_or_missing_scenario_file_is_one_job_not_one_per_seed(tmp_path: Path) -> None:
    bad = write(tmp_path, "bad.yaml", ROOM_XR4000.replace("time_limit: 30", "time_limit: -1"))
    jobs = expand_inputs([bad, tmp_path / "missing.yml"], scenarios=["enclosed"], seeds=parse_seeds("1-3"))
    assert [(j.name, j.group, j.seed) for j in jobs] == [
        ("bad", "bad", 1),
        ("missing", "missing", 1),
        ("enclosed-s1", "enclosed", 1),
        ("enclosed-s2", "enclosed", 2),
        ("enclosed-s3", "enclosed", 3),
    ]


def test_scenario_input_errors(tmp_path: Path) -> None:
    log = write(tmp_path, "run.clf", "")
    with pytest.raises(ConfigError, match=r"no shipped scenario 'u_trapp' \(did you mean 'u_trap'\?\); "
                                          r"shipped: all, corridor_junction, "):
        expand_inputs([], scenarios=["u_trapp"])
    with pytest.raises(ConfigError, match="scenarios: no scenario named"):
        expand_inputs([log], scenarios=[" , "])
    with pytest.raises(ConfigError, match="seeds apply to scenarios, and no scenario file or shipped"):
        expand_inputs([log], seeds=(1, 2))
    with pytest.raises(ConfigError, match="no inputs: give log files, folders of logs, scenario files"):
        expand_inputs([])


def test_folders_are_searched_for_logs_only(tmp_path: Path) -> None:
    write(tmp_path, "d/run.clf", "")
    write(tmp_path, "d/world.yaml", ROOM_XR4000)
    assert [j.name for j in expand_inputs([tmp_path / "d"])] == ["run"]


# ---------------------------------------------------------------- scores, thresholds, aggregates


def result_json(outcome: str, *, end: float = 12.5, clearance: float | None = 0.4,
                contact: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "outcome": outcome,
        "end_time_s": end,
        "time_to_goal_s": end if outcome == "success" else None,
        "collision": contact,
        "path_length_m": 3.25,
        "min_clearance_m": clearance,
        "time_inside_security_pct": 12.0,
    }


def test_metrics_of_a_run_from_its_result_and_timing() -> None:
    timing = {"sim_ms_per_step": 0.5, "stack_ms_per_tick": 4.0, "steps": 10}
    assert metrics_from_result(result_json("success"), timing) == {
        "success": 1, "collisions": 0, "goal_missed": 0, "timeouts": 0, "time_to_goal_s": 12.5,
        "clearance_m": 0.4, "path_length_m": 3.25, "security_time_pct": 12.0, "sim_ms_per_step": 0.5,
        "stack_ms_per_tick": 4.0,
    }
    hit = result_json("collision", end=3.1, clearance=None, contact={"t_s": 3.1, "object": "door"})
    m = metrics_from_result(hit, {})
    assert (m["success"], m["collisions"], m["goal_missed"], m["timeouts"]) == (0, 1, 0, 0)
    # the stack stopped at the goal it believed, 0.34 m from the true one: its own outcome, not a time-out
    short = {**result_json("goal_missed", end=21.0), "ticks": 200, "takeovers": 3,
             "active_modes": {"gnd": 150, "local": 50},
             "goal_missed": {"stack_goal_reached_s": 19.6, "stopped_s": 20.0, "true_distance_m": 0.34,
                             "tolerance_m": 0.3}}
    ms = metrics_from_result(short, {})
    assert (ms["success"], ms["goal_missed"], ms["timeouts"], ms["goal_miss_m"]) == (0, 1, 0, 0.34)
    assert (ms["takeovers"], ms["local_ticks_pct"]) == (3.0, 25.0)
    assert outcome_note(short) == ("goal missed at 21.00 s: the stack stopped at the goal, the true axle "
                                   "0.340 m from it (tolerance 0.3 m)")
    assert "time_to_goal_s" not in m and "clearance_m" not in m  # null in result.json: not measured
    assert outcome_note(hit) == "collision with door at 3.10 s"
    moved_into = {"t_s": 4.0, "object": "person", "hit_by_mover": True}
    assert outcome_note(result_json("collision", contact=moved_into)) == "hit by person at 4.00 s"
    assert outcome_note(result_json("timeout", end=60.0)) == "timeout at 60.00 s: goal not reached"
    assert outcome_note(result_json("success")) == "success at 12.50 s"


def test_thresholds_file_takes_scenario_keys_on_runs_and_over_seeds(tmp_path: Path) -> None:
    th = load_thresholds(write(tmp_path, "t.toml", (
        "[thresholds]\ncollisions = 0\nmin_clearance_m = 0.05\n"
        '[inputs."u_trap"]\nmin_success = false\nmin_success_rate = 0.75\nmean_time_to_goal_s = 100\n'
        'relations = "t.toml"\ngoal = [1.0, 2.0]\n'
    )))
    run = Job("u_trap-s1", Path("u_trap.yaml"), kind="scenario", seed=1, group="u_trap")
    assert th.limits_for(run) == {
        "min_ticks": 1, "min_clearance_m": 0.05, "min_success_rate": 0.75, "reactor_p99_ms": 50.0,
        "planner_p99_ms": 200.0, "stack_p99_ms": 300.0, "collisions": 0, "mean_time_to_goal_s": 100,
    }
    assert th.aggregate_limits("u_trap", Path("u_trap.yaml")) == {
        "min_success_rate": 0.75, "mean_time_to_goal_s": 100,
    }
    assert th.aggregate_limits("enclosed", Path("enclosed.yaml")) == {}
    assert "min_success_rate" not in th.limits_for(Job("u_trap-old", Path("u_trap-old.clf")))  # a log
    assert th.apply(run) == run  # a scenario keeps its own goal and has no relations
    assert Thresholds().limits_for(run)["min_success"] == DEFAULT_LIMITS["min_success"] == 1


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[thresholds]\nmin_success_rate = 1.5\n", r"min_success_rate is a fraction of the runs, from 0 to"),
        ("[thresholds]\ncollisions = 0.5\n", r"collisions must be a non-negative integer or false"),
        ('[inputs."x"]\nsuccess_rate = 1\n', r"unknown key 'success_rate' \(did you mean 'min_success_rate'"),
    ],
)
def test_scenario_threshold_errors_name_the_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    path = write(tmp_path, "t.toml", text)
    with pytest.raises(ConfigError, match=str(path) + ".*" + match):
        load_thresholds(path)


def run_row(group: str, seed: int, outcome: str, time_s: float | None = None, clearance: float = 0.5,
            status: str = "pass", stack_p99: float = 5.0) -> InputResult:
    metrics: dict[str, float] = {
        "success": int(outcome == "success"), "collisions": int(outcome == "collision"),
        "goal_missed": int(outcome == "goal_missed"), "timeouts": int(outcome == "timeout"),
        "clearance_m": clearance, "stack_p99_ms": stack_p99,
    }
    if time_s is not None:
        metrics["time_to_goal_s"] = time_s
    return InputResult(f"{group}-s{seed}", f"/s/{group}.yaml", status,  # type: ignore[arg-type]
                       metrics=metrics, group=group, seed=seed, outcome=outcome)


def rows_fixture() -> list[InputResult]:
    return [
        InputResult("office", "office.clf", "pass", ticks=10, metrics={"stack_p99_ms": 2.0}),
        run_row("u_trap", 1, "success", 20.0, 0.30),
        run_row("u_trap", 2, "success", 30.0, 0.12, stack_p99=9.0),
        run_row("u_trap", 3, "collision", clearance=0.0, status="fail"),
        InputResult("u_trap-s4", "/s/u_trap.yaml", "error", error="crashed", group="u_trap", seed=4),
        run_row("enclosed", 1, "timeout", clearance=0.8, status="fail"),
        run_row("enclosed", 2, "goal_missed", clearance=0.9, status="fail"),
    ]


def test_aggregates_over_seeds_known_answers() -> None:
    th = Thresholds(limits={**DEFAULT_LIMITS, "min_success_rate": 0.5, "collision_rate": 0.0})
    u_trap, enclosed = aggregate_scenarios(rows_fixture(), th)
    assert (u_trap.scenario, u_trap.seeds, u_trap.runs, u_trap.errors) == ("u_trap", (1, 2, 3, 4), 4, 1)
    assert (u_trap.successes, u_trap.collisions, u_trap.goal_missed, u_trap.timeouts) == (2, 1, 0, 0)
    assert u_trap.metrics == {
        "success_rate": 2 / 3, "collision_rate": 1 / 3, "goal_missed_rate": 0.0, "timeout_rate": 0.0,
        "mean_time_to_goal_s": 25.0, "clearance_m": 0.0, "stack_p99_ms": 9.0,
    }
    assert (enclosed.runs, enclosed.goal_missed, enclosed.timeouts) == (2, 1, 1)
    assert (enclosed.metrics["goal_missed_rate"], enclosed.metrics["timeout_rate"]) == (0.5, 0.5)
    assert u_trap.failures == ("collision_rate 0.3333 > 0",)
    assert u_trap.status == "error"  # a run errored: the worst of runs and thresholds
    assert enclosed.metrics["success_rate"] == 0.0 and "mean_time_to_goal_s" not in enclosed.metrics
    assert enclosed.failures == ("success_rate 0 < 0.5",) and enclosed.status == "fail"
    # without aggregate limits nothing is checked; the status still shows the runs' worst
    plain = aggregate_scenarios(rows_fixture())
    assert [(a.limits, a.failures, a.status) for a in plain] == [({}, (), "error"), ({}, (), "fail")]
    all_errors = aggregate_scenarios(rows_fixture()[4:5], th)[0]
    assert math.isnan(all_errors.metrics["success_rate"])
    assert all_errors.failures[0] == "success_rate not measured (limit 0.5)"


def test_reports_carry_the_runs_and_the_aggregates() -> None:
    th = Thresholds(limits={**DEFAULT_LIMITS, "min_success_rate": 0.5})
    rows = rows_fixture()
    aggs = aggregate_scenarios(rows, th)
    md = summary_md(rows, aggs)
    assert "7 inputs: 3 pass, 3 fail, 1 error" in md
    assert "| office | pass | 10 |" in md  # logs keep their table
    assert "| u_trap-s2 | pass | 2 | success | 30.00 | 0.1200 |" in md
    assert "| enclosed-s2 | FAIL | 2 | goal_missed |" in md
    # columns: runs, success, collisions, goal missed, time-outs, errors, mean time, clearance, stack p99,
    # challenge metric
    assert ("| u_trap | ERROR | 4 | 2/3 (67 %) | 1 | 0 | 0 | 1 | 25.00 | 0.0000 | 9.000 |  |  |") in md
    assert ("| enclosed | FAIL | 2 | 0/2 (0 %) | 0 | 1 | 1 | 0 |  | 0.8000 | 5.000 |  | success_rate 0 < 0.5 "
            "|" in md)
    table = list(csv.DictReader(scenarios_csv(aggs).splitlines()))
    assert [(r["scenario"], r["status"], r["success_rate"], r["goal_missed"], r["goal_missed_rate"],
             r["timeouts"], r["seeds"]) for r in table] == [
        ("u_trap", "error", "0.667", "0", "0.000", "0", "1 2 3 4"),
        ("enclosed", "fail", "0.000", "1", "0.500", "1", "1 2"),
    ]
    root = ET.fromstring(junit_xml(rows, aggs))
    runs, over_seeds = root.findall("testsuite")
    assert [c.get("name") for c in runs.findall("testcase")] == [r.name for r in rows]
    assert (over_seeds.get("name"), over_seeds.get("tests"), over_seeds.get("failures")) == (
        "gndreplay.batch.scenarios", "2", "1")
    failure = over_seeds.findall("testcase")[1].find("failure")
    assert failure is not None and failure.get("message") == "success_rate 0 < 0.5"
    assert root.get("tests") == "9" and root.get("failures") == "4" and root.get("errors") == "1"
    enclosed_out = over_seeds.findall("testcase")[1].findtext("system-out") or ""
    assert "goal_missed: 1" in enclosed_out and "timeouts: 1" in enclosed_out
    # no aggregate limits: one test case per input (per scenario x seed) and nothing more
    assert len(ET.fromstring(junit_xml(rows, aggregate_scenarios(rows))).findall("testsuite")) == 1


# ---------------------------------------------------------------- configuration of a scenario run


def test_a_scenario_run_uses_the_scenarios_preset_unless_one_is_given(tmp_path: Path) -> None:
    from gndreplay.config import load_config
    from gndreplay.sim import resolve_scenario
    from gndreplay.sim.closedloop import configure_scenario

    spec = dataclasses.replace(resolve_scenario("u_trap"), preset="xr4000")
    toml = write(tmp_path, "c.toml", "[robot]\nvmax_mps = 0.2\n")
    _, own = configure_scenario(spec, config=toml)
    assert own == load_config(toml, preset_name="xr4000") and own.robot.vmax_mps == 0.2
    assert configure_scenario(spec, preset="wheelchair")[1].preset == "wheelchair"
    chosen = CliOverrides(planner="TUNNEL", sets=("reactor.security_m=0.4",))
    tunnel = configure_scenario(spec, overrides=chosen)
    assert tunnel[1].planner.kind == "tunnel" and tunnel[1].reactor.security_m == 0.4
    pinned = write(tmp_path, "p.toml", 'preset = "xr4000"\n')
    with pytest.raises(ConfigError, match=r"p.toml: preset 'xr4000' conflicts"):
        configure_scenario(spec, config=pinned, preset="wheelchair")


def test_parse_latency() -> None:
    assert parse_latency("0") == 0.0 and parse_latency("0.15") == 0.15 and parse_latency("measured") is None
    for bad, match in (("x", "seconds or 'measured'"), ("-1", r"in \[0, 10\) s"), ("nan", r"in \[0, 10\)")):
        with pytest.raises(ConfigError, match=f"--latency must be {match}"):
            parse_latency(bad)


def test_make_tasks_gives_scenarios_the_sim_options_with_an_absolute_config() -> None:
    jobs = [Job("a", Path("a.clf")), Job("s-s1", Path("s.yaml"), kind="scenario", seed=1, group="s")]
    sim = SimOptions(time_limit_s=5.0, config=Path("c.toml"))
    cfg: Any = None
    opts: Any = None
    log, scen = make_tasks(jobs, cfg=cfg, options=opts, thresholds=Thresholds(), out_dir=Path("o"), sim=sim)
    assert log.sim is None
    assert scen.sim == SimOptions(time_limit_s=5.0, config=Path.cwd() / "c.toml")


# ---------------------------------------------------------------- the pool, with a fake scenario runner


@dataclass(frozen=True)
class FakeRun:
    out_dir: Path
    ticks: int
    data: dict[str, Any] = field(repr=False)


def fake_scenario_runner(task: Task) -> FakeRun:
    """A 'scenario' file lists ``seed outcome`` lines; the run directory gets what simulate writes."""
    outcomes = dict(line.split() for line in task.job.path.read_text().splitlines())
    outcome = outcomes[str(task.job.seed)]
    task.run_dir.mkdir(parents=True)
    summary = {"ticks": 5, "latency_ms": {"stack": {"p99": 3.0}}, "flags": {}}
    contact = {"t_s": 2.0, "object": "wall"} if outcome == "collision" else None
    for name, data in (("summary.json", summary), ("sim_timing.json", {"sim_ms_per_step": 0.1}),
                       ("result.json", result_json(outcome, end=2.0 + task.job.seed, contact=contact))):
        (task.run_dir / name).write_text(json.dumps(data))
    return FakeRun(task.run_dir, 5, summary)


def fake_scenario_batch(tmp_path: Path, thresholds: Thresholds, out: str) -> Any:
    spec = write(tmp_path, "in/s.yaml", "1 success\n2 collision\n3 success\n")
    jobs = [Job(f"s-s{k}", spec, kind="scenario", seed=k, group="s") for k in (1, 2, 3)]
    cfg: Any = None
    opts: Any = None
    return run_batch(jobs, cfg=cfg, options=opts, thresholds=thresholds, out_dir=tmp_path / out,
                     runner=fake_scenario_runner, junit=tmp_path / out / "junit.xml")


def test_a_run_that_misses_its_goal_fails_and_a_success_rate_can_replace_that(tmp_path: Path) -> None:
    res = fake_scenario_batch(tmp_path, Thresholds(), "strict")
    assert [(r.name, r.status) for r in res.results] == [("s-s1", "pass"), ("s-s2", "fail"), ("s-s3", "pass")]
    assert res.results[1].failures == ("success 0 < 1 (collision with wall at 2.00 s)",)
    assert res.exit_code == 1
    tolerant = Thresholds(limits={**DEFAULT_LIMITS, "min_success": 0, "min_success_rate": 0.6})
    res = fake_scenario_batch(tmp_path, tolerant, "rate")
    assert [r.status for r in res.results] == ["pass"] * 3 and res.exit_code == 0
    assert res.aggregates[0].metrics["success_rate"] == pytest.approx(2 / 3)
    assert (tmp_path / "rate" / "scenarios.csv").is_file()
    strict_rate = Thresholds(limits={**DEFAULT_LIMITS, "min_success": 0, "min_success_rate": 0.9})
    res = fake_scenario_batch(tmp_path, strict_rate, "rate-strict")
    assert [r.status for r in res.results] == ["pass"] * 3 and res.exit_code == 1  # the aggregate fails
    suites = ET.parse(tmp_path / "rate-strict" / "junit.xml").getroot().findall("testsuite")
    assert [s.get("failures") for s in suites] == ["0", "1"]


def test_execute_reads_the_scores_of_a_scenario_run(tmp_path: Path) -> None:
    spec = write(tmp_path, "s.yaml", "4 timeout\n")
    task = Task(Job("s-s4", spec, kind="scenario", seed=4, group="s"), cfg=None,  # type: ignore[arg-type]
                options=None, run_dir=tmp_path / "run", limits=dict(DEFAULT_LIMITS))  # type: ignore[arg-type]
    r = execute(task, fake_scenario_runner)
    assert (r.status, r.group, r.seed, r.outcome) == ("fail", "s", 4, "timeout at 6.00 s: goal not reached")
    assert r.metrics["timeouts"] == 1 and r.metrics["sim_ms_per_step"] == 0.1 and r.metrics["ticks"] == 5


# ---------------------------------------------------------------- the command, on real closed-loop runs


def test_cli_batch_runs_scenarios_beside_a_log_and_a_bad_scenario_file(tmp_path: Path) -> None:
    """Two seeds of a shipped (wheelchair) and a user (xr4000) scenario, 2 s each, the sample log, a
    scenario file with a bad key and a missing one: every good input runs, exit 2 names the bad ones."""
    from typer.testing import CliRunner

    from gndreplay.cli import app

    room = write(tmp_path, "room.yaml", ROOM_XR4000)
    bad = write(tmp_path, "bad.yaml", ROOM_XR4000.replace("time_limit:", "time_limt:"))
    out = tmp_path / "out"
    args = ["batch", str(SAMPLE_LOG), str(room), str(bad), str(tmp_path / "missing.yaml"),
            "--scenarios", "u_trap", "--seeds", "1,2", "--time-limit", "2", "--latency", "0.05",
            "--perfect-odometry", "--no-figures", "--until", "1", "--out", str(out),
            "--junit", str(out / "junit.xml"), "--quiet"]
    result = CliRunner().invoke(app, args, env={"MPLBACKEND": "Agg"})
    assert result.exit_code == 2, result.output
    errors = [line for line in result.stderr.splitlines() if line.startswith("gndreplay: error:")]
    assert errors == [
        f"gndreplay: error: bad: {bad.absolute()}: time_limt: unknown key (known: name, description, preset, "
        "start, goal, time_limit, world, events, movers, mode, local, subgoals, teleop, expect)",
        f"gndreplay: error: missing: {(tmp_path / 'missing.yaml').absolute()}: scenario file not found",
    ]
    rows = {r["name"]: r for r in csv.DictReader((out / "summary.csv").open())}
    assert list(rows) == ["office", "room-s1", "room-s2", "bad", "missing", "u_trap-s1", "u_trap-s2"]
    assert rows["office"]["status"] == "pass" and rows["office"]["scenario"] == ""
    for name, preset in (("room-s1", "xr4000"), ("room-s2", "xr4000"), ("u_trap-s1", "wheelchair"),
                         ("u_trap-s2", "wheelchair")):
        row = rows[name]
        assert (row["status"], row["outcome"], row["timeouts"]) == (
            "fail", "timeout at 2.00 s: goal not reached", "1")
        assert row["failures"] == "success 0 < 1 (timeout at 2.00 s: goal not reached)"
        assert float(row["clearance_m"]) > 0 and float(row["stack_p99_ms"]) > 0 and int(row["ticks"]) > 0
        run_dir = out / row["run_dir"]  # relative to the batch folder
        res = json.loads((run_dir / "result.json").read_text())
        assert (res["seed"], res["time_limit_s"], res["latency_s"], res["perfect_odometry"]) == (
            int(row["seed"]), 2.0, 0.05, True)
        assert f'preset = "{preset}"' in (run_dir / "config.toml").read_text()  # the scenario's own
        assert not (run_dir / "fig_world.png").exists()
    assert (rows["bad"]["status"], rows["missing"]["status"]) == ("error", "error")
    cases = ET.parse(out / "junit.xml").getroot().findall("testsuite/testcase")
    assert sorted(c.get("name") or "" for c in cases) == sorted(rows)  # one per input, per scenario x seed
    scen = {r["scenario"]: r for r in csv.DictReader((out / "scenarios.csv").open())}
    assert [(k, v["runs"], v["timeouts"], v["errors"], v["success_rate"]) for k, v in scen.items()] == [
        ("room", "2", "2", "0", "0.000"),
        ("bad", "1", "0", "1", "nan"),
        ("missing", "1", "0", "1", "nan"),
        ("u_trap", "2", "2", "0", "0.000"),
    ]
    md = (out / "summary.md").read_text()
    assert "## Scenarios over seeds" in md and "| u_trap | FAIL | 2 | 0/2 (0 %) | 0 | 0 | 2 | 0 |" in md


def test_cli_batch_passes_the_scenario_options(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    import gndreplay.batch
    from gndreplay.batch import BatchResult
    from gndreplay.cli import app

    seen: dict[str, Any] = {}

    def capture(jobs: Any, **kw: Any) -> BatchResult:
        seen.update(kw, jobs=jobs)
        return BatchResult((), tmp_path, tmp_path / "s.csv", tmp_path / "s.md", None, 0.0)

    monkeypatch.setattr(gndreplay.batch, "run_batch", capture)
    toml = write(tmp_path, "c.toml", "[robot]\nvmax_mps = 0.2\n")
    args = ["batch", "--scenarios", "enclosed", "--seeds", "0-1", "--latency", "measured", "--time-limit",
            "3", "--no-figures", "--config", str(toml), "--planner", "tunnel", "--quiet"]
    assert CliRunner().invoke(app, args).exit_code == 0
    assert [j.name for j in seen["jobs"]] == ["enclosed-s0", "enclosed-s1"]
    assert seen["sim"] == SimOptions(latency_s=None, time_limit_s=3.0, figures=False, config=toml,
                                     overrides=CliOverrides(planner="tunnel"))
    for bad, message in ((["--seeds", "3-1"], "seeds: range '3-1' in '3-1' goes down"),
                         (["--latency", "soon"], "--latency must be seconds or 'measured'"),
                         (["--scenarios", "nope"], "scenarios: no shipped scenario 'nope'")):
        result = CliRunner().invoke(app, ["batch", "--scenarios", "enclosed", *bad])
        assert result.exit_code == 2, result.stderr
        assert result.stderr.startswith(f"gndreplay: error: {message}"), result.stderr


def test_scenario_runs_take_the_navigation_options_as_simulate_does(tmp_path: Path) -> None:
    """--mode / --local / --subgoals replace the scenario's own keys, --no-selector the config's selector;
    a mode the scenario cannot run is that run's error (naming the file), never a silent GND run."""
    from gndreplay.batch.scenarios import run_scenario, scenario_scores
    from gndreplay.types import Subgoal

    room = write(tmp_path, "room.yaml", ROOM_XR4000)
    job = Job("room-s0", room, kind="scenario", seed=0, group="room")
    base = SimOptions(time_limit_s=1.0, figures=False, perfect_odometry=True)

    def nav(out: str, sim: SimOptions) -> tuple[dict[str, Any], dict[str, float]]:
        run = run_scenario(job, tmp_path / out, sim)
        res = json.loads((run.out_dir / "result.json").read_text())
        return res, scenario_scores(run.out_dir)[0]

    res, _ = nav("plain", base)
    assert (res["navigation"]["mode"], res["navigation"]["selector"], res["navigation"]["local"]) == (
        "gnd", True, "nd")
    res, scores = nav("local", SimOptions(time_limit_s=1.0, figures=False, perfect_odometry=True,
                                          overrides=CliOverrides(mode="LOCAL", local="wall-left",
                                                                 no_selector=True)))
    assert (res["navigation"]["mode"], res["navigation"]["selector"], res["navigation"]["local"]) == (
        "local", False, "wall-left")
    assert scores["takeovers"] == res["takeovers"]
    assert res["active_modes"] == {"local": res["ticks"]} and scores["local_ticks_pct"] == 100.0
    stop = (Subgoal(2.0, 2.0, 0.0, "stop"),)
    res, _ = nav("follow", SimOptions(time_limit_s=1.0, figures=False, overrides=CliOverrides(mode="follow"),
                                      subgoals=stop))
    assert (res["navigation"]["mode"], res["navigation"]["subgoals"]) == ("follow", 1)
    with pytest.raises(ConfigError, match=r"room.yaml: teleop: missing"):
        run_scenario(job, tmp_path / "teleop", SimOptions(overrides=CliOverrides(mode="teleop")))
    with pytest.raises(ConfigError, match=r"--mode: expected one of gnd, teleop, follow, local, got 'drive'"):
        run_scenario(job, tmp_path / "drive", SimOptions(overrides=CliOverrides(mode="drive")))


def test_goals_missed_have_their_own_thresholds_per_run_and_over_seeds(tmp_path: Path) -> None:
    from gndreplay.batch import check_limits

    th = load_thresholds(write(tmp_path, "t.toml", (
        '[inputs."u_trap"]\nmin_success = false\ngoal_missed = 0\ngoal_missed_rate = 0.25\ntakeovers = 3\n')))
    run = Job("u_trap-s1", Path("u_trap.yaml"), kind="scenario", seed=1, group="u_trap")
    limits = th.limits_for(run)
    assert (limits["goal_missed"], limits["takeovers"]) == (0, 3) and "min_success" not in limits
    assert th.aggregate_limits("u_trap", Path("u_trap.yaml")) == {"goal_missed_rate": 0.25}
    row = run_row("u_trap", 1, "goal_missed", status="fail")
    assert check_limits(row.metrics, limits) == ("goal_missed 1 > 0",)
    agg = aggregate_scenarios([row, run_row("u_trap", 2, "success", 10.0)], th)[0]
    assert agg.failures == ("goal_missed_rate 0.5 > 0.25",)
    with pytest.raises(ConfigError, match=r"goal_missed_rate is a fraction of the runs"):
        load_thresholds(write(tmp_path, "bad.toml", "[thresholds]\ngoal_missed_rate = 2\n"))
