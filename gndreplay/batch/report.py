"""Batch outputs: summary.csv, summary.md and JUnit XML, one row / test case per input, written atomically."""

from __future__ import annotations

import csv
import io
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence

from .worker import InputResult

__all__ = [
    "CSV_COLUMNS",
    "junit_xml",
    "summary_csv",
    "summary_md",
]

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
)
CSV_COLUMNS: tuple[str, ...] = (
    "name",
    "status",
    "ticks",
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
)
SUITE = "gndreplay.batch"
_XML_INVALID = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def _cell(metric: str, value: float | None) -> str:
    if value is None:
        return ""
    if math.isnan(value):
        return "nan"
    if metric.endswith("_ms"):
        return f"{value:.3f}"
    if metric.endswith(("_m", "_deg")):
        return f"{value:.4f}"
    return str(int(value))


def _note(r: InputResult) -> str:
    return r.error if r.status == "error" else "; ".join(r.failures)


def summary_csv(results: Sequence[InputResult]) -> str:
    """summary.csv text: a ``CSV_COLUMNS`` header, then one row per input (empty cell = not measured)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for r in results:
        w.writerow(
            [
                r.name,
                r.status,
                r.ticks,
                *(_cell(m, r.metrics.get(m)) for m in METRIC_COLUMNS),
                f"{r.wall_s:.3f}",
                "; ".join(r.failures),
                r.error,
                r.path,
                "" if r.run_dir is None else str(r.run_dir),
            ]
        )
    return buf.getvalue()


def _md_escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")


def summary_md(results: Sequence[InputResult]) -> str:
    """summary.md text: a totals line and a Markdown table, one row per input."""
    n = {s: sum(r.status == s for r in results) for s in ("pass", "fail", "error")}
    header = ["input", "status", "ticks", *(h for h, _ in _MD_METRICS), "notes"]
    lines = [
        "# gndreplay batch",
        "",
        f"{len(results)} inputs: {n['pass']} pass, {n['fail']} fail, {n['error']} error",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "|".join(["---", "---", "---:", *("---:" for _ in _MD_METRICS), "---"]) + "|",
    ]
    for r in results:
        cells = [
            r.name,
            r.status.upper() if r.status != "pass" else r.status,
            str(r.ticks),
            *(_cell(m, r.metrics.get(m)) for _, m in _MD_METRICS),
            _note(r),
        ]
        lines.append("| " + " | ".join(_md_escape(c) for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _x(text: str) -> str:
    """``text`` without the characters XML 1.0 cannot carry (control bytes from a corrupt log)."""
    return _XML_INVALID.sub("\ufffd", text)


def junit_xml(results: Sequence[InputResult]) -> str:
    """JUnit XML: one ``<testsuite name="gndreplay.batch">`` with one ``<testcase>`` per input; a
    ``<failure>`` lists the thresholds exceeded, an ``<error>`` carries an unreadable input's message."""
    failures = sum(r.status == "fail" for r in results)
    errors = sum(r.status == "error" for r in results)
    total_s = sum(r.wall_s for r in results)
    counts = {
        "tests": str(len(results)),
        "failures": str(failures),
        "errors": str(errors),
        "skipped": "0",
        "time": f"{total_s:.3f}",
    }
    root = ET.Element("testsuites", {"name": "gndreplay batch", **counts})
    suite = ET.SubElement(root, "testsuite", {"name": SUITE, **counts})
    for r in results:
        case = ET.SubElement(
            suite, "testcase", {"classname": SUITE, "name": _x(r.name), "time": f"{r.wall_s:.3f}"}
        )
        if r.status == "fail":
            node = ET.SubElement(case, "failure", {"message": _x("; ".join(r.failures)), "type": "threshold"})
            node.text = _x("\n".join(r.failures))
        elif r.status == "error":
            node = ET.SubElement(case, "error", {"message": _x(r.error), "type": r.error_type or "error"})
            node.text = _x(r.detail or r.error)
        out = [f"path: {_x(r.path)}", f"ticks: {r.ticks}"]
        if r.run_dir is not None:
            out.append(f"run_dir: {_x(str(r.run_dir))}")
        out += [f"{m}: {_cell(m, v)}" for m, v in r.metrics.items() if m != "ticks"]
        ET.SubElement(case, "system-out").text = "\n".join(out)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"
