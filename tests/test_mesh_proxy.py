"""Convex mesh proxies (scene/proxies.py, gpis_proxy.h): the device clips rays to exactly the
convex mesh, non-convex or open meshes are errors, and a mesh box bounds a GPIS like a box."""

import numpy as np
import pyopencl as cl
import pytest
import trimesh

from gpiscl import load_scene, render_result
from gpiscl.host.layout import records as layouts
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.host.scene.proxies import analyse
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.transforms import euler_matrix
from gpiscl.testing.stats import assert_agree
from gpiscl.testing.wrappers import OCCUPANCY_CLIP_WRAPPER, program

ROTATE, TRANSLATE, EXTENT = [20.0, -35.0, 10.0], [0.3, -0.2, 0.5], [1.2, 0.8, 1.6]


def box_mesh(tmp_path):
    path = tmp_path / "box.obj"
    trimesh.creation.box(extents=EXTENT).export(path)
    return {"type": "mesh", "file": str(path),
            "transform": {"scale": 1.0, "rotate": ROTATE, "translate": TRANSLATE}}


def slab_interval(o, d):
    """Ray parameters inside the rotated box, by the slab test in the box's own frame, and
    |cos| between the ray and the faces that bound it at each end."""
    R = euler_matrix(ROTATE)
    ol, dl = (o - TRANSLATE) @ R, d @ R          # R^T applied to row vectors
    half = np.asarray(EXTENT) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (-half - ol) / dl, (half - ol) / dl
    near, far = np.minimum(a, b), np.maximum(a, b)
    cos = np.abs(dl) / np.linalg.norm(d, axis=1, keepdims=True)
    rows = np.arange(len(o))
    return (near.max(1), far.min(1), cos[rows, near.argmax(1)], cos[rows, far.argmin(1)])


def test_device_clip_is_the_slab_interval_of_the_rotated_box(device, tmp_path):
    proxy = box_mesh(tmp_path)
    planes = analyse(proxy)[0]
    assert len(planes) == 6
    g = layouts.GPIS_OBJECT.zeros(1)
    g["proxy_kind"] = layouts.GPIS_PROXIES["mesh"]
    g["proxy_first"], g["proxy_count"] = 0, len(planes)
    rng = np.random.default_rng(3)
    n = 4096
    o = rng.uniform(-2.5, 2.5, (n, 3))
    o[: n // 8] = rng.uniform(-0.3, 0.3, (n // 8, 3)) + TRANSLATE  # some start inside
    target = np.asarray(TRANSLATE) + rng.uniform(-1.2, 1.2, (n, 3))
    d = (target - o) * rng.uniform(0.5, 2.0, (n, 1))   # t need not be arc length
    src = join_sources((), ("gpis_proxy.h",)) + OCCUPANCY_CLIP_WRAPPER
    kern = program(device.ctx, src, [f"-I{PYOPENCL_CL_DIR}"])["occ_clip_k"]
    mf = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    bufs = [cl.Buffer(device.ctx, mf, hostbuf=np.ascontiguousarray(a))
            for a in (g, np.zeros(1, np.float32), np.zeros(1, np.uint32),
                      planes.astype(np.float32), o.astype(np.float32), d.astype(np.float32))]
    out = np.empty((n, 4), np.float32)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    kern(device.queue, (n,), None, *bufs, np.int32(1), ob)
    cl.enqueue_copy(device.queue, out, ob)
    lo, hi, cos_lo, cos_hi = slab_interval(o, d)
    started_inside = lo < 0.0
    lo, hi = np.maximum(lo, 0.0), np.minimum(hi, 1e30)
    inside = lo < hi
    hit = np.isfinite(out[:, 0])
    # grazing rays (chord within float rounding) may go either way
    sure = np.abs(hi - lo) > 1e-4
    assert np.array_equal(hit[sure], inside[sure])
    assert 0.2 < inside.mean() < 0.9
    both = hit & inside
    scale = np.linalg.norm(d[both], axis=1)
    # float32 planes and arithmetic: a few ulps of the plane offsets and of o.n, stretched
    # by 1 / |cos| of the angle between the ray and the bounding face
    ulps = 16 * np.finfo(np.float32).eps * (1.0 + np.linalg.norm(o[both], axis=1) + 2.0)
    err_lo = np.abs(out[both, 0] - lo[both]) * scale
    err_hi = np.abs(out[both, 1] - hi[both]) * scale
    assert np.all(err_lo[~started_inside[both]] <= (ulps / cos_lo[both])[~started_inside[both]])
    assert np.all(err_hi <= ulps / cos_hi[both])


def gpis_scene(proxy):
    # 64 spp: at 32 the box-vs-sphere contrast below was borderline (block z 4.2 against
    # a threshold of 4.4) once function space drew hit slopes from their exact law
    return {"camera": {"position": [0, 0.4, 4], "look_at": [0, 0, 0], "fov": 36,
                       "resolution": [16, 16]},
            "render": {"spp": 64, "seed": 4, "max_depth": 6},
            "lights": [{"type": "environment", "radiance": 0.05},
                       {"type": "directional", "direction": [1, 1, 1], "irradiance": 2.0}],
            "shapes": [{"type": "gpis", "proxy": proxy, "mean": {"type": "constant", "value": 0.0},
                        "kernel": {"type": "squared_exponential", "sigma": 0.6,
                                   "length_scale": 0.15},
                        "sampler": {"type": "function_space"},
                        "bsdf": {"type": "diffuse", "albedo": 0.8}}]}


def test_a_box_mesh_proxy_bounds_like_the_box(device, tmp_path):
    """A volume-type GPIS (constant mean) fills its proxy, so the proxy's shape is what the
    picture shows: an axis-aligned box mesh renders like the box proxy (z-test per pixel),
    and unlike a sphere of similar size."""
    path = tmp_path / "cube.obj"
    mesh = trimesh.creation.box(extents=[1.6, 1.2, 1.4])
    mesh.apply_translation([0.1, -0.1, 0.0])
    mesh.export(path)
    as_mesh = render_result(gpis_scene({"type": "mesh", "file": str(path)}), device=device)
    as_box = render_result(gpis_scene({"type": "box", "min": [-0.7, -0.7, -0.7],
                                       "max": [0.9, 0.5, 0.7]}), device=device)
    assert as_mesh.stats.gpis_failed == 0
    assert_agree(as_mesh.image.mean, as_mesh.image.stderr, as_box.image.mean,
                 as_box.image.stderr, block=2, what="box mesh proxy vs box proxy")
    sphere = render_result(gpis_scene({"type": "sphere", "center": [0.1, -0.1, 0],
                                       "radius": 0.8}), device=device)
    with pytest.raises(AssertionError):
        assert_agree(as_mesh.image.mean, as_mesh.image.stderr, sphere.image.mean,
                     sphere.image.stderr, block=2)


@pytest.mark.parametrize("make,reason", [
    (lambda: trimesh.creation.torus(1.0, 0.3), "must be convex"),
    (lambda: trimesh.Trimesh(trimesh.creation.box().vertices,
                             trimesh.creation.box().faces[:-2]), "closed"),
])
def test_non_convex_or_open_meshes_are_errors(tmp_path, make, reason):
    path = tmp_path / "m.obj"
    make().export(path)
    scene = gpis_scene({"type": "mesh", "file": str(path)})
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    assert info.value.key == "shapes[0].proxy.file" and reason in info.value.reason
