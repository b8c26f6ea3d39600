"""The strict scene loader: defaults, resolution, round trips and one-line errors."""
import copy
import json
import math
import os

import numpy as np
import pytest

from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene, write_resolved
from gpiscl.scenes import default_scene, furnace_sphere


def minimal(**extra):
    scene = {"lights": [{"type": "environment"}]}
    scene.update(extra)
    return scene


def write_json(path, obj):
    path.write_text(obj if isinstance(obj, str) else json.dumps(obj, indent=1))
    return path


def write_obj(path):
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")
    return path


def write_exr(path, channels=("R", "G", "B")):
    import OpenEXR
    px = np.ones((4, 8), np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {c: px.copy() for c in channels}) as f:
        f.write(str(path))
    return path


# ---------------------------------------------------------------- resolving

def test_defaults_are_filled():
    data = load_scene(minimal()).data
    assert data["camera"] == {"position": [0.0, 1.0, 4.0], "look_at": [0.0, 1.0, 0.0],
                              "up": [0.0, 1.0, 0.0], "fov": 40.0, "resolution": [256, 256]}
    assert data["render"] == {"spp": 16, "max_depth": 8, "seed": 0, "batch_size": None,
                              "nee": True, "realization": None, "tonemap": "clamp",
                              "russian_roulette": {"start_depth": 3, "max_survival": 0.95}}
    assert data["shapes"] == []
    assert data["lights"] == [{"type": "environment", "radiance": [1.0, 1.0, 1.0]}]


def test_shape_and_light_defaults_and_expansion():
    data = load_scene(minimal(
        shapes=[{"type": "sphere"}, {"type": "disk", "normal": [0, 0, 3]},
                {"type": "rectangle", "bsdf": {"type": "mirror"}},
                {"type": "box", "min": [0, 0, 0], "max": [1, 2, 3], "bsdf": {"type": "null"}}],
        lights=[{"type": "directional", "direction": [0, 2, 0], "irradiance": 3},
                {"type": "rectangle", "center": [0, 2, 0], "u": [1, 0, 0], "v": [0, 0, 1],
                 "radiance": [1, 2, 3]}])).data
    sphere, disk, rect, box = data["shapes"]
    assert sphere == {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0,
                      "bsdf": {"type": "diffuse", "albedo": [0.8, 0.8, 0.8]}}
    assert disk["normal"] == [0.0, 0.0, 1.0]
    assert rect["u"] == [1.0, 0.0, 0.0] and rect["v"] == [0.0, 0.0, -1.0]
    assert rect["bsdf"] == {"type": "mirror", "albedo": [1.0, 1.0, 1.0], "material": None,
                            "eta": None, "k": None}
    assert box["bsdf"] == {"type": "null"}
    sun, area = data["lights"]
    assert sun == {"type": "directional", "direction": [0.0, 1.0, 0.0],
                   "irradiance": [3.0, 3.0, 3.0], "angular_radius": 0.265}
    assert area["two_sided"] is False and area["radiance"] == [1.0, 2.0, 3.0]
    assert all(type(x) is float for x in area["radiance"])


def test_dict_input_is_not_mutated_and_scene_passes_through():
    src = minimal(shapes=[{"type": "sphere", "radius": 2}])
    before = copy.deepcopy(src)
    scene = load_scene(src)
    assert src == before
    assert scene.source == "<dict>" and os.path.isabs(scene.base_dir)
    assert load_scene(scene) is scene


def test_numpy_values_in_dict_scenes_resolve_to_plain_json():
    scene = load_scene(minimal(shapes=[{"type": "sphere", "center": np.array([1.0, 2, 3]),
                                        "radius": np.float32(0.5)}],
                               render={"spp": np.int64(4)}))
    json.dumps(scene.data, allow_nan=False)
    assert scene.data["render"]["spp"] == 4 and type(scene.data["render"]["spp"]) is int


def test_paths_are_made_absolute(tmp_path, monkeypatch):
    (tmp_path / "sub").mkdir()
    write_obj(tmp_path / "sub" / "tri.obj")
    write_exr(tmp_path / "sub" / "sky.exr")
    scene_file = write_json(tmp_path / "sub" / "s.json", {
        "shapes": [{"type": "mesh", "file": "tri.obj"}],
        "lights": [{"type": "environment_map", "file": "sky.exr"}]})
    scene = load_scene(scene_file)
    assert scene.source == str(scene_file)
    assert scene.base_dir == str(tmp_path / "sub")
    mesh = scene.data["shapes"][0]
    assert mesh["file"] == str(tmp_path / "sub" / "tri.obj")
    assert mesh["transform"] == {"scale": [1.0, 1.0, 1.0], "rotate": [0.0, 0.0, 0.0],
                                 "translate": [0.0, 0.0, 0.0]}
    assert scene.data["lights"][0] == {"type": "environment_map", "scale": 1.0, "rotation": 0.0,
                                       "file": str(tmp_path / "sub" / "sky.exr")}
    # dict scenes resolve against the working directory
    monkeypatch.chdir(tmp_path / "sub")
    d = load_scene({"shapes": [{"type": "mesh", "file": "tri.obj", "transform": {"scale": 2}}],
                    "lights": [{"type": "environment"}]})
    assert d.data["shapes"][0]["file"] == str(tmp_path / "sub" / "tri.obj")
    assert d.data["shapes"][0]["transform"]["scale"] == [2.0, 2.0, 2.0]


