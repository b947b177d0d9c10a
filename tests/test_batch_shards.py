"""Shards of a batch (``--shard I/N``), batch.json, and ``batch --merge``: the selection rule and the index
from the environment, merged shards equal to the unsharded batch byte for byte (fake and real runs, the
process pool and dask), refusals of shards that do not make one batch, and shard folders left untouched."""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from test_batch import FakeOptions, fake_runner, write_input

import gndreplay.batch.run as batch_run
from gndreplay.batch import (
    BATCH_FILE,
    BatchResult,
    InputResult,
    Job,
    Shard,
    SimOptions,
    Thresholds,
    expand_inputs,
    load_thresholds,
    merge_batches,
    parse_shard,
    read_record,
    run_batch,
    shard_indices,
)
from gndreplay.batch.record import BatchRecord, RecordError, record_json
from gndreplay.errors import ConfigError
from gndreplay.fsutil import RUN_MARKER, write_marker

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_LOG = ROOT / "sample_logs" / "office.clf.bz2"
OUTPUTS = ("summary.csv", "summary.md", "scenarios.csv", "junit.xml")

# ---------------------------------------------------------------- the rule and the index


def test_shards_partition_the_inputs_round_robin() -> None:
    assert shard_indices(7, Shard(1, 3)) == [1, 4]
    assert shard_indices(7, None) == list(range(7))
    for total, count in ((0, 1), (5, 1), (5, 2), (3, 5), (10, 4)):
        parts = [shard_indices(total, Shard(i, count)) for i in range(count)]
        assert sorted(i for p in parts for i in p) == list(range(total))  # each input in exactly one shard
        assert all(i % count == k for k, p in enumerate(parts) for i in p)
    assert shard_indices(3, Shard(4, 5)) == []  # more shards than inputs: an empty shard


def test_parse_shard_explicit_and_from_the_environment() -> None:
    assert parse_shard("1/4", {}) == Shard(1, 4)
    assert parse_shard(" 0/1 ", {"JOB_COMPLETION_INDEX": "9"}) == Shard(0, 1)  # explicit wins
    assert parse_shard("4", {"JOB_COMPLETION_INDEX": "3"}) == Shard(3, 4)
    assert parse_shard("4", {"AWS_BATCH_JOB_ARRAY_INDEX": "2"}) == Shard(2, 4)
    assert parse_shard("4", {"JOB_COMPLETION_INDEX": "2", "AWS_BATCH_JOB_ARRAY_INDEX": "2"}) == Shard(2, 4)


