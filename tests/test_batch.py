"""gndreplay.batch: input expansion, thresholds, reports, the process pool (isolation of bad and crashing
inputs, order, exit codes) and the dask backend, first with injected fake runners, then on real logs."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import signal
import socket
import stat
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import pytest

from gndreplay.batch import (
    CSV_COLUMNS,
    DEFAULT_LIMITS,
    InputResult,
    Job,
    Task,
    Thresholds,
    check_limits,
    execute,
    expand_inputs,
    junit_xml,
    load_thresholds,
    make_tasks,
    metrics_from_summary,
    run_batch,
    run_tasks,
    safe_name,
    summary_csv,
    summary_md,
    unique_names,
)
from gndreplay.errors import ConfigError, GndReplayError, LogFormatError, OutputError
from gndreplay.fsutil import RUN_MARKER, TMP_PREFIX, staging_dir

SAMPLE_LOG = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"


# ---------------------------------------------------------------- fakes (module level: workers unpickle them)


@dataclass(frozen=True)
class FakeOptions:
    """Stands in for RunOptions (a dataclass with a goal)."""

    goal_xy: tuple[float, float] | None = None


@dataclass(frozen=True)
class FakeOutcome:
    out_dir: Path
    ticks: int
    data: Mapping[str, Any] = field(repr=False)


def fake_summary(ticks: int, reactor_p99_ms: float, estops: int) -> dict[str, Any]:
    lat = {"median": 1.0, "p90": 2.0, "p99": 3.0, "max": 4.0}
    return {
        "ticks": ticks,
        "flags": {"EMERGENCY_STOP": estops, "MATCH_FAILED": 0},
        "latency_ms": {
            "match": lat,
            "model": lat,
            "planner": {"median": 5.0, "p90": 6.0, "p99": 7.0, "max": 8.0},
            "reactor": {**lat, "p99": reactor_p99_ms},
            "stack": lat,
            "total": lat,
        },
    }


def fake_runner(task: Task) -> FakeOutcome:
    """A 'log' is a text file with one command: ``GOOD ticks reactor_p99 estops [x y ...]`` writes a run
    directory (trajectory poses given as x y pairs, theta 0, one per second from t=100 s), ``BAD`` raises a
    LogFormatError, ``CRASH`` a RuntimeError, ``DIE`` ends the worker process with os._exit(3), ``KILL`` with
    SIGKILL, ``HANG`` sleeps for an hour."""
    words = task.job.path.read_text().split()
    if words[0] == "HANG":  # records its pid (so the test can see it was killed), then never returns
        with staging_dir(task.run_dir):  # as run_log does: a killed worker leaves this behind
            (task.job.path.parent / f"{task.job.name}.pid").write_text(str(os.getpid()))
            time.sleep(3600)
    if words[0] == "BAD":
        raise LogFormatError(f"{task.job.path} line 1: not a log\n(second line)")
    if words[0] == "CRASH":
        raise RuntimeError("boom")
    if words[0] == "DIE":
        os._exit(3)
    if words[0] == "KILL":
        os.kill(os.getpid(), signal.SIGKILL)
    ticks, p99, estops = int(words[1]), float(words[2]), int(words[3])
    xy = [float(w) for w in words[4:]]
    lines = [f"{100 + k}.0 {xy[2 * k]} {xy[2 * k + 1]} 0 0 0 0 1\n" for k in range(len(xy) // 2)]
    summary = fake_summary(ticks, p99, estops)
    with staging_dir(task.run_dir) as tmp:  # as run_log does: the run directory appears marked
        (tmp / "trajectory_corrected.tum").write_text("# t x y z qx qy qz qw\n" + "".join(lines))
        (tmp / "summary.json").write_text(json.dumps(summary))
    return FakeOutcome(task.run_dir, ticks, summary)


def write_input(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return p


def fake_batch(tmp_path: Path, specs: dict[str, str], *, out: str = "out", **kw: Any) -> Any:
    """run_batch over fake inputs ``tmp_path/in/<name>.clf`` holding the given fake-runner commands."""
    jobs = [Job(name=n, path=write_input(tmp_path / "in", f"{n}.clf", s)) for n, s in specs.items()]
    cfg: Any = None
    options: Any = FakeOptions()
    return run_batch(jobs, cfg=cfg, options=options, out_dir=tmp_path / out, runner=fake_runner, **kw)


# ---------------------------------------------------------------- inputs


def test_expand_inputs_finds_logs_recursively_in_sorted_order(tmp_path: Path) -> None:
    for name in (
        "b.clf.bz2",
        "a.clf",
        "c.log.gz",
        "notes.txt",
        "x.tar.gz",
        ".hidden.clf",
        "sub/d.bag",
        "sub/e.mcap",
        "bag2/metadata.yaml",
        "bag2/bag2_0.mcap",
        "bag2/bag2_0.db3",
    ):
        write_input(tmp_path / "logs", name, "")
    single = write_input(tmp_path / "other", "f.carmen", "")
    jobs = expand_inputs([tmp_path / "logs", single, tmp_path / "logs" / "a.clf"])
    assert [(j.name, j.path.relative_to(tmp_path).as_posix()) for j in jobs] == [
        ("a", "logs/a.clf"),
        ("b", "logs/b.clf.bz2"),
        ("bag2", "logs/bag2"),  # a ROS2 bag folder is one log
        ("c", "logs/c.log.gz"),
        ("d", "logs/sub/d.bag"),
        ("e", "logs/sub/e.mcap"),
        ("f", "other/f.carmen"),  # a.clf given again: runs once
    ]
    assert all(j.kind == "log" and j.relations is None and j.goal_xy is None for j in jobs)


def test_expand_inputs_keeps_files_as_given_and_missing_paths_for_the_report(tmp_path: Path) -> None:
    odd = write_input(tmp_path, "run.data", "")
    jobs = expand_inputs([odd, tmp_path / "missing.clf"])
    assert [(j.name, j.path) for j in jobs] == [("run.data", odd), ("missing", tmp_path / "missing.clf")]


def test_expand_inputs_rejects_an_empty_folder_and_no_inputs(tmp_path: Path) -> None:
    write_input(tmp_path, "empty/readme.txt", "")
    with pytest.raises(ConfigError, match=r"empty: no logs in this folder"):
        expand_inputs([tmp_path / "empty"])
    with pytest.raises(ConfigError, match="no inputs"):
        expand_inputs([])


def test_unique_names_qualify_colliding_stems() -> None:
    paths = [Path("x/run.clf"), Path("y/run.bag"), Path("y/run.clf.gz"), Path("z/my log.clf")]
    assert unique_names(paths) == ["x-run", "y-run", "y-run-2", "my_log"]


def test_names_are_never_hidden_dot_or_dotdot() -> None:
    paths = [Path(".hidden.clf"), Path("..clf"), Path("x...bag.clf"), Path("a/...clf"), Path(".c/run.clf"),
             Path("d/run.clf")]
    names = unique_names(paths)
    assert names == ["hidden", "clf", "x...bag", "a-clf", "c-run", "d-run"]
    assert not any(n.startswith(".") for n in names)
    assert (safe_name(".."), safe_name("."), safe_name(".a b/c")) == ("input", "input", "a_b_c")


def test_dot_named_inputs_run_under_safe_names(tmp_path: Path) -> None:
    hidden = write_input(tmp_path / "in", ".hidden.clf", "GOOD 3 1.0 0")
    dots = write_input(tmp_path / "in", "..clf", "GOOD 4 1.0 0")
    jobs = expand_inputs([hidden, dots])
    res = run_batch(jobs, cfg=cast(Any, None), options=cast(Any, FakeOptions()), out_dir=tmp_path / "out",
                    runner=fake_runner)
    assert [(r.name, r.status, r.ticks) for r in res.results] == [("hidden", "pass", 3), ("clf", "pass", 4)]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        RUN_MARKER, "batch.json", "clf", "hidden", "summary.csv", "summary.md"
    ]
    assert sorted(p.name for p in (tmp_path / "in").iterdir()) == ["..clf", ".hidden.clf"]  # inputs intact


def special_files(tmp_path: Path) -> tuple[Path, Path, socket.socket]:
    """A FIFO and a listening Unix socket named like logs (the caller closes the socket)."""
    fifo = tmp_path / "pipe.clf"
    os.mkfifo(fifo)
    sock_path = tmp_path / "s.bag"
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(sock_path))
    return fifo, sock_path, sock


def test_fifos_devices_and_sockets_are_refused_up_front(tmp_path: Path) -> None:
    fifo, sock_path, sock = special_files(tmp_path)
    with sock:
        good = write_input(tmp_path, "good.clf", "GOOD 3 1.0 0")
        bag = write_input(tmp_path, "bag/metadata.yaml", "").parent  # a ROS2 bag folder ...
        os.mkfifo(bag / "bag_0.mcap")  # ... whose storage file is a FIFO
        jobs = expand_inputs([good, fifo, sock_path, Path("/dev/null"), bag])  # expanding opens nothing
        with pytest.raises(ConfigError) as err:
            run_batch(jobs, cfg=cast(Any, None), options=cast(Any, FakeOptions()), out_dir=tmp_path / "out",
                      runner=fake_runner)
    assert str(err.value) == (
        f"not a log file or folder (never opened): {fifo} (a FIFO), {sock_path} (a socket), "
        f"/dev/null (a character device), {bag / 'bag_0.mcap'} (a FIFO)"
    )
    assert not (tmp_path / "out").exists()  # refused before any work
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_fifo_through_the_cli_is_one_error_line_and_exit_2(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from gndreplay.cli import app

    fifo, _, sock = special_files(tmp_path)
    sock.close()
    result = CliRunner().invoke(app, ["batch", str(fifo), "--out", str(tmp_path / "out"), "--quiet"])
    assert result.exit_code == 2
    assert result.stderr == f"gndreplay: error: not a log file or folder (never opened): {fifo} (a FIFO)\n"
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- thresholds


def write_toml(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "limits.toml"
    p.write_text(text)
    return p


def test_thresholds_file_overrides_defaults_and_matches_inputs_by_name_or_path(tmp_path: Path) -> None:
    (tmp_path / "rel").mkdir()
    (tmp_path / "rel" / "a.relations").write_text("")
    p = write_toml(
        tmp_path,
        """
        [thresholds]
        reactor_p99_ms = 20
        stack_p99_ms = false
        emergency_stops = 0
        [inputs."mit-*"]
        relations = "rel/a.relations"
        match_trans_err_mean_m = 0.2
        reactor_p99_ms = 35.5
        [inputs."*/rosbag1/*"]
        goal = [1, -2.5]
        emergency_stops = false
        """,
    )
    th = load_thresholds(p)
    assert th.source == p
    base = {"min_ticks": 1, "min_success": 1, "reactor_p99_ms": 20, "planner_p99_ms": 200.0,
            "emergency_stops": 0}  # min_success: scenario runs only (a log has no such metric)
    assert th.limits_for(Job("aces", Path("d/aces.clf"))) == base
    mit = Job("mit-csail", Path("d/mit-csail.clf.bz2"))
    assert th.limits_for(mit) == {**base, "reactor_p99_ms": 35.5, "match_trans_err_mean_m": 0.2}
    assert th.apply(mit) == Job("mit-csail", mit.path, relations=tmp_path / "rel" / "a.relations")
    bag = Job("mit-sort", Path("d/rosbag1/mit-sort.bag"))
    limits = th.limits_for(bag)
    assert "emergency_stops" not in limits and limits["reactor_p99_ms"] == 35.5  # both rules apply
    assert th.apply(bag).goal_xy == (1.0, -2.5)
    # a job's own settings win over the file's
    own = Job("mit-csail", mit.path, relations=Path("mine.relations"))
    assert th.apply(own).relations == Path("mine.relations")


def test_default_thresholds_are_generous_multiples_of_the_supervisor_time_outs() -> None:
    from gndreplay.pipeline.supervisor import SupervisorParams

    assert Thresholds().limits_for(Job("x", Path("x.clf"))) == dict(DEFAULT_LIMITS)
    sup = SupervisorParams()
    budget_ms = {"reactor": sup.budget_reactor_s * 1e3, "planner": sup.budget_planner_s * 1e3}
    budget_ms["stack"] = budget_ms["reactor"] + budget_ms["planner"] + sup.budget_model_s * 1e3
    for module, ms in budget_ms.items():
        assert DEFAULT_LIMITS[f"{module}_p99_ms"] >= 2 * ms
    assert DEFAULT_LIMITS["min_ticks"] == 1


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "[thresholds]\nreactor_p99 = 3",
            r"limits.toml: \[thresholds\] unknown key 'reactor_p99' "
            r"\(did you mean 'reactor_p99_ms'\?\)",
        ),
        ("[limits]\nx = 1", r"limits.toml: top level: unknown key 'limits'"),
        (
            "[thresholds]\nreactor_p99_ms = -1",
            r"reactor_p99_ms must be a non-negative number or false, got -1",
        ),
        ("[thresholds]\nreactor_p99_ms = 'fast'", r"reactor_p99_ms must be a non-negative number"),
        ("[thresholds]\nreactor_p99_ms = true", r"reactor_p99_ms must be a non-negative number"),
        ("[thresholds]\nemergency_stops = 0.5", r"emergency_stops must be a non-negative integer or false"),
        ("[thresholds]\nmin_ticks = nan", r"min_ticks must be a non-negative integer"),
        ("thresholds = 3", r"\[thresholds\] must be a table"),
        (
            "[inputs.x]\nrelation = 'a'",
            r"\[inputs.'x'\] unknown key 'relation' \(did you mean 'relations'\?\)",
        ),
        (
            "[inputs.x]\nrelations = 'nope.relations'",
            r"\[inputs.'x'\] .*nope\.relations: relations file not found",
        ),
        ("[inputs.x]\ngoal = [1]", r"\[inputs.'x'\] goal must be \[x, y\] in metres, got \[1\]"),
        ("[inputs]\nx = 1", r"\[inputs.'x'\] must be a table"),
        ("[thresholds\n", r"limits.toml: not a valid TOML file"),
    ],
)
def test_thresholds_file_errors_name_the_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_thresholds(write_toml(tmp_path, text))


def test_thresholds_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope.toml: thresholds file not found"):
        load_thresholds(tmp_path / "nope.toml")


def test_check_limits_known_answers() -> None:
    metrics = {
        "ticks": 40,
        "reactor_p99_ms": 63.25,
        "planner_p99_ms": 10.0,
        "emergency_stops": 3,
        "match_trans_err_mean_m": math.nan,
    }
    limits = {
        "min_ticks": 50,
        "reactor_p99_ms": 50.0,
        "planner_p99_ms": 10.0,
        "emergency_stops": 2,
        "match_trans_err_mean_m": 0.1,
        "no_region": 0,
        "stack_p99_ms": 1.0,
    }
    assert check_limits(metrics, limits) == (
        "ticks 40 < 50",
        "reactor_p99_ms 63.25 > 50",
        "emergency_stops 3 > 2",
        "match_trans_err_mean_m not measured (limit 0.1)",
    )  # equal is a pass; absent metrics (no_region, stack) are not checked
    assert check_limits(metrics, {}) == ()


def test_metrics_from_summary() -> None:
    m = metrics_from_summary(fake_summary(12, 9.5, 2))
    assert m["ticks"] == 12 and m["reactor_p99_ms"] == 9.5 and m["planner_max_ms"] == 8.0
    assert m["emergency_stops"] == 2 and m["match_failures"] == 0 and m["no_region"] == 0
    assert (
        metrics_from_summary({"ticks": 0, "latency_ms": {"match": {}}, "flags": {}})
        .keys()
        .isdisjoint({"match_p99_ms", "reactor_p99_ms"})
    )


def _truth(ate: float, rpe_m: float, rpe_deg: float) -> dict[str, Any]:
    aligned = {"ate_rmse_m": ate, "rpe_trans_rmse_m": rpe_m, "rpe_rot_rmse_deg": rpe_deg, "matched": 10}
    return {"poses": 10, "odom": {"aligned": {**aligned, "ate_rmse_m": 9.0}},
            "corrected": {"aligned": aligned, "unaligned": {**aligned, "ate_rmse_m": 8.0}}}


def test_truth_metrics_are_the_corrected_trajectorys_aligned_errors() -> None:
    m = metrics_from_summary({**fake_summary(12, 9.5, 2), "truth": _truth(0.25, 0.01, 0.5)})
    assert (m["ate_m"], m["rpe_m"], m["rpe_deg"]) == (0.25, 0.01, 0.5)
    absent = metrics_from_summary({**fake_summary(12, 9.5, 2), "truth": None})
    assert absent.keys().isdisjoint({"ate_m", "rpe_m", "rpe_deg"})
    unpaired = metrics_from_summary({**fake_summary(12, 9.5, 2), "truth": _truth(math.nan, math.nan, 0.5)})
    assert math.isnan(unpaired["ate_m"]) and math.isnan(unpaired["rpe_m"]) and unpaired["rpe_deg"] == 0.5


def test_a_truth_threshold_fails_an_input_without_truth_and_says_so() -> None:
    limits = {"ate_m": 0.2, "rpe_deg": 1.0, "match_trans_err_mean_m": 0.1}
    assert check_limits({"ate_m": 0.25, "rpe_deg": 0.5}, limits) == ("ate_m 0.25 > 0.2",)
    assert check_limits({"ate_m": 0.15, "rpe_deg": 0.5}, limits) == ()  # relations absent: not checked
    assert check_limits({"ticks": 3}, limits) == (
        "ate_m not measured: the input has no ground truth (limit 0.2; ate_m = false in its [inputs] table "
        "skips the check)",
        "rpe_deg not measured: the input has no ground truth (limit 1; rpe_deg = false in its [inputs] "
        "table skips the check)",
    )
    assert check_limits({"ate_m": math.nan}, {"ate_m": 0.2}) == ("ate_m not measured (limit 0.2)",)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[thresholds]\nate = 0.1", r"unknown key 'ate' \(did you mean 'ate_m'\?\)"),
        ("[thresholds]\nrpe_m_deg = 0.1", r"unknown key 'rpe_m_deg' \(did you mean 'rpe_deg'\?\)"),
        ("[thresholds]\nrpe_deg = 200", r"rpe_deg must be at most 180 deg \(a half turn"),
        ("[thresholds]\nate_m = 2e6", r"ate_m must be at most 1e\+06 m"),
        ("[thresholds]\nate_m = -0.1", r"ate_m must be a non-negative number or false"),
    ],
)
def test_truth_thresholds_are_validated_like_the_others(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_thresholds(write_toml(tmp_path, text))


def test_truth_thresholds_in_a_real_batch(tmp_path: Path) -> None:
    """The sample (CARMEN TRUEPOS) and two copies without its truth lines, under ``ate_m``: the sample is
    scored, the first copy fails for want of truth, the second is switched off for it."""
    import bz2

    from gndreplay.config import Config
    from gndreplay.replay import RunOptions

    text = bz2.decompress(SAMPLE_LOG.read_bytes()).decode()
    blind = "".join(x for x in text.splitlines(keepends=True) if not x.startswith("TRUEPOS"))
    for name in ("blind", "blind-off"):
        (tmp_path / f"{name}.clf").write_text(blind)
    th = load_thresholds(write_toml(tmp_path, '[thresholds]\nate_m = 0.5\nrpe_m = 0.1\n'
                                              '[inputs."blind-off"]\nate_m = false\nrpe_m = false\n'))
    jobs = [Job("office", SAMPLE_LOG), Job("blind", tmp_path / "blind.clf"),
            Job("blind-off", tmp_path / "blind-off.clf")]
    res = run_batch(jobs, cfg=Config(), options=RunOptions(until_s=3.0), thresholds=th,
                    out_dir=tmp_path / "b")
    office, blind_run, off = res.results
    summary = json.loads((office.run_dir / "summary.json").read_text())
    assert office.status == "pass" and office.metrics["ate_m"] == pytest.approx(
        summary["truth"]["corrected"]["aligned"]["ate_rmse_m"])
    assert blind_run.status == "fail" and blind_run.failures == (
        "ate_m not measured: the input has no ground truth (limit 0.5; ate_m = false in its [inputs] table "
        "skips the check)",
        "rpe_m not measured: the input has no ground truth (limit 0.1; rpe_m = false in its [inputs] table "
        "skips the check)")
    assert off.status == "pass" and "ate_m" not in off.metrics
    rows = {r["name"]: r for r in csv.DictReader(io.StringIO((tmp_path / "b" / "summary.csv").read_text()))}
    assert float(rows["office"]["ate_m"]) == pytest.approx(office.metrics["ate_m"], abs=1e-4)
    assert rows["blind"]["ate_m"] == "" and res.exit_code == 1


# ---------------------------------------------------------------- trajectories and relations


def test_read_tum_round_trip(tmp_path: Path) -> None:
    from gndreplay.evaluation import read_tum, write_tum

    t = [1_700_000_000_123_456_789, 1_700_000_001_000_000_000]
    poses = [(1.5, -2.0, 0.3), (2.0, 0.25, -3.0)]
    write_tum(tmp_path / "t.tum", t, poses)
    t2, p2 = read_tum(tmp_path / "t.tum")
    assert t2.tolist() == t
    assert p2.ravel().tolist() == pytest.approx([c for pose in poses for c in pose], abs=1e-12)
    (tmp_path / "bad.tum").write_text("1.0 2 3\n")
    with pytest.raises(GndReplayError, match=r"bad.tum line 1: not a TUM pose .*found 3"):
        read_tum(tmp_path / "bad.tum")


def test_relation_error_known_answer_through_a_thresholds_file(tmp_path: Path) -> None:
    # trajectory (theta 0): t=100 at (0, 0), t=101 at (1, 0), t=102 at (1, 1)
    # reference: 100->101 is (1.1, 0) (error 0.1), 101->102 is (0, 1) (error 0); 103 does not exist
    rel = tmp_path / "run.relations"
    rel.write_text("100.0 101.0 1.1 0 0 0 0 0\n101.0 102.0 0 1 0 0 0 0\n101.0 103.0 0 0 0 0 0 0\n")
    th = write_toml(
        tmp_path,
        f"""
        [inputs.run]
        relations = "{rel.name}"
        match_trans_err_mean_m = 0.04
        """,
    )
    res = fake_batch(
        tmp_path,
        {"run": "GOOD 3 1.0 0 0 0 1 0 1 1", "other": "GOOD 3 1.0 0 0 0"},
        thresholds=load_thresholds(th),
    )
    run, other = res.results
    assert run.metrics["relations_matched"] == 2
    assert run.metrics["match_trans_err_mean_m"] == pytest.approx(0.05)
    assert run.metrics["match_trans_err_max_m"] == pytest.approx(0.1)
    assert run.metrics["match_rot_err_mean_deg"] == pytest.approx(0.0)
    assert run.status == "fail" and run.failures == ("match_trans_err_mean_m 0.05 > 0.04",)
    assert other.status == "pass" and "match_trans_err_mean_m" not in other.metrics
    assert res.exit_code == 1


# ---------------------------------------------------------------- reports


def results_fixture() -> list[InputResult]:
    return [
        InputResult(
            "good",
            "a/good.clf",
            "pass",
            ticks=10,
            metrics={"ticks": 10, "reactor_p99_ms": 1.23456},
            run_dir=Path("out/good"),
            wall_s=1.0,
        ),
        InputResult(
            "slow",
            "a/slow.clf",
            "fail",
            ticks=5,
            metrics={"ticks": 5, "reactor_p99_ms": 80.0},
            failures=("reactor_p99_ms 80 > 50", "emergency_stops 2 > 0"),
            run_dir=Path("out/slow"),
        ),
        InputResult(
            "bad|x",
            "a/bad.clf",
            "error",
            error="a/bad.clf line 3: junk \x00 here",
            error_type="LogFormatError",
        ),
    ]


def test_summary_csv_round_trip() -> None:
    rows = list(csv.DictReader(io.StringIO(summary_csv(results_fixture()))))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert [(r["name"], r["status"], r["ticks"]) for r in rows] == [
        ("good", "pass", "10"),
        ("slow", "fail", "5"),
        ("bad|x", "error", "0"),
    ]
    assert rows[0]["reactor_p99_ms"] == "1.235" and rows[0]["planner_p99_ms"] == ""
    assert rows[1]["failures"] == "reactor_p99_ms 80 > 50; emergency_stops 2 > 0"
    assert rows[2]["error"].startswith("a/bad.clf line 3: junk")


def test_summary_md_has_one_row_per_input() -> None:
    md = summary_md(results_fixture())
    assert "3 inputs: 1 pass, 1 fail, 1 error" in md
    rows = [line for line in md.splitlines() if line.startswith("| ") and "input" not in line]
    assert len(rows) == 3
    assert rows[1].startswith("| slow | FAIL | 5 | 80.000 |") and "reactor_p99_ms 80 > 50" in rows[1]
    assert rows[2].startswith("| bad\\|x | ERROR | 0 |")


def test_junit_xml_parses_with_counts_and_messages() -> None:
    root = ET.fromstring(junit_xml(results_fixture()))
    suite = root.find("testsuite")
    assert suite is not None
    assert (suite.get("name"), suite.get("tests"), suite.get("failures"), suite.get("errors")) == (
        "gndreplay.batch",
        "3",
        "1",
        "1",
    )
    cases = suite.findall("testcase")
    assert [(c.get("classname"), c.get("name")) for c in cases] == [
        ("gndreplay.batch", "good"),
        ("gndreplay.batch", "slow"),
        ("gndreplay.batch", "bad|x"),
    ]
    assert cases[0].find("failure") is None and cases[0].find("error") is None
    failure = cases[1].find("failure")
    assert failure is not None and failure.get("message") == "reactor_p99_ms 80 > 50; emergency_stops 2 > 0"
    error = cases[2].find("error")
    assert error is not None and error.get("type") == "LogFormatError"
    assert error.get("message") == "a/bad.clf line 3: junk \ufffd here"  # NUL cannot be carried by XML


# ---------------------------------------------------------------- the pool, with fake runners


def test_batch_isolates_bad_crashing_and_dying_inputs(tmp_path: Path) -> None:
    seen: list[str] = []
    specs = {
        "good1": "GOOD 7 1.0 0",
        "bad": "BAD",
        "crash": "CRASH",
        "die": "DIE",
        "good2": "GOOD 9 2.0 1",
        "kill": "KILL",
    }
    res = fake_batch(
        tmp_path, specs, workers=2, progress=lambda r: seen.append(r.name), junit=tmp_path / "junit.xml"
    )
    by = {r.name: r for r in res.results}
    assert [r.name for r in res.results] == list(specs)  # input order, whatever the completion order
    assert sorted(seen) == sorted(specs)
    assert (by["good1"].status, by["good1"].ticks, by["good1"].metrics["reactor_p99_ms"]) == ("pass", 7, 1.0)
    assert (by["good2"].status, by["good2"].ticks, by["good2"].metrics["emergency_stops"]) == ("pass", 9, 1)
    assert by["good1"].run_dir == (tmp_path / "out" / "good1").absolute()
    assert by["bad"].status == "error" and by["bad"].error_type == "LogFormatError"
    assert by["bad"].error == f"{(tmp_path / 'in' / 'bad.clf').absolute()} line 1: not a log (second line)"
    assert by["crash"].error == "crashed: RuntimeError: boom" and "Traceback" in by["crash"].detail
    assert by["die"].error == "crashed: worker process died (exit code 3)"
    assert by["kill"].error == "crashed: worker process died (killed by SIGKILL)"
    assert res.exit_code == 2
    assert (res.count("pass"), res.count("fail"), res.count("error")) == (2, 0, 4)
    rows = list(csv.DictReader(res.summary_csv.open()))
    assert [(r["name"], r["status"]) for r in rows] == [(n, by[n].status) for n in specs]
    suite = ET.parse(tmp_path / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("6", "0", "4")
    leftovers = [p.name for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]
    assert leftovers == [RUN_MARKER]  # atomic writes, no temporary files or run directories left


@pytest.mark.parametrize("workers", [1, 2])
def test_a_hung_input_times_out_its_worker_is_killed_and_the_batch_goes_on(
    tmp_path: Path, workers: int
) -> None:
    specs = {"good1": "GOOD 7 1.0 0", "hang": "HANG", "good2": "GOOD 9 2.0 1", "good3": "GOOD 2 1.0 0"}
    res = fake_batch(tmp_path, specs, workers=workers, timeout_s=1.5, junit=tmp_path / "junit.xml")
    by = {r.name: r for r in res.results}
    assert (by["hang"].status, by["hang"].error, by["hang"].error_type) == (
        "error", "timed out after 1.5 s", "Timeout"
    )
    assert [by[n].status for n in ("good1", "good2", "good3")] == ["pass"] * 3
    assert res.exit_code == 2 and res.summary_csv.is_file() and (tmp_path / "junit.xml").is_file()
    rows = list(csv.DictReader(res.summary_csv.open()))
    assert (rows[1]["name"], rows[1]["status"]) == ("hang", "error")
    assert rows[1]["error"] == "timed out after 1.5 s"
    pid = int((tmp_path / "in" / "hang.pid").read_text())
    with pytest.raises(ProcessLookupError):  # the hung worker was killed and reaped
        os.kill(pid, 0)
    # what the killed worker was writing is gone; the batch folder holds only complete results
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        RUN_MARKER, "batch.json", "good1", "good2", "good3", "summary.csv", "summary.md"
    ]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(TMP_PREFIX)]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")
def test_a_killed_batch_leaves_no_worker_behind(tmp_path: Path) -> None:
    import subprocess

    script = (
        "import sys; from pathlib import Path; sys.path.insert(0, sys.argv[1]); import test_batch\n"
        "if __name__ == '__main__':\n"
        "    test_batch.fake_batch(Path(sys.argv[2]), {'hang': 'HANG'})\n"
    )
    batch = subprocess.Popen([sys.executable, "-c", script, str(Path(__file__).parent), str(tmp_path)])
    pid_file = tmp_path / "in" / "hang.pid"
    try:
        deadline = time.monotonic() + 60
        while not pid_file.is_file() or not pid_file.read_text():
            assert time.monotonic() < deadline and batch.poll() is None, "the worker never started"
            time.sleep(0.05)
    finally:
        batch.kill()  # SIGKILL: the batch process runs no clean-up of its own
        batch.wait()
    worker = int(pid_file.read_text())
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.kill(worker, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        os.kill(worker, signal.SIGKILL)
        pytest.fail("the worker outlived the killed batch")


def test_timeout_must_be_positive(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="timeout must be a positive number of seconds, got 0"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, timeout_s=0)


def test_an_earlier_batch_folder_is_kept_unless_overwrite(tmp_path: Path) -> None:
    first = fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, junit=tmp_path / "out" / "junit.xml")
    assert first.out_dir == tmp_path / "out" and (tmp_path / "out" / RUN_MARKER).is_file()
    assert first.junit == tmp_path / "out" / "junit.xml" and first.junit.is_file()
    before = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir() if p.is_file()}
    second = fake_batch(tmp_path, {"a": "GOOD 2 1.0 0"}, junit=tmp_path / "out" / "junit.xml")
    assert second.out_dir == tmp_path / "out-2"  # beside it, not over it
    assert second.junit == tmp_path / "out-2" / "junit.xml"  # the JUnit file moves with its folder
    assert second.results[0].run_dir == tmp_path / "out-2" / "a" and second.results[0].ticks == 2
    assert {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir() if p.is_file()} == before
    third = fake_batch(tmp_path, {"a": "GOOD 3 1.0 0"}, overwrite=True)
    assert third.out_dir == tmp_path / "out" and third.results[0].run_dir == tmp_path / "out" / "a"
    assert json.loads((tmp_path / "out" / "a" / "summary.json").read_text())["ticks"] == 3
    assert not (tmp_path / "out" / "junit.xml").exists()  # replaced as a whole
    assert (tmp_path / "out-2" / "a").is_dir()


def test_unsafe_batch_folders_are_refused_before_any_work(tmp_path: Path) -> None:
    user = tmp_path / "mine"
    (user / "notes.txt").parent.mkdir()
    (user / "notes.txt").write_text("keep me")
    with pytest.raises(OutputError, match=r"mine: exists, is not empty and was not written by gndreplay"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, out="mine")
    assert [p.name for p in user.iterdir()] == ["notes.txt"] and (user / "notes.txt").read_text() == "keep me"
    with pytest.raises(OutputError, match=r"contains the input"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, out="in")  # the inputs are written to tmp_path/in
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match=r"file: is a file"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, out="file")
    with pytest.raises(OutputError, match=r"is a folder; --junit must name a file"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, out="o", junit=user)
    assert not (tmp_path / "o").exists() and (tmp_path / "file").read_text() == "x"
    assert sorted(p.name for p in (tmp_path / "in").iterdir()) == ["a.clf"]


def test_a_folder_search_skips_gndreplay_outputs(tmp_path: Path) -> None:
    write_input(tmp_path / "logs", "a.clf", "GOOD 1 1.0 0")
    res = fake_batch(tmp_path, {"b": "GOOD 1 1.0 0"}, out="logs/results")
    (res.out_dir / "b" / "results.mcap").write_bytes(b"")  # what `--mcap` adds to a run directory
    assert [j.name for j in expand_inputs([tmp_path / "logs"])] == ["a"]


@pytest.mark.parametrize(("umask", "mode"), [(0o022, 0o644), (0o077, 0o600)])
def test_result_files_get_the_usual_permissions(tmp_path: Path, umask: int, mode: int) -> None:
    old = os.umask(umask)
    try:
        res = fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, junit=tmp_path / "j" / "junit.xml")
    finally:
        os.umask(old)
    for path in (res.summary_csv, res.summary_md, tmp_path / "j" / "junit.xml"):
        assert stat.S_IMODE(path.stat().st_mode) == mode, path


def test_batch_exit_code_1_when_a_threshold_is_exceeded(tmp_path: Path) -> None:
    th = Thresholds(limits={"reactor_p99_ms": 1.5, "emergency_stops": 0})
    res = fake_batch(tmp_path, {"fast": "GOOD 3 1.0 0", "slow": "GOOD 3 2.0 1"}, thresholds=th)
    assert [(r.name, r.status, r.failures) for r in res.results] == [
        ("fast", "pass", ()),
        ("slow", "fail", ("reactor_p99_ms 2 > 1.5", "emergency_stops 1 > 0")),
    ]
    assert res.exit_code == 1
    assert fake_batch(tmp_path, {"fast": "GOOD 3 1.0 0"}, thresholds=th).exit_code == 0


def test_make_tasks_folds_goals_and_rejects_duplicate_names() -> None:
    common: dict[str, Any] = {
        "cfg": None,
        "options": FakeOptions(),
        "thresholds": Thresholds(),
        "out_dir": Path("out"),
    }
    tasks = make_tasks([Job("a", Path("a.clf"), goal_xy=(1.0, 2.0)), Job("b", Path("x/../b.clf"))], **common)
    assert [t.options for t in tasks] == [FakeOptions((1.0, 2.0)), FakeOptions()]
    assert tasks[0].run_dir == Path.cwd() / "out" / "a"  # absolute: workers may run elsewhere
    assert tasks[1].job.path == Path.cwd() / "b.clf"
    assert tasks[1].limits == dict(DEFAULT_LIMITS)
    with pytest.raises(ConfigError, match=r"input name 'a' is empty, repeated"):
        make_tasks([Job("a", Path("a.clf")), Job("a", Path("b.clf"))], **common)
    with pytest.raises(ConfigError, match=r"input name 'x/y' .* contains '/'"):
        make_tasks([Job("x/y", Path("a.clf"))], **common)
    with pytest.raises(ConfigError, match="no inputs"):
        make_tasks([], **common)
    with pytest.raises(ConfigError, match="workers must be >= 1, got 0"):
        run_tasks(tasks, workers=0, runner=fake_runner)


def test_make_tasks_gives_figures_to_logs_only() -> None:
    """``figures`` is a log's switch; a scenario run's figures come from its ``SimOptions``."""
    jobs = [Job("a", Path("a.clf")), Job("s", Path("s.yaml"), kind="scenario")]
    common: dict[str, Any] = {"cfg": None, "options": FakeOptions(), "thresholds": Thresholds(),
                              "out_dir": Path("out")}
    assert [t.figures for t in make_tasks(jobs, **common)] == [False, False]
    assert [t.figures for t in make_tasks(jobs, figures=True, **common)] == [True, False]


def test_execute_in_process_captures_errors(tmp_path: Path) -> None:
    bad = write_input(tmp_path, "bad.clf", "BAD")
    cfg: Any = None
    options: Any = FakeOptions()
    task = Task(Job("bad", bad), cfg=cfg, options=options, run_dir=tmp_path / "o")
    r = execute(task, fake_runner)
    assert (r.status, r.error_type, r.run_dir) == ("error", "LogFormatError", None)


def test_dask_missing_is_a_config_error_naming_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ConfigError, match=r'pip install "gndreplay\[dask\]"'):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, dask_address="tcp://127.0.0.1:1")


def deterministic(results: tuple[InputResult, ...]) -> list[tuple[Any, ...]]:
    """The parts of results that do not depend on timing (latencies, wall-clock over-budget counts, and their
    values in failures)."""
    return [
        (
            r.name,
            r.status,
            r.ticks,
            r.error,
            tuple(f.split()[0] for f in r.failures),
            {k: v for k, v in r.metrics.items() if not k.endswith(("_ms", "_over_budget"))},
        )
        for r in results
    ]


def test_dask_gives_the_process_pool_results(tmp_path: Path, dask_cluster: Any) -> None:
    specs = {"good1": "GOOD 7 1.0 0", "bad": "BAD", "crash": "CRASH", "good2": "GOOD 9 2.0 1"}
    pool = fake_batch(tmp_path, specs, out="pool", workers=2)
    dask = fake_batch(tmp_path, specs, out="dask", dask_address=dask_cluster.scheduler_address)
    assert deterministic(dask.results) == deterministic(pool.results)
    assert [r.status for r in dask.results] == ["pass", "error", "error", "pass"]
    assert dask.results[0].run_dir == (tmp_path / "dask" / "good1").absolute()
    assert dask.exit_code == pool.exit_code == 2


def test_dask_times_out_a_hung_input_and_restarts_its_worker(tmp_path: Path, dask_cluster: Any) -> None:
    specs = {"good1": "GOOD 7 1.0 0", "hang": "HANG", "good2": "GOOD 9 2.0 1"}
    res = fake_batch(tmp_path, specs, out="dask", dask_address=dask_cluster.scheduler_address, timeout_s=2)
    assert [(r.name, r.status, r.error) for r in res.results] == [
        ("good1", "pass", ""), ("hang", "error", "timed out after 2 s"), ("good2", "pass", "")
    ]
    pid = int((tmp_path / "in" / "hang.pid").read_text())
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:  # the restart of the worker process is asynchronous
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        pytest.fail("the dask worker running the hung input was not stopped")


# ---------------------------------------------------------------- the command


def capture_run_batch(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Replace ``run_batch`` by a stand-in recording the keywords the command passes it (an empty batch)."""
    import gndreplay.batch
    from gndreplay.batch import BatchResult

    seen: dict[str, Any] = {}

    def capture(jobs: Any, **kw: Any) -> BatchResult:
        seen.update(kw)
        return BatchResult((), tmp_path, tmp_path / "s.csv", tmp_path / "s.md", None, 0.0)

    monkeypatch.setattr(gndreplay.batch, "run_batch", capture)
    return seen


