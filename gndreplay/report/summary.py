"""summary.json: what a run did, aggregated from its ticks (:class:`SummaryRecorder` collects a few numbers
per tick as the replay streams, :func:`summarise` builds the summary at the end; ``rundir.write_summary``
writes it, ``rundir.read_summary`` reads it back).

The assisted-navigation audit (the multi-loop paper's takeovers) is part of it: :func:`interventions`
aggregates commands.csv's desired and active navigation modes and takeover reasons into ticks per active
mode, the takeovers and the reflexive overrides, each with its start, duration and reason. Everything but
``latency_ms`` and ``over_budget`` (the wall clock) is a pure function of the ticks.

With ground truth in the log, ``truth`` (:func:`truth_section`) scores the odometry and the corrected
trajectory against it: ATE and RPE per second in SE(2), after the SE(2) Umeyama alignment ("aligned") and
from the first pose ("unaligned"), see ``gndreplay.evaluation.trajectory_errors``. ``matcher_health``
(:func:`health_section`) says how the scan matcher did over every scan: failures by reason, its disagreement
with the odometry, the longest stretch without an accepted match, and a warning when it likely hurt
(``gndreplay.evaluation.matcher_health``: measured against the truth when there is one).
"""

from __future__ import annotations

import math
from array import array
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from .. import __version__
from .. import detmath as dm
from ..config import Config, config_to_dict
from ..evaluation import matcher_health, trajectory_errors
from ..geometry import relative, wrap_angle
from ..pipeline.stack import MODULES, TickResult
from ..scanmatch import health_params
from ..types import BUDGET_FLAGS, REFLEXIVE_MODES, Flag, Subgoal
from .rundir import (
    CORRECTED_TRAJECTORY_FILE,
    ODOM_TRAJECTORY_FILE,
    TRUTH_TRAJECTORY_FILE,
    csv_text,
    episodes,
    recorded_flags,
    tick_edges,
)

__all__ = [
    "COMMAND_GAP_WARN_SHARE",
    "NO_COMMAND_REASONS",
    "STALE_COMMAND_REASONS",
    "SummaryOptions",
    "SummaryRecorder",
    "command_gap_warning",
    "health_section",
    "interventions",
    "matcher_warning",
    "motion_agreement",
    "summarise",
    "truth_section",
]

#: summary.json's truth section: trajectory name -> its TUM file in the run directory
TRUTH_SCORED = (("odom", ODOM_TRAJECTORY_FILE), ("corrected", CORRECTED_TRAJECTORY_FILE))
#: summary.json's names of the two alignments (``evaluation.ALIGNMENTS``)
TRUTH_ALIGNMENTS = (("aligned", "se2"), ("unaligned", "origin"))


class SummaryOptions(Protocol):
    """The replay options summary.json records (``gndreplay.replay.RunOptions`` is one)."""

    @property
    def goal_xy(self) -> tuple[float, float] | None: ...

    @property
    def goal_ahead_m(self) -> float: ...

    @property
    def until_s(self) -> float | None: ...

    @property
    def every(self) -> int: ...

    @property
    def subgoals(self) -> tuple[Subgoal, ...]: ...


class SummaryRecorder:
    """Accumulates the per-tick numbers the summary needs as the replay streams, packed: about 150 bytes
    per tick (numbers in ``array.array``, each text once, ticks holding references to it), so a run of
    many hours still holds only a few tens of MB."""

    def __init__(self, *, enforce_budgets: bool = False) -> None:
        self.enforce_budgets = enforce_budgets
        self.t_s = array("d")
        self.pose = array("d")  # x, y, theta per tick
        self.cmd = array("d")  # v, w, direction per tick
        self.timing = array("d")  # len(MODULES) per tick
        self.modes: Counter[str] = Counter()
        self.situations: Counter[str] = Counter()
        self.flags: Counter[str] = Counter()
        self.over_budget: Counter[str] = Counter()
        self.planner = array("d")  # nodes expanded (cells for NF1), path length [m] per tick
        self.t_ns = array("q")
        self.audit: tuple[list[str], list[str], list[str], list[str]] = ([], [], [], [])
        """desired, active, takeover reason, GND mode / rule: one column per field, one entry per tick."""
        self.match_ok = array("b")  # per scan (also those the stack skips): match accepted
        self.match_reason: list[str] = []  # why it failed ("" when accepted)
        self._texts: dict[str, str] = {}

    def _text(self, s: str) -> str:
        """``s`` as the one string object of its value (a tick holds a reference, not a copy)."""
        return self._texts.setdefault(s, s)

    def add_match(self, ok: bool, reason: str) -> None:
        """A scan the matcher corrected: every scan of the run, in time order (``--every`` runs the stack on
        fewer), one per pose of the trajectories."""
        self.match_ok.append(bool(ok))
        self.match_reason.append("" if ok else self._text(reason))

    def add(self, r: TickResult) -> None:
        """A tick the stack ran on."""
        self.t_s.append(r.t_ns / 1e9)
        self.t_ns.append(r.t_ns)
        for col, text in zip(self.audit, (r.desired_mode, r.active_mode, csv_text(r.takeover_reason),
                                          r.mode.value), strict=True):
            col.append(self._text(text))
        p = r.pose_corrected
        self.pose.extend((p.x, p.y, p.theta))
        self.cmd.extend((r.command.v_mps, r.command.w_radps, r.direction_rad))
        self.timing.extend(r.timings_ms.get(m, 0.0) for m in MODULES)
        self.modes[r.mode.value] += 1
        self.situations[r.situation.name] += 1
        for name in recorded_flags(r.flags, enforce_budgets=self.enforce_budgets).names():
            self.flags[name] += 1
        for name in (r.flags & BUDGET_FLAGS).names():
            self.over_budget[name] += 1
        self.planner.extend((float(r.planner_nodes), r.planner_length_m))


