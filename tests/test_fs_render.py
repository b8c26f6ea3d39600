"""Function-space GPIS rendered end to end: white furnace under every memory model,
batch-size independence, and the global model against the weight-space render."""

import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.testing.scenes import (MEMORIES, SUN_AND_SKY, function_space_sampler, gpis_scene,
                                   render_checked)
from gpiscl.testing.stats import assert_agree, image_mean_se, z_threshold

@pytest.mark.parametrize("bsdf", ["mirror", "diffuse"])
@pytest.mark.parametrize("memory", MEMORIES)
def test01_white_furnace(device, memory, bsdf):
    """Albedo 1 in a unit environment, roulette off: every pixel is 1. The mirror gives 1
    per path (zero variance: any lost or killed path shows exactly); the diffuse BSDF
    uses NEE + MIS, so it also checks that a shadow ray's 0/1 visibility has the same law
    as the escape of a continuation ray from the same vertex record."""
    env = [{"type": "environment", "radiance": 1.0}]
    res = render_checked(gpis_scene(function_space_sampler(memory), bsdf, 1.0, env, spp=16), device)
    img = res.image
    assert res.stats.killed_paths == 0, res.stats.summary()
    assert res.stats.rays > 1.5 * res.stats.paths   # the ball is hit, often repeatedly
    assert_agree(img.mean, img.stderr, np.ones_like(img.mean), block=4, what="furnace")
    if bsdf == "mirror":
        assert np.all(img.stderr == 0)


def test02_image_does_not_depend_on_the_batch_size(device):
    scene = gpis_scene(function_space_sampler("global"), "diffuse", 0.8,
                       [{"type": "environment", "radiance": 1.0}], spp=4)
    a = render_checked(scene, device).image.mean
    b = render_checked(scene, device, batch_size=333).image.mean
    np.testing.assert_array_equal(a, b)




def test03_global_memory_agrees_with_weight_space(device):
    """Weight space is the exact global model (one realization per path); function space
    with global memory must agree per pixel (z-test, Bonferroni) and in the image mean.
    Measured at 256 spp with the old uniform step (c = 0.9, ~1.7% of crossings missed) and cap 64
    leave a 0.3-0.5% offset in the image mean, c = 0.99 with cap 256 agrees to 0.1%; both
    are below this test's ~0.9% resolution (the image mean's standard error, channels
    taken as correlated: stats.image_mean_se). Renewal and renewal_plus forget the path
    between vertices: their difference is printed (1-2% here, see issue 4's note)."""
    spp = 32

    def image(sampler):
        return render_checked(gpis_scene(sampler, "diffuse", 0.9, SUN_AND_SKY, spp, seed=7,
                                         max_depth=64, rr_start=8), device).image

    ws = image({"type": "weight_space", "features": 256})
    imgs = {m: image(function_space_sampler(m, memory_cap=64))
            for m in ("global", "renewal_plus", "renewal")}
    g = imgs["global"]
    assert_agree(g.mean, g.stderr, ws.mean, ws.stderr, what="global vs weight space")
    for m, img in imgs.items():
        diff = img.mean.mean() - ws.mean.mean()
        se = image_mean_se(img.stderr, ws.stderr)
        print(f"{m}: image mean {img.mean.mean():.4f} vs weight space {ws.mean.mean():.4f}: "
              f"{diff / ws.mean.mean():+.2%} +- {se / ws.mean.mean():.2%}")
        if m == "global":
            assert abs(diff) < z_threshold(1) * se


@pytest.mark.parametrize("kernel", ["matern32", "matern52"])
def test03b_matern_global_memory_agrees_with_weight_space(device, kernel):
    """test03 for the Matern kernels: weight space with 1024 features of their Student-t
    spectra against function space's general conditional sampler (global memory), per
    pixel (z-test, Bonferroni) and in the image mean."""
    spp = 32
    k = {"type": kernel, "sigma": 0.3, "length_scale": 0.25}

    def render(sampler):
        scene = gpis_scene(sampler, "diffuse", 0.9, SUN_AND_SKY, spp, seed=7, max_depth=64,
                           rr_start=8)
        scene["shapes"][0]["kernel"] = k
        return render_checked(scene, device).image

    ws = render({"type": "weight_space", "features": 1024})
    g = render(function_space_sampler("global", memory_cap=64))
    assert_agree(g.mean, g.stderr, ws.mean, ws.stderr, what=f"{kernel} global vs weight space")
    diff = g.mean.mean() - ws.mean.mean()
    se = image_mean_se(g.stderr, ws.stderr)
    print(f"{kernel}: image mean {g.mean.mean():.4f} vs weight space {ws.mean.mean():.4f}: "
          f"{diff / ws.mean.mean():+.2%} +- {se / ws.mean.mean():.2%}")
    assert abs(diff) < z_threshold(1) * se