def test_cli_batch_takes_the_read_options_of_run_and_a_timeout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from typer.testing import CliRunner

    from gndreplay.cli import app
    from gndreplay.io import ReadOptions

    seen = capture_run_batch(tmp_path, monkeypatch)
    log = write_input(tmp_path, "a.bag", "")
    args = ["batch", str(log), "--format", "rosbag1", "--scan-topic", "/scan", "--odom-topic", "/tf",
            "--cmd-topic", "/cmd_vel", "--truth-topic", "/truth", "--strict", "--timeout", "12.5",
            "--overwrite", "--preset", "XR4000", "--quiet"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert seen["read"] == ReadOptions(fmt="rosbag1", scan_topic="/scan", odom_topic="/tf",
                                       cmd_topic="/cmd_vel", truth_topic="/truth", strict=True)
    assert seen["timeout_s"] == 12.5 and seen["overwrite"] is True
    assert seen["cfg"].preset == "xr4000"  # preset names are case-insensitive
    assert CliRunner().invoke(app, ["batch", str(log), "--timeout", "0"]).exit_code == 2  # typer: min


@pytest.mark.parametrize(
    ("flag", "logs", "scenarios"),
    [((), False, True), (("--figures",), True, True), (("--no-figures",), False, False)],
)
def test_cli_batch_figures_default_to_scenario_runs_only(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, flag: tuple[str, ...], logs: bool, scenarios: bool
) -> None:
    from typer.testing import CliRunner

    from gndreplay.cli import app

    seen = capture_run_batch(tmp_path, monkeypatch)
    log = write_input(tmp_path, "a.clf", "")
    result = CliRunner().invoke(app, ["batch", str(log), *flag, "--quiet"])
    assert result.exit_code == 0, result.output
    assert (seen["figures"], seen["sim"].figures) == (logs, scenarios)


def test_cli_batch_format_reaches_the_worker(tmp_path: Path) -> None:
    """Without --format a .txt input is refused with a hint to use --format, which batch has; with
    ``--format carmen`` the worker reads it as CARMEN and says why it is not one."""
    from typer.testing import CliRunner

    from gndreplay.cli import app

    log = write_input(tmp_path, "notes.txt", "hello\n")
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["batch", str(log), "--out", str(out), "--format", "carmen", "--quiet"])
    assert result.exit_code == 2
    assert result.stderr.startswith(f"gndreplay: error: notes.txt: {log.absolute()}: not a CARMEN log")
    row = next(csv.DictReader((out / "summary.csv").open()))
    assert (row["name"], row["status"]) == ("notes.txt", "error") and "not a CARMEN log" in row["error"]