def motion_agreement(
    t_s: NDArray[np.float64],
    poses: NDArray[np.float64],
    cmd: NDArray[np.float64],
    *,
    horizon_s: float = 1.0,
    min_motion_m: float = 0.05,
) -> dict[str, float]:
    """Agreement between the commands and the motion the robot actually made in the log.

    For tick i the actual motion is the corrected pose horizon_s later expressed in the robot frame at
    i: its bearing (where the robot went), its distance / horizon (speed) and its heading change /
    horizon (turn rate). Heading agreement compares the ND+ direction with that bearing on ticks where
    the robot moved at least min_motion_m; speed and turn-rate agreement compare v and w.
    """
    n = t_s.shape[0]
    if n < 2:
        return {"ticks_compared": 0}
    j = np.searchsorted(t_s, t_s + horizon_s)
    ok = j < n
    i = np.nonzero(ok)[0]
    j = j[ok]
    if i.size == 0:  # the run is shorter than the horizon
        return {"horizon_s": horizon_s, "ticks_compared": 0}
    dt = t_s[j] - t_s[i]
    rel = relative(poses[i], poses[j])
    dist = np.hypot(rel[:, 0], rel[:, 1])
    v_act = dist * np.sign(rel[:, 0]) / dt
    w_act = rel[:, 2] / dt
    bearing = dm.atan2_a(rel[:, 1], rel[:, 0])
    moved = (dist >= min_motion_m) & np.isfinite(cmd[i, 2]) & (cmd[i, 0] > 0)
    err = np.abs(np.asarray(wrap_angle(cmd[i, 2] - bearing)))[moved]
    out: dict[str, float] = {
        "horizon_s": horizon_s,
        "ticks_compared": int(i.size),
        "heading_ticks": int(err.size),
        "heading_err_median_deg": float(np.degrees(np.median(err))) if err.size else float("nan"),
        "heading_within_30deg": float(np.mean(err <= math.radians(30))) if err.size else float("nan"),
        "speed_mae_mps": float(np.mean(np.abs(cmd[i, 0] - v_act))),
        "turn_rate_mae_radps": float(np.mean(np.abs(cmd[i, 1] - w_act))),
        "turn_sign_agreement": float(
            np.mean(np.sign(cmd[i, 1]) == np.sign(w_act))
        ),
    }
    return out


def _latency(values: NDArray[np.float64]) -> dict[str, float]:
    if values.size == 0:
        return {}
    q = np.percentile(values, [50, 90, 99])
    return {"median": float(q[0]), "p90": float(q[1]), "p99": float(q[2]), "max": float(values.max())}


def _planner_stats(rec: SummaryRecorder, cfg: Config) -> dict[str, Any]:
    """Which planner ran and its work per tick: nodes expanded (NF1: cells the wave labelled; tunnel: nodes
    expanded) and the length of the path or tunnel chain it returned, over the ticks where it found one."""
    stats = np.array(rec.planner, dtype=np.float64).reshape(-1, 2)
    out: dict[str, Any] = {"kind": cfg.planner.kind}
    for k, name in enumerate(("nodes", "path_m")):
        col = stats[np.isfinite(stats[:, k]), k]
        if col.size:
            q = np.percentile(col, [50, 99])
            out[name] = {"median": float(q[0]), "p99": float(q[1]), "max": float(col.max())}
    return out


