"""A matcher run in a second process, ahead of its consumer: ``MatchAhead``.

An open-loop replay knows every scan in advance, so scan matching need not wait for the navigation stack:
the log is read in the calling process, each scan and odometry pose is sent to a child process that runs
the matcher, and the results come back in order while the caller works on earlier ticks. The child runs
the same matcher on the same inputs in the same order, so the poses are those of the sequential run, bit
for bit (floats cross the pipe as their bytes); only the wall-clock match time is measured in the child.

The child is a fresh interpreter (``python -c``, talking over two pipes): it inherits no state, so it is
safe beside the caller's threads, and unlike ``multiprocessing``'s spawn it never re-imports the caller's
main script, which may have no ``__main__`` guard. It warms its matcher's kernels while the caller warms
its own, so a cold numba cache is compiled by both processes at once. POSIX only (``available``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from ..compiling import CompileListener
from ..errors import ScanMatchError
from ..types import Tick
from .base import Matcher, MatchResult

__all__ = ["MatchAhead", "available", "worthwhile"]

_READY = "ready"
_COMPILED = "compiled"


def available() -> bool:
    """Whether ``MatchAhead`` can run here (it passes pipe descriptors to the child: POSIX)."""
    return os.name == "posix"


def worthwhile() -> bool:
    """Whether matching ahead pays here: ``available`` and at least two CPUs this process may use."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return available() and cpus >= 2


