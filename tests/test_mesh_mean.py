"""Mesh and grid means: SDF bakes against analytic distances, the device grid leaf against
its numpy twin, the Lipschitz bound weight space relies on, the bake cache, bad grid files,
and a weight-space render with a sphere-mesh mean against the analytic sphere mean."""
import dataclasses
import json
import math
import os

import numpy as np
import pyopencl as cl
import pytest
import trimesh

from gpiscl import load_scene, render_result
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.host.gp import means as means_module
from gpiscl.host.layout.gp_records import (GRID_BRICK, GRID_PAYLOAD_FLOATS, MEAN_KINDS,
                                         pack_mean)
from gpiscl.host.gp.means import (Box, Difference, GridMean, Sphere, Transform, Union)
from gpiscl.host.compile import sdf_bake
from gpiscl.host.errors import SceneError
from gpiscl.testing.stats import assert_agree
from gpiscl.testing.wrappers import GP_MEAN_WRAPPER, program

KERNELS = GP_MEAN_WRAPPER + r"""

__kernel void lipschitz(__global const MeanNode* nodes, int count, __global float* out)
{
    out[0] = ws_mean_lipschitz(nodes, count);
}

__kernel void lipschitz_on(__global const MeanNode* nodes, int count,
                           __global const float* pq, __global float* out)
{
    int i = get_global_id(0);
    out[i] = gp_mean_lipschitz_on(nodes, count, vload3(2 * i, pq), vload3(2 * i + 1, pq));
}
"""

ROT = np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]])


@pytest.fixture(scope="module")
def prg(device):
    src = join_sources(
        (), ("ws_features.h", "ws_posterior.h", "ws_intersect.h")) + KERNELS
    return program(device.ctx, src, [f"-I{PYOPENCL_CL_DIR}", "-DWS_LANES=8"])


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """Bakes go to a per-test cache, so a test never sees another's entries."""
    monkeypatch.setenv("GPISCL_CACHE", str(tmp_path / "cache"))


def _buf(device, a):
    return cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(a))


