"""Colour and emission fields on GPIS objects (gpiscl/host/scene/colour_fields.py, gpis_fields.h):
the device evaluator against the numpy reference, closed-form renders, and scene errors."""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl import load_scene, render_result
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.host.scene.colour_fields import evaluate
from gpiscl.host.io.grids import save_rgb_grid
from gpiscl.host.compile.colour_fields import pack_field
from gpiscl.host.errors import SceneError
from gpiscl.testing.reference.camera import hit_sphere, pixel_rays
from gpiscl.testing.stats import z_threshold


WRAPPER = r"""
__kernel void field_eval(__global const MeanNode* nodes, int f, __global const float* x,
                         __global float4* out)
{
    int i = get_global_id(0);
    out[i] = (float4)(gpis_field_eval(nodes, f, vload3(i, x), -1.0f), 0.0f);
}
"""


def _linear_grid(tmp_path, name, axis, lo, hi, a, b, n=(3, 4, 5)):
    """An RGB grid over [lo, hi] whose values go from a to b linearly along `axis`."""
    h = (hi - lo) / (n[axis] - 1)
    origin = [-1.0, -1.0, -1.0]
    origin[axis] = lo
    t = np.linspace(0.0, 1.0, n[axis])
    shape = [1, 1, 1]
    shape[axis] = n[axis]
    values = np.asarray(a) + (np.asarray(b) - np.asarray(a)) * t.reshape(*shape, 1)
    values = np.broadcast_to(values, (*n, 3))
    path = tmp_path / name
    save_rgb_grid(path, values, origin, h)
    return str(path)


def test02_device_evaluator_matches_numpy(device, tmp_path):
    """Every field kind at random points (inside and beyond a grid's box): gpis_field_eval
    equals gpis_fields.evaluate; the grid has distinct samples, so a wrong index order or
    channel interleave shows."""
    rng = np.random.default_rng(7)
    values = rng.uniform(0.0, 1.0, (4, 5, 6, 3))
    grid = tmp_path / "random.npz"
    save_rgb_grid(grid, values, [-0.5, -0.25, 0.0], 0.3)
    fields = [{"type": "constant", "value": [0.25, 0.5, 0.75]},
              {"type": "checker", "scale": 0.37, "a": [1, 0, 0.5], "b": [0, 1, 0.25],
               "offset": [0.1, 0.2, 0.3]},
              {"type": "gradient", "start": [0.5, -1, 0], "end": [-0.5, 1, 0.5],
               "a": [0, 0.5, 1], "b": [1, 0.5, 0]},
              {"type": "grid", "file": str(grid)}]
    # the renderer's header order: gpis_fields.h builds on gp_mean.h's grid cells
    src = join_sources((), ("gpis_fields.h",)) + WRAPPER
    kernel = cl.Kernel(cl.Program(device.ctx, src).build([f"-I{PYOPENCL_CL_DIR}"]), "field_eval")
    x = rng.uniform(-1.5, 2.0, (4096, 3)).astype(np.float32)
    for field in fields:
        # a dummy record first: index 0 means "no field"
        nodes = np.concatenate([pack_field({"type": "constant", "value": [0] * 3}),
                                pack_field(field)])
        mf = cl.mem_flags
        nb = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nodes)
        xb = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
        out = np.zeros((len(x), 4), np.float32)
        ob = cl.Buffer(device.ctx, mf.WRITE_ONLY, out.nbytes)
        for f, expect in ((1, evaluate(field, x.astype(np.float64))),
                          (0, np.full((len(x), 3), -1.0))):
            kernel(device.queue, (len(x),), None, nb, np.int32(f), xb, ob)
            cl.enqueue_copy(device.queue, out, ob)
            got = out[:, :3]
            if field["type"] == "checker":   # float32 floor may differ on a cell face
                y = (x.astype(np.float64) + field["offset"]) / field["scale"]
                interior = np.all(np.abs(y - np.round(y)) > 1e-4, axis=1)
                got, expect = got[interior], expect[interior]
            np.testing.assert_allclose(got, expect, atol=2e-6, err_msg=field["type"])


def _camera(res):
    return {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov": 36.0,
            "resolution": [res, res]}


def _gpis(bsdf, albedo, sampler=None, **fields):
    return {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.6},
            "mean": {"type": "sphere", "radius": 1.0},
            "kernel": {"type": "squared_exponential", "sigma": 1e-4, "length_scale": 0.2},
            "sampler": sampler or {"type": "weight_space", "features": 64},
            "bsdf": {"type": bsdf, "albedo": albedo}, **fields}


