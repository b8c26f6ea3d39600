"""Procedural bakes and grid slope bounds are cached like mesh bakes (compile/sdf_bake.py):
a warm start reads exactly what a cold one computed."""
import dataclasses

import numpy as np

from gpiscl.host.compile import sdf_bake
from gpiscl.host.gp.knob import knob_grid
from gpiscl.host.gp.means import GridMean, brick_slope_bounds
from gpiscl.host.layout.gp_records import GRID_BRICK, pack_mean


def test_procedural_bake_is_cached_by_function_and_resolution(tmp_path, monkeypatch):
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path))
    cold, hit = sdf_bake.procedural_mean("knob_outer", 24)
    assert not hit
    warm, hit = sdf_bake.procedural_mean("knob_outer", 24)
    assert hit
    ref = knob_grid("knob_outer", 24)
    for g in (cold, warm):
        assert g.values.dtype == np.float32
        np.testing.assert_array_equal(g.values, ref.values)
        assert g.origin == ref.origin and g.voxel_size == ref.voxel_size
    assert not sdf_bake.procedural_mean("knob_outer", 25)[1]
    assert not sdf_bake.procedural_mean("knob_inner", 24)[1]
    assert len(list(sdf_bake.cache_dir("procedural").glob("*.npz"))) == 3


def test_slope_bounds_from_the_cache_equal_computed_ones(tmp_path, monkeypatch):
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path))
    base = knob_grid("knob_outer", 20)   # 19 cells: two of sdf_bake's linear slabs
    for interpolation in ("linear", "cubic"):
        fresh = dataclasses.replace(base, interpolation=interpolation)
        assert not sdf_bake.prepare_slopes(fresh)
        assert "cell_bounds" not in fresh.__dict__   # not kept: 64x the bricks' bytes
        warm = dataclasses.replace(base, interpolation=interpolation)
        assert sdf_bake.prepare_slopes(warm)
        # read, not recomputed: what the device records need is there already
        assert "lipschitz" in warm.__dict__ and GRID_BRICK in warm.brick_bounds
        assert "cell_bounds" not in warm.__dict__
        ref = dataclasses.replace(base, interpolation=interpolation)   # never cached
        for g in (warm, fresh):
            np.testing.assert_array_equal(brick_slope_bounds(g, GRID_BRICK),
                                          brick_slope_bounds(ref, GRID_BRICK))
            assert g.lipschitz == ref.lipschitz                  # bit for bit
            np.testing.assert_array_equal(g.cell_bounds, ref.cell_bounds)
            np.testing.assert_array_equal(pack_mean(g), pack_mean(ref))
        if interpolation == "cubic":
            np.testing.assert_array_equal(warm.coefficients, ref.coefficients)
    # other values or placement: another entry
    moved = GridMean(base.values, (0.5, 0.0, 0.0), base.voxel_size)
    assert not sdf_bake.prepare_slopes(moved)
    changed = GridMean(base.values + np.float32(0.25), base.origin, base.voxel_size)
    assert not sdf_bake.prepare_slopes(changed)
    assert len(list(sdf_bake.cache_dir("slopes").glob("*.npz"))) == 4


def test_damaged_slope_entries_are_recomputed(tmp_path, monkeypatch):
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path))
    grid = knob_grid("knob_inner", 12)
    sdf_bake.prepare_slopes(grid)
    (entry,) = sdf_bake.cache_dir("slopes").glob("*.npz")
    entry.write_bytes(b"not an npz")
    again = GridMean(grid.values, grid.origin, grid.voxel_size)
    assert not sdf_bake.prepare_slopes(again)
    np.testing.assert_array_equal(brick_slope_bounds(again, GRID_BRICK),
                                  brick_slope_bounds(grid, GRID_BRICK))
    assert again.lipschitz == grid.lipschitz
