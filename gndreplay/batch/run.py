"""Run many inputs (logs, scenario runs), each in its own worker process (or on a dask.distributed
cluster), then write the summary files.

Process pool (:mod:`.pool`): spawned worker processes with one numeric thread each, one input at a time
per worker. A Python exception inside an input is already a value (see :func:`execute`); a worker that dies
outright (segfault, ``os._exit``, out of memory) fails the one input it held; an input running longer than
the timeout is reported "timed out after N s" and its worker is killed. The batch always goes on and
writes its summary.
"""

from __future__ import annotations

import logging
import math
import os
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import fsutil
from ..errors import ConfigError, OutputError
from ..fsutil import atomic_write_text
from .aggregate import ScenarioAggregate, aggregate_scenarios
from .baseline import (
    DEFAULT_LATENCY_RATIO,
    BaselineCheck,
    check_baseline,
    check_baseline_dir,
    missing_from_batch,
)
from .jobs import Job, special_files
from .pool import Emit, run_pool, timeout_result
from .record import BATCH_FILE, BatchRecord, batch_digest, record_json, relative_runs, thresholds_ref
from .report import is_own_junit, junit_xml, scenarios_csv, summary_csv, summary_md, sweep_csv
from .scenarios import SimOptions
from .shard import Shard, shard_indices
from .sweep import SweepPoint
from .thresholds import Thresholds
from .worker import InputResult, Runner, Task, crash_message, error_result, execute, run_input

if TYPE_CHECKING:
    from ..config import Config
    from ..io import ReadOptions
    from ..replay import RunOptions
    from ..report.compare import Tolerance

__all__ = [
    "DASK_EXTRA_HINT",
    "DEFAULT_TIMEOUT_S",
    "Baseline",
    "BatchResult",
    "Setting",
    "build_batch",
    "make_tasks",
    "run_batch",
    "run_tasks",
    "write_outputs",
]

log = logging.getLogger(__name__)

DASK_EXTRA_HINT = 'dask.distributed is not installed: pip install "gndreplay[dask]"'
ProgressFn = Callable[[InputResult], None]
#: Default per-input time limit [s]: generous (the longest dev log replays in minutes on one core).
DEFAULT_TIMEOUT_S = 3600.0
_DASK_POLL_S = 0.2


@dataclass(frozen=True, slots=True)
class Setting:
    """One configuration a batch runs every input under: a sweep's combination (``point``), the stack
    configuration of the logs and how the scenarios are run and configured."""

    point: SweepPoint
    cfg: Config
    sim: SimOptions | None = None


@dataclass(frozen=True, slots=True)
class Baseline:
    """The batch folder every run is compared with (``batch.baseline``).

    Attributes:
        folder: the baseline batch folder.
        tolerance: the behaviour tolerances (``gndreplay compare --tolerance``).
        max_latency_ratio: a module's median time over the baseline's above this fails (0: not judged).
        update: the batch is written to ``folder`` as the new baseline (the comparison with the old one,
            if any, is reported; its differences do not fail the batch).
    """

    folder: Path
    tolerance: Tolerance
    max_latency_ratio: float = DEFAULT_LATENCY_RATIO
    update: bool = False


@dataclass(frozen=True, slots=True)
class _Outputs:
    """What ``write_outputs`` computed beside the files: the aggregates over seeds, the JUnit text, the
    checks against the baseline and the baseline's inputs this batch did not run."""

    aggregates: tuple[ScenarioAggregate, ...]
    junit: str
    checks: tuple[BaselineCheck, ...] = ()
    missing: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class BatchResult:
    """What a batch produced.

    Attributes:
        results: one per input (a scenario: per scenario and seed), in input order.
        out_dir: the batch folder (run directories, summary.csv, summary.md, scenarios.csv).
        summary_csv, summary_md: the summary files.
        junit: the JUnit XML file, if one was asked for.
        wall_s: wall time of the whole batch [s].
        aggregates: one per scenario, over its seeds (see ``aggregate_scenarios``).
        checks: one per input with a run, against the baseline (empty without ``--baseline``).
        missing: the baseline's inputs this batch did not run.
        baseline_updated: the batch was written as the new baseline (its checks do not fail it).
        points: the sweep's combinations (one unnamed point when nothing is swept).
    """

    results: tuple[InputResult, ...]
    out_dir: Path
    summary_csv: Path
    summary_md: Path
    junit: Path | None
    wall_s: float
    aggregates: tuple[ScenarioAggregate, ...] = ()
    checks: tuple[BaselineCheck, ...] = ()
    missing: tuple[str, ...] = ()
    baseline_updated: bool = False
    points: tuple[SweepPoint, ...] = ()

    def count(self, status: str) -> int:
        """Inputs with this status ("pass", "fail" or "error")."""
        return sum(r.status == status for r in self.results)

    @property
    def exit_code(self) -> int:
        """0 all inputs passed, 1 a threshold was exceeded (by an input or a scenario's aggregate over
        seeds) or a run's behaviour or latency changed against the baseline, 2 an input (or its baseline
        run) could not be read, or crashed."""
        if self.count("error") or (any(c.error for c in self.checks) and not self.baseline_updated):
            return 2
        changed = not self.baseline_updated and any(
            c.behaviour_failure or c.latency_failure for c in self.checks)
        return 1 if self.count("fail") or any(a.failures for a in self.aggregates) or changed else 0


