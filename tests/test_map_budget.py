"""The hit rasters' memory bound: re-binning at a coarser cell when the hits spread over more cells than the
budget, with the counts of a raster accumulated at that cell from the start."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_report import write_run

from gndreplay.report import MapSink, build_report, load_maps
from gndreplay.report.maps import HitRaster, save_maps
from gndreplay.report.mcap_export import MAP_STEP, hits_to_occupancy

T = 4  # tile side [cells] of the small rasters below
BUDGET = 4 * 4 * T * T  # 4 x 4 tiles


def lawnmower_points(side_m: float, rng: np.random.Generator, n: int = 400) -> list[np.ndarray]:
    """Batches of hits along parallel walls over a square of ``side_m``, swept column by column (the area
    grows batch after batch, as a long drive does), with points on exact cell edges and a few nan."""
    batches = []
    for x in np.arange(0.0, side_m, side_m / 8):
        pts = np.column_stack([np.full(n, x) + rng.normal(0.0, 0.3, n),
                               rng.uniform(-side_m / 2, side_m / 2, n)])
        pts[:20] = np.round(pts[:20] * 10.0) / 10.0  # on the lattice of 0.1 m (and its multiples)
        pts[20:22] = np.nan
        batches.append(pts)
    return batches


def test_raster_stays_within_its_budget_and_rebins_exactly() -> None:
    rng = np.random.default_rng(5)
    r = HitRaster(0.1, tile_cells=T, batch_points=256, max_cells=BUDGET)
    batches = lawnmower_points(40.0, rng)
    for pts in batches:
        r.add(pts)
        r.flush()
        assert r.n_tiles * T * T <= BUDGET
    a, origin = r.to_array()
    assert a.size <= BUDGET
    assert r.level >= 4 and r.cell_m == 0.1 * 2**r.level  # 40 m in 16 cells per side: >= 1.6 m cells
    # the same points counted at the final cell from the start, without a budget
    direct = HitRaster(r.cell_m, tile_cells=T, max_cells=1 << 30)
    for pts in batches:
        direct.add(pts)
    b, origin_b = direct.to_array()
    assert origin == origin_b and a.dtype == b.dtype == np.uint16
    np.testing.assert_array_equal(a, b)
    assert int(a.sum()) == sum(int(np.isfinite(p).all(axis=1).sum()) for p in batches)  # every hit kept


def test_raster_under_budget_is_unchanged() -> None:
    rng = np.random.default_rng(6)
    pts = rng.uniform(-3.0, 3.0, size=(2000, 2))
    small = HitRaster(0.1, tile_cells=T, max_cells=BUDGET * 16)  # 6 m in 0.4 m tiles: 16 x 16 tiles fit
    big = HitRaster(0.1, tile_cells=T, max_cells=1 << 30)
    small.add(pts)
    big.add(pts)
    a, oa = small.to_array()
    b, ob = big.to_array()
    assert small.level == 0 and oa == ob
    np.testing.assert_array_equal(a, b)


def test_rebinning_saturates_summed_counts() -> None:
    r = HitRaster(1.0, tile_cells=T, max_cells=BUDGET)
    r.add(np.tile([[0.5, 0.5]], (70_000, 1)))  # one cell past the uint16 range
    r.add(np.tile([[1.5, 0.5]], (40_000, 1)))  # its neighbour, merged with it at the next level
    r.add(np.tile([[2.5, 0.5]], (3, 1)))
    a, _ = r.to_array()
    assert a.tolist() == [[65535, 40000, 3]]
    r.add(np.array([[1000.0, 0.5]]))  # 1 km away: 1 m cells would span 250 tiles, 16 m cells span 16
    r.flush()
    assert r.level == 4
    a, origin = r.to_array()
    assert origin == (0.0, 0.0) and a.shape == (1, 63)
    assert a[0, 0] == 65535 and a[0, -1] == 1 and a.sum() == 65536


def test_raster_ignores_points_too_far_to_count() -> None:
    r = HitRaster(0.1, tile_cells=T, max_cells=BUDGET)
    r.add(np.array([[1e10, 0.0], [0.0, -1e300], [np.inf, 0.0], [0.05, 0.05]]))
    a, origin = r.to_array()
    assert r.level == 0 and a.tolist() == [[1]] and origin == (0.0, 0.0)


def test_raster_budget_must_hold_two_by_two_tiles() -> None:
    with pytest.raises(ValueError, match="2 x 2 tiles"):
        HitRaster(0.1, tile_cells=T, max_cells=4 * T * T - 1)


def test_save_maps_puts_both_rasters_on_one_cell(tmp_path: Path) -> None:
    cor = HitRaster(0.1, tile_cells=T, max_cells=BUDGET)
    raw = HitRaster(0.1, tile_cells=T, max_cells=BUDGET)
    cor.add(np.array([[0.05, 0.05], [1.05, 0.05]]))
    raw.add(np.array([[0.05, 0.05], [100.0, 0.05]]))  # the raw odometry drifted: a coarser raster
    save_maps(tmp_path / "maps.npz", cor, raw, None, scans=1)
    maps = load_maps(tmp_path / "maps.npz")
    assert maps.cell_m == raw.cell_m == cor.cell_m > 0.1
    assert int(maps.corrected_hits.sum()) == int(maps.raw_hits.sum()) == 2
    x0, x1, _, _ = maps.raw_extent
    assert x0 <= 0.05 and x1 > 100.0


def test_run_with_a_small_budget_redraws(tmp_path: Path) -> None:
    d = tmp_path / "run"
    sink = MapSink(cell_m=0.005, max_cells=4 * 256 * 256)  # 1.28 m tiles: the room needs coarser cells
    write_run(d, sinks=(sink,))
    maps = load_maps(d / "maps.npz")
    assert maps.cell_m > 0.005 and math.log2(maps.cell_m / 0.005).is_integer()
    assert maps.corrected_hits.size <= 4 * 256 * 256 and maps.raw_hits.size <= 4 * 256 * 256
    written = {p.name for p in build_report(d)}
    assert {"fig_model.png", "fig_raw.png"} <= written


def test_hits_to_occupancy_in_blocks_matches_the_mapping() -> None:
    hits = np.random.default_rng(7).integers(0, 7, size=(1100, 1000)).astype(np.uint16)
    want = np.where(hits > 0, np.minimum(hits.astype(np.int64) * MAP_STEP, 100), -1).ravel()
    np.testing.assert_array_equal(hits_to_occupancy(hits), want)
