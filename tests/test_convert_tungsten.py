"""tools/convert_tungsten.py: the authors' CSG test scene imports, renders, and what we
cannot import is an error naming the key path."""
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gpiscl import load_scene, render_result
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.tungsten import convert_tungsten

ROOT = Path(__file__).resolve().parent.parent
CSG = ROOT / "tests" / "data" / "tungsten" / "gp-csg-test.json"
SKY = {"type": "environment", "radiance": 0.3}


def authors_scene():
    return json.loads(CSG.read_text())


def test_csg_scene_maps_every_gp_setting():
    scene, notes = convert_tungsten(authors_scene(), str(CSG), SKY)
    data = load_scene(scene).data  # strict loader accepts it
    gpis = [s for s in data["shapes"] if s["type"] == "gpis"]
    # csg union -> two independent objects sharing the proxy box
    assert len(gpis) == 2
    assert gpis[0]["proxy"] == gpis[1]["proxy"]
    assert gpis[0]["proxy"]["min"] == pytest.approx([-1.5, -0.499, -1.5])
    assert gpis[0]["proxy"]["max"] == pytest.approx([1.5, 2.501, 1.5])
    assert gpis[0]["mean"] == {"type": "sphere", "center": [-0.4, 0.8, 0.0], "radius": 0.8}
    assert gpis[1]["kernel"]["sigma"] == 0.001 and gpis[1]["kernel"]["length_scale"] == 0.5
    s = gpis[0]["sampler"]
    assert (s["type"], s["memory"]) == ("function_space", "renewal_plus")  # goldfish: Renewal+
    assert "samples" not in s and "step_corr" not in s   # the step is adaptive
    assert gpis[0]["bsdf"] == {"type": "mirror", "albedo": [0.35, 0.3, 0.9],
                               "material": None, "eta": None, "k": None}   # no Fresnel
    assert data["render"]["max_depth"] == 20 and data["render"]["spp"] == 1
    assert data["camera"]["fov"] == pytest.approx(20.0)  # square image: vertical = horizontal
    sun = [l for l in data["lights"] if l["type"] == "directional"]
    assert len(sun) == 2
    # the sky cap: radiance power / (2 pi (1 - cos 50 deg)) over the cap, seen on axis
    theta = math.radians(50)
    E = 4.5 / (2 * math.pi * (1 - math.cos(theta))) * math.pi * math.sin(theta) ** 2
    assert sun[1]["irradiance"][0] == pytest.approx(E)
    assert sun[1]["direction"] == pytest.approx([0, 1, 0])
    floor = data["shapes"][0]
    assert floor["type"] == "rectangle" and floor["bsdf"]["albedo"] == pytest.approx([0.5] * 3)
    assert any("checker" in n for n in notes) and any("environment" in n for n in notes)


@pytest.mark.parametrize("v,kind", [(1.5, "matern32"), (2.5, "matern52")])
def test_matern_covariances_map_by_smoothness(v, kind):
    """Their matern {sigma, v, lengthScale, aniso} -> ours, the same sigma and l (both
    scale r by sqrt(2 v) / l), with a note on their lgamma normalisation."""
    doc = _with(GP + ["left", "covariance"], {"type": "matern", "sigma": 0.05, "v": v,
                                              "lengthScale": 0.3, "aniso": [1, 2, 1]})
    scene, notes = convert_tungsten(doc, str(CSG), SKY)
    gpis = [s for s in load_scene(scene).data["shapes"] if s["type"] == "gpis"]
    k = gpis[0]["kernel"]
    assert (k["type"], k["sigma"], k["length_scale"]) == (kind, 0.05, 0.3)
    assert k["aniso"] == [1, 2, 1]
    assert any("lgamma" in n for n in notes)


def test_converted_scene_renders(device):
    scene, _ = convert_tungsten(authors_scene(), str(CSG), SKY)
    res = render_result(scene, spp=2, resolution=(12, 12), device=device)
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0
    assert np.all(np.isfinite(res.image.mean)) and res.image.mean.max() > 0


