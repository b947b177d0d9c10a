"""gndreplay batch against a baseline (behaviour and latency checks per input, summary.md, JUnit) and
parameter sweeps (``--set key=a,b``): the pure parts first, then short real batches on the sample log and a
shipped scenario.

The JUnit files are validated against junit-10.xsd (tests/data), the JUnit schema of Jenkins' xunit
plugin (MIT licence, in its header), which pytest's own tests use for its JUnit output and which GitLab
and GitHub's JUnit reporters accept.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from gndreplay.batch import InputResult, junit_xml
from gndreplay.batch.baseline import BaselineCheck, check_baseline
from gndreplay.batch.sweep import MAX_COMBINATIONS, split_values, sweep_points
from gndreplay.cli import app
from gndreplay.errors import ConfigError
from gndreplay.fsutil import RUN_MARKER
from gndreplay.report.compare import Tolerance, compare_runs, load_compare_run

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_LOG = ROOT / "sample_logs" / "office.clf.bz2"
SCHEMA = Path(__file__).resolve().parent / "data" / "junit-10.xsd"
#: A short batch: the sample log's first 20 s and a scenario's first 12 s (both diverge under a changed
#: security distance, well before their ends).
BATCH = [str(SAMPLE_LOG), "--scenarios", "u_trap", "--seeds", "1", "--until", "20", "--time-limit", "12",
         "--progress", "none", "--jobs", "2", "--no-figures"]


def cli(*args: str) -> Any:
    return CliRunner().invoke(app, [*args])


def validate_junit(text: str) -> None:
    xmlschema = pytest.importorskip("xmlschema")
    xmlschema.XMLSchema(str(SCHEMA)).validate(text)


def rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


# ---------------------------------------------------------------- sweeps: the combinations


def test_a_set_without_a_list_is_one_unnamed_point() -> None:
    (point,) = sweep_points(["reactor.security_m=0.4", "planner.kind=tunnel"])
    assert point.name == "" and point.values == ()
    assert point.sets == ("reactor.security_m=0.4", "planner.kind=tunnel")


def test_the_cross_product_keeps_the_order_and_the_fixed_pairs() -> None:
    points = sweep_points(["reactor.security_m=0.3,0.5", "planner.kind=tunnel", "robot.vmax_mps=0.3, 0.5, 1"])
    assert len(points) == 6
    assert [p.values for p in points[:3]] == [
        (("reactor.security_m", "0.3"), ("robot.vmax_mps", v)) for v in ("0.3", "0.5", "1")
    ]
    assert points[4].sets == ("reactor.security_m=0.5", "planner.kind=tunnel", "robot.vmax_mps=0.5")
    assert points[0].name == "reactor.security_m=0.3,robot.vmax_mps=0.3"
    assert len({p.name for p in points}) == 6


def test_commas_inside_brackets_and_quotes_do_not_split() -> None:
    assert split_values("[1, 2], [3, 4]") == ["[1, 2]", "[3, 4]"]
    assert split_values('"a,b", c') == ['"a,b"', "c"]
    (point,) = sweep_points(["robot.footprint=[[0, 1], [2, 3]]"])
    assert point.name == ""
    assert len(sweep_points(['x.name="a,b","c"'])) == 2


def test_folder_names_are_safe_and_unique() -> None:
    points = sweep_points(['x.s="a/b","a?b"'])
    assert all("/" not in p.name and "?" not in p.name and p.name for p in points)
    assert len({p.name for p in points}) == 2


@pytest.mark.parametrize(
    ("sets", "match"),
    [
        (["a.b=1,,2"], "empty value"),
        (["a.b=1,2,1"], "listed twice"),
        (["a.b=1,2", "a.b=3,4"], "swept twice"),
        (["a.b=[1,2"], "unclosed"),
        (["a.b=1]"], "unbalanced"),
        ([f"a.k{i}=1,2" for i in range(10)] + ["a.z=1,2"], f"more than {MAX_COMBINATIONS}"),
    ],
)
def test_bad_sweeps_are_one_config_error(sets: list[str], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        sweep_points(sets)


def test_a_sweep_value_is_validated_like_a_toml_key_before_anything_runs(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = cli("batch", str(SAMPLE_LOG), "--out", str(out), "--set", "reactor.security_m=0.3,-1", "--quiet")
    assert result.exit_code == 2
    assert "reactor.security_m" in result.output and "Traceback" not in result.output
    assert not out.exists()


# ---------------------------------------------------------------- sweeps: a real batch


def test_a_sweep_runs_every_input_under_each_combination(tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    result = cli("batch", str(SAMPLE_LOG), "--until", "6", "--jobs", "2", "--progress", "none",
                 "--out", str(out), "--set", "reactor.security_m=0.3,0.5", "--set", "robot.vmax_mps=0.3,0.4",
                 "--set", "planner.kind=tunnel", "--junit", str(out / "junit.xml"))
    assert result.exit_code == 0, result.output
    table = rows(out / "sweep.csv")
    assert [(r["reactor.security_m"], r["robot.vmax_mps"]) for r in table] == [
        ("0.3", "0.3"), ("0.3", "0.4"), ("0.5", "0.3"), ("0.5", "0.4")]
    assert all(r["inputs"] == "1" and r["pass"] == "1" for r in table)
    summary = rows(out / "summary.csv")
    assert [r["variant"] for r in summary] == [p.name for p in sweep_points(
        ["reactor.security_m=0.3,0.5", "robot.vmax_mps=0.3,0.4"])]
    for r in summary:  # each run ran under its own combination (its config.toml says so) and the fixed pair
        config = (out / r["variant"] / "office" / "config.toml").read_text()
        security, vmax = (kv.split("=")[1] for kv in r["variant"].split(","))
        assert f"security_m = {security}" in config and f"vmax_mps = {vmax}" in config
        assert 'kind = "tunnel"' in config
    assert "## Sweep" in (out / "summary.md").read_text()
    validate_junit((out / "junit.xml").read_text())
    # the batch folder and each combination's folder list what gndreplay wrote: --overwrite may replace them
    assert cli("batch", str(SAMPLE_LOG), "--until", "2", "--progress", "none", "--out", str(out),
               "--overwrite", "--quiet").exit_code == 0
    assert (out / RUN_MARKER).exists() and not any(out.glob("reactor*"))


# ---------------------------------------------------------------- the baseline: real batches


@pytest.fixture(scope="module")
def baseline(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A baseline batch folder written by --update-baseline (the first one: nothing to compare with)."""
    folder = tmp_path_factory.mktemp("ci") / "baseline"
    result = cli("batch", *BATCH, "--baseline", str(folder), "--update-baseline", "--quiet")
    assert result.exit_code in (0, 1), result.output  # 1: the scenario does not reach its goal in 12 s
    assert (folder / "summary.csv").is_file() and (folder / RUN_MARKER).is_file()
    return folder


