"""Map rasters for the figures, accumulated while a replay streams (``MapSink``) and stored as ``maps.npz``.

``gndreplay report RUN_DIR`` must redraw the figures without the log, so the run keeps what the map panels
need: two global hit-count rasters (every scan hit placed with the corrected pose and with the raw odometry
pose) and one snapshot of the robot-centred grid. Memory is bounded whatever the log's length and the area it
covers: tiles are created where hits land, up to ``MAX_RASTER_CELLS`` cells per raster, beyond which a
raster is re-binned at twice the cell side (``HitRaster``); and a fixed number of grid snapshots is kept.

maps.npz keys (all numpy arrays; scalars are 0-d):
    format_version: 1.
    cell_m: side of a raster cell [m], of both rasters: the configured side (5 cm), or a power-of-two
        multiple of it when the hits spread over more than ``MAX_RASTER_CELLS`` cells at that side.
    corrected_hits, raw_hits: (H, W) uint16 hit counts (saturated at 65535), ``[row, col]`` with row along
        world y; corrected_origin_xy, raw_origin_xy: (2,) world (x, y) [m] of the outer corner of cell (0, 0).
    scans: number of scans accumulated.
    grid_cells: (N, N) uint8 robot-centred grid (0 unknown, 1 free, 2 occupied; ``[row, col]``, row = y),
        grid_origin_xy (2,), grid_cell_m, grid_t_s (tick time [s]), grid_elapsed_s (from the first scan),
        grid_tick (tick index), grid_pose (3,) corrected robot pose, grid_goal_xy (2,), grid_path_xy (K, 2)
        planned path, grid_mode / grid_situation / grid_flags (str). Absent when the stack never ran.

Reading it back (``load_maps``) checks the header of every member first: its type and number of
dimensions, and that all of them together declare at most ``MAX_MAPS_BYTES``, so a damaged or hostile
file is refused before anything is allocated from it.
"""

from __future__ import annotations

import math
import os
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import one_line
from ..geometry import compose, transform_points
from ..pipeline.model import RobotCentredGrid
from ..pipeline.stack import TickResult
from ..types import BUDGET_FLAGS, Pose2D, Tick

__all__ = [
    "MAPS_FILE",
    "MAX_MAPS_BYTES",
    "MAX_RASTER_CELLS",
    "GridSnapshot",
    "HitRaster",
    "MapSink",
    "MapsData",
    "load_maps",
]

MAPS_FILE = "maps.npz"
FORMAT_VERSION = 1
MAX_MAPS_BYTES = 1 << 30
"""Most bytes the arrays of a maps.npz may declare together, and the largest file read (1 GB: the two
rasters of 5 cm cells over 1 km x 500 m)."""
MAX_RASTER_CELLS = 1 << 24
"""Most cells a hit raster spans (16.8 M: 32 MB of tiles, and at most that in maps.npz); a larger area is
accumulated at a coarser cell (``HitRaster``)."""
MAX_ABS_COORD_M = 1e9
"""Hits farther than this from the origin on either axis are ignored (they would not fit an int64 cell)."""
_U16_MAX = np.iinfo(np.uint16).max