def _with(path, value):
    doc = authors_scene()
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return doc


GP = ["media", 0, "gaussian_process"]
BAD = [
    (_with(GP + ["left", "mean"], {"type": "neural", "network": "net.bin"}),
     "media[0].gaussian_process.left.mean.type", "not supported"),
    (_with(GP + ["left", "mean"], {"type": "procedural", "f": {"type": "noise"}}),
     "media[0].gaussian_process.left.mean.f", "procedural scalar means are not supported"),
    (_with(GP + ["right", "covariance", "smoothness"], 0.01),
     "media[0].gaussian_process.right.covariance.smoothness", "the reference ignores it"),
    (_with(GP + ["left", "covariance"], {"type": "periodic", "w": 1.0}),
     "media[0].gaussian_process.left.covariance.type", "radial"),
    (_with(GP + ["left", "covariance"], {"type": "matern", "sigma": 0.1}),
     "media[0].gaussian_process.left.covariance.v", "smoothness 1 is not supported"),
    (_with(GP + ["left", "covariance"], {"type": "matern", "v": 0.5}),
     "media[0].gaussian_process.left.covariance.v", "v = 1.5 and 2.5"),
    (_with(GP + ["left", "covariance"], {"type": "matern", "v": 1.5, "nu": 2}),
     "media[0].gaussian_process.left.covariance.nu", "unknown matern key"),
    (_with(GP + ["left", "covariance"], {"type": "matern", "v": 2.5, "lengthScale": -1}),
     "media[0].gaussian_process.left.covariance.lengthScale", "must be > 0"),
    (_with(["media", 0, "correlation_context"], "parrot"),
     "media[0].correlation_context", "unknown memory model"),
    (_with(["media", 0, "phase_function", "bsdf", "type"], "plastic"),
     "media[0].phase_function.bsdf.type", "micro-BSDF"),
    (_with(["media", 0, "phase_function", "bsdf"], {"type": "rough_conductor",
                                                    "distribution": "ggx"}),
     "media[0].phase_function.bsdf.distribution", "beckmann only"),
    (_with(["primitives", 1, "transform", "rotation"], [0, 45, 0]),
     "primitives[1].transform.rotation", "axis-aligned"),
    (_with(["primitives", 1, "int_medium"], "fog"),
     "primitives[1].int_medium", 'no entry named "fog"'),
    (_with(["primitives", 0, "type"], "curves"), "primitives[0].type", "not supported"),
    (_with(["camera", "type"], "thinlens"), "camera.type", "pinhole only"),
    # malformed values: one line at the input's key path
    (_with(["primitives", 2, "cap_angle"], 0), "primitives[2].cap_angle", "must be > 0"),
    (_with(["camera"], 5), "camera", "expected an object"),
    (_with(["camera", "resolution"], "abc"), "camera.resolution", "expected an integer"),
    (_with(["camera", "resolution"], [512, 0]), "camera.resolution[1]", "must be >= 1"),
    (_with(["media", 0, "sample_points"], 1.5), "media[0].sample_points",
     "expected an integer"),
    (_with(GP + ["left", "id"], -1), "media[0].gaussian_process.left.id", "must be >= 0"),
    (_with(GP + ["left", "mean", "radius"], float("nan")),
     "media[0].gaussian_process.left.mean.radius", "must be finite"),
    (_with(["primitives", 1, "transform", "position"], [0, "1", 0]),
     "primitives[1].transform.position[1]", "expected a number"),
    (_with(["media", 0, "sigma_s"], 0), "media[0].sigma_s", "must be > 0"),
]


@pytest.mark.parametrize("doc,key,reason", BAD, ids=[b[1] for b in BAD])
def test_unsupported_input_names_the_key(doc, key, reason):
    with pytest.raises(SceneError) as info:
        convert_tungsten(doc, str(CSG), SKY)
    assert info.value.key == key and reason in info.value.reason