# ---------------------------------------------------------------- real runs


def corrupted_inputs(folder: Path) -> list[Path]:
    """A truncated .bz2 log (the sample log's first 1000 bytes) and a .bag of random bytes."""
    truncated = folder / "truncated.clf.bz2"
    truncated.write_bytes(SAMPLE_LOG.read_bytes()[:1000])
    garbage = folder / "garbage.bag"
    garbage.write_bytes(bytes(range(256)) * 8)
    return [truncated, garbage]


def real_batch(tmp_path: Path, out: str, **kw: Any) -> Any:
    """The sample log (10 s), the same log under a threshold it cannot meet, and two corrupted files."""
    from gndreplay.config import Config
    from gndreplay.replay import RunOptions

    jobs = [Job("office", SAMPLE_LOG), Job("office-strict", SAMPLE_LOG)]
    jobs += expand_inputs(corrupted_inputs(tmp_path))
    th = load_thresholds(write_toml(tmp_path, '[inputs."*-strict"]\nreactor_p99_ms = 0.0001\n'))
    return run_batch(
        jobs, cfg=Config(), options=RunOptions(until_s=10.0), thresholds=th, out_dir=tmp_path / out, **kw
    )


def test_real_batch_good_log_passes_corrupted_inputs_fail_alone(tmp_path: Path) -> None:
    seen: list[str] = []
    res = real_batch(
        tmp_path,
        "out",
        workers=2,
        junit=tmp_path / "out" / "junit.xml",
        progress=lambda r: seen.append(r.name),
    )
    office, strict, truncated, garbage = res.results
    assert sorted(seen) == sorted(r.name for r in res.results)
    # the good input: a complete run directory whose summary is the row
    assert office.status == "pass" and office.failures == () and office.error == ""
    assert office.run_dir == (tmp_path / "out" / "office").absolute()
    summary = json.loads((office.run_dir / "summary.json").read_text())
    assert office.ticks == summary["ticks"] == 51  # 5 Hz scans, t = 0 .. 10 s
    assert office.metrics["reactor_p99_ms"] == summary["latency_ms"]["reactor"]["p99"]
    assert office.metrics["emergency_stops"] == summary["flags"]["EMERGENCY_STOP"]
    assert len((office.run_dir / "commands.csv").read_text().splitlines()) == 1 + office.ticks
    # the same log under an impossible threshold fails with the measured value
    assert strict.status == "fail" and strict.ticks == 51
    assert strict.failures == (f"reactor_p99_ms {strict.metrics['reactor_p99_ms']:.4g} > 0.0001",)
    # the corrupted inputs: one-line errors naming the file, no run directory
    assert (truncated.status, truncated.error_type, truncated.run_dir) == ("error", "LogFormatError", None)
    assert truncated.error.startswith(f"{(tmp_path / 'truncated.clf.bz2').absolute()}: truncated or corrupt")
    assert garbage.status == "error" and garbage.error.startswith(
        f"{(tmp_path / 'garbage.bag').absolute()}: "
    )
    assert "\n" not in truncated.error + garbage.error
    assert not (tmp_path / "out" / "truncated").exists()
    assert res.exit_code == 2
    # JUnit: valid XML with the right counts and messages
    suite = ET.parse(tmp_path / "out" / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("4", "1", "2")
    cases = {c.get("name"): c for c in suite.findall("testcase")}
    assert list(cases) == ["office", "office-strict", "truncated", "garbage"]
    failure, error = cases["office-strict"].find("failure"), cases["truncated"].find("error")
    assert failure is not None and failure.get("message") == strict.failures[0]
    assert error is not None and error.get("message") == truncated.error
    rows = list(csv.DictReader((tmp_path / "out" / "summary.csv").open()))
    assert [(r["name"], r["status"], r["ticks"]) for r in rows] == [
        ("office", "pass", "51"),
        ("office-strict", "fail", "51"),
        ("truncated", "error", "0"),
        ("garbage", "error", "0"),
    ]


def test_real_batch_draws_a_logs_figures_when_asked(tmp_path: Path) -> None:
    """With ``figures`` a log's run directory gets what ``gndreplay run`` draws: maps.npz, the figures and
    report.md; without, none of them."""
    from gndreplay.config import Config
    from gndreplay.replay import RunOptions
    from gndreplay.report import FIGURES, MAPS_FILE, REPORT_FILE

    drawn = {MAPS_FILE, REPORT_FILE, *FIGURES}
    for figures in (True, False):
        res = run_batch([Job("office", SAMPLE_LOG)], cfg=Config(), options=RunOptions(until_s=2.0),
                        out_dir=tmp_path / f"out-{figures}", figures=figures)
        (office,) = res.results
        assert office.status == "pass" and office.run_dir is not None
        names = {p.name for p in office.run_dir.iterdir()}
        assert (drawn & names) == (drawn if figures else set())


def test_real_batch_on_dask_matches_the_process_pool(tmp_path: Path, dask_cluster: Any) -> None:
    pool = real_batch(tmp_path, "pool", workers=2)
    dask = real_batch(tmp_path, "dask", dask_address=dask_cluster.scheduler_address)
    assert deterministic(dask.results) == deterministic(pool.results)
    assert [r.status for r in dask.results] == ["pass", "fail", "error", "error"]
    for name in ("office", "office-strict"):  # byte-identical outputs
        for file in ("commands.csv", "trajectory_corrected.tum"):
            assert (tmp_path / "dask" / name / file).read_bytes() == (
                tmp_path / "pool" / name / file
            ).read_bytes()
    assert dask.exit_code == pool.exit_code == 2


@pytest.mark.slow
def test_dev_log_scan_match_error_against_its_relations(tmp_path: Path, datasets: Path) -> None:
    from gndreplay.config import Config
    from gndreplay.replay import RunOptions

    th = tmp_path / "limits.toml"
    th.write_text(
        f'[inputs."mit-csail*"]\nrelations = "{datasets / "relations" / "mit-csail.relations"}"\n'
        "match_trans_err_mean_m = 0.5\nmin_relations_matched = 50\n"
    )
    jobs = expand_inputs(
        [datasets / "carmen" / "mit-csail.clf.bz2", datasets / "rosbag1" / "mit-csail.sort.bag"]
    )
    res = run_batch(
        jobs,
        cfg=Config(),
        options=RunOptions(until_s=120.0),
        thresholds=load_thresholds(th),
        out_dir=tmp_path / "out",
        workers=2,
    )
    carmen, bag = res.results
    for r in (carmen, bag):
        assert r.status == "pass", r.failures or r.error
        assert r.metrics["relations_matched"] >= 50
        assert 0.0 < r.metrics["match_trans_err_mean_m"] < 0.5
    # the bag carries the same scans as the CARMEN log: the same relations match
    assert carmen.metrics["relations_matched"] == bag.metrics["relations_matched"]
    assert res.exit_code == 0


@pytest.mark.slow
def test_cli_batch_over_the_dev_logs_and_a_corrupted_file(tmp_path: Path, datasets: Path) -> None:
    """The issue's check through the real command: good inputs pass, the corrupted one is reported with its
    one-line error, exit code 2, and the JUnit XML parses with one test case per input."""
    import xml.etree.ElementTree as ET

    from typer.testing import CliRunner

    from gndreplay.cli import app

    broken = tmp_path / "broken.clf.bz2"
    broken.write_bytes((datasets / "carmen" / "mit-csail.clf.bz2").read_bytes()[:50_000])
    junit = tmp_path / "junit.xml"
    inputs = [str(datasets / "carmen"), str(datasets / "rosbag1" / "mit-csail.sort.bag"), str(broken)]
    args = ["batch", *inputs, "--jobs", "2", "--until", "30", "--out", str(tmp_path / "batch"),
            "--junit", str(junit), "--quiet"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    errors = [line for line in result.stderr.splitlines() if line.startswith("gndreplay: error:")]
    assert len(errors) == 1 and "broken" in errors[0] and "Traceback" not in result.output
    suite = ET.parse(junit).getroot()
    suite = suite if suite.tag == "testsuite" else suite.find("testsuite")
    assert suite is not None
    cases = suite.findall("testcase")
    n_carmen = len(expand_inputs([datasets / "carmen"]))  # every CARMEN dev log there
    assert len(cases) == n_carmen + 2
    assert [c.get("name") for c in cases if c.find("error") is not None] == ["broken"]
    assert all(c.find("failure") is None for c in cases)
    rows = (tmp_path / "batch" / "summary.csv").read_text().splitlines()
    assert len(rows) == 1 + n_carmen + 2 and sum(",pass," in r for r in rows) == n_carmen + 1


def test_largest_inputs_are_submitted_first(tmp_path: Path) -> None:
    from gndreplay.batch.run import largest_first

    sizes = {"small.clf": 10, "big.clf": 1000, "mid.clf": 100, "tie.clf": 100}
    for name, n in sizes.items():
        (tmp_path / name).write_bytes(b"x" * n)
    from gndreplay.config import Config
    from gndreplay.replay import RunOptions

    jobs = expand_inputs([tmp_path / n for n in sizes])
    tasks = make_tasks(jobs, cfg=Config(), options=RunOptions(), thresholds=Thresholds(), out_dir=tmp_path)
    assert [tasks[i].job.name for i in largest_first(tasks)] == ["big", "mid", "tie", "small"]


# ---------------------------------------------------------------- review F1: --junit, --overwrite, budgets


def test_junit_never_replaces_a_file_gndreplay_did_not_write(tmp_path: Path) -> None:
    mine = tmp_path / "mine.txt"
    mine.write_text("important\n")
    with pytest.raises(OutputError, match=r"mine\.txt: exists and is not a JUnit file gndreplay wrote"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, junit=mine)
    assert mine.read_text() == "important\n" and not (tmp_path / "out").exists()  # refused before any work
    log = write_input(tmp_path / "in", "a.clf", "GOOD 1 1.0 0")
    with pytest.raises(OutputError, match=r"a\.clf: is the input"):
        fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, junit=log)
    assert log.read_text() == "GOOD 1 1.0 0"
    junit = tmp_path / "reports" / "junit.xml"
    first = fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, junit=junit)
    assert first.junit == junit and "<testsuites name=\"gndreplay batch\"" in junit.read_text()
    with pytest.raises(OutputError, match=r"junit\.xml: exists \(an earlier batch's JUnit file\)"):
        fake_batch(tmp_path, {"a": "GOOD 2 1.0 0"}, out="o2", junit=junit)
    third = fake_batch(tmp_path, {"a": "GOOD 7 1.0 0"}, out="o3", junit=junit, overwrite=True)
    assert third.junit == junit and "ticks: 7" in junit.read_text()