@pytest.mark.parametrize(
    ("text", "env", "match"),
    [
        ("2/2", {}, r"^--shard: index 2 is out of range for 2 shards \(0 to 1\)$"),
        ("0/0", {}, r"^--shard: the number of shards must be 1 to 100000, got 0$"),
        ("1/2/3", {}, r"^--shard: expected I/N \(shard I of N, from 0\) or N"),
        ("-1/2", {}, r"^--shard: expected I/N"),
        ("a", {}, r"^--shard: expected I/N"),
        ("3", {}, r"^--shard 3: the shard index comes from JOB_COMPLETION_INDEX or AWS_BATCH_JOB_ARRAY_INDEX "
                  r"\(a Kubernetes Indexed Job, an AWS Batch array job\) and neither is set; "
                  r"give --shard I/3$"),
        ("3", {"JOB_COMPLETION_INDEX": "x1"}, r"^--shard 3: JOB_COMPLETION_INDEX='x1' is not a shard index"),
        ("3", {"AWS_BATCH_JOB_ARRAY_INDEX": "-1"}, r"AWS_BATCH_JOB_ARRAY_INDEX='-1' is not a shard index"),
        ("3", {"AWS_BATCH_JOB_ARRAY_INDEX": "3"},
         r"^--shard 3: AWS_BATCH_JOB_ARRAY_INDEX=3 is out of range for 3 shards \(0 to 2\)"),
        ("3", {"JOB_COMPLETION_INDEX": "1", "AWS_BATCH_JOB_ARRAY_INDEX": "2"},
         r"JOB_COMPLETION_INDEX=1, AWS_BATCH_JOB_ARRAY_INDEX=2 disagree"),
    ],
)
def test_parse_shard_errors(text: str, env: dict[str, str], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_shard(text, env)


def captured_run_batch(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Replace ``run_batch`` by a stand-in recording the keywords the command passes it (an empty batch)."""
    import gndreplay.batch

    seen: dict[str, Any] = {}

    def capture(jobs: Any, **kw: Any) -> BatchResult:
        seen.update(kw, jobs=jobs)
        return BatchResult((), tmp_path, tmp_path / "s.csv", tmp_path / "s.md", None, 0.0)

    monkeypatch.setattr(gndreplay.batch, "run_batch", capture)
    return seen


@pytest.mark.parametrize("var", ["JOB_COMPLETION_INDEX", "AWS_BATCH_JOB_ARRAY_INDEX"])
def test_cli_shard_takes_its_index_from_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, var: str
) -> None:
    from typer.testing import CliRunner

    from gndreplay.cli import app

    log = write_input(tmp_path, "a.clf", "")
    for name in ("JOB_COMPLETION_INDEX", "AWS_BATCH_JOB_ARRAY_INDEX"):
        monkeypatch.delenv(name, raising=False)
    seen = captured_run_batch(tmp_path, monkeypatch)
    result = CliRunner().invoke(app, ["batch", str(log), "--shard", "4", "--quiet"])
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [
        "gndreplay: error: --shard 4: the shard index comes from JOB_COMPLETION_INDEX or "
        "AWS_BATCH_JOB_ARRAY_INDEX (a Kubernetes Indexed Job, an AWS Batch array job) and neither is set; "
        "give --shard I/4"
    ]
    monkeypatch.setenv(var, "3")
    result = CliRunner().invoke(app, ["batch", str(log), "--shard", "4", "--quiet"])
    assert result.exit_code == 0, result.output
    assert seen["shard"] == Shard(3, 4) and [j.name for j in seen["jobs"]] == ["a"]  # the whole list
    monkeypatch.setenv(var, "4")
    result = CliRunner().invoke(app, ["batch", str(log), "--shard", "4", "--quiet"])
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [
        f"gndreplay: error: --shard 4: {var}=4 is out of range for 4 shards (0 to 3); --shard must give the "
        "job's number of completions / array size"
    ]
    result = CliRunner().invoke(app, ["batch", str(log), "--shard", "1/0", "--quiet"])
    assert (result.exit_code, result.stderr) == (
        2, "gndreplay: error: --shard: the number of shards must be 1 to 100000, got 0\n")


# ---------------------------------------------------------------- fake runs, byte for byte


def steady_wall_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every result's wall time a function of its name, so two runs of one input write the same bytes."""
    real = batch_run.run_tasks

    def steady(tasks: Any, **kw: Any) -> tuple[InputResult, ...]:
        return tuple(dataclasses.replace(r, wall_s=0.125 * len(r.name)) for r in real(tasks, **kw))

    monkeypatch.setattr(batch_run, "run_tasks", steady)


#: Fake inputs: two logs, an unreadable one, a crash, and three seeds of a "scenario" g (fake-run logs
#: grouped as a scenario: its aggregate over seeds is checked against a thresholds file).
FAKE = {"a": "GOOD 7 1.0 0 1 2 3 4", "bad": "BAD", "g-s1": "GOOD 5 2.0 1", "crash": "CRASH",
        "g-s2": "GOOD 6 60.0 0", "b": "GOOD 9 3.0 2", "g-s3": "GOOD 4 1.5 0"}
LIMITS = '[thresholds]\nemergency_stops = 1\n[inputs."g"]\ncollision_rate = 0.5\nmin_success_rate = 0.5\n'


def fake_jobs(tmp_path: Path) -> list[Job]:
    jobs = []
    for name, text in FAKE.items():
        path = tmp_path / "in" / f"{name}.clf"
        if not path.exists():
            write_input(tmp_path / "in", path.name, text)
        group, _, seed = name.partition("-s")
        jobs.append(Job(name, path, group=group if seed else "", seed=int(seed or 0)))
    return jobs


def fake(tmp_path: Path, out: str, *, shard: Shard | None = None, **kw: Any) -> BatchResult:
    th = load_thresholds(write_input(tmp_path, "limits.toml", LIMITS))
    folder = tmp_path / out
    return run_batch(fake_jobs(tmp_path), cfg=None, options=FakeOptions(), thresholds=th,  # type: ignore[arg-type]
                     out_dir=folder, runner=fake_runner, junit=folder / "junit.xml", shard=shard, **kw)


def tree_digest(folder: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file (and "dir" of every folder) below ``folder``."""
    return {p.relative_to(folder).as_posix(): "dir" if p.is_dir() else
            hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*"))}


def record_without_shard(folder: Path) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((folder / BATCH_FILE).read_text())
    doc.pop("shard")
    return doc


def assert_same_batch(merged: Path, whole: Path) -> None:
    """The batch files byte for byte, batch.json but its shard, and every run directory's files."""
    for name in OUTPUTS:
        assert (merged / name).read_bytes() == (whole / name).read_bytes(), name
    assert (merged / BATCH_FILE).read_bytes() == (whole / BATCH_FILE).read_bytes()
    assert record_without_shard(merged) == record_without_shard(whole)
    assert tree_digest(merged) == tree_digest(whole)


@pytest.mark.parametrize("count", [2, 9])
def test_merged_shards_are_the_unsharded_batch_byte_for_byte(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, count: int
) -> None:
    steady_wall_clock(monkeypatch)
    whole = fake(tmp_path, "whole", workers=2)
    shards = [fake(tmp_path, f"shard-{i}", shard=Shard(i, count), workers=2) for i in range(count)]
    for i, s in enumerate(shards):  # each shard ran its inputs (i % count == index), none of the others
        names = [r.name for r in s.results]
        assert names == [n for k, n in enumerate(FAKE) if k % count == i]
        assert sorted(p.name for p in s.out_dir.iterdir() if p.is_dir()) == sorted(
            r.name for r in s.results if r.run_dir is not None)
        rec = read_record(s.out_dir)
        assert (rec.shard, rec.total, rec.indices) == (Shard(i, count), len(FAKE), tuple(range(i, 7, count)))
    empty = shards[-1]  # 9 shards of 7 inputs: shard 8 has none, and is a valid batch folder
    if count == 9:
        assert empty.results == () and empty.exit_code == 0
        assert (empty.out_dir / "summary.csv").read_text().count("\n") == 1  # the header alone
        assert "0 inputs: 0 pass, 0 fail, 0 error" in (empty.out_dir / "summary.md").read_text()
    before = {s.out_dir.name: tree_digest(s.out_dir) for s in shards}
    merged = merge_batches([s.out_dir for s in reversed(shards)], out_dir=tmp_path / "merged",
                           junit=tmp_path / "merged" / "junit.xml")
    assert {s.out_dir.name: tree_digest(s.out_dir) for s in shards} == before  # shards untouched
    assert_same_batch(merged.out_dir, whole.out_dir)
    assert [(r.name, r.status, r.run_dir) for r in merged.results] == [
        (r.name, r.status, None if r.run_dir is None else merged.out_dir / r.name) for r in whole.results]
    assert merged.exit_code == whole.exit_code == 2
    assert [(a.scenario, a.runs, a.failures) for a in merged.aggregates] == [
        (a.scenario, a.runs, a.failures) for a in whole.aggregates]
    assert merged.aggregates[0].runs == 3 and merged.aggregates[0].failures  # over all seeds again
    # the run directories are hard links to the shards' files
    a_shard = next(s for s in shards if any(r.name == "a" for r in s.results))
    assert (merged.out_dir / "a" / "summary.json").samefile(a_shard.out_dir / "a" / "summary.json")
    # the merged folder is gndreplay's: listed by its marker, replaced only with overwrite
    assert {"a", "b", "g-s1", BATCH_FILE, "summary.csv"} <= set(
        (merged.out_dir / RUN_MARKER).read_text().splitlines())
    again = merge_batches([s.out_dir for s in shards], out_dir=tmp_path / "merged", overwrite=True)
    assert again.out_dir == merged.out_dir
    assert {s.out_dir.name: tree_digest(s.out_dir) for s in shards} == before


def test_summary_and_junit_give_run_directories_relative_to_the_batch_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    res = fake(tmp_path, "out", workers=2)
    rows = {r["name"]: r for r in csv.DictReader((res.out_dir / "summary.csv").open())}
    assert (rows["a"]["run_dir"], rows["bad"]["run_dir"]) == ("a", "")
    assert rows["a"]["path"] == str((tmp_path / "in" / "a.clf").absolute())  # the input stays absolute
    assert "run_dir: a\n" in (res.out_dir / "junit.xml").read_text()
    doc = json.loads((res.out_dir / BATCH_FILE).read_text())
    assert (doc["format"], doc["version"], doc["shard"], doc["tasks"], doc["indices"]) == (
        "gndreplay batch", 1, None, 7, list(range(7)))
    assert doc["thresholds"] == {"path": str(tmp_path / "limits.toml"),
                                 "sha256": hashlib.sha256(LIMITS.encode()).hexdigest()}
    first = doc["results"][0]
    assert set(first) == {f.name for f in dataclasses.fields(InputResult)}
    assert (first["name"], first["run_dir"], first["metrics"]["reactor_p99_ms"]) == ("a", "a", 1.0)


def test_the_record_reads_back_every_field_nested_run_directories_and_nan(tmp_path: Path) -> None:
    r = InputResult(name="x", path="/in/x.clf", status="fail", error="", error_type="", ticks=3,
                    metrics={"ate_m": math.nan, "ticks": 3.0, "stack_p99_ms": 1.25}, failures=("ate_m not",),
                    run_dir=Path("v1/x"), wall_s=0.5, detail="tb", group="g", seed=4, outcome="timeout")
    rec = BatchRecord("d" * 64, 3, Shard(1, 2), (1,), None, "e" * 64, (r,))
    text = record_json(rec)
    assert "NaN" not in text and json.loads(text)["results"][0]["metrics"]["ate_m"] is None
    (tmp_path / BATCH_FILE).write_text(text)
    back = read_record(tmp_path)
    (b,) = back.results
    assert math.isnan(b.metrics["ate_m"])
    assert dataclasses.replace(b, metrics={}) == dataclasses.replace(r, metrics={})
    assert {k: v for k, v in b.metrics.items() if k != "ate_m"} == {"ticks": 3.0, "stack_p99_ms": 1.25}
    assert dataclasses.replace(back, results=()) == dataclasses.replace(rec, results=())


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda d: d.update(version=2), r"format version 2; this gndreplay reads version 1"),
        (lambda d: d.update(format="x"), r"not a gndreplay batch record"),
        (lambda d: d.update(indices=[0]), r"indices: expected the indices of shard 1/2 of 3 inputs"),
        (lambda d: d["results"][0].update(colour="red"), r"results\[0\]: unknown field 'colour'"),
        (lambda d: d["results"][0].update(run_dir="../x"), r"results\[0\].run_dir: expected a path inside"),
        (lambda d: d["results"][0].update(run_dir="/x"), r"results\[0\].run_dir: expected a path inside"),
        (lambda d: d["results"][0].update(ticks="3"), r"results\[0\].ticks: expected an integer, got '3'"),
        (lambda d: d["results"][0].update(status="ok"), r"results\[0\].status: expected 'pass' or 'fail'"),
        (lambda d: d["results"][0].pop("name"), r"results\[0\]: .*missing .* 'name'"),
    ],
)
def test_a_malformed_record_is_one_line_naming_it(tmp_path: Path, edit: Any, match: str) -> None:
    r = InputResult(name="x", path="/in/x.clf", status="pass", run_dir=Path("x"))
    doc = json.loads(record_json(BatchRecord("d" * 64, 3, Shard(1, 2), (1,), None, "e" * 64, (r,))))
    edit(doc)
    (tmp_path / BATCH_FILE).write_text(json.dumps(doc))
    with pytest.raises(RecordError, match=match):
        read_record(tmp_path)


