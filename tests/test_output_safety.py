"""``--out`` never deletes or overwrites anything gndreplay did not write (issue 12, item 1).

Every case snapshots the user's files (paths and bytes) before and checks they are all still there after.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from gndreplay.cli import app
from gndreplay.config import PRESETS
from gndreplay.errors import OutputError
from gndreplay.fsutil import (
    RUN_MARKER,
    TMP_PREFIX,
    check_output_dir,
    format_stamp,
    is_output_dir,
    remove_stale_staging,
    resolve_output_dir,
    safe_name,
    staging_dir,
    write_marker,
)
from gndreplay.replay import RunOptions, run_log

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
runner = CliRunner()
FAST = ["--until", "2", "--no-figures", "-q"]


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (relative path -> bytes)."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def assert_kept(before: dict[str, bytes], root: Path) -> None:
    """Every file of ``before`` is still under ``root`` with the same bytes."""
    after = snapshot(root)
    lost = [k for k, v in before.items() if after.get(k) != v]
    assert not lost, f"user files lost or changed: {lost}"


def cli(*args: object) -> tuple[int, str]:
    res = runner.invoke(app, [str(a) for a in args])
    return res.exit_code, res.output


def staging_dirs(parent: Path) -> list[Path]:
    return sorted(parent.glob(f"{TMP_PREFIX}*"))


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    """A folder holding the user's log and a note."""
    d = tmp_path / "d"
    d.mkdir()
    shutil.copy(SAMPLE, d / "log.clf.bz2")
    (d / "notes.txt").write_text("mine\n")
    return d


@pytest.fixture
def in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.chdir(tmp_path)
    yield tmp_path


# ---- refused before any work ---------------------------------------------------------------------------


def test_out_holding_the_input_is_refused(user_dir: Path) -> None:
    before = snapshot(user_dir)
    code, out = cli("run", user_dir / "log.clf.bz2", "--out", user_dir, *FAST)
    assert code == 2 and "contains the input" in out and len(out.strip().splitlines()) == 1
    assert_kept(before, user_dir)
    code, out = cli("run", user_dir / "log.clf.bz2", "--out", user_dir, "--overwrite", *FAST)
    assert code == 2
    assert_kept(before, user_dir)


