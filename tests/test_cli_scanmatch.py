"""``gndreplay scanmatch`` end to end on the sample log, scored against relations made from its truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.geometry import relative
from gndreplay.io import read_ticks

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"


def write_relations(path: Path, *, step: int = 10, span: int = 100) -> int:
    """SLAM-benchmark relations (t1 t2 x y z roll pitch yaw) between scans i and i + span, every step."""
    ticks = [t for t in read_ticks(SAMPLE) if t.truth is not None]
    lines = []
    for i in range(0, len(ticks) - span, step):
        a, b = ticks[i], ticks[i + span]
        assert a.truth is not None and b.truth is not None
        d = relative(a.truth.as_array(), b.truth.as_array())
        lines.append(f"{a.t_ns / 1e9:.6f} {b.t_ns / 1e9:.6f} {d[0]:.6f} {d[1]:.6f} 0 0 0 {d[2]:.6f}\n")
    path.write_text("".join(lines))
    return len(lines)


def test_scanmatch_all_side_by_side_beats_odometry(tmp_path: Path) -> None:
    rel = tmp_path / "office.relations"
    n = write_relations(rel)
    out = tmp_path / "sm"
    result = CliRunner().invoke(
        app, ["scanmatch", str(SAMPLE), "--relations", str(rel), "--out", str(out), "--json"]
    )
    assert result.exit_code == 0, result.output
    rows = {r["method"]: r for r in json.loads(result.stdout)}
    assert set(rows) == {"odom", "idc", "kiss-icp"}
    for method, row in rows.items():
        assert row["scans"] == 570 and row["relations"]["matched"] == n
        tum = np.loadtxt(out / f"{method}.tum")
        assert tum.shape == (570, 8)
    assert rows["idc"]["relations"]["trans_mean_m"] < rows["odom"]["relations"]["trans_mean_m"]
    assert rows["idc"]["failures"] <= 0.1 * 570  # a failed match keeps the odometry increment


def test_scanmatch_table_and_bad_inputs(tmp_path: Path) -> None:
    runner = CliRunner()
    table = runner.invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--out", str(tmp_path / "o")])
    assert table.exit_code == 0 and "odom" in table.stdout and "ms median" in table.stdout
    bad = runner.invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "icp"])
    assert bad.exit_code == 2 and "--matcher: expected one of" in bad.output
    missing = runner.invoke(app, ["scanmatch", str(tmp_path / "none.clf")])
    assert missing.exit_code == 2 and "none.clf" in missing.stderr and "Traceback" not in missing.output
    garbage = tmp_path / "junk.clf"
    garbage.write_text("this is not a log\n")
    junk = runner.invoke(app, ["scanmatch", str(garbage), "--out", str(tmp_path / "j")])
    assert junk.exit_code == 2 and "junk.clf" in junk.stderr
    assert not (tmp_path / "j").exists()


def test_scanmatch_relations_that_match_no_scan_are_an_error(tmp_path: Path) -> None:
    """Relations of another log: exit 2 with one line naming the file, and no output written."""
    rel = tmp_path / "other.relations"
    rel.write_text("1000.000000 1000.500000 0.1 0 0 0 0 0\n2000.000000 2000.500000 0.1 0 0 0 0 0\n")
    out = tmp_path / "sm"
    result = CliRunner().invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--relations", str(rel),
                                      "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert "other.relations: none of its 2 relations matches" in result.stderr
    assert "Traceback" not in result.output and not out.exists()


def test_scanmatch_keeps_an_earlier_run_and_overwrites_on_request(tmp_path: Path) -> None:
    out = tmp_path / "sm"
    runner = CliRunner()
    first = runner.invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--out", str(out)])
    assert first.exit_code == 0 and (out / "odom.tum").is_file()
    again = runner.invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--out", str(out)])
    assert again.exit_code == 0 and "holds an earlier run" in again.stderr
    assert (tmp_path / "sm-2" / "odom.tum").read_bytes() == (out / "odom.tum").read_bytes()
    over = runner.invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--out", str(out),
                               "--overwrite"])
    assert over.exit_code == 0 and "earlier run" not in over.stderr and not (tmp_path / "sm-3").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("the user's")
    refused = runner.invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--out", str(mine)])
    assert refused.exit_code == 2 and "not written by gndreplay" in refused.stderr
    assert (mine / "notes.txt").read_text() == "the user's"
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
