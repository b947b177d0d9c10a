"""snapshots/: one picture of the decision (``report.decision``) at each key event of a run, and
snapshots/index.csv listing them; report.md links them in its timeline.

Events (``tick_events``, a pure function of two consecutive ticks), by kind:

- ``mode``: the mode changed between two modes that are not reflexive overrides (GND's mpND / mND /
  ROTATE; the multi-loop modules' TELEOP / FOLLOW / LOCAL);
- ``emergency``: an emergency stop began (Mode.EMERGENCY or Flag.EMERGENCY_STOP);
- ``reflexive``: another reflexive rule began replacing the command (SAFE_SLOW, SAFE_TURN, SAFE_REVERSE,
  STALE);
- ``trap``: Flag.TRAP_DETECTED began; ``escape``: the trap escape (Mode.ESCAPE) began;
- ``planner``: the planner began failing or falling back (PLANNER_NO_PATH, GOAL_IN_OBSTACLE,
  PLANNER_TIMEOUT, PLANNER_FALLBACK);
- ``takeover``: the active navigation mode stopped being the desired one;
- ``goal``: the goal was reached.

``SnapshotOptions`` limits them: at most one snapshot per kind per ``min_interval_s`` of log time, at most
``max_per_kind`` per kind and ``max_snapshots`` per run (``EventGate``). The sink keeps only the facts of
the ticks it will draw (``DecisionInput``: the grid copied when an event is admitted, never per tick) and
draws them at ``finish`` with the run's config.toml, so a run's sinks need no configuration beside it.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Config, load_config
from ..errors import ConfigError
from ..fsutil import atomic_write_text, format_stamp, write_marker
from ..io.userfile import read_text
from ..pipeline.model import RobotCentredGrid
from ..pipeline.stack import TickResult
from ..types import NS_PER_S, REFLEXIVE_MODES, Flag, Mode, Pose2D, Tick
from .decision import (
    DecisionInput,
    clear_decision,
    decision_figure,
    decision_input,
    decision_view,
    draw_decision,
)
from .rundir import CONFIG_FILE, RunDirError, csv_text

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "EVENT_KINDS",
    "INDEX_FILE",
    "INDEX_HEADER",
    "PLANNER_FLAGS",
    "SNAPSHOTS_DIR",
    "Event",
    "EventGate",
    "SnapshotEntry",
    "SnapshotOptions",
    "SnapshotSink",
    "read_snapshot_index",
    "tick_events",
]

SNAPSHOTS_DIR = "snapshots"
INDEX_FILE = "index.csv"
INDEX_HEADER = "t,elapsed_s,kind,reason,file\n"
EVENT_KINDS: tuple[str, ...] = (
    "mode", "emergency", "reflexive", "trap", "escape", "planner", "takeover", "goal",
)  # fmt: skip
PLANNER_FLAGS = Flag.PLANNER_NO_PATH | Flag.GOAL_IN_OBSTACLE | Flag.PLANNER_TIMEOUT | Flag.PLANNER_FALLBACK
MAX_INDEX_BYTES = 16 << 20
"""Largest snapshots/index.csv read back (a run writes a few KB)."""

_OVERRIDES = frozenset(REFLEXIVE_MODES) | {Mode.GOAL.value}  # not "modes" of the mode-change event
_OTHER_REFLEXES = frozenset(REFLEXIVE_MODES) - {Mode.EMERGENCY.value, Mode.ESCAPE.value}


@dataclass(frozen=True, slots=True)
class Event:
    """A key event at a tick: its ``kind`` (one of ``EVENT_KINDS``) and a one-line ``reason``."""

    kind: str
    reason: str


def _began(prev: TickResult | None, cur: TickResult, flags: Flag) -> Flag:
    """The flags of ``flags`` set at ``cur`` and not at ``prev``."""
    return cur.flags & flags & ~(prev.flags if prev is not None else Flag.NONE)


def _names(flags: Flag) -> str:
    return "|".join(flags.names())


def tick_events(prev: TickResult | None, cur: TickResult) -> tuple[Event, ...]:
    """The key events of tick ``cur`` after ``prev`` (None: the first tick), in ``EVENT_KINDS`` order (see
    the module docstring). Each fires at its onset only: a rule, flag or takeover lasting many ticks is one
    event."""
    out: list[Event] = []
    mode, before = cur.mode.value, prev.mode.value if prev is not None else None
    if before is not None and mode != before and mode not in _OVERRIDES and before not in _OVERRIDES:
        out.append(Event("mode", f"{before} -> {mode}"))
    stop = _began(prev, cur, Flag.EMERGENCY_STOP)
    if (mode == Mode.EMERGENCY.value and before != mode) or stop:
        out.append(Event("emergency", f"{mode}" + (f" ({_names(stop)})" if stop else "")))
    if mode in _OTHER_REFLEXES and before != mode:
        out.append(Event("reflexive", f"{mode} replaced the command" if mode != Mode.STALE.value
                         else "STALE: sensor data too old, stop"))
    if trap := _began(prev, cur, Flag.TRAP_DETECTED):
        out.append(Event("trap", f"{_names(trap)} ({mode})"))
    if mode == Mode.ESCAPE.value and before != mode:
        out.append(Event("escape", "ESCAPE: trap escape manoeuvre"))
    if planner := _began(prev, cur, PLANNER_FLAGS):
        out.append(Event("planner", f"{_names(planner)} ({mode})"))
    taken = cur.active_mode != cur.desired_mode
    if taken and (prev is None or prev.active_mode == prev.desired_mode):
        why = f": {cur.takeover_reason}" if cur.takeover_reason else ""
        out.append(Event("takeover", f"{cur.active_mode} took over from {cur.desired_mode}{why}"))
    if _began(prev, cur, Flag.GOAL_REACHED) or (mode == Mode.GOAL.value and before != mode):
        out.append(Event("goal", "goal reached"))
    return tuple(out)


@dataclass(frozen=True, slots=True)
class SnapshotOptions:
    """Which events get a snapshot, and how they look.

    Attributes:
        min_interval_s: at most one snapshot per event kind per this many seconds of log time (**choice**:
            10 s; an override flickering on and off is drawn once, not every time it recurs).
        max_per_kind: at most this many snapshots of one kind (**choice**: 8, so that frequent mode changes
            cannot use up the run's snapshots before a rare trap).
        max_snapshots: at most this many snapshots per run (**choice**: 40).
        kinds: the event kinds drawn (``EVENT_KINDS``).
        radius_m: half the side of the square view around the robot [m] (**choice**: 5 m, ND+'s range).
        dpi: resolution of the PNGs (7 x 8 inch figures).
    """

    min_interval_s: float = 10.0
    max_per_kind: int = 8
    max_snapshots: int = 40
    kinds: tuple[str, ...] = EVENT_KINDS
    radius_m: float = 5.0
    dpi: int = 100

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_interval_s <= 1e6:
            raise ConfigError(f"snapshots: min_interval_s must be in [0, 1e6], got {self.min_interval_s}")
        for name in ("max_per_kind", "max_snapshots"):
            value = getattr(self, name)
            if not (isinstance(value, int) and 0 <= value <= 100_000):
                raise ConfigError(f"snapshots: {name} must be an integer in [0, 100000], got {value!r}")
        unknown = [k for k in self.kinds if k not in EVENT_KINDS]
        if unknown:
            raise ConfigError(f"snapshots: unknown event kind(s) {', '.join(unknown)}; "
                              f"known: {', '.join(EVENT_KINDS)}")
        if not 0.5 <= self.radius_m <= 100.0:
            raise ConfigError(f"snapshots: radius_m must be in [0.5, 100], got {self.radius_m}")
        if not 20 <= self.dpi <= 600:
            raise ConfigError(f"snapshots: dpi must be in [20, 600], got {self.dpi}")


class EventGate:
    """Admits events under ``SnapshotOptions``: kinds asked for, one per kind per ``min_interval_s``, at most
    ``max_per_kind`` per kind and ``max_snapshots`` ticks drawn in all."""

    def __init__(self, options: SnapshotOptions) -> None:
        self.options = options
        self._last_ns: dict[str, int] = {}
        self._per_kind: dict[str, int] = {}
        self.drawn = 0  # ticks admitted (one snapshot each)
        self.dropped = 0  # events not admitted

    def admit(self, events: Sequence[Event], t_ns: int) -> list[Event]:
        """The events of a tick at ``t_ns`` that get its snapshot (empty: no snapshot), the gate's counts
        updated. Events of one tick share one snapshot."""
        o = self.options
        if self.drawn >= o.max_snapshots:
            self.dropped += len(events)
            return []
        gap = round(o.min_interval_s * NS_PER_S)
        taken = [e for e in events if e.kind in o.kinds
                 and self._per_kind.get(e.kind, 0) < o.max_per_kind
                 and (e.kind not in self._last_ns or t_ns - self._last_ns[e.kind] >= gap)]
        kinds = {e.kind for e in taken}
        for k in kinds:
            self._last_ns[k] = t_ns
            self._per_kind[k] = self._per_kind.get(k, 0) + 1
        self.drawn += bool(taken)
        self.dropped += len(events) - len(taken)
        return taken


@dataclass(frozen=True, slots=True)
class SnapshotEntry:
    """A row of snapshots/index.csv: the event's time (``t``: the tick's stamp as in commands.csv;
    ``elapsed_s``: seconds since the first scan), kind, reason, and the PNG's name in snapshots/."""

    t: str
    elapsed_s: float
    kind: str
    reason: str
    file: str


def _file_name(k: int, events: Sequence[Event], elapsed_s: float) -> str:
    kinds = "-".join(dict.fromkeys(e.kind for e in events))
    return f"{k:03d}_{elapsed_s:08.2f}s_{kinds}.png"


@dataclass(slots=True)
class _Pending:
    inp: DecisionInput
    events: list[Event] = field(default_factory=list)


class SnapshotSink:
    """A ``RunSink`` writing snapshots/ (PNGs and index.csv) for the key events of the run (module
    docstring). ``config``: the run's configuration (None: read the run directory's config.toml at
    ``finish``, which the replay writes before the sinks finish). ``split``: draw the snapshots in two
    processes (``split.run_split``; None: where two CPUs are free; the files are the same either way).
    Give it before the ``ReportSink``, whose report.md links the snapshots."""

    def __init__(self, options: SnapshotOptions = SnapshotOptions(), config: Config | None = None, *,
                 split: bool | None = None) -> None:
        self.options = options
        self.config = config
        self.split = split  # draw in two processes (``split.run_split``; None: where two CPUs are free)
        self.gate = EventGate(options)
        self._t0_ns: int | None = None
        self._prev: TickResult | None = None
        self._pending: list[_Pending] = []
        self.written: list[str] = []

    def add_scan(self, tick: Tick, pose_corrected: Pose2D) -> None:
        """The first scan's time is the run's time origin."""
        if self._t0_ns is None:
            self._t0_ns = tick.t_ns

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Detect the tick's events; when one is admitted, keep the tick's facts for drawing."""
        events = self.gate.admit(tick_events(self._prev, result), result.t_ns)
        self._prev = result
        if events:
            t0 = self._t0_ns if self._t0_ns is not None else result.t_ns
            self._pending.append(_Pending(decision_input(tick, result, grid, t0_ns=t0), events))

    def finish(self, run_dir: Path) -> None:
        """Draw the kept ticks into ``run_dir/snapshots/`` with index.csv and the folder's marker."""
        from functools import partial

        from .figures import import_agg, save_figure
        from .split import run_split

        run_dir = Path(run_dir)
        cfg = self.config if self.config is not None else load_config(run_dir / CONFIG_FILE)
        out = run_dir / SNAPSHOTS_DIR
        out.mkdir(exist_ok=True)
        opts = self.options
        drawn: list[tuple[Figure, Axes]] = []  # one figure per process, cleared between snapshots

        def draw(inp: DecisionInput, headline: str, path: Path) -> None:
            if not drawn:
                drawn.append(decision_figure())
            fig, ax = drawn[0]
            clear_decision(ax)
            draw_decision(ax, decision_view(inp, cfg, headline=headline, radius_m=opts.radius_m))
            save_figure(fig, path, dpi=opts.dpi)

        rows = [INDEX_HEADER]
        jobs, names = [], []
        for k, p in enumerate(self._pending, start=1):
            name = _file_name(k, p.events, p.inp.t_s)
            headline = "; ".join(f"{e.kind}: {e.reason}" for e in p.events)
            jobs.append(partial(draw, p.inp, headline, out / name))
            names.append(name)
            rows += [f"{format_stamp(p.inp.t_ns)},{p.inp.t_s:.3f},{e.kind},{csv_text(e.reason)},{name}\n"
                     for e in p.events]
        if jobs:
            import_agg()
        run_split(jobs, split=self.split)
        self.written += names
        atomic_write_text(out / INDEX_FILE, "".join(rows))
        write_marker(out)  # the folder lists what gndreplay wrote in it (an --overwrite may replace them)
        self._pending.clear()

    def abort(self) -> None:
        """Drop the kept ticks (the staging directory holds nothing of this sink before ``finish``)."""
        self._pending.clear()


def read_snapshot_index(run_dir: Path) -> list[SnapshotEntry] | None:
    """snapshots/index.csv of ``run_dir``, or None when the run has none.

    Raises:
        RunDirError: the file is too large, not UTF-8, has another header or a malformed row (named by
            line), or names a file outside snapshots/.
    """
    path = Path(run_dir) / SNAPSHOTS_DIR / INDEX_FILE
    if not path.is_file():
        return None
    try:
        text = read_text(path, "snapshot index", MAX_INDEX_BYTES)
    except ConfigError as err:
        raise RunDirError(str(err)) from None
    rows = list(csv.reader(io.StringIO(text, newline="")))
    if not rows or ",".join(rows[0]) + "\n" != INDEX_HEADER:
        raise RunDirError(f"{path}: expected header {INDEX_HEADER.strip()}")
    out = []
    for k, r in enumerate(rows[1:], start=2):
        try:
            if len(r) != 5:
                raise ValueError(f"{len(r)} fields")
            if "/" in r[4] or "\\" in r[4] or not r[4].endswith(".png") or r[4].startswith("."):
                raise ValueError(f"file {r[4][:60]!r} is not a PNG in {SNAPSHOTS_DIR}/")
            out.append(SnapshotEntry(t=r[0], elapsed_s=float(r[1]), kind=r[2], reason=r[3], file=r[4]))
        except ValueError as err:
            raise RunDirError(f"{path} line {k}: expected t,elapsed_s (a number),kind,reason,file "
                              f"({err})") from None
    return out
