"""The material and light kind tables (host/kinds/materials.py, lights.py): every kind has
its schema, packer, device id and device functions, and a kind added from one device
file and one declaration renders right (proof (b) of the define-once redesign)."""
import contextlib
import re
from pathlib import Path

import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.host.kinds import lights, materials
from gpiscl.host.kinds.lights import LIGHTS, LightHost
from gpiscl.host.kinds.materials import MATERIALS, MICRO_BSDFS
from gpiscl.host.kinds.table import Kind, KindTable
from gpiscl.host.kinds.values import ALBEDO, RGB
from gpiscl.host.layout import records as layouts
from gpiscl.host.schema import Context, Field, Record
from gpiscl.testing.scenes import gpis_scene
from gpiscl.testing.stats import assert_agree, image_mean_se, z_threshold

ROOT = Path(__file__).resolve().parent.parent
TOY_KINDS = ROOT / "tests" / "data" / "kinds"

# A scene object of every light kind that needs more than its defaults.
LIGHT_EXAMPLES = {
    "environment_map": {"file": str(ROOT / "scenes" / "assets" / "sky.exr")},
    "point": {"position": [0, 1, 0], "intensity": 2.0},
    "sphere": {"center": [0, 1, 0], "radius": 0.5, "radiance": 3.0},
    "rectangle": {"center": [0, 1, 0], "u": [1, 0, 0], "v": [0, 0, 1], "radiance": 1.0},
    "directional": {"direction": [0, 1, 0], "irradiance": 1.0},
}
# What each table's dispatch asks of a kind with the given trait (None: every kind).
MATERIAL_FUNCTIONS = {None: ("eval", "sample")}
LIGHT_FUNCTIONS = {None: ("sample",), "at_infinity": ("radiance",),
                   "area": ("area_radiance",)}
# packer keys that are not record fields: compile/scene.py's instructions
LIGHT_EXTRAS = {"primitive", "environment_file"}


def _resolve(table, name, example):
    return table.schema.resolve({"type": name, **example}, "x", Context("t.json", str(ROOT)))


def _device_functions(table, kind, wanted):
    """The `<kind>_<function>` definitions missing from the kind's device file."""
    text = table.device_path(kind).read_text()
    needed = [f for trait, fs in wanted.items() if trait is None or kind.traits[trait]
              for f in fs]
    return [f for f in needed if not re.search(rf"\b{kind.name}_{f}\s*\(", text)]


@pytest.mark.parametrize("table, axis, record, functions, examples, extras", [
    (MATERIALS, materials, layouts.MATERIAL, MATERIAL_FUNCTIONS, {}, set()),
    (LIGHTS, lights, layouts.LIGHT, LIGHT_FUNCTIONS, LIGHT_EXAMPLES, LIGHT_EXTRAS),
], ids=["materials", "lights"])
def test_every_kind_has_schema_packer_device_id_and_device_functions(
        table, axis, record, functions, examples, extras):
    header = layouts.c_header()
    source = axis.device_source()   # with the generated dispatch
    for i, kind in enumerate(table):
        assert table.schema.variants[kind.name] is kind.schema
        packed = kind.host(_resolve(table, kind.name, examples.get(kind.name, {})))
        assert set(packed) - extras <= set(record.dtype.names), kind.name
        assert f"#define {table.c_name(kind.name)} {i}\n" in header
        if kind.traits.get("pass_through"):   # no BSDF: the trait is all the device needs
            assert kind.device_file is None
            continue
        assert _device_functions(table, kind, functions) == [], kind.name
        for trait, fs in functions.items():
            if trait is None or kind.traits[trait]:
                for f in fs:
                    assert f"return {kind.name}_{f}(" in source, (kind.name, f)


def test_micro_bsdfs_are_the_materials_with_the_micro_trait():
    assert tuple(MICRO_BSDFS.variants) == MATERIALS.with_trait("micro")
    assert "null" not in MICRO_BSDFS.variants


