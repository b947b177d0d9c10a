"""Time-base sanity: a synthetic clock is named, and relations on another clock are set beside the log's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.evaluation import Relations, load_relations
from gndreplay.info import log_info
from gndreplay.io import read_ticks, write_carmen
from gndreplay.io.clock import fmt_ns, scan_clock
from gndreplay.scanmatch.run import relations_time_base
from tests.test_cli_scanmatch import SAMPLE, write_relations

T0 = 1_000_000_000 * 10**9  # 1e9 s, as a converter's generated clock starts


def synthetic_log(path: Path, n: int = 120) -> Path:
    """The sample's first ``n`` scans restamped on a generated clock: exactly 10 Hz from exactly 1e9 s."""
    ticks = []
    for i, tick in enumerate(read_ticks(SAMPLE)):
        if i == n:
            break
        t = T0 + i * 100_000_000
        ticks.append(dataclasses.replace(tick, t_ns=t, scan=dataclasses.replace(tick.scan, t_ns=t)))
    write_carmen(path, ticks)
    return path


def relations(t1_s: list[float], t2_s: list[float]) -> Relations:
    z = np.zeros(len(t1_s))
    return Relations(np.round(np.array(t1_s) * 1e9).astype(np.int64),
                     np.round(np.array(t2_s) * 1e9).astype(np.int64), z, z.copy(), z.copy())


def test_scan_clock_tells_generated_from_recorded() -> None:
    generated = T0 + 100_000_000 * np.arange(50)
    period, clock = scan_clock(generated)
    assert period == 0.1 and clock is not None and "exactly 0.1 s apart" in clock and "1000000000 s" in clock
    jitter = generated + np.arange(50) % 3  # a recorded clock jitters by a few ns at least
    assert scan_clock(jitter)[1] is None


def test_time_base_line_sets_the_ranges_side_by_side() -> None:
    t = T0 + 100_000_000 * np.arange(101)  # 1e9 .. 1e9 + 10 s
    rel = relations([1_100_000_000.0, 1_100_000_100.0], [1_100_000_001.0, 1_100_007_666.0])
    line = relations_time_base(t, rel, 0, tol_s=1e-4, name="x.relations")
    assert line == ("x.relations: none of its 2 relations matches two scan stamps of the log within "
                    "0.0001 s: the log's scans span 1000000000 to 1000000010 s (10.0 s), the relations "
                    "1100000000 to 1100007666 s (7666.0 s); the log's clock looks synthetic (all 101 scans "
                    "exactly 0.1 s apart from a round start: generated, not recorded; relations stamped on a "
                    "recorded clock cannot match)")
    recorded = t + np.arange(101) % 7
    some = relations_time_base(recorded, rel, 0, tol_s=1e-4)
    assert some is not None and some.startswith("relations: none of its 2") and "looks recorded" in some
    four = relations([1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0])
    few = relations_time_base(recorded, four, 1, tol_s=1e-4)
    assert few is not None and few.startswith("relations: only 1 of its 4 relations match")
    assert "the relations 1 to 8 s (7.0 s)" in few
    assert relations_time_base(recorded, four, 2, tol_s=1e-4) is None  # half match: nothing to say
    assert relations_time_base(recorded[:0], rel, 0, tol_s=1e-4) is None


def test_scanmatch_on_a_synthetic_clock_names_it(tmp_path: Path) -> None:
    log = synthetic_log(tmp_path / "synthetic.clf")
    assert log_info(log).synthetic_clock
    rel = tmp_path / "office.relations"
    write_relations(rel)  # on the sample's recorded clock
    refs = load_relations(rel)
    result = CliRunner().invoke(app, ["scanmatch", str(log), "--matcher", "odom", "--relations", str(rel),
                                      "--out", str(tmp_path / "sm")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    err = " ".join(result.stderr.split())  # rich may wrap the line
    lo, hi = fmt_ns(int(refs.t1_ns.min())), fmt_ns(int(refs.t2_ns.max()))
    assert f"none of its {len(refs)} relations matches" in err
    assert "the log's scans span 1000000000 to 1000000011.9 s (11.9 s)" in err
    assert f"the relations {lo} to {hi} s" in err
    assert "the log's clock looks synthetic (all 120 scans exactly 0.1 s apart" in err


def test_scanmatch_warns_when_few_relations_match(tmp_path: Path) -> None:
    rel = tmp_path / "office.relations"
    n = write_relations(rel)
    lines = rel.read_text().splitlines(keepends=True)
    shifted = [f"{float(a) + 5000:.6f} {float(b) + 5000:.6f} {rest}"
               for a, b, rest in (ln.split(" ", 2) for ln in lines[: n - n // 4])]
    rel.write_text("".join(shifted + lines[n - n // 4:]))  # a quarter still on the log's clock
    result = CliRunner().invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--relations", str(rel),
                                      "--out", str(tmp_path / "sm")])
    assert result.exit_code == 0, result.output
    err = " ".join(result.stderr.split())
    assert f"gndreplay: warning: {rel}: only {n // 4} of its {n} relations match" in err
    assert "the log's clock looks synthetic (all 570 scans exactly 0.2 s apart" in err  # the sample's is
    assert "odom" in result.stdout  # the table is still printed


def test_scanmatch_quiet_when_the_relations_match(tmp_path: Path) -> None:
    rel = tmp_path / "office.relations"
    write_relations(rel)
    result = CliRunner().invoke(app, ["scanmatch", str(SAMPLE), "--matcher", "odom", "--relations", str(rel),
                                      "--out", str(tmp_path / "sm")])
    assert result.exit_code == 0 and "warning" not in result.stderr
