"""The command line as a user meets it, and the files a render writes."""
import json
import subprocess
import sys

import numpy as np
import pytest

from gpiscl import load_scene, render_result
from gpiscl.host.io.images import read_exr
from gpiscl.host.render.output import write_outputs
from gpiscl.scenes import furnace_sphere


def gpiscl_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "gpiscl", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


def test_exr_round_trip_keeps_mean_and_standard_error(device, tmp_path):
    scene = load_scene(furnace_sphere(albedo=0.5))
    res = render_result(scene, spp=4, device=device)
    paths = write_outputs(res.image, scene, tmp_path / "img.exr")
    ch = read_exr(paths["exr"])
    rgb = np.stack([ch["R"], ch["G"], ch["B"]], axis=-1)
    np.testing.assert_array_equal(rgb, res.image.mean)
    np.testing.assert_array_equal(ch["stderr.G"], res.image.stderr[..., 1])
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert load_scene(str(paths["scene"])).data == scene.data


def test_render_command_writes_exr_png_and_resolved_scene(tmp_path):
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(furnace_sphere(albedo=0.5)))
    out = tmp_path / "r" / "img.exr"
    r = gpiscl_cli("render", str(scene), "-o", str(out), "--spp", "2", "--resolution", "8x6",
                   "--stats")
    assert r.returncode == 0, r.stderr
    assert out.exists() and out.with_suffix(".png").exists()
    resolved = json.loads((tmp_path / "r" / "img.scene.json").read_text())
    assert resolved["camera"]["resolution"] == [8, 6] and resolved["render"]["spp"] == 2
    assert "scatter" in r.stderr and "items/s" in r.stderr  # the --stats table
    assert read_exr(out)["R"].shape == (6, 8)


BAD_SCENES = [
    ('{"lights": [{"type": "environment"}], "camera": {"fov": 200}}', "camera.fov"),
    ('{"lights": [{"type": "environment", "radiance": -1}]}', "lights[0].radiance"),
    ('{"lights": []}', "lights"),
    ('{"lights": [{"type": "environment"}], "shapes": [{"type": "cone"}]}', "shapes[0].type"),
    ('{"lights": [{"type": "environment"}], "render": {"spp": 0}}', "render.spp"),
    ('{"lights": [{"type": "environment"}], "colour": 1}', "colour"),
    ('{"lights": [{"type": "environment"}', "invalid JSON"),
]


@pytest.mark.parametrize("text,key", BAD_SCENES)
def test_bad_scene_gives_one_line_error_and_exit_code_2(tmp_path, text, key):
    path = tmp_path / "bad.json"
    path.write_text(text)
    r = gpiscl_cli("render", str(path), "-o", str(tmp_path / "x.exr"))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith(f"error: {path}") and key in lines[0]
    assert not (tmp_path / "x.exr").exists()


def test_missing_scene_file_and_bad_device_are_clean_errors(tmp_path):
    r = gpiscl_cli("render", str(tmp_path / "nope.json"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and "nope.json" in r.stderr
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(furnace_sphere()))
    r = gpiscl_cli("render", str(scene), "--device", "no-such-device")
    assert r.returncode == 2 and "no-such-device" in r.stderr and "Traceback" not in r.stderr


def test_devices_lists_the_default_device():
    r = gpiscl_cli("devices")
    assert r.returncode == 0
    assert any(line.startswith("*") for line in r.stdout.splitlines())


def test_realization_flag_sets_and_clears_the_fixed_realization(tmp_path):
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps({
        "render": {"realization": 5}, "lights": [{"type": "environment"}],
        "camera": {"resolution": [4, 4]}}))
    for flag, expected in (("3", 3), ("none", None), ("NONE", None)):
        out = tmp_path / f"r{flag}.exr"
        r = gpiscl_cli("render", str(scene), "-o", str(out), "--spp", "1",
                       "--realization", flag)
        assert r.returncode == 0, r.stderr
        resolved = json.loads(out.with_suffix(".scene.json").read_text())
        assert resolved["render"]["realization"] == expected
    r = gpiscl_cli("render", str(scene), "-o", str(tmp_path / "x.exr"), "--realization", "-1")
    assert r.returncode == 2 and "--realization" in r.stderr


def test_errors_found_while_compiling_name_file_and_shape(tmp_path):
    """A mean CSG tree too deep for the device's stack is found only when the scene is
    compiled: still one line naming the file and the shape's key path."""
    def balanced(depth, x=0.0):
        if depth == 0:
            return {"type": "sphere", "center": [x, 0, 0], "radius": 0.01}
        return {"type": "union", "left": balanced(depth - 1, x), "right":
                balanced(depth - 1, x + 2.0 ** (depth - 1) * 0.03)}
    scene = {"lights": [{"type": "environment"}], "camera": {"resolution": [4, 4]},
             "shapes": [{"type": "sphere", "radius": 0.1},
                        {"type": "gpis", "proxy": {"type": "sphere", "radius": 20},
                         "mean": balanced(9),
                         "kernel": {"type": "squared_exponential", "sigma": 0.01,
                                    "length_scale": 0.1}}]}
    path = tmp_path / "deep.json"
    path.write_text(json.dumps(scene))
    r = gpiscl_cli("render", str(path), "-o", str(tmp_path / "x.exr"), "--spp", "1")
    assert r.returncode == 2, r.stderr
    err = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and f"{path}: shapes[1].mean: " in err[0] and "stack" in err[0]
    assert "Traceback" not in r.stderr


def test_api_renders_share_one_device_and_its_programs():
    """Built programs are cached per context (and keep it alive): API calls without a
    device must reuse one, or a loop of renders would grow memory without bound."""
    from gpiscl.host.render import device as device_mod
    from gpiscl.scenes import furnace_sphere
    render_result(furnace_sphere(), spp=1, resolution=(4, 4))
    built = len(device_mod._BUILT)
    for _ in range(3):
        render_result(furnace_sphere(), spp=1, resolution=(4, 4))
    assert len(device_mod._BUILT) == built
    assert device_mod.shared_device() is device_mod.shared_device()