class HitRaster:
    """A sparse, tiled hit-count raster over the plane whose memory is bounded whatever the area.

    Square tiles of ``tile_cells`` cells are created where points land, so memory follows the explored
    area, up to ``max_cells``: the tiles' bounding box never spans more cells than that. A point that would
    widen the box past it first re-bins the raster at twice the cell side (each coarse cell sums its four
    fine cells), as often as needed, so ``cell_m`` grows with the area covered while tile memory stays
    under ``2 * max_cells`` bytes and ``to_array`` under ``max_cells`` cells. The counts are those of a
    raster accumulated at the final cell side from the start, saturated at 65535.

    Cell (i, j) of the world lattice spans x in [j c, (j + 1) c), y in [i c, (i + 1) c) with c = cell_m.
    Points with a non-finite coordinate, or one beyond ``MAX_ABS_COORD_M``, are ignored.
    """

    def __init__(self, cell_m: float = 0.05, *, tile_cells: int = 256, batch_points: int = 1 << 16,
                 max_cells: int = MAX_RASTER_CELLS) -> None:
        if not (math.isfinite(cell_m) and cell_m > 0.0):
            raise ValueError(f"cell_m must be finite and > 0, got {cell_m!r}")
        if tile_cells < 1:
            raise ValueError(f"tile_cells must be >= 1, got {tile_cells!r}")
        if max_cells < 4 * tile_cells * tile_cells:  # any box shrinks to 2 x 2 tiles, never to one
            raise ValueError(f"max_cells must hold 2 x 2 tiles (4 * {tile_cells}**2), got {max_cells!r}")
        self.base_cell_m = float(cell_m)
        self.level = 0
        self.tile_cells = int(tile_cells)
        self.batch_points = int(batch_points)
        self.max_cells = int(max_cells)
        self._tiles: dict[tuple[int, int], NDArray[np.uint16]] = {}
        self._box: tuple[int, int, int, int] | None = None  # tile rows r0..r1, cols c0..c1 (inclusive)
        self._pending: list[NDArray[np.float64]] = []
        self._n_pending = 0

    @property
    def cell_m(self) -> float:
        """Side of a cell [m]: the base side times 2 ** ``level`` (exact: a power of two)."""
        return self.base_cell_m * 2.0**self.level

    @property
    def n_tiles(self) -> int:
        """Tiles allocated (after counting the pending points)."""
        self.flush()
        return len(self._tiles)

    def add(self, xy: NDArray[np.float64]) -> None:
        """Count the world points ``xy`` (M, 2) [m] into their cells.

        Points are buffered and counted in batches of ``batch_points`` (per-call numpy overhead dominates
        for a single scan); ``flush``, ``to_array``, ``n_tiles`` and ``coarsen_to`` count the pending ones
        first."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        self._pending.append(p)
        self._n_pending += p.shape[0]
        if self._n_pending >= self.batch_points:
            self.flush()

    def flush(self) -> None:
        """Count the pending points (which may coarsen the raster)."""
        if not self._pending:
            return
        p = np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0]
        self._pending, self._n_pending = [], 0
        p = p[(np.abs(p) <= MAX_ABS_COORD_M).all(axis=1)]  # also drops nan
        if p.shape[0] == 0:
            return
        while True:
            c = self.cell_m
            rows = np.floor(p[:, 1] / c).astype(np.int64)
            cols = np.floor(p[:, 0] / c).astype(np.int64)
            t = self.tile_cells
            box = (int(rows.min()) // t, int(rows.max()) // t, int(cols.min()) // t, int(cols.max()) // t)
            if self._box is not None:
                box = _union(box, self._box)
            if self._box_cells(box) <= self.max_cells:
                break
            self._coarsen()
        self._box = box
        self._accumulate(rows, cols, None)

    def _box_cells(self, box: tuple[int, int, int, int]) -> int:
        r0, r1, c0, c1 = box
        return (r1 - r0 + 1) * (c1 - c0 + 1) * self.tile_cells**2

    def _accumulate(self, rows: NDArray[np.int64], cols: NDArray[np.int64],
                    weights: NDArray[np.uint16] | None) -> None:
        """Add ``weights`` (None: 1 each) to the cells (rows, cols) of the current level, saturating."""
        t = self.tile_cells
        tr, lr = np.divmod(rows, t)
        tc, lc = np.divmod(cols, t)
        local = lr * t + lc
        r0, c0 = int(tr.min()), int(tc.min())
        span = int(tc.max()) - c0 + 1
        key = (tr - r0) * span + (tc - c0)  # one int64 per tile, relative to the points' own box
        order = np.argsort(key, kind="stable")
        k_sorted = key[order]
        cuts = np.flatnonzero(k_sorted[1:] != k_sorted[:-1]) + 1
        for a, b in zip(np.r_[0, cuts].tolist(), np.r_[cuts, key.size].tolist(), strict=True):
            k = int(k_sorted[a])
            ij = (r0 + k // span, c0 + k % span)
            idx = order[a:b]
            counts = np.bincount(local[idx], weights=None if weights is None else weights[idx],
                                 minlength=t * t)
            tile = self._tiles.get(ij)
            if tile is None:
                tile = self._tiles[ij] = np.zeros((t, t), dtype=np.uint16)
            flat = tile.reshape(-1)  # a view: tiles are C-contiguous
            total = flat + counts  # int64 or float64 (weighted): exact far beyond 65535
            flat[:] = np.minimum(total, _U16_MAX)

    def _coarsen(self) -> None:
        """Re-bin every tile at twice the cell side: cell (i, j) goes to (i // 2, j // 2), counts summed."""
        t = self.tile_cells
        old, self._tiles = self._tiles, {}
        self.level += 1
        while old:
            (i, j), tile = old.popitem()  # released as it is re-binned
            nz = np.flatnonzero(tile)
            if nz.size:
                lr, lc = np.divmod(nz, t)
                self._accumulate((i * t + lr) // 2, (j * t + lc) // 2, tile.reshape(-1)[nz])
        if self._tiles:
            keys = np.array(list(self._tiles), dtype=np.int64)
            lo, hi = keys.min(axis=0), keys.max(axis=0)
            self._box = (int(lo[0]), int(hi[0]), int(lo[1]), int(hi[1]))
        else:
            self._box = None

    def coarsen_to(self, level: int) -> None:
        """Re-bin until the cell side is ``base_cell_m * 2 ** level`` (no change at or past it)."""
        self.flush()
        while self.level < level:
            self._coarsen()

    def to_array(self) -> tuple[NDArray[np.uint16], tuple[float, float]]:
        """The dense raster (saturated at 65535) cropped to the cells that hold hits, and the world (x, y)
        [m] of the outer corner of its cell (0, 0); at most ``max_cells`` cells, built without a larger
        intermediate. An empty raster is (1, 1) zeros at the origin."""
        self.flush()
        t = self.tile_cells
        row_lo = col_lo = np.iinfo(np.int64).max
        row_hi = col_hi = np.iinfo(np.int64).min
        for (i, j), tile in self._tiles.items():
            rows = np.flatnonzero(tile.any(axis=1))
            if rows.size == 0:
                continue
            cols = np.flatnonzero(tile.any(axis=0))
            row_lo, row_hi = min(row_lo, i * t + int(rows[0])), max(row_hi, i * t + int(rows[-1]))
            col_lo, col_hi = min(col_lo, j * t + int(cols[0])), max(col_hi, j * t + int(cols[-1]))
        if row_hi < row_lo:
            return np.zeros((1, 1), dtype=np.uint16), (0.0, 0.0)
        out = np.zeros((row_hi - row_lo + 1, col_hi - col_lo + 1), dtype=np.uint16)
        for (i, j), tile in self._tiles.items():
            a0, a1 = max(i * t, row_lo), min((i + 1) * t, row_hi + 1)
            b0, b1 = max(j * t, col_lo), min((j + 1) * t, col_hi + 1)
            if a0 < a1 and b0 < b1:
                out[a0 - row_lo : a1 - row_lo, b0 - col_lo : b1 - col_lo] = \
                    tile[a0 - i * t : a1 - i * t, b0 - j * t : b1 - j * t]
        c = self.cell_m
        return out, (float(col_lo * c), float(row_lo * c))


def _union(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    return (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))


@dataclass(frozen=True, slots=True, eq=False)
class GridSnapshot:
    """The robot-centred grid at one tick, with what the stack decided there.

    Attributes:
        cells: (N, N) uint8 UNKNOWN / FREE / OCCUPIED, ``[row, col]`` with row along world y.
        origin_xy: world (x, y) [m] of the outer corner of cell (0, 0).
        cell_m: cell side [m].
        t_s: tick time [s]; elapsed_s: time since the first scan [s]; tick: tick index.
        pose: (3,) corrected robot pose; goal_xy: (2,); path_xy: (K, 2) planned path (corrected frame).
        mode, situation, flags: as in commands.csv.
    """

    cells: NDArray[np.uint8]
    origin_xy: tuple[float, float]
    cell_m: float
    t_s: float
    elapsed_s: float
    tick: int
    pose: NDArray[np.float64]
    goal_xy: NDArray[np.float64]
    path_xy: NDArray[np.float64]
    mode: str
    situation: str
    flags: str

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) [m] for ``imshow(origin="lower")``."""
        return _extent(self.cells.shape, self.origin_xy, self.cell_m)


def _extent(
    shape: tuple[int, ...], origin_xy: tuple[float, float], cell_m: float
) -> tuple[float, float, float, float]:
    x0, y0 = origin_xy
    return (x0, x0 + shape[1] * cell_m, y0, y0 + shape[0] * cell_m)


def _snapshot(tick: Tick, result: TickResult, grid: RobotCentredGrid, elapsed_s: float) -> GridSnapshot:
    path = np.asarray(result.path_xy, dtype=np.float64).reshape(-1, 2)
    return GridSnapshot(
        cells=np.array(grid.cells, dtype=np.uint8, copy=True),
        origin_xy=(float(grid.origin_xy[0]), float(grid.origin_xy[1])),
        cell_m=float(grid.params.cell_m),
        t_s=result.t_ns / 1e9,
        elapsed_s=elapsed_s,
        tick=int(tick.index),
        pose=result.pose_corrected.as_array(),
        goal_xy=np.asarray(result.goal, dtype=np.float64).reshape(2),
        path_xy=path.copy(),
        mode=str(result.mode.value),
        situation=str(result.situation.name),
        flags="|".join((result.flags & ~BUDGET_FLAGS).names()),  # no wall-clock facts in the maps
    )


class MapSink:
    """A ``RunSink`` that accumulates the figure maps and writes ``maps.npz``.

    Every scan's hits are placed at laser pose = robot pose ∘ ``scan.sensor_pose``, once with the corrected
    pose (the model map) and once with the raw odometry (the smeared map).

    The grid snapshot: with ``snapshot_at_s`` set, the first tick the stack ran at or after that much log
    time from the first scan (the last tick if the run is shorter). With None (default), the tick nearest
    the middle of the run: the length of the run is unknown while streaming, so the sink keeps at most
    ``max_snapshots`` candidate snapshots on a regular time lattice (dropping those before the current
    half-way point, and thinning the lattice by 2 when full) and picks the nearest at ``finish``; the
    chosen tick is within about duration / max_snapshots of the middle.

    Args:
        cell_m: raster cell side [m] (coarser where the hits spread over more than ``max_cells`` cells).
        max_range_m: ignore hits farther than this from the laser (None: all hits).
        snapshot_at_s: see above.
        max_snapshots: bound of the candidate buffer (>= 2).
        max_cells: most cells each raster spans (``HitRaster``).
    """

    def __init__(
        self,
        *,
        cell_m: float = 0.05,
        max_range_m: float | None = None,
        snapshot_at_s: float | None = None,
        max_snapshots: int = 16,
        max_cells: int = MAX_RASTER_CELLS,
    ) -> None:
        if max_snapshots < 2:
            raise ValueError(f"max_snapshots must be >= 2, got {max_snapshots!r}")
        self.corrected = HitRaster(cell_m, max_cells=max_cells)
        self.raw = HitRaster(cell_m, max_cells=max_cells)
        self.max_range_m = max_range_m
        self.snapshot_at_s = snapshot_at_s
        self.max_snapshots = max_snapshots
        self.scans = 0
        self._t0_ns: int | None = None
        self._step_s = 1.0
        self._candidates: list[tuple[int, GridSnapshot]] = []  # (lattice slot, snapshot)
        self._fixed: GridSnapshot | None = None
        self._latest: tuple[Tick, TickResult, RobotCentredGrid, float] | None = None

    # ---- RunSink ------------------------------------------------------------------------------------

    def add_scan(self, tick: Tick, pose_corrected: Pose2D) -> None:
        """Place the scan's hits with the corrected pose and with the raw odometry."""
        if self._t0_ns is None:
            self._t0_ns = tick.t_ns
        self.scans += 1
        scan = tick.scan
        pts = scan.points()
        if self.max_range_m is not None and pts.shape[0]:
            pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= self.max_range_m]
        if pts.shape[0] == 0:
            return
        sensor = scan.sensor_pose.as_array()
        self.corrected.add(transform_points(compose(pose_corrected.as_array(), sensor), pts))
        self.raw.add(transform_points(compose(tick.odom.as_array(), sensor), pts))

    def add_result(self, tick: Tick, result: TickResult, grid: RobotCentredGrid) -> None:
        """Keep the grid snapshot candidates (see the class docstring)."""
        if self._t0_ns is None:
            self._t0_ns = tick.t_ns
        elapsed = (result.t_ns - self._t0_ns) / 1e9
        # the grid is not touched after the last tick, so a reference is enough for the latest state
        self._latest = (tick, result, grid, elapsed)
        if self.snapshot_at_s is not None:
            if self._fixed is None and elapsed >= self.snapshot_at_s:
                self._fixed = _snapshot(tick, result, grid, elapsed)
            return
        slot = math.floor(elapsed / self._step_s)
        if not self._candidates or slot > self._candidates[-1][0]:
            self._candidates.append((slot, _snapshot(tick, result, grid, elapsed)))
            self._prune(elapsed)

    def _prune(self, elapsed: float) -> None:
        half = 0.5 * elapsed
        before = [k for k, (_, s) in enumerate(self._candidates) if s.elapsed_s <= half]
        if len(before) > 1:  # only the newest candidate at or before the half-way point can still win
            del self._candidates[: before[-1]]
        while len(self._candidates) > self.max_snapshots:
            self._step_s *= 2.0
            kept: list[tuple[int, GridSnapshot]] = []
            for _, snap in self._candidates:
                slot = math.floor(snap.elapsed_s / self._step_s)
                if not kept or slot > kept[-1][0]:
                    kept.append((slot, snap))
            self._candidates = kept

    @property
    def candidates(self) -> int:
        """Grid snapshots held right now (at most ``max_snapshots``)."""
        return len(self._candidates) + (self._fixed is not None)

    def snapshot(self) -> GridSnapshot | None:
        """The chosen grid snapshot (None when the stack never ran)."""
        if self._latest is None:
            return None
        if self.snapshot_at_s is not None:
            return self._fixed if self._fixed is not None else _snapshot(*self._latest)
        half = 0.5 * self._latest[3]
        best = min((s for _, s in self._candidates), key=lambda s: abs(s.elapsed_s - half))
        if abs(self._latest[3] - half) < abs(best.elapsed_s - half):  # a run of one tick
            return _snapshot(*self._latest)
        return best

    def finish(self, run_dir: Path) -> None:
        """Write ``maps.npz`` into ``run_dir``."""
        save_maps(Path(run_dir) / MAPS_FILE, self.corrected, self.raw, self.snapshot(), scans=self.scans)

    def abort(self) -> None:
        """RunSink hook for a failed replay: nothing to release (the rasters are in memory)."""


