"""Parameter sweeps: ``batch INPUTS --set reactor.security_m=0.3,0.5 --set robot.vmax_mps=0.3,0.5`` runs every
input under each combination of the listed values (the cross product, in the order the keys are given).

A ``--set`` with one value is an ordinary override and applies to every combination; a ``--set`` whose
value is a comma-separated list (commas inside ``[...]``, ``{...}`` or quotes do not split: ``[1, 2]`` is
one TOML array) is a sweep axis. Each combination is validated as a configuration before anything runs,
and its runs go to ``<batch>/<combination>/<input>/``; the sweep table (:func:`sweep_rows`) gives one row
of metrics per combination.
"""

from __future__ import annotations

import itertools
import math
import re
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from .. import fsutil
from ..errors import ConfigError
from ..io.userfile import brief
from .jobs import numbered
from .worker import InputResult

__all__ = ["MAX_COMBINATIONS", "SWEEP_COLUMNS", "SweepPoint", "split_values", "sweep_points", "sweep_rows"]

#: More combinations than this is a typo (a batch that would never end), refused before anything runs.
MAX_COMBINATIONS = 1000
_OPEN = {"[": "]", "{": "}"}
_UNSAFE = re.compile(r"[^A-Za-z0-9._+=,-]")


@dataclass(frozen=True, slots=True)
class SweepPoint:
    """One combination of a sweep.

    Attributes:
        name: its folder in the batch ("" when nothing is swept: the runs sit in the batch folder itself):
            the swept ``key=value`` pairs joined by ``,``, characters other than letters, digits and
            ``._+=,-`` replaced by ``_``.
        values: (key, value as written) of each swept key, in the order the keys were given.
        sets: every ``--set`` pair of this combination, in the order given (fixed pairs and this
            combination's value of each axis).
    """

    name: str
    values: tuple[tuple[str, str], ...]
    sets: tuple[str, ...]


def split_values(text: str) -> list[str]:
    """``text`` split on the commas outside brackets, braces and quotes, each part stripped.

    Raises:
        ConfigError: an unbalanced bracket or quote.
    """
    parts: list[str] = []
    stack: list[str] = []
    quote = ""
    start = 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in _OPEN:
            stack.append(_OPEN[ch])
        elif ch in "]}":
            if not stack or stack.pop() != ch:
                raise ConfigError(f"--set: unbalanced {ch!r} in {brief(text)}")
        elif ch == "," and not stack:
            parts.append(text[start:i].strip())
            start = i + 1
    if quote or stack:
        raise ConfigError(f"--set: unclosed {quote or stack[-1]!r} in {brief(text)}")
    parts.append(text[start:].strip())
    return parts


def _axis(text: str) -> tuple[str, list[str]]:
    """(key, values) of one ``--set key=v1,v2,...``."""
    key, sep, raw = text.partition("=")
    values = split_values(raw) if sep else [raw]
    if len(values) > 1:
        if any(not v for v in values):
            raise ConfigError(f"--set {brief(text)}: an empty value in the list")
        if len(set(values)) != len(values):
            raise ConfigError(f"--set {brief(text)}: a value is listed twice")
    return key.strip(), values


def _folder_name(values: Sequence[tuple[str, str]]) -> str:
    """``key=value,key=value`` with every character a folder name should not hold replaced by ``_``."""
    return fsutil.safe_name(_UNSAFE.sub("_", ",".join(f"{k}={v}" for k, v in values)), "combination")


def sweep_points(sets: Sequence[str]) -> tuple[SweepPoint, ...]:
    """The combinations of the ``--set`` pairs: one unnamed point with every pair when none lists several
    values, else the cross product of the listed values (the first key varying slowest).

    Raises:
        ConfigError: the same key swept twice, an empty or repeated value in a list, unbalanced brackets or
            quotes, or more than ``MAX_COMBINATIONS`` combinations (one line quoting the option).
    """
    axes = [(i, *_axis(text)) for i, text in enumerate(sets)]
    swept = [(i, key, values) for i, key, values in axes if len(values) > 1]
    if not swept:
        return (SweepPoint("", (), tuple(sets)),)
    keys = [key for _, key, _ in swept]
    for key in keys:
        if keys.count(key) > 1:
            raise ConfigError(f"--set: {key} is swept twice; give its values in one --set {key}=a,b,...")
    count = math.prod(len(values) for _, _, values in swept)
    if count > MAX_COMBINATIONS:
        raise ConfigError(f"--set: {count} combinations (more than {MAX_COMBINATIONS}); sweep fewer values")
    points = []
    for combo in itertools.product(*(values for _, _, values in swept)):
        chosen = {i: value for (i, _, _), value in zip(swept, combo, strict=True)}
        pairs = tuple(
            f"{key}={chosen[i]}" if i in chosen else sets[i] for i, key, _ in axes
        )
        values = tuple((key, value) for key, value in zip(keys, combo, strict=True))
        points.append(SweepPoint(_folder_name(values), values, pairs))
    names = numbered([p.name for p in points])
    return tuple(SweepPoint(n, p.values, p.sets) for n, p in zip(names, points, strict=True))


#: The sweep table's metric columns after the swept keys and the counts: (header, metric, how).
SWEEP_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("success %", "success", "rate"),
    ("collisions", "collisions", "sum"),
    ("mean time to goal s", "time_to_goal_s", "mean"),
    ("min clearance m", "clearance_m", "min"),
    ("emergency stops", "emergency_stops", "sum"),
    ("no region", "no_region", "sum"),
    ("match failures", "match_failures", "sum"),
    ("ATE m (mean)", "ate_m", "mean"),
    ("stack p99 ms (worst)", "stack_p99_ms", "max"),
    ("mean challenge", "challenge_metric", "mean"),
)


def _reduce(values: list[float], how: str) -> float:
    if not values:
        return math.nan
    if how == "sum":
        return float(sum(values))
    if how == "mean":
        return statistics.fmean(values)
    if how == "rate":
        return 100.0 * statistics.fmean(values)
    return float(min(values) if how == "min" else max(values))


def sweep_rows(
    points: Sequence[SweepPoint], results: Sequence[InputResult]
) -> tuple[list[str], list[list[object]]]:
    """The sweep table: (header, one row per combination): the swept values, the inputs run, passed,
    failed and in error, then ``SWEEP_COLUMNS`` over the completed runs of that combination (a rate over
    the runs that report the metric: success over scenario runs; NaN when none does)."""
    keys = [key for key, _ in points[0].values] if points else []
    header = [*keys, "inputs", "pass", "fail", "error", *(h for h, _, _ in SWEEP_COLUMNS)]
    rows: list[list[object]] = []
    for point in points:
        mine = [r for r in results if r.variant == point.name]
        done = [r for r in mine if r.status != "error"]
        row: list[object] = [value for _, value in point.values]
        row += [len(mine), *(sum(r.status == s for r in mine) for s in ("pass", "fail", "error"))]
        for _, metric, how in SWEEP_COLUMNS:
            row.append(_reduce([r.metrics[metric] for r in done if metric in r.metrics
                                and math.isfinite(r.metrics[metric])], how))
        rows.append(row)
    return header, rows