def _coverage(cam, sub=16):
    o, d = pixel_rays(cam, sub)
    return np.isfinite(hit_sphere(o, d, (0, 0, 0), 1.0)).mean(axis=-1)


@pytest.mark.parametrize("bsdf", ["diffuse", "mirror"])
def test03_constant_colour_on_a_convex_object(device, bsdf):
    """Under a unit environment an albedo-1 convex object (the sphere mean at sigma 1e-4)
    reflects light that never returns to it, so a covered pixel is c L = c exactly in
    expectation (deterministic for the mirror); half-covered pixels mix c and 1."""
    c = [0.5, 0.25, 0.875]
    cam = _camera(10)
    scene = {"camera": cam, "lights": [{"type": "environment", "radiance": 1.0}],
             "render": {"spp": 64, "seed": 11, "max_depth": 8},
             "shapes": [_gpis(bsdf, 1.0, color=c)]}
    res = render_result(scene, device=device)
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0, st.summary()
    cov = _coverage(cam)[..., None]
    expect = cov * np.asarray(c) + (1.0 - cov)
    img, se = res.image.mean.astype(float), res.image.stderr.astype(float)
    inside = cov[..., 0] == 1.0
    assert inside.sum() >= 16
    if bsdf == "mirror":
        np.testing.assert_allclose(img[inside], expect[inside], rtol=1e-5)
    else:
        # float32 rounding floors the error: the sky's hemisphere NEE and the cosine BSDF
        # sample share one density: a covered pixel is c in every sample
        z = np.abs(img[inside] - expect[inside]) / np.maximum(se[inside], 1e-6)
        assert z.max() < z_threshold(z.size), z.max()
        # the whole covered region at once: a small bias cannot hide in the noise
        total_se = np.sqrt((se[inside] ** 2).sum(0)) / inside.sum()
        bias = np.abs(img[inside].mean(0) - np.asarray(c))
        assert np.all(bias < z_threshold(3) * np.maximum(total_se, 1e-6)), (bias, total_se)


def test04_grid_colour_equals_its_constant_and_gradient_equivalents(device, tmp_path):
    """A grid of constant samples renders bit for bit like the constant colour (same
    random numbers, same weights); grids linear along x, y or z render like the gradient
    fields they sample (trilinear interpolation of a linear function is exact)."""
    c = [0.25, 0.5, 0.75]
    grid = tmp_path / "const.npz"
    save_rgb_grid(grid, np.broadcast_to(np.asarray(c), (2, 3, 4, 3)), [-2, -2, -2], 2.0)
    base = {"camera": _camera(8), "lights": [{"type": "environment", "radiance": 1.0}],
            "render": {"spp": 8, "seed": 2, "max_depth": 6,
                       "russian_roulette": {"start_depth": 100}}}
    img = {}
    for name, color in (("constant", c), ("grid", {"type": "grid", "file": str(grid)})):
        res = render_result({**base, "shapes": [_gpis("diffuse", 1.0, color=color)]},
                            device=device)
        img[name] = res.image.mean
    np.testing.assert_array_equal(img["grid"], img["constant"])

    # emission shows the field at the first hit only: an exact per-sample comparison
    dark = {**base, "lights": [{"type": "environment", "radiance": 0.0}]}
    a, b = [0.0, 0.25, 1.0], [1.0, 0.75, 0.0]
    for axis in range(3):
        start, end = [0.0] * 3, [0.0] * 3
        start[axis], end[axis] = -0.8, 0.8
        path = _linear_grid(tmp_path, f"lin{axis}.npz", axis, -0.8, 0.8, a, b)
        out = []
        for em in ({"type": "gradient", "start": start, "end": end, "a": a, "b": b},
                   {"type": "grid", "file": path}):
            res = render_result({**dark, "shapes": [_gpis("diffuse", 0.0, emission=em)]},
                                device=device)
            out.append(res.image.mean)
        assert out[0].max() > 0.5
        np.testing.assert_allclose(out[1], out[0], atol=2e-5, err_msg=f"axis {axis}")


@pytest.mark.parametrize("sampler", [{"type": "weight_space", "features": 64},
                                     {"type": "function_space"}],
                         ids=["weight_space", "function_space"])
