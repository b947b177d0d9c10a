"""gndreplay compare: two runs of the sample log, the same or with one parameter changed."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import PRESETS, Config
from gndreplay.errors import ConfigError
from gndreplay.io import ReadOptions
from gndreplay.io.sync import SyncOptions
from gndreplay.replay import RunOptions, run_log
from gndreplay.report.compare import (
    Tolerance,
    compare_runs,
    load_compare_run,
    read_tolerance,
)
from gndreplay.rerun import compare_dirs, decision_at
from gndreplay.sim import simulate_scenario
from gndreplay.types import REFLEXIVE_MODES

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
    for name in ("commands.csv", "timing.csv", "stages.csv"):
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


def _cell(path: Path, row: int, column: str) -> str:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[row + 1][rows[0].index(column)]


def _edit_tum(path: Path, row: int, dx: float) -> None:
    lines = path.read_text().splitlines(keepends=True)
    body = [k for k, line in enumerate(lines) if not line.startswith("#")]
    parts = lines[body[row]].split()
    parts[1] = repr(float(parts[1]) + dx)
    lines[body[row]] = " ".join(parts) + "\n"
    path.write_text("".join(lines))


def test_first_stage_in_pipeline_order(runs: dict[str, Path], tmp_path: Path) -> None:
    """Edits at or before the divergent tick are found, the earliest first (at one tick in pipeline order);
    those after it are not stages."""
    b = tmp_path / "b"
    shutil.copytree(runs["a"], b)
    a_run = load_compare_run(runs["a"])
    t = a_run.commands.t_s
    _edit_csv(b / "commands.csv", 8, "v", "0.123456")
    _edit_csv(b / "commands.csv", 9, "situation", "LS2")
    c = compare_runs(a_run, load_compare_run(b))
    assert c.divergence is not None and c.divergence.index_a == 8
    assert set(c.divergence.fields) == {"v"}
    # the proposal in stages.csv the same: the command out is the supervisor's
    assert c.stage is not None and c.stage.stage == "supervisor" and c.stage.evidence == "commands.csv v"
    assert [s.stage for s in c.stages] == ["supervisor"]  # the situation changed after the divergence
    _edit_csv(b / "stages.csv", 8, "proposed_v", "0.123456")
    c = compare_runs(a_run, load_compare_run(b))
    assert [s.stage for s in c.stages] == ["reactor", "supervisor"]
    assert c.stage is not None and c.stage.evidence == "stages.csv proposed_v"
    assert c.stage.b["proposed_v"] == 0.123456

    _edit_csv(b / "stages.csv", 6, "path_m", "99.0")
    _edit_csv(b / "commands.csv", 7, "mode", "SAFE_SLOW")
    c = compare_runs(a_run, load_compare_run(b))
    assert c.divergence is not None and c.divergence.index_a == 7
    assert c.divergence.fields["mode"] == (str(a_run.commands.modes[7]), "SAFE_SLOW")
    assert [s.stage for s in c.stages] == ["planner", "supervisor"]
    assert c.stage is not None and c.stage.t_s == t[6] and c.stage.b["path_m"] == 99.0
    assert c.stage.evidence == "stages.csv path_m"

    _edit_tum(b / "trajectory_corrected.tum", 3, 0.5)
    c = compare_runs(a_run, load_compare_run(b))
    assert c.stage is not None and c.stage.stage == "pose" and c.stage.t_s == a_run.corrected[3, 0]
    assert c.stage.b[0] == pytest.approx(c.stage.a[0] + 0.5)
    # an earlier tick's grid comes first; at the pose's own tick the pose comes before the grid
    crc = _cell(b / "stages.csv", 2, "grid_digest")
    _edit_csv(b / "stages.csv", 2, "grid_digest", f"{int(crc, 16) ^ 1:016x}")
    c = compare_runs(a_run, load_compare_run(b))
    assert [s.stage for s in c.stages][:2] == ["grid", "pose"] and c.stage is not None and c.stage.t_s == t[2]
    assert c.stage.evidence == "stages.csv grid_digest"
    _edit_csv(b / "stages.csv", 2, "grid_digest", crc)
    _edit_csv(b / "stages.csv", 3, "grid_changed", "123456")
    assert [s.stage for s in compare_runs(a_run, load_compare_run(b)).stages][:2] == ["pose", "grid"]
    wide = Tolerance(pose_m=1.0, path_m=100.0)
    _edit_csv(b / "stages.csv", 3, "grid_changed", _cell(runs["a"] / "stages.csv", 3, "grid_changed"))
    assert compare_runs(a_run, load_compare_run(b), wide).stage.stage == "supervisor"


def test_run_without_stages_file_falls_back(runs: dict[str, Path], tmp_path: Path) -> None:
    """A run directory without stages.csv compares on commands.csv and timing.csv, and says so."""
    old = tmp_path / "old"
    shutil.copytree(runs["a"], old)
    (old / "stages.csv").unlink()
    _edit_csv(old / "commands.csv", 8, "v", "0.123456")
    c = compare_runs(load_compare_run(runs["a"]), load_compare_run(old))
    assert c.divergence is not None and c.divergence.index_a == 8
    mode = str(load_compare_run(old).commands.modes[8])
    assert c.stage is not None and c.stage.stage == ("supervisor" if mode in REFLEXIVE_MODES else "reactor")
    assert any("stages.csv missing in run B" in n for n in c.notes)
    _edit_csv(old / "timing.csv", 6, "path_m", "99.000")
    c = compare_runs(load_compare_run(runs["a"]), load_compare_run(old))
    assert c.stage is not None and c.stage.stage == "planner" and c.stage.evidence == "timing.csv path_m"


# ---- stages.csv, the stage found from it, the snapshot at the first divergent tick ----------------------


def _table(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def _same(x: str, y: str) -> bool:
    """Two cells of a run's table alike: numbers by value (-0.0 is 0.0), text exactly."""
    try:
        return float(x) == float(y)
    except ValueError:
        return x == y