def test_a_schema_view_and_the_device_source_follow_registrations(tmp_path):
    """KindTable.schema_where and device_source (a device file may lie outside kernels_cl)"""
    t = KindTable("toy", "TOY", [Kind("a", Record({}), traits={"on": True})], traits=("on",))
    view = t.schema_where("on", "toy-on")
    (tmp_path / "b.h").write_text("int b_f(void) { return 2; }\n")
    with t.registered(Kind("b", Record({}), str(tmp_path / "b.h"), traits={"on": True})):
        t.register(Kind("c", Record({}), traits={"on": False}))
        assert list(view.variants) == ["a", "b"]
        assert t.device_source() == f'#line 1 "{tmp_path / "b.h"}"\nint b_f(void) {{ return 2; }}\n'
        t.unregister("c")
    assert list(view.variants) == ["a"] and t.device_source() == ""


# --- proof (b): a kind from one device file and one declaration ------------------------

def tinted_diffuse():
    """A diffuse micro-BSDF whose albedo is its `tint`."""
    return Kind("tinted_diffuse", Record({"tint": Field(ALBEDO, 0.5)}),
                str(TOY_KINDS / "tinted_diffuse.h"),
                {"micro": True, "delta": False, "pass_through": False, "random_normal": 0},
                lambda bsdf: {"albedo": bsdf["tint"]})


def sky_dome():
    """Uniform `radiance` from the upper hemisphere, black below."""
    return Kind("sky_dome", Record({"radiance": Field(RGB, 1.0)}),
                str(TOY_KINDS / "sky_dome.h"),
                {"environment": False, "at_infinity": True, "area": False,
                 "positioned": False},
                LightHost(lambda lt: {"radiance": lt["radiance"]},
                          lambda fields, radius, lobe=None: 0.0))   # like a constant sky


@pytest.fixture(scope="module")
def toy_kinds():
    with contextlib.ExitStack() as stack:
        stack.enter_context(MATERIALS.registered(tinted_diffuse()))
        stack.enter_context(LIGHTS.registered(sky_dome()))
        yield
    assert "tinted_diffuse" not in MATERIALS and "sky_dome" not in LIGHTS


def test_toy_kinds_render_the_closed_form_of_a_plane_under_a_dome(device, toy_kinds):
    """An unoccluded plane facing up under a dome of radiance L reflects tint * L in
    every direction (E = pi L, f = tint / pi), with NEE through sky_dome_sample and
    tinted_diffuse_eval, and MIS through sky_dome_radiance."""
    tint, L = np.array([0.3, 0.6, 0.9]), 2.0
    scene = {"camera": {"position": [0, 2, 2], "look_at": [0, 0, 0], "up": [0, 1, 0],
                        "fov": 30, "resolution": [12, 12]},
             "render": {"spp": 64, "seed": 5, "max_depth": 4},
             "shapes": [{"type": "rectangle", "center": [0, 0, 0], "u": [20, 0, 0],
                         "v": [0, 0, -20], "bsdf": {"type": "tinted_diffuse",
                                                    "tint": list(tint)}}],
             "lights": [{"type": "sky_dome", "radiance": L}]}
    res = render_result(scene, device=device)
    assert res.stats.nan_paths == 0 and res.stats.shadow_rays > 0
    img = res.image
    expected = np.broadcast_to(tint * L, img.mean.shape)
    assert_agree(img.mean, img.stderr, expected, what="plane under a dome")
    # the whole image: resolves a 0.5 % error where a pixel resolves 10 %
    assert abs(img.mean.mean() - expected.mean()) < z_threshold(2) * image_mean_se(img.stderr)
    assert np.all(img.stderr > 0)   # a sampled estimate, not the closed form copied


def test_toy_micro_bsdf_on_a_gpis_is_a_white_furnace(device, toy_kinds):
    """Tint 1 in a unit environment, roulette off: the GPIS is invisible (every pixel 1)."""
    scene = gpis_scene({"type": "weight_space", "features": 256}, "diffuse", 1.0,
                       [{"type": "environment", "radiance": 1.0}], spp=16)
    scene["shapes"][0]["bsdf"] = {"type": "tinted_diffuse", "tint": 1.0}
    res = render_result(scene, device=device)
    assert res.stats.nan_paths == 0 and res.stats.rays > 1.5 * res.stats.paths
    img = res.image
    assert_agree(img.mean, img.stderr, np.ones_like(img.mean), block=4, what="furnace")
    assert abs(img.mean.mean() - 1.0) < z_threshold(2) * image_mean_se(img.stderr)