def device_eval(device, prg, mean, x):
    nodes = pack_mean(mean)
    x = np.ascontiguousarray(x, np.float32)
    out = np.empty((len(x), 4), np.float32)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["mean_eval"](device.queue, (len(x),), None, _buf(device, nodes),
                     np.int32(len(nodes)), _buf(device, x), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out[:, 3], out[:, :3]


def device_lipschitz(device, prg, mean):
    nodes = pack_mean(mean)
    out = np.empty(1, np.float32)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["lipschitz"](device.queue, (1,), None, _buf(device, nodes), np.int32(len(nodes)), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return float(out[0])


def write_mesh(tmp_path, mesh, name="mesh.obj"):
    path = tmp_path / name
    mesh.export(path)
    return str(path)


# ---- bakes against analytic distances ---------------------------------------------------

def test01_sphere_bake_matches_the_analytic_distance(tmp_path):
    """Icosphere (subdivisions 4, vertices on the unit sphere) baked at 48^3.
    Error bound, derived: (a) faceting: every face's plane is at distance p_f =
    |n_f . v0| from the centre and the mesh lies between radius min p_f and 1 along every
    ray, so mesh and sphere signed distances differ by at most H = 1 - min_f p_f (points
    between the surfaces included: there the two magnitudes sum to a radial gap <= H);
    (b) trilinear interpolation is a convex combination of samples, so it carries (a)
    unchanged, plus the interpolation error of the smooth |x| - 1 itself, at most
    h^2 / 8 (sum of |d^2/dx_i^2|) = h^2 / (4 r) over a cell at radius >= r = |x| - sqrt(3) h;
    (c) float32 storage in the cache, ~1e-7."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    grid, hit = sdf_bake.mesh_mean(write_mesh(tmp_path, mesh), resolution=48)
    assert not hit
    v0 = mesh.vertices[mesh.faces[:, 0]]
    H = 1.0 - np.min(np.abs(np.sum(mesh.face_normals * v0, axis=1)))
    h = grid.voxel_size
    assert 5e-4 < H < 2e-3 and h < 0.06
    # samples: (a) and (c) only
    axes = [grid.origin[a] + h * np.arange(grid.shape[a]) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    err = np.asarray(grid.values) - (np.linalg.norm(nodes, axis=-1) - 1.0)
    assert np.max(np.abs(err)) <= H + 1e-6
    assert np.min(err) > -1e-6          # the inscribed mesh: distances never shrink
    # interpolated points, away from the centre's cusp
    rng = np.random.default_rng(1)
    x = rng.uniform(-1.15, 1.15, (20000, 3))
    r = np.linalg.norm(x, axis=1)
    x, r = x[r > 0.3], r[r > 0.3]
    value, grad = grid.value_and_gradient(x)
    bound = H + h**2 / (4.0 * (r - math.sqrt(3) * h)) + 1e-6
    ratio = np.abs(value - (r - 1.0)) / bound
    assert np.max(ratio) <= 1.0
    assert np.median(ratio) > 0.3        # and the bound is not loose: it is the error's size


def test02_box_bake_matches_the_analytic_distance(tmp_path):
    """A 12-triangle box has no faceting error: samples are exact (float32 storage
    aside). The box's SDF is convex and 1-Lipschitz, so by Jensen the trilinear
    interpolant (weights with barycentre x) never lies below it, and above it by at most
    sum_c w_c |grad f(c) - grad f(x)| |c - x| <= 2 * (sqrt(3) h / 2) where the gradient
    turns (edges, medial axis), and by h^2/8 trace(Hessian) elsewhere."""
    half = np.array([0.5, 0.3, 0.4])
    mesh = trimesh.creation.box(extents=2 * half)
    mesh.apply_translation([0.1, -0.2, 0.05])
    grid, _ = sdf_bake.mesh_mean(write_mesh(tmp_path, mesh), resolution=40)
    box = Box(half_extents=tuple(half), center=(0.1, -0.2, 0.05))
    h = grid.voxel_size
    axes = [grid.origin[a] + h * np.arange(grid.shape[a]) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    np.testing.assert_allclose(grid.values, box.value(nodes), atol=1e-6)
    lo = np.asarray(grid.origin)
    x = np.random.default_rng(2).uniform(lo, lo + h * (np.asarray(grid.shape) - 1),
                                         (20000, 3))
    err = grid.value(x) - box.value(x)
    assert err.min() >= -1e-6 and err.max() <= math.sqrt(3) * h + 1e-6
    # most cells see one face: there the interpolant is exact to float precision
    assert np.mean(err < 1e-5) > 0.5


def test02b_transform_applies_to_the_vertices_before_baking(tmp_path):
    """The scene's transform (scale, then rotate, then translate, as for mesh shapes) is
    baked in, so even a non-uniform scale gives exact distances: a unit cube scaled to
    (1, 0.6, 0.8) and turned 90 degrees about y is the box of half extents (0.4, 0.3, 0.5)."""
    from gpiscl.host.scene.transforms import transform_matrix
    path = write_mesh(tmp_path, trimesh.creation.box(extents=(1.0, 1.0, 1.0)))
    m = transform_matrix({"scale": [1.0, 0.6, 0.8], "rotate": [0.0, 90.0, 0.0],
                           "translate": [0.2, 0.1, -0.3]})
    grid, _ = sdf_bake.mesh_mean(path, resolution=24, object_to_world=m)
    box = Box(half_extents=(0.4, 0.3, 0.5), center=(0.2, 0.1, -0.3))
    axes = [grid.origin[a] + grid.voxel_size * np.arange(grid.shape[a]) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    np.testing.assert_allclose(grid.values, box.value(nodes), atol=1e-6)


def test03_open_mesh_uses_the_winding_number_sign(tmp_path):
    """A sphere with a few faces removed is not watertight: inside still means winding
    number > 1/2, so points well inside and outside keep their signs."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    keep = np.ones(len(mesh.faces), bool)
    keep[:6] = False
    mesh.update_faces(keep)
    assert not mesh.is_watertight
    grid, _ = sdf_bake.mesh_mean(write_mesh(tmp_path, mesh), resolution=24)
    x = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1], [1.2, 0.0, 0.0], [0.0, -1.1, 0.3]])
    assert np.all(np.sign(grid.value(x)) == [-1, -1, 1, 1])
    # the narrow band's far points take their sign from the fast winding number: the same
    banded, _ = sdf_bake.mesh_mean(str(tmp_path / "mesh.obj"), resolution=24, band=0.1)
    np.testing.assert_allclose(banded.values, np.clip(grid.values, -0.1, 0.1), atol=1e-7)


