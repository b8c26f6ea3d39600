"""The function_space sampler in scene files: defaults, strict validation, compilation."""
import pytest

from gpiscl.host.layout import records as layouts
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene
from gpiscl.host.compile.scene import compile_scene


def scene(sampler, kernel=None):
    g = {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.0},
         "mean": {"type": "sphere", "radius": 0.5},
         "kernel": kernel or {"type": "squared_exponential", "length_scale": 0.2},
         "sampler": sampler}
    return {"shapes": [g], "lights": [{"type": "environment"}]}


def test01_defaults_are_filled_and_compiled():
    s = load_scene(scene({"type": "function_space"}))
    assert s.data["shapes"][0]["sampler"] == {
        "type": "function_space", "memory": "renewal_plus", "memory_cap": 64,
        "miss_tolerance": 2e-6, "refine": 0}
    o = compile_scene(s.data).gpis.objects[0]
    assert o["sampler"] == layouts.GPIS_SAMPLERS["function_space"]
    assert (o["window"], o["memory_cap"], o["refine"]) == (16, 64, 0)
    assert o["memory"] == layouts.GPIS_MEMORIES["renewal_plus"]
    assert abs(o["miss_tolerance"] - 2e-6) < 1e-12 and o["step_corr"] == 0   # adaptive


@pytest.mark.parametrize("memory", ["none", "renewal", "renewal_plus", "global"])
def test02_memory_models_compile(memory):
    s = load_scene(scene({"type": "function_space", "memory": memory,
                          "memory_cap": 16, "miss_tolerance": 1e-3, "refine": 3}))
    o = compile_scene(s.data).gpis.objects[0]
    assert o["memory"] == layouts.GPIS_MEMORIES[memory]
    assert (o["memory_cap"], o["refine"]) == (16, 3)
    assert abs(o["miss_tolerance"] - 1e-3) < 1e-10


def test03_thin_plate_is_allowed_in_function_space_only():
    tp = {"type": "thin_plate", "radius": 2.0}     # the proxy's diameter is 2
    load_scene(scene({"type": "function_space"}, tp))
    with pytest.raises(SceneError, match="thin_plate has no spectral density"):
        load_scene(scene({"type": "weight_space"}, tp))


def test04_thin_plate_radius_must_span_the_proxy():
    with pytest.raises(SceneError) as e:
        load_scene(scene({"type": "function_space"},
                         {"type": "thin_plate", "radius": 2.0, "aniso": [1, 1, 4]}))
    assert e.value.key == "shapes[0].kernel.radius"
    assert "radius must be >= 4" in e.value.reason


@pytest.mark.parametrize("sampler, key, reason", [
    ({"samples": 32}, "samples", "removed: values are sampled one at a time"),
    ({"step_corr": 0.9}, "step_corr", "removed: the step is adaptive now; use miss_tolerance"),
    ({"miss_tolerance": 0.0}, "miss_tolerance", "must be >= 1e-09"),
    ({"memory": "elephant"}, "memory", "one of"),
    ({"memory_cap": 4}, "memory_cap", "must be >= 8"),
    ({"refine": -1}, "refine", "must be >= 0"),
    ({"features": 64}, "features", "unknown key"),
])
def test05_bad_values_name_the_key(sampler, key, reason):
    with pytest.raises(SceneError) as e:
        load_scene(scene({"type": "function_space", **sampler}))
    assert e.value.key == f"shapes[0].sampler.{key}", str(e.value)
    assert reason in e.value.reason, str(e.value)
