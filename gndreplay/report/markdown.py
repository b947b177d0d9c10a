"""report.md: the run's summary as Markdown tables, with the figures linked."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry import compose, inverse
from .figures import FIGURES, budgets_ms, scan_period_s
from .rundir import RunData
from .snapshots import SNAPSHOTS_DIR, SnapshotEntry, read_snapshot_index

__all__ = ["health_rows", "interventions_section", "render_report", "timeline_section", "trajectory_gap",
           "truth_section"]

_LATENCY_ROWS = ("match", "model", "planner", "reactor", "supervisor", "stack", "total")
_OVER = {"match": "MATCH_OVER_BUDGET", "model": "MODEL_OVER_BUDGET", "planner": "PLANNER_OVER_BUDGET",
         "reactor": "REACTOR_OVER_BUDGET"}


def _num(x: Any, fmt: str = ".2f") -> str:
    if isinstance(x, bool) or x is None:
        return "-" if x is None else str(x)
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return "nan" if math.isnan(x) else format(x, fmt)
    return str(x)


def _table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return [*out, ""]


def _histogram(title: str, column: str, counts: Mapping[str, int], total: int) -> list[str]:
    if not counts:
        return [f"## {title}", "", "none", ""]
    rows = [(k, str(v), f"{100.0 * v / total:.1f} %" if total else "-")
            for k, v in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))]
    return [f"## {title}", "", *_table((column, "ticks", "share"), rows)]


#: Rows of each intervention table at most (summary.json lists them all).
MAX_EPISODE_ROWS = 50


def _episode_rows(episodes: Sequence[Mapping[str, Any]], *cols: str) -> list[tuple[str, ...]]:
    return [(_num(e.get("t_start_s"), ".2f"), _num(e.get("duration_s"), ".2f"), _num(e.get("ticks")),
             *(str(e.get(c, "")) or "-" for c in cols)) for e in episodes[:MAX_EPISODE_ROWS]]


def _more(episodes: Sequence[Any]) -> list[str]:
    extra = len(episodes) - MAX_EPISODE_ROWS
    return [f"... and {extra} more (summary.json lists them all).", ""] if extra > 0 else []


def interventions_section(iv: Mapping[str, Any] | None, n: int) -> list[str]:
    """report.md's "Interventions": ticks per active navigation mode, the takeovers and the reflexive
    overrides (from summary.json's ``interventions``), or a sentence saying there were none."""
    out = ["## Interventions", ""]
    if not iv:
        return [*out, "Not recorded (a run written before the assisted-navigation audit).", ""]
    desired = ", ".join(sorted(iv.get("desired", {}) or {})) or "-"
    out += [f"Desired navigation mode: {desired}. Ticks per active mode:", ""]
    active: Mapping[str, int] = iv.get("active", {}) or {}
    out += _table(("active mode", "ticks", "share"),
                  [(k, str(v), f"{100.0 * v / n:.1f} %" if n else "-")
                   for k, v in sorted(active.items(), key=lambda kv: (-kv[1], kv[0]))])
    missing, stale = int(iv.get("no_command_ticks", 0) or 0), int(iv.get("stale_command_ticks", 0) or 0)
    if missing or stale:
        pct = [f" ({100.0 * k / n:.1f} %)" if n else "" for k in (missing, stale)]
        out += [f"Ticks without a usable teleop command (the robot stood still): {missing}{pct[0]} with none "
                f"or a non-finite one, {stale}{pct[1]} with a stale one.", ""]
    takeovers: Sequence[Mapping[str, Any]] = iv.get("takeovers", []) or []
    out += ["### Takeovers", ""]
    if takeovers:
        out += _table(("start [s]", "duration [s]", "ticks", "desired", "taken over by", "reason"),
                      _episode_rows(takeovers, "desired", "active", "reason")) + _more(takeovers)
    else:
        out += ["No takeover: the desired mode was active on every tick.", ""]
    emergencies: Sequence[Mapping[str, Any]] = iv.get("emergencies", []) or []
    out += ["### Emergencies and reflexive overrides", ""]
    if emergencies:
        out += _table(("start [s]", "duration [s]", "ticks", "rule"), _episode_rows(emergencies, "rule"))
        out += _more(emergencies)
    else:
        out += ["No emergency stop and no reflexive override.", ""]
    out += ["Times are seconds since the first tick; an episode lasts until the tick after it (one tick "
            "period past its last tick when it runs to the end).", ""]
    return out


def truth_section(truth: Mapping[str, Any] | None) -> list[str]:
    """The errors of the odometry and the corrected trajectory against ground truth (summary.json's
    ``truth``), aligned (SE(2) Umeyama) and unaligned (from the first pose); nothing without truth."""
    if not isinstance(truth, Mapping):
        return []
    rows = []
    for name in ("odom", "corrected"):
        for how, e in (truth.get(name) or {}).items():
            if isinstance(e, Mapping):
                rows.append((name, how, _num(e.get("matched")),
                             *(_num(e.get(k), ".3f") for k in ("ate_rmse_m", "ate_mean_m", "ate_median_m",
                                                               "ate_max_m", "rpe_trans_rmse_m")),
                             _num(e.get("rpe_rot_rmse_deg"), ".3f"), _num(e.get("rpe_pairs"))))
    return ["## Ground truth", "",
            *_table(("trajectory", "alignment", "poses", "ATE RMSE [m]", "mean", "median", "max",
                     "RPE 1 s RMSE [m]", "RPE 1 s RMSE [deg]", "RPE pairs"), rows),
            "ATE: translational error of each pose after aligning the trajectory to the truth (aligned: "
            "SE(2) least squares; unaligned: first poses put together). RPE: error of the motion over 1 s.",
            ""]


def _trio(q: Mapping[str, Any], key: str, unit: str, fmt: str) -> str:
    return " / ".join(_num(q.get(key.format(k)), fmt) for k in ("median", "p95", "max")) + f" {unit}"


def health_rows(health: Mapping[str, Any] | None) -> list[tuple[str, str]]:
    """report.md's rows of the scan matcher's health (summary.json's ``matcher_health``); none without it."""
    if not isinstance(health, Mapping):
        return []
    n = int(health.get("scans", 0) or 0)
    failed = int(health.get("failed", 0) or 0)
    reasons: Mapping[str, int] = health.get("reasons", {}) or {}
    why = ": " + ", ".join(f"{k} {v}" for k, v in reasons.items()) if reasons else ""
    share = f" ({100.0 * failed / n:.1f} %)" if n else ""
    rows = [("failed matches, every scan", f"{failed} of {n} scans{share}{why}"),
            ("of which refused (a match found, inconsistent with the odometry or its prior)",
             str(health.get("refused", 0)))]
    if health.get("after_gap"):
        rows.append(("of which after a gap in the log (map restarted)", str(health["after_gap"])))
    longest = health.get("longest_without_match", {}) or {}
    if longest.get("scans"):
        rows.append(("longest stretch without an accepted match",
                     f"{_num(longest.get('duration_s'))} s ({longest['scans']} scans) from t = "
                     f"{_num(longest.get('t_start_s'), '.1f')} s"))
    else:
        rows.append(("longest stretch without an accepted match", "none (every match accepted)"))
    step = health.get("step_vs_odometry", {}) or {}
    rows += [("per scan vs odometry, translation median / p95 / max", _trio(step, "trans_{}_m", "m", ".3f")),
             ("per scan vs odometry, rotation median / p95 / max", _trio(step, "rot_{}_deg", "deg", ".2f"))]
    w = health.get("worst_window", {}) or {}
    if isinstance(w.get("sigmas"), int | float) and not math.isnan(w["sigmas"]):
        rows.append((f"worst {_num(w.get('window_s'), 'g')} s window vs odometry",
                     f"{_num(w.get('trans_m'), '.3f')} m, {_num(w.get('rot_deg'), '.1f')} deg from t = "
                     f"{_num(w.get('t_start_s'), '.1f')} s: {_num(w['sigmas'])} sigmas of the odometry error "
                     f"model ({_num(w.get('sigma_m'), '.3f')} m, {_num(w.get('sigma_deg'), '.1f')} deg)"))
    if health.get("verdict") == "measured":
        verdict = (f"measured: aligned ATE RMSE {_num(health.get('ate_matcher_m'), '.3f')} m, the odometry's "
                   f"{_num(health.get('ate_odom_m'), '.3f')} m")
    else:
        verdict = "estimated from the failures and the disagreement with the odometry (no ground truth)"
    rows += [("verdict", verdict), ("warning", str(health.get("warning") or "none"))]
    return rows


def timeline_section(entries: Sequence[SnapshotEntry] | None) -> list[str]:
    """report.md's "Timeline": the key events that got a snapshot (snapshots/index.csv), each linked to its
    picture; nothing when the run has no snapshots/."""
    if entries is None:
        return []
    out = ["## Timeline", ""]
    if not entries:
        return [*out, "No key event (mode change, reflexive rule, trap, planner failure, takeover, goal) "
                "got a snapshot.", ""]
    rows = [(f"{e.elapsed_s:.2f}", e.kind, e.reason.replace("|", " \\| "),
             f"[{e.file}]({SNAPSHOTS_DIR}/{e.file})") for e in entries]
    out += _table(("t [s]", "event", "reason", "snapshot"), rows)
    out += ["Each snapshot is the decision at that tick: the robot-centred grid with the scan, the planned "
            "path and goal, ND+'s chosen region, gaps and security zone, the motion direction, the footprint "
            "and the area the command sweeps over the braking horizon. Events are rate-limited per kind and "
            "capped per run; times are seconds since the first scan.", ""]
    return out


def trajectory_gap(odom: NDArray[np.float64], corrected: NDArray[np.float64]) -> dict[str, float]:
    """How far the correction moved the trajectory: path lengths of both (M, 4) t, x, y, yaw trajectories,
    and the distance between them (both anchored at the first pose) at the end and at its largest."""
    if odom.shape[0] == 0 or odom.shape != corrected.shape:
        return {}

    def length(a: NDArray[np.float64]) -> float:
        return float(np.hypot(*np.diff(a[:, 1:3], axis=0).T).sum()) if a.shape[0] > 1 else 0.0

    # express the corrected trajectory in the odometry frame, anchored at the first pose
    anchor = compose(odom[0, 1:4], inverse(corrected[0, 1:4]))
    cor = compose(anchor, corrected[:, 1:4])
    gap = np.hypot(odom[:, 1] - cor[:, 0], odom[:, 2] - cor[:, 1])
    return {"path_odom_m": length(odom), "path_corrected_m": length(corrected), "final_gap_m": float(gap[-1]),
            "max_gap_m": float(gap.max())}


def render_report(data: RunData, figures: Iterable[str] = tuple(FIGURES), *, name: str | None = None) -> str:
    """The Markdown text of report.md (deterministic given the run's files); links the named figures.
    ``name`` titles it (default: the run directory's name)."""
    s = data.summary
    n = int(s.get("ticks", len(data.commands)))
    cfg = s.get("config", {}) or {}
    flags: Mapping[str, int] = s.get("flags", {}) or {}
    over_budget: Mapping[str, int] = s.get("over_budget", {}) or {}
    budgets = budgets_ms(s)
    period = scan_period_s(data.traj_corrected[:, 0])
    opts = s.get("options", {}) or {}
    out = [f"# gndreplay run: {name or data.run_dir.name}", ""]
    health = s.get("matcher_health")
    if isinstance(health, Mapping) and health.get("warning"):
        out += [f"> **Warning:** {health['warning']} (see Scan matching).", ""]
    overview = [
        ("log", f"`{s.get('log', '-')}`"),
        ("gndreplay version", str(s.get("gndreplay_version", "-"))),
        ("ticks (stack runs)", str(n)),
        ("scans", str(data.traj_corrected.shape[0])),
        ("duration", f"{_num(s.get('duration_s'))} s"),
        ("scan period (median)", "-" if period is None else f"{1e3 * period:.1f} ms"),
        ("goal", f"fixed {opts['goal']}" if opts.get("goal") else f"{_num(opts.get('goal_ahead_m'))} m ahead "
                 "along the corrected trajectory"),
        ("stack every N scans", _num(opts.get("every"))),
    ]
    if opts.get("until_s") is not None:
        overview.append(("until", f"{_num(opts['until_s'])} s"))
    out += ["## Run", "", *_table(("", ""), overview)]

    lat: Mapping[str, Mapping[str, float]] = s.get("latency_ms", {}) or {}
    rows = []
    for m in _LATENCY_ROWS:
        q = lat.get(m)
        if not q:
            continue
        b = budgets.get(m)
        over = over_budget.get(_OVER[m], flags.get(_OVER[m], "-")) if m in _OVER else "-"
        rows.append((m, *(_num(q.get(k)) for k in ("median", "p90", "p99", "max")),
                     "-" if b is None else f"{b:g}", str(over)))
    out += ["## Latency per tick [ms]", "",
            *_table(("module", "median", "p90", "p99", "max", "budget", "ticks over budget"), rows)]
    out += ["stack = model + planner + reactor; total = match + stack.", ""]

    out += _histogram("GND modes", "mode", s.get("modes", {}) or {}, n)
    out += _histogram("ND+ situations", "situation", s.get("situations", {}) or {}, n)

    fired = [(k, str(v), f"{100.0 * v / n:.1f} %" if n else "-") for k, v in flags.items() if v]
    silent = [k for k, v in flags.items() if not v]
    out += ["## Flags", ""]
    out += _table(("flag", "ticks", "share"), fired) if fired else ["no flag fired", ""]
    if silent:
        out += [f"Never fired: {', '.join(silent)}.", ""]

    out += interventions_section(s.get("interventions"), n)
    out += timeline_section(read_snapshot_index(data.run_dir))

    agree = s.get("agreement", {}) or {}
    if agree:
        out += ["## Agreement with the logged motion", "",
                *_table(("metric", "value"), [(k, _num(v, ".3f")) for k, v in agree.items()])]

    sm = cfg.get("scanmatch", {}) or {}
    gap = trajectory_gap(data.traj_odom, data.traj_corrected)
    q = lat.get("match", {})
    rows = [("matcher", str(sm.get("method", "-"))),
            ("match failures (MATCH_FAILED)", f"{flags.get('MATCH_FAILED', 0)} of {n} ticks"),
            ("match time median / p99", f"{_num(q.get('median'))} / {_num(q.get('p99'))} ms" if q else "-")]
    names = {"path_odom_m": "path length, raw odometry [m]",
             "path_corrected_m": "path length, corrected [m]",
             "final_gap_m": "corrected vs odometry at the end [m]",
             "max_gap_m": "corrected vs odometry, max [m]"}
    rows += [(names[k], f"{v:.3f}") for k, v in gap.items()]
    rows += health_rows(health)
    out += ["## Scan matching", "", *_table(("", ""), rows)]
    if isinstance(health, Mapping):
        out += ["The matcher's health counts every scan it matched (the stack may run on fewer: `--every`). "
                "Per scan: an accepted match's increment against the odometry's. A window: the corrected "
                "motion over it against the odometry's, in sigmas of the odometry error model (translation "
                "0.1 m + 1/6 of the distance, rotation 3.3 deg + 1/6 of the turn + 2 deg per metre, by "
                "default). The warning is measured against the ground truth when there is one, else "
                "estimated from these numbers.", ""]
    out += truth_section(s.get("truth"))

    rr = s.get("read_report")
    if isinstance(rr, Mapping) and rr:
        scalars = [(str(k), _num(v, ".3f")) for k, v in rr.items() if isinstance(v, str | int | float | bool)]
        if scalars:
            out += ["## Log reading", "", *_table(("", ""), scalars)]

    out += ["## Figures", ""]
    for name in figures:
        caption = FIGURES.get(name, "")
        out += [f"### {name}", "", caption, "", f"![{name}]({name})", ""]
    return "\n".join(out).rstrip("\n") + "\n"
