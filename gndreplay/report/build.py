"""``build_report``: (re)draw the figures and report.md of a run directory from its files alone."""

from __future__ import annotations

from pathlib import Path

from ..fsutil import atomic_write_text
from .figures import build_figures
from .markdown import render_report
from .rundir import load_run

__all__ = ["REPORT_FILE", "build_report"]

REPORT_FILE = "report.md"


def build_report(run_dir: Path) -> list[Path]:
    """Read ``run_dir`` (commands.csv, timing.csv, the TUM trajectories, summary.json and maps.npz when
    present) and write fig_model.png, fig_raw.png, fig_commands.png, fig_timing.png and report.md into it,
    overwriting. Deterministic: the same files give the same bytes.

    Returns:
        The paths written (the four figures, then report.md).

    Raises:
        RunDirError: a required file is missing or malformed.
    """
    run_dir = Path(run_dir)
    data = load_run(run_dir)
    written = build_figures(data, run_dir)
    text = render_report(data, [p.name for p in written])
    report = run_dir / REPORT_FILE
    atomic_write_text(report, text)
    return [*written, report]