def test_overwrite_refuses_a_batch_folder_with_a_user_file_inside_a_run_folder(tmp_path: Path) -> None:
    fake_batch(tmp_path, {"a": "GOOD 1 1.0 0"}, junit=tmp_path / "out" / "reports" / "junit.xml")
    notes = tmp_path / "out" / "a" / "my_notes.txt"
    notes.write_text("notes\n")
    before = snapshot_files(tmp_path / "out")
    with pytest.raises(OutputError, match=r"out: holds files gndreplay did not write \(a/my_notes\.txt\)"):
        fake_batch(tmp_path, {"a": "GOOD 2 1.0 0"}, overwrite=True)
    assert snapshot_files(tmp_path / "out") == before
    notes.unlink()  # without it the folder is all gndreplay's (the JUnit subfolder included): replaced
    again = fake_batch(tmp_path, {"a": "GOOD 3 1.0 0"}, overwrite=True)
    assert again.out_dir == tmp_path / "out" and again.results[0].ticks == 3


def snapshot_files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_over_budget_metrics_come_from_the_over_budget_table() -> None:
    data = {**fake_summary(12, 9.5, 2), "over_budget": {"REACTOR_OVER_BUDGET": 4, "PLANNER_OVER_BUDGET": 1,
                                                       "MODEL_OVER_BUDGET": 0, "MATCH_OVER_BUDGET": 7}}
    m = metrics_from_summary(data)
    assert (m["reactor_over_budget"], m["planner_over_budget"], m["model_over_budget"],
            m["match_over_budget"]) == (4, 1, 0, 7)
    assert check_limits(m, {"reactor_over_budget": 3}) == ("reactor_over_budget 4 > 3",)
    assert metrics_from_summary(fake_summary(1, 1.0, 0))["reactor_over_budget"] == 0  # no table: 0
