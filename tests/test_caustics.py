"""Manifold next-event estimation through classical mirror spheres (lib/caustics.h): the
reflection point and its Jacobian against a numpy ray trace, and renders of a floor lit
only by a light's reflection in a mirror sphere against BSDF sampling alone (the old
estimator), per 4x4 block and over the whole image, with GPIS in the way of the two shadow
segments in weight space and in function space."""

import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.render.integrator import WavefrontIntegrator
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.host.scene.loading import load_scene
from gpiscl.testing.scenes import function_space_sampler
from gpiscl.testing.stats import assert_agree, image_mean_se, z_threshold
from gpiscl.testing.wrappers import program

WRAPPER = r"""
__kernel void reflection(__global const float* sphere, __global const float* x,
                         __global const float* y, __global const float* nl,
                         __global float* out, int count)
{
    int i = get_global_id(0);
    if (i >= count) return;
    float3 p = (float3)(0.0f), n = (float3)(0.0f);
    bool ok = caustic_reflection_point(vload3(0, sphere), sphere[3], vload3(i, x),
                                       vload3(i, y), &p, &n);
    float J = ok ? caustic_jacobian(vload3(i, x), p, n, sphere[3], vload3(i, y),
                                    vload3(i, nl)) : 0.0f;
    __global float* o = out + 8 * i;
    vstore4((float4)(p, ok ? 1.0f : 0.0f), 0, o);
    vstore4((float4)(n, J), 1, o);
}
"""
CENTER, RADIUS = np.array([0.2, 0.1, -0.3]), 0.6


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _device_reflection(device, x, y, nl):
    prg = program(device.ctx, join_sources([]) + WRAPPER, [f"-I{PYOPENCL_CL_DIR}"])
    f32 = [np.ascontiguousarray(a, np.float32) for a in
           (np.array([*CENTER, RADIUS]), x, y, nl)]
    bufs = [cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                      hostbuf=a) for a in f32]
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 32 * len(x))
    prg["reflection"](device.queue, (len(x),), None, *bufs, out, np.int32(len(x)))
    res = np.empty((len(x), 8), np.float32)
    cl.enqueue_copy(device.queue, res, out)
    return res.astype(np.float64)


def _reflect_to_plane(x, d, y, nl):
    """Where the ray x + t d, reflected by the sphere, meets the plane through y with
    normal nl (float64; NaN where it misses the sphere)."""
    oc = x - CENTER
    b = np.sum(oc * d, -1)
    disc = b * b - (np.sum(oc * oc, -1) - RADIUS**2)
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    p = x + t[:, None] * d
    n = (p - CENTER) / RADIUS
    r = d - 2 * np.sum(d * n, -1, keepdims=True) * n
    s = np.sum((y - p) * nl, -1) / np.sum(r * nl, -1)
    return p + s[:, None] * r


def test_reflection_point_and_jacobian_against_a_numpy_trace(device):
    """Random x, y outside the sphere: where the device finds p, it lies on the sphere
    and reflects x's ray towards y; its |d omega_x / d A_y| matches central differences of
    a float64 trace of rays about x -> p onto y's plane (a random normal nl)."""
    rng = np.random.default_rng(5)
    count = 3000
    x = CENTER + _unit(rng.normal(size=(count, 3))) * rng.uniform(0.7, 4, (count, 1))
    y = CENTER + _unit(rng.normal(size=(count, 3))) * rng.uniform(0.7, 4, (count, 1))
    nl = _unit(rng.normal(size=(count, 3)))
    res = _device_reflection(device, x, y, nl)
    ok = res[:, 3] > 0
    assert 0.3 < ok.mean() < 0.9, ok.mean()   # pairs on opposite sides have none
    p, n, J = res[ok, :3], res[ok, 4:7], res[ok, 7]
    xo, yo, nlo = x[ok], y[ok], nl[ok]
    np.testing.assert_allclose(np.linalg.norm(p - CENTER, axis=-1), RADIUS, rtol=1e-5)
    d = _unit(p - xo)
    r = d - 2 * np.sum(d * n, -1, keepdims=True) * n
    assert np.all(np.sum(r * _unit(yo - p), -1) > 1 - 1e-5)
    assert np.all(np.sum(n * _unit(xo - p), -1) > 0)
    # central differences of the plane hit over two directions across d
    e1 = _unit(np.cross(d, rng.normal(size=d.shape)))
    e2 = np.cross(d, e1)
    h = 1e-5
    dy = [(_reflect_to_plane(xo, _unit(d + h * e), yo, nlo)
           - _reflect_to_plane(xo, _unit(d - h * e), yo, nlo)) / (2 * h) for e in (e1, e2)]
    area = np.linalg.norm(np.cross(dy[0], dy[1]), axis=-1)
    # away from grazing the sphere or the plane, where neither float32 nor differences
    # resolve it
    fine = (np.isfinite(area) & (np.abs(np.sum(n * d, -1)) > 0.05)
            & (np.abs(np.sum(r * nlo, -1)) > 0.05))
    assert fine.mean() > 0.9
    np.testing.assert_allclose(J[fine] * area[fine], 1.0, rtol=2e-3)


