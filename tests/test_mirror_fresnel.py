"""The mirror's optional Fresnel term (a conductor preset or eta and k, bsdf/mirror.h with
bsdf/fresnel.h): its scene keys, and a mirror sphere in a unit environment against the
Fresnel reflectance quadrature predicts for every pixel, also as a nearly deterministic
GPIS in weight and in function space. Function-space mirrors' light samples with a
conductor: tests/test_fs_nee.py (NEE + MIS against BSDF sampling)."""
import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.host.errors import SceneError
from gpiscl.host.kinds.conductors import CONDUCTORS
from gpiscl.host.kinds.materials import MATERIALS
from gpiscl.host.schema import Context
from gpiscl.testing.reference.camera import hit_sphere, pixel_rays
from gpiscl.testing.reference.rough_conductor import fresnel_conductor
from gpiscl.testing.stats import block_means, image_mean_se, z_threshold

CAMERA = {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov": 40,
          "resolution": [24, 24]}
# float32 Fresnel on the device and the 16 x 16 quadrature of each pixel agree to ~1e-6;
# pixels that see the sphere's flat middle have a smaller sample standard error than that
FLOAT_FLOOR = 1e-5


def _mirror(**keys):
    return MATERIALS.schema.resolve({"type": "mirror", **keys}, "bsdf", Context("t.json", "."))


def _packed(bsdf):
    return MATERIALS["mirror"].host(bsdf)


def test_a_mirror_without_a_conductor_packs_no_fresnel_term():
    assert set(_packed(_mirror())) == {"albedo"}   # Material.fresnel stays 0
    au = _packed(_mirror(material="Au"))
    assert au["fresnel"] == 1 and (au["eta"], au["k"]) == CONDUCTORS["Au"]
    own = _packed(_mirror(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 2.1]))
    assert own["fresnel"] == 1 and own["k"] == (3.9, 2.4, 2.1)


@pytest.mark.parametrize("keys, where", [
    ({"material": "Fe"}, "bsdf.material"),
    ({"eta": [1.0, 1.0, 1.0]}, "bsdf.k"),
    ({"material": "Au", "eta": 1.0, "k": 2.0}, "bsdf.eta"),
], ids=["unknown preset", "eta without k", "preset and eta"])
def test_bad_fresnel_keys_are_scene_errors(keys, where):
    with pytest.raises(SceneError) as err:
        _mirror(**keys)
    assert where in str(err.value)


def _sphere_scene(bsdf, spp, sampler=None):
    """The unit sphere in a unit environment: a plain sphere, or (sampler given) a GPIS
    of a sphere mean so smooth (sigma 0.001, l 0.5: normals spread by 0.16 degrees) that
    its pixels are the sphere's to far below the noise."""
    shape = {"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "bsdf": bsdf}
    if sampler is not None:
        shape = {"type": "gpis", "proxy": {"type": "sphere", "center": [0, 0, 0], "radius": 1.1},
                 "mean": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
                 "kernel": {"type": "squared_exponential", "sigma": 0.001, "length_scale": 0.5},
                 "sampler": sampler, "bsdf": bsdf}
    return {"camera": CAMERA, "render": {"spp": spp, "seed": 4, "max_depth": 8,
                                         "russian_roulette": {"start_depth": 100}},
            "shapes": [shape], "lights": [{"type": "environment", "radiance": 1.0}]}


def _expected(eta, k, albedo):
    """Per pixel: the reflected unit sky, albedo F(cos) where a ray meets the sphere (it
    leaves a convex mirror for good), 1 where it misses; 16 x 16 rays a pixel."""
    o, d = pixel_rays(CAMERA, 16)
    t = hit_sphere(o, d, [0, 0, 0], 1.0)
    hit = np.isfinite(t)
    x = o + np.where(hit, t, 0.0)[..., None] * d
    cos = -np.sum(x * d, axis=-1)   # the unit sphere's normal is x
    value = np.where(hit[..., None], np.asarray(albedo) * fresnel_conductor(cos, eta, k), 1.0)
    return value.mean(axis=2)


@pytest.mark.parametrize("keys, eta_k, sampler", [
    ({"material": "Au"}, CONDUCTORS["Au"], None),
    ({"eta": [1.5, 0.4, 2.0], "k": [0.2, 3.0, 0.0]}, ((1.5, 0.4, 2.0), (0.2, 3.0, 0.0)), None),
    ({"material": "Au"}, CONDUCTORS["Au"], {"type": "weight_space"}),
    ({"material": "Au"}, CONDUCTORS["Au"], {"type": "function_space"}),
], ids=["Au", "own eta k", "Au weight-space GPIS", "Au function-space GPIS"])
def test_mirror_sphere_in_a_unit_environment_reflects_fresnel(device, keys, eta_k, sampler):
    """Every 4x4 block (z from the pixels' sample variances plus the float floor: a
    block, not a pixel, so that an edge pixel whose few samples all missed the sphere
    still shows its coverage's variance) and the image mean against the quadrature; the
    plain mirror's pixels are exactly 1."""
    albedo = [0.9, 1.0, 0.8]
    img = render_result(_sphere_scene({"type": "mirror", "albedo": albedo, **keys}, 32,
                                      sampler), device=device).image
    ref = _expected(*eta_k, albedo)
    mean, se = block_means(img.mean, img.stderr, 4)
    ref_blocks, _ = block_means(ref, np.zeros_like(ref), 4)
    z = np.abs(mean - ref_blocks) / np.sqrt(se**2 + FLOAT_FLOOR**2)
    assert z.max() < z_threshold(z.size), f"max |z| {z.max():.2f} over {z.size}"
    se = image_mean_se(img.stderr) + FLOAT_FLOOR
    assert abs(img.mean.mean() - ref.mean()) < z_threshold(1) * se
    plain = render_result(_sphere_scene({"type": "mirror", "albedo": 1.0}, 4, sampler),
                          device=device).image
    assert np.all(plain.mean == 1.0) and np.all(plain.stderr == 0.0)