def serve(read_fd: int, write_fd: int) -> None:
    """The child's entry: read (make, warm_up) from the pipe, warm up (reporting each kernel compiled),
    say ready, then answer each (scan, odometry) with (MatchResult, match ms) until the pipe closes. A
    failure is sent back as the exception."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and closes the pipe
    rx, tx = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
    try:
        setup = rx.recv()
        if setup is None:  # closed before it was set up
            return
        make, warm_up = setup
        if warm_up is not None:
            with CompileListener(lambda name: tx.send((_COMPILED, name))):
                warm_up()
        matcher = make()
        tx.send((_READY, None))
        while True:
            msg = rx.recv()
            if msg is None:
                return
            scan, odom = msg
            t0 = time.perf_counter_ns()
            res = matcher.update(scan, odom)
            tx.send((res, (time.perf_counter_ns() - t0) / 1e6))
    except (BrokenPipeError, EOFError):
        return
    except BaseException as exc:  # the parent re-raises it at the tick it belongs to
        try:
            tx.send(exc)
        except OSError:  # the parent closed the pipe: nobody left to tell
            return
        except Exception:  # an exception that does not pickle
            with contextlib.suppress(OSError):
                tx.send(RuntimeError(f"scan matcher failed: {exc!r}"))


class MatchAhead:
    """A matcher in a child process, fed up to ``depth`` ticks ahead of the consumer.

    Use as a context manager: the child starts on entry (call ``ready`` to wait for its warm-up) and is
    stopped on exit, also on an error or Ctrl-C. ``results(ticks)`` yields (tick, MatchResult, match ms)
    in the order of ``ticks``.

    Args:
        make: builds the matcher in the child (picklable: a module-level function or a partial of one).
        warm_up: compiles the matcher's kernels in the child before it says ready (picklable), or None.
        depth: ticks sent ahead of the one being consumed (memory: ``depth`` scans).
    """

    def __init__(self, make: Callable[[], Matcher], warm_up: Callable[[], None] | None = None, *,
                 depth: int = 32) -> None:
        if depth < 1:
            raise ValueError(f"depth must be >= 1, got {depth!r}")
        self._make, self._warm_up, self.depth = make, warm_up, depth
        self._tx: Connection | None = None
        self._rx: Connection | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._ready = False

    def __enter__(self) -> MatchAhead:
        if not available():
            raise RuntimeError("MatchAhead needs POSIX pipes")
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        # this gndreplay, also from a source tree: its root is put first on the child's path unless the
        # path holds it already (an installed package: site-packages, which must stay after the standard
        # library)
        root = str(Path(__file__).resolve().parents[2])
        code = (f"import sys; root = {root!r}; sys.path[:0] = [] if root in sys.path else [root]; "
                f"from gndreplay.scanmatch.ahead import serve; serve({to_child_r}, {from_child_w})")
        try:
            # its own process group: a terminal's Ctrl-C (or a SIGTERM to the group) reaches only the
            # caller, which closes the pipes; the child would otherwise print KeyboardInterrupt's traceback
            # while still importing, before ``serve`` ignores SIGINT
            self._proc = subprocess.Popen([sys.executable, "-c", code], pass_fds=(to_child_r, from_child_w),
                                          stdin=subprocess.DEVNULL, process_group=0)
        except BaseException:
            for fd in (to_child_r, to_child_w, from_child_r, from_child_w):
                os.close(fd)
            raise
        os.close(to_child_r)
        os.close(from_child_w)
        self._tx = Connection(to_child_w, readable=False)
        self._rx = Connection(from_child_r, writable=False)
        try:
            self._tx.send((self._make, self._warm_up))
        except BaseException:  # e.g. a ``make`` that does not pickle: no ``__exit__`` will stop the child
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the child (it ends when the pipe closes; killed if it does not within 5 s)."""
        tx, rx, proc = self._tx, self._rx, self._proc
        self._tx = self._rx = self._proc = None
        if tx is not None:
            with contextlib.suppress(BrokenPipeError, OSError):
                tx.send(None)
            tx.close()
        if rx is not None:
            rx.close()
        if proc is not None:
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()

    def _recv(self) -> Any:
        assert self._rx is not None, "MatchAhead used outside its with block"
        try:
            msg = self._rx.recv()
        except EOFError:
            raise self._ended() from None
        if isinstance(msg, BaseException):
            raise msg
        return msg

    def _ended(self) -> ScanMatchError:
        """The error of a child that ended owing results (killed, out of memory, crashed)."""
        status = None
        if self._proc is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                status = self._proc.wait(timeout=2.0)
        return ScanMatchError(f"the scan matcher's process ended unexpectedly (exit status {status}); "
                              "--no-match-ahead matches in this process")

    def ready(self, on_compile: Callable[[str], None] | None = None) -> None:
        """Wait until the child has warmed up; ``on_compile`` hears each kernel it compiled."""
        while not self._ready:
            kind, value = self._recv()
            if kind == _COMPILED:
                if on_compile is not None:
                    on_compile(value)
            elif kind == _READY:
                self._ready = True

    def results(
        self, ticks: Iterable[Tick], ahead_while: Callable[[Tick], bool] | None = None
    ) -> Iterator[tuple[Tick, MatchResult, float]]:
        """(tick, its match, match ms) for each tick in order, the child matching up to ``depth`` ticks
        ahead. From the first tick for which ``ahead_while`` is False on, ticks are read only as they are
        consumed, as a sequential pass reads them: a consumer that stops early (``until_s``) leaves the log
        read exactly as far. An exception of the matcher is raised here at the tick that caused it."""
        self.ready()
        assert self._tx is not None
        pending: deque[Tick] = deque()
        it = iter(ticks)
        eager, exhausted, ended = True, False, False
        while True:
            while not exhausted and not ended and len(pending) < (self.depth if eager else 1):
                tick = next(it, None)
                if tick is None:
                    exhausted = True
                    break
                try:
                    self._tx.send((tick.scan, tick.odom))
                except BrokenPipeError:  # the child ended: what it owes (its exception) is still to be read
                    ended = True
                    break
                pending.append(tick)
                if ahead_while is not None and not ahead_while(tick):
                    eager = False
            if not pending:
                if ended:
                    raise self._ended()
                return
            res, ms = self._recv()
            yield pending.popleft(), res, ms