# A floor lit only by a light's reflection in a mirror sphere: the light faces up, below
# the sphere, so the floor sees its back (one-sided: dark) and gets its light after one
# mirror bounce, which BSDF sampling finds rarely (the old estimator's fireflies).
def caustic_scene(spp, seed, sphere_bsdf, blocker=None):
    shapes = [{"type": "rectangle", "center": [0, 0, 0], "u": [4, 0, 0], "v": [0, 0, -4],
               "bsdf": {"type": "diffuse", "albedo": 0.8}},
              {"type": "sphere", "center": [0, 1.2, 0], "radius": 0.5, "bsdf": sphere_bsdf}]
    if blocker is not None:   # a rough GPIS ball in the way of both segments, some paths'
        shapes.append({"type": "gpis",
                       "proxy": {"type": "sphere", "center": [0.45, 0.5, 0.0],
                                 "radius": 0.32},
                       "mean": {"type": "sphere", "center": [0.45, 0.5, 0.0],
                                "radius": 0.18},
                       "kernel": {"type": "squared_exponential", "sigma": 0.05,
                                  "length_scale": 0.1},
                       "sampler": blocker, "bsdf": {"type": "diffuse", "albedo": 0.5}})
    return {"camera": {"position": [1.4, 3.0, 0.5], "look_at": [1.4, 0, 0], "up": [0, 0, -1],
                       "fov": 26, "resolution": [24, 24]},
            "render": {"spp": spp, "seed": seed, "max_depth": 3},
            "shapes": shapes,
            "lights": [{"type": "rectangle", "center": [0.1, 0.3, 0], "u": [1.0, 0, 0],
                        "v": [0, 0, -1.0], "radiance": [30.0, 25.0, 20.0]}]}


def render(device, scene, caustic_nee):
    data = load_scene(scene).data
    res = WavefrontIntegrator(device, compile_scene(data),
                              {**data["render"], "caustic_nee": caustic_nee}, None).render(
                                  data["render"]["spp"])
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0 and st.truncated_paths == 0, st.summary()
    return res


GOLD = {"type": "mirror", "material": "Au"}


@pytest.mark.long
@pytest.mark.parametrize("sphere_bsdf,blocker", [
    ({"type": "mirror", "albedo": 0.9}, None),
    (GOLD, {"type": "weight_space"}),
    (GOLD, function_space_sampler("renewal_plus")),
], ids=["classical", "weight-space-blocker", "function-space-blocker"])
def test_caustics_agree_with_bsdf_sampling(device, long_run, sphere_bsdf, blocker):
    """Independent seeds; the old estimator at 8x the samples (its variance is what limits
    the test). Measured at 256 spp: the Jacobian 1.1x off fails the whole image (z 8.2
    classical, 3.4 with a blocker); BSDF's copies of the paths left in emission.cl (counted
    twice) fail blocks in all three (|z| 5.5-6.3); survivors of the second roulette stage
    not divided by q fail all three (block |z| 5.8-9.4, image z -5.9), of the first two of
    three (4.9, 7.8); a tail blocked by the GPIS but not by shadow_rays.cl fails both
    blocker scenes (image z 3.7, 5.5)."""
    spp = 1024 if long_run else 256
    new = render(device, caustic_scene(spp, 11, sphere_bsdf, blocker), True)
    old = render(device, caustic_scene(8 * spp, 12, sphere_bsdf, blocker), False)
    a, b = new.image, old.image
    assert b.mean.mean() > 0.02, "the reflected light reaches the floor"
    assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=4, what="manifold NEE vs BSDF")
    z = (a.mean.mean() - b.mean.mean()) / image_mean_se(a.stderr, b.stderr)
    assert abs(z) < z_threshold(1), f"manifold NEE vs BSDF, whole image: z {z:.2f}"
    # the point of it: per-sample variance far below BSDF sampling's
    var_new = np.median(a.stderr**2) * spp
    var_old = np.median(b.stderr**2) * 8 * spp
    assert var_new < 0.5 * var_old, (var_new, var_old)


def test_a_vertex_inside_a_mirror_sphere_keeps_its_reflected_light(device):
    """A floor and a light inside a closed mirror sphere (the light faces away from the
    floor, which it lights only through the concave mirror, several reflection points a
    pair): the manifold sample has nothing there, so BSDF sampling must keep those paths.
    Measured with the sphere's inside counted like its outside (scatter.cl): image z -39.9."""
    scene = {"camera": {"position": [0, 0.5, 2.0], "look_at": [0, -1, 0], "up": [0, 1, 0],
                        "fov": 50, "resolution": [16, 16]},
             "render": {"spp": 128, "seed": 5, "max_depth": 3},
             "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 3.0,
                         "bsdf": {"type": "mirror", "albedo": 0.9}},
                        {"type": "rectangle", "center": [0, -1, 0], "u": [2, 0, 0],
                         "v": [0, 0, -2], "bsdf": {"type": "diffuse", "albedo": 0.8}}],
             "lights": [{"type": "rectangle", "center": [0, 1, 0], "u": [0.6, 0, 0],
                         "v": [0, 0, -0.6], "radiance": [5.0, 5.0, 5.0]}]}
    new = render(device, scene, True).image
    scene["render"]["seed"] = 6
    old = render(device, scene, False).image
    assert old.mean.mean() > 0.05, "the light reaches the floor through the mirror"
    z = (new.mean.mean() - old.mean.mean()) / image_mean_se(new.stderr, old.stderr)
    assert abs(z) < z_threshold(1), f"inside a mirror sphere: image z {z:.2f}"