def save_maps(
    path: Path, corrected: HitRaster, raw: HitRaster, snap: GridSnapshot | None, *, scans: int
) -> None:
    """Write the rasters and the snapshot as a compressed npz (keys in the module docstring). The two
    rasters share one cell side: the finer one is re-binned to the coarser one's first."""
    if corrected.base_cell_m != raw.base_cell_m:
        raise ValueError(f"the rasters' cell sides differ: {corrected.base_cell_m} and {raw.base_cell_m} m")
    corrected.flush()
    raw.flush()
    level = max(corrected.level, raw.level)
    corrected.coarsen_to(level)
    raw.coarsen_to(level)
    cor, cor_o = corrected.to_array()
    raw_a, raw_o = raw.to_array()
    arrays: dict[str, Any] = {
        "format_version": np.int64(FORMAT_VERSION),
        "cell_m": np.float64(corrected.cell_m),
        "scans": np.int64(scans),
        "corrected_hits": cor,
        "corrected_origin_xy": np.asarray(cor_o, dtype=np.float64),
        "raw_hits": raw_a,
        "raw_origin_xy": np.asarray(raw_o, dtype=np.float64),
    }
    if snap is not None:
        arrays |= {
            "grid_cells": snap.cells,
            "grid_origin_xy": np.asarray(snap.origin_xy, dtype=np.float64),
            "grid_cell_m": np.float64(snap.cell_m),
            "grid_t_s": np.float64(snap.t_s),
            "grid_elapsed_s": np.float64(snap.elapsed_s),
            "grid_tick": np.int64(snap.tick),
            "grid_pose": snap.pose,
            "grid_goal_xy": snap.goal_xy,
            "grid_path_xy": snap.path_xy,
            "grid_mode": np.str_(snap.mode),
            "grid_situation": np.str_(snap.situation),
            "grid_flags": np.str_(snap.flags),
        }
    with open(path, "wb") as f:
        np.savez_compressed(f, **arrays)


