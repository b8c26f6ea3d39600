"""Inputs refused before any work, each with one line naming the file, key path and reason:
non-finite and out-of-float32-range numbers anywhere (scene, meshes, grids, environment
maps), damaged files, depth that would overflow or recurse, and files that are not what
they claim, without echoing their content."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from unprivileged import permissions_enforced
from gpiscl.host.io.images import write_exr
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene

ROOT = Path(__file__).resolve().parents[1]
CUBE = """v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8
f 3 8 7\nf 4 1 5\nf 4 5 8\n"""


def scene(tmp_path, shapes=(), lights=None, **top):
    doc = {"lights": lights or [{"type": "environment"}], "shapes": list(shapes), **top}
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    return path


def gpis(mean, **extra):
    return {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.4}, "mean": mean,
            "kernel": {"type": "squared_exponential", "sigma": 0.05, "length_scale": 0.15},
            **extra}


def refused(path, key, reason):
    with pytest.raises(SceneError) as info:
        load_scene(str(path))
    assert info.value.key == key and reason in info.value.reason, str(info.value)
    return str(info.value)


def test_numbers_beyond_float32_are_refused(tmp_path):
    box = {"type": "box", "min": [0, 0, 0], "max": [1, 3.5e38, 1]}
    refused(scene(tmp_path, [box]), "shapes[0].max[1]", "float32")
    floor = {"type": "rectangle", "center": [0, -1, 0], "u": [1e20, 0, 0], "v": [0, 0, -6]}
    refused(scene(tmp_path, [floor]), "shapes[0].u[0]", "within")
    refused(scene(tmp_path, render={"max_depth": 2**31}), "render.max_depth", "int32")
    refused(scene(tmp_path, render={"russian_roulette": {"start_depth": 2**31}}),
            "render.russian_roulette.start_depth", "int32")


@pytest.mark.parametrize("vertex,reason", [("nan 0 0", "NaN"), ("1e39 0 0", "beyond"),
                                           ("1e30 0 0", "beyond")])
def test_mesh_vertices_must_be_finite_and_in_range(tmp_path, vertex, reason):
    (tmp_path / "m.obj").write_text(CUBE.replace("v 1 1 1", "v " + vertex))
    refused(scene(tmp_path, [{"type": "mesh", "file": "m.obj"}]), "shapes[0].file", reason)


def test_obj_index_zero_is_refused(tmp_path):
    (tmp_path / "m.obj").write_text(CUBE + "f 0 1 2\n")
    refused(scene(tmp_path, [{"type": "mesh", "file": "m.obj"}]), "shapes[0].file",
            "line 21 uses vertex index 0")


@pytest.mark.parametrize("texel,reason", [(-1.0, "negative"), (np.nan, "NaN"),
                                          (np.inf, "NaN")])
def test_environment_maps_must_be_finite_and_non_negative(tmp_path, texel, reason):
    rgb = np.ones((4, 8, 3), np.float32)
    rgb[1, 2, 0] = texel
    write_exr(tmp_path / "sky.exr", rgb)
    light = [{"type": "environment_map", "file": "sky.exr"}]
    refused(scene(tmp_path, lights=light), "lights[0].file", reason)


def test_truncated_environment_map_is_refused(tmp_path):
    rng = np.random.default_rng(0)
    write_exr(tmp_path / "full.exr", rng.random((64, 128, 3)).astype(np.float32))
    data = (tmp_path / "full.exr").read_bytes()
    (tmp_path / "sky.exr").write_bytes(data[: len(data) // 2])
    light = [{"type": "environment_map", "file": "sky.exr"}]
    path = scene(tmp_path, lights=light)
    refused(path, "lights[0].file", "truncated")
    # from the shell: our one line and nothing else (OpenEXR printed its own two
    # diagnostics, one on stdout and one on stderr, before it)
    r = subprocess.run([sys.executable, "-m", "gpiscl", "render", str(path), "-o",
                        str(tmp_path / "x.exr")], capture_output=True, text=True, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, (r.stdout,
                                                                              r.stderr)
    assert "truncated" in r.stderr


@pytest.mark.parametrize("voxel,reason", [(1e-300, "voxel_size"), (1e30, "voxel_size")])
def test_grid_voxel_size_must_be_in_range(tmp_path, voxel, reason):
    np.savez(tmp_path / "g.npz", values=np.ones((4, 4, 4)), origin=[0, 0, 0],
             voxel_size=voxel)
    refused(scene(tmp_path, [gpis({"type": "grid", "file": "g.npz"})]),
            "shapes[0].mean.file", reason)


def test_deep_nesting_is_a_clear_error(tmp_path):
    mean = {"type": "sphere", "radius": 0.5}
    for _ in range(600):
        mean = {"type": "union", "left": mean, "right": {"type": "sphere", "radius": 0.1}}
    with pytest.raises(SceneError, match="nested more than 100 levels deep") as info:
        load_scene(str(scene(tmp_path, [gpis(mean)])))
    assert len(str(info.value)) < 300


def test_tiny_occupancy_is_refused(tmp_path):
    refused(scene(tmp_path, [gpis({"type": "sphere", "radius": 0.8},
                                  bounds={"occupancy": 1e-20})]),
            "shapes[0].bounds.occupancy", ">= 1e-12")


def test_errors_never_echo_the_content_of_a_named_file(tmp_path):
    secret = tmp_path / "secret"
    secret.write_text("root:x:0:0:the secret line\n")
    (tmp_path / "leak.txt").symlink_to(secret)
    shape = gpis({"type": "sphere", "radius": 0.8}, sampler={"type": "function_space"},
                 observations={"file": "leak.txt"})
    message = refused(scene(tmp_path, [shape]), "shapes[0].observations.file",
                      "not rows of numbers (row 1, column 1)")
    assert "secret line" not in message and "root:x" not in message
    (tmp_path / "m.obj").write_text("v the secret line\nf 1 2 3\n")
    with pytest.raises(SceneError) as info:
        load_scene(str(scene(tmp_path, [{"type": "mesh", "file": "m.obj"}])))
    assert "secret" not in str(info.value)


def test_scene_files_that_are_not_regular_files(tmp_path):
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    with pytest.raises(SceneError, match="not a regular file"):
        load_scene(str(fifo))
    with pytest.raises(SceneError, match="not a regular file"):
        load_scene("/dev/zero")


def test_assets_resolve_next_to_the_scene_file_through_a_link(tmp_path):
    (tmp_path / "project").mkdir()
    (tmp_path / "link").mkdir()
    (tmp_path / "project" / "m.obj").write_text(CUBE)
    real = scene(tmp_path / "project", [{"type": "mesh", "file": "m.obj"}])
    (tmp_path / "link" / "scene.json").symlink_to(real)
    s = load_scene(str(tmp_path / "link" / "scene.json"))
    assert s.data["shapes"][0]["file"] == str(tmp_path / "project" / "m.obj")


def test_unreadable_points_file_is_one_line(tmp_path):
    (tmp_path / "p.xyz").write_text("0 0 0\n")
    (tmp_path / "p.xyz").chmod(0)
    shape = gpis({"type": "sphere", "radius": 0.8}, sampler={"type": "function_space"},
                 observations={"file": "p.xyz"})
    path = scene(tmp_path, [shape])
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run(permissions_enforced([sys.executable, "-m", "gpiscl", "render", str(path),
                                             "-o", str(tmp_path / "x.exr")]),
                       capture_output=True, text=True, cwd=ROOT, env=env)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "shapes[0].observations.file" in r.stderr and "Permission denied" in r.stderr


def test_observed_points_beyond_float32_are_refused(tmp_path):
    """A point at 1e300 rendered with thousands of undecided root searches (exit 0)."""
    (tmp_path / "p.xyz").write_text("0 0.8 0\n1e300 0 0\n")
    shape = gpis({"type": "sphere", "radius": 0.8}, sampler={"type": "function_space"},
                 observations={"file": "p.xyz"})
    refused(scene(tmp_path, [shape]), "shapes[0].observations.file", "beyond")


def test_cluster_without_dask_is_one_line(tmp_path, monkeypatch, capsys):
    """Dask is an optional extra: without it --cluster says how to get it, before any work."""
    from gpiscl.cli import main
    monkeypatch.setitem(sys.modules, "distributed", None)     # import distributed fails
    monkeypatch.delitem(sys.modules, "gpiscl.host.distributed.cluster", raising=False)
    import gpiscl.host.distributed as distributed
    monkeypatch.delattr(distributed, "cluster", raising=False)
    path = scene(tmp_path, [{"type": "sphere", "center": [0, 0, 0], "radius": 0.5}])
    assert main(["render", str(path), "--cluster", "local:1", "-o",
                 str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gpiscl[distributed]" in err[0], err
    assert not (tmp_path / "x.exr").exists()


def test_the_command_line_gives_these_as_one_line(tmp_path):
    (tmp_path / "m.obj").write_text(CUBE.replace("v 1 1 1", "v nan 0 0"))
    path = scene(tmp_path, [{"type": "mesh", "file": "m.obj"}])
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "gpiscl", "render", str(path), "-o",
                        str(tmp_path / "x.exr")], capture_output=True, text=True, cwd=ROOT,
                       env=env)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith(f"error: {path}: shapes[0].file: mesh has 1 NaN")


def test_small_command_line_mistakes_are_one_line(tmp_path):
    import numpy as np
    np.save(tmp_path / "structured.npy", np.zeros(4, dtype=[("a", "f4"), ("b", "f4")]))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for args, fragment in (
            (["render", "--device", "0:0:0", "-o", str(tmp_path / "a.exr")], "expected P:D"),
            (["render", "--exposure", "1e308", "-o", str(tmp_path / "b.exr")], "--exposure"),
            (["render", "--exposure", "nan", "-o", str(tmp_path / "c.exr")], "--exposure"),
            (["sample", "squared_exponential", "--observations",
              str(tmp_path / "structured.npy"), "-o", str(tmp_path / "f")], "must be numbers")):
        r = subprocess.run([sys.executable, "-m", "gpiscl", *args], capture_output=True,
                           text=True, cwd=ROOT, env=env)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert fragment in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("doc,key", [({"camera": 5}, "camera"),
                                     ({"camera": {"resolution": "abc"}}, "camera.resolution"),
                                     ({"renderer": 3}, "renderer"),
                                     ({"primitives": 3}, "primitives"),
                                     ({"primitives": [7]}, "primitives[0]"),
                                     ([1, 2], "")])
def test_malformed_tungsten_input_is_a_scene_error(doc, key):
    from gpiscl.host.scene.tungsten import convert_tungsten
    with pytest.raises(SceneError) as info:
        convert_tungsten(doc, "in.json", {"type": "environment", "radiance": 0.5})
    assert info.value.file == "in.json" and info.value.key == key, str(info.value)


def test_spp_beyond_int32_is_refused_in_the_scene_and_on_the_command_line(tmp_path):
    """The device counts sample indices in int32: 2^31 spp rendered on (for hours) with
    the index wrapping, from the command line and from a scene file alike."""
    refused(scene(tmp_path, render={"spp": 2**31}), "render.spp", "must be < 2147483648")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "gpiscl", "render", "--spp", str(2**31), "-o",
                        str(tmp_path / "x.exr")], capture_output=True, text=True, cwd=ROOT,
                       env=env, timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "--spp" in r.stderr and "2147483648" in r.stderr
    assert not (tmp_path / "x.exr").exists()
