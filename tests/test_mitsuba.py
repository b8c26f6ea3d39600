"""An independent check of the classical counterparts against Mitsuba 3 (the optional
extra: pip install -e '.[mitsuba]'; skipped only when mitsuba cannot be imported).

Both scenes are radially symmetric about the view axis (a directional light shining along
it), so the renderers' image orientations cannot differ. Mitsuba's per-pixel standard
errors come from independent renders with different seeds; each 4x4 block is a z-test
(Bonferroni over all blocks and channels, gpiscl/testing/stats.py).
* medium: the "medium" counterpart of a constant-mean GPIS (Rice's entry rate 2, diffuse
  micro-BSDF 0.8) against Mitsuba's homogeneous medium with sigma_t 2, albedo 0.8 and the
  Lambert-sphere phase function tabulated (docs/design/classical-limits.md, Eq. 4);
* surface: the "surface" counterpart of a plane-mean GPIS with a gold rough_conductor
  micro-BSDF against Mitsuba's roughconductor (Beckmann, the same alpha, eta and k)."""
import math

import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.host.compile.classical import with_counterparts
from gpiscl.host.gp import SquaredExponential
from gpiscl.host.gp import classical as C
from gpiscl.host.kinds.conductors import eta_k
from gpiscl.host.scene.loading import load_scene
from gpiscl.testing.stats import assert_agree

mi = pytest.importorskip("mitsuba")

RES, FOV = 24, 40.0
CAMERA = {"position": [0, 0, 4], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov": FOV,
          "resolution": [RES, RES]}
SUN = {"type": "directional", "direction": [0, 0, 1], "irradiance": 3.0, "angular_radius": 0.0}


def gpis(mean, proxy, micro, classical, sampler=None):
    shape = {"type": "gpis", "clip": True, "proxy": proxy, "mean": mean, "bsdf": micro,
             "kernel": {"type": "squared_exponential", "sigma": 1.0 if classical == "medium"
                        else 0.01, "length_scale": LENGTH if classical == "medium" else 0.1},
             "classical": classical}
    if sampler:
        shape["sampler"] = sampler
    return shape


# Rice's entry rate 2 at mean level 2 sigma
LENGTH = float(C.entry_rate(SquaredExponential(1.0, 1.0), 2.0)) / 2.0


def mitsuba_render(scene_dict, spp, renders):
    mi.set_variant("scalar_rgb")
    scene = mi.load_dict(scene_dict)
    imgs = np.stack([np.asarray(mi.render(scene, spp=spp, seed=s)) for s in range(renders)])
    mean = imgs.mean(0)
    # float32 rounding (1e-6 relative) floors the error: the background is the same
    # constant in every render up to it, and exactly the radiance in gpiscl's film
    return mean, np.hypot(imgs.std(0, ddof=1) / math.sqrt(renders), 1e-6 * np.abs(mean))


def mitsuba_base(emitters):
    return {"type": "scene",
            "integrator": {"type": "volpath", "max_depth": 256},
            "sensor": {"type": "perspective", "fov": FOV,
                       "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4],
                                                                  target=[0, 0, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": RES, "height": RES,
                                "rfilter": {"type": "box"}, "pixel_format": "rgb"}},
            "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 3.0},
            **emitters}


def test_medium_counterpart_matches_mitsuba(device):
    doc = {"camera": CAMERA, "render": {"spp": 256, "seed": 1, "max_depth": 256},
           "shapes": [gpis({"type": "constant", "value": 2.0},
                           {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
                           {"type": "diffuse", "albedo": 0.8}, "medium",
                           {"type": "function_space"})],
           "lights": [SUN, {"type": "environment", "radiance": 0.1}]}
    ours = render_result(doc, device=device).image
    mi.set_variant("scalar_rgb")
    c = np.linspace(-1.0, 1.0, 513)     # Mitsuba's tabphase: over the deflection cosine
    phase = C.lambert_sphere_phase(np.arccos(c))
    theirs = mitsuba_render(dict(mitsuba_base({"sky": {"type": "constant", "radiance": 0.1}}),
                                 ball={"type": "sphere", "radius": 1.0,
                                       "bsdf": {"type": "null"},
                                       "interior": {"type": "homogeneous", "sigma_t": 2.0,
                                                    "albedo": 0.8,
                                                    "phase": {"type": "tabphase",
                                                              "values": ", ".join(
                                                                  f"{v:.9g}" for v in phase)}}}),
                            64, 8)
    z = assert_agree(ours.mean, ours.stderr, *theirs, block=4, what="medium vs mitsuba")
    print(f"medium: max |z| {z.max():.2f} over {z.size}; means {ours.mean.mean():.5f} "
          f"{theirs[0].mean():.5f}")


def test_surface_counterpart_matches_mitsuba(device):
    gold = {"type": "rough_conductor", "material": "Au", "roughness": 0.1}
    doc = {"camera": CAMERA, "render": {"spp": 64, "seed": 1, "max_depth": 8},
           "shapes": [gpis({"type": "plane", "point": [0, 0, 0], "normal": [0, 0, 1]},
                           {"type": "box", "min": [-3, -3, -0.1], "max": [3, 3, 0.1]},
                           gold, "surface")],
           "lights": [SUN]}
    plane = with_counterparts(load_scene(doc).data)["shapes"][0]
    assert plane["type"] == "rectangle"
    alpha = plane["bsdf"]["roughness"]
    assert math.isclose(alpha, math.hypot(math.sqrt(2) * 0.01 / 0.1, 0.1))
    ours = render_result(doc, device=device).image
    eta, k = eta_k(plane["bsdf"])
    mi.set_variant("scalar_rgb")
    theirs = mitsuba_render(dict(mitsuba_base({}), plane={
        "type": "rectangle", "to_world": mi.ScalarTransform4f().scale([3, 3, 1]),
        "bsdf": {"type": "roughconductor", "distribution": "beckmann", "alpha": alpha,
                 "eta": {"type": "rgb", "value": list(eta)},
                 "k": {"type": "rgb", "value": list(k)}}}), 16, 8)
    z = assert_agree(ours.mean, ours.stderr, *theirs, block=4, what="surface vs mitsuba")
    print(f"surface (alpha {alpha:.4f}): max |z| {z.max():.2f} over {z.size}; means "
          f"{ours.mean.mean():.5f} {theirs[0].mean():.5f}")
