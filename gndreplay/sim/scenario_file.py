"""Scenario files (YAML): a world, its events and movers, a start and a goal, read into a frozen
:class:`ScenarioSpec`.

Schema (unknown keys are errors; every error is one line naming the file and the key)::

    name: u_trap
    description: free text                      # optional
    preset: wheelchair                          # or xr4000, compact (``config.PRESETS``)
    start: [x, y, theta]                        # m, m, rad
    goal: [x, y]
    time_limit: 120                             # s
    expect: reachable                           # optional: unreachable lets the start touch / the goal sit
                                                #   in an obstacle (a test of an impossible task)
    world:
      map: office.yaml                          # optional: a ROS map (or a BeeSoft .dat[.gz]), element "map";
                                                #   or {file: f, unknown: occupied|free, occupied_thresh: p,
                                                #   free_thresh: p} (thresholds: a BeeSoft map's)
      sdf: office.world                         # optional: a Gazebo world's static boxes, cylinders, spheres
      walls:    {id: [x1, y1, x2, y2], ...}     # or [x1, y1, x2, y2, thickness]; default 0.1 m
      boxes:    {id: [cx, cy, length, width, theta], ...}
      circles:  {id: [cx, cy, r], ...}
      polygons: {id: [[x, y], [x, y], [x, y], ...], ...}
    events:
      - {at: 20.0, add: {walls: {door: [x1, y1, x2, y2]}}}   # appears at t = 20 s
      - {at: 45.0, remove: door}
      - {at: 10.0, close: door, over: 2.0}                    # a wall's leaf slides shut from (x1, y1)
      - {at: 10.0, close: door}                               # over: 0 (default): shut at once at t = 10 s
      - {at: 10.0, close: door, over: 2.0, swing: 90}         # ... or swings shut about (x1, y1) from +90 deg
      - {at: 30.0, open: door, over: 2.0}
    movers:
      - {id: person, radius: 0.25, speed: 1.0, path: [[x, y], ...], loop: false, start_at: 0.0, yield_m: 0.3}
    mode: gnd                                   # optional: gnd (default) | teleop | follow | local
    local: nd                                   # optional: the local navigation strategy
    subgoals: [[x, y, theta, stop], ...]        # mode follow: stop | forward | reverse
    teleop:                                     # mode teleop: one of
      commands: [[t_s, v, w], ...]              #   a script (last entry [t_end, 0, 0])
      track: {points: [[x, y], ...], speed: v, lookahead: 0.8, tolerance: 0.3}   # a careless driver

A wall with ``close`` / ``open`` events is a door leaf: open (absent, or swung away) before its first
``close``, closed before its first ``open``; ``over`` (default 0) is the motion's duration, 0 a step at
``at``. Like a person moving it, a leaf waits while its next step would bring it closer than 0.3 m to
the robot (``DEFAULT_YIELD_M``). A mover stands at its first waypoint until ``start_at``, then walks the
path at ``speed`` (back to the start and again if ``loop``), and stays at its last waypoint. ``name`` is a
plain name (letters, digits, ``_ . -``, not starting with ``.`` or ``-``): it names the run directory.

A scenario file is read like every user file (:mod:`gndreplay.io.userfile`): a regular file of at most
``MAX_SCENARIO_BYTES``, its YAML bounded in nesting and in what aliases expand to. Every number goes through
``userfile.check_number`` with its physical range (``MAX_TIME_S``, ``MAX_SIZE_M``, ...), every list holds
at most ``MAX_ELEMENTS`` / ``MAX_MOVERS`` / ``MAX_EVENTS`` / ``MAX_POINTS`` / ``MAX_TELEOP_ROWS`` items, and
a value quoted in an error is cut short (``userfile.brief``).

World files (``map``, ``sdf``; :mod:`.maps`, :mod:`.sdf`, docs/worlds.md) are named relative to the
scenario file's folder and mix with the elements above: the map is the element ``map`` (events may remove
it), an SDF shape the element ``model/link/collision``. What a world file held but the simulator skips is
logged as one warning per file and kept in ``ScenarioSpec.world_warnings``. The start and the goal are
checked against the world at t = 0 when a run starts (:func:`.worldstate.check_endpoints`).

Navigation mode: ``mode`` (when given) overrides the configuration's ``navigation.mode`` and
``local`` its ``navigation.local.strategy``. Poses (start, goal, subgoals, track) are in the scenario's
world frame; the simulated odometry starts at ``start`` with that frame, so they are the robot's odometry
frame too. ``mode: follow`` needs ``subgoals`` (the goal defaults to the last one's position) and succeeds
when the stack reports the final subgoal reached, without contact. ``mode: teleop`` needs ``teleop`` (see
:mod:`.teleop`; a track's goal defaults to its last point) and succeeds when the script's time is over or
the track's end is reached, without contact. ``subgoals`` and ``teleop`` are errors in other modes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from .. import detmath as dm
from ..config import PRESETS
from ..errors import FOLLOW_NEEDS_SUBGOALS, ConfigError, did_you_mean
from ..io.subgoals import MAX_ABS_SUBGOAL_M, MAX_ABS_THETA_RAD
from ..io.userfile import brief, check_number, load_yaml, parse_yaml
from ..pipeline.local import LOCAL_STRATEGIES
from ..pipeline.stack import NAV_MODES
from ..types import Subgoal, SubgoalKind
from .geometry import EdgeGroups, Shapes, box_vertices, wall_vertices
from .maps import OccupancyMap, load_map
from .sdf import read_sdf_world
from .teleop import DEFAULT_LOOKAHEAD_M, TeleopSpec
from .worldstate import WorldSnapshots, check_endpoints

__all__ = [
    "DEFAULT_WALL_THICKNESS_M",
    "MAP_ELEMENT_ID",
    "MAX_ELEMENTS",
    "MAX_EVENTS",
    "MAX_ID_CHARS",
    "MAX_MOVERS",
    "MAX_POINTS",
    "MAX_SCENARIO_BYTES",
    "MAX_SCRIPT_TIME_S",
    "MAX_SIZE_M",
    "MAX_SWING_DEG",
    "MAX_TELEOP_ROWS",
    "MAX_TELEOP_SPEED",
    "MAX_TIME_S",
    "MAX_TRACK_LENGTH_M",
    "MIN_TIME_LIMIT_S",
    "MIN_TRACK_SEGMENT_M",
    "DoorAction",
    "Element",
    "Mover",
    "ScenarioSpec",
    "check_subgoals_used",
    "load_scenario",
    "parse_scenario",
    "resolve_scenario",
    "scenario_ref",
    "shipped_scenarios",
]

F64 = NDArray[np.float64]
DEFAULT_WALL_THICKNESS_M = 0.1
#: Bounds of a scenario's numbers (a value beyond them is a typo, and 1e300 would overflow the arithmetic):
#: positions (start, goal, geometry, waypoints, track points) as subgoals' [m], headings [rad], sizes
#: (radius, length, width, thickness, yield distance) [m], times (time limit, events, start_at, command
#: script) [s], |speed| of movers, teleop commands and the track driver [m/s, rad/s], track look-ahead /
#: tolerance [m], a door's swing [deg].
MAX_TIME_S = 1e6
MAX_SCRIPT_TIME_S = MAX_TIME_S
#: Shortest time limit [s]: a run shorter than the control period would have no step to take.
MIN_TIME_LIMIT_S = 0.1
MAX_SIZE_M = MAX_ABS_SUBGOAL_M
MAX_TELEOP_SPEED = 100.0
MAX_TRACK_LENGTH_M = 100.0
MAX_SWING_DEG = 360.0
#: Largest scenario file read, and most items of each list (a world beyond them is a mistake, and would
#: take gigabytes): elements (walls, boxes, circles, polygons, with those events add), movers, events,
#: points of one list (polygon vertices, a mover's waypoints, track points, subgoals), teleop script rows;
#: characters of an element's or a mover's id.
MAX_SCENARIO_BYTES = 1 << 20
MAX_ELEMENTS = 10_000
MAX_MOVERS = 1_000
MAX_EVENTS = 10_000
MAX_POINTS = 10_000
MAX_TELEOP_ROWS = 100_000
MAX_ID_CHARS = 100
#: Shortest segment of a teleop track [m] (a shorter one has no usable direction).
MIN_TRACK_SEGMENT_M = 1e-3
DEFAULT_YIELD_M = 0.3
_KINDS = ("walls", "boxes", "circles", "polygons")
_FILES = ("map", "sdf")
_EXPECT = ("reachable", "unreachable")
MAP_ELEMENT_ID = "map"
_PRESETS = tuple(PRESETS)
_NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9_.-]{{0,{MAX_ID_CHARS - 1}}}")
_Bounds = tuple[float, float]
_POS: _Bounds = (-MAX_ABS_SUBGOAL_M, MAX_ABS_SUBGOAL_M)
_HEADING: _Bounds = (-MAX_ABS_THETA_RAD, MAX_ABS_THETA_RAD)
_SIZE: _Bounds = (0.0, MAX_SIZE_M)
_TIME: _Bounds = (0.0, MAX_TIME_S)
_TIME_LIMIT: _Bounds = (MIN_TIME_LIMIT_S, MAX_TIME_S)
_SPEED: _Bounds = (0.0, MAX_TELEOP_SPEED)
_VELOCITY: _Bounds = (-MAX_TELEOP_SPEED, MAX_TELEOP_SPEED)
_TRACK: _Bounds = (0.0, MAX_TRACK_LENGTH_M)
_SWING: _Bounds = (-MAX_SWING_DEG, MAX_SWING_DEG)


@dataclass(frozen=True, slots=True)
class DoorAction:
    """A leaf moving to ``closed`` (1) or open (0) between ``t0_s`` and ``t1_s`` (``t1_s == t0_s``: a step
    at ``t0_s``)."""

    t0_s: float
    t1_s: float
    closed: float

    @property
    def instant(self) -> bool:
        """The leaf jumps to its new state at ``t0_s``."""
        return self.t1_s <= self.t0_s


@dataclass(frozen=True, slots=True, eq=False)
class Element:
    """One obstacle of the world.

    Attributes:
        id: the scenario's name for it (reported on contact).
        kind: "wall", "box", "circle", "polygon" or "map".
        vertices: outline ``(K, 2)`` (closed position for a door leaf); None for a circle and a map.
        circle: ``(cx, cy, r)`` for a circle.
        segment: ``(x1, y1, x2, y2, thickness)`` for a wall (a door leaf is drawn from it).
        appear_s, remove_s: present from ``appear_s`` (None: from the start) until ``remove_s`` (None: ever).
        door: leaf motions in time order (empty: a fixed element).
        swing_rad: 0 for a sliding leaf, else the open angle of a swinging one (about (x1, y1)).
        grid: a map's occupancy grid, and ``groups`` its occupied cells' boundary.
    """

    id: str
    kind: Literal["wall", "box", "circle", "polygon", "map"]
    vertices: F64 | None
    circle: tuple[float, float, float] | None = None
    segment: tuple[float, float, float, float, float] | None = None
    appear_s: float | None = None
    remove_s: float | None = None
    door: tuple[DoorAction, ...] = ()
    swing_rad: float = 0.0
    grid: OccupancyMap | None = None
    groups: EdgeGroups | None = None

    def present(self, t_s: float) -> bool:
        """Whether the element exists at ``t_s``."""
        after = self.appear_s is None or t_s >= self.appear_s
        return after and (self.remove_s is None or t_s < self.remove_s)

    def closed_fraction(self, t_s: float) -> float:
        """A door leaf's closure at ``t_s``: 0 open, 1 closed (1 for a fixed element). An instant action
        applies from its ``t0_s`` on (included)."""
        if not self.door:
            return 1.0
        f = 1.0 - self.door[0].closed
        for a in self.door:
            if t_s < a.t0_s or (t_s == a.t0_s and not a.instant):
                break
            if t_s >= a.t1_s or a.instant:
                f = a.closed
            else:
                f = f + (a.closed - f) * (t_s - a.t0_s) / (a.t1_s - a.t0_s)
                break
        return f

    def steps_done(self, t_s: float) -> int:
        """How many instant door actions have applied by ``t_s`` (a change of the world no speed bounds)."""
        return sum(1 for a in self.door if a.instant and t_s >= a.t0_s)

    def leaf_speed(self, t_s: float) -> float:
        """Upper bound of the speed of any point of a moving door leaf at ``t_s`` [m/s] (0 when still)."""
        if self.segment is None:
            return 0.0
        x0, y0, x1, y1, th = self.segment
        length = math.hypot(x1 - x0, y1 - y0)
        for a in self.door:
            if a.t0_s <= t_s < a.t1_s:
                rate = 1.0 / (a.t1_s - a.t0_s)
                reach = abs(self.swing_rad) * math.hypot(length, th / 2.0) if self.swing_rad else length
                return rate * reach
        return 0.0

    def outline_at(self, t_s: float, door_t_s: float | None = None) -> F64 | EdgeGroups | None:
        """The polygon at ``t_s`` (a map's edge groups; None when absent, a circle, or a fully open sliding
        leaf); a door leaf is drawn as it is at ``door_t_s`` (default ``t_s``; later when the person moving
        it waited)."""
        if self.groups is not None and self.present(t_s):
            return self.groups
        if self.vertices is None or not self.present(t_s):
            return None
        if not self.door or self.segment is None:
            return self.vertices
        f = self.closed_fraction(t_s if door_t_s is None else door_t_s)
        x0, y0, x1, y1, th = self.segment
        if self.swing_rad:
            a = dm.atan2(y1 - y0, x1 - x0) + (1.0 - f) * self.swing_rad
            length = math.hypot(x1 - x0, y1 - y0)
            return wall_vertices(x0, y0, x0 + length * dm.cos(a), y0 + length * dm.sin(a), th)
        if f <= 0.0:
            return None
        return wall_vertices(x0, y0, x0 + f * (x1 - x0), y0 + f * (y1 - y0), th)


@dataclass(frozen=True, slots=True, eq=False)
class Mover:
    """A circle walking along waypoints (see the module docstring)."""

    id: str
    radius_m: float
    speed_mps: float
    path: F64
    loop: bool = False
    start_at_s: float = 0.0
    yield_m: float = DEFAULT_YIELD_M
    _points: F64 = field(init=False, repr=False)
    _cum: F64 = field(init=False, repr=False)

    def __post_init__(self) -> None:
        p = np.vstack([self.path, self.path[:1]]) if self.loop else self.path
        object.__setattr__(self, "_points", p)
        object.__setattr__(self, "_cum", np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))]))

    def position(self, s_m: float) -> tuple[float, float]:
        """The point at arc length ``s_m`` along the path (wrapped when looping, clamped otherwise)."""
        p, cum = self._points, self._cum
        total = float(cum[-1])
        if total <= 0.0:
            return float(p[0, 0]), float(p[0, 1])
        s = s_m % total if self.loop else min(max(s_m, 0.0), total)
        k = min(int(np.searchsorted(cum, s, side="right")) - 1, len(cum) - 2)
        f = (s - cum[k]) / (cum[k + 1] - cum[k]) if cum[k + 1] > cum[k] else 0.0
        return float(p[k, 0] + f * (p[k + 1, 0] - p[k, 0])), float(p[k, 1] + f * (p[k + 1, 1] - p[k, 1]))


@dataclass(frozen=True, slots=True, eq=False)
class ScenarioSpec:
    """A parsed scenario file."""

    name: str
    description: str
    preset: str
    start: tuple[float, float, float]
    goal: tuple[float, float]
    time_limit_s: float
    elements: tuple[Element, ...]
    movers: tuple[Mover, ...]
    source: str
    mode: str | None = None
    local: str | None = None
    subgoals: tuple[Subgoal, ...] = ()
    teleop: TeleopSpec | None = None
    expect: str = "reachable"
    world_warnings: tuple[str, ...] = ()

    def element_ids(self) -> list[str]:
        """Names of the elements then of the movers, in index order (a contact names one of them)."""
        return [e.id for e in self.elements] + [m.id for m in self.movers]

    def check_endpoints(self, world: WorldSnapshots | Shapes, local: F64 | None, radius_m: float,
                        contact_m: float) -> None:
        """The start and goal checks of a run against ``world`` at t = 0
        (:func:`.worldstate.check_endpoints`)."""
        check_endpoints(self, world, local, radius_m, contact_m)


# --------------------------------------------------------------------------------------------- parsing


class _Err:
    def __init__(self, source: str) -> None:
        self.source = source

    def __call__(self, key: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: {key}: {message}")


def _label(k: Any) -> str:
    """A mapping key as a part of a key path: itself when a short plain string, else quoted and cut."""
    return k if isinstance(k, str) and len(k) <= MAX_ID_CHARS and k.isprintable() else brief(k)


def _ident(raw: Any, key: str, err: _Err) -> str:
    """An element's or a mover's id as text: a scalar of at most MAX_ID_CHARS characters (it names the
    object in errors and in result.json)."""
    if isinstance(raw, list | dict | set | tuple):
        raise err(key, f"expected a name, got {brief(raw)}")
    if isinstance(raw, int) and raw.bit_length() > 4 * MAX_ID_CHARS:  # ~120 digits; str() fails from 4,300
        raise err(key, f"a name of more than {MAX_ID_CHARS} characters, got {brief(raw)}")
    name = str(raw)
    if len(name) > MAX_ID_CHARS:
        raise err(key, f"a name of {len(name):,} characters (at most {MAX_ID_CHARS}), got {brief(name)}")
    return name


def _num(v: Any, key: str, err: _Err, bounds: _Bounds, *, positive: bool = False) -> float:
    """The one check of a scenario's numbers: ``v`` within ``bounds`` (and > 0 when ``positive``) through
    :func:`~gndreplay.io.userfile.check_number` (no bool, string, huge integer or non-finite value)."""
    x = check_number(v, f"{err.source}: {key}", *bounds)
    if positive and x <= 0.0:
        raise err(key, f"must be > 0, got {x:g}")
    return x


def _nums(v: Any, key: str, err: _Err, sizes: tuple[int, ...], bounds: tuple[_Bounds, ...]) -> list[float]:
    """A list of ``sizes`` numbers, item i within ``bounds[i]`` (the last repeats); an error names the
    item (``key[i]``)."""
    if not isinstance(v, list) or len(v) not in sizes:
        want = " or ".join(str(n) for n in sizes)
        raise err(key, f"expected a list of {want} numbers, got {brief(v)}")
    return [_num(x, f"{key}[{i}]", err, bounds[min(i, len(bounds) - 1)]) for i, x in enumerate(v)]


def _list(v: Any, key: str, err: _Err, what: str, least: int, most: int) -> list[Any]:
    """``v`` as a list of ``least`` to ``most`` ``what`` (the bound keeps a document's size in check)."""
    if not isinstance(v, list) or len(v) < least:
        at_least = f">= {least} " if least > 1 else ""
        raise err(key, f"expected a list of {at_least}{what}, got {brief(v)}")
    if len(v) > most:
        raise err(key, f"{len(v):,} {what}, more than the {most:,} a scenario may have")
    return v


def _choice(v: Any, key: str, err: _Err, choices: tuple[str, ...]) -> str:
    """``v`` when it is one of ``choices``, else an error listing them (and the closest)."""
    if v not in choices:
        raise err(key, f"expected one of {', '.join(choices)}, got {brief(v)}{did_you_mean(v, choices)}")
    return str(v)


def _table(v: Any, key: str, err: _Err, allowed: tuple[str, ...],
           required: tuple[str, ...] = ()) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise err(key, f"expected a mapping, got {brief(v)}")
    for k in v:
        if k not in allowed:
            where = f"{key}.{_label(k)}" if key else _label(k)
            raise err(where, f"unknown key (known: {', '.join(allowed)})")
    for k in required:
        if k not in v:
            raise err(f"{key}.{k}" if key else k, "missing")
    return v


def _elements(world: Any, key: str, err: _Err, appear_s: float | None, room: int) -> list[Element]:
    """The elements of a ``world`` mapping (or an event's ``add``); at most ``room`` of them."""
    table = _table(world, key, err, _KINDS)
    groups: list[tuple[str, dict[Any, Any]]] = []
    for kind in _KINDS:
        items = table.get(kind) or {}
        if not isinstance(items, dict):
            raise err(f"{key}.{kind}", f"expected a mapping of id: geometry, got {brief(items)}")
        groups.append((kind, items))
    if sum(len(items) for _, items in groups) > room:
        raise err(key, f"more than the {MAX_ELEMENTS:,} elements (walls, boxes, circles, polygons) a "
                       "scenario may have")
    out: list[Element] = []
    for kind, items in groups:
        for raw, geom in items.items():
            name = _ident(raw, f"{key}.{kind}", err)
            k = f"{key}.{kind}.{name}"
            if kind == "walls":
                g = _nums(geom, k, err, (4, 5), (_POS, _POS, _POS, _POS, _SIZE))
                th = g[4] if len(g) == 5 else DEFAULT_WALL_THICKNESS_M
                if math.hypot(g[2] - g[0], g[3] - g[1]) <= 0.0:
                    raise err(k, "the wall has zero length")
                out.append(Element(name, "wall", wall_vertices(g[0], g[1], g[2], g[3], th),
                                   segment=(g[0], g[1], g[2], g[3], th), appear_s=appear_s))
            elif kind == "boxes":
                g = _nums(geom, k, err, (5,), (_POS, _POS, _SIZE, _SIZE, _HEADING))
                if g[2] <= 0.0 or g[3] <= 0.0:
                    raise err(k, "length and width must be > 0")
                out.append(Element(name, "box", box_vertices(*g), appear_s=appear_s))
            elif kind == "circles":
                g = _nums(geom, k, err, (3,), (_POS, _POS, _SIZE))
                if g[2] <= 0.0:
                    raise err(k, f"radius must be > 0, got {g[2]}")
                out.append(Element(name, "circle", None, circle=(g[0], g[1], g[2]), appear_s=appear_s))
            else:
                rows = _list(geom, k, err, "[x, y] vertices", 3, MAX_POINTS)
                v = np.array([_nums(q, f"{k}[{i}]", err, (2,), (_POS,)) for i, q in enumerate(rows)],
                             dtype=np.float64)
                out.append(Element(name, "polygon", v, appear_s=appear_s))
    return out


def _movers(raw: Any, err: _Err) -> list[Mover]:
    allowed = ("id", "radius", "speed", "path", "loop", "start_at", "yield_m")
    out = []
    for i, m in enumerate(_list(raw, "movers", err, "movers", 0, MAX_MOVERS)):
        key = f"movers[{i}]"
        _table(m, key, err, allowed, ("id", "radius", "speed", "path"))
        path = _list(m["path"], f"{key}.path", err, "[x, y] waypoints", 1, MAX_POINTS)
        loop = m.get("loop", False)
        if not isinstance(loop, bool):
            raise err(f"{key}.loop", f"expected true or false, got {brief(loop)}")
        out.append(Mover(
            id=_ident(m["id"], f"{key}.id", err),
            radius_m=_num(m["radius"], f"{key}.radius", err, _SIZE, positive=True),
            speed_mps=_num(m["speed"], f"{key}.speed", err, _SPEED),
            path=np.array([_nums(p, f"{key}.path[{j}]", err, (2,), (_POS,)) for j, p in enumerate(path)],
                          dtype=np.float64),
            loop=loop,
            start_at_s=_num(m.get("start_at", 0.0), f"{key}.start_at", err, _TIME),
            yield_m=_num(m.get("yield_m", DEFAULT_YIELD_M), f"{key}.yield_m", err, _SIZE),
        ))
    return out


def _file_entry(raw: Any, key: str, err: _Err, base: Path, allowed: tuple[str, ...]
                ) -> tuple[Path, dict[str, Any]]:
    """A world file key: ``name`` or ``{file: name, ...options}``; the path relative to ``base``."""
    opts = _table(raw, key, err, allowed, ("file",)) if isinstance(raw, dict) else {"file": raw}
    name = opts["file"]
    if not isinstance(name, str) or not name or "\0" in name or len(name) > 4096:
        raise err(f"{key}.file" if isinstance(raw, dict) else key, f"expected a file name, got {brief(name)}")
    return base / name, opts


def _world_files(world: dict[str, Any], err: _Err, base: Path) -> tuple[list[Element], list[str]]:
    """The elements of the world's ``map`` and ``sdf`` files, and their warnings (one line per file)."""
    out: list[Element] = []
    notes: list[str] = []
    if "map" in world:
        path, opts = _file_entry(world["map"], "world.map", err, base,
                                 ("file", "unknown", "occupied_thresh", "free_thresh"))
        unknown = _choice(opts.get("unknown", "occupied"), "world.map.unknown", err, ("occupied", "free"))
        thresh, free = (_num(opts[k], f"world.map.{k}", err, (0.0, 1.0)) if k in opts else None
                        for k in ("occupied_thresh", "free_thresh"))
        try:
            grid = load_map(path, unknown="free" if unknown == "free" else "occupied", occupied_thresh=thresh,
                            free_thresh=free)
        except ConfigError as e:
            raise err("world.map", str(e)) from None
        out.append(Element(MAP_ELEMENT_ID, "map", None, grid=grid, groups=grid.edges()))
        notes += grid.warnings
    if "sdf" in world:
        path, _ = _file_entry(world["sdf"], "world.sdf", err, base, ("file",))
        try:
            sdf = read_sdf_world(path)
        except ConfigError as e:
            raise err("world.sdf", str(e)) from None
        for sh in sdf.shapes:
            out.append(Element(sh.id, "polygon", sh.vertices) if sh.circle is None
                       else Element(sh.id, "circle", None, circle=sh.circle))
        note = sdf.warning(str(path))
        if note is not None:
            notes.append(note)
    return out, notes


def parse_scenario(doc: Any, source: str, base: Path | None = None) -> ScenarioSpec:
    """Validate a loaded YAML document; ``source`` names it in errors, ``base`` is the folder world files
    are named from (default: ``source``'s folder)."""
    err = _Err(source)
    base = Path(source).parent if base is None else Path(base)
    top = ("name", "description", "preset", "start", "goal", "time_limit", "world", "events", "movers",
           "mode", "local", "subgoals", "teleop", "expect")
    d = _table(doc, "", err, top, ("name", "start", "time_limit", "world"))
    name = d["name"]
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise err("name", f"expected a plain name (letters, digits, _ . -, not starting with . or -; at most "
                          f"{MAX_ID_CHARS} characters), got {brief(name)}")
    description = d.get("description", "")
    if not isinstance(description, str):
        raise err("description", f"expected a string, got {brief(description)}")
    preset = _choice(d.get("preset", "wheelchair"), "preset", err, _PRESETS)
    sx, sy, st = _nums(d["start"], "start", err, (3,), (_POS, _POS, _HEADING))
    mode, local, subgoals, teleop = _navigation(d, err)
    if "goal" in d:
        gx, gy = _nums(d["goal"], "goal", err, (2,), (_POS,))
    elif subgoals:
        gx, gy = subgoals[-1].x, subgoals[-1].y
    elif teleop is not None and teleop.track is not None:
        gx, gy = float(teleop.track[-1, 0]), float(teleop.track[-1, 1])
    else:
        raise err("goal", "missing (only mode follow and a teleop track imply one)")
    time_limit = _num(d["time_limit"], "time_limit", err, _TIME_LIMIT)
    expect = _choice(d.get("expect", "reachable"), "expect", err, _EXPECT)
    world = _table(d["world"], "world", err, _KINDS + _FILES)
    files, world_warnings = _world_files(world, err, base)
    if len(files) > MAX_ELEMENTS:
        raise err("world", f"more than the {MAX_ELEMENTS:,} elements a scenario may have")
    elements = files + _elements({k: v for k, v in world.items() if k not in _FILES}, "world", err, None,
                                 MAX_ELEMENTS - len(files))
    by_id: dict[str, Element] = {}
    actions: dict[str, list[tuple[str, DoorAction, float | None]]] = {}
    removes: dict[str, float] = {}

    def register(e: Element, key: str) -> None:
        if e.id in by_id:
            raise err(key, f"duplicate id {brief(e.id)}")
        by_id[e.id] = e

    for i, e in enumerate(elements):
        register(e, ("world.map" if e.kind == "map" else "world.sdf") if i < len(files)
                 else f"world.{e.kind}s.{e.id}" if e.kind != "box" else f"world.boxes.{e.id}")
    for i, ev in enumerate(_list(d.get("events") or [], "events", err, "events", 0, MAX_EVENTS)):
        key = f"events[{i}]"
        _table(ev, key, err, ("at", "add", "remove", "close", "open", "over", "swing"), ("at",))
        at = _num(ev["at"], f"{key}.at", err, _TIME)
        what = [k for k in ("add", "remove", "close", "open") if k in ev]
        if len(what) != 1:
            raise err(key, "expected exactly one of add, remove, close, open")
        op = what[0]
        if op != "close" and op != "open" and ("over" in ev or "swing" in ev):
            raise err(f"{key}.over", "only close / open events take over and swing")
        if op == "add":
            for e in _elements(ev["add"], f"{key}.add", err, at, MAX_ELEMENTS - len(elements)):
                register(e, f"{key}.add.{e.id}")
                elements.append(e)
            continue
        target = ev[op]
        if not isinstance(target, str) or target not in by_id:
            raise err(f"{key}.{op}", f"unknown element {brief(target)}")
        if op == "remove":
            removes[target] = at
            continue
        if by_id[target].kind != "wall":
            raise err(f"{key}.{op}", f"only walls can open or close; {brief(target)} is a "
                                     f"{by_id[target].kind}")
        over = _num(ev.get("over", 0.0), f"{key}.over", err, _TIME)
        swing = math.radians(_num(ev["swing"], f"{key}.swing", err, _SWING)) if "swing" in ev else None
        actions.setdefault(target, []).append((key, DoorAction(at, at + over, 1.0 if op == "close" else 0.0),
                                               swing))
    movers = _movers(d.get("movers") or [], err)
    for m in movers:
        if m.id in by_id:
            raise err(f"movers.{m.id}", f"duplicate id {brief(m.id)}")
    final: list[Element] = []
    for e in elements:
        acts = sorted(actions.get(e.id, []), key=lambda a: a[1].t0_s)
        swings = {s for _, _, s in acts if s is not None}
        if len(swings) > 1:
            raise err(f"{acts[0][0]}.swing", f"door {brief(e.id)} has different swing angles")
        final.append(replace(e, remove_s=removes.get(e.id), door=tuple(a for _, a, _ in acts),
                             swing_rad=swings.pop() if swings else 0.0))
    return ScenarioSpec(name, description.strip(), preset, (sx, sy, st), (gx, gy), time_limit, tuple(final),
                        tuple(movers), source, mode, local, subgoals, teleop, expect, tuple(world_warnings))


def _navigation(d: dict[str, Any], err: _Err) -> tuple[str | None, str | None, tuple[Subgoal, ...],
                                                       TeleopSpec | None]:
    """The keys of the multi-loop architecture: mode, local, subgoals, teleop (see the module docstring)."""
    mode = d.get("mode")
    if mode is not None:
        mode = _choice(mode, "mode", err, NAV_MODES)
    local = d.get("local")
    if local is not None:
        local = _choice(local, "local", err, LOCAL_STRATEGIES)
    subgoals: tuple[Subgoal, ...] = ()
    if "subgoals" in d:
        if mode != "follow":
            raise err("subgoals", f"only with mode: follow (mode is {mode or 'gnd'})")
        subgoals = _subgoals(d["subgoals"], err)
    elif mode == "follow":
        raise err("subgoals", f"missing ({FOLLOW_NEEDS_SUBGOALS})")
    teleop = None
    if "teleop" in d:
        if mode != "teleop":
            raise err("teleop", f"only with mode: teleop (mode is {mode or 'gnd'})")
        teleop = _teleop(d["teleop"], err)
    elif mode == "teleop":
        raise err("teleop", "missing (mode teleop needs commands or a track)")
    return mode, local, subgoals, teleop


def check_subgoals_used(spec: ScenarioSpec, option: str = "--subgoals") -> None:
    """Refuse subgoals on a scenario whose mode does not follow them (the command line's ``option``
    overriding the scenario's mode or subgoals), as the scenario file itself does.

    Raises:
        ConfigError: one line naming the option, the scenario and its mode.
    """
    if spec.subgoals and spec.mode != "follow":
        raise ConfigError(f"{option}: only navigation mode follow uses subgoals (scenario {spec.name} has "
                          f"mode {spec.mode or 'gnd'})")


def _subgoals(raw: Any, err: _Err) -> tuple[Subgoal, ...]:
    """``[[x, y, theta, kind], ...]`` -> subgoals, validated as the rows of a subgoal file after the
    scenario's own checks: the list's length, each number through :func:`_num` (a number written as text
    is left to the row check, which reads it), the kind with the closest one."""
    from ..io.subgoals import subgoals_from_rows

    kinds = get_args(SubgoalKind)
    for i, row in enumerate(_list(raw, "subgoals", err, "[x, y, theta, kind] rows", 1, MAX_POINTS)):
        key = f"subgoals[{i}]"
        if not isinstance(row, list) or len(row) not in (3, 4):
            raise err(key, f"expected a list [x, y, theta] or [x, y, theta, kind], got {brief(row)}")
        for j, (v, bounds) in enumerate(zip(row, (_POS, _POS, _HEADING), strict=False)):
            if not (isinstance(v, str) and len(v) <= MAX_ID_CHARS):  # the row check reads "1.5" as 1.5
                _num(v, f"{key}[{j}]", err, bounds)
        if len(row) == 4 and row[3] not in kinds:
            raise err(key, f"kind must be one of {', '.join(kinds)}, got {brief(row[3])}"
                           f"{did_you_mean(row[3], kinds)}")
    return subgoals_from_rows(raw, f"{err.source}: subgoals")


def _teleop(raw: Any, err: _Err) -> TeleopSpec:
    t = _table(raw, "teleop", err, ("commands", "track"))
    if len(t) != 1:
        raise err("teleop", "expected exactly one of commands, track")
    if "commands" in t:
        rows = _list(t["commands"], "teleop.commands", err, "[t_s, v, w] rows", 2, MAX_TELEOP_ROWS)
        cmds = np.array([_nums(r, f"teleop.commands[{i}]", err, (3,), (_TIME, _VELOCITY))
                         for i, r in enumerate(rows)], dtype=np.float64)
        if np.any(np.diff(cmds[:, 0]) <= 0.0):
            raise err("teleop.commands", "times must be >= 0 and increasing")
        if cmds[-1, 1] != 0.0 or cmds[-1, 2] != 0.0:
            raise err(f"teleop.commands[{len(rows) - 1}]", "the last entry ends the script: [t_end, 0, 0]")
        return TeleopSpec(commands=cmds)
    tr = _table(t["track"], "teleop.track", err, ("points", "speed", "lookahead", "tolerance"),
                ("points", "speed"))
    pts = _list(tr["points"], "teleop.track.points", err, "[x, y] points", 2, MAX_POINTS)
    xy = np.array([_nums(q, f"teleop.track.points[{i}]", err, (2,), (_POS,)) for i, q in enumerate(pts)],
                  dtype=np.float64)
    if np.any(np.hypot(*np.diff(xy, axis=0).T) < MIN_TRACK_SEGMENT_M):
        raise err("teleop.track.points", f"two consecutive points are closer than {MIN_TRACK_SEGMENT_M:g} m")
    tol = tr.get("tolerance")
    return TeleopSpec(
        track=xy,
        speed_mps=_num(tr["speed"], "teleop.track.speed", err, _SPEED, positive=True),
        lookahead_m=_num(tr.get("lookahead", DEFAULT_LOOKAHEAD_M), "teleop.track.lookahead", err, _TRACK,
                         positive=True),
        tolerance_m=None if tol is None else _num(tol, "teleop.track.tolerance", err, _TRACK, positive=True),
    )


def load_scenario(path: Path) -> ScenarioSpec:
    """Read and validate a scenario file: a regular file of at most MAX_SCENARIO_BYTES, its YAML bounded
    (:func:`~gndreplay.io.userfile.load_yaml`)."""
    path = Path(path)
    return parse_scenario(load_yaml(path, "scenario file", MAX_SCENARIO_BYTES), str(path), path.parent)


def _shipped(name: str) -> ScenarioSpec:
    """The shipped scenario ``name`` (a file of the package, parsed with the same bounds as a user's)."""
    f = resources.files(__package__).joinpath("scenarios", f"{name}.yaml")
    where = f"scenarios/{name}.yaml"
    return parse_scenario(parse_yaml(f.read_text(encoding="utf-8"), where), where)


def _shipped_names() -> list[str]:
    files = resources.files(__package__).joinpath("scenarios").iterdir()
    return sorted(f.name.removesuffix(".yaml") for f in files if f.name.endswith(".yaml"))


def shipped_scenarios() -> dict[str, str]:
    """Name -> description of the scenarios shipped with gndreplay."""
    out = {}
    for name in _shipped_names():
        spec = _shipped(name)
        out[spec.name] = spec.description.split("\n")[0]
    return out


def resolve_scenario(name_or_path: str | Path) -> ScenarioSpec:
    """A shipped scenario by name, or a scenario file by path."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or _is_file(p):
        return load_scenario(p)
    name = str(name_or_path)
    if name not in _shipped_names():
        known = ", ".join(shipped_scenarios())
        raise ConfigError(f"{_label(name)}: no such scenario file or shipped scenario (shipped: {known})"
                          f"{did_you_mean(name, _shipped_names())}")
    return _shipped(name)


def scenario_ref(spec: ScenarioSpec) -> str | None:
    """What ``resolve_scenario`` reads ``spec`` again from: the absolute path of its file, or a shipped
    scenario's name; None for a scenario not read from a file."""
    if _is_file(Path(spec.source)):
        return str(Path(spec.source).resolve())
    shipped = Path(spec.source)
    if shipped.parent == Path("scenarios") and shipped.suffix == ".yaml" and shipped.stem in _shipped_names():
        return shipped.stem
    return None


def _is_file(p: Path) -> bool:
    """``p`` names an existing file (a name too long for the system is none)."""
    try:
        return p.is_file()
    except OSError:
        return False
