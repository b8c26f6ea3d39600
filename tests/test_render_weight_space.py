"""Weight-space GPIS in full renders: furnace, the sigma -> 0 limit, one fixed realization
against a numpy ray cast of the same features, and the surface-type slope law.

Tolerances are z-tests against the films' own standard errors or the sample counts
(gpiscl/testing/stats.py); seeds are fixed so the tests repeat exactly.
"""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl import render_result
from gpiscl.host.gp import Matern52, Plane, Sphere, SquaredExponential
from gpiscl.host.gp import spectral
from gpiscl.testing.reference import weight_space as ws
from gpiscl.host.layout.gp_records import pack_kernel, pack_mean
from gpiscl.testing.reference.camera import pixel_rays
from gpiscl.testing.stats import assert_agree, image_mean_se, z_threshold
from gpiscl.testing.scenes import camera
from gpiscl.testing.weight_space import build
from gpiscl.testing.wrappers import buffer

KERNELS = {
    "squared_exponential": {"sigma": 0.1, "length_scale": 0.2},
    "rational_quadratic": {"sigma": 0.1, "length_scale": 0.2, "alpha": 1.0},
    "periodic": {"sigma": 0.1, "length_scale": 1.0, "w": 8.0},
    "locally_periodic": {"sigma": 0.1, "length_scale": 1.0, "w": 8.0, "se_length_scale": 0.3},
    "matern32": {"sigma": 0.1, "length_scale": 0.2},
    "matern52": {"sigma": 0.1, "length_scale": 0.2},
}


def gpis(kernel, bsdf, albedo, sigma=None, features=64, radius=1.0):
    k = {"type": kernel, **KERNELS[kernel]}
    if sigma is not None:
        k["sigma"] = sigma
    return {"type": "gpis", "proxy": {"type": "sphere", "radius": radius + 0.6},
            "mean": {"type": "sphere", "radius": radius}, "kernel": k,
            "sampler": {"type": "weight_space", "features": features},
            "bsdf": {"type": bsdf, "albedo": albedo}}


@pytest.mark.parametrize("bsdf", ["diffuse", "mirror"])
@pytest.mark.parametrize("kernel", sorted(KERNELS))
def test_white_furnace(device, kernel, bsdf):
    """An albedo-1 micro-BSDF in a unit environment is invisible for every kernel: light
    is only redirected, so each pixel is 1 unless a path is killed (counted)."""
    scene = {"camera": camera(12), "lights": [{"type": "environment", "radiance": 1.0}],
             "render": {"spp": 16, "seed": 3, "max_depth": 256,
                        "russian_roulette": {"start_depth": 1000}},
             "shapes": [gpis(kernel, bsdf, 1.0)]}
    res = render_result(scene, device=device)
    st = res.stats
    assert st.nan_paths == 0 and st.truncated_paths == 0
    assert st.gpis_failed == 0, st.summary()
    # a down-crossing's gradient faces the ray, so no path may be killed (each would
    # darken its pixel by 1 and is counted in the summary)
    assert st.killed_paths == 0, st.summary()
    img = res.image
    # 4x4 blocks (256 samples each) keep the sample variance a trustworthy estimate
    assert_agree(img.mean, img.stderr, np.ones_like(img.mean), block=4,
                 what=f"{kernel} {bsdf} furnace")
    # the whole image at once is the sharper test of a small bias
    se = image_mean_se(img.stderr)
    assert abs(img.mean.mean() - 1.0) <= z_threshold(1) * se