def run_tool(*args):
    """tools/convert_tungsten.py on this checkout's gpiscl (a script's sys.path starts at
    tools/, so an installed gpiscl elsewhere would otherwise win)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, str(ROOT / "tools" / "convert_tungsten.py"),
                           *map(str, args)], capture_output=True, text=True, env=env)


def test_missing_environment_map_is_an_error_unless_substituted(tmp_path):
    out = tmp_path / "scene.json"
    r = run_tool(CSG, out)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "primitives[4].emission" in r.stderr and "substitute environment" in r.stderr
    r = run_tool(CSG, out, "--environment", "0.3")
    assert r.returncode == 0, r.stderr
    assert load_scene(out).data["lights"][-1] == {"type": "environment",
                                                 "radiance": [0.3, 0.3, 0.3]}


def _tungsten_rotation(degrees):
    """The reference's Mat4f::rotYXZ, entry by entry as their Mat4f.cpp writes it (not
    as a product of textbook rotations, which is how the Y sign went wrong before)."""
    c = np.cos(np.radians(degrees))
    s = np.sin(np.radians(degrees))
    return np.array([
        [c[1] * c[2] - s[1] * s[0] * s[2], -c[1] * s[2] - s[1] * s[0] * c[2], -s[1] * c[0]],
        [c[0] * s[2], c[0] * c[2], -s[0]],
        [s[1] * c[2] + c[1] * s[0] * s[2], -s[1] * s[2] + c[1] * s[0] * c[2], c[1] * c[0]]])


def test_y_rotation_turns_as_theirs():
    """A sun cap tilted by x = 90 degrees (to +z) and turned by y = 90 degrees: their
    rotYXZ points it along -x; a right-handed Ry (the old reading) gave +x."""
    doc = _with(["primitives", 2, "transform"], {"rotation": [90, 90, 0]})
    scene, _ = convert_tungsten(doc, str(CSG), SKY)
    sun = scene["lights"][0]
    assert sun["type"] == "directional"
    np.testing.assert_allclose(sun["direction"], _tungsten_rotation([90, 90, 0]) @ [0, 1, 0],
                               atol=1e-12)
    np.testing.assert_allclose(sun["direction"], [-1, 0, 0], atol=1e-12)


def _mesh_doc(tmp_path, mean):
    (tmp_path / "meshes").mkdir(exist_ok=True)
    (tmp_path / "meshes" / "wedge.obj").write_bytes(
        (ROOT / "scenes" / "assets" / "wedge.obj").read_bytes())
    doc = _with(GP + ["left", "mean"], mean)
    source = tmp_path / "scene.json"
    source.write_text(json.dumps(doc))
    return doc, str(source)


def test_mesh_mean_maps_file_and_transform(tmp_path):
    """A Tungsten mesh mean becomes our mesh mean: the file resolved against the scene's
    folder and a transform that puts every vertex where the reference's T R S puts it."""
    t = {"position": [0.1, 1.0, -0.49], "scale": [0.5, 0.25, 0.75], "rotation": [30, -50, 70]}
    doc, source = _mesh_doc(tmp_path, {"type": "mesh", "file": "meshes/wedge.obj",
                                       "transform": t, "signed": True})
    scene, notes = convert_tungsten(doc, source, SKY)
    mean = scene["shapes"][1]["mean"]
    assert mean["type"] == "mesh" and mean["file"] == str(tmp_path / "meshes" / "wedge.obj")
    data = load_scene(scene).data           # the strict loader accepts it
    mt = data["shapes"][1]["mean"]["transform"]
    from gpiscl.host.scene.transforms import euler_matrix
    import trimesh
    v = np.asarray(trimesh.load(ROOT / "scenes" / "assets" / "wedge.obj", process=False).vertices)
    ours = v * mt["scale"] @ euler_matrix(mt["rotate"]).T + mt["translate"]
    theirs = v * t["scale"] @ _tungsten_rotation(t["rotation"]).T + t["position"]
    np.testing.assert_allclose(ours, theirs, atol=1e-12)
    assert any("signed" in n for n in notes) and any("baked" in n for n in notes)


