"""Scene settings by key path (--set KEY=VALUE, the API's settings=), --resolution N,
--device by type, the built-in scene's name, sizes in errors: what a newcomer meets first."""
import json
import subprocess
import sys

import pytest

from gpiscl import api
from gpiscl.cli import args
from gpiscl.host.errors import API_SOURCE, CLI_SOURCE, SceneError
from gpiscl.host.io.images import read_exr_attributes
from gpiscl.host.render.device import DEVICE_TYPES, shared_device
from gpiscl.scenes import default_scene, furnace_sphere


def gpiscl_cli(*argv, cwd=None):
    return subprocess.run([sys.executable, "-m", "gpiscl", *argv], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


def test_settings_replace_values_by_key_path_and_leave_the_scene_alone():
    scene = api.load_scene(default_scene())
    before = repr(scene.data)
    new = scene.with_overrides(settings={"render.nee": False, "camera.fov": 30,
                                         "shapes[0].bsdf.albedo": [1, 0, 0]})
    assert new.data["render"]["nee"] is False and new.data["camera"]["fov"] == 30
    assert new.data["shapes"][0]["bsdf"]["albedo"] == [1.0, 0.0, 0.0]
    assert repr(scene.data) == before


@pytest.mark.parametrize("settings,key,reason", [
    ({"render.nee": 3}, "settings['render.nee']", "expected true or false (got number 3)"),
    ({"render.bogus": 1}, "settings['render.bogus']", "unknown key"),
    ({"camera": {"fov": 500}}, "settings['camera'].fov", "must be < 180 (got 500)"),
    ({"shapes[99].bsdf": {}}, "settings['shapes[99].bsdf']", "shapes has 8 elements"),
    ({"render.spp.x": 1}, "settings['render.spp.x']", "render.spp is a number, not an object"),
    ({"render..nee": 1}, "settings['render..nee']", "expected a key path like render.nee"),
])
def test_a_bad_setting_is_named_by_its_key(settings, key, reason):
    with pytest.raises(SceneError) as info:
        api.load_scene(default_scene()).with_overrides(settings=settings)
    assert info.value.file == API_SOURCE and info.value.key == key
    assert info.value.reason.startswith(reason), info.value.reason


def test_the_command_line_names_a_setting_as_it_was_given():
    out = args.as_cli(SceneError(API_SOURCE, "settings['camera'].fov", "must be < 180"),
                      {"settings": "--set"})
    assert (out.file, out.key, out.reason) == (CLI_SOURCE, "--set camera.fov", "must be < 180")
    assert args.setting("render.nee=false") == ("render.nee", False)
    assert args.setting("shapes[0].bsdf.albedo=[1, 0, 0]") == ("shapes[0].bsdf.albedo",
                                                               [1, 0, 0])
    assert args.setting("render.tonemap=filmic") == ("render.tonemap", "filmic")


@pytest.mark.parametrize("text,size", [("64", (64, 64)), ("640x480", (640, 480)),
                                       ("8X6", (8, 6))])
def test_resolution_takes_n_for_n_by_n(text, size):
    assert args.resolution(text) == size


def test_a_bad_resolution_or_setting_is_one_usage_line():
    for option in (["--resolution", "64x"], ["--resolution", "1x2x3"], ["--set", "camera"]):
        r = gpiscl_cli("render", *option)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert r.stderr.startswith("error: python -m gpiscl render: argument "), r.stderr


def test_render_command_applies_repeated_settings_to_the_built_in_scene(tmp_path):
    out = tmp_path / "img.exr"
    r = gpiscl_cli("render", "-o", str(out), "--resolution", "4", "--spp", "1",
                   "--device", "cpu", "--set", "render.max_depth=2",
                   "--set", "camera.fov=30", "--set", "render.nee=false")
    assert r.returncode == 0, r.stderr
    assert r.stderr.startswith("rendering the built-in scene at 4x4, 1 spp on "), r.stderr
    resolved = json.loads((tmp_path / "img.scene.json").read_text())
    assert resolved["render"]["max_depth"] == 2 and resolved["render"]["nee"] is False
    assert resolved["camera"]["fov"] == 30 and resolved["camera"]["resolution"] == [4, 4]
    assert read_exr_attributes(out)["gpiscl:scene"] == "the built-in scene"


def test_a_bad_setting_on_the_command_line_is_one_scene_error_before_any_work(tmp_path):
    out = tmp_path / "img.exr"
    r = gpiscl_cli("render", "-o", str(out), "--set", "render.nee=3")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == ("error: <command line>: --set render.nee: expected true or false "
                        "(got number 3)\n")
    assert not out.exists()


def test_api_render_takes_settings(device):
    bright = api.render(furnace_sphere(albedo=1.0), spp=1, resolution=(4, 4), device=device)
    dark = api.render(furnace_sphere(albedo=1.0), spp=1, resolution=(4, 4), device=device,
                      settings={"shapes[0].bsdf.albedo": 0.0})
    assert bright.min() > 0.5 and dark[1:3, 1:3].max() == 0.0


def test_device_takes_the_types_devices_lists():
    types = {t for d in api.devices() for t in d["type"].split(" | ")}
    assert types <= set(DEVICE_TYPES) | {"other"}
    if "cpu" in types:
        assert shared_device("cpu").is_cpu


def test_memory_sizes_in_an_error_are_in_a_unit_that_fits(tmp_path):
    r = gpiscl_cli("render", "--max-memory", "10K", "-o", str(tmp_path / "img.exr"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "pixels need about 14.4 MiB for the film; 10 KiB available" in r.stderr, r.stderr