def test04_bakes_are_cached_by_content_and_settings(tmp_path):
    path = write_mesh(tmp_path, trimesh.creation.icosphere(subdivisions=2))
    g1, hit1 = sdf_bake.mesh_mean(path, resolution=16)
    entries = list(sdf_bake.cache_dir().glob("*.npz"))
    assert not hit1 and len(entries) == 1
    assert str(sdf_bake.cache_dir()).startswith(os.environ["GPISCL_CACHE"])
    g2, hit2 = sdf_bake.mesh_mean(path, resolution=16)
    assert hit2 and np.array_equal(g1.values, g2.values) and g1.origin == g2.origin
    assert not sdf_bake.mesh_mean(path, resolution=17)[1]            # other settings
    assert not sdf_bake.mesh_mean(path, resolution=16, band=0.2)[1]
    trimesh.creation.icosphere(subdivisions=1).export(path)            # other content
    assert not sdf_bake.mesh_mean(path, resolution=16)[1]
    assert len(list(sdf_bake.cache_dir().glob("*.npz"))) == 4


def test05_band_clamps_the_distance(tmp_path):
    path = write_mesh(tmp_path, trimesh.creation.icosphere(subdivisions=2))
    grid, _ = sdf_bake.mesh_mean(path, resolution=20, band=0.1)
    full, _ = sdf_bake.mesh_mean(path, resolution=20)
    assert np.max(np.abs(grid.values)) <= 0.1 + 1e-7
    np.testing.assert_allclose(grid.values, np.clip(full.values, -0.1, 0.1), atol=1e-7)


# ---- the device grid leaf against its numpy twin ------------------------------------------

def random_grid(rng, shape=(5, 6, 7), origin=(-1.0, -1.2, -0.9), h=0.4, interp="linear"):
    return GridMean(rng.normal(size=shape), origin, h, interp)


def _grid_index(mean_to_grid, grid, x):
    """Index coordinates of world points in a grid leaf (for the face-distance filter)."""
    return (mean_to_grid(x) - np.asarray(grid.origin)) / grid.voxel_size


RIGID = np.concatenate([ROT, [[0.25], [0.0], [-0.5]]], 1)
AFFINE = np.concatenate([ROT @ np.diag([1.5, 0.75, 1.0]), [[0.1], [0.2], [0.0]]], 1)


def cases(interp="linear"):
    rng = np.random.default_rng(4)
    g1 = random_grid(rng, interp=interp)
    g2 = random_grid(rng, (3, 2, 4), (0.0, 0.1, -0.5), 0.3, interp)
    inv = {}
    for name, m in (("rigid", RIGID), ("affine", AFFINE)):
        w2o = Transform(g1, m).world_to_object
        inv[name] = lambda x, w2o=w2o: x @ w2o[:, :3].T + w2o[:, 3]
    same = lambda x: x  # noqa: E731
    return {
        "grid": (g1, [(g1, same)]),
        "rigid": (Transform(g1, RIGID), [(g1, inv["rigid"])]),
        "affine": (Transform(g1, AFFINE), [(g1, inv["affine"])]),
        "csg": (Difference(Union(Transform(g1, AFFINE), Sphere(radius=0.5), k=0.25),
                           Union(g2, Box(half_extents=(0.3, 0.2, 0.4)), k=0.0), k=0.125),
                [(g1, inv["affine"]), (g2, same)]),
    }


@pytest.mark.parametrize("interp", ["linear", "cubic"])
@pytest.mark.parametrize("name", ["grid", "rigid", "affine", "csg"])
def test06_device_grid_matches_the_numpy_twin(device, prg, name, interp):
    mean, leaves = cases(interp)[name]
    # half near the grids (inside their boxes: trilinear), half around them (continuation)
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(-1.2, 1.2, (2000, 3)), rng.uniform(-3, 3, (2000, 3))])
    x = x.astype(np.float32)
    value, grad = device_eval(device, prg, mean, x)
    v_ref, g_ref = mean.value_and_gradient(x.astype(np.float64))
    # float32 maps and samples: a few ulp of values up to ~10 (|x| <= 5 outside the box)
    np.testing.assert_allclose(value, v_ref, atol=2e-5, rtol=2e-6)
    # gradients jump across cell faces (one-sided by design): where float32 rounding of
    # the index coordinate may pick the other cell, the twins may differ, so skip points
    # within 1e-4 voxel of a face of any grid leaf
    near = np.zeros(len(x), bool)
    for grid, to_grid in leaves:
        u = _grid_index(to_grid, grid, x.astype(np.float64))
        near |= np.any(np.abs(u - np.round(u)) < 1e-4, axis=1)
    assert np.mean(near) < 0.01
    # smooth blends divide value rounding by k >= 0.125
    np.testing.assert_allclose(grad[~near], g_ref[~near], atol=1e-4)


