"""Unbounded GPIS ("proxy": {"type": "scene"}): sampled up to the scene's box."""
import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene
from gpiscl.host.compile.scene import scene_box


def _scene(proxy, kernel=None, sampler=None):
    return {"shapes": [{"type": "rectangle", "center": [0, 0, 0], "u": [4, 0, 0],
                        "v": [0, 0, -4], "bsdf": {"type": "diffuse", "albedo": 0.5}},
                       {"type": "gpis", "proxy": proxy,
                        "mean": {"type": "plane", "point": [0, 0.6, 0], "normal": [0, 1, 0],
                                 "scale": 0.3},
                        "kernel": kernel or {"type": "squared_exponential", "sigma": 0.5,
                                             "length_scale": 0.3},
                        "sampler": sampler or {"type": "function_space"},
                        "bsdf": {"type": "diffuse", "albedo": 0.8}}],
            "lights": [{"type": "environment", "radiance": 1.0},
                       {"type": "point", "position": [0, 3, 0], "intensity": 2.0}],
            "camera": {"position": [0, 1.5, 5], "look_at": [0, 0.5, 0],
                       "resolution": [16, 16]},
            "render": {"spp": 4, "seed": 2}}


def test_scene_box_holds_shapes_lights_and_camera():
    lo, hi = scene_box(load_scene(_scene({"type": "scene"})).data)
    # rectangle x, z in [-2, 2] at y = 0; point light at y = 3; camera at z = 5
    raw_lo, raw_hi = np.array([-2, 0, -2]), np.array([2, 3, 5])
    grow = 0.01 * np.linalg.norm(raw_hi - raw_lo) + 1e-3
    np.testing.assert_allclose(lo, raw_lo - grow, atol=1e-4)
    np.testing.assert_allclose(hi, raw_hi + grow, atol=1e-4)


@pytest.mark.parametrize("sampler", [None, {"type": "weight_space"}], ids=["fs", "ws"])
def test_a_scene_proxy_renders_like_the_explicit_box(device, sampler):
    """The same box written out draws the same samples: equal images to rounding."""
    lo, hi = scene_box(load_scene(_scene({"type": "scene"})).data)
    a = render_result(_scene({"type": "scene"}, sampler=sampler), device=device)
    b = render_result(_scene({"type": "box", "min": lo.tolist(), "max": hi.tolist()},
                             sampler=sampler), device=device)
    assert a.stats.gpis_failed == 0 and a.stats.nan_paths == 0, a.stats.summary()
    np.testing.assert_array_equal(a.image.mean, b.image.mean)
    assert a.stats.rays > 1.5 * a.stats.paths      # the surface is hit and scatters


def test_unbounded_proxies_refuse_what_needs_a_bound():
    with pytest.raises(SceneError) as e:
        load_scene(_scene({"type": "scene"}, {"type": "thin_plate", "radius": 4.0}))
    assert e.value.key == "shapes[1].proxy.type" and "bounded proxy" in e.value.reason
    lin = {"type": "linear", "value": 1.0, "gradient": [0.1, 0, 0]}
    with pytest.raises(SceneError) as e:
        load_scene(_scene({"type": "scene"}, {"type": "squared_exponential",
                                              "sigma_field": lin}))
    assert e.value.key == "shapes[1].kernel.sigma_field"
    load_scene(_scene({"type": "scene"}, {"type": "squared_exponential",
                                          "sigma_field": {**lin, "gradient": [0, 0, 0]}}))