def test_stages_file_written_and_reproducible(runs: dict[str, Path]) -> None:
    a = (runs["a"] / "stages.csv").read_bytes()
    assert a == (runs["a2"] / "stages.csv").read_bytes()
    header, rows = _table(runs["a"] / "stages.csv")
    assert header[:3] == ["t", "grid_digest", "grid_changed"]
    commands, timing = _rows(runs["a"]), _table(runs["a"] / "timing.csv")
    assert [r[0] for r in rows] == [r[0] for r in commands] == [r[0] for r in timing[1]]
    col = {name: header.index(name) for name in header}
    path_col = timing[0].index("path_m")
    for s, c, tm in zip(rows, commands, timing[1], strict=True):
        # no ND+ region exactly when the situation is NONE; timing.csv prints the same path length rounded
        assert (s[col["nd_first"]] == "") == (c[5] == "NONE") == (s[col["nd_direction_rad"]] == "")
        assert (f"{float(s[col['path_m']]):.3f}" if s[col["path_m"]] else "nan") == tm[path_col]
        assert s[col["planner_ok"]] == ("1" if s[col["path_m"]] else "0")
    assert int(rows[0][col["grid_changed"]]) > 0  # the first scan fills an empty grid


#: stages.csv's columns of the grid, the planner and the reactor (the test's own reading)
_STAGE_COLUMNS = {
    "grid": ("grid_digest", "grid_changed", "grid_row", "grid_col"),
    "planner": ("planner_ok", "planner_nodes", "path_m", "path_dir_rad"),
    "reactor": ("nd_first", "nd_last", "nd_direction_rad", "proposed_mode", "proposed_v", "proposed_vy",
                "proposed_w"),
}


