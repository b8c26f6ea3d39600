"""Scene preparation on the device (render/device_bakes.py) against its numpy twins:
procedural bakes (gp/knob.py knob_grid) and trilinear slope bounds (compile/sdf_bake.py
over gp/means.py) are the same numbers bit for bit, so a bound from the device is the
certified numpy bound itself, and the bake cache does not depend on who filled it."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gpiscl import load_scene
from gpiscl.host.compile import sdf_bake
from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.gp import means
from gpiscl.host.gp.knob import knob_grid
from gpiscl.host.gp.means import GridMean
from gpiscl.host.layout.gp_records import GRID_BRICK, pack_mean
from gpiscl.host.render.device_bakes import DeviceBakes


@pytest.fixture(scope="module")
def bakes(device):
    return DeviceBakes(device)


@pytest.mark.parametrize("function", ["knob", "knob_inner", "knob_outer"])
def test_procedural_bake_equals_the_numpy_twin(bakes, function):
    # 37: an odd count, so no axis is a multiple of anything the device might assume
    dev, ref = bakes.procedural(function, 37), knob_grid(function, 37)
    assert dev.values.dtype == np.float32 and dev.values.shape == ref.values.shape
    np.testing.assert_array_equal(dev.values, ref.values)
    assert dev.origin == ref.origin and dev.voxel_size == ref.voxel_size


def _random_grid(rng, shape, negative_face: bool):
    values = rng.normal(size=shape) * rng.uniform(0.1, 3.0)
    if not negative_face:
        values = np.abs(values) + 0.01   # faces >= 0: the outside slope is max(a, 1)
    return GridMean(values, (-0.3, 0.2, 0.1), 0.37)


@pytest.mark.parametrize("shape,negative_face", [((9, 6, 7), True), ((14, 5, 11), False),
                                                 ((2, 2, 2), True), ((17, 18, 6), False)])
def test_linear_slope_bounds_equal_the_numpy_bounds(bakes, shape, negative_face):
    """Brick bounds and lipschitz bit for bit (partial bricks, one-cell grids, either face
    rule), so every device bound is >= the certified numpy bound (it is equal)."""
    grid = _random_grid(np.random.default_rng(sum(shape)), shape, negative_face)
    for brick in (GRID_BRICK, 3):
        bricks, lipschitz = bakes.linear_slopes(grid.values, grid.voxel_size, brick)
        ref = means.brick_slope_bounds(grid, brick)
        np.testing.assert_array_equal(bricks, ref)
        assert np.all(bricks >= ref)
        assert lipschitz == grid.lipschitz >= 1.0


def test_knob_slope_bounds_and_records_equal_the_numpy_ones(bakes, tmp_path, monkeypatch):
    """The knob's float32 grid end to end: what the device records hold is identical."""
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path))
    base = knob_grid("knob_outer", 40)
    on_device, on_host = (dataclasses.replace(base) for _ in range(2))
    assert not sdf_bake.prepare_slopes(on_device, cache=False, bakes=bakes)
    assert not sdf_bake.prepare_slopes(on_host, cache=False)
    assert on_device.lipschitz == on_host.lipschitz
    np.testing.assert_array_equal(means.brick_slope_bounds(on_device, GRID_BRICK),
                                  means.brick_slope_bounds(on_host, GRID_BRICK))
    np.testing.assert_array_equal(pack_mean(on_device), pack_mean(on_host))


def test_compiled_knob_scene_is_identical_and_a_warm_cache_builds_nothing(device, tmp_path,
                                                                          monkeypatch):
    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "knob.json")
    data = scene.data
    for g in data["shapes"]:
        if g["type"] == "gpis":
            g["mean"]["child"]["resolution"] = 33   # small bakes: the test stays fast
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path / "host"))
    host = compile_scene(data, scene.source)
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path / "device"))
    cold = DeviceBakes(device)
    on_device = compile_scene(data, scene.source, cold)
    assert cold.built
    np.testing.assert_array_equal(on_device.gpis.mean_nodes, host.gpis.mean_nodes)
    warm = DeviceBakes(device)
    again = compile_scene(data, scene.source, warm)   # everything from the bake cache
    assert not warm.built
    np.testing.assert_array_equal(again.gpis.mean_nodes, host.gpis.mean_nodes)