def test04_failed_free_flights_are_counted_and_reported(device):
    """A length scale far below the proxy size needs more than FS_MAX_STEPS steps (at
    most 2 length scales each, fs_march.h): each such ray is counted in gpis_failed and
    the summary says so. 4x4 pixels (was 6x6: 15 of 16 rays fail, 34 of 36, in 37% of
    the time; each costs FS_MAX_STEPS steps)."""
    scene = gpis_scene(function_space_sampler("renewal_plus"), "diffuse", 0.8,
                       [{"type": "environment", "radiance": 1.0}], spp=1)
    g = scene["shapes"][0]
    g["kernel"]["length_scale"] = 1e-5
    g["mean"] = {"type": "constant", "value": 10.0}
    g["bounds"] = {"occupancy": None}   # the bound would skip the whole far-outside proxy
    scene["camera"]["resolution"] = [4, 4]   # each failing ray costs FS_MAX_STEPS steps
    res = render_result(scene, device=device)
    assert res.stats.gpis_failed > 0.5 * 4 * 4 * 0.4   # rays through the proxy
    assert "failed GPIS flights" in res.stats.summary()
    np.testing.assert_allclose(res.image.mean, 1.0, rtol=1e-6)   # failed: no hit


KERNELS = {"thin_plate": {"type": "thin_plate", "sigma": 0.04, "radius": 4.0},
           "rq_aniso": {"type": "rational_quadratic", "sigma": 0.3, "length_scale": 0.25,
                        "alpha": 0.75, "aniso": [1, 0.5, 2]},
           "periodic": {"type": "periodic", "sigma": 0.2, "length_scale": 1.0, "w": 1.0},
           "locally_periodic": {"type": "locally_periodic", "sigma": 0.2, "length_scale": 1.0,
                                "w": 1.0, "se_length_scale": 0.5},
           "matern32": {"type": "matern32", "sigma": 0.3, "length_scale": 0.25},
           "matern52": {"type": "matern52", "sigma": 0.3, "length_scale": 0.2,
                        "aniso": [1, 0.5, 2]}}


@pytest.mark.parametrize("memory", ["renewal_plus", "global"])
@pytest.mark.parametrize("kernel", KERNELS)
def test05_mirror_furnace_for_every_kernel(device, kernel, memory):
    """Anisotropic and product kernels take the general gradient conditional (no closed
    form), thin-plate the bisection step rule: still exactly 1 per path."""
    scene = gpis_scene(function_space_sampler(memory), "mirror", 1.0,
                       [{"type": "environment", "radiance": 1.0}], spp=4)
    scene["shapes"][0]["kernel"] = KERNELS[kernel]
    res = render_checked(scene, device)
    assert res.stats.killed_paths == 0 and res.stats.rays > 1.2 * res.stats.paths
    np.testing.assert_allclose(res.image.mean, 1.0, rtol=1e-6)


@pytest.mark.parametrize("bsdf", ["mirror", "diffuse"])
def test06_furnace_with_overlapping_objects_and_a_surface_inside(device, bsdf):
    """Two overlapping function-space objects (global and renewal memory) and a sphere
    inside a proxy: memory resets at other events, per-object random streams, and the
    two scratch slices that keep the winning object's rows (global ring)."""
    env = [{"type": "environment", "radiance": 1.0}]
    scene = gpis_scene(function_space_sampler("global"), bsdf, 1.0, env, spp=16)
    second = dict(scene["shapes"][0], sampler=function_space_sampler("renewal"))
    second["proxy"] = {"type": "sphere", "center": [0.6, 0.3, 0.0], "radius": 0.8}
    second["mean"] = {"type": "sphere", "center": [0.6, 0.3, 0.0], "radius": 0.4}
    scene["shapes"] += [second, {"type": "sphere", "center": [-0.5, -0.6, 0.4], "radius": 0.3,
                                 "bsdf": {"type": bsdf, "albedo": 1.0}}]
    res = render_checked(scene, device)
    img = res.image
    assert res.stats.killed_paths == 0
    assert_agree(img.mean, img.stderr, np.ones_like(img.mean), block=4, what="furnace")
