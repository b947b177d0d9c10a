"""The matcher factory, trajectory correction over a tick stream, and the ``scanmatch`` command's function."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import itertools
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..errors import ScanMatchError
from ..evaluation import (
    HealthParams,
    MatcherHealth,
    Relations,
    RelationStats,
    TrajectoryErrors,
    matcher_health,
    relation_errors,
    trajectory_errors,
    write_tum,
)
from ..fsutil import check_output_dir, resolve_output_dir, staging_dir
from ..io import DEFAULT_READ, LogReader, ReadOptions, open_log
from ..io.clock import fmt_ns, scan_clock
from ..types import Pose2D, Scan, Tick
from .ahead import MatchAhead, available
from .base import Matcher, MatchResult, OdomMatcher
from .idc import IdcMatcher, IdcParams
from .kiss import KissIcpMatcher, KissParams

__all__ = ["METHODS", "CorrectedTrajectory", "MatcherReport", "correct_trajectories", "correct_trajectory",
           "health_params", "interleave_bearings", "keep_by_travel", "log_ticks", "make_matcher",
           "matcher_report", "relations_time_base", "run_scanmatch", "timed_matches", "warm_up_matcher"]

Method = Literal["idc", "kiss-icp", "odom"]
METHODS: tuple[Method, ...] = ("odom", "idc", "kiss-icp")
#: Under this share of the relations matching the log's scan stamps, ``scanmatch`` warns (the errors
#: describe a few relations only: likely another clock, or relations of another log).
FEW_MATCHED = 0.5


def make_matcher(method: Method, *, idc: IdcParams | None = None, kiss: KissParams | None = None) -> Matcher:
    """A fresh matcher; each gets only its own parameters.

    Raises:
        ScanMatchError: unknown method.
    """
    if method == "idc":
        return IdcMatcher(idc)
    if method == "kiss-icp":
        return KissIcpMatcher(kiss)
    if method == "odom":
        return OdomMatcher()
    raise ScanMatchError(f"unknown matcher {method!r}: expected one of {', '.join(METHODS)}")


def warm_up_matcher(make: Callable[[], Matcher]) -> None:
    """Compile the kernels of the matchers ``make`` builds on synthetic scans of a bumpy round room before
    timing, with every mix of writable and read-only ranges and angles (numba compiles each apart; the
    CARMEN reader hands out writable ranges with shared read-only beam angles, a pipe writable copies)."""
    for ranges_ro, angles_ro in itertools.product((False, True), repeat=2):
        matcher = make()
        angles = np.linspace(-math.pi / 2, math.pi / 2, 361)
        angles.flags.writeable = not angles_ro
        for k in range(3):
            pose = Pose2D(0.05 * k, 0.0, 0.01 * k)
            ranges = 4.0 + 0.4 * dm.sin_a(5.0 * (angles + pose.theta)) - pose.x * dm.cos_a(angles)
            ranges.flags.writeable = not ranges_ro
            matcher.update(Scan(t_ns=k, ranges_m=ranges, angles_rad=angles, max_range_m=30.0), pose)


def health_params(idc: IdcParams | None = None) -> HealthParams:
    """The matcher-health limits with the odometry error model of the IDC parameters (the configured ones:
    whichever matcher runs, it is the odometry's model)."""
    return HealthParams.from_odometry(idc if idc is not None else IdcParams())


@dataclass(frozen=True, eq=False)
class CorrectedTrajectory:
    """One matcher's output over a log.

    Attributes:
        method: matcher name.
        t_ns: (N,) int64 scan stamps.
        poses: (N, 3) corrected robot poses (x, y, theta).
        ok: (N,) bool, False where the match failed (MATCH_FAILED).
        pairs, iterations: (N,) int64 per-scan figures; residual_m: (N,) float64.
        ms: (N,) float64 wall-clock time of each ``update`` call [ms] (the only non-deterministic field).
        reason: (N,) why each match failed ("" where it did not).
        odom: (N, 3) the odometry poses of the scans.
        truth_t_ns, truth: (M,) stamps and (M, 3) poses of the scans that have ground truth (M may be 0).
    """

    method: str
    t_ns: NDArray[np.int64]
    poses: NDArray[np.float64]
    ok: NDArray[np.bool_]
    pairs: NDArray[np.int64]
    residual_m: NDArray[np.float64]
    iterations: NDArray[np.int64]
    ms: NDArray[np.float64]
    reason: tuple[str, ...]
    odom: NDArray[np.float64]
    truth_t_ns: NDArray[np.int64]
    truth: NDArray[np.float64]

    @property
    def failures(self) -> int:
        return int(np.count_nonzero(~self.ok))


class _Collector:
    """Accumulates one matcher's (tick, result, ms) into a ``CorrectedTrajectory``."""

    def __init__(self, method: str) -> None:
        self.method = method
        self.t: list[int] = []
        self.poses: list[tuple[float, float, float]] = []
        self.ok: list[bool] = []
        self.pairs: list[int] = []
        self.resid: list[float] = []
        self.iters: list[int] = []
        self.ms: list[float] = []
        self.reason: list[str] = []
        self.odom: list[tuple[float, float, float]] = []
        self.truth_t: list[int] = []
        self.truth: list[tuple[float, float, float]] = []

    def add(self, tick: Tick, res: MatchResult, ms: float) -> None:
        self.ms.append(ms)
        self.t.append(tick.t_ns)
        self.poses.append((res.pose.x, res.pose.y, res.pose.theta))
        self.ok.append(res.ok)
        self.pairs.append(res.pairs)
        self.resid.append(res.residual_m)
        self.iters.append(res.iterations)
        self.reason.append("" if res.ok else res.reason)
        self.odom.append((tick.odom.x, tick.odom.y, tick.odom.theta))
        if tick.truth is not None:
            self.truth_t.append(tick.t_ns)
            self.truth.append((tick.truth.x, tick.truth.y, tick.truth.theta))

    def result(self) -> CorrectedTrajectory:
        return CorrectedTrajectory(
            self.method, np.array(self.t, dtype=np.int64),
            np.array(self.poses, dtype=np.float64).reshape(-1, 3),
            np.array(self.ok, dtype=bool), np.array(self.pairs, dtype=np.int64),
            np.array(self.resid, dtype=np.float64), np.array(self.iters, dtype=np.int64),
            np.array(self.ms, dtype=np.float64), tuple(self.reason),
            np.array(self.odom, dtype=np.float64).reshape(-1, 3), np.array(self.truth_t, dtype=np.int64),
            np.array(self.truth, dtype=np.float64).reshape(-1, 3))


def timed_matches(ticks: Iterable[Tick], matcher: Matcher) -> Iterator[tuple[Tick, MatchResult, float]]:
    """(tick, ``matcher``'s result, the wall-clock ms of its update) for each tick, in order."""
    for tick in ticks:
        t0 = time.perf_counter_ns()
        res = matcher.update(tick.scan, tick.odom)
        yield tick, res, (time.perf_counter_ns() - t0) / 1e6


def correct_trajectory(ticks: Iterable[Tick], matcher: Matcher) -> CorrectedTrajectory:
    """Run ``matcher`` over the ticks (time order) and collect its corrected trajectory and timings."""
    out = _Collector(matcher.name)
    for tick, res, ms in timed_matches(ticks, matcher):
        out.add(tick, res, ms)
    return out.result()


def correct_trajectories(ticks: Iterable[Tick], methods: Sequence[Method], *, idc: IdcParams | None = None,
                         kiss: KissParams | None = None) -> list[CorrectedTrajectory]:
    """``correct_trajectory`` of every method in one pass over the ticks, each matcher but raw odometry in
    its own process (``MatchAhead``: one matcher per core, the same results as one pass each)."""
    outs = [_Collector(m) for m in methods]
    with contextlib.ExitStack() as stack:
        streams: list[Iterator[tuple[Tick, MatchResult, float]]] = []
        for method, copy in zip(methods, itertools.tee(ticks, len(methods)), strict=True):
            make = functools.partial(make_matcher, method, idc=idc, kiss=kiss)
            if method == "odom":
                streams.append(timed_matches(copy, make()))
            else:
                ahead = stack.enter_context(MatchAhead(make, functools.partial(warm_up_matcher, make)))
                streams.append(ahead.results(copy))
        for row in zip(*streams, strict=True):
            for out, (tick, res, ms) in zip(outs, row, strict=True):
                out.add(tick, res, ms)
    return [o.result() for o in outs]


def keep_by_travel(ticks: Iterable[Tick], dist_m: float, angle_rad: float) -> list[Tick]:
    """The ticks after which the odometry moved ``dist_m`` or turned ``angle_rad`` since the last kept one
    (the first is kept): the log as one sampled by distance would hold it (CARMEN robotlaser style)."""
    kept: list[Tick] = []
    last = (0.0, 0.0, 0.0)
    for tick in ticks:
        o = tick.odom
        if kept:
            c, s = dm.cos(last[2]), dm.sin(last[2])
            dx, dy = o.x - last[0], o.y - last[1]
            turn = abs(math.remainder(o.theta - last[2], 2.0 * math.pi))
            if math.hypot(c * dx + s * dy, -s * dx + c * dy) < dist_m and turn < angle_rad:
                continue
        kept.append(tick)
        last = (o.x, o.y, o.theta)
    return kept


def interleave_bearings(ticks: Iterable[Tick], step_rad: float, phases: int) -> list[Tick]:
    """The ticks with scan k's bearings shifted by (k mod ``phases``) * ``step_rad`` and its ranges resampled
    there: the interleaved start bearings of a scanner that alternates its first beam (a ROBOTLASER log
    with four start angles 0.25 deg apart), built from a log that has one geometry. A range is interpolated
    between the two beams around its new bearing when both hit one surface (within 0.1 m + 5 %), else it
    is the nearer beam's; past the last beam it is invalid (nan)."""
    out = []
    for k, tick in enumerate(ticks):
        s = tick.scan
        a, r = s.angles_rad, s.ranges_m
        q = a + step_rad * (k % phases)
        j = np.clip(np.searchsorted(a, q), 1, max(a.shape[0] - 1, 1))
        r0, r1 = r[j - 1], r[j]
        f = (q - a[j - 1]) / (a[j] - a[j - 1])
        with np.errstate(invalid="ignore"):
            same = np.isfinite(r0) & np.isfinite(r1) & (np.abs(r1 - r0) < 0.1 + 0.05 * np.minimum(r0, r1))
            ranges = np.where(same, r0 + f * (r1 - r0), np.where(f < 0.5, r0, r1))
        ranges[q > a[-1]] = np.nan
        scan = dataclasses.replace(s, ranges_m=ranges, angles_rad=q)
        out.append(dataclasses.replace(tick, scan=scan))
    return out


@dataclass(frozen=True)
class MatcherReport:
    """One row of the ``scanmatch`` table.

    Attributes:
        method: matcher name.
        scans: scans processed.
        failures: failed matches (odometry increment kept).
        ms_median, ms_p99: time per scan [ms] (the first scan, which only initialises, is excluded).
        relations: relation errors, when relations were given.
        tum_path: the trajectory written, when an output folder was given.
        truth: the errors against the log's ground truth (SE(2)-aligned ATE, RPE over 1 s), when it has one.
        health: the matcher's health (``evaluation.matcher_health``: failures, disagreement with the
            odometry, the warning).
    """

    method: str
    scans: int
    failures: int
    ms_median: float
    ms_p99: float
    relations: RelationStats | None = None
    tum_path: str | None = None
    truth: TrajectoryErrors | None = None
    health: MatcherHealth | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "scans": self.scans, "failures": self.failures,
                "ms_median": self.ms_median, "ms_p99": self.ms_p99,
                "relations": None if self.relations is None else self.relations.to_dict(),
                "tum_path": self.tum_path,
                "truth": None if self.truth is None else self.truth.to_dict(),
                "health": None if self.health is None else self.health.to_dict()}


