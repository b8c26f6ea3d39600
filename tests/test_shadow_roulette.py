"""Russian roulette on the shadow rays of light samples that pick the normal at
function-space mirrors and rough conductors (fs_random_normal.h
fs_random_normal_shadow_survival, scatter.cl): the image with it equals the image without
it (the old estimator), per 4x4 block and over the whole image, while most shadow rays are
gone; a roulette that forgets to divide a survivor by q fails (measured in the docstring)."""

import numpy as np
import pytest

from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.render.integrator import SHADOW_ROULETTE, WavefrontIntegrator
from gpiscl.host.scene.loading import load_scene
from gpiscl.testing.scenes import function_space_sampler, gpis_scene
from gpiscl.testing.stats import assert_agree, image_mean_se, z_threshold

MIRROR = {"type": "mirror", "albedo": 0.9}
CONDUCTOR = {"type": "rough_conductor", "material": "Au", "roughness": 0.3}
# a 3 degree sun (light samples find it through the normal's law only) and a dim sky,
# which the mirror leaves to BSDF sampling: most of the sun's samples land in the tails
LIGHTS = [{"type": "directional", "direction": [0.5, 0.8, 0.6], "irradiance": 3.0,
           "angular_radius": 3.0},
          {"type": "environment", "radiance": 0.3}]


def render(bsdf, threshold, spp, seed, device):
    scene = gpis_scene(function_space_sampler("renewal_plus"), "mirror", 0.9, LIGHTS, spp=spp,
                       seed=seed, max_depth=16, rr_start=3)
    # smoother than gpis_scene's ball (normals spread by ~18 degrees), so that the box proxy
    # does not cut it
    scene["shapes"][0]["kernel"] = {"type": "squared_exponential", "sigma": 0.1,
                                    "length_scale": 0.3}
    scene["shapes"][0]["bsdf"] = bsdf
    data = load_scene(scene).data
    settings = {**data["render"], "shadow_roulette": threshold}
    res = WavefrontIntegrator(device, compile_scene(data), settings, None).render(spp)
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0 and st.truncated_paths == 0, st.summary()
    return res


@pytest.mark.parametrize("bsdf", [MIRROR, CONDUCTOR], ids=["mirror", "conductor"])
@pytest.mark.parametrize("threshold", [SHADOW_ROULETTE, 1.0], ids=["default", "strong"])
def test_roulette_keeps_the_image_and_drops_shadow_rays(device, long_run, bsdf, threshold):
    """Roulette at the renderer's threshold and at a strong one (1: every light sample
    worth less than a white Lambertian's reflection of it) against none, independent
    seeds, 256 spp. Measured with survivors not divided by q: the mirror fails at both
    thresholds (largest block |z| 9.1 and 42.6, threshold 4.3; image z -3.6 and -23.4),
    the conductor at the strong one (block 9.4, image -12.7; at the default its lost
    light is within noise, block 1.7)."""
    spp = 1024 if long_run else 256
    new = render(bsdf, threshold, spp, 31, device)
    old = render(bsdf, 0.0, spp, 32, device)
    assert new.stats.shadow_rays < 0.7 * old.stats.shadow_rays, \
        (new.stats.shadow_rays, old.stats.shadow_rays)
    a, b = new.image, old.image
    assert b.mean.max() > 0.5, "the sun is seen in the ball"
    assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=4, what="roulette vs none")
    z = (a.mean.mean() - b.mean.mean()) / image_mean_se(a.stderr, b.stderr)
    assert abs(z) < z_threshold(1), f"roulette vs none, whole image: z {z:.2f}"