def test_security_change_stage_read_from_the_stage_files(runs: dict[str, Path]) -> None:
    """The first stage compare names for a changed security distance is the one the two runs' files
    differ in first, read here directly: ND+ (the reactor), with the grid and the planner the same."""
    ha, sa = _table(runs["a"] / "stages.csv")
    _, sb = _table(runs["b"] / "stages.csv")
    ca, cb = _rows(runs["a"]), _rows(runs["b"])
    first: dict[str, int] = {}
    for stage, cols in _STAGE_COLUMNS.items():
        idx = [ha.index(c) for c in cols]
        diff = [k for k, (x, y) in enumerate(zip(sa, sb, strict=True))
                if not all(_same(x[j], y[j]) for j in idx)]
        if diff:
            first[stage] = diff[0]
    situation = [k for k, (x, y) in enumerate(zip(ca, cb, strict=True)) if x[5] != y[5]]
    if situation:
        first["reactor"] = min(first.get("reactor", situation[0]), situation[0])
    pose_a = (runs["a"] / "trajectory_corrected.tum").read_text().splitlines()
    pose_b = (runs["b"] / "trajectory_corrected.tum").read_text().splitlines()
    assert pose_a == pose_b  # a replay's poses come from the log
    order = ("grid", "planner", "reactor")
    expected = min(first, key=lambda s: (first[s], order.index(s)))

    code, out, err = _invoke(runs["a"], runs["b"], "--json")
    assert code == 1, err
    doc = json.loads(out)
    assert expected == doc["stage"]["stage"] == "reactor"
    k = first["reactor"]
    assert doc["stage"]["t_s"] == float(sa[k][0])
    assert doc["divergence"]["index_a"] >= k
    assert all(first.get(s, len(sa)) > doc["divergence"]["index_a"] for s in ("grid", "planner"))
    changed = [c for c in _STAGE_COLUMNS["reactor"] if not _same(sa[k][ha.index(c)], sb[k][ha.index(c)])]
    assert set(changed) <= set(doc["stage"]["evidence"].replace(",", " ").replace(";", " ").split())
    assert not any("stages.csv" in n for n in doc["notes"])


