"""The surface counterpart of a GPIS ("classical": "surface", compile/classical.py): the
mean's zero set with a Beckmann BSDF of alpha = sqrt(2 lambda_2) / |grad mu|; in a white
furnace, and against the GPIS it stands for (z per 4x4 block, tolerances from the films'
standard errors). docs/design/classical-limits.md, Sec. 3."""
import copy
import math

import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.host.compile.classical import with_counterparts
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene
from stats import assert_agree, image_mean_se, z_threshold

MIRROR = {"type": "mirror", "albedo": 1.0}
GOLD = {"type": "rough_conductor", "material": "Au", "roughness": 0.1}


def sphere_scene(micro, classical=False, spp=64, light="rectangle", kernel=None):
    g = {"type": "gpis", "proxy": {"type": "sphere", "center": [0, 0, 0], "radius": 1.1},
         "mean": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
         "kernel": kernel or {"type": "squared_exponential", "sigma": 0.01, "length_scale": 0.1},
         "bsdf": micro}
    if classical:
        g["classical"] = "surface"
    lights = ([{"type": "environment", "radiance": 1.0}] if light == "furnace" else
              [{"type": "environment", "radiance": 0.2},
               {"type": "rectangle", "center": [1.5, 2.5, 1.5], "u": [1, 0, 0], "v": [0, 0, 1],
                "radiance": 8.0}])
    return {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 40, "resolution": [32, 32]},
            "render": {"spp": spp, "seed": 3, "max_depth": 32}, "shapes": [g], "lights": lights}


def counterpart(doc):
    scene = load_scene(doc)
    return with_counterparts(scene.data, "<test>")["shapes"][0]


def test01_counterpart_shapes_and_roughness():
    """Sphere mean -> sphere; the shipped rough mirror plane -> a rectangle filling its box,
    facing the mean's normal, with alpha = sqrt(2) sigma / l = 0.1414; a rough micro-BSDF
    adds its roughness in quadrature; Matern 3/2 has sqrt(6) sigma / l."""
    s = counterpart(sphere_scene(GOLD, classical=True))
    assert s["type"] == "sphere" and s["radius"] == 1.0
    assert math.isclose(s["bsdf"]["roughness"], math.hypot(math.sqrt(2) * 0.1, 0.1))
    m32 = {"type": "matern32", "sigma": 0.01, "length_scale": 0.1}
    s = counterpart(sphere_scene(MIRROR, classical=True, kernel=m32))
    assert math.isclose(s["bsdf"]["roughness"], math.sqrt(6) * 0.1)
    assert s["bsdf"]["type"] == "rough_conductor" and min(s["bsdf"]["k"]) >= 1e4
    doc = load_scene("scenes/ws_rough_mirror_plane.json").data
    doc = copy.deepcopy(doc)
    doc["shapes"][0]["classical"] = "surface"
    plane = counterpart(doc)
    assert plane["type"] == "rectangle"
    assert math.isclose(plane["bsdf"]["roughness"], math.sqrt(2) * 0.01 / 0.1)
    u, v = np.asarray(plane["u"]), np.asarray(plane["v"])
    assert np.allclose(np.cross(u, v) / np.linalg.norm(np.cross(u, v)), [0, 1, 0])
    assert np.allclose(sorted([np.linalg.norm(u), np.linalg.norm(v)]), [6, 6])
    # without the key nothing changes (the same dict)
    scene = load_scene(sphere_scene(GOLD))
    assert with_counterparts(scene.data) is scene.data


@pytest.mark.parametrize("change, key", [
    (lambda g: g["mean"].update(type="box", half_extents=[1, 1, 1]), "classical"),
    (lambda g: g["kernel"].update(aniso=[1, 2, 1]), "kernel.aniso"),
    (lambda g: g.update(emission=1.0), "emission"),
    (lambda g: g["kernel"].update(sigma=0.2), "classical"),   # alpha 2.8: no microfacet limit
])
def test02_refused_counterparts_name_the_key(change, key):
    doc = sphere_scene(MIRROR, classical=True)
    change(doc["shapes"][0])
    if doc["shapes"][0]["mean"]["type"] == "box":
        doc["shapes"][0]["mean"].pop("radius")
    with pytest.raises(SceneError, match=key.replace(".", r"\.")):
        counterpart(doc)


def test03_white_furnace(device):
    """Albedo-1 mirror micro-BSDF in a unit environment: the GPIS is invisible (every block
    1 within noise); its counterpart, a single-scattering Beckmann BSDF, loses the energy
    of the bounces between facets (measured 0.38% at alpha 0.14 over the sphere), so it
    lies below 1 and below the GPIS by more than the noise."""
    gpis = render_result(sphere_scene(MIRROR, light="furnace"), device=device).image
    classic = render_result(sphere_scene(MIRROR, classical=True, light="furnace"),
                            device=device).image
    assert_agree(gpis.mean, gpis.stderr, np.ones_like(gpis.mean), block=4, what="gpis furnace")
    se = image_mean_se(gpis.stderr, classic.stderr)
    gap = float(gpis.mean.mean() - classic.mean.mean())
    print(f"furnace: gpis {gpis.mean.mean():.5f}, counterpart {classic.mean.mean():.5f}, "
          f"gap {gap:.5f} (se {se:.5f})")
    assert 0.0 < gap < 0.02 and gap > z_threshold(1) * se
    assert 1.0 - classic.mean.mean() > z_threshold(1) * image_mean_se(classic.stderr)


@pytest.mark.parametrize("micro", [MIRROR, GOLD], ids=["mirror", "rough_gold"])
def test04_counterpart_renders_like_the_gpis(device, micro):
    """A rectangle light and a dim environment: the GPIS (sigma/l = 0.1, weight space) and
    its counterpart agree per 4x4 block within the films' errors (64 spp)."""
    a = render_result(sphere_scene(micro), device=device).image
    b = render_result(sphere_scene(micro, classical=True), device=device).image
    z = assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=4, what="gpis vs counterpart")
    print(f"max |z| {z.max():.2f} over {z.size} blocks; means {a.mean.mean():.5f} "
          f"{b.mean.mean():.5f}")
