"""Batch outputs: summary.csv, summary.md and JUnit XML, one row / test case per input (a scenario: per
scenario and seed), plus scenarios.csv and a summary.md table of the per-scenario aggregates over seeds.
"""

from __future__ import annotations

import csv
import io
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from pathlib import Path

from .aggregate import ScenarioAggregate
from .baseline import BaselineCheck, ratio_text
from .sweep import SweepPoint, sweep_rows
from .worker import InputResult

__all__ = [
    "CSV_COLUMNS",
    "JUNIT_SUITES_NAME",
    "SCENARIO_CSV_COLUMNS",
    "is_own_junit",
    "junit_xml",
    "scenarios_csv",
    "summary_csv",
    "summary_md",
    "sweep_csv",
]

#: ``name`` of the root element of the JUnit files gndreplay writes (how an earlier one is recognised).
JUNIT_SUITES_NAME = "gndreplay batch"
_JUNIT_ROOT = f'<testsuites name="{JUNIT_SUITES_NAME}"'

#: Metric columns of summary.csv, after name, status and ticks.
METRIC_COLUMNS: tuple[str, ...] = (
    "match_p99_ms",
    "model_p99_ms",
    "planner_p99_ms",
    "reactor_p99_ms",
    "stack_p99_ms",
    "total_p99_ms",
    "match_failures",
    "planner_no_path",
    "planner_timeouts",
    "no_region",
    "emergency_stops",
    "traps",
    "match_trans_err_mean_m",
    "match_rot_err_mean_deg",
    "relations_matched",
    "ate_m",
    "rpe_m",
    "rpe_deg",
    "success",
    "collisions",
    "goal_missed",
    "timeouts",
    "goal_miss_m",
    "takeovers",
    "local_ticks_pct",
    "time_to_goal_s",
    "clearance_m",
    "path_length_m",
    "optimal_path_m",
    "challenge_metric",
    "security_time_pct",
    "sim_ms_per_step",
    "stack_ms_per_tick",
)
CSV_COLUMNS: tuple[str, ...] = (
    "name",
    "variant",
    "status",
    "ticks",
    "scenario",
    "seed",
    "outcome",
    *METRIC_COLUMNS,
    "wall_s",
    "failures",
    "error",
    "path",
    "run_dir",
)
#: summary.md: (header, metric) for the metric columns shown.
_MD_METRICS: tuple[tuple[str, str], ...] = (
    ("reactor p99 ms", "reactor_p99_ms"),
    ("planner p99 ms", "planner_p99_ms"),
    ("stack p99 ms", "stack_p99_ms"),
    ("match fail", "match_failures"),
    ("no region", "no_region"),
    ("e-stop", "emergency_stops"),
    ("trans err m", "match_trans_err_mean_m"),
    ("ATE m", "ate_m"),
)
#: summary.md, scenario runs: (header, metric) after name, status and seed.
_MD_SCENARIO_METRICS: tuple[tuple[str, str], ...] = (
    ("time s", "time_to_goal_s"),
    ("clearance m", "clearance_m"),
    ("path m", "path_length_m"),
    ("optimal m", "optimal_path_m"),
    ("challenge", "challenge_metric"),
    ("ATE m", "ate_m"),
    ("stack p99 ms", "stack_p99_ms"),
    ("takeovers", "takeovers"),
    ("local %", "local_ticks_pct"),
    ("sim ms/step", "sim_ms_per_step"),
)
#: scenarios.csv: the aggregate columns after the counts.
_AGGREGATE_COLUMNS: tuple[str, ...] = (
    "success_rate",
    "collision_rate",
    "goal_missed_rate",
    "timeout_rate",
    "mean_time_to_goal_s",
    "clearance_m",
    "stack_p99_ms",
    "mean_challenge_metric",
)
SCENARIO_CSV_COLUMNS: tuple[str, ...] = (
    "scenario",
    "variant",
    "status",
    "runs",
    "errors",
    "successes",
    "collisions",
    "goal_missed",
    "timeouts",
    *_AGGREGATE_COLUMNS,
    "seeds",
    "failures",
    "path",
)
SUITE = "gndreplay.batch"
SCENARIO_SUITE = "gndreplay.batch.scenarios"
BASELINE_SUITE = "gndreplay.batch.baseline"
_XML_INVALID = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def _cell(metric: str, value: float | None) -> str:
    if value is None:
        return ""
    if math.isnan(value):
        return "nan"
    if metric.endswith(("_ms", "_rate")) or "_ms_per_" in metric:
        return f"{value:.3f}"
    if metric.endswith("challenge_metric"):
        return f"{value:.4f}"
    if metric.endswith(("_m", "_deg")):
        return f"{value:.4f}"
    if metric.endswith(("_s", "_pct")):
        return f"{value:.2f}"
    return str(int(value))