@dataclass(frozen=True, slots=True, eq=False)
class MapsData:
    """maps.npz read back: the two hit rasters (uint16 counts) and the optional grid snapshot."""

    cell_m: float
    scans: int
    corrected_hits: NDArray[np.uint16]
    corrected_origin_xy: tuple[float, float]
    raw_hits: NDArray[np.uint16]
    raw_origin_xy: tuple[float, float]
    snapshot: GridSnapshot | None

    @property
    def corrected_extent(self) -> tuple[float, float, float, float]:
        return _extent(self.corrected_hits.shape, self.corrected_origin_xy, self.cell_m)

    @property
    def raw_extent(self) -> tuple[float, float, float, float]:
        return _extent(self.raw_hits.shape, self.raw_origin_xy, self.cell_m)


def _xy(a: NDArray[np.float64]) -> tuple[float, float]:
    return float(a[0]), float(a[1])


#: member -> (accepted dtype kinds, shape with None for any length), as ``save_maps`` writes them.
_MEMBERS: Mapping[str, tuple[str, tuple[int | None, ...]]] = {
    "format_version": ("iu", ()),
    "cell_m": ("f", ()),
    "scans": ("iu", ()),
    "corrected_hits": ("u", (None, None)),
    "corrected_origin_xy": ("f", (2,)),
    "raw_hits": ("u", (None, None)),
    "raw_origin_xy": ("f", (2,)),
    "grid_cells": ("u", (None, None)),
    "grid_origin_xy": ("f", (2,)),
    "grid_cell_m": ("f", ()),
    "grid_t_s": ("f", ()),
    "grid_elapsed_s": ("f", ()),
    "grid_tick": ("iu", ()),
    "grid_pose": ("f", (3,)),
    "grid_goal_xy": ("f", (2,)),
    "grid_path_xy": ("f", (None, 2)),
    "grid_mode": ("U", ()),
    "grid_situation": ("U", ()),
    "grid_flags": ("U", ()),
}
_RASTER_MEMBERS = ("format_version", "cell_m", "scans", "corrected_hits", "corrected_origin_xy", "raw_hits",
                   "raw_origin_xy")
