"""``batch --baseline DIR``: every input's run compared with the same input's run in a baseline batch folder
(``gndreplay.report.compare``), two checks per input:

- **behaviour**: the commands tick by tick (within ``--tolerance``), the ticks run and, for scenario runs,
  the outcome and scores; it fails at the first divergence and names the tick, the fields and the first
  stage that differed;
- **latency**: each module's median time against the baseline's; it fails when one grows by more than
  ``max_ratio`` (modules whose baseline median is under ``LATENCY_FLOOR_MS`` are not judged: a ratio of
  microseconds is noise). Wall-clock times are only comparable on the same kind of machine.

An input the baseline does not have is "new" (no check fails); a baseline input this batch did not run is
listed as missing. The baseline is any batch folder (a run, or shards merged): runs are matched by their
path inside it.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import ConfigError, GndReplayError, one_line
from .worker import InputResult

if TYPE_CHECKING:  # numpy and the run-directory readers load only when a baseline is compared
    from ..report.compare import Comparison, Tolerance

__all__ = [
    "DEFAULT_LATENCY_RATIO",
    "LATENCY_FLOOR_MS",
    "BaselineCheck",
    "check_baseline",
    "check_baseline_dir",
    "missing_from_batch",
]

#: Default ``--latency-ratio``: a module whose median time grows by more than half fails the check.
DEFAULT_LATENCY_RATIO = 1.5
#: Modules with a baseline median below this [ms] are reported, never judged.
LATENCY_FLOOR_MS = 0.05
_SUMMARY = "summary.csv"


@dataclass(frozen=True, slots=True)
class BaselineCheck:
    """One input against the baseline.

    Attributes:
        label: the input's name in the batch (``InputResult.label``).
        new: the baseline has no run of this input (nothing is checked).
        error: the input or its baseline run could not be read ("" otherwise; the input's own error is
            reported by the batch, not repeated here).
        behaviour_failure: why the behaviour check failed ("" passed or not checked).
        latency_failure: why the latency check failed ("" passed or not checked).
        divergence: the first divergent tick in words ("" none).
        outcome_change: the scenario scores that changed, in words ("" none or not a scenario).
        latency_ratio: the largest module median ratio (this run over the baseline's) among the judged
            modules, and that module (None, "" when none could be judged).
        baseline_run: the baseline run directory compared with.
    """

    label: str
    new: bool = False
    error: str = ""
    behaviour_failure: str = ""
    latency_failure: str = ""
    divergence: str = ""
    outcome_change: str = ""
    latency_ratio: float | None = None
    slowest_module: str = ""
    baseline_run: str = ""

    @property
    def checked(self) -> bool:
        """Both checks ran (the input and its baseline run were read)."""
        return not self.new and not self.error

    @property
    def verdict(self) -> str:
        """"same", "different", "slower", "different, slower", "new" or "error"."""
        if self.error:
            return "error"
        if self.new:
            return "new"
        parts = [w for w, bad in (("different", self.behaviour_failure), ("slower", self.latency_failure))
                 if bad]
        return ", ".join(parts) if parts else "same"


def check_baseline_dir(baseline: Path) -> Path:
    """``baseline`` if it is a batch folder (a folder holding summary.csv).

    Raises:
        ConfigError: it does not exist or is not a batch folder.
    """
    path = Path(baseline)
    if not path.is_dir():
        raise ConfigError(f"{baseline}: no such baseline folder (--update-baseline writes one)")
    if not (path / _SUMMARY).is_file():
        raise ConfigError(f"{baseline}: not a gndreplay batch folder (no {_SUMMARY}); --baseline takes the "
                          "folder of an earlier batch")
    return path


def _divergence_text(c: Comparison) -> str:
    d = c.divergence
    if d is None:
        if c.only_a_count or c.only_b_count:
            return f"ticks differ: {c.only_a_count} only in the baseline, {c.only_b_count} only in this run"
        return ""
    fields = ", ".join(f"{n} {_short(x)} -> {_short(y)}" for n, (x, y) in d.fields.items())
    stage = f"; first stage {c.stage.stage}" if c.stage is not None else ""
    return f"+{d.elapsed_s:.3f} s (tick {d.index_b}): {fields}{stage}"


def _short(x: object) -> str:
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x) if x not in ("", None) else "-"


def _outcome_text(c: Comparison) -> str:
    if c.outcome is None:
        return ""
    return ", ".join(f"{k} {_short(c.outcome.values[k][0])} -> {_short(c.outcome.values[k][1])}"
                     for k in c.outcome.changed)


def _latency(c: Comparison, max_ratio: float) -> tuple[float | None, str, str]:
    """(worst judged median ratio, its module, failure message or "")."""
    judged = [m for m in c.latency if m.median_a >= LATENCY_FLOOR_MS and m.median_ratio is not None]
    if not judged:
        return None, "", ""
    worst = max(judged, key=lambda m: (m.median_ratio, m.module))
    assert worst.median_ratio is not None
    slow = [m for m in judged if max_ratio > 0 and m.median_ratio is not None and m.median_ratio > max_ratio]
    failure = "; ".join(f"{m.module} median {m.median_b:.3f} ms is {m.median_ratio:.2f}x the baseline's "
                        f"{m.median_a:.3f} ms (limit {max_ratio:g}x)" for m in slow)
    return worst.median_ratio, worst.module, failure


def _check_one(label: str, run: Path, base: Path, tolerance: Tolerance, max_ratio: float) -> BaselineCheck:
    from ..report.compare import compare_runs, load_compare_run

    if not base.is_dir():
        return BaselineCheck(label, new=True)
    try:
        c = compare_runs(load_compare_run(base), load_compare_run(run), tolerance)
    except GndReplayError as err:
        return BaselineCheck(label, error=one_line(err), baseline_run=str(base))
    divergence = _divergence_text(c)
    outcome = _outcome_text(c)
    behaviour = "" if c.same else "; ".join(
        part for part in (f"behaviour differs from the baseline at {divergence}" if divergence else
                          "behaviour differs from the baseline",
                          f"outcome changed: {outcome}" if outcome else "") if part)
    ratio, module, latency = _latency(c, max_ratio)
    return BaselineCheck(label, behaviour_failure=behaviour, latency_failure=latency, divergence=divergence,
                         outcome_change=outcome, latency_ratio=ratio, slowest_module=module,
                         baseline_run=str(base))


def check_baseline(
    results: Sequence[InputResult],
    *,
    batch_dir: Path,
    runs_dir: Path,
    baseline: Path,
    tolerance: Tolerance,
    max_ratio: float = DEFAULT_LATENCY_RATIO,
) -> tuple[BaselineCheck, ...]:
    """One check per result that has a run directory (an input in error has none and gets none), in
    order.

    Args:
        batch_dir: where the results' ``run_dir`` say the batch folder is.
        runs_dir: where the run directories are now (the staging folder while a batch is written; else
            ``batch_dir``).
        baseline: the baseline batch folder; the run ``batch_dir/rel`` is compared with ``baseline/rel``.
        max_ratio: the latency limit (0: latency reported, never judged).
    """
    checks = []
    for r in results:
        if r.status == "error" or r.run_dir is None or not Path(r.run_dir).is_relative_to(batch_dir):
            continue
        rel = Path(r.run_dir).relative_to(batch_dir)
        checks.append(_check_one(r.label, runs_dir / rel, Path(baseline) / rel, tolerance, max_ratio))
    return tuple(checks)


def missing_from_batch(results: Sequence[InputResult], baseline: Path) -> tuple[str, ...]:
    """The inputs of the baseline (its summary.csv rows, ``variant/name`` in a sweep) this batch did not
    run."""
    try:
        with open(Path(baseline) / _SUMMARY, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error):
        return ()
    have = {r.label for r in results}
    labels = [f"{row['variant']}/{row['name']}" if row.get("variant") else row.get("name", "")
              for row in rows]
    return tuple(label for label in labels if label and label not in have)


def ratio_text(ratio: float | None) -> str:
    """A latency ratio for a table cell ("-" when none)."""
    return f"{ratio:.2f}x" if ratio is not None and math.isfinite(ratio) else "-"
