"""Subgoal lists of the functional loop (``--subgoals FILE`` and the scenario's ``subgoals:`` rows).

File format, one subgoal per line::

    # x [m]  y [m]  theta [rad]  kind (stop | forward | reverse; optional, default forward)
    2.0  0.0  0.0
    4.0  1.5  1.57  forward
    5.0  3.0  3.14  stop

Blank lines and ``#`` comments (whole line or trailing) are allowed. Poses are in the corrected odometry
frame. Every bad line (field count, a non-number, a non-finite value, |x| or |y| above 1e6 m, an unknown
kind, |theta| above 1e3 rad), an empty list, an unreadable file, a folder, a FIFO / device / socket (never
opened: reading one could block for ever) or a file above 1 MB raises ``ConfigError`` with one line naming the
file and line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast, get_args

from ..errors import ConfigError
from ..types import Subgoal, SubgoalKind
from .userfile import brief, read_text

__all__ = [
    "MAX_ABS_SUBGOAL_M", "MAX_ABS_THETA_RAD", "MAX_SUBGOAL_FILE_BYTES",
    "load_subgoals", "subgoals_from_rows",
]

MAX_ABS_SUBGOAL_M = 1e6
"""Largest |x| or |y| [m] accepted (the readers' bound on positions)."""
MAX_ABS_THETA_RAD = 1e3
"""Largest |theta| [rad] accepted (a heading beyond it is a typo, and would lose precision when wrapped)."""
MAX_SUBGOAL_FILE_BYTES = 1 << 20
"""Largest subgoal file read (1 MB: tens of thousands of subgoals)."""

_KINDS: tuple[str, ...] = get_args(SubgoalKind)


def _number(v: Any, name: str, where: str) -> float:
    """A finite float from a YAML number or a file token."""
    if isinstance(v, bool):
        raise ConfigError(f"{where}: {name} must be a number, got {v!r}")
    try:
        x = float(v)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an integer beyond a float
        raise ConfigError(f"{where}: {name} must be a number, got {brief(v)}") from None
    if not math.isfinite(x):
        raise ConfigError(f"{where}: {name} must be finite, got {brief(v)}")
    return x


def _subgoal(fields: Sequence[Any], where: str) -> Subgoal:
    """One validated subgoal from ``[x, y, theta]`` or ``[x, y, theta, kind]``."""
    if len(fields) not in (3, 4):
        raise ConfigError(f"{where}: expected 'x y theta [kind]' (3 or 4 fields), got {len(fields)}")
    x, y, theta = (_number(v, n, where) for v, n in zip(fields[:3], ("x", "y", "theta"), strict=True))
    for v, n in ((x, "x"), (y, "y")):
        if abs(v) > MAX_ABS_SUBGOAL_M:
            raise ConfigError(f"{where}: |{n}| must be <= {MAX_ABS_SUBGOAL_M:g} m, got {v!r}")
    if abs(theta) > MAX_ABS_THETA_RAD:
        raise ConfigError(f"{where}: |theta| must be <= {MAX_ABS_THETA_RAD:g} rad, got {theta!r}")
    kind = fields[3] if len(fields) == 4 else "forward"
    if kind not in _KINDS:
        raise ConfigError(f"{where}: kind must be one of {', '.join(_KINDS)}, got {brief(kind)}")
    return Subgoal(x, y, theta, cast(SubgoalKind, kind))


def subgoals_from_rows(rows: Any, where: str) -> tuple[Subgoal, ...]:
    """Subgoals from rows ``[[x, y, theta, kind], ...]`` (kind optional), e.g. a scenario's YAML list;
    ``where`` names the source in errors (``"run.yaml: subgoals"`` -> ``"run.yaml: subgoals[2]: ..."``)."""
    if not isinstance(rows, list | tuple) or not rows:
        raise ConfigError(
            f"{where}: expected a non-empty list of [x, y, theta, kind] rows, got {brief(rows)}"
        )
    out = []
    for i, row in enumerate(rows):
        if not isinstance(row, list | tuple):
            raise ConfigError(f"{where}[{i}]: expected a list [x, y, theta, kind], got {brief(row)}")
        out.append(_subgoal(row, f"{where}[{i}]"))
    return tuple(out)


def load_subgoals(path: Path) -> tuple[Subgoal, ...]:
    """Read a subgoal file (format: module docstring)."""
    text = read_text(Path(path), "subgoal file", MAX_SUBGOAL_FILE_BYTES)
    out = []
    for n, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if fields:
            out.append(_subgoal(fields, f"{path} line {n}"))
    if not out:
        raise ConfigError(f"{path}: no subgoal in the file (one 'x y theta [kind]' per line)")
    return tuple(out)