def matcher_report(traj: CorrectedTrajectory, relations: Relations | None = None, *, tol_s: float = 1e-4,
                   tum_path: str | None = None, health: HealthParams | None = None) -> MatcherReport:
    """Summarise a corrected trajectory: timings, failures, relation errors, errors against the log's ground
    truth (aligned) and the matcher's health (``health``: its limits, default ``health_params()``)."""
    ms = traj.ms[1:] if traj.ms.size > 1 else traj.ms
    med = float(np.median(ms)) if ms.size else math.nan
    p99 = float(np.percentile(ms, 99)) if ms.size else math.nan
    stats = None if relations is None else relation_errors(traj.t_ns, traj.poses, relations, tol_s=tol_s)
    truth = (traj.truth_t_ns, traj.truth) if traj.truth_t_ns.size else None
    errors = None if truth is None else trajectory_errors(traj.t_ns, traj.poses, *truth)
    state = matcher_health(traj.t_ns, traj.odom, traj.poses, traj.ok, traj.reason, matcher=traj.method,
                           truth=truth, params=health if health is not None else health_params())
    return MatcherReport(traj.method, int(traj.t_ns.size), traj.failures, med, p99, stats, tum_path, errors,
                         state)


def _span(t_ns: NDArray[np.int64]) -> str:
    lo, hi = int(t_ns.min()), int(t_ns.max())
    return f"{fmt_ns(lo)} to {fmt_ns(hi)} s ({(hi - lo) / 1e9:.1f} s)"


