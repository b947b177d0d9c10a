"""Run many inputs, each in its own worker process (or on a dask.distributed cluster), then write the
summary files.

Process pool: ``ProcessPoolExecutor`` with the spawn start method and one numeric thread per worker, one
future per input. A Python exception inside an input is already a value (see :func:`execute`). A worker
that dies outright (segfault, ``os._exit``, out of memory) breaks the whole pool and fails every input in
flight, so those inputs are run again each in a process of its own: the one that dies again is reported
with its exit status, the others get their real result.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import shutil
import signal
import time
import uuid
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ConfigError
from .jobs import Job
from .report import atomic_write_text, junit_xml, summary_csv, summary_md
from .thresholds import Thresholds
from .worker import InputResult, Runner, Task, crash_message, error_result, execute, pin_threads, run_input

if TYPE_CHECKING:
    from ..config import Config
    from ..replay import ReadOptions, RunOptions

__all__ = ["DASK_EXTRA_HINT", "BatchResult", "make_tasks", "run_batch", "run_tasks"]

log = logging.getLogger(__name__)

DASK_EXTRA_HINT = 'dask.distributed is not installed: pip install "gndreplay[dask]"'
ProgressFn = Callable[[InputResult], None]


@dataclass(frozen=True, slots=True)
class BatchResult:
    """What a batch produced.

    Attributes:
        results: one per input, in input order.
        out_dir: the batch folder (run directories, summary.csv, summary.md).
        summary_csv, summary_md: the summary files.
        junit: the JUnit XML file, if one was asked for.
        wall_s: wall time of the whole batch [s].
    """

    results: tuple[InputResult, ...]
    out_dir: Path
    summary_csv: Path
    summary_md: Path
    junit: Path | None
    wall_s: float

    def count(self, status: str) -> int:
        """Inputs with this status ("pass", "fail" or "error")."""
        return sum(r.status == status for r in self.results)

    @property
    def exit_code(self) -> int:
        """0 all inputs passed, 1 a threshold was exceeded, 2 an input could not be read (or crashed)."""
        if self.count("error"):
            return 2
        return 1 if self.count("fail") else 0


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
) -> list[Task]:
    """One task per job: per-input settings and limits from ``thresholds``, absolute paths (workers may run
    elsewhere), run directory ``out_dir / job.name``, and the job's goal folded into the options.

    Raises:
        ConfigError: duplicate or empty job names, or no jobs.
    """
    if not jobs:
        raise ConfigError("no inputs: give log files or folders of logs")
    seen: set[str] = set()
    for job in jobs:
        if not job.name or job.name in seen or "/" in job.name or job.name.startswith("."):
            raise ConfigError(f"input name {job.name!r} is empty, repeated, hidden or contains '/'")
        seen.add(job.name)
    out_dir = _absolute(out_dir)
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
                run_dir=out_dir / job.name,
                limits=thresholds.limits_for(job),
                read=read,
            )
        )
    return tasks


def _crash_result(task: Task, exitcode: int | None) -> InputResult:
    if exitcode is not None and exitcode < 0:
        try:
            how = f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            how = f"killed by signal {-exitcode}"
    else:
        how = f"exit code {exitcode}"
    return error_result(task.job, f"crashed: worker process died ({how})", error_type="WorkerDied")


def _child(task: Task, runner: Runner, conn: Connection) -> None:
    """Entry point of an isolated worker process: run the task, send the result back."""
    pin_threads()
    conn.send(execute(task, runner))
    conn.close()


def _run_alone(task: Task, runner: Runner) -> InputResult:
    """Run one task in a fresh process of its own; a process that dies is reported with its exit status."""
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(task, runner, send), name=f"gndreplay-batch:{task.job.name}")
    proc.start()
    send.close()
    try:
        result: InputResult | None = recv.recv()
    except EOFError:
        result = None
    finally:
        recv.close()
        proc.join()
    return result if result is not None else _crash_result(task, proc.exitcode)


def _remove_stale_temp_dirs(task: Task) -> None:
    """Remove the temporary run directories a killed worker left (``run_log`` writes into
    ``.<name>.<random>`` next to the run directory and renames it when done)."""
    parent = task.run_dir.parent
    if parent.is_dir():
        for entry in parent.glob(f".{task.run_dir.name}.*"):
            if entry.is_dir():
                shutil.rmtree(entry, ignore_errors=True)


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


def _pool_run(
    tasks: Sequence[Task], runner: Runner, workers: int, emit: Callable[[int, InputResult], None]
) -> None:
    ctx = mp.get_context("spawn")
    broken: list[int] = []
    with ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=pin_threads
    ) as pool:
        futures: dict[Future[InputResult], int] = {}
        for i in largest_first(tasks):
            try:
                futures[pool.submit(execute, tasks[i], runner)] = i
            except BrokenProcessPool:
                broken.append(i)
        try:
            for fut in as_completed(futures):
                i = futures[fut]
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    broken.append(i)
                    continue
                except Exception as err:  # the task or its result could not be sent (pickling)
                    result = error_result(tasks[i].job, crash_message(err), error_type=type(err).__name__)
                emit(i, result)
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    if broken:
        log.warning("a worker process died; running the %d inputs it took down one per process", len(broken))
        for i in broken:
            _remove_stale_temp_dirs(tasks[i])
        with ThreadPoolExecutor(max_workers=min(workers, len(broken))) as threads:
            alone = {threads.submit(_run_alone, tasks[i], runner): i for i in sorted(broken)}
            for fut in as_completed(alone):
                emit(alone[fut], fut.result())


def _import_distributed() -> Any:
    try:
        import distributed
    except ImportError as err:
        raise ConfigError(DASK_EXTRA_HINT) from err
    return distributed


def _dask_run(
    tasks: Sequence[Task], runner: Runner, address: str, emit: Callable[[int, InputResult], None]
) -> None:
    distributed = _import_distributed()
    batch_id = uuid.uuid4().hex[:8]
    try:
        client = distributed.Client(address, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as err:
        raise ConfigError(f"cannot connect to the dask scheduler at {address!r}: {err}") from err
    with client:
        futures = {
            client.submit(execute, tasks[i], runner, key=f"gndreplay-batch-{batch_id}-{i}", pure=False): i
            for i in largest_first(tasks)
        }
        pending = set(futures)
        try:
            for fut in distributed.as_completed(list(futures), loop=client.loop):
                pending.discard(fut)
                i = futures[fut]
                try:
                    result = fut.result()
                except Exception as err:  # KilledWorker (the input killed its workers), lost data, ...
                    result = error_result(tasks[i].job, crash_message(err), error_type=type(err).__name__)
                emit(i, result)
        finally:
            if pending:
                client.cancel(list(pending))


def run_tasks(
    tasks: Sequence[Task],
    *,
    workers: int = 1,
    dask_address: str | None = None,
    runner: Runner = run_input,
    progress: ProgressFn | None = None,
) -> tuple[InputResult, ...]:
    """Run the tasks in worker processes (or on the dask scheduler at ``dask_address``).

    Returns:
        one result per task, in task order (whatever the completion order); ``progress`` is called with
        each result as it completes.

    Raises:
        ConfigError: ``workers`` < 1, dask not installed, or the scheduler cannot be reached.
    """
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    results: dict[int, InputResult] = {}

    def emit(i: int, result: InputResult) -> None:
        results[i] = result
        if progress is not None:
            progress(result)

    if not tasks:
        return ()
    if dask_address is not None:
        _dask_run(tasks, runner, dask_address, emit)
    else:
        _pool_run(tasks, runner, workers, emit)
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
) -> BatchResult:
    """Run every job in its own worker process and write ``summary.csv``, ``summary.md`` (and ``junit``).

    Args:
        jobs: the inputs (``expand_inputs`` makes them from paths); names must be unique.
        cfg, options, read: stack configuration, replay options and log-reading options for every input.
        thresholds: pass/fail limits and per-input settings (None: ``DEFAULT_LIMITS``).
        out_dir: batch folder; input ``name`` writes its run directory to ``out_dir/name``.
        workers: worker processes (inputs run in parallel).
        dask_address: send the inputs to this dask.distributed scheduler instead (``gndreplay[dask]``);
            paths must be visible to its workers.
        progress: called in this process with each input's result as it completes.
        junit: write JUnit XML here (one test case per input).
        runner: what a worker does with a task (tests inject fakes; a picklable module-level function).

    Raises:
        ConfigError: no jobs, bad names, ``workers`` < 1, dask missing or unreachable.
    """
    t0 = time.perf_counter()
    thresholds = thresholds if thresholds is not None else Thresholds()
    out_dir = Path(out_dir)
    tasks = make_tasks(jobs, cfg=cfg, options=options, thresholds=thresholds, out_dir=out_dir, read=read)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = run_tasks(tasks, workers=workers, dask_address=dask_address, runner=runner, progress=progress)
    csv_path, md_path = out_dir / "summary.csv", out_dir / "summary.md"
    atomic_write_text(csv_path, summary_csv(results))
    atomic_write_text(md_path, summary_md(results))
    if junit is not None:
        atomic_write_text(Path(junit), junit_xml(results))
    return BatchResult(
        results, out_dir, csv_path, md_path, None if junit is None else Path(junit), time.perf_counter() - t0
    )