def test_small_sigma_converges_to_the_mean_surface(device):
    """sigma -> 0: the GPIS is its mean's sphere with the micro-BSDF as its BSDF."""
    lights = [{"type": "environment", "radiance": 0.5},
              {"type": "directional", "direction": [1, 1, 1], "irradiance": 3.0}]
    render = {"spp": 64, "seed": 5, "max_depth": 8}
    albedo = [0.7, 0.5, 0.3]
    base = {"camera": camera(16), "lights": lights, "render": render}
    g = render_result({**base, "shapes": [gpis("squared_exponential", "diffuse", albedo,
                                                 sigma=1e-4)]}, device=device)
    s = render_result({**base, "shapes": [{"type": "sphere", "radius": 1.0,
                                           "bsdf": {"type": "diffuse", "albedo": albedo}}]},
                      device=device)
    assert g.stats.gpis_failed == 0 and g.stats.killed_paths == 0
    assert_agree(g.image.mean, g.image.stderr, s.image.mean, s.image.stderr, block=2,
                 what="sigma -> 0 against the mean surface")
    # and the test can see a difference that matters: a grey sphere is not the limit
    grey = render_result({**base, "shapes": [{"type": "sphere", "radius": 1.0,
                                              "bsdf": {"type": "diffuse", "albedo": 0.5}}]},
                         device=device)
    with pytest.raises(AssertionError):
        assert_agree(g.image.mean, g.image.stderr, grey.image.mean, grey.image.stderr,
                     block=2)


def _numpy_escape_fraction(kernel, key, m, cam, sub, proxy_radius, mean):
    """Fraction of a sub x sub ray grid per pixel that misses the realization (numpy)."""
    theta, tau, w = ws.regenerate_features(kernel, key, 0, m)
    o, d = pixel_rays(cam, sub)
    h, wd = d.shape[:2]
    d = d.reshape(-1, 3)
    b = d @ o
    disc = b * b - (o @ o - proxy_radius**2)
    inside = disc > 0
    t0 = -b - np.sqrt(np.maximum(disc, 0))
    t1 = -b + np.sqrt(np.maximum(disc, 0))
    dt = kernel.length_scale / 16
    steps = int(math.ceil(2 * proxy_radius / dt)) + 1
    hit = np.zeros(len(d), bool)
    for chunk in np.array_split(np.flatnonzero(inside), 16):
        s = np.linspace(0, 1, steps)[None, :]
        t = t0[chunk, None] + s * (t1 - t0)[chunk, None]
        x = o + t[..., None] * d[chunk, None, :]
        f = ws.evaluate_value(theta, tau, w, kernel.variance, x, mean)
        _, t_hi = ws.dense_scan_first_root(f, np.arange(steps))
        hit[chunk] = np.isfinite(t_hi)
    return 1.0 - hit.reshape(h, wd, sub * sub).mean(axis=2)


@pytest.mark.long
def test_fixed_realization_matches_a_numpy_ray_cast(device, long_run):
    """--realization R: every pixel sees the same geometry, the realization the numpy twin
    regenerates from key (R, 0xffffffff); a black GPIS in a unit environment shows its
    silhouette, i.e. the escape fraction of each pixel. The short form casts 12x12 pixels
    (the numpy cast is the cost), the long form 16x16."""
    res_px, spp, sub, m, R = (16 if long_run else 12), 64, 6, 64, 11
    kernel = SquaredExponential(sigma=0.15, length_scale=0.25)
    cam = camera(res_px)
    scene = {"camera": cam, "lights": [{"type": "environment", "radiance": 1.0}],
             "render": {"spp": spp, "seed": 2, "max_depth": 4},
             "shapes": [{"type": "gpis", "proxy": {"type": "sphere", "radius": 1.6},
                         "mean": {"type": "sphere", "radius": 1.0},
                         "kernel": {"type": "squared_exponential", "sigma": 0.15,
                                    "length_scale": 0.25},
                         "sampler": {"type": "weight_space", "features": m},
                         "bsdf": {"type": "diffuse", "albedo": 0.0}}]}
    img = render_result(scene, device=device, realization=R).image.mean[..., 0]
    ref = _numpy_escape_fraction(kernel, (R, 0xFFFFFFFF), m, cam, sub, 1.6, Sphere())
    # jittered samples vs a sub x sub grid: binomial noise plus at most ~1/sub of
    # quadrature error where an edge crosses the pixel
    z = z_threshold(img.size)
    tol = z * np.sqrt(np.maximum(ref * (1 - ref), 0.25 / sub**2) / spp) + 1.0 / sub
    assert np.all(np.abs(img - ref) <= tol), np.abs(img - ref).max()
    assert 0.2 < ref.mean() < 0.9  # the silhouette is in the picture
    other = render_result(scene, device=device, realization=R + 1).image.mean[..., 0]
    assert np.sum(np.abs(other - img) > 0.5) >= 3  # another realization, other geometry


