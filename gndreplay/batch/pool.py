"""A small process pool that knows which input each worker runs, so it can time an input out and kill it.

``concurrent.futures.ProcessPoolExecutor`` can neither stop one running task nor say which input a dead
worker held (a dead worker breaks the whole pool). Here each worker is a spawned process with its own pipe;
the parent hands it one task at a time, so:

- an input that runs longer than ``timeout_s`` is reported ``"timed out after N s"``, its worker is killed
  (SIGKILL, then reaped) and replaced, and the batch goes on;
- a worker that dies (segfault, ``os._exit``, out of memory) fails exactly the input it held, with its exit
  status; the other inputs are not touched;
- workers are reused between inputs, so the numeric libraries are imported and compiled once per worker;
- on Linux a worker dies with the batch process, even when that one is killed outright.

The clock of an input starts when its worker says it has started it (after the task is unpickled), so
spawning a fresh worker and importing the replay code are not charged to it; a worker that does not even
start the input within the timeout plus two minutes is treated as hung too.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import multiprocessing as mp
import pickle
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from typing import Any

from .worker import InputResult, Runner, Task, crash_message, error_result, execute, pin_threads

__all__ = ["Emit", "crash_result", "run_pool", "timeout_result"]

Emit = Callable[[int, InputResult], None]

#: Seconds a worker gets to exit after being told to, before it is killed.
_EXIT_GRACE_S = 5.0
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
#: Extra seconds a worker gets to start an input it was handed (spawn, imports) before its clock runs.
_STARTUP_S = 120.0


def crash_result(task: Task, exitcode: int | None) -> InputResult:
    """The "error" row of an input whose worker process died with ``exitcode``."""
    if exitcode is not None and exitcode < 0:
        try:
            how = f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            how = f"killed by signal {-exitcode}"
    else:
        how = f"exit code {exitcode}"
    return error_result(task.job, f"crashed: worker process died ({how})", error_type="WorkerDied")


def timeout_result(task: Task, timeout_s: float) -> InputResult:
    """The "error" row of an input stopped after ``timeout_s`` seconds."""
    return error_result(task.job, f"timed out after {timeout_s:g} s", error_type="Timeout", wall_s=timeout_s)


def _die_with_parent() -> None:
    """Linux: have the kernel SIGKILL this worker when the batch process dies (even by SIGKILL), so a
    killed batch leaves no worker running on."""
    if not sys.platform.startswith("linux"):
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def _serve(conn: Connection) -> None:
    """A worker process: run the tasks the parent sends (pickled ``(task, runner)``) until it sends an
    empty message or goes away.

    Sends ``("start", None)`` when a task begins, then ``("done", InputResult)``, or ``("crash", message)``
    when the task cannot be unpickled or its result cannot be sent back.
    """
    pin_threads()  # before the task's unpickling imports numpy / numba
    _die_with_parent()
    try:
        while True:
            try:
                payload = conn.recv_bytes()
            except EOFError:  # the parent went away
                return
            if not payload:
                return
            try:
                task, runner = pickle.loads(payload)
            except Exception as err:
                conn.send(("crash", crash_message(err)))
                continue
            conn.send(("start", None))
            result = execute(task, runner)
            try:
                conn.send(("done", result))
            except Exception as err:  # an unpicklable metric or detail
                conn.send(("crash", crash_message(err)))
    except KeyboardInterrupt:  # Ctrl-C reaches the whole process group; the parent reports it
        return
    except BrokenPipeError:
        return


@dataclass(slots=True)
class _Worker:
    """One worker process and the input it holds (``index`` None: idle)."""

    proc: BaseProcess
    conn: Connection
    index: int | None = None
    deadline: float = math.inf

    def stop(self, *, kill: bool) -> None:
        """End the process (asked to when idle; SIGKILL when busy or not exiting) and reap it."""
        if not kill:
            with contextlib.suppress(OSError):
                self.conn.send_bytes(b"")
            self.proc.join(_EXIT_GRACE_S)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def _spawn(ctx: Any) -> _Worker:
    parent, child = ctx.Pipe(duplex=True)
    proc = ctx.Process(target=_serve, args=(child,), name="gndreplay-batch-worker")
    proc.start()
    child.close()
    return _Worker(proc, parent)


def run_pool(
    tasks: Sequence[Task],
    order: Sequence[int],
    runner: Runner,
    workers: int,
    emit: Emit,
    *,
    timeout_s: float | None = None,
    on_killed: Callable[[Task], object] | None = None,
) -> None:
    """Run ``tasks[i]`` for ``i`` in ``order`` on up to ``workers`` spawned processes; ``emit(i, result)``
    as each completes. ``timeout_s`` (None: no limit) bounds each input; ``on_killed(task)`` runs after the
    worker of a timed-out or dead input is gone (to clean what it left)."""
    ctx = mp.get_context("spawn")
    queue = deque(order)
    pool: list[_Worker] = []
    limit = math.inf if timeout_s is None else float(timeout_s)

    def finish(w: _Worker, result: InputResult, *, dead: bool) -> None:
        assert w.index is not None
        i, w.index, w.deadline = w.index, None, math.inf
        if dead:
            pool.remove(w)
            w.stop(kill=True)
            if on_killed is not None:
                on_killed(tasks[i])
        emit(i, result)

    try:
        while queue or any(w.index is not None for w in pool):
            # hand every idle worker (and new ones, up to ``workers``) the next input
            while queue:
                idle = next((w for w in pool if w.index is None), None)
                fresh = idle is None
                if idle is None:
                    if len(pool) >= workers:
                        break
                    idle = _spawn(ctx)
                    pool.append(idle)
                i = queue.popleft()
                try:
                    payload = pickle.dumps((tasks[i], runner))
                except Exception as err:  # the task cannot be sent
                    emit(i, error_result(tasks[i].job, crash_message(err), error_type=type(err).__name__))
                    continue
                idle.index, idle.deadline = i, time.monotonic() + limit + _STARTUP_S
                try:
                    idle.conn.send_bytes(payload)
                except OSError:  # the worker is dead: a reused one died idle, the input goes to another
                    idle.proc.join(_EXIT_GRACE_S)
                    if fresh:
                        finish(idle, crash_result(tasks[i], idle.proc.exitcode), dead=True)
                    else:
                        idle.index = None
                        pool.remove(idle)
                        idle.stop(kill=True)
                        queue.appendleft(i)
            busy = [w for w in pool if w.index is not None]
            if not busy:
                continue
            wait_s = max(0.0, min(w.deadline for w in busy) - time.monotonic())
            ready = wait([w.conn for w in busy], timeout=None if math.isinf(wait_s) else wait_s)
            for w in busy:
                assert w.index is not None
                if w.conn in ready:
                    try:
                        kind, value = w.conn.recv()
                    except (EOFError, OSError):  # the worker died holding this input
                        w.proc.join(_EXIT_GRACE_S)
                        finish(w, crash_result(tasks[w.index], w.proc.exitcode), dead=True)
                        continue
                    if kind == "start":
                        w.deadline = time.monotonic() + limit
                    elif kind == "done":
                        finish(w, value, dead=False)
                    else:
                        failed = error_result(tasks[w.index].job, value, error_type="WorkerError")
                        finish(w, failed, dead=False)
                elif time.monotonic() >= w.deadline:
                    finish(w, timeout_result(tasks[w.index], limit), dead=True)
    finally:
        for w in pool:
            w.stop(kill=w.index is not None)