_GRID_MEMBERS = tuple(name for name in _MEMBERS if name.startswith("grid_"))
_KIND_WORDS = {"iu": "integers", "u": "unsigned integers", "f": "floats", "U": "text"}
#: What reading a damaged archive or .npy member raises (zipfile, zlib, numpy's header parser).
_MALFORMED: tuple[type[Exception], ...] = (
    zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, KeyError, TypeError, OverflowError,
    NotImplementedError, RuntimeError,
)


def _why(err: BaseException) -> str:
    text = one_line(err, 200)
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def _npy_header(f: IO[bytes]) -> tuple[tuple[int, ...], np.dtype[Any]]:
    """(shape, dtype) declared by the header of a .npy stream, without reading its data."""
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(f)
    elif version == (2, 0):
        shape, _, dtype = np.lib.format.read_array_header_2_0(f)
    else:
        raise ValueError(f".npy format version {version[0]}.{version[1]} is not one numpy writes for maps")
    return shape, dtype


def _check_member(name: str, shape: tuple[int, ...], dtype: np.dtype[Any]) -> int:
    """The bytes member ``name`` declares, if its dtype and shape are the ones ``save_maps`` writes.

    Raises:
        ValueError: another type or shape (named).
    """
    kinds, want = _MEMBERS[name]
    if dtype.kind not in kinds or len(shape) != len(want) or any(
        n < 0 or (w is not None and n != w) for n, w in zip(shape, want, strict=True)
    ):
        dims = ", ".join("N" if w is None else str(w) for w in want)
        expected = f"shape ({dims}{',' if len(want) == 1 else ''})" if want else "a scalar"
        raise ValueError(f"member {name!r}: a {dtype} array of shape {shape}, expected {expected} of "
                         f"{_KIND_WORDS[kinds]}")
    return math.prod(shape) * dtype.itemsize