def test06b_cubic_grids_interpolate_smoothly_to_fourth_order(device, prg):
    """The cubic leaf passes through its samples (host to rounding, device to float32),
    its gradient is continuous across cell faces (where trilinear's jumps), and on a
    smooth function its error falls >= 16x per halving of h (O(h^4); trilinear ~4x)."""
    rng = np.random.default_rng(61)
    g = random_grid(rng, interp="cubic")
    idx = np.argwhere(np.ones(g.shape, bool))
    x = np.asarray(g.origin) + g.voxel_size * idx
    np.testing.assert_allclose(g.value(x), g.values.ravel(), atol=1e-12)
    value, _ = device_eval(device, prg, g, x.astype(np.float32))
    np.testing.assert_allclose(value, g.values.ravel(), atol=2e-5 * np.abs(g.values).max())
    # one-sided gradients 1e-9 voxel either side of interior faces normal to x
    face = np.asarray(g.origin) + g.voxel_size * (np.array([2.0, 2.3, 3.6]) + rng.uniform(
        0, 0.3, (50, 3)) * [0, 1, 1])
    e = np.array([1e-9 * g.voxel_size, 0, 0])
    for interp, continuous in (("cubic", True), ("linear", False)):
        gg = GridMean(g.values, g.origin, g.voxel_size, interp)
        jump = np.abs(gg.gradient(face + e) - gg.gradient(face - e)).max()
        assert (jump < 1e-6) == continuous, (interp, jump)

    def f(p):
        return np.sin(p[..., 0]) * np.cos(0.7 * p[..., 1]) + 0.3 * p[..., 2] ** 2

    pts = rng.uniform(0.3, 1.7, (2000, 3))
    # cubic: >= 16 far from the faces; the natural end conditions' O(h^2) error decays
    # by ~0.27 per cell inwards, so points a fixed distance in gain more than 16x
    for interp, lo, hi in (("cubic", 12.0, np.inf), ("linear", 3.0, 5.0)):
        errs = []
        for n in (11, 21, 41):
            h = 2.0 / (n - 1)
            ax = h * np.arange(n)
            grid = GridMean(f(np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1)),
                            (0, 0, 0), h, interp)
            errs.append(np.abs(grid.value(pts) - f(pts)).max())
        ratios = np.array(errs[:-1]) / np.array(errs[1:])
        print(interp, errs, ratios)
        assert np.all((lo < ratios) & (ratios < hi)), (interp, ratios)