def test_merge_recreates_nested_run_directories(tmp_path: Path) -> None:
    """A run directory one level down (``<variant>/<name>``) is recreated there, each folder marked."""
    shard = tmp_path / "shard"
    (shard / "v1" / "x").mkdir(parents=True)
    (shard / "v1" / "x" / "commands.csv").write_text("t\n")
    write_marker(shard / "v1" / "x")
    r = InputResult(name="x", path="/in/x.clf", status="pass", ticks=1, run_dir=Path("v1/x"))
    th = Thresholds()
    from gndreplay.batch.record import thresholds_digest

    record = BatchRecord("d" * 64, 1, None, (0,), None, thresholds_digest(th), (r,))
    (shard / BATCH_FILE).write_text(record_json(record))
    res = merge_batches([shard], out_dir=tmp_path / "out")
    assert (tmp_path / "out" / "v1" / "x" / "commands.csv").read_text() == "t\n"
    assert "x" in (tmp_path / "out" / "v1" / RUN_MARKER).read_text().splitlines()
    assert "v1" in (tmp_path / "out" / RUN_MARKER).read_text().splitlines()
    assert res.results[0].run_dir == tmp_path / "out" / "v1" / "x"
    assert next(csv.DictReader((tmp_path / "out" / "summary.csv").open()))["run_dir"] == "v1/x"