def _digest(cells: np.ndarray) -> int:
    """The grid digest as documented, computed here with numpy (not the kernel): the cell codes row-major,
    zero-padded to whole 8-byte words, read as little-endian uint64, times the splitmix64 keys, summed
    modulo 2**64."""
    flat = np.zeros(-(-cells.size // 8) * 8, dtype=np.uint8)
    flat[: cells.size] = cells.reshape(-1)
    words = flat.view("<u8").astype(np.uint64)
    z = np.arange(1, words.size + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    keys = (z ^ (z >> np.uint64(31))) | np.uint64(1)
    return int(np.sum(words * keys, dtype=np.uint64))


def test_snapshot_of_a_replay(runs: dict[str, Path], tmp_path: Path) -> None:
    """compare --out re-runs both logs up to the first divergent tick and draws both decisions; the re-run's
    grid is the one stages.csv digested (its digest, the cells changed since the tick before)."""
    code, out, err = _invoke(runs["a"], runs["b"], "--json", "--out", tmp_path / "cmp")
    assert code == 1, err
    doc = json.loads(out)
    assert doc["snapshot"] == "fig_compare_snapshot.png"
    assert not [n for n in doc["notes"] if n.startswith("snapshot")], doc["notes"]
    assert (tmp_path / "cmp" / "fig_compare_snapshot.png").stat().st_size > 10_000
    assert "fig_compare_snapshot.png" in (tmp_path / "cmp" / ".gndreplay").read_text()

    header, rows = _table(runs["a"] / "stages.csv")
    k = doc["divergence"]["index_a"]
    now = decision_at(runs["a"], float(rows[k][0]))
    before = decision_at(runs["a"], float(rows[k - 1][0]))
    assert not now.notes and now.decision.mode == _rows(runs["a"])[k][4]
    assert f"{now.decision.command.v_mps:.6f}" == _rows(runs["a"])[k][1]
    assert _digest(now.decision.cells) == int(rows[k][header.index("grid_digest")], 16)
    assert now.decision.origin_xy == before.decision.origin_xy  # no shift between: cells compare 1:1
    changed = int(np.count_nonzero(now.decision.cells != before.decision.cells))
    assert changed == int(rows[k][header.index("grid_changed")])


def test_snapshot_of_a_scenario_run(tmp_path: Path) -> None:
    """Two closed-loop runs of a scenario, the security distance changed: the snapshot re-runs both."""
    for name, security in (("a", 0.3), ("b", 0.6)):
        simulate_scenario("u_trap", out_dir=tmp_path / name, cfg=_cfg(security), seed=0, time_limit_s=5.0,
                          figures=False)
    c, written = compare_dirs(tmp_path / "a", tmp_path / "b", out=tmp_path / "cmp")
    assert c.divergence is not None and c.stage is not None and written == tmp_path / "cmp"
    assert c.snapshot == "fig_compare_snapshot.png" and not c.notes, c.notes
    assert (written / "fig_compare_snapshot.png").stat().st_size > 10_000
    rerun = decision_at(tmp_path / "b", c.divergence.t_s)
    assert f"{rerun.decision.command.w_radps:.6f}" == _rows(tmp_path / "b")[c.divergence.index_b][3]


def test_snapshot_skips_a_run_that_cannot_be_rerun(runs: dict[str, Path], tmp_path: Path) -> None:
    """A log moved away, or an old run directory (no stages.csv, no source): a note and an empty panel;
    the exit code is still the behaviour's."""
    moved = tmp_path / "moved"
    shutil.copytree(runs["b"], moved)
    summary = json.loads((moved / "summary.json").read_text())
    summary["source"]["path"] = str(tmp_path / "gone.clf.bz2")
    (moved / "summary.json").write_text(json.dumps(summary))
    code, out, err = _invoke(runs["a"], moved, "--out", tmp_path / "cmp")
    assert code == 1, err
    assert "note: snapshot of run B:" in out and "gone.clf.bz2" in out and "not there" in out
    assert (tmp_path / "cmp" / "fig_compare_snapshot.png").is_file()

    old = tmp_path / "old"
    shutil.copytree(runs["a"], old)
    (old / "stages.csv").unlink()
    summary = json.loads((old / "summary.json").read_text())
    del summary["source"]
    (old / "summary.json").write_text(json.dumps(summary))
    code, out, err = _invoke(old, runs["b"], "--json", "--out", tmp_path / "cmp2")
    assert code == 1, err
    notes = json.loads(out)["notes"]
    assert any("stages.csv missing in run A" in n for n in notes)
    assert any(n.startswith("snapshot of run A:") and "no source" in n for n in notes)
    assert not any(n.startswith("snapshot of run B") for n in notes)


def test_snapshot_needs_out(runs: dict[str, Path], tmp_path: Path) -> None:
    code, out, err = _invoke(runs["a"], runs["b"], "--snapshot")
    assert code == 2 and out == "" and "--out" in err and len(err.strip().splitlines()) == 1
    code, out, _ = _invoke(runs["a"], runs["b"], "--no-snapshot", "--out", tmp_path / "cmp", "--json")
    assert code == 1 and json.loads(out)["snapshot"] is None
    assert not (tmp_path / "cmp" / "fig_compare_snapshot.png").exists()


def test_direction_tolerance(runs: dict[str, Path], tmp_path: Path) -> None:
    tol = tmp_path / "tol.toml"
    tol.write_text("[tolerance]\ndirection_rad = 4.0\n")
    code, _, err = _invoke(runs["a"], runs["a2"], "--tolerance", tol)
    assert code == 2 and "direction_rad" in err and "0 to" in err
    tol.write_text("[tolerance]\ndirection_rad = 0.5\n")
    assert read_tolerance(tol) == Tolerance(direction_rad=0.5)


def test_read_options_round_trip_through_summary() -> None:
    read = ReadOptions(fmt="carmen", scan_topic="FLASER", strict=True, default_sensor_pose=(0.1, 0.0, 0.2),
                       sync=SyncOptions(gap_ns=5))
    assert ReadOptions.from_dict(json.loads(json.dumps(read.to_dict()))) == read
    with pytest.raises(ConfigError, match="sync"):
        ReadOptions.from_dict({"sync": {"gap": 1}})