def test07_packing_puts_the_samples_inline():
    rng = np.random.default_rng(6)
    g = random_grid(rng, shape=(9, 6, 7))
    nodes = pack_mean(Union(g, Sphere()))
    bricks = means_module.brick_slope_bounds(g, GRID_BRICK)
    assert bricks.shape == (2, 2, 2)          # 8 x 5 x 6 cells in bricks of 4^3
    n_payload = -(-(g.values.size + bricks.size) // GRID_PAYLOAD_FLOATS)
    assert len(nodes) == 1 + n_payload + 2
    assert nodes[0]["kind"] == MEAN_KINDS["grid"] and nodes[0]["flags"] == n_payload
    assert nodes[0]["p0"][2] == GRID_BRICK
    assert np.all(nodes[1:1 + n_payload]["kind"] == MEAN_KINDS["payload"])
    # samples in (i ny + j) nz + k order, scaled by 1 / (S h), then the brick bounds / S
    payload = nodes[1:1 + n_payload]
    floats = np.stack([payload[f] for f in ("row0", "row1", "row2", "p0", "p1")], 1).ravel()
    s_h = g.lipschitz * g.voxel_size
    np.testing.assert_allclose(floats[:g.values.size] * s_h, g.values.ravel(), rtol=1e-6)
    np.testing.assert_allclose(floats[g.values.size:g.values.size + bricks.size],
                               bricks.ravel() / g.lipschitz, rtol=1e-6)
    assert bricks.max() <= g.lipschitz


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test07b_packing_in_layers_is_the_whole_grid_pass_bit_for_bit(interp):
    """gp_records writes a grid's samples into its records a few x layers at a time: the
    floats must be those of one float64 pass over the whole grid rounded to float32 (the
    packing before), past several layer blocks and with the payload not a whole record."""
    rng = np.random.default_rng(7)
    g = dataclasses.replace(random_grid(rng, shape=(19, 6, 7)), interpolation=interp)
    nodes = pack_mean(g)
    samples = g.coefficients if interp == "cubic" else np.asarray(g.values, np.float64)
    s_index = g.lipschitz * g.voxel_size
    bricks = means_module.brick_slope_bounds(g, GRID_BRICK) / g.lipschitz
    want = np.asarray(np.concatenate([(samples / s_index).ravel(), bricks.ravel()]),
                      np.float32)
    assert want.size % GRID_PAYLOAD_FLOATS        # a partly filled last record
    payload = nodes[1:]
    assert len(payload) == nodes[0]["flags"] == -(-want.size // GRID_PAYLOAD_FLOATS)
    floats = np.stack([payload[f] for f in ("row0", "row1", "row2", "p0", "p1")], 1).ravel()
    np.testing.assert_array_equal(floats[:want.size], want)
    assert not np.any(floats[want.size:])
    assert np.all(payload["kind"] == MEAN_KINDS["payload"]) and not np.any(payload["flags"])


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test08_lipschitz_bound_holds(device, prg, interp):
    """ws_mean_lipschitz (unchanged) yields the grid's slope bound through the leaf's
    scale, and no gradient exceeds it, inside the box, outside it, or transformed."""
    rng = np.random.default_rng(7)
    g = random_grid(rng, interp=interp)
    cs = cases(interp)
    x = rng.uniform(-4, 4, (20000, 3))
    for mean, expected in [(g, g.lipschitz), (Transform(g, RIGID), g.lipschitz),
                           (Transform(g, np.diag([2.0, 2.0, 2.0, 1.0])), g.lipschitz),
                           (cs["affine"][0], None), (cs["csg"][0], None),
                           (Union(GridMean(np.zeros((2, 2, 2))), Sphere()), 1.0)]:
        lip = device_lipschitz(device, prg, mean)
        if expected is not None:
            assert lip == pytest.approx(expected, rel=1e-5)
        host = np.linalg.norm(mean.gradient(x), axis=1)
        dev = np.linalg.norm(device_eval(device, prg, mean, x)[1], axis=1)
        assert max(host.max(), dev.max()) <= lip * (1 + 1e-5)
    if interp == "cubic":
        return
    # the bound is attained: a linear field of slope a along x reaches sqrt(a^2 + 1)
    # beyond the y and z faces where it is negative (g + d), and 1 where every sample is
    # >= 0 (sqrt(g^2 + d^2), whose slope exceeds 1 nowhere)
    i, j, k = np.meshgrid(np.arange(4), np.arange(3), np.arange(5), indexing="ij")
    for shift, expected in [(-1.5, math.sqrt(0.25 + 1.0)), (0.0, 1.0)]:
        lin = GridMean(0.5 * (i + shift) * 0.25 + 0.0 * j + 0.0 * k, (0, 0, 0), 0.25)
        assert lin.lipschitz == pytest.approx(expected)
        gn = np.linalg.norm(lin.gradient(rng.uniform(-1, 2, (4000, 3))), axis=1)
        assert gn.max() == pytest.approx(lin.lipschitz, rel=1e-6)


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test08c_segment_bounds_hold_and_are_tighter(device, prg, tmp_path, interp):
    """gp_mean_lipschitz_on (brick bounds of the cells a segment crosses): no gradient
    on the segment exceeds it (300 segments of lengths 0.01-2 through, near and outside
    a baked sphere, transformed; 64 points each, end points included), it never exceeds
    the global bound, and short segments near the surface get a tighter one."""
    mean = _sphere_grid(tmp_path, interp)
    nodes = pack_mean(mean)
    rng = np.random.default_rng(81)
    n = 300
    centre = RIGID[:, 3]
    p = centre + rng.normal(size=(n, 3)) * rng.uniform(0.2, 1.6, (n, 1))
    q = p + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-2, 0.3, (n, 1))
    pq = np.stack([p, q], 1).astype(np.float32)
    out = np.empty(n, np.float32)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["lipschitz_on"](device.queue, (n,), None, _buf(device, nodes), np.int32(len(nodes)),
                        _buf(device, pq), ob)
    cl.enqueue_copy(device.queue, out, ob)
    glob = device_lipschitz(device, prg, mean)
    t = np.linspace(0, 1, 64)
    x = pq[:, :1, :].astype(float) + t[None, :, None] * (pq[:, 1:, :] - pq[:, :1, :])
    grad = np.linalg.norm(mean.gradient(x.reshape(-1, 3)), axis=1).reshape(n, 64).max(1)
    dev_grad = np.linalg.norm(device_eval(device, prg, mean, x.reshape(-1, 3))[1],
                              axis=1).reshape(n, 64).max(1)
    assert np.all(np.maximum(grad, dev_grad) <= out * (1 + 1e-5)), \
        np.max(np.maximum(grad, dev_grad) / out)
    assert np.all(out <= glob * (1 + 1e-6))
    short = np.linalg.norm(q - p, axis=1) < 0.05
    print(f"{interp}: global {glob:.3f}, median over short segments {np.median(out[short]):.3f}")
    assert np.median(out[short]) < glob


def test08b_outside_the_box_is_continuous_and_bounds_a_distance(tmp_path):
    """Across the box's faces the value is continuous. Beyond them a baked SDF (positive
    on the faces) continues as sqrt(g(c)^2 + d^2), which never exceeds the true distance
    (|x - p|^2 >= d^2 + |c - p|^2 for every p in the convex box) by more than the bake's
    error at c (faceting H plus interpolation h^2 / 4 at radius >= 1). Samples of a
    1-Lipschitz function keep the interpolant's slope below sqrt(3) (sqrt(2) on faces)."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    grid, _ = sdf_bake.mesh_mean(write_mesh(tmp_path, mesh), resolution=24)
    assert 1.0 <= grid.lipschitz <= math.sqrt(3)
    lo = np.asarray(grid.origin)
    hi = lo + grid.voxel_size * (np.asarray(grid.shape) - 1)
    rng = np.random.default_rng(11)
    n = np.arange(500)
    face = rng.uniform(lo, hi, (500, 3))
    axis = rng.integers(0, 3, 500)
    face[n, axis] = np.where(rng.random(500) < 0.5, lo[axis], hi[axis])
    normal = np.zeros((500, 3))
    normal[n, axis] = np.where(face[n, axis] == lo[axis], -1.0, 1.0)
    for eps in (1e-6, 1e-9):
        jump = grid.value(face + eps * normal) - grid.value(face - eps * normal)
        assert np.max(np.abs(jump)) < 3 * eps * grid.lipschitz
    far = rng.normal(size=(4000, 3)) * 3.0
    far = far[np.any((far < lo) | (far > hi), axis=1)]
    v0 = mesh.vertices[mesh.faces[:, 0]]
    H = 1.0 - np.min(np.abs(np.sum(mesh.face_normals * v0, axis=1)))
    true = np.linalg.norm(far, axis=1) - 1.0      # the mesh's distance is within H of it
    excess = grid.value(far) - true
    assert np.max(excess) <= 2 * H + grid.voxel_size**2 / 4 + 1e-6
    assert np.all(grid.value(far) >= np.max(np.abs(far) - hi, axis=1))   # >= d


# ---- grid files and scene errors ------------------------------------------------------------

def _gpis_scene(mean, proxy_radius=1.6, sigma=1e-3):
    return {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 36.0, "resolution": [12, 12]},
            "lights": [{"type": "environment", "radiance": 0.5},
                       {"type": "directional", "direction": [1, 1, 1], "irradiance": 3.0}],
            "render": {"spp": 16, "seed": 5, "max_depth": 4},
            "shapes": [{"type": "gpis", "proxy": {"type": "sphere", "radius": proxy_radius},
                        "mean": mean,
                        "kernel": {"type": "squared_exponential", "sigma": sigma,
                                   "length_scale": 0.2},
                        "sampler": {"type": "weight_space", "features": 64},
                        "bsdf": {"type": "diffuse", "albedo": [0.7, 0.5, 0.3]}}]}


def _load(tmp_path, scene):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    return load_scene(str(path))


GOOD = {"values": np.zeros((3, 4, 5)), "origin": np.zeros(3), "voxel_size": np.float64(0.5)}
NAN = np.zeros((3, 4, 5))
NAN[1, 2, 3] = np.nan
BAD_GRIDS = {
    "2-D values": ({**GOOD, "values": np.zeros((3, 4))}, "'values' must be 3-D"),
    "thin values": ({**GOOD, "values": np.zeros((3, 1, 5))}, "'values' must be 3-D"),
    "NaN": ({**GOOD, "values": NAN}, "'values' has 1 NaN"),
    "zero voxel": ({**GOOD, "voxel_size": np.float64(0.0)}, "'voxel_size' must be one positive"),
    "negative voxel": ({**GOOD, "voxel_size": np.float64(-1.0)}, "'voxel_size' must be one"),
    "origin": ({**GOOD, "origin": np.zeros(2)}, "'origin' must be 3 finite"),
    "missing": ({k: v for k, v in GOOD.items() if k != "origin"}, "lacks array(s) 'origin'"),
    "extra": ({**GOOD, "sigma": np.ones(3)}, "unknown array(s) 'sigma'"),
}


@pytest.mark.parametrize("case", BAD_GRIDS)
def test09_bad_grid_files_name_file_and_key(tmp_path, case):
    arrays, message = BAD_GRIDS[case]
    np.savez(tmp_path / "g.npz", **arrays)
    with pytest.raises(SceneError) as err:
        _load(tmp_path, _gpis_scene({"type": "grid", "file": "g.npz"}))
    text = str(err.value)
    assert message in text and "shapes[0].mean.file" in text
    assert str(tmp_path / "g.npz") in text and str(tmp_path / "scene.json") in text


def test10_grid_file_round_trips_into_the_program(tmp_path):
    g = random_grid(np.random.default_rng(8))
    sdf_bake.save_grid(tmp_path / "g.npz", g)
    scene = _load(tmp_path, _gpis_scene({"type": "transform", "translate": [0.5, 0, 0],
                                         "child": {"type": "grid", "file": "g.npz"}}))
    from gpiscl.host.compile.gpis import build_mean
    mean = build_mean(scene.data["shapes"][0]["mean"])
    x = np.random.default_rng(9).uniform(-2, 2, (100, 3))
    np.testing.assert_allclose(mean.value(x), Transform(g, np.concatenate(
        [np.eye(3), [[0.5], [0], [0]]], 1)).value(x), atol=1e-12)
    # "cubic": the spline through the same samples
    scene = _load(tmp_path, _gpis_scene({"type": "grid", "file": "g.npz",
                                         "interpolation": "cubic"}))
    cubic = build_mean(scene.data["shapes"][0]["mean"])
    assert cubic.interpolation == "cubic"
    idx = np.argwhere(np.ones(g.shape, bool))
    np.testing.assert_allclose(cubic.value(np.asarray(g.origin) + g.voxel_size * idx),
                               g.values.ravel(), atol=1e-12)


# ---- a render: sphere-mesh mean vs the analytic sphere mean -----------------------------------

def test11_mesh_mean_render_agrees_with_the_analytic_sphere(device, tmp_path):
    """Small sigma: both GPIS are their mean surfaces with a diffuse micro-BSDF. The baked
    sphere (64^3, H ~ 6e-4 plus interpolation ~4e-4) moves the surface by ~1e-3 and turns
    normals by O(h / 2) ~ 0.02 rad: below what 16 spp per pixel can resolve."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    write_mesh(tmp_path, mesh, "sphere.obj")
    scene = _load(tmp_path, _gpis_scene({"type": "mesh", "file": "sphere.obj",
                                         "resolution": 64}))
    baked = render_result(scene, device=device)
    exact = render_result(_gpis_scene({"type": "sphere", "radius": 1.0}), device=device)
    for r in (baked, exact):
        assert r.stats.gpis_failed == 0 and r.stats.nan_paths == 0
    assert_agree(baked.image.mean, baked.image.stderr, exact.image.mean, exact.image.stderr,
                 what="sphere mesh mean vs analytic sphere mean")
    # the comparison can see a surface that matters: a smaller sphere is not the same
    small = render_result(_gpis_scene({"type": "sphere", "radius": 0.85}), device=device)
    with pytest.raises(AssertionError):
        assert_agree(baked.image.mean, baked.image.stderr, small.image.mean,
                     small.image.stderr)


# ---- weight-space root finding on a grid mean ------------------------------------------------

@pytest.fixture(scope="module")
def ws_prg(device):
    from gpiscl.testing.weight_space import WS_BOUND_WRAPPERS, build
    return build(device, WS_BOUND_WRAPPERS)


def _sphere_grid(tmp_path, interp="linear"):
    mesh = trimesh.creation.icosphere(subdivisions=3)
    grid, _ = sdf_bake.mesh_mean(write_mesh(tmp_path, mesh), resolution=20)
    return Transform(dataclasses.replace(grid, interpolation=interp), RIGID)


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test12_bounds_and_first_roots_hold_with_a_grid_mean(device, ws_prg, tmp_path, interp):
    """ws_intersect.h, unchanged, on a baked mean: its piecewise-linear bounds contain every
    evaluation of f over random intervals (the grid's Lipschitz bound is what makes the
    mean's cones valid), and its first roots miss no crossing a dense float64 scan finds."""
    from gpiscl.host.gp import SquaredExponential
    from gpiscl.testing.weight_space import (assert_tents_contain, dump, gp_args, host_values,
                                             keys_for, random_rays, roots_and_scan, run)
    from gpiscl.testing.wrappers import buffer
    kernel = SquaredExponential(sigma=0.1, length_scale=0.25)
    mean = _sphere_grid(tmp_path, interp)
    rng = np.random.default_rng(12)
    m, n, npts = 32, 96, 33
    # bounds over intervals 1e-4 l .. 4 l, some starting outside the grid's box
    o, d = random_rays(rng, n, spread=2.5)
    half = kernel.length_scale * 10.0 ** rng.uniform(-4, 0.3, n)
    a = rng.uniform(0.0, 3.0, n)
    ab = np.stack([a, a + 2 * half], -1).astype(np.float32)
    keys = keys_for(n, 91)
    tents, vals = run(device, ws_prg["ws_tents_k"], n, *gp_args(device, kernel, mean),
                      np.int32(m), buffer(device, keys), buffer(device, o), buffer(device, d),
                      buffer(device, ab), np.int32(npts),
                      out_shapes=[((n, 9), np.float32), ((n, npts, 2), np.float32)])
    theta, tau, w = dump(device, ws_prg, kernel, keys, m)
    t = vals[..., 0].astype(float)
    exact = host_values(theta, tau, w, kernel, mean, o, d, t)
    assert_tents_contain(tents, ab, t, vals[..., 1], exact)
    # first roots against a dense scan (spacing l / 200) over rays crossing the sphere
    n, t0, t1 = 128, 0.0, 4.0
    tol = 1e-4 * kernel.length_scale
    o = rng.normal(size=(n, 3))
    o = 2.5 * o / np.linalg.norm(o, axis=1, keepdims=True) + RIGID[:, 3]
    d = rng.uniform(-1.2, 1.2, (n, 3)) + RIGID[:, 3] - o     # at the sphere, or past it
    o, d = o.astype(np.float32), (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    hit, _, t_hi, ts, _ = roots_and_scan(device, ws_prg, kernel, mean, o, d, keys_for(n, 92),
                                         m, t0, t1, tol)
    t_dev = hit[:, 3].astype(float)
    crossing = np.isfinite(t_hi)
    assert 0.2 < np.mean(crossing) < 0.95            # the rays do meet the surface
    assert np.all(t_dev[crossing] <= t_hi[crossing] + tol), "missed a root"
    both = crossing & (t_dev < 1e29)
    # nearly always the same crossing: within the scan's spacing of it, give or take tol
    # (earlier only for a dip narrower than the spacing, which only the bound catches)
    dt = ts[1] - ts[0]
    assert np.mean(t_dev[both] >= t_hi[both] - dt - tol) > 0.95
