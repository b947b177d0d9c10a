"""What a worker runs: one :class:`Task` in, one :class:`InputResult` out, every failure captured as a value.

This module is imported by each fresh worker process before anything heavy: it imports no numpy, numba or
replay code at module level, so :func:`pin_threads` (the pool's initializer) takes effect before the
numeric libraries read their thread settings.
"""

from __future__ import annotations

import logging
import os
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

from ..errors import ConfigError, GndReplayError, one_line
from .jobs import Job
from .metrics import metrics_from_summary, relation_metrics
from .scenarios import SimOptions, scenario_scores
from .thresholds import check_limits

if TYPE_CHECKING:
    from ..config import Config
    from ..io import ReadOptions
    from ..replay import RunOptions

__all__ = [
    "THREAD_ENV_VARS",
    "InputResult",
    "RunOutcome",
    "Runner",
    "Status",
    "Task",
    "crash_message",
    "error_result",
    "execute",
    "pin_threads",
    "run_input",
]

log = logging.getLogger(__name__)

#: Thread-count variables of the numeric libraries, set to 1 in each worker so N workers use N cores.
THREAD_ENV_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "NUMBA_NUM_THREADS",
)

Status = Literal["pass", "fail", "error"]


def pin_threads() -> None:
    """Worker initializer: one thread per numeric library (must run before numpy / numba are imported)."""
    for name in THREAD_ENV_VARS:
        os.environ[name] = "1"


@dataclass(frozen=True, slots=True)
class Task:
    """Everything a worker needs for one input (picklable: frozen config and options, plain paths).

    Attributes:
        job: the input (its per-input goal already folded into ``options``).
        cfg: the stack configuration of a log (a scenario's comes from ``sim`` and its own preset).
        options: replay options (logs).
        run_dir: the run directory to write (absolute).
        limits: threshold key -> limit for this input.
        read: how to open the log (None: the defaults).
        sim: how to run a scenario and configure its stack (None: ``SimOptions()``).
        figures: draw a log's figures, maps.npz and report.md (``report.sinks.default_sinks``); a scenario
            run's come from ``sim``.
        variant: the sweep combination it belongs to (``SweepPoint.name``; "" outside a sweep).
    """

    job: Job
    cfg: Config
    options: RunOptions
    run_dir: Path
    limits: Mapping[str, float] = field(default_factory=dict)
    read: ReadOptions | None = None
    sim: SimOptions | None = None
    figures: bool = False
    variant: str = ""


class RunOutcome(Protocol):
    """What a runner returns (``gndreplay.replay.RunSummary`` is one)."""

    @property
    def out_dir(self) -> Path: ...

    @property
    def ticks(self) -> int: ...

    @property
    def data(self) -> Mapping[str, Any]: ...


#: Runs one task and writes its run directory; raises on failure. Must be picklable (a module-level function).
Runner = Callable[[Task], RunOutcome]


def run_input(task: Task) -> RunOutcome:
    """The default runner: replay a log with ``run_log``, or run a scenario in closed loop
    (``gndreplay.batch.scenarios.run_scenario``).

    Raises:
        LogFormatError: the log cannot be read.
        ConfigError: a bad scenario file or configuration, or an unknown input kind.
    """
    job = task.job
    if job.kind == "log":
        from ..io import ReadOptions
        from ..replay import run_log
        from ..report.sinks import default_sinks

        return run_log(
            job.path, task.cfg, task.run_dir, options=task.options, read=task.read or ReadOptions(),
            sinks=default_sinks(figures=task.figures),
        )
    if job.kind == "scenario":
        from .scenarios import run_scenario

        return run_scenario(job, task.run_dir, task.sim or SimOptions())
    raise ConfigError(f"{job.path}: {job.kind} inputs are not supported")


