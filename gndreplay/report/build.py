"""``build_report``: (re)draw the figures and report.md of a run directory from its files alone, or the
figures of a time window of it; ``ReportSink`` does it inside a replay's staging directory, so a run
directory appears with its figures."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..errors import OutputError
from ..fsutil import (
    RUN_MARKER,
    add_to_marker,
    atomic_write_text,
    check_may_write,
    is_output_dir,
    write_errors,
)
from ..pipeline.model import RobotCentredGrid
from ..pipeline.stack import TickResult
from ..types import Pose2D, Tick
from .figures import build_figures, figure_names
from .markdown import render_report
from .rundir import load_run, window_run

__all__ = ["REPORT_FILE", "ReportSink", "build_report"]

REPORT_FILE = "report.md"


def build_report(run_dir: Path, *, name: str | None = None, require_marker: bool = False,
                 t_from: float | None = None, t_to: float | None = None) -> list[Path]:
    """Read ``run_dir`` (commands.csv, timing.csv, the TUM trajectories, summary.json and maps.npz when
    present) and write fig_model.png, fig_raw.png, fig_commands.png, fig_timing.png, fig_modes.png,
    fig_error.png (when the run has ground truth) and report.md into it, replacing only files gndreplay wrote
    there (listed in its ``.gndreplay`` marker).
    Deterministic: the same files give the same bytes. ``name`` titles report.md (default: the directory's
    name). Each file is written beside its place and renamed there, so a failure leaves the earlier one.

    With a time window (``t_from`` and / or ``t_to``: seconds since the run's first tick; None: from its
    start, to its end) only the figures of ``figures.WINDOW_FIGURES`` are drawn, for that stretch, as
    ``fig_commands_<from>-<to>.png`` and so on (listed in the marker; the whole run's figures and report.md
    are left as they are).

    Args:
        require_marker: refuse a folder without the marker (``gndreplay report``: a folder gndreplay did
            not write gets no figures added).

    Returns:
        The paths written (the figures of ``figures.figure_names``, then report.md; or the window's figures).

    Raises:
        RunDirError: a required file is missing or malformed.
        ConfigError: the window is empty or outside the run (one line naming the run and its span).
        OutputError: a figure or report.md exists there and gndreplay did not write it, the marker is a
            symbolic link or not a regular file, or (``require_marker``) there is no marker (all checked
            before anything is drawn); the disk is full, the quota exceeded or the file system read-only.
    """
    run_dir = Path(run_dir)
    if require_marker and not is_output_dir(run_dir):
        raise OutputError(f"{run_dir}: not a gndreplay run folder (no {RUN_MARKER} marker); nothing written")
    data = load_run(run_dir)
    if t_from is not None or t_to is not None:
        data = window_run(data, t_from, t_to)
        check_may_write(run_dir, list(figure_names(data.window)))
        with write_errors(run_dir):
            written = build_figures(data, run_dir)
            add_to_marker(run_dir, [p.name for p in written])
        return written
    check_may_write(run_dir, [*figure_names(None, truth=data.has_truth), REPORT_FILE])
    with write_errors(run_dir):  # inside a staging directory, the staging names the output instead
        written = build_figures(data, run_dir)
        text = render_report(data, [p.name for p in written], name=name)
        report = run_dir / REPORT_FILE
        atomic_write_text(report, text)
        add_to_marker(run_dir, [p.name for p in (*written, report)])  # a later --overwrite may replace them
    return [*written, report]


class ReportSink:
    """A ``RunSink`` (and ``StagedSink``) that draws the figures and report.md at ``finish``, inside the
    staging directory, so the run directory is published complete. Give it last: it reads the files the
    replay and the other sinks (maps.npz) wrote. ``on_draw`` is called just before drawing (progress)."""

    def __init__(self, on_draw: Callable[[], None] | None = None) -> None:
        self.on_draw = on_draw
        self._name: str | None = None
        self.written: list[str] = []

    def start(self, staging: Path, target: Path) -> None:
        """Remember the run directory's final name (report.md's title)."""
        self._name = Path(target).name

    def add_scan(self, tick: Tick, pose_corrected: Pose2D) -> None:
        """Nothing while streaming: the report reads the run's files."""

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Nothing while streaming: the report reads the run's files."""

    def finish(self, run_dir: Path) -> None:
        """Draw the figures and report.md into ``run_dir``."""
        if self.on_draw is not None:
            self.on_draw()
        self.written = [Path(p).name for p in build_report(run_dir, name=self._name)]

    def abort(self) -> None:
        """Nothing to release."""
