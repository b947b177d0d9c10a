"""Random obstacle fields as scenario files (``gndreplay scenario generate``), after the navigation
challenge's (BARN) worlds.

A field is a ``FIELD_CELLS`` x ``FIELD_CELLS`` grid of ``CELL_M`` cells (4.5 x 4.5 m) filled by a cellular
automaton: each cell starts occupied with the field's fill probability (drawn from ``FILL_RANGE``), then
``SMOOTHING`` rounds of the 4-5 rule (a cell is occupied when at least 5 of the 9 cells of its 3 x 3
neighbourhood are; outside the grid counts as free) grow clusters and clear lanes. Every occupied cell is a
cylinder of radius ``CYLINDER_R_M`` at its centre (neighbours overlap: clusters are solid). The robot starts
``START_GAP_M`` before the field on its centre line, heading along it, the goal is ``GOAL_AHEAD_M`` ahead;
walls along both sides of the corridor, and behind the start, keep the robot from going round. A field is
drawn again until the robot's inscribed circle connects the start to the goal on the challenge score's grid
(:func:`gndreplay.sim.score.optimal_path`), so every field is passable in principle.

Field ``i`` of seed ``s`` draws from ``numpy.random.SeedSequence([s, i])``: the same seed gives the same
files, byte for byte, and a field does not depend on how many were asked for. The files use the existing
scenario syntax (``world.walls`` and ``world.circles``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import ConfigError
from ..fsutil import check_output_dir, resolve_output_dir, staging_dir
from ..io.userfile import check_number
from ..robot import RobotConfig
from .geometry import Shapes, wall_vertices
from .scenario import check_seed
from .score import optimal_path

__all__ = [
    "CELL_M", "CYLINDER_R_M", "FIELD_CELLS", "FILL_RANGE", "GOAL_AHEAD_M", "MAX_FIELDS", "START_GAP_M",
    "Field", "draw_field", "field_yaml", "generate_fields",
]

CELL_M = 0.15
FIELD_CELLS = 30
CYLINDER_R_M = 0.15
FILL_RANGE = (0.38, 0.46)
SMOOTHING = 3
START_GAP_M = 1.5
GOAL_AHEAD_M = 10.0
TIME_LIMIT_S = 120.0
#: Largest number of fields in one call, and of draws for one passable field.
MAX_FIELDS = 10_000
MAX_DRAWS = 1_000
_WALL_M = 0.1


@dataclass(frozen=True, slots=True)
class Field:
    """One drawn field.

    Attributes:
        occupied: ``(FIELD_CELLS, FIELD_CELLS)`` cells holding a cylinder (rows across the corridor, from
            its right side; columns along it).
        fill: the fill probability it was drawn with.
        draws: how many fields were drawn until this passable one.
        optimal_m: the inscribed circle's shortest path from the start to the goal [m].
    """

    occupied: NDArray[np.bool_]
    fill: float
    draws: int
    optimal_m: float


def _automaton(rng: np.random.Generator, fill: float) -> NDArray[np.bool_]:
    """The cellular automaton of the module docstring."""
    grid = rng.random((FIELD_CELLS, FIELD_CELLS)) < fill
    for _ in range(SMOOTHING):
        pad = np.pad(grid.astype(np.int8), 1)
        count = np.zeros((FIELD_CELLS, FIELD_CELLS), dtype=np.int8)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                count += pad[1 + dr:1 + dr + FIELD_CELLS, 1 + dc:1 + dc + FIELD_CELLS]
        grid = count >= 5
    return grid


def _cylinders(occupied: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``(K, 3)`` cylinders (x, y, r) of the occupied cells, in row-major order."""
    rows, cols = np.nonzero(occupied)
    half = FIELD_CELLS * CELL_M / 2.0
    x = START_GAP_M + (cols + 0.5) * CELL_M
    y = -half + (rows + 0.5) * CELL_M
    return np.column_stack([np.round(x, 6), np.round(y, 6), np.full(len(rows), CYLINDER_R_M)])


def _walls() -> dict[str, tuple[float, float, float, float]]:
    """The corridor's side walls and the wall behind the start: (x1, y1, x2, y2)."""
    y = FIELD_CELLS * CELL_M / 2.0 + _WALL_M
    x0, x1 = -1.0, GOAL_AHEAD_M + 1.0
    return {"left": (x0, y, x1, y), "right": (x0, -y, x1, -y), "back": (x0, -y, x0, y)}