MESH = GP + ["left", "mean"]


@pytest.mark.parametrize("mean,key,reason", [
    ({"type": "mesh", "file": "meshes/wedge.wo3"}, "file", "convert it"),
    ({"type": "mesh", "file": "meshes/none.obj"}, "file", "file not found"),
    ({"type": "mesh", "file": "meshes/wedge.obj", "min": -0.1}, "min", "clamped"),
    ({"type": "mesh", "file": "meshes/wedge.obj", "smooth": True}, "smooth", "unknown"),
    ({"type": "mesh", "file": "meshes/wedge.obj", "transform": [1] * 16}, "transform",
     "only {position, scale, rotation}"),
], ids=["wo3", "missing", "min", "unknown", "matrix"])
def test_unsupported_mesh_means_name_the_key(tmp_path, mean, key, reason):
    doc, source = _mesh_doc(tmp_path, mean)
    with pytest.raises(SceneError) as info:
        convert_tungsten(doc, source, SKY)
    assert info.value.key == "media[0].gaussian_process.left.mean." + key
    assert reason in info.value.reason, info.value.reason


def test_mesh_proxy_maps_to_a_convex_mesh_proxy(tmp_path):
    """The authors' wedge: the medium's proxy is a mesh with a forward BSDF."""
    doc, source = _mesh_doc(tmp_path, {"type": "spherical"})
    doc["primitives"][1] = {"type": "mesh", "file": "meshes/wedge.obj", "bsdf": "processBox",
                            "int_medium": "gp",
                            "transform": {"position": [0, 1, -0.49], "scale": 0.5}}
    scene, _ = convert_tungsten(doc, source, SKY)
    data = load_scene(scene).data   # the strict loader accepts it: closed and convex
    proxies = [s["proxy"] for s in data["shapes"] if s["type"] == "gpis"]
    assert len(proxies) == 2 and all(p["type"] == "mesh" for p in proxies)
    assert proxies[0]["file"] == str(tmp_path / "meshes" / "wedge.obj")
    assert proxies[0]["transform"]["translate"] == pytest.approx([0, 1, -0.49])
    assert proxies[0]["transform"]["scale"] == pytest.approx([0.5] * 3)


# ---- VDB-backed means and sigma grids (the authors' baked CSG and bunny scenes) ----------

def _baked_doc(scale=2.0, offset=0.0):
    """The CSG test with its GP replaced by the baked one of gp-csg-test/baked-32.json,
    with the bunny's grid transform and interpolation keys."""
    doc = authors_scene()
    grid = {"type": "vdb", "file": "baked.vdb", "normalize_size": False,
            "transform": {"position": [0, 0.8, 0]}}
    doc["media"][0]["gaussian_process"] = {
        "id": 0, "type": "standard",
        "mean": {"type": "tabulated",
                 "grid": {**grid, "density_name": "mean", "interpolate": "quadratic"}},
        "covariance": {"type": "nonstationary", "offset": offset, "scale": scale,
                       "cov": {"type": "squared_exponential", "lengthScale": 0.5, "sigma": 1},
                       "grid": {**grid, "density_name": "variance", "interpolate": "linear"}}}
    return doc


def _assets():
    from gpiscl.host.io.grids import load_grid
    assets = ROOT / "scenes" / "assets"
    return load_grid(assets / "csg_baked_mean.npz"), load_grid(assets / "csg_baked_sigma.npz")