# ---------------------------------------------------------------- refusals


def two_shards(tmp_path: Path, **kw: Any) -> list[Path]:
    return [fake(tmp_path, f"s{i}", shard=Shard(i, 2), **kw).out_dir for i in range(2)]


def test_merge_refuses_what_is_not_one_whole_batch(tmp_path: Path) -> None:
    s0, s1 = two_shards(tmp_path)
    before = {p.name: tree_digest(p) for p in (s0, s1)}
    other = fake(tmp_path / "o", "t1", shard=Shard(1, 2)).out_dir  # other inputs (another folder)
    third = fake(tmp_path, "u1", shard=Shard(1, 3)).out_dir
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "notes.txt").write_text("mine")
    out = tmp_path / "merged"
    cases = [
        ([s0, other], rf"^{other}: a shard of another batch than {s0} \(the inputs, options, "
                      r"configuration or thresholds differ: batch.json digests differ\)$"),
        ([s0], r"^shard 1/2 missing: give every shard folder of the batch \(2 shards\)$"),
        ([s0, s1, s0], rf"^{s0} and {s0} are both shard 0/2; give each once$"),
        ([s0, third], rf"^{third}: shard 1/3, but {s0} is one of 2 shards$"),
        ([s0, plain], rf"^{plain}: no batch.json in it: not a gndreplay batch folder$"),
        ([s0, tmp_path / "nope"], rf"^{tmp_path / 'nope'}: not a folder"),
        ([], r"^--merge: give the shard folders of a batch$"),
    ]
    for folders, match in cases:
        with pytest.raises(RecordError, match=match):
            merge_batches(folders, out_dir=out)
    assert not out.exists()
    # the thresholds: changed since the shards ran, or another file given, are refused; the same content
    # elsewhere is taken
    (tmp_path / "limits.toml").write_text(LIMITS + "# edited\n")
    with pytest.raises(ConfigError, match=r"limits.toml: not the thresholds the shards ran with"):
        merge_batches([s0, s1], out_dir=out)
    with pytest.raises(ConfigError, match=r"the default thresholds: not the thresholds the shards ran with"):
        merge_batches([s0, s1], out_dir=out, thresholds=Thresholds())
    copy = write_input(tmp_path / "elsewhere", "ci.toml", LIMITS)
    res = merge_batches([s0, s1], out_dir=out, thresholds=load_thresholds(copy))
    assert [r.name for r in res.results] == list(FAKE)
    (tmp_path / "limits.toml").unlink()
    with pytest.raises(ConfigError, match=r"limits.toml: the thresholds file the shards ran with is not "):
        merge_batches([s0, s1], out_dir=tmp_path / "merged2")
    # the output is protected as any batch folder: never a shard folder, never over a foreign folder
    with pytest.raises(Exception, match=r"contains the input"):
        merge_batches([s0, s1], out_dir=s0, thresholds=load_thresholds(copy), overwrite=True)
    with pytest.raises(Exception, match=r"not written by gndreplay"):
        merge_batches([s0, s1], out_dir=plain, thresholds=load_thresholds(copy))
    assert {p.name: tree_digest(p) for p in (s0, s1)} == before