def _absolute(path: Path) -> Path:
    """Absolute and without ``..`` (symbolic links kept)."""
    return Path(os.path.abspath(path))


def make_tasks(
    jobs: Sequence[Job],
    *,
    cfg: Config,
    options: RunOptions,
    thresholds: Thresholds,
    out_dir: Path,
    read: ReadOptions | None = None,
    sim: SimOptions | None = None,
    figures: bool = False,
    variant: str = "",
) -> list[Task]:
    """One task per job: per-input settings and limits from ``thresholds``, absolute paths (workers may run
    elsewhere; also ``sim``'s config file), run directory ``out_dir / job.name`` (in a sweep
    ``out_dir / variant / job.name``), and the job's goal folded into the options. Scenario jobs get ``sim``
    (None: ``SimOptions()``), logs ``figures``.

    Raises:
        ConfigError: duplicate or empty job names, no jobs, or inputs that are FIFOs, devices or sockets
            (reading one could block the batch forever; they are named, never opened).
    """
    if not jobs:
        raise ConfigError("no inputs: give log files, folders of logs, scenario files or shipped scenarios")
    seen: set[str] = set()
    for job in jobs:
        if not job.name or job.name in seen or "/" in job.name or job.name.startswith("."):
            raise ConfigError(f"input name {job.name!r} is empty, repeated, hidden or contains '/'")
        seen.add(job.name)
    special = [entry for job in jobs for entry in special_files(job.path)]
    if special:
        raise ConfigError(f"not a log file or folder (never opened): {', '.join(special)}")
    out_dir = _absolute(out_dir)
    sim = sim if sim is not None else SimOptions()
    if sim.config is not None:
        sim = replace(sim, config=_absolute(sim.config))
    tasks = []
    for job in jobs:
        job = thresholds.apply(job)
        job = replace(
            job,
            path=_absolute(job.path),
            relations=None if job.relations is None else _absolute(job.relations),
        )
        opts = options if job.goal_xy is None else replace(options, goal_xy=job.goal_xy)
        tasks.append(
            Task(
                job=job,
                cfg=cfg,
                options=opts,
                run_dir=out_dir / variant / job.name if variant else out_dir / job.name,
                limits=thresholds.limits_for(job),
                read=read,
                sim=sim if job.kind == "scenario" else None,
                figures=figures and job.kind == "log",
                variant=variant,
            )
        )
    return tasks