def test_identical_batches_are_the_same_and_pass(baseline: Path, tmp_path: Path) -> None:
    out = tmp_path / "again"
    result = cli("batch", *BATCH, "--out", str(out), "--baseline", str(baseline),
                 "--junit", str(out / "j.xml"), "--latency-ratio", "0",
                 "--thresholds", str(_no_success_limit(tmp_path)))
    assert result.exit_code == 0, result.output
    md = (out / "summary.md").read_text()
    assert "2 inputs against the baseline: 0 behaviour changed, 0 slower, 0 new, 0 unreadable" in md
    assert "| office | same | - | - |" in md and "| u_trap-s1 | same | - | - |" in md
    junit = (out / "j.xml").read_text()
    validate_junit(junit)
    assert junit.count('classname="gndreplay.batch.baseline.behaviour"') == 2
    assert junit.count('classname="gndreplay.batch.baseline.latency"') == 2


def _no_success_limit(tmp_path: Path) -> Path:
    path = tmp_path / "limits.toml"
    path.write_text("[thresholds]\nmin_success = false\n")
    return path


def _first_differing_row(a: Path, b: Path) -> tuple[int, str]:
    """(index, t) of the first commands.csv row whose behaviour columns differ, read independently of the
    compare code (every column but none: commands.csv holds no timing)."""
    ra, rb = rows(a), rows(b)
    for k, (x, y) in enumerate(zip(ra, rb, strict=False)):
        assert x["t"] == y["t"]
        if x != y:
            return k, x["t"]
    raise AssertionError("no row differs")