def test_out_dot_is_refused(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(user_dir)
    before = snapshot(user_dir)
    for out in (".", ".."):
        code, text = cli("run", "log.clf.bz2", "--out", out, *FAST)
        assert code == 2 and "current directory" in text, text
    assert_kept(before, user_dir)
    assert not staging_dirs(user_dir) and not staging_dirs(user_dir.parent)


def test_a_dot_dot_stem_gets_a_safe_default_name(in_tmp: Path) -> None:
    logs = in_tmp / "logs"
    logs.mkdir()
    shutil.copy(SAMPLE, logs / "...log.clf.bz2")  # the stem of this name used to be ".."
    (in_tmp / "keep.txt").write_text("mine\n")
    before = snapshot(in_tmp)
    code, text = cli("run", logs / "...log.clf.bz2", *FAST)
    assert code == 0, text
    assert_kept(before, in_tmp)
    assert is_output_dir(in_tmp / "out" / "run")
    assert safe_name("..") == safe_name(".") == safe_name("") == "run"
    assert safe_name(".hidden") == "hidden" and safe_name("a/b\x00c") == "a_b_c"


def test_out_a_file_or_inside_a_file_is_refused_before_any_work(tmp_path: Path) -> None:
    f = tmp_path / "file.txt"
    f.write_text("mine\n")
    before = snapshot(tmp_path)
    for out, why in ((f, "is a file"), (f / "sub", "inside")):
        t0 = time.perf_counter()
        code, text = cli("run", SAMPLE, "--out", out, "--no-figures", "-q")  # the whole log: refused first
        assert code == 2 and why in text, text
        assert time.perf_counter() - t0 < 30.0  # not after a replay of the whole log
    assert_kept(before, tmp_path)


def test_a_non_empty_folder_gndreplay_did_not_write_is_refused(tmp_path: Path) -> None:
    d = tmp_path / "results"
    d.mkdir()
    (d / "thesis.tex").write_text("mine\n")
    before = snapshot(tmp_path)
    for extra in ([], ["--overwrite"]):
        code, text = cli("run", SAMPLE, "--out", d, *extra, *FAST)
        assert code == 2 and RUN_MARKER in text, text
    assert_kept(before, tmp_path)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert cli("run", SAMPLE, "--out", empty, *FAST)[0] == 0 and is_output_dir(empty)


def test_an_earlier_run_is_kept_unless_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "runs" / "aces"
    assert cli("run", SAMPLE, "--out", out, *FAST)[0] == 0
    first = snapshot(out)
    assert cli("run", SAMPLE, "--out", out, *FAST)[0] == 0  # beside it, not over it
    assert_kept(first, out)
    assert is_output_dir(out.with_name("aces-2"))
    assert resolve_output_dir(out) == out.with_name("aces-3")
    (out / "commands.csv").write_text("edited\n")  # gndreplay's own file: --overwrite may replace it
    assert cli("run", SAMPLE, "--out", out, "--overwrite", *FAST)[0] == 0
    assert (out / "commands.csv").read_text().startswith("t,v,")
    (out / "my-notes.txt").write_text("mine\n")  # a file the user added: never deleted
    before = snapshot(tmp_path)
    code, text = cli("run", SAMPLE, "--out", out, "--overwrite", *FAST)
    assert code == 2 and "my-notes.txt" in text
    assert_kept(before, tmp_path)
    assert not staging_dirs(out.parent)


def test_figures_drawn_later_by_report_may_be_overwritten(tmp_path: Path) -> None:
    out = tmp_path / "r"
    assert cli("run", SAMPLE, "--out", out, "--until", "2", "-q", "--no-figures")[0] == 0
    assert cli("report", out)[0] == 0  # adds the figures and report.md to the marker
    assert "report.md" in (out / RUN_MARKER).read_text().splitlines()
    assert cli("run", SAMPLE, "--out", out, "--overwrite", *FAST)[0] == 0
    assert not (out / "report.md").exists() and not out.with_name("r-2").exists()


def test_check_output_dir_api(tmp_path: Path) -> None:
    (tmp_path / "log.clf").write_text("x\n")
    with pytest.raises(OutputError, match="contains the input"):
        check_output_dir(tmp_path, inputs=[tmp_path / "log.clf"])
    bag = tmp_path / "bag"
    bag.mkdir()
    with pytest.raises(OutputError, match="inside the input folder"):
        check_output_dir(bag / "out", inputs=[bag])
    check_output_dir(tmp_path / "new" / "deeper")  # a new folder: fine, nothing created
    assert not (tmp_path / "new").exists()


def test_format_stamp_is_exact() -> None:
    assert format_stamp(1_103_939_430_181_894_000) == "1103939430.181894000"
    assert format_stamp(0) == "0.000000000" and format_stamp(-1) == "-0.000000001"


# ---- staging: interrupted runs leave nothing ------------------------------------------------------------


def test_staging_is_removed_on_an_exception_and_published_on_success(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt), staging_dir(out) as tmp:
        (tmp / "a.txt").write_text("half\n")
        raise KeyboardInterrupt
    assert not out.exists() and not staging_dirs(tmp_path)
    with staging_dir(out) as tmp:
        (tmp / "a.txt").write_text("whole\n")
    assert (out / "a.txt").read_text() == "whole\n" and is_output_dir(out)
    assert "a.txt" in (out / RUN_MARKER).read_text().splitlines()


def test_interrupt_while_drawing_figures_leaves_no_run_directory(tmp_path: Path) -> None:
    class Interrupting:
        def add_scan(self, tick: object, pose: object) -> None: ...
        def add_result(self, tick: object, result: object, grid: object) -> None: ...
        def abort(self) -> None: ...
        def finish(self, run_dir: Path) -> None:
            (run_dir / "fig_model.png").write_bytes(b"half a figure")
            raise KeyboardInterrupt

    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        run_log(SAMPLE, PRESETS["wheelchair"], out, options=RunOptions(until_s=2.0), sinks=[Interrupting()])
    assert not out.exists() and not staging_dirs(tmp_path)


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    return int(proc.stdout)


def _staged_by_a_dead_process(parent: Path) -> Path:
    """A staging folder of a run that was killed (its process is gone), made by the real code."""
    code = ("import os, sys; from pathlib import Path; from gndreplay.fsutil import staging_dir; "
            "stage = staging_dir(Path(sys.argv[1]) / 'run'); tmp = stage.__enter__(); "
            "(tmp / 'commands.csv').write_text('x'); print(tmp, flush=True); os._exit(0)")
    proc = subprocess.run([sys.executable, "-c", code, str(parent)], capture_output=True, text=True,
                          check=True)
    return Path(proc.stdout.strip())


def test_stale_staging_of_a_dead_process_only_is_removed(tmp_path: Path) -> None:
    from gndreplay.fsutil import _host

    with staging_dir(tmp_path / "alive") as alive:  # this process's: never removed
        stale = _staged_by_a_dead_process(tmp_path)
        assert stale.parent == tmp_path and stale.name.startswith(TMP_PREFIX)
        assert (stale / "commands.csv").is_file()
        look_alike = tmp_path / f"{TMP_PREFIX}{_host()}-{_dead_pid()}-abcd1234"
        look_alike.mkdir()
        (look_alike / "commands.csv").write_text("x\n")
        assert remove_stale_staging(tmp_path) == [stale]
        assert not stale.exists() and alive.exists() and look_alike.exists()


def _spawn_run(out: Path, tmpdir: Path, *extra: str) -> subprocess.Popen[bytes]:
    env = {**os.environ, "TMPDIR": str(tmpdir), "MPLBACKEND": "Agg"}
    code = "from gndreplay.cli import main; main()"
    return subprocess.Popen([sys.executable, "-c", code, "run", str(SAMPLE), "--out", str(out), "-q",
                             "--mcap", *extra], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wait_for_ticks(parent: Path, proc: subprocess.Popen[bytes], timeout_s: float = 120.0) -> Path:
    """Wait until the run streams (its staging directory has commands.csv with rows); return it."""
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        for d in staging_dirs(parent):
            cmd = d / "commands.csv"
            if cmd.is_file() and cmd.stat().st_size > 2000:
                return d
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(0.05)
    proc.kill()
    raise AssertionError("the run never started streaming")


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_run_leaves_nothing_behind_after_the_next_run(tmp_path: Path, sig: signal.Signals) -> None:
    parent, tmpdir = tmp_path / "runs", tmp_path / "tmpdir"
    parent.mkdir()
    tmpdir.mkdir()
    (parent / "mine.txt").write_text("mine\n")
    before = snapshot(tmp_path)
    out = parent / "office"
    proc = _spawn_run(out, tmpdir)
    staged = _wait_for_ticks(parent, proc)
    proc.send_signal(sig)
    code = proc.wait(timeout=60)
    assert code == -sig or code == 128 + sig, proc.stderr.read() if proc.stderr else code
    if sig == signal.SIGTERM:  # Python saw it: the staging directory is already gone
        assert not staged.exists()
    assert not out.exists()
    assert list(tmpdir.iterdir()) == []  # the MCAP is staged inside the run's staging directory
    assert cli("run", SAMPLE, "--out", out, *FAST)[0] == 0  # the next run cleans a killed run's leftovers
    assert not staging_dirs(parent) and is_output_dir(out)
    assert_kept(before, tmp_path)


# ---- review F1: nested user files, `..`, unwritable parents, symlinks --------------------------------------


def test_overwrite_refuses_a_user_file_anywhere_inside_the_output(tmp_path: Path) -> None:
    out = tmp_path / "batch"
    with staging_dir(out / "run") as tmp:  # a marked run folder inside a marked folder (a batch)
        (tmp / "commands.csv").write_text("t\n")
    write_marker(out)
    check_output_dir(out, overwrite=True)  # all gndreplay's: may be replaced
    (out / "run" / "my_notes.txt").write_text("notes\n")
    with pytest.raises(OutputError, match=r"holds files gndreplay did not write \(run/my_notes\.txt\)"):
        check_output_dir(out, overwrite=True)
    (out / "run" / "my_notes.txt").unlink()
    (out / "run" / RUN_MARKER).unlink()  # a listed folder without its own marker is not known to be ours
    with pytest.raises(OutputError, match=r"\(run/\)"):
        check_output_dir(out, overwrite=True)
    with pytest.raises(OutputError, match=r"run/"), staging_dir(out, overwrite=True) as tmp:
        (tmp / "x").write_text("x\n")
    assert (out / "run" / "commands.csv").read_text() == "t\n" and not staging_dirs(tmp_path)


def test_out_through_a_missing_folder_and_dot_dot(tmp_path: Path) -> None:
    out = tmp_path / "nx" / ".." / "dotdot"
    check_output_dir(out)
    assert resolve_output_dir(out) == tmp_path / "dotdot"
    with staging_dir(out) as tmp:
        (tmp / "a.txt").write_text("a\n")
    assert (tmp_path / "dotdot" / "a.txt").read_text() == "a\n" and not (tmp_path / "nx").exists()
    assert resolve_output_dir(out) == tmp_path / "dotdot-2"  # the earlier one is seen through the `..` too
    code, text = cli("run", SAMPLE, "--out", tmp_path / "nx" / ".." / "viacli", *FAST)
    assert code == 0, text
    assert is_output_dir(tmp_path / "viacli") and not (tmp_path / "nx").exists()


@pytest.mark.parametrize("where", ["/proc/gndreplay-test-out", "/sys/gndreplay-test-out"])
def test_an_out_that_cannot_be_created_is_refused_before_any_work(where: str) -> None:
    if not Path(where).parent.is_dir():
        pytest.skip(f"no {Path(where).parent} here")
    with pytest.raises(OutputError, match=rf"{where}: cannot create it in {Path(where).parent}"):
        check_output_dir(Path(where))
    with pytest.raises(OutputError, match=rf"{Path(where).parent}: cannot create the output folder"), \
            staging_dir(Path(where)):
        pass
    code, text = cli("run", SAMPLE, "--out", where, *FAST)
    lines = text.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert lines[0].startswith(f"gndreplay: error: {where}: cannot create it in {Path(where).parent} (")


def test_an_unwritable_parent_is_refused_before_any_work(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        probe = ro / "probe"
        try:
            probe.mkdir()
        except PermissionError:
            pass
        else:
            probe.rmdir()
            pytest.skip("running as root: permissions are not enforced")
        with pytest.raises(OutputError, match=r"ro/out: cannot create it in .*ro \(Permission denied\)"):
            check_output_dir(ro / "out")
    finally:
        ro.chmod(0o700)


def test_a_symlinked_out_is_refused_before_any_work(tmp_path: Path) -> None:
    target = tmp_path / "empty_target"
    target.mkdir()
    link = tmp_path / "linkout"
    link.symlink_to(target)
    with pytest.raises(OutputError, match=r"linkout: is a symbolic link; give the folder it points to"):
        check_output_dir(link)
    code, text = cli("run", SAMPLE, "--out", link, *FAST)
    assert code == 2 and "linkout: is a symbolic link" in text and len(text.strip().splitlines()) == 1
    assert link.is_symlink() and list(target.iterdir()) == [] and not staging_dirs(tmp_path)


# ---- the marker is a file gndreplay wrote; look-alike staging folders; full disks; concurrent runs -------


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run directory written by ``gndreplay run`` (copy it before changing anything)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    code, text = cli("run", SAMPLE, "--out", out, *FAST)
    assert code == 0, text
    return out


def one_error_line(code: int, text: str) -> str:
    """The single stderr line of a refused command (exit 2, no traceback)."""
    lines = text.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in text, text
    return lines[0]


def test_a_symlinked_marker_is_refused_and_never_written_through(finished_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    elsewhere = tmp_path / "elsewhere.txt"
    elsewhere.write_text("mine\n")
    (out / RUN_MARKER).unlink()
    (out / RUN_MARKER).symlink_to(elsewhere)
    before = snapshot(tmp_path)
    for args in (("report", out), ("run", SAMPLE, "--out", out, *FAST),
                 ("run", SAMPLE, "--out", out, "--overwrite", *FAST)):
        line = one_error_line(*cli(*args))
        assert f"{out / RUN_MARKER}: is a symbolic link" in line, line
    with pytest.raises(OutputError, match=rf"{RUN_MARKER}: is a symbolic link"):
        write_marker(out)
    assert_kept(before, tmp_path)
    assert elsewhere.read_text() == "mine\n" and (out / RUN_MARKER).is_symlink()
    assert not list(out.glob("fig_*")) and not (out / "report.md").exists()
    assert not out.with_name("run-2").exists() and not staging_dirs(tmp_path)
    (out / RUN_MARKER).unlink()
    (out / RUN_MARKER).mkdir()  # not a regular file either
    with pytest.raises(OutputError, match=rf"{RUN_MARKER}: is not a regular file"):
        write_marker(out)
    line = one_error_line(*cli("report", out))
    assert f"{out / RUN_MARKER}: is not a regular file" in line, line


def test_the_marker_is_replaced_not_written_in_place(finished_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    inode = (out / RUN_MARKER).stat().st_ino
    hard = tmp_path / "hardlink"  # another name of the same file: must keep the old text
    os.link(out / RUN_MARKER, hard)
    old = hard.read_text()
    assert cli("report", out)[0] == 0
    assert hard.read_text() == old and (out / RUN_MARKER).stat().st_ino != inode
    assert "report.md" in (out / RUN_MARKER).read_text().splitlines()


def test_report_refuses_a_folder_gndreplay_did_not_write(finished_run: Path, tmp_path: Path) -> None:
    from gndreplay.report import build_report

    mine = tmp_path / "mine"
    shutil.copytree(finished_run, mine)
    (mine / RUN_MARKER).unlink()  # the user's copy of a run's files, say
    before = snapshot(mine)
    with pytest.raises(OutputError, match=rf"mine: not a gndreplay run folder \(no {RUN_MARKER} marker\)"):
        build_report(mine, require_marker=True)
    assert snapshot(mine) == before


def test_a_look_alike_staging_folder_is_never_removed(tmp_path: Path) -> None:
    from gndreplay.fsutil import _host

    parent = tmp_path / "runs"
    parent.mkdir()
    dead = _dead_pid()
    plain = parent / f"{TMP_PREFIX}{_host()}-{dead}-abcd1234"  # named like a killed run's staging folder
    plain.mkdir()
    (plain / "thesis.tex").write_text("mine\n")
    marked = parent / f"{TMP_PREFIX}{_host()}-{dead}-0123beef"  # ... and marked, as a copied run folder is
    marked.mkdir()
    (marked / "thesis.tex").write_text("mine too\n")
    write_marker(marked)
    forged = _staged_by_a_dead_process(tmp_path)  # proof of another folder's name: not this one's
    copy = parent / f"{TMP_PREFIX}{_host()}-{dead}-feedf00d"
    shutil.copytree(forged, copy)
    (copy / "thesis.tex").write_text("mine three\n")
    before = snapshot(tmp_path)
    assert remove_stale_staging(parent) == []
    code, text = cli("run", SAMPLE, "--out", parent / "out", *FAST)
    assert code == 0, text
    assert_kept(before, tmp_path)
    assert plain.is_dir() and marked.is_dir() and copy.is_dir()


NO_ROOM = [errno.ENOSPC, errno.EROFS, errno.EDQUOT]


def _fail_writing(monkeypatch: pytest.MonkeyPatch, name: str, code: int) -> None:
    """``Path.write_text`` of a file called ``name`` raises OSError(code)."""
    real = Path.write_text

    def write_text(self: Path, *args: Any, **kw: Any) -> int:
        if self.name == name:
            raise OSError(code, os.strerror(code), str(self))
        return real(self, *args, **kw)

    monkeypatch.setattr(Path, "write_text", write_text)


@pytest.mark.parametrize("code", NO_ROOM, ids=errno.errorcode.get)
def test_a_full_disk_during_a_run_is_one_line_and_the_earlier_run_stays(
        finished_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, code: int) -> None:
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    before = snapshot(tmp_path)
    _fail_writing(monkeypatch, "summary.json", code)
    for extra, target in (([], out.with_name("run-2")), (["--overwrite"], out)):
        line = one_error_line(*cli("run", SAMPLE, "--out", out, *extra, *FAST))
        assert line.startswith(f"gndreplay: error: {target}: cannot write ({os.strerror(code)})"), line
    assert_kept(before, tmp_path)
    assert snapshot(tmp_path) == before and not staging_dirs(tmp_path)


@pytest.mark.parametrize("code", NO_ROOM, ids=errno.errorcode.get)
def test_a_full_disk_during_report_is_one_line(finished_run: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch, code: int) -> None:
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    before = snapshot(tmp_path)

    def savefig(self: Any, fname: Any, **kw: Any) -> None:
        Path(fname).write_bytes(b"\x89PNG half")
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr("matplotlib.figure.Figure.savefig", savefig)
    line = one_error_line(*cli("report", out))
    assert line.startswith(f"gndreplay: error: {out}: cannot write ({os.strerror(code)})"), line
    assert snapshot(tmp_path) == before  # no half figure, no temporary


def test_a_full_disk_during_simulate_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _fail_writing(monkeypatch, "result.json", errno.ENOSPC)
    out = tmp_path / "sim"
    line = one_error_line(*cli("simulate", "u_trap", "--out", out, "--time-limit", "0.5", "--no-figures",
                               "--progress", "none"))
    assert line.startswith(f"gndreplay: error: {out}: cannot write (No space left on device)"), line
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_writing_a_simulated_log_is_one_line(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import gndreplay.io.carmen as carmen

    def full(*args: Any, **kw: Any) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(carmen, "_write_body", full)
    monkeypatch.setattr("gndreplay.sim.scenario.run_scenario", lambda scn, seed: None)
    monkeypatch.setattr("gndreplay.sim.scenario.iter_ticks", lambda run, t0_ns: iter(()))
    monkeypatch.setattr("gndreplay.sim.scenario.iter_odometry", lambda run, t0_ns: iter(()))
    out = tmp_path / "office.clf.bz2"
    line = one_error_line(*cli("simulate", "office", "--out", out))
    assert line.startswith(f"gndreplay: error: {out}: cannot write (No space left on device)"), line
    assert list(tmp_path.iterdir()) == []


class _ConcurrentRun:
    """A sink whose ``finish`` publishes another run at ``out`` while this one is still staged: the race of
    two runs started at once with the same --out."""

    def __init__(self, out: Path) -> None:
        self.out = out

    def add_scan(self, tick: object, pose: object) -> None: ...
    def add_result(self, tick: object, result: object, grid: object) -> None: ...
    def abort(self) -> None: ...

    def finish(self, run_dir: Path) -> None:
        with staging_dir(self.out) as tmp:
            (tmp / "other.txt").write_text("the other run\n")


def test_a_name_taken_while_staged_goes_to_the_next_free_one(tmp_path: Path) -> None:
    out = tmp_path / "run"
    stage = staging_dir(out)
    with stage as tmp:
        (tmp / "a.txt").write_text("mine\n")
        with staging_dir(out) as other:  # a concurrent run, published first
            (other / "b.txt").write_text("other\n")
    assert stage.out == out.with_name("run-2") and (stage.out / "a.txt").read_text() == "mine\n"
    assert (out / "b.txt").read_text() == "other\n" and not (out / "a.txt").exists()
    summary = run_log(SAMPLE, PRESETS["wheelchair"], out, options=RunOptions(until_s=2.0),
                      sinks=[_ConcurrentRun(out.with_name("run-3"))])
    assert summary.out_dir == out.with_name("run-4")  # run-3 was taken while it ran: the next free name
    assert (out.with_name("run-3") / "other.txt").is_file() and (summary.out_dir / "commands.csv").is_file()
    assert is_output_dir(summary.out_dir) and not staging_dirs(tmp_path)


def _error_runner(task: Any) -> Any:
    """A batch runner (module level: workers unpickle it) for which every input is unreadable."""
    from gndreplay.errors import LogFormatError

    raise LogFormatError(f"{task.job.path}: not a log")


def test_a_batch_folder_taken_while_staged_goes_to_the_next_free_one(tmp_path: Path) -> None:
    from gndreplay.batch import Job, run_batch

    (tmp_path / "a.clf").write_text("not a log\n")
    out = tmp_path / "batch"

    def progress(result: Any) -> None:
        with staging_dir(out) as tmp:  # another batch, published while this one runs
            (tmp / "summary.csv").write_text("theirs\n")

    res = run_batch([Job(name="a", path=tmp_path / "a.clf")], cfg=PRESETS["wheelchair"],
                    options=RunOptions(), out_dir=out, runner=_error_runner, progress=progress)
    assert res.out_dir == out.with_name("batch-2") and (out / "summary.csv").read_text() == "theirs\n"
    assert res.summary_csv == res.out_dir / "summary.csv" and res.summary_csv.is_file()
    assert not staging_dirs(tmp_path)


def test_a_signal_inside_nested_kernel_calls_is_reported_as_the_signal() -> None:
    """SIGTERM or Ctrl-C arriving inside a numba call surfaces as SystemErrors "returned a result with an
    exception set", up to several deep: still exit 143 / 130 with the staging folder gone, no traceback."""
    import typer

    from gndreplay.cli import cli_errors
    from gndreplay.fsutil import _Terminated

    def chained(first: BaseException, depth: int) -> BaseException:
        err = first
        for _ in range(depth):
            outer = SystemError("CPUDispatcher(<function f>) returned a result with an exception set")
            outer.__cause__ = err
            err = outer
        return err

    @cli_errors
    def command(err: BaseException) -> None:
        raise err

    for first, code in ((_Terminated(143), 143), (KeyboardInterrupt(), 130)):
        for depth in (1, 3):
            with pytest.raises(typer.Exit) as exit_info:
                command(chained(first, depth))
            assert exit_info.value.exit_code == code