def test05_emission_times_coverage(device, sampler):
    """A black-albedo emissive GPIS in a black world: every pixel is exactly E times the
    fraction of its samples that hit; at sigma 1e-4 that is the mean sphere's coverage."""
    E = np.asarray([2.0, 3.0, 0.5])
    cam = _camera(10)
    spp = 64
    scene = {"camera": cam, "lights": [{"type": "environment", "radiance": 0.0}],
             "render": {"spp": spp, "seed": 4, "max_depth": 4},
             "shapes": [_gpis("diffuse", 0.0, sampler=sampler, emission=E.tolist())]}
    res = render_result(scene, device=device)
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0, st.summary()
    img = res.image.mean.astype(float)
    hits = img / E                            # the fraction of samples that hit
    np.testing.assert_allclose(hits, hits[..., :1].repeat(3, -1), atol=1e-6)
    cov = _coverage(cam)
    frac = hits[..., 0]
    assert np.all(np.abs(frac * spp - np.round(frac * spp)) < 1e-4)   # whole samples
    np.testing.assert_array_equal(frac[cov == 1.0], 1.0)
    np.testing.assert_array_equal(frac[cov == 0.0], 0.0)
    # edge pixels: binomial sampling of the coverage (plus the 16x16 grid's own error)
    edge = (cov > 0) & (cov < 1)
    assert edge.sum() >= 8
    se = np.sqrt(cov[edge] * (1 - cov[edge]) / spp)
    total = abs(frac[edge].sum() - cov[edge].sum())
    assert total < z_threshold(1) * math.sqrt((se ** 2).sum()) + 0.01 * edge.sum()


def _load(tmp_path, gpis_fields):
    scene = {"shapes": [_gpis("diffuse", 0.5, **gpis_fields)],
             "lights": [{"type": "environment", "radiance": 1.0}]}
    return load_scene(scene)


BAD_GRIDS = [
    ("values", np.zeros((3, 3, 3)), "must be (nx, ny, nz, 3)"),
    ("values", np.zeros((1, 3, 3, 3)), "every n >= 2"),
    ("values", np.full((2, 2, 2, 3), np.nan), "NaN or infinite"),
    ("values", np.full((2, 2, 2, 3), -0.5), "must be >= 0"),
    ("values", np.full((2, 2, 2, 3), 1.5), "must be <= 1"),
    ("voxel_size", np.float64(-1.0), "'voxel_size' must be one positive number"),
    ("origin", np.zeros(2), "'origin' must be 3 finite numbers"),
]


@pytest.mark.parametrize("key,value,message", BAD_GRIDS,
                         ids=[f"{k}:{m[:12]}" for k, _, m in BAD_GRIDS])
def test06_bad_colour_grids_are_scene_errors(tmp_path, key, value, message):
    arrays = {"values": np.full((2, 2, 2, 3), 0.5), "origin": np.zeros(3),
              "voxel_size": np.float64(0.5)}
    arrays[key] = value
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(SceneError) as err:
        _load(tmp_path, {"color": {"type": "grid", "file": str(path)}})
    assert err.value.key == "shapes[0].color.file" and message in err.value.reason, str(err.value)


def test07_other_scene_errors(tmp_path):
    np.savez(tmp_path / "extra.npz", values=np.ones((2, 2, 2, 3)), origin=np.zeros(3),
             voxel_size=1.0, density=np.ones(3))
    cases = [
        ({"color": 1.5}, "shapes[0].color", "must be <= 1"),
        ({"emission": [-1, 0, 0]}, "shapes[0].emission[0]", "must be >= 0"),
        ({"color": {"type": "stripes"}}, "shapes[0].color.type", "unknown color type"),
        ({"emission": {"type": "gradient", "start": [0, 0, 0], "end": [0, 0, 0], "a": 1,
                       "b": 0}}, "shapes[0].emission.end", "must differ from start"),
        ({"color": {"type": "grid", "file": str(tmp_path / "extra.npz")}},
         "shapes[0].color.file", "unknown array(s) 'density'"),
        ({"color": {"type": "grid", "file": str(tmp_path / "missing.npz")}},
         "shapes[0].color.file", "file not found"),
        ({"color": "red"}, "shapes[0].color", "expected a number, a list of 3 numbers"),
    ]
    for fields, key, message in cases:
        with pytest.raises(SceneError) as err:
            _load(tmp_path, fields)
        assert err.value.key == key and message in err.value.reason, str(err.value)
    # emission grids may exceed 1; a resolved scene reloads to itself
    np.savez(tmp_path / "bright.npz", values=np.full((2, 2, 2, 3), 7.0), origin=np.zeros(3),
             voxel_size=1.0)
    scene = _load(tmp_path, {"emission": {"type": "grid", "file": str(tmp_path / "bright.npz")},
                             "color": 0.5})
    g = scene.data["shapes"][0]
    assert g["color"] == {"type": "constant", "value": [0.5, 0.5, 0.5]}
    assert load_scene(scene.data).data == scene.data