SLOPE_KERNEL = r"""
__kernel void first_hit_normals(__global const GpKernel* kp, __global const MeanNode* mean,
                                int mc, __global const float* cdf, int nc, int M,
                                __global const float* o, float tol, __global float4* out)
{
    int r = get_global_id(0), status;
    float3 n;
    float t = ws_first_root(kp[0], mean, mc, cdf, nc, M, (uint2)((uint)r, 99u), 0,
                            vload3(r, o), (float3)(0.0f, -1.0f, 0.0f), 0.0f, 2.0f, tol, &n,
                            &status);
    out[r] = (float4)(n, status ? -1.0f : t);
}
"""


@pytest.mark.parametrize("kind", ["squared_exponential", "matern52"])
def test_surface_type_slopes_follow_the_beckmann_law(device, kind):
    """Plane mean y, small sigma / l: the surface is the height field y = -g(x, z), and
    vertical rays hit it uniformly in (x, z), so hit normals have slopes
    n_x / n_y = g_x ~ N(0, sigma^2 a_x / l^2) (our SE convention, A = diag(aniso)) up to
    O(sigma^2 / l^2): a Beckmann distribution of roughness alpha_i^2 = 2 sigma^2 a_i / l^2.
    Matern 5/2: -k''(0) = 5 sigma^2 a_x / (3 l^2) instead."""
    sigma, ell, aniso, m, n = 0.004, 0.2, (1.0, 1.0, 4.0), 256, 20000
    if kind == "matern52":
        kernel, factor = Matern52(sigma=sigma, length_scale=ell, aniso=aniso), 5.0 / 3.0
    else:
        kernel, factor = SquaredExponential(sigma=sigma, length_scale=ell, aniso=aniso), 1.0
    prg = build(device, SLOPE_KERNEL)
    rng = np.random.default_rng(4)
    o = np.stack([rng.uniform(-5, 5, n), np.full(n, 0.5), rng.uniform(-5, 5, n)], -1)
    nodes = pack_mean(Plane(normal=(0.0, 1.0, 0.0)))
    cdf = spectral.order_table(kernel)
    out = np.empty((n, 4), np.float32)
    out_buf = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["first_hit_normals"](device.queue, (n,), None, buffer(device, pack_kernel(kernel)),
                             buffer(device, nodes), np.int32(len(nodes)), buffer(device, cdf),
                             np.int32(len(cdf)), np.int32(m), buffer(device, o.astype(np.float32)),
                             np.float32(1e-5), out_buf)
    cl.enqueue_copy(device.queue, out, out_buf)
    t = out[:, 3]
    assert np.all((t > 0.4) & (t < 0.6)), "every vertical ray hits near y = 0"
    z = z_threshold(4)
    for axis, a in ((0, aniso[0]), (2, aniso[2])):
        slope = out[:, axis].astype(float) / out[:, 1]
        var = factor * sigma**2 * a / ell**2
        # sampling error of a variance estimate (Gaussian slopes: sd = var sqrt(2 / n)) and
        # the O(var^2) height-field terms (1 + g_y)^-2 ~ 1 + 3 var
        est = np.mean(slope**2)
        assert abs(est - var) < z * var * math.sqrt(2 / n) + 4 * var * var, (axis, est, var)
        # the shape is Gaussian: chi-square over 10 equiprobable bins
        from statistics import NormalDist
        edges = [NormalDist(0, math.sqrt(var)).inv_cdf(q) for q in np.arange(1, 10) / 10]
        counts = np.bincount(np.searchsorted(edges, slope), minlength=10)
        chi2 = float(np.sum((counts - n / 10) ** 2 / (n / 10)))
        assert chi2 < 40.0, (axis, chi2)  # P(chi2_9 > 40) ~ 7e-6


def test_a_fixed_realization_needs_weight_space(device):
    from gpiscl.host.errors import SceneError
    shape = gpis("squared_exponential", "diffuse", 0.5)
    shape["sampler"] = {"type": "function_space"}
    scene = {"camera": camera(4), "lights": [{"type": "environment"}], "shapes": [shape]}
    with pytest.raises(SceneError) as info:
        render_result(scene, device=device, realization=1)
    assert info.value.key == "render.realization" and "function_space" in info.value.reason