def _input_bytes(task: Task) -> int:
    """Size of an input on disk (a ROS2 bag folder: its files), a cheap proxy for its replay time."""
    path = Path(task.job.path)
    try:
        if path.is_dir():
            return sum(f.stat().st_size for f in path.iterdir() if f.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def largest_first(tasks: Sequence[Task]) -> list[int]:
    """Submission order: largest inputs first (longest-processing-time scheduling), so a long log does not
    start last and leave the other workers idle; results are still reported in input order."""
    return sorted(range(len(tasks)), key=lambda i: (-_input_bytes(tasks[i]), i))


def _import_distributed() -> Any:
    try:
        import distributed
    except ImportError as err:
        raise ConfigError(DASK_EXTRA_HINT) from err
    return distributed


def _dask_run(
    tasks: Sequence[Task], runner: Runner, address: str, emit: Emit, timeout_s: float | None
) -> None:
    distributed = _import_distributed()
    batch_id = uuid.uuid4().hex[:8]
    try:
        client = distributed.Client(address, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as err:
        raise ConfigError(f"cannot connect to the dask scheduler at {address!r}: {err}") from err
    with client:
        pending = {
            client.submit(execute, tasks[i], runner, key=f"gndreplay-batch-{batch_id}-{i}", pure=False): i
            for i in largest_first(tasks)
        }
        started: dict[str, tuple[float, str]] = {}  # task key -> (first seen processing, worker address)
        try:
            while pending:
                for fut in [f for f in pending if f.done()]:
                    i = pending.pop(fut)
                    try:
                        result = fut.result()
                    except Exception as err:  # KilledWorker (the input killed its workers), lost data, ...
                        result = error_result(tasks[i].job, crash_message(err), error_type=type(err).__name__)
                    emit(i, result)
                if pending and timeout_s is not None:
                    _dask_timeouts(client, tasks, pending, started, timeout_s, emit)
                if pending:
                    time.sleep(_DASK_POLL_S)
        finally:
            if pending:
                client.cancel(list(pending))


def _dask_timeouts(
    client: Any,
    tasks: Sequence[Task],
    pending: dict[Any, int],
    started: dict[str, tuple[float, str]],
    timeout_s: float,
    emit: Emit,
) -> None:
    """Report the inputs a dask worker has held for ``timeout_s`` as timed out, cancel them and restart
    their worker (dask cannot interrupt a running task: restarting its process is the only way to stop it;
    the other tasks of that worker are rescheduled by dask).

    The clock starts when the scheduler hands the input to a worker (``Client.processing``), which may hold
    it a little while behind the task it is running: keep the timeout well above one input's run time.
    """
    now = time.monotonic()
    where = {key: addr for addr, keys in client.processing().items() for key in keys}
    for fut, i in list(pending.items()):
        addr = where.get(fut.key)
        if addr is None:  # queued on the scheduler, or finished since the last look
            continue
        t_start, seen_on = started.get(fut.key, (now, addr))
        if seen_on != addr:  # rescheduled after its worker was lost: its clock starts again
            t_start = now
        started[fut.key] = (t_start, addr)
        if now - t_start >= timeout_s:
            del pending[fut]
            client.cancel([fut])
            try:
                client.restart_workers([addr], raise_for_error=False)
            except Exception as err:  # a worker without a nanny cannot be restarted
                log.warning("input %s timed out; its dask worker %s could not be restarted: %s",
                            tasks[i].job.name, addr, err)
            emit(i, timeout_result(tasks[i], timeout_s))


def _check_run_args(workers: int, timeout_s: float | None) -> None:
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if timeout_s is not None and not 0.0 < timeout_s < math.inf:
        raise ConfigError(f"the per-input timeout must be a positive number of seconds, got {timeout_s}")


def run_tasks(
    tasks: Sequence[Task],
    *,
    workers: int = 1,
    dask_address: str | None = None,
    runner: Runner = run_input,
    progress: ProgressFn | None = None,
    timeout_s: float | None = DEFAULT_TIMEOUT_S,
) -> tuple[InputResult, ...]:
    """Run the tasks in worker processes (or on the dask scheduler at ``dask_address``).

    Args:
        timeout_s: an input running longer is stopped (its worker killed) and reported "timed out after
            N s"; None: no limit.

    Returns:
        one result per task, in task order (whatever the completion order); ``progress`` is called with
        each result as it completes.

    Raises:
        ConfigError: ``workers`` < 1, ``timeout_s`` <= 0, dask not installed, or the scheduler cannot be
            reached.
    """
    _check_run_args(workers, timeout_s)
    results: dict[int, InputResult] = {}

    def emit(i: int, result: InputResult) -> None:
        results[i] = result
        if progress is not None:
            progress(result)

    if not tasks:
        return ()
    if dask_address is not None:
        _dask_run(tasks, runner, dask_address, emit, timeout_s)
    else:
        run_pool(
            tasks, largest_first(tasks), runner, workers, emit, timeout_s=timeout_s,
            on_killed=lambda task: fsutil.remove_stale_staging(task.run_dir.parent),
        )
    return tuple(results[i] for i in range(len(tasks)))


def run_batch(
    jobs: Sequence[Job],
    *,
    cfg: Config,
    options: RunOptions,
    thresholds: Thresholds | None = None,
    out_dir: Path = Path("out/batch"),
    workers: int = 1,
    dask_address: str | None = None,
    progress: ProgressFn | None = None,
    junit: Path | None = None,
    read: ReadOptions | None = None,
    runner: Runner = run_input,
    timeout_s: float | None = DEFAULT_TIMEOUT_S,
    overwrite: bool = False,
    sim: SimOptions | None = None,
    figures: bool = False,
    shard: Shard | None = None,
    sweep: Sequence[Setting] = (),
    baseline: Baseline | None = None,
) -> BatchResult:
    """Run every job in its own worker process and write the batch folder: one run directory per input,
    ``summary.csv``, ``summary.md`` (and ``junit``), ``batch.json`` (:mod:`.record`); with scenario jobs also
    ``scenarios.csv``, the per-scenario aggregates over seeds, checked against the aggregate thresholds.
    With ``shard``, only that shard's jobs run (``shard.shard_indices``; ``merge_batches`` joins the
    shard folders).

    The batch folder gets the protections of a run directory (``gndreplay.fsutil``), checked before any
    work: never a file, the current folder, a folder holding an input, or a non-empty folder gndreplay did
    not write. It is built in a staging directory beside it and appears, marked, only when complete; an
    earlier batch folder there is replaced only with ``overwrite``, otherwise the batch is written beside
    it as ``out_dir-2``, ... (``BatchResult.out_dir`` says where; also when a concurrent batch took the
    name first).

    Args:
        jobs: the inputs (``expand_inputs`` makes them from paths); names must be unique.
        cfg, options, read: stack configuration, replay options and log-reading options for every log.
        thresholds: pass/fail limits and per-input settings (None: ``DEFAULT_LIMITS``).
        out_dir: batch folder; input ``name`` writes its run directory to ``out_dir/name``.
        workers: worker processes (inputs run in parallel).
        dask_address: send the inputs to this dask.distributed scheduler instead (``gndreplay[dask]``);
            paths must be visible to its workers.
        progress: called in this process with each input's result as it completes.
        junit: write JUnit XML here (one test case per input); inside ``out_dir`` it moves with the folder.
        runner: what a worker does with a task (tests inject fakes; a picklable module-level function).
        timeout_s: per-input time limit [s] (None: none); an input over it is an "error" row
            "timed out after N s" and its worker process is killed.
        overwrite: replace an earlier batch folder at ``out_dir``.
        sim: how scenario jobs run and which configuration they get (None: ``SimOptions()``, each
            scenario's own preset).
        figures: draw each log's figures, maps.npz and report.md in its run directory (a scenario run's
            figures: ``sim.figures``).
        shard: run only the jobs of this shard (None: all of them).
        sweep: run every job under each of these settings (a sweep's combinations, each in its folder
            ``out_dir / point.name``) instead of ``cfg`` and ``sim``; sweep.csv gives a row per setting.
        baseline: compare every run with the same run in this baseline batch folder (two checks per input,
            in summary.md and the JUnit file); with ``update``, ``out_dir`` is the baseline folder.

    Raises:
        ConfigError: no jobs, bad names, FIFO / device inputs, ``workers`` < 1, bad timeout, dask missing
            or unreachable, a baseline folder that is not a batch folder.
        OutputError: ``out_dir`` (or ``junit``) is unsafe to write, or the disk is full (quota, read-only)
            while writing.
    """
    t0 = time.perf_counter()
    thresholds = thresholds if thresholds is not None else Thresholds()
    out_dir = _absolute(Path(out_dir))
    settings = tuple(sweep) or (Setting(SweepPoint("", (), ()), cfg, sim),)
    tasks = [
        task
        for s in settings
        for task in make_tasks(jobs, cfg=s.cfg, options=options, thresholds=thresholds, out_dir=out_dir,
                               read=read, sim=s.sim, figures=figures, variant=s.point.name)
    ]
    _check_run_args(workers, timeout_s)
    th_path, th_sha = thresholds_ref(thresholds)
    record = BatchRecord(
        digest=batch_digest(tasks, out_dir, thresholds_sha256=th_sha, timeout_s=timeout_s),
        total=len(tasks), shard=shard, indices=tuple(shard_indices(len(tasks), shard)),
        thresholds_path=th_path, thresholds_sha256=th_sha, points=tuple(s.point for s in settings),
    )

    def produce(tmp: Path, final: Path) -> tuple[InputResult, ...]:
        """Run this shard's tasks into the staging folder ``tmp`` (a sweep's in a marked folder per
        combination); results as they will be at ``final``."""
        mine = [tasks[i] for i in record.indices]
        combos = sorted({t.variant for t in mine if t.variant})
        for name in combos:
            _mkdirs_marked(tmp, Path(name))
        staged = [replace(t, run_dir=tmp / t.run_dir.relative_to(out_dir)) for t in mine]
        shown = None if progress is None else (lambda r: progress(_moved(r, tmp, final)))
        results = run_tasks(
            staged, workers=workers, dask_address=dask_address, runner=runner, progress=shown,
            timeout_s=timeout_s,
        )
        for folder in (tmp, *(tmp / name for name in combos)):
            fsutil.remove_stale_staging(folder)  # left by an input whose worker was killed
        for name in combos:
            fsutil.write_marker(tmp / name)
        return tuple(_moved(replace(r, variant=t.variant), tmp, final)
                     for t, r in zip(mine, results, strict=True))

    return build_batch(
        out_dir, inputs=[t.job.path for t in tasks], junit=junit, overwrite=overwrite, thresholds=thresholds,
        record=record, produce=produce, t0=t0, baseline=baseline,
    )


def build_batch(
    out_dir: Path,
    *,
    inputs: Sequence[Path],
    junit: Path | None,
    overwrite: bool,
    thresholds: Thresholds,
    record: BatchRecord,
    produce: Callable[[Path, Path], tuple[InputResult, ...]],
    t0: float,
    baseline: Baseline | None = None,
) -> BatchResult:
    """Build the batch folder ``out_dir`` as every gndreplay output is built (checked before any work,
    staged, published under the first free name): ``produce(tmp, final)`` writes the run directories into
    the staging folder ``tmp`` and returns the results as they will be at ``final``; then
    ``write_outputs`` (with the checks against ``baseline``). Used by ``run_batch`` and ``merge_batches``.

    Raises:
        ConfigError: ``baseline`` is not a batch folder (checked before any work).
        OutputError: ``out_dir`` (or ``junit``) is unsafe to write, or the disk is full while writing.
    """
    out_dir = _absolute(Path(out_dir))
    old_baseline = _baseline_folder(baseline)
    fsutil.check_output_dir(out_dir, inputs=inputs, overwrite=overwrite)
    junit_rel, junit_out = _junit_place(junit, out_dir, inputs=inputs, overwrite=overwrite)
    target = fsutil.resolve_output_dir(out_dir, overwrite=overwrite)
    stage = fsutil.staging_dir(target, overwrite=overwrite, base=out_dir)
    with stage as tmp:
        results = produce(tmp, target)
        outputs = write_outputs(
            tmp, target, results, thresholds=thresholds, record=record, junit_rel=junit_rel,
            baseline=None if baseline is None or old_baseline is None
            else replace(baseline, folder=old_baseline),
            updated=baseline is not None and baseline.update,
        )
    if stage.out != target:  # a concurrent batch took the name first: the folder is at the next free one
        results = tuple(_moved(r, target, stage.out) for r in results)
        target = stage.out
    if junit_out is not None:
        with fsutil.write_errors(junit_out):
            junit_out.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(junit_out, outputs.junit)
    junit_path = target / junit_rel if junit_rel is not None else junit_out
    return BatchResult(
        results, target, target / "summary.csv", target / "summary.md", junit_path, time.perf_counter() - t0,
        outputs.aggregates, checks=outputs.checks, missing=outputs.missing,
        baseline_updated=baseline is not None and baseline.update, points=record.points,
    )


def _baseline_folder(baseline: Baseline | None) -> Path | None:
    """The baseline folder to compare with, checked before any work; None without one (or, updating, when
    there is none yet: the first baseline)."""
    if baseline is None:
        return None
    folder = _absolute(baseline.folder)
    if baseline.update and not folder.exists():
        return None
    return check_baseline_dir(folder)


def write_outputs(
    tmp: Path,
    final: Path,
    results: Sequence[InputResult],
    *,
    thresholds: Thresholds,
    record: BatchRecord,
    junit_rel: Path | None,
    baseline: Baseline | None = None,
    updated: bool = False,
) -> _Outputs:
    """Write the files of a finished batch into its staging folder ``tmp`` (published at ``final``): the
    per-scenario aggregates over seeds, the checks of every run against ``baseline`` (its folder checked;
    ``updated``: the batch becomes the new baseline, the changes are accepted), summary.csv, summary.md,
    scenarios.csv (with scenarios), sweep.csv (in a sweep: ``record.points``), the JUnit file at
    ``junit_rel`` inside it (if given) and batch.json (``record`` with ``results``). Run directories are
    written relative to the batch folder."""
    shown = relative_runs(results, final)
    aggregates = aggregate_scenarios(results, thresholds)
    checks: tuple[BaselineCheck, ...] = ()
    missing: tuple[str, ...] = ()
    if baseline is not None:
        checks = check_baseline(results, batch_dir=final, runs_dir=tmp, baseline=baseline.folder,
                                tolerance=baseline.tolerance, max_ratio=baseline.max_latency_ratio)
        missing = missing_from_batch(results, baseline.folder)
    junit_text = junit_xml(shown, aggregates, checks=checks, baseline_updated=updated)
    atomic_write_text(tmp / "summary.csv", summary_csv(shown))
    atomic_write_text(tmp / "summary.md", summary_md(shown, aggregates, checks=checks, missing=missing,
                                                     points=record.points, baseline_updated=updated))
    if aggregates:
        atomic_write_text(tmp / "scenarios.csv", scenarios_csv(aggregates))
    if any(p.name for p in record.points):
        atomic_write_text(tmp / "sweep.csv", sweep_csv(record.points, results))
    if junit_rel is not None:
        _mkdirs_marked(tmp, junit_rel.parent)
        atomic_write_text(tmp / junit_rel, junit_text)
        fsutil.add_to_marker((tmp / junit_rel).parent, [junit_rel.name])
    atomic_write_text(tmp / BATCH_FILE, record_json(replace(record, results=shown)))
    return _Outputs(aggregates, junit_text, checks, missing)


def _moved(r: InputResult, old: Path, new: Path) -> InputResult:
    """``r`` with its run directory under ``new`` instead of ``old`` (a result outside ``old`` as it is)."""
    if r.run_dir is None or not Path(r.run_dir).is_relative_to(old):
        return r
    return replace(r, run_dir=new / Path(r.run_dir).relative_to(old))


def _mkdirs_marked(root: Path, rel: Path) -> None:
    """Create the folders ``rel`` inside the staging folder ``root``, each marked as gndreplay's (a later
    ``--overwrite`` of the batch folder may then replace them)."""
    here = root
    for part in rel.parts:
        here = here / part
        here.mkdir(exist_ok=True)
        if not fsutil.is_output_dir(here):
            fsutil.write_marker(here, [])
        fsutil.add_to_marker(here.parent, [part])


def _junit_place(
    junit: Path | None, out_dir: Path, *, inputs: Sequence[Path] = (), overwrite: bool = False
) -> tuple[Path | None, Path | None]:
    """(path inside the batch folder, or None; path outside it, or None) of the JUnit file, checked before
    any work.

    Raises:
        OutputError: ``junit`` is a folder, a symbolic link, an input (or inside an input folder), or an
            existing file that is not a JUnit file gndreplay wrote (or is one and ``overwrite`` is not given).
    """
    if junit is None:
        return None, None
    path = _absolute(Path(junit))
    if path.is_dir():
        raise OutputError(f"{junit}: is a folder; --junit must name a file")
    if path.is_symlink():
        raise OutputError(f"{junit}: is a symbolic link; --junit must name a file")
    real = Path(os.path.realpath(path))
    for p in inputs:
        ip = Path(os.path.realpath(_absolute(Path(p))))
        if real == ip or real.is_relative_to(ip):
            raise OutputError(f"{junit}: is the input {p} or inside it; choose another --junit file")
    if path == out_dir:
        raise OutputError(f"{junit}: is the batch folder; --junit must name a file")
    if path.is_relative_to(out_dir):
        return path.relative_to(out_dir), None
    if path.exists():
        if not is_own_junit(path):
            raise OutputError(f"{junit}: exists and is not a JUnit file gndreplay wrote; not overwriting it")
        if not overwrite:
            raise OutputError(f"{junit}: exists (an earlier batch's JUnit file); --overwrite replaces it")
    return None, path