def test_shards_run_from_checkouts_at_different_places_merge(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Inputs given relative to the current folder: two checkouts (CI runners) agree on the batch."""
    shards = []
    for i, place in enumerate(("runner-a/project", "runner-b/project")):
        checkout = tmp_path / place
        for name in ("a", "b"):
            write_input(checkout / "in", f"{name}.clf", FAKE[name])
        write_input(checkout, "ci.toml", LIMITS)
        monkeypatch.chdir(checkout)
        jobs = [Job(n, Path("in") / f"{n}.clf") for n in ("a", "b")]
        res = run_batch(jobs, cfg=None, options=FakeOptions(),  # type: ignore[arg-type]
                        thresholds=load_thresholds("ci.toml"), out_dir=Path("out"), runner=fake_runner,
                        shard=Shard(i, 2))
        shards.append(res.out_dir)
    merged = merge_batches(shards, out_dir=tmp_path / "merged")
    assert [(r.name, r.status, r.path) for r in merged.results] == [
        ("a", "pass", str(tmp_path / "runner-a/project/in/a.clf")),
        ("b", "fail", str(tmp_path / "runner-b/project/in/b.clf"))]


def test_cli_merge_takes_only_its_options(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from gndreplay.cli import app

    s0, s1 = two_shards(tmp_path)
    out = tmp_path / "merged"
    for extra, flag in ((["--until", "3"], "--until"), (["--shard", "0/2"], "--shard"),
                        (["--scenarios", "u_trap"], "--scenarios"), (["--preset", "xr4000"], "--preset")):
        result = CliRunner().invoke(app, ["batch", "--merge", str(s0), str(s1), "--out", str(out), *extra])
        assert result.exit_code == 2
        assert result.stderr.startswith(f"gndreplay: error: --merge: not with {flag} (it takes only ")
        assert result.stderr.count("\n") == 1
    result = CliRunner().invoke(app, ["batch", "--merge", str(s0), "--out", str(out)])
    assert (result.exit_code, result.stderr) == (
        2, "gndreplay: error: shard 1/2 missing: give every shard folder of the batch (2 shards)\n")
    args = ["batch", "--merge", str(s1), str(s0), "--out", str(out), "--junit", str(tmp_path / "j.xml"),
            "--thresholds", str(tmp_path / "limits.toml"), "--quiet"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2  # the batch's exit code: an unreadable and a crashed input
    assert (out / "summary.csv").is_file() and (tmp_path / "j.xml").is_file()
    assert "gndreplay: error: bad: " in result.stderr


# ---------------------------------------------------------------- dask and real runs


def test_a_shard_on_dask_merges_with_one_from_the_pool(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dask_cluster: Any
) -> None:
    steady_wall_clock(monkeypatch)
    whole = fake(tmp_path, "whole", workers=2)
    pool0 = fake(tmp_path, "pool0", shard=Shard(0, 2), workers=2)
    dask0 = fake(tmp_path, "dask0", shard=Shard(0, 2), dask_address=dask_cluster.scheduler_address)
    for name in (*OUTPUTS, BATCH_FILE):
        assert (dask0.out_dir / name).read_bytes() == (pool0.out_dir / name).read_bytes(), name
    pool1 = fake(tmp_path, "pool1", shard=Shard(1, 2), workers=2)
    merged = merge_batches([dask0.out_dir, pool1.out_dir], out_dir=tmp_path / "merged",
                           junit=tmp_path / "merged" / "junit.xml")
    assert_same_batch(merged.out_dir, whole.out_dir)


#: summary.csv columns that are wall-clock measurements (different on every run).
def clock_column(name: str) -> bool:
    return name.endswith("_ms") or "_ms_per_" in name or name in ("wall_s", "failures")


def real(tmp_path: Path, jobs: Sequence[Job], out: str, shard: Shard | None = None) -> BatchResult:
    from gndreplay.config import Config
    from gndreplay.replay import RunOptions

    return run_batch(jobs, cfg=Config(), options=RunOptions(until_s=2.0), out_dir=tmp_path / out, workers=2,
                     sim=SimOptions(time_limit_s=2.0, figures=False), shard=shard)


def test_real_shards_merge_into_the_unsharded_batch(tmp_path: Path) -> None:
    """The sample log (2 s) and a shipped scenario (2 s, seeds 1 and 2) as one batch and as two shards:
    every run directory's commands.csv is byte-identical, the summary rows equal but for the clocks."""
    jobs = expand_inputs([SAMPLE_LOG], scenarios=["u_trap"], seeds=(1, 2))
    assert [j.name for j in jobs] == ["office", "u_trap-s1", "u_trap-s2"]
    whole = real(tmp_path, jobs, "whole")
    shards = [real(tmp_path, jobs, f"s{i}", Shard(i, 2)) for i in range(2)]
    assert [[r.name for r in s.results] for s in shards] == [["office", "u_trap-s2"], ["u_trap-s1"]]
    merged = merge_batches([s.out_dir for s in shards], out_dir=tmp_path / "merged")
    for r in whole.results:
        assert r.run_dir is not None and r.ticks > 0
        commands = (r.run_dir / "commands.csv").read_bytes()
        assert (merged.out_dir / r.name / "commands.csv").read_bytes() == commands

    def rows(folder: Path) -> list[dict[str, str]]:
        return [{k: v for k, v in row.items() if not clock_column(k)}
                for row in csv.DictReader((folder / "summary.csv").open())]

    assert rows(merged.out_dir) == rows(whole.out_dir)
    assert [r["run_dir"] for r in rows(merged.out_dir)] == ["office", "u_trap-s1", "u_trap-s2"]
    assert merged.exit_code == whole.exit_code
    assert read_record(merged.out_dir).digest == read_record(whole.out_dir).digest