@dataclass(frozen=True, slots=True)
class InputResult:
    """The outcome of one input: one summary row and one JUnit test case.

    Attributes:
        name, path: the input.
        status: "pass", "fail" (a threshold was exceeded, or a scenario run did not reach its goal under
            the default ``min_success``) or "error" (unreadable input or crash).
        error: one-line error message ("" unless status is "error").
        error_type: exception type name of the error ("" unless status is "error").
        ticks: ticks the stack ran on.
        metrics: metric name -> value (see ``gndreplay.batch.metrics``).
        failures: one message per exceeded threshold.
        run_dir: the run directory written, or None.
        wall_s: wall time of the input in its worker [s].
        detail: traceback of a crash ("" otherwise).
        group, seed: a scenario run's scenario (its name in the batch) and seed ("" and 0 for a log).
        outcome: how a scenario run ended, in words (``"collision with door at 3.10 s"``; "" otherwise).
        variant: the sweep combination it ran under ("" outside a sweep).
    """

    name: str
    path: str
    status: Status
    error: str = ""
    error_type: str = ""
    ticks: int = 0
    metrics: Mapping[str, float] = field(default_factory=dict)
    failures: tuple[str, ...] = ()
    run_dir: Path | None = None
    wall_s: float = 0.0
    detail: str = ""
    group: str = ""
    seed: int = 0
    outcome: str = ""
    variant: str = ""

    @property
    def label(self) -> str:
        """Its name in the batch: ``variant/name`` in a sweep, else ``name``."""
        return f"{self.variant}/{self.name}" if self.variant else self.name


def crash_message(err: BaseException) -> str:
    """``"crashed: <type>: <message on one line>"`` for an unexpected exception."""
    message = one_line(err)
    return f"crashed: {type(err).__name__}: {message}" if message else f"crashed: {type(err).__name__}"


def error_result(
    job: Job, message: str, *, error_type: str, wall_s: float = 0.0, detail: str = ""
) -> InputResult:
    """An "error" row for ``job``."""
    return InputResult(
        name=job.name,
        path=str(job.path),
        status="error",
        error=message,
        error_type=error_type,
        wall_s=wall_s,
        detail=detail,
        group=job.group,
        seed=job.seed,
    )


def _scored_metrics(outcome: RunOutcome, job: Job) -> tuple[dict[str, float], str]:
    """The input's metrics and, for a scenario run, how it ended (read back from its run directory)."""
    metrics = metrics_from_summary(outcome.data)
    if job.relations is not None:
        from ..evaluation import load_relations, read_tum, relation_errors
        from ..report.rundir import CORRECTED_TRAJECTORY_FILE

        t_ns, poses = read_tum(Path(outcome.out_dir) / CORRECTED_TRAJECTORY_FILE)
        stats = relation_errors(t_ns, poses, load_relations(job.relations))
        metrics.update(relation_metrics(stats))
    if job.kind != "scenario":
        return metrics, ""
    scores, note = scenario_scores(Path(outcome.out_dir))
    metrics.update(scores)
    return metrics, note


def execute(task: Task, runner: Runner = run_input) -> InputResult:
    """Run one task and score it; never raises for a bad input.

    A ``GndReplayError`` becomes an "error" row with its one-line message; any other exception an "error"
    row ``"crashed: <type>: <message>"`` with the traceback in ``detail``.
    """
    t0 = time.perf_counter()
    job = task.job
    try:
        outcome = runner(task)
        metrics, note = _scored_metrics(outcome, job)
    except GndReplayError as err:
        return error_result(
            job,
            one_line(err) or type(err).__name__,
            error_type=type(err).__name__,
            wall_s=time.perf_counter() - t0,
        )
    except Exception as err:
        log.debug("input %s crashed", job.name, exc_info=True)
        return error_result(
            job,
            crash_message(err),
            error_type=type(err).__name__,
            wall_s=time.perf_counter() - t0,
            detail=traceback.format_exc(),
        )
    failures = check_limits(metrics, task.limits, {"success": note})
    return InputResult(
        name=job.name,
        path=str(job.path),
        status="fail" if failures else "pass",
        ticks=int(outcome.ticks),
        metrics=metrics,
        failures=failures,
        run_dir=Path(outcome.out_dir),
        wall_s=time.perf_counter() - t0,
        group=job.group,
        seed=job.seed,
        outcome=note,
    )
