"""render/kriging_cache.py: a weight-space posterior's weights, solved once per path and
object and read back by the path's later rays and shadow rays, give the image of solving
them on every ray bit for bit; weights keyed to the wrong path do not."""
import numpy as np
import pytest

from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.render import kriging_cache as KC, program_sources
from gpiscl.host.render.integrator import WavefrontIntegrator
from gpiscl.host.scene.loading import load_scene
from gpiscl.testing.scenes import fibonacci_sphere

SIGMA = 0.06


def posterior_gpis(folder, name, center, n):
    """A GPIS sphere of radius 0.6 at center, its prior's mean 10% wider, conditioned on
    n points of the true sphere (noise 5% of sigma)."""
    c = np.asarray(center, float)
    np.savetxt(folder / f"{name}.xyz", 0.6 * fibonacci_sphere(n) + c)
    return {"type": "gpis", "proxy": {"type": "sphere", "center": list(c), "radius": 0.9},
            "mean": {"type": "sphere", "center": list(c), "radius": 0.66},
            "kernel": {"type": "squared_exponential", "sigma": SIGMA, "length_scale": 0.15},
            "sampler": {"type": "weight_space"},
            "observations": {"file": str(folder / f"{name}.xyz"), "noise": 0.05 * SIGMA},
            "bsdf": {"type": "diffuse", "albedo": 0.8}}


def two_posteriors(folder):
    """A prior GPIS, then two posterior objects of different row counts (so different
    slot offsets) side by side on a floor before a wall, under a sun and a sky: camera rays hit either, bounce
    between them, the floor and the wall, and shadow rays cross them."""
    prior = posterior_gpis(folder, "prior", [0, 0.55, -0.4], 1)
    prior["mean"]["radius"], prior["proxy"]["radius"] = 0.25, 0.4
    del prior["observations"]
    shapes = [{"type": "rectangle", "center": [0, -0.6, 0], "u": [8, 0, 0], "v": [0, 0, -8],
               "bsdf": {"type": "diffuse", "albedo": 0.8}},
              {"type": "rectangle", "center": [0, 1.4, -1.0], "u": [8, 0, 0], "v": [0, 4, 0],
               "bsdf": {"type": "diffuse", "albedo": 0.8}},
              prior,
              posterior_gpis(folder, "left", [-0.65, 0, 0], 60),
              posterior_gpis(folder, "right", [0.65, 0, 0], 25)]
    scene = {"camera": {"position": [0, 0.6, 3.6], "look_at": [0, -0.1, 0], "fov": 40,
                        "resolution": [20, 12]},
             "render": {"spp": 4, "seed": 7, "max_depth": 8},
             "shapes": shapes,
             "lights": [{"type": "directional", "direction": [0.6, 1.0, 0.7],
                         "irradiance": 2.5, "angular_radius": 1.0},
                        {"type": "environment", "radiance": 0.4}]}
    data = load_scene(scene).data
    return compile_scene(data), data["render"]


def render(device, compiled, settings, **extra):
    """Batches of at most 96 paths, so later batches reuse the slots of earlier paths."""
    integ = WavefrontIntegrator(device, compiled, {**settings, **extra}, batch_size=96)
    res = integ.render(int(settings["spp"]))
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0 and st.truncated_paths == 0, st.summary()
    return res


def same_image(a, b) -> bool:
    return all(np.array_equal(getattr(a.image, f), getattr(b.image, f))
               for f in ("mean", "stderr", "count"))


def test01_layout_gives_each_posterior_object_its_own_slot(device, tmp_path):
    compiled, _ = two_posteriors(tmp_path)
    gpis = compiled.gpis
    table, tags, doubles = KC.layout(gpis.objects, gpis.mean_nodes)
    assert table.tolist() == [[-1, -1], [0, 0], [1, 61]]
    assert (tags, doubles) == (2, 61 + 26)
    assert KC.max_batch(gpis.objects, gpis.mean_nodes, device) \
        == KC.budget(device) // (8 * 87 + 2 * KC.TAG_BYTES)


@pytest.mark.parametrize("realization", [None, 3])
def test02_cached_weights_render_the_uncached_image_bit_for_bit(device, tmp_path,
                                                                realization):
    """Exact by construction: the kept v and rho are the values the first search computed,
    and every search would compute the same ones (they depend on the key and object
    alone). With one fixed realization every path shares its key, and so its weights."""
    compiled, settings = two_posteriors(tmp_path)
    settings = {**settings, "realization": realization}
    cached = render(device, compiled, settings)
    uncached = render(device, compiled, settings, kriging_cache=False)
    st = cached.stats
    assert st.rays > 2 * st.paths and st.shadow_rays > st.paths // 2, st.summary()
    assert st.batches > 4
    assert (st.rays, st.shadow_rays) == (uncached.stats.rays, uncached.stats.shadow_rays)
    assert same_image(cached, uncached)


def test03_weights_of_another_path_change_the_image(device, tmp_path, monkeypatch):
    """The test above can fail: a tag without the path's key lets each batch's path read
    the weights its slot kept from the previous batch's path of the same index."""
    source = program_sources.kernel_source
    right = "return (uint4)(key.x, key.y, (uint)object + 1u, 0u);"

    def keyless(name):
        text = source(name)
        if name == "ws_posterior.h":
            assert right in text
            text = text.replace(right, "return (uint4)(0u, 0u, (uint)object + 1u, 0u);")
        return text

    compiled, settings = two_posteriors(tmp_path)
    uncached = render(device, compiled, settings, kriging_cache=False)
    monkeypatch.setattr(program_sources, "kernel_source", keyless)
    wrong = render(device, compiled, settings)
    assert not same_image(wrong, uncached)