def test_round_trip(tmp_path):
    write_obj(tmp_path / "tri.obj")
    write_exr(tmp_path / "sky.exr")
    src = default_scene()
    src["shapes"].append({"type": "mesh", "file": "tri.obj",
                          "transform": {"scale": [1, 2, 3], "rotate": [10, 20, 30],
                                        "translate": [0.1, 0.2, 0.3]}})
    src["shapes"].append({"type": "disk", "normal": [0.3, 0.7, 0.1]})
    src["lights"] += [{"type": "environment_map", "file": "sky.exr", "rotation": 33.3},
                      {"type": "point", "position": [0, 1, 0], "intensity": 0.1},
                      {"type": "sphere", "center": [0, 1, 0], "radius": 0.1, "radiance": 2},
                      {"type": "directional", "direction": [1, 1, 1], "irradiance": [1, 2, 3]}]
    first = load_scene(write_json(tmp_path / "scene.json", src))
    write_resolved(first, tmp_path / "resolved.json")
    # reload from elsewhere: absolute paths keep pointing at the same files
    (tmp_path / "elsewhere").mkdir()
    moved = tmp_path / "elsewhere" / "resolved.json"
    moved.write_text((tmp_path / "resolved.json").read_text())
    second = load_scene(moved)
    assert second.data == first.data
    assert json.loads(moved.read_text()) == first.data
    # resolving a resolved dict is the identity, bit for bit
    assert load_scene(copy.deepcopy(first.data)).data == first.data
    n = first.data["shapes"][-1]["normal"]
    assert math.isclose(math.hypot(*n), 1.0, rel_tol=1e-15)


@pytest.mark.parametrize("factory", [default_scene, furnace_sphere,
                                     lambda: furnace_sphere(0.5, "mirror"),
                                     lambda: furnace_sphere(bsdf="null")])
def test_factories_validate(factory):
    data = load_scene(factory()).data
    json.dumps(data, allow_nan=False)
    assert data["lights"]


def test_factory_contents():
    d = load_scene(default_scene()).data
    assert d["camera"]["resolution"] == [256, 256] and d["render"]["spp"] == 16
    bsdfs = [s["bsdf"]["type"] for s in d["shapes"] if s["type"] in ("sphere", "gpis")]
    assert sorted(bsdfs) == ["diffuse", "mirror"]
    gpis = [s for s in d["shapes"] if s["type"] == "gpis"]
    assert len(gpis) == 1 and gpis[0]["sampler"] == {"type": "weight_space", "features": 256}
    assert [lt["type"] for lt in d["lights"]] == ["rectangle"]
    f = load_scene(furnace_sphere(albedo=[0.5, 0.6, 0.7])).data
    assert f["camera"]["resolution"] == [32, 32]
    assert f["shapes"] == [{"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0,
                            "bsdf": {"type": "diffuse", "albedo": [0.5, 0.6, 0.7]}}]
    assert f["lights"] == [{"type": "environment", "radiance": [1.0, 1.0, 1.0]}]


# ---------------------------------------------------------------- errors

SPHERES = [{"type": "sphere"}, {"type": "sphere"}, {"type": "sphere", "radius": -1}]
TWO_LIGHTS = [{"type": "environment"}, {"type": "environment_map", "file": "sky.exr"}]