def test_vdb_grids_map_to_grid_means_and_sigma_fields(tmp_path, monkeypatch, device):
    """Without a binding, grids converted elsewhere (STEM.NAME.npz beside the .vdb) are
    used; offset/scale reach the sigma values, the grid transform becomes a transform
    mean and moves the sigma grid's origin, and the scene renders."""
    from gpiscl.host.io import vdb
    from gpiscl.host.io.grids import load_field_grid, save_grid
    monkeypatch.setattr(vdb, "import_openvdb", lambda: None)
    mean, sd = _assets()
    save_grid(tmp_path / "baked.mean.npz", mean)
    save_grid(tmp_path / "baked.variance.npz", sd)
    (tmp_path / "baked.vdb").write_bytes(b"")
    scene, notes = convert_tungsten(_baked_doc(), str(tmp_path / "scene.json"), SKY)
    g = [s for s in load_scene(scene).data["shapes"] if s["type"] == "gpis"][0]
    assert g["mean"]["type"] == "transform" and g["mean"]["translate"] == [0, 0.8, 0]
    assert g["mean"]["child"]["interpolation"] == "linear"
    assert any("quadratic" in n for n in notes)
    field = load_field_grid(g["kernel"]["sigma_field"]["file"])
    np.testing.assert_allclose(field.values, 2.0 * sd.values, rtol=1e-6)
    np.testing.assert_allclose(field.origin, np.asarray(sd.origin) + [0, 0.8, 0])
    assert g["sampler"]["type"] == "function_space"
    res = render_result(scene, spp=1, resolution=(8, 8), device=device)
    assert res.stats.gpis_failed == 0 and res.stats.nan_paths == 0, res.stats.summary()


def test_vdb_grids_without_a_binding_or_a_converted_copy_say_how(tmp_path, monkeypatch):
    from gpiscl.host.io import vdb
    monkeypatch.setattr(vdb, "import_openvdb", lambda: None)
    (tmp_path / "baked.vdb").write_bytes(b"")
    with pytest.raises(SceneError) as info:
        convert_tungsten(_baked_doc(), str(tmp_path / "scene.json"), SKY)
    assert info.value.key == "media[0].gaussian_process.mean.grid.file"
    assert "convert-vdb baked.vdb baked.mean.npz --grid mean" in info.value.reason


def test_vdb_grids_convert_with_a_binding_and_refuse_a_negative_sigma(tmp_path, monkeypatch):
    """With a (stand-in) OpenVDB binding the grids are converted into grid_dir; a sigma
    grid that offset and scale make negative is an error at the covariance's key."""
    import types
    from gpiscl.host.io import vdb
    from gpiscl.testing.fake_openvdb import FakeGrid
    mean, sd = _assets()

    def fake(name, grid):
        voxels = {tuple(int(i) for i in ijk): float(grid.values[tuple(ijk)])
                  for ijk in np.argwhere(np.ones(grid.shape, bool))}
        return FakeGrid(name, voxels, 0.0, grid.voxel_size, grid.origin)

    grids = [fake("mean", mean), fake("variance", sd)]
    monkeypatch.setattr(vdb, "import_openvdb",
                        lambda: types.SimpleNamespace(readAll=lambda path: (grids, {})))
    (tmp_path / "baked.vdb").write_bytes(b"")
    out = tmp_path / "grids"
    out.mkdir()
    scene, _ = convert_tungsten(_baked_doc(), str(tmp_path / "scene.json"), SKY, grid_dir=out)
    load_scene(scene)
    assert (out / "baked.mean.npz").is_file() and (out / "baked.variance.sigma.npz").is_file()
    with pytest.raises(SceneError) as info:
        convert_tungsten(_baked_doc(offset=-0.05), str(tmp_path / "scene.json"), SKY,
                         grid_dir=out)
    assert info.value.key == "media[0].gaussian_process.covariance.grid"
    assert "must be > 0" in info.value.reason


def test_rough_copper_maps_to_the_rough_conductor():
    """The wedge scenes' phase function: rough_conductor Cu, Beckmann 0.1."""
    doc = _with(["media", 0, "phase_function", "bsdf"],
                {"type": "rough_conductor", "material": "Cu", "distribution": "beckmann",
                 "roughness": 0.1})
    scene, _ = convert_tungsten(doc, str(CSG), SKY)
    gpis = [s for s in load_scene(scene).data["shapes"] if s["type"] == "gpis"]
    assert gpis[0]["bsdf"] == {"type": "rough_conductor", "material": "Cu", "roughness": 0.1,
                               "albedo": [1.0, 1.0, 1.0], "eta": None, "k": None}