def test_a_changed_security_distance_fails_with_its_first_divergent_tick_and_stage(
    baseline: Path, tmp_path: Path
) -> None:
    out = tmp_path / "changed"
    result = cli("batch", *BATCH, "--out", str(out), "--baseline", str(baseline),
                 "--junit", str(out / "j.xml"), "--set", "reactor.security_m=0.4", "--latency-ratio", "0",
                 "--thresholds", str(_no_success_limit(tmp_path)))
    assert result.exit_code == 1, result.output
    for name in ("office", "u_trap-s1"):
        k, t = _first_differing_row(baseline / name / "commands.csv", out / name / "commands.csv")
        c = compare_runs(load_compare_run(baseline / name), load_compare_run(out / name), Tolerance())
        assert c.divergence is not None and c.divergence.index_b == k
        assert c.divergence.t_s == pytest.approx(float(t), abs=1e-9)
        assert c.stage is not None
        line = next(x for x in (out / "summary.md").read_text().splitlines() if x.startswith(f"| {name} |"))
        assert "DIFFERENT" in line and f"(tick {k})" in line and f"first stage {c.stage.stage}" in line
        assert f"fail: {name}: behaviour differs from the baseline" in result.output
    scenario = next(x for x in (out / "summary.md").read_text().splitlines() if x.startswith("| u_trap-s1 |"))
    assert "min_clearance_m" in scenario  # the outcome's scores changed with it
    junit = (out / "j.xml").read_text()
    validate_junit(junit)
    assert junit.count('type="baseline-behaviour"') == 2 and 'type="baseline-latency"' not in junit