def _check_archive(path: Path) -> set[str]:
    """The known members of maps.npz at ``path`` after checking every header and the declared total.

    Raises:
        ValueError: a file larger than MAX_MAPS_BYTES, not a zip of .npy members, a member of the wrong
            type or shape, more than MAX_MAPS_BYTES declared, or a required member missing (each named).
    """
    try:
        size = os.stat(path).st_size
    except OSError as err:
        raise ValueError(f"cannot read it: {_why(err)}") from err
    if size > MAX_MAPS_BYTES:
        raise ValueError(f"{size} bytes, more than the {MAX_MAPS_BYTES >> 20} MB maps may have")
    try:
        zf = zipfile.ZipFile(path)
    except _MALFORMED as err:
        raise ValueError(f"not a maps archive (a zip of .npy arrays): {_why(err)}") from err
    declared, present = 0, set()
    with zf:
        for info in zf.infolist():
            name = info.filename.removesuffix(".npy")
            if name not in _MEMBERS:
                continue
            try:
                with zf.open(info) as f:
                    shape, dtype = _npy_header(f)
            except _MALFORMED as err:
                raise ValueError(f"member {name!r}: {_why(err)}") from err
            declared += _check_member(name, shape, dtype)
            if declared > MAX_MAPS_BYTES:
                raise ValueError(f"member {name!r}: a {dtype} array of shape {shape} brings the arrays past "
                                 f"the {MAX_MAPS_BYTES >> 20} MB maps may declare")
            present.add(name)
    required = _RASTER_MEMBERS + (_GRID_MEMBERS if "grid_cells" in present else ())
    missing = [m for m in required if m not in present]
    if missing:
        raise ValueError(f"member {missing[0]!r} missing")
    return present