def relations_time_base(t_ns: NDArray[np.int64], relations: Relations, matched: int, *, tol_s: float,
                        name: str = "relations") -> str | None:
    """One line when under :data:`FEW_MATCHED` of ``relations`` (``matched`` of them) match the scan stamps
    ``t_ns``: the log's and the relations' time ranges side by side, and the log's clock when it looks
    synthetic (:func:`gndreplay.io.clock.scan_clock`): relations are stamped on the recording's clock.
    None when enough match or there are no relations or scans."""
    if len(relations) == 0 or t_ns.size == 0 or matched >= FEW_MATCHED * len(relations):
        return None
    ends = np.concatenate([relations.t1_ns, relations.t2_ns])
    period, clock = scan_clock(t_ns)
    synthetic = (f"; the log's clock looks synthetic (all {t_ns.size} scans exactly {period:g} s apart from "
                 "a round start: generated, not recorded; relations stamped on a recorded clock cannot match)"
                 if clock else "; the log's clock looks recorded (not synthetic)")
    head = (f"none of its {len(relations)} relations matches" if matched == 0
            else f"only {matched} of its {len(relations)} relations match")
    return (f"{name}: {head} two scan stamps of the log within {tol_s:g} s: the log's scans span "
            f"{_span(t_ns)}, the relations {_span(ends)}{synthetic}")