def test_a_slowed_module_fails_the_latency_check_not_the_behaviour_check(
    baseline: Path, tmp_path: Path
) -> None:
    here = tmp_path / "slow"
    shutil.copytree(baseline, here)
    timing = here / "office" / "timing.csv"
    table = rows(timing)
    for r in table:
        r["planner_ms"] = repr(3.0 * float(r["planner_ms"]))
    with open(timing, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(table)
    result = InputResult(name="office", path=str(SAMPLE_LOG), status="pass", run_dir=here / "office")
    (check,) = check_baseline([result], batch_dir=here, runs_dir=here, baseline=baseline,
                              tolerance=Tolerance(), max_ratio=1.5)
    assert check.behaviour_failure == "" and check.divergence == ""
    assert check.latency_failure.startswith("planner median")
    assert "3.00x the baseline" in check.latency_failure
    assert check.slowest_module == "planner" and check.latency_ratio == pytest.approx(3.0, rel=1e-6)
    assert check.verdict == "slower"
    (unjudged,) = check_baseline([result], batch_dir=here, runs_dir=here, baseline=baseline,
                                 tolerance=Tolerance(), max_ratio=0.0)
    assert unjudged.latency_failure == "" and unjudged.verdict == "same"


def test_new_and_missing_inputs_are_reported_not_failed(baseline: Path, tmp_path: Path) -> None:
    out = tmp_path / "other"
    result = cli("batch", str(SAMPLE_LOG), "--until", "20", "--progress", "none", "--no-figures",
                 "--out", str(out), "--baseline", str(baseline), "--scenarios", "enclosed", "--seeds", "1",
                 "--time-limit", "3",
                 "--thresholds", str(_no_success_limit(tmp_path)), "--latency-ratio", "0",
                 "--junit", str(out / "j.xml"))
    assert result.exit_code == 0, result.output
    md = (out / "summary.md").read_text()
    assert "| enclosed-s1 | new |" in md
    assert "Not in this batch: u_trap-s1" in md
    junit = (out / "j.xml").read_text()
    validate_junit(junit)
    assert junit.count("<skipped") == 2  # behaviour and latency of the new input


def test_update_baseline_replaces_only_a_gndreplay_folder(baseline: Path, tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    result = cli("batch", str(SAMPLE_LOG), "--until", "2", "--progress", "none", "--baseline", str(mine),
                 "--update-baseline", "--quiet")
    assert result.exit_code == 2 and (mine / "notes.txt").read_text() == "keep me"
    copy = tmp_path / "copy"
    shutil.copytree(baseline, copy)
    result = cli("batch", *BATCH, "--baseline", str(copy), "--update-baseline",
                 "--set", "reactor.security_m=0.4", "--thresholds", str(_no_success_limit(tmp_path)))
    assert result.exit_code == 0, result.output  # the changes are accepted, not failed
    assert "accepted: office: behaviour differs" in result.output
    assert "(accepted: written as the new baseline)" in (copy / "summary.md").read_text()
    assert "security_m = 0.4" in (copy / "office" / "config.toml").read_text()


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--update-baseline"], "--baseline DIR"),
        (["--tolerance", "tol.toml"], "--baseline DIR"),
        (["--baseline", "nowhere"], "no such baseline folder"),
        (["--baseline", "."], "not a gndreplay batch folder"),
    ],
)
def test_baseline_option_errors_are_one_line_and_exit_2(
    args: list[str], match: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    result = cli("batch", str(SAMPLE_LOG), "--until", "2", "--out", "out", *args, "--quiet")
    assert result.exit_code == 2
    assert match in result.output and "Traceback" not in result.output
    assert not (tmp_path / "out").exists()


def test_an_unreadable_baseline_run_is_an_error_check(baseline: Path, tmp_path: Path) -> None:
    broken = tmp_path / "broken"
    shutil.copytree(baseline, broken)
    (broken / "office" / "commands.csv").write_text("t,v\n1,2,3\n")
    result = InputResult(name="office", path=str(SAMPLE_LOG), status="pass", run_dir=baseline / "office")
    (check,) = check_baseline([result], batch_dir=baseline, runs_dir=baseline, baseline=broken,
                              tolerance=Tolerance(), max_ratio=1.5)
    assert check.verdict == "error" and "commands.csv" in check.error


# ---------------------------------------------------------------- JUnit against the schema


def test_every_kind_of_junit_case_is_valid_against_the_schema() -> None:
    results = [
        InputResult(name="a", path="/logs/a.clf", status="pass", ticks=3, metrics={"stack_p99_ms": 1.0}),
        InputResult(name="b", path="/logs/b.clf", status="fail", failures=("reactor_p99_ms 9 > 8",),
                    variant="reactor.security_m=0.3"),
        InputResult(name="c", path="/logs/c\x01.clf", status="error", error="bad <log> & \x02",
                    error_type="LogFormatError"),
    ]
    checks = [
        BaselineCheck("a", divergence="", latency_ratio=1.01, slowest_module="total"),
        BaselineCheck("reactor.security_m=0.3/b", behaviour_failure="differs", latency_failure="slow"),
        BaselineCheck("d", new=True),
        BaselineCheck("e", error="commands.csv: missing"),
    ]
    text = junit_xml(results, checks=checks)
    validate_junit(text)
    assert 'tests="11" failures="3" errors="3"' in text.splitlines()[1]
    assert 'name="reactor.security_m=0.3/b"' in text
    validate_junit(junit_xml(results))


# ---------------------------------------------------------------- a sweep on dask = the process pool


def test_a_20_run_sweep_on_a_dask_cluster_gives_the_process_pools_bytes(
    tmp_path: Path, dask_cluster: Any
) -> None:
    from gndreplay.batch import Setting, SimOptions, expand_inputs, run_batch, sweep_points
    from gndreplay.config import CliOverrides, configure
    from gndreplay.replay import RunOptions

    sets = ["reactor.security_m=0.3,0.4,0.5,0.6,0.7", "robot.vmax_mps=0.3,0.5"]
    settings = [Setting(p, configure(overrides=CliOverrides(sets=p.sets)),
                        SimOptions(time_limit_s=4.0, figures=False, overrides=CliOverrides(sets=p.sets)))
                for p in sweep_points(sets)]
    jobs = expand_inputs([SAMPLE_LOG], scenarios=["u_trap"], seeds=(1,))
    kw: dict[str, Any] = dict(cfg=settings[0].cfg, options=RunOptions(until_s=8.0), sweep=settings)
    pool = run_batch(jobs, out_dir=tmp_path / "pool", workers=2, **kw)
    dask = run_batch(jobs, out_dir=tmp_path / "dask", dask_address=dask_cluster.scheduler_address, **kw)
    assert len(pool.results) == len(dask.results) == 20
    assert all(r.status != "error" for r in (*pool.results, *dask.results))
    for a, b in zip(pool.results, dask.results, strict=True):
        assert a.label == b.label and a.run_dir is not None and b.run_dir is not None
        for name in ("commands.csv", "trajectory_corrected.tum", "trajectory_odom.tum"):
            assert (Path(a.run_dir) / name).read_bytes() == (Path(b.run_dir) / name).read_bytes(), name
    assert len(rows(tmp_path / "pool" / "sweep.csv")) == 10
    drop = ("_ms", "wall_s", "run_dir", "ms_per_step", "ms_per_tick")
    rows_a, rows_b = rows(tmp_path / "pool" / "summary.csv"), rows(tmp_path / "dask" / "summary.csv")
    assert [{k: v for k, v in r.items() if not k.endswith(drop)} for r in rows_a] == [
        {k: v for k, v in r.items() if not k.endswith(drop)} for r in rows_b]


def test_a_sharded_sweep_merged_against_the_unsharded_one_as_baseline(tmp_path: Path) -> None:
    sweep = [str(SAMPLE_LOG), "--until", "4", "--progress", "none", "--quiet",
             "--set", "reactor.security_m=0.3,0.5", "--set", "robot.vmax_mps=0.3,0.4"]
    whole, merged = tmp_path / "whole", tmp_path / "merged"
    assert cli("batch", *sweep, "--out", str(whole)).exit_code == 0
    for i in (0, 1):
        assert cli("batch", *sweep, "--shard", f"{i}/2", "--out", str(tmp_path / f"shard-{i}")).exit_code == 0
    result = cli("batch", "--merge", str(tmp_path / "shard-0"), str(tmp_path / "shard-1"),
                 "--out", str(merged), "--baseline", str(whole), "--latency-ratio", "0",
                 "--junit", str(merged / "j.xml"))
    assert result.exit_code == 0, result.output
    assert "4 inputs against the baseline: 0 behaviour changed" in (merged / "summary.md").read_text()
    validate_junit((merged / "j.xml").read_text())
    timing = "stack p99 ms (worst)"
    assert [{k: v for k, v in r.items() if k != timing} for r in rows(merged / "sweep.csv")] == [
        {k: v for k, v in r.items() if k != timing} for r in rows(whole / "sweep.csv")]
    for r in rows(whole / "summary.csv"):
        run = Path(r["run_dir"])
        assert (merged / run / "commands.csv").read_bytes() == (whole / run / "commands.csv").read_bytes()