def _span(edges: NDArray[np.float64], first: int, end: int) -> dict[str, Any]:
    """An episode's start [s since the first tick], duration (``tick_edges``: until the tick after it, or
    one tick period past the last tick at the end of the run) and ticks; times are rounded to the
    nanosecond, the stamps' resolution, so 0.2 s does not print as 0.1999999999999993."""
    return {"t_start_s": round(float(edges[first]), 9),
            "duration_s": round(float(edges[end] - edges[first]), 9), "ticks": end - first}


#: Takeover reasons the stack records on a teleop tick whose desired module stands still for want of a
#: usable command (``pipeline.stack``'s teleop command check): ``no_command_ticks`` / ``stale_command_ticks``.
NO_COMMAND_REASONS = ("teleop: no command", "teleop: command not finite")
STALE_COMMAND_REASONS = ("teleop: command stale",)


def interventions(
    t_ns: Sequence[int], desired: Sequence[str], active: Sequence[str], reasons: Sequence[str],
    modes: Sequence[str],
) -> dict[str, Any]:
    """The assisted-navigation audit of a run (summary.json's ``interventions``), from its ticks.

    Ticks per desired and per active navigation mode; the takeovers: consecutive ticks whose active mode is
    not the desired one are one takeover (its reason and active mode: those of its first tick); the
    reflexive overrides (``modes`` in ``REFLEXIVE_MODES``: emergency stops, safe replacements, stale data,
    trap escapes): consecutive ticks of the same rule are one. Each episode has ``t_start_s`` (since the
    first tick), ``duration_s`` (``tick_edges``: until the tick after it; at the end of the run, one median
    tick period past its last tick) and
    ``ticks``. ``no_command_ticks`` / ``stale_command_ticks``: ticks whose teleop command was missing or not
    finite / older than the timeout (the robot stood still for want of a driver's command, with active ==
    desired: not takeovers, but a replay where they are many did not test the driver's commands). Pure:
    behaviour only, no wall clock.
    """
    edges = tick_edges((np.asarray(t_ns, dtype=np.int64) - (t_ns[0] if len(t_ns) else 0)) / 1e9)
    taken = ["takeover" if a != d else "" for d, a in zip(desired, active, strict=True)]
    rules = [m if m in REFLEXIVE_MODES else "" for m in modes]
    takeovers = [{**_span(edges, i, j), "desired": desired[i], "active": active[i], "reason": reasons[i]}
                 for i, j in episodes(taken)]
    emergencies = [{**_span(edges, i, j), "rule": rules[i]} for i, j in episodes(rules)]
    return {
        "desired": dict(sorted(Counter(desired).items())),
        "active": dict(sorted(Counter(active).items())),
        "takeover_ticks": sum(1 for x in taken if x),
        "takeovers": takeovers,
        "reflexive_ticks": sum(1 for x in rules if x),
        "emergencies": emergencies,
        "no_command_ticks": sum(1 for r in reasons if r in NO_COMMAND_REASONS),
        "stale_command_ticks": sum(1 for r in reasons if r in STALE_COMMAND_REASONS),
    }


#: Share of ticks without a usable teleop command above which ``command_gap_warning`` speaks.
COMMAND_GAP_WARN_SHARE = 0.2


def command_gap_warning(summary: dict[str, Any]) -> str | None:
    """One line when more than ``COMMAND_GAP_WARN_SHARE`` of a run's ticks had no usable teleop command
    (missing, not finite or stale: the robot stood still, so the audit says little about the driver's
    commands), else None. ``summary``: summary.json's content."""
    iv, n = summary.get("interventions") or {}, int(summary.get("ticks", 0) or 0)
    missing, stale = int(iv.get("no_command_ticks", 0) or 0), int(iv.get("stale_command_ticks", 0) or 0)
    if n == 0 or missing + stale <= COMMAND_GAP_WARN_SHARE * n:
        return None
    return (f"{missing + stale} of {n} ticks ({100.0 * (missing + stale) / n:.0f} %) had no usable teleop "
            f"command ({missing} none or not finite, {stale} stale): the robot stood still on them")