def _shapes(occupied: NDArray[np.bool_]) -> Shapes:
    walls = [wall_vertices(*w, _WALL_M) for w in _walls().values()]
    circles = [tuple(c) for c in _cylinders(occupied).tolist()]
    return Shapes.build(walls, list(range(len(walls))), circles,
                        list(range(len(walls), len(walls) + len(circles))))


def draw_field(seed: int, index: int, robot: RobotConfig) -> Field:
    """Field ``index`` of ``seed`` for ``robot``'s footprint (its inscribed circle must pass).

    Raises:
        ConfigError: no passable field in ``MAX_DRAWS`` draws (a robot too wide for any lane).
    """
    rng = np.random.default_rng(np.random.SeedSequence([check_seed(seed), index]))
    for draw in range(1, MAX_DRAWS + 1):
        fill = float(rng.uniform(*FILL_RANGE))
        occupied = _automaton(rng, fill)
        best = optimal_path(_shapes(occupied), (0.0, 0.0), (GOAL_AHEAD_M, 0.0), robot.inscribed_radius_m)
        if best.length_m is not None:
            return Field(occupied, fill, draw, best.length_m)
    raise ConfigError(f"no passable field for a robot of inscribed radius {robot.inscribed_radius_m:g} m in "
                      f"{MAX_DRAWS} draws (seed {seed}, field {index})")


def field_yaml(name: str, field: Field, preset_name: str, seed: int, index: int) -> str:
    """The scenario file of a field (the syntax of :mod:`.scenario_file`)."""
    lines = [
        f"name: {name}",
        f"description: random obstacle field {index} of seed {seed} (fill {field.fill:.3f}, "
        f"{int(field.occupied.sum())} cylinders, optimal path {field.optimal_m:.2f} m)",
        f"preset: {preset_name}",
        "start: [0.0, 0.0, 0.0]",
        f"goal: [{GOAL_AHEAD_M!r}, 0.0]",
        f"time_limit: {TIME_LIMIT_S!r}",
        "world:",
        "  walls:",
        *(f"    {k}: [{x1!r}, {y1!r}, {x2!r}, {y2!r}, {_WALL_M!r}]"
          for k, (x1, y1, x2, y2) in _walls().items()),
    ]
    cyl = _cylinders(field.occupied)
    if len(cyl):
        lines.append("  circles:")
        lines += [f"    c{k:03d}: [{x!r}, {y!r}, {r!r}]" for k, (x, y, r) in enumerate(cyl.tolist())]
    return "\n".join(lines) + "\n"


def generate_fields(out: Path, *, count: int, seed: int, robot: RobotConfig, preset_name: str,
                    overwrite: bool = False) -> tuple[Path, list[Path]]:
    """Write ``count`` fields (``field_000.yaml``, ...) into the output folder ``out`` (staged, marked as
    gndreplay's; an earlier such folder is replaced only with ``overwrite``, else the files go beside it,
    ``out-2``; a folder gndreplay did not write is refused).

    Returns:
        The folder written and its files.

    Raises:
        ConfigError: a count outside 1..MAX_FIELDS or a bad seed.
        OutputError: ``out`` cannot be written safely (``fsutil.check_output_dir``).
    """
    if isinstance(count, bool) or not isinstance(count, int):
        raise ConfigError(f"--count must be an integer from 1 to {MAX_FIELDS}, got {count!r}")
    check_number(count, "--count", 1, MAX_FIELDS)
    check_seed(seed, "--seed")
    check_output_dir(out, overwrite=overwrite)
    texts = {}
    for i in range(count):
        name = f"field_{seed}_{i:03d}"
        texts[f"field_{i:03d}.yaml"] = field_yaml(name, draw_field(seed, i, robot), preset_name, seed, i)
    target = resolve_output_dir(out, overwrite=overwrite)
    staging = staging_dir(target, overwrite=overwrite, base=out)
    with staging as tmp:
        for fname, text in texts.items():
            (tmp / fname).write_text(text, encoding="utf-8")
    return staging.out, [staging.out / f for f in texts]