def log_ticks(log: Path, read: ReadOptions = DEFAULT_READ, *,
              on_open: Callable[[LogReader], None] | None = None,
              on_tick: Callable[[Tick], None] | None = None) -> Callable[[], Iterator[Tick]]:
    """A factory of fresh tick streams of ``log`` (``run_scanmatch``'s ``ticks_factory``): each call opens
    the log for one matcher's pass (an unreadable log or a bad topic fails on the first). ``on_open`` hears
    each opened reader and ``on_tick`` each tick as it is handed out (progress displays)."""

    def ticks() -> Iterator[Tick]:
        with open_log(log, options=read) as reader:
            if on_open is not None:
                on_open(reader)
            for tick in reader.ticks():
                if on_tick is not None:
                    on_tick(tick)
                yield tick

    return ticks


def run_scanmatch(ticks_factory: Callable[[], Iterable[Tick]], methods: Sequence[Method] = METHODS, *,
                  relations: Relations | None = None, out_dir: str | os.PathLike[str] | None = None,
                  idc: IdcParams | None = None, kiss: KissParams | None = None,
                  tol_s: float = 1e-4, relations_name: str = "relations", overwrite: bool = False,
                  inputs: Sequence[str | os.PathLike[str]] = (),
                  on_pass: Callable[[str], None] | None = None,
                  on_warning: Callable[[str], None] | None = None,
                  parallel: bool = False) -> list[MatcherReport]:
    """The ``gndreplay scanmatch`` command as a function: each matcher over the same log, one report each
    (``matcher_report``: timings, failures, relation errors, errors against the log's ground truth and the
    matcher's health with the odometry error model of ``idc``). With ``parallel`` (and more than one
    method, where ``MatchAhead`` is available) the matchers run side by side in one pass over the log
    (``correct_trajectories``): the same trajectories, each matcher on its own core.

    Args:
        ticks_factory: returns a fresh tick stream of the log (called once per matcher).
        methods: matchers to run, in table order.
        relations: reference relations for the error columns.
        out_dir: when given, one TUM trajectory per matcher is written there as ``<method>.tum``. It is
            checked before any work (``fsutil.check_output_dir``: never a file, the current folder, a folder
            holding an input or files gndreplay did not write); an earlier output there is replaced only
            with ``overwrite``, otherwise the run goes beside it (``out_dir-2``, ...; the rows' ``tum_path``
            say where). The files are written into a staging folder published only when all are complete.
        idc, kiss: matcher parameters.
        tol_s: stamp tolerance for relations [s].
        relations_name: how error messages name the relations (their file).
        overwrite: replace an earlier gndreplay output at ``out_dir``.
        inputs: the input files (log, relations), which ``out_dir`` must not contain.
        on_pass: hears each matcher's name before its pass over the log (progress displays); in parallel,
            once, the names joined by " + ".
        on_warning: hears, once, :func:`relations_time_base`'s line when few relations match.

    Raises:
        ScanMatchError: unknown method, or relations given of which none matches a scan of the log (a table
            of NaN would hide a wrong relations file or a wrong ``tol_s``); the message sets the log's and
            the relations' time ranges side by side (:func:`relations_time_base`).
        OutputError: ``out_dir`` is unsafe to write.
    """
    out = None if out_dir is None else Path(out_dir)
    target = None
    if out is not None:
        check_output_dir(out, inputs=[Path(p) for p in inputs if Path(p).exists()], overwrite=overwrite)
        target = resolve_output_dir(out, overwrite=overwrite)
    rows: list[MatcherReport] = []
    trajs: list[CorrectedTrajectory] = []
    together: list[CorrectedTrajectory] = []
    if parallel and len(methods) > 1 and available():
        for method in methods:
            make_matcher(method, idc=idc, kiss=kiss)  # an unknown method fails here, before the pass
        if on_pass is not None:
            on_pass(" + ".join(methods))
        together = correct_trajectories(ticks_factory(), methods, idc=idc, kiss=kiss)
    for k, method in enumerate(methods):
        if together:
            traj = together[k]
        else:
            if on_pass is not None:
                on_pass(method)
            traj = correct_trajectory(ticks_factory(), make_matcher(method, idc=idc, kiss=kiss))
        row = matcher_report(traj, relations, tol_s=tol_s, health=health_params(idc))
        if relations is not None and row.relations is not None and not rows:
            note = relations_time_base(traj.t_ns, relations, row.relations.matched, tol_s=tol_s,
                                       name=relations_name)
            if row.relations.matched == 0:
                raise ScanMatchError(note or f"{relations_name}: no relation matches (the log has no scans)")
            if note is not None and on_warning is not None:
                on_warning(note)
        rows.append(row)
        trajs.append(traj)
    if out is None or target is None:
        return rows
    stage = staging_dir(target, overwrite=overwrite, base=out)
    with stage as tmp:
        for method, traj in zip(methods, trajs, strict=True):
            write_tum(tmp / f"{method}.tum", traj.t_ns, traj.poses)
    return [dataclasses.replace(row, tum_path=str(stage.out / f"{method}.tum"))
            for method, row in zip(methods, rows, strict=True)]