def truth_section(
    trajectories: Mapping[str, tuple[NDArray[np.int64], NDArray[np.float64]]],
) -> dict[str, Any] | None:
    """summary.json's ``truth``: ATE / RPE of the odometry and the corrected trajectory against the truth,
    aligned and unaligned; None without truth. ``trajectories``: TUM file name -> (stamps [ns], (N, 3) poses)
    (``rundir.TrajectoryWriter.arrays``)."""
    truth = trajectories.get(TRUTH_TRAJECTORY_FILE)
    if truth is None or truth[0].size == 0:
        return None
    out: dict[str, Any] = {"poses": int(truth[0].size)}
    for name, file in TRUTH_SCORED:
        t, poses = trajectories[file]
        out[name] = {label: trajectory_errors(t, poses, *truth, alignment=how).to_dict()
                     for label, how in TRUTH_ALIGNMENTS}
    return out


def health_section(
    trajectories: Mapping[str, tuple[NDArray[np.int64], NDArray[np.float64]]], rec: SummaryRecorder,
    cfg: Config,
) -> dict[str, Any] | None:
    """summary.json's ``matcher_health``: ``evaluation.matcher_health`` of the configured matcher over every
    scan (the corrected trajectory against the odometry, the matches ``rec`` recorded, the truth when there
    is one), with the odometry error model of ``[scanmatch.idc]``; None when ``rec`` did not record one
    match per pose."""
    t, odom = trajectories[ODOM_TRAJECTORY_FILE]
    _, corrected = trajectories[CORRECTED_TRAJECTORY_FILE]
    if len(rec.match_ok) != t.size:
        return None
    truth = trajectories.get(TRUTH_TRAJECTORY_FILE)
    return matcher_health(t, odom, corrected, rec.match_ok, rec.match_reason, matcher=cfg.scanmatch.method,
                          truth=truth if truth is not None and truth[0].size else None,
                          params=health_params(cfg.scanmatch.idc)).to_dict()


def matcher_warning(summary: Mapping[str, Any]) -> str | None:
    """summary.json's ``matcher_health.warning`` (the one line saying the scan matcher likely hurt), or
    None."""
    health = summary.get("matcher_health")
    warning = health.get("warning") if isinstance(health, Mapping) else None
    return warning if isinstance(warning, str) and warning else None


def summarise(
    rec: SummaryRecorder, cfg: Config, log: Path, options: SummaryOptions, read_report: Any,
    trajectories: Mapping[str, tuple[NDArray[np.int64], NDArray[np.float64]]] | None = None,
    source: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """summary.json: counts, histograms, agreement, the errors against ground truth (``trajectories``, see
    :func:`truth_section`), the matcher's health (:func:`health_section`), how to read the input again
    (``source``, as the replay's caller gives it: ``gndreplay.rerun`` reads it) and (last, the only
    non-deterministic part) latency and the ticks over each module's time budget. ``flags`` counts what
    commands.csv records."""
    n = len(rec.t_s)
    timing = np.array(rec.timing, dtype=np.float64).reshape(n, len(MODULES))
    latency = {m: _latency(timing[:, k]) for k, m in enumerate(MODULES)}
    latency["stack"] = _latency(timing[:, 1:].sum(axis=1))  # model + planner + reactor + supervisor
    latency["total"] = _latency(timing.sum(axis=1))
    t = np.array(rec.t_s)
    agreement = motion_agreement(t, np.array(rec.pose).reshape(n, 3), np.array(rec.cmd).reshape(n, 3))
    desired, active, reasons, modes = rec.audit
    return {
        "gndreplay_version": __version__,
        "log": str(log),
        "ticks": n,
        "duration_s": float(t[-1] - t[0]) if n else 0.0,
        "modes": dict(sorted(rec.modes.items())),
        "situations": dict(sorted(rec.situations.items())),
        "flags": {
            name: rec.flags.get(name, 0)
            for name in (f.name for f in Flag if f.value and f.name)
            if rec.enforce_budgets or not Flag[name] & BUDGET_FLAGS
        },
        "interventions": interventions(rec.t_ns, desired, active, reasons, modes),
        "agreement": agreement,
        "truth": truth_section(trajectories) if trajectories is not None else None,
        "matcher_health": health_section(trajectories, rec, cfg) if trajectories is not None else None,
        "read_report": read_report,
        "options": {
            "goal": list(options.goal_xy) if options.goal_xy else None,
            "goal_ahead_m": options.goal_ahead_m,
            "until_s": options.until_s,
            "every": options.every,
            "subgoals": [[g.x, g.y, g.theta, g.kind] for g in options.subgoals],
        },
        "source": dict(source) if source is not None else None,
        "config": config_to_dict(cfg),
        "planner": _planner_stats(rec, cfg),
        "latency_ms": latency,
        "over_budget": {name: rec.over_budget.get(name, 0) for name in BUDGET_FLAGS.names()},
    }