# (id, scene text or dict, key path, reason fragment)
BAD = [
    ("invalid_json", '{"lights": [\n  {"type": "environment"}\n  {"type": "point"}]}', "",
     "invalid JSON at line 3, column 3: Expecting ',' delimiter"),
    ("top_level_list", "[1, 2]", "", "top level must be a JSON object (got list)"),
    ("duplicate_key", '{"camera": {"fov": 30, "fov": 50}, "lights": [{"type": "environment"}]}',
     "camera.fov", "duplicate key"),
    ("unknown_key", minimal(lights=[{"type": "directional", "direction": [0, 1, 0],
                                     "irradiance": 1, "colour": 1}]),
     "lights[0].colour",
     "unknown key (expected one of: direction, irradiance, angular_radius, type)"),
    ("unknown_top_key", minimal(integrator="path"), "integrator", "unknown key"),
    ("missing_required", minimal(lights=[{"type": "point", "position": [0, 1, 0]}]),
     "lights[0].intensity", "missing required key"),
    ("missing_type", minimal(shapes=[{"radius": 1}]), "shapes[0].type", "missing required key"),
    ("wrong_type", minimal(camera={"fov": "wide"}), "camera.fov",
     'expected a number (got string "wide")'),
    ("bool_is_not_number", minimal(shapes=[{"type": "sphere", "radius": True}]),
     "shapes[0].radius", "expected a number (got boolean true)"),
    ("float_is_not_int", minimal(render={"spp": 16.0}), "render.spp", "expected an integer"),
    ("out_of_range", minimal(shapes=SPHERES), "shapes[2].radius", "must be > 0 (got -1)"),
    ("fov_range", minimal(camera={"fov": 180}), "camera.fov", "must be < 180"),
    ("seed_range", minimal(render={"seed": 2**32}), "render.seed", "must be < 4294967296"),
    ("survival_range", minimal(render={"russian_roulette": {"max_survival": 0}}),
     "render.russian_roulette.max_survival", "must be > 0"),
    ("resolution_range", minimal(camera={"resolution": [0, 10]}), "camera.resolution[0]",
     "must be >= 1"),
    ("bsdf_missing_type", minimal(shapes=[{"type": "sphere", "bsdf": {"albedo": [0.5, 1.5, 0]}}]),
     "shapes[0].bsdf.type", "missing required key"),
    ("albedo_above_one", minimal(shapes=[{"type": "sphere",
                                          "bsdf": {"type": "diffuse", "albedo": [0.5, 1.5, 0]}}]),
     "shapes[0].bsdf.albedo[1]", "must be <= 1"),
    ("negative_radiance", minimal(lights=[{"type": "environment", "radiance": -0.5}]),
     "lights[0].radiance", "must be >= 0"),
    ("unknown_shape_type", minimal(shapes=[{"type": "cube"}]), "shapes[0].type",
     'unknown shape type "cube" (expected one of: sphere, rectangle, box, disk, mesh, gpis)'),
    ("unknown_bsdf_type", minimal(shapes=[{"type": "sphere", "bsdf": {"type": "glass"}}]),
     "shapes[0].bsdf.type", "expected one of: diffuse, mirror, null, rough_conductor"),
    ("vector_length", minimal(camera={"position": [0, 1]}), "camera.position",
     "expected a list of 3 numbers (got 2 items)"),
    ("nan", '{"lights": [{"type": "environment", "radiance": [1, NaN, 1]}]}',
     "lights[0].radiance[1]", "must be a finite number (got NaN)"),
    ("infinity", '{"camera": {"position": [0, 1, Infinity]}, "lights": [{"type": "environment"}]}',
     "camera.position[2]", "must be a finite number"),
    ("huge_number", '{"camera": {"fov": 1e999}, "lights": [{"type": "environment"}]}',
     "camera.fov", "must be a finite number"),
    ("missing_mesh", minimal(shapes=[{"type": "mesh", "file": "nope.obj"}]), "shapes[0].file",
     "file not found"),
    ("unreadable_mesh", minimal(shapes=[{"type": "mesh", "file": "empty.obj"}]),
     "shapes[0].file", "mesh has no triangles"),
    ("mesh_format", minimal(shapes=[{"type": "mesh", "file": "tri.fbx"}]), "shapes[0].file",
     "unsupported file type"),
    ("mesh_scale", minimal(shapes=[{"type": "mesh", "file": "tri.obj",
                                    "transform": {"scale": [1, 0, 1]}}]),
     "shapes[0].transform.scale[1]", "must be > 0"),
    ("missing_envmap", minimal(lights=[{"type": "environment_map", "file": "nope.exr"}]),
     "lights[0].file", "file not found"),
    ("corrupt_envmap", minimal(lights=[{"type": "environment_map", "file": "junk.exr"}]),
     "lights[0].file", "cannot read as an OpenEXR image"),
    ("grey_envmap", minimal(lights=[{"type": "environment_map", "file": "grey.exr"}]),
     "lights[0].file", "lacks channel(s) R, G, B"),
    ("no_lights", {"lights": []}, "lights", "at least one light"),
    ("lights_missing", {"shapes": []}, "lights", "missing required key"),
    ("two_environments", {"lights": TWO_LIGHTS}, "lights[1]", "at most one environment light"),
    ("degenerate_rectangle", minimal(shapes=[{"type": "rectangle", "u": [1, 0, 0],
                                              "v": [-2, 0, 0]}]),
     "shapes[0].v", "must not be parallel to u"),
    ("zero_edge", minimal(lights=[{"type": "rectangle", "center": [0, 1, 0], "u": [0, 0, 0],
                                   "v": [1, 0, 0], "radiance": 1}]),
     "lights[0].u", "must be a non-zero vector"),
    ("degenerate_box", minimal(shapes=[{"type": "box", "min": [0, 1, 0], "max": [1, 1, 1]}]),
     "shapes[0].max", "must be > min in every component (got max[1] = 1 <= min[1] = 1)"),
    ("camera_on_target", minimal(camera={"position": [1, 2, 3], "look_at": [1, 2, 3]}),
     "camera.look_at", "must differ from position"),
    ("camera_up_parallel", minimal(camera={"position": [0, 5, 0], "look_at": [0, 0, 0]}),
     "camera.up", "must not be parallel to the view direction"),
    ("zero_direction", minimal(lights=[{"type": "directional", "direction": [0, 0, 0],
                                        "irradiance": 1}]),
     "lights[0].direction", "must be a non-zero vector"),
    ("sun_too_wide", minimal(lights=[{"type": "directional", "direction": [0, 1, 0],
                                      "irradiance": 1, "angular_radius": 90}]),
     "lights[0].angular_radius", "must be < 90 (got 90); allowed: 0 <= x < 90"),
    ("shapes_not_list", minimal(shapes={"type": "sphere"}), "shapes",
     "expected a list of shape objects"),
    ("batch_size", minimal(render={"batch_size": 0}), "render.batch_size", "must be >= 1"),
    ("two_sided_bool", minimal(lights=[{"type": "rectangle", "center": [0, 1, 0],
                                        "u": [1, 0, 0], "v": [0, 0, 1], "radiance": 1,
                                        "two_sided": 1}]),
     "lights[0].two_sided", "expected true or false (got number 1)"),
]