def _cell(z: Any, name: str) -> float:
    """A cell side [m]: finite and positive (the figures' extents are drawn from it)."""
    x = float(_member(z, name))
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"member {name!r}: a cell side must be finite and > 0, got {x!r}")
    return x


def _origin(z: Any, name: str) -> tuple[float, float]:
    """A raster origin [m]: two finite numbers."""
    xy = _xy(_member(z, name))
    if not all(map(math.isfinite, xy)):
        raise ValueError(f"member {name!r}: an origin must be finite, got {xy!r}")
    return xy


def _member(z: Any, name: str) -> Any:
    """Member ``name`` of the open archive; ValueError naming it when its data is damaged."""
    try:
        return z[name]
    except _MALFORMED as err:
        raise ValueError(f"member {name!r}: {_why(err)}") from err


def load_maps(path: Path) -> MapsData:
    """Read ``maps.npz`` (see the module docstring).

    Raises:
        ValueError: not a maps archive, unknown format version, a member missing, of the wrong type or shape,
            too large or damaged; one line naming the member (the caller names the file).
    """
    present = _check_archive(path)
    try:
        z = np.load(path, allow_pickle=False)
    except _MALFORMED as err:
        raise ValueError(f"not a maps archive (a zip of .npy arrays): {_why(err)}") from err
    with z:
        version = int(_member(z, "format_version"))
        if version != FORMAT_VERSION:
            raise ValueError(f"maps format_version {version} is not supported (expected {FORMAT_VERSION})")
        snap = None
        if "grid_cells" in present:
            snap = GridSnapshot(
                cells=_member(z, "grid_cells"),
                origin_xy=_origin(z, "grid_origin_xy"),
                cell_m=_cell(z, "grid_cell_m"),
                t_s=float(_member(z, "grid_t_s")),
                elapsed_s=float(_member(z, "grid_elapsed_s")),
                tick=int(_member(z, "grid_tick")),
                pose=_member(z, "grid_pose"),
                goal_xy=_member(z, "grid_goal_xy"),
                path_xy=_member(z, "grid_path_xy").reshape(-1, 2),
                mode=str(_member(z, "grid_mode")),
                situation=str(_member(z, "grid_situation")),
                flags=str(_member(z, "grid_flags")),
            )
        return MapsData(
            cell_m=_cell(z, "cell_m"),
            scans=int(_member(z, "scans")),
            corrected_hits=_member(z, "corrected_hits"),
            corrected_origin_xy=_origin(z, "corrected_origin_xy"),
            raw_hits=_member(z, "raw_hits"),
            raw_origin_xy=_origin(z, "raw_origin_xy"),
            snapshot=snap,
        )