def _note(r: InputResult) -> str:
    return r.error if r.status == "error" else "; ".join(r.failures)


def summary_csv(results: Sequence[InputResult]) -> str:
    """summary.csv text: a ``CSV_COLUMNS`` header, then one row per input (empty cell = not measured)."""
    return _csv_text(
        CSV_COLUMNS,
        (
            [
                r.name, r.variant, r.status, r.ticks, r.group, r.seed if r.group else "", r.outcome,
                *(_cell(m, r.metrics.get(m)) for m in METRIC_COLUMNS), f"{r.wall_s:.3f}",
                "; ".join(r.failures), r.error, r.path, "" if r.run_dir is None else str(r.run_dir)
            ]
            for r in results
        ),
    )


def _csv_text(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """CSV text (``\n`` line ends) of a header and rows."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def _md_escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")


def _status(status: str) -> str:
    return status.upper() if status != "pass" else status


def _table(header: Sequence[str], align: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(_md_escape(c) for c in cells) + " |" for cells in rows]
    return lines


def _pct(count: int, of: int) -> str:
    return f"{count}/{of} ({100.0 * count / of:.0f} %)" if of else "-"


def _baseline_md(checks: Sequence[BaselineCheck], missing: Sequence[str], *, updated: bool) -> list[str]:
    """The baseline section of summary.md: a verdict line and one table row per input."""
    changed = sum(bool(c.behaviour_failure) for c in checks)
    slower = sum(bool(c.latency_failure) for c in checks)
    verdict = (f"{len(checks)} inputs against the baseline: {changed} behaviour changed, {slower} slower, "
               f"{sum(c.new for c in checks)} new, {sum(bool(c.error) for c in checks)} unreadable")
    lines = ["", "## Against the baseline", "", verdict + (" (accepted: written as the new baseline)"
                                                            if updated else "")]
    if missing:
        lines += ["", "Not in this batch: " + ", ".join(missing)]
    verdicts = {"same": "same", "new": "new"}
    lines += ["", *_table(
        ["input", "verdict", "first divergence", "outcome change", "latency ratio"],
        ["---", "---", "---", "---", "---:"],
        [[c.label, verdicts.get(c.verdict, c.verdict.upper()), c.error or c.divergence or "-",
          c.outcome_change or "-",
          ratio_text(c.latency_ratio) + (f" ({c.slowest_module})" if c.slowest_module else "")]
         for c in checks],
    )]
    return lines


def _sweep_md(points: Sequence[SweepPoint], results: Sequence[InputResult]) -> list[str]:
    """The sweep section of summary.md: one row of metrics per combination."""
    header, rows = sweep_rows(points, results)
    keys = len(points[0].values)
    cells = [[str(v) if k < keys + 4 else _sweep_cell(v) for k, v in enumerate(row)] for row in rows]
    return ["", "## Sweep", "", "One row per combination, over its inputs: success over the scenario runs, "
            "sums of counts, the mean time of the successes, the smallest clearance, the worst stack p99.",
            "", *_table(header, ["---"] * keys + ["---:"] * (len(header) - keys), cells)]


def _sweep_cell(value: object) -> str:
    return "-" if not isinstance(value, float) or math.isnan(value) else f"{value:.3g}" if abs(value) < 1000 \
        else f"{value:.0f}"


def sweep_csv(points: Sequence[SweepPoint], results: Sequence[InputResult]) -> str:
    """sweep.csv text: the sweep table (``sweep_rows``), one row per combination (empty cell: no run
    reported the metric)."""
    header, rows = sweep_rows(points, results)
    return _csv_text(header, ([("" if isinstance(v, float) and math.isnan(v) else
                                f"{v:.6g}" if isinstance(v, float) else v) for v in row] for row in rows))


def summary_md(
    results: Sequence[InputResult],
    aggregates: Sequence[ScenarioAggregate] = (),
    *,
    checks: Sequence[BaselineCheck] = (),
    missing: Sequence[str] = (),
    points: Sequence[SweepPoint] = (),
    baseline_updated: bool = False,
) -> str:
    """summary.md text, fit for a CI job summary: a totals line; with a baseline, its table (input,
    verdict, first divergence, outcome change, latency ratio); in a sweep, the table of the combinations;
    then one row per log; when there are scenarios, one row per scenario run and a table of the
    per-scenario aggregates over seeds."""
    n = {s: sum(r.status == s for r in results) for s in ("pass", "fail", "error")}
    lines = [
        "# gndreplay batch",
        "",
        f"{len(results)} inputs: {n['pass']} pass, {n['fail']} fail, {n['error']} error",
    ]
    if checks or missing:
        lines += _baseline_md(checks, missing, updated=baseline_updated)
    if any(p.name for p in points):
        lines += _sweep_md(points, results)
    logs = [r for r in results if not r.group]
    if logs:
        lines += ["", "## Logs"] if len(lines) > 3 else []
        lines += ["", *_table(
            ["input", "status", "ticks", *(h for h, _ in _MD_METRICS), "notes"],
            ["---", "---", "---:", *("---:" for _ in _MD_METRICS), "---"],
            [[r.label, _status(r.status), str(r.ticks), *(_cell(m, r.metrics.get(m)) for _, m in _MD_METRICS),
              _note(r)] for r in logs],
        )]
    runs = [r for r in results if r.group]
    if runs:
        lines += ["", "## Scenario runs", "", *_table(
            ["run", "status", "seed", "outcome", *(h for h, _ in _MD_SCENARIO_METRICS), "notes"],
            ["---", "---", "---:", "---", *("---:" for _ in _MD_SCENARIO_METRICS), "---"],
            [[r.label, _status(r.status), str(r.seed), r.outcome,
              *(_cell(m, r.metrics.get(m)) for _, m in _MD_SCENARIO_METRICS), _note(r)] for r in runs],
        )]
    if aggregates:
        lines += ["", "## Scenarios over seeds", "",
                  "Status: the worst of the scenario's runs and its thresholds over seeds; rates are of the "
                  "completed runs (errors apart); time: mean of the successes; clearance: the smallest of "
                  "any run; stack p99: the worst run's; goal missed: the stack stopped at the goal it "
                  "believed, the true axle outside the tolerance; challenge: the mean navigation-challenge "
                  "metric, a failure counting 0.", "", *_table(
            ["scenario", "status", "runs", "success", "collisions", "goal missed", "time-outs", "errors",
             "mean time s", "min clearance m", "stack p99 ms", "challenge", "notes"],
            ["---", "---", *("---:" for _ in range(10)), "---"],
            [[a.label, _status(a.status), str(a.runs), _pct(a.successes, a.runs - a.errors),
              str(a.collisions), str(a.goal_missed), str(a.timeouts), str(a.errors),
              _cell("mean_time_to_goal_s", a.metrics.get("mean_time_to_goal_s")),
              _cell("clearance_m", a.metrics.get("clearance_m")),
              _cell("stack_p99_ms", a.metrics.get("stack_p99_ms")),
              _cell("mean_challenge_metric", a.metrics.get("mean_challenge_metric")), "; ".join(a.failures)]
             for a in aggregates],
        )]
    return "\n".join(lines) + "\n"


def scenarios_csv(aggregates: Sequence[ScenarioAggregate]) -> str:
    """scenarios.csv text: a ``SCENARIO_CSV_COLUMNS`` header, then one row per scenario."""
    return _csv_text(
        SCENARIO_CSV_COLUMNS,
        (
            [
                a.scenario, a.variant, a.status, a.runs, a.errors, a.successes, a.collisions, a.goal_missed,
                a.timeouts,
                *(_cell(m, a.metrics.get(m)) for m in _AGGREGATE_COLUMNS), " ".join(str(s) for s in a.seeds),
                "; ".join(a.failures), a.path
            ]
            for a in aggregates
        ),
    )


def _x(text: str) -> str:
    """``text`` without the characters XML 1.0 cannot carry (control bytes from a corrupt log)."""
    return _XML_INVALID.sub("\ufffd", text)


def _counts(tests: int, fail: int, err: int, time_s: float, skipped: int | None = None) -> dict[str, str]:
    """A suite's count attributes (``skipped`` only where the JUnit schema allows it: on a testsuite)."""
    out = {"tests": str(tests), "failures": str(fail), "errors": str(err)}
    if skipped is not None:
        out["skipped"] = str(skipped)
    return out | {"time": f"{time_s:.3f}"}


def _baseline_cases(
    root: ET.Element, checks: Sequence[BaselineCheck], *, updated: bool
) -> tuple[int, int, int]:
    """The baseline suite: a behaviour and a latency test case per input checked (an input new to the
    baseline: skipped; an unreadable baseline run: an error). Returns (tests, failures, errors)."""
    cases: list[tuple[str, str, str, str]] = []  # (check, label, kind, message); kind: "", failure, ...
    for c in checks:
        for check, failure in (("behaviour", c.behaviour_failure), ("latency", c.latency_failure)):
            if c.error:
                cases.append((check, c.label, "error", c.error))
            elif c.new:
                cases.append((check, c.label, "skipped", "not in the baseline"))
            elif failure and not updated:
                cases.append((check, c.label, "failure", failure))
            else:
                cases.append((check, c.label, "", failure))
    fail = sum(k == "failure" for _, _, k, _ in cases)
    err = sum(k == "error" for _, _, k, _ in cases)
    skipped = sum(k == "skipped" for _, _, k, _ in cases)
    suite = ET.SubElement(root, "testsuite", {"name": BASELINE_SUITE, **_counts(len(cases), fail, err, 0.0,
                                                                               skipped)})
    by_label = {c.label: c for c in checks}
    for check, label, kind, message in cases:
        case = ET.SubElement(suite, "testcase", {"classname": f"{BASELINE_SUITE}.{check}", "name": _x(label),
                                                 "time": "0.000"})
        if kind:
            attrs = {"message": _x(message)} | ({} if kind == "skipped" else {"type": f"baseline-{check}"})
            node = ET.SubElement(case, kind, attrs)
            if kind != "skipped":
                node.text = _x(message)
        c = by_label[label]
        out = [f"baseline run: {_x(c.baseline_run)}"] if c.baseline_run else []
        if check == "behaviour":
            out += [f"first divergence: {_x(c.divergence or 'none')}",
                    f"outcome change: {_x(c.outcome_change or 'none')}"]
        else:
            out += [f"largest module median ratio: {ratio_text(c.latency_ratio)} {c.slowest_module}".rstrip()]
        if updated and message and kind == "":
            out.append(f"accepted as the new baseline: {_x(message)}")
        if out:
            ET.SubElement(case, "system-out").text = "\n".join(out)
    return len(cases), fail, err


def junit_xml(
    results: Sequence[InputResult],
    aggregates: Sequence[ScenarioAggregate] = (),
    *,
    checks: Sequence[BaselineCheck] = (),
    baseline_updated: bool = False,
) -> str:
    """JUnit XML (valid against the JUnit schema Jenkins, GitLab and GitHub's reporters read): one
    ``<testsuite name="gndreplay.batch">`` with one ``<testcase>`` per input (a scenario: per scenario and
    seed; in a sweep named ``combination/input``); a ``<failure>`` lists the thresholds exceeded (a run
    that did not reach its goal says how it ended), an ``<error>`` carries an unreadable input's message.
    Scenarios with aggregate thresholds add a ``<testsuite name="gndreplay.batch.scenarios">``, one test
    case per scenario; a baseline comparison a ``<testsuite name="gndreplay.batch.baseline">`` with a
    behaviour and a latency test case per input."""
    checked = [a for a in aggregates if a.limits]
    failures = sum(r.status == "fail" for r in results) + sum(bool(a.failures) for a in checked)
    errors = sum(r.status == "error" for r in results)
    total_s = sum(r.wall_s for r in results)
    root = ET.Element("testsuites", {"name": JUNIT_SUITES_NAME})
    suite = ET.SubElement(root, "testsuite", {"name": SUITE, **_counts(
        len(results), sum(r.status == "fail" for r in results), errors, total_s, 0)})
    for r in results:
        case = ET.SubElement(
            suite, "testcase", {"classname": SUITE, "name": _x(r.label), "time": f"{r.wall_s:.3f}"}
        )
        if r.status == "fail":
            node = ET.SubElement(case, "failure", {"message": _x("; ".join(r.failures)), "type": "threshold"})
            node.text = _x("\n".join(r.failures))
        elif r.status == "error":
            node = ET.SubElement(case, "error", {"message": _x(r.error), "type": r.error_type or "error"})
            node.text = _x(r.detail or r.error)
        out = [f"path: {_x(r.path)}", f"ticks: {r.ticks}"]
        if r.variant:
            out.append(f"combination: {_x(r.variant)}")
        if r.group:
            out += [f"scenario: {_x(r.group)}", f"seed: {r.seed}"]
            if r.outcome:
                out.append(f"outcome: {_x(r.outcome)}")
        if r.run_dir is not None:
            out.append(f"run_dir: {_x(str(r.run_dir))}")
        out += [f"{m}: {_cell(m, v)}" for m, v in r.metrics.items() if m != "ticks"]
        ET.SubElement(case, "system-out").text = "\n".join(out)
    if checked:
        agg_s = {a.label: sum(r.wall_s for r in results if r.group == a.scenario and r.variant == a.variant)
                 for a in checked}
        scen = ET.SubElement(root, "testsuite", {"name": SCENARIO_SUITE, **_counts(
            len(checked), sum(bool(a.failures) for a in checked), 0, sum(agg_s.values()), 0)})
        for a in checked:
            case = ET.SubElement(scen, "testcase", {"classname": SCENARIO_SUITE, "name": _x(a.label),
                                                    "time": f"{agg_s[a.label]:.3f}"})
            if a.failures:
                node = ET.SubElement(case, "failure", {"message": _x("; ".join(a.failures)),
                                                       "type": "threshold"})
                node.text = _x("\n".join(a.failures))
            out = [f"path: {_x(a.path)}", f"seeds: {' '.join(str(s) for s in a.seeds)}",
                   f"runs: {a.runs}", f"errors: {a.errors}", f"successes: {a.successes}",
                   f"collisions: {a.collisions}", f"goal_missed: {a.goal_missed}", f"timeouts: {a.timeouts}"]
            out += [f"{m}: {_cell(m, v)}" for m, v in a.metrics.items()]
            out += [f"limit {k}: {v:g}" for k, v in a.limits.items()]
            ET.SubElement(case, "system-out").text = "\n".join(out)
    tests = len(results) + len(checked)
    if checks:
        n, fail, err = _baseline_cases(root, checks, updated=baseline_updated)
        tests, failures, errors = tests + n, failures + fail, errors + err
    root.attrib |= _counts(tests, failures, errors, total_s)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def is_own_junit(path: Path) -> bool:
    """``path`` is a JUnit file gndreplay wrote (its root element, within the first two lines, is
    ``<testsuites name="gndreplay batch"``): the only kind of existing file ``--junit`` may replace."""
    try:
        with open(path, "rb") as f:
            head = f.read(512).decode("utf-8", errors="replace")
    except OSError:
        return False
    return any(line.startswith(_JUNIT_ROOT) for line in head.splitlines()[:2])