@pytest.fixture
def assets(tmp_path):
    write_obj(tmp_path / "tri.obj")
    (tmp_path / "tri.fbx").write_text("not really")
    (tmp_path / "empty.obj").write_text("# no faces\n")
    (tmp_path / "junk.exr").write_bytes(b"definitely not an EXR")
    write_exr(tmp_path / "sky.exr")
    write_exr(tmp_path / "grey.exr", channels=("Y",))
    return tmp_path


@pytest.mark.parametrize("name,content,key,reason", BAD, ids=[b[0] for b in BAD])
def test_bad_scene_files(assets, name, content, key, reason):
    path = write_json(assets / f"{name}.json", content)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    err = info.value
    assert err.file == str(path)
    assert err.key == key
    assert reason in err.reason
    text = str(err)
    assert "\n" not in text
    assert text == ": ".join([str(path)] + ([key] if key else []) + [err.reason])


def test_error_message_format(tmp_path):
    path = write_json(tmp_path / "x.json", minimal(shapes=SPHERES))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(info.value) == f"{path}: shapes[2].radius: must be > 0 (got -1)"


def test_scene_file_not_found(tmp_path):
    with pytest.raises(SceneError) as info:
        load_scene(tmp_path / "missing.json")
    assert info.value.key == "" and "file not found" in str(info.value)


def test_dict_errors_name_dict():
    with pytest.raises(SceneError) as info:
        load_scene(minimal(camera={"fov": -5}))
    assert str(info.value) == "<dict>: camera.fov: must be > 0 (got -5); allowed: 0 < x < 180"
    with pytest.raises(SceneError, match=r"^<dict>: lights\[0\]\.radiance\[0\]: must be a finite"):
        load_scene({"lights": [{"type": "environment", "radiance": [float("nan"), 0, 0]}]})


def test_not_a_scene_argument():
    with pytest.raises(TypeError):
        load_scene(42)


def test_new_kinds_are_declared_not_coded():
    """A later object kind needs only a declaration (here registered and then removed)."""
    from gpiscl.host.scene.records import SHAPES, shape
    from gpiscl.host.schema import Field, Number, Vector
    SHAPES.register("blob", shape({"center": Field(Vector(), [0, 0, 0]),
                                   "lengthscale": Field(Number(gt=0), 0.5)}))
    try:
        data = load_scene(minimal(shapes=[{"type": "blob"}])).data
        assert data["shapes"][0]["lengthscale"] == 0.5
        with pytest.raises(SceneError, match=r"shapes\[0\]\.lengthscale: must be > 0"):
            load_scene(minimal(shapes=[{"type": "blob", "lengthscale": 0}]))
    finally:
        del SHAPES.variants["blob"]
