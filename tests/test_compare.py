"""gndreplay compare: two runs of the sample log, the same or with one parameter changed."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import PRESETS, Config
from gndreplay.replay import RunOptions, run_log
from gndreplay.report.compare import (
    Tolerance,
    compare_runs,
    load_compare_run,
    read_tolerance,
)

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
#: Long enough for the security distance to matter (the robot nears a wall).
UNTIL_S = 20.0
runner = CliRunner()


def _cfg(security_m: float) -> Config:
    cfg = PRESETS["wheelchair"]
    return dataclasses.replace(cfg, reactor=dataclasses.replace(cfg.reactor, security_m=security_m))


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("compare")
    out = {"a": root / "a", "a2": root / "a2", "b": root / "b"}
    base = PRESETS["wheelchair"].reactor.security_m
    for name, security in (("a", base), ("a2", base), ("b", base + 0.2)):
        run_log(SAMPLE, _cfg(security), out[name], options=RunOptions(until_s=UNTIL_S))
    return out


def _invoke(*args: object) -> tuple[int, str, str]:
    r = runner.invoke(app, ["compare", *(str(a) for a in args)])
    return r.exit_code, r.stdout, r.stderr


def _rows(run: Path) -> list[list[str]]:
    with open(run / "commands.csv", newline="") as f:
        return list(csv.reader(f))[1:]


def test_identical_runs_compare_equal(runs: dict[str, Path]) -> None:
    code, out, err = _invoke(runs["a"], runs["a2"], "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["verdict"] == "same"
    assert doc["divergence"] is None and doc["stage"] is None
    assert doc["common_ticks"] == doc["ticks_a"] == len(_rows(runs["a"])) > 0
    assert set(doc["counts"].values()) == {0}
    assert {m["module"] for m in doc["latency"]} >= {"match", "model", "planner", "reactor", "total"}


def test_security_distance_change_first_divergence(runs: dict[str, Path], tmp_path: Path) -> None:
    ra, rb = _rows(runs["a"]), _rows(runs["b"])
    assert [r[0] for r in ra] == [r[0] for r in rb]
    # the first row whose command or labels differ, by a direct scan of the two files
    first = next(k for k, (x, y) in enumerate(zip(ra, rb, strict=True)) if x[1:11] != y[1:11])
    assert first > 0  # mid-run: the robot nears a wall
    expected_fields = {name for name, j in (("v", 1), ("vy", 2), ("w", 3), ("mode", 4), ("situation", 5),
                                            ("flags", 6)) if ra[first][j] != rb[first][j]}
    changed = sum(1 for x, y in zip(ra, rb, strict=True) if x[1] != y[1])

    code, out, err = _invoke(runs["a"], runs["b"], "--json", "--out", tmp_path / "cmp")
    assert code == 1, err
    doc = json.loads(out)
    d = doc["divergence"]
    assert doc["verdict"] == "different"
    assert d["index_a"] == d["index_b"] == first
    assert f"{d['t_s']:.6f}" == ra[first][0][:-3]
    assert set(d["fields"]) == expected_fields
    for name, j in (("v", 1), ("w", 3)):
        if name in expected_fields:
            assert d["fields"][name] == [float(ra[first][j]), float(rb[first][j])]
    assert doc["counts"]["v"] == changed
    stage = doc["stage"]
    assert stage["stage"] in ("pose", "planner", "reactor", "supervisor")
    assert stage["t_s"] <= d["t_s"]
    # the replay's poses come from the log: the security distance changes the reactor's command
    assert stage["stage"] == "reactor"
    written = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert written["divergence"] == d
    assert (tmp_path / "cmp" / "fig_compare.png").stat().st_size > 0

    code, text, _ = _invoke(runs["a"], runs["b"])
    assert code == 1
    assert f"first divergence: t={ra[first][0][:-3]}" in text
    assert "first stage that differs: reactor" in text


def test_tolerance_hides_small_command_differences(runs: dict[str, Path], tmp_path: Path) -> None:
    a, b = load_compare_run(runs["a"]), load_compare_run(runs["b"])
    exact = compare_runs(a, b)
    assert exact.divergence is not None
    wide = compare_runs(a, b, Tolerance(v_mps=10.0, vy_mps=10.0, w_radps=10.0))
    labels_differ = any(exact.counts[n] for n in ("mode", "situation", "flags"))
    assert wide.same == (not labels_differ)
    assert wide.counts["v"] == wide.counts["w"] == 0
    tol = tmp_path / "tol.toml"
    tol.write_text("[tolerance]\nv_mps = 10.0\nvy_mps = 10.0\nw_radps = 10.0\n")
    assert read_tolerance(tol) == Tolerance(v_mps=10.0, vy_mps=10.0, w_radps=10.0)


@pytest.mark.parametrize("text, words", [
    ("[tolerance]\nv_mp = 0.1\n", ["v_mp", "did you mean 'v_mps'"]),
    ("[tolerance]\nw_radps = -1\n", ["w_radps", "0 to"]),
    ("[tolerance]\nv_mps = 'a'\n", ["v_mps", "must be a number"]),
    ("[tolerances]\nv_mps = 0.1\n", ["tolerances"]),
    ("[tolerance\n", ["tol.toml"]),
])
def test_bad_tolerance_file_one_line_exit_2(runs: dict[str, Path], tmp_path: Path, text: str,
                                            words: list[str]) -> None:
    tol = tmp_path / "tol.toml"
    tol.write_text(text)
    code, out, err = _invoke(runs["a"], runs["a2"], "--tolerance", tol)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "tol.toml" in err and all(w in err for w in words), err


def test_corrupt_commands_exit_2_one_line(runs: dict[str, Path], tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(runs["a"], bad)
    lines = (bad / "commands.csv").read_text().splitlines(keepends=True)
    lines[3] = "1700000000.4,zero,0,0,mpND\n"
    (bad / "commands.csv").write_text("".join(lines))
    code, out, err = _invoke(runs["a"], bad)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert str(bad / "commands.csv") in err and "line 4" in err

    (bad / "commands.csv").unlink()
    code, _, err = _invoke(bad, runs["a"])
    assert code == 2 and str(bad / "commands.csv") in err and "missing" in err
    code, _, err = _invoke(tmp_path / "nowhere", runs["a"])
    assert code == 2 and "nowhere" in err and len(err.strip().splitlines()) == 1


def test_slowed_module_shows_in_latency_not_behaviour(runs: dict[str, Path], tmp_path: Path) -> None:
    slow = tmp_path / "slow"
    shutil.copytree(runs["a"], slow)
    with open(slow / "timing.csv", newline="") as f:
        rows = list(csv.reader(f))
    col = rows[0].index("planner_ms")
    for r in rows[1:]:
        r[col] = f"{float(r[col]) * 3:.4f}"
    with open(slow / "timing.csv", "w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(rows)
    code, out, err = _invoke(runs["a"], slow, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["verdict"] == "same" and doc["divergence"] is None
    latency = {m["module"]: m for m in doc["latency"]}
    assert latency["planner"]["median_ratio"] == pytest.approx(3.0, rel=0.01)
    assert latency["planner"]["p99_ratio"] == pytest.approx(3.0, rel=0.01)
    assert latency["reactor"]["median_ratio"] == pytest.approx(1.0)


def test_ticks_only_in_one_run(runs: dict[str, Path], tmp_path: Path) -> None:
    short = tmp_path / "short"
    shutil.copytree(runs["a"], short)
    for name in ("commands.csv", "timing.csv"):
        lines = (short / name).read_text().splitlines(keepends=True)
        (short / name).write_text("".join(lines[:-5]))
    a, b = load_compare_run(runs["a"]), load_compare_run(short)
    c = compare_runs(a, b)
    assert not c.same and c.divergence is None
    assert (c.only_a_count, c.only_b_count) == (5, 0)
    assert c.only_a == (float(a.commands.t_s[-5]),)
    assert c.common_ticks == len(a.commands) - 5
    code, out, _ = _invoke(runs["a"], short)
    assert code == 1 and "only in A 5" in out


def test_outcome_of_closed_loop_runs(runs: dict[str, Path], tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    shutil.copytree(runs["a"], a)
    shutil.copytree(runs["a"], b)
    base = {"outcome": "success", "collision": None, "time_to_goal_s": 12.0, "min_clearance_m": 0.4,
            "longest_stall_s": 1.0}
    (a / "result.json").write_text(json.dumps(base))
    (b / "result.json").write_text(json.dumps(base | {"outcome": "collision", "collision": {"t_s": 3.0}}))
    c = compare_runs(load_compare_run(a), load_compare_run(b))
    assert c.outcome is not None and set(c.outcome.changed) == {"outcome", "collision"}
    assert c.outcome.values["collision"] == (False, True)
    assert not c.same and c.divergence is None
    (b / "result.json").write_text("{")
    code, _, err = _invoke(a, b)
    assert code == 2 and str(b / "result.json") in err


def _edit_csv(path: Path, row: int, column: str, value: str) -> None:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    rows[row + 1][rows[0].index(column)] = value
    with open(path, "w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(rows)


def _edit_tum(path: Path, row: int, dx: float) -> None:
    lines = path.read_text().splitlines(keepends=True)
    body = [k for k, line in enumerate(lines) if not line.startswith("#")]
    parts = lines[body[row]].split()
    parts[1] = repr(float(parts[1]) + dx)
    lines[body[row]] = " ".join(parts) + "\n"
    path.write_text("".join(lines))


def test_first_stage_in_pipeline_order(runs: dict[str, Path], tmp_path: Path) -> None:
    """Edits at or before the divergent tick are found in pipeline order; those after it are not stages."""
    b = tmp_path / "b"
    shutil.copytree(runs["a"], b)
    a_run = load_compare_run(runs["a"])
    t = a_run.commands.t_s
    _edit_csv(b / "commands.csv", 8, "v", "0.123456")
    _edit_csv(b / "commands.csv", 9, "situation", "LS2")
    c = compare_runs(a_run, load_compare_run(b))
    assert c.divergence is not None and c.divergence.index_a == 8
    assert set(c.divergence.fields) == {"v"}
    assert c.stage is not None and c.stage.stage == "reactor" and "v" in c.stage.evidence
    assert [s.stage for s in c.stages] == ["reactor"]  # the situation changed after the divergence

    _edit_csv(b / "timing.csv", 6, "path_m", "99.000")
    _edit_csv(b / "commands.csv", 7, "mode", "SAFE_SLOW")
    c = compare_runs(a_run, load_compare_run(b))
    assert c.divergence is not None and c.divergence.index_a == 7
    assert c.divergence.fields["mode"] == (str(a_run.commands.modes[7]), "SAFE_SLOW")
    assert [s.stage for s in c.stages] == ["planner", "supervisor"]
    assert c.stage is not None and c.stage.t_s == t[6] and c.stage.b["path_m"] == 99.0

    _edit_tum(b / "trajectory_corrected.tum", 3, 0.5)
    c = compare_runs(a_run, load_compare_run(b))
    assert c.stage is not None and c.stage.stage == "pose" and c.stage.t_s == a_run.corrected[3, 0]
    assert c.stage.b[0] == pytest.approx(c.stage.a[0] + 0.5)
    assert compare_runs(a_run, load_compare_run(b), Tolerance(pose_m=1.0, path_m=100.0)).stage.stage == (
        "supervisor")
