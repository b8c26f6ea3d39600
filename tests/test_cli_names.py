"""The command line reports the API's argument errors under its own option names, and
Scene.with_overrides is the one way to apply render settings to a scene."""
import pytest

from gpiscl.cli import args
from gpiscl.host.errors import API_SOURCE, CLI_SOURCE, SceneError
from gpiscl.host.scene.loading import load_scene

SPELLED = {"resolution": "--resolution", "cluster": "--cluster", "partials": "--merge",
           "target": "KERNEL_OR_SCENE"}


@pytest.mark.parametrize("key,reason,want_key,want_reason", [
    ("resolution[0]", "must be >= 1 (got 0)", "--resolution[0]", "must be >= 1 (got 0)"),
    ("aov", "not available with `cluster` yet", "aov", "not available with --cluster yet"),
    ("partials", "needs >= 2 realizations in all", "--merge", "needs >= 2 realizations in all"),
    ("kernel.w", "must be > 0", "kernel.w", "must be > 0"),
    ("x", "see `nothing`", "x", "see `nothing`"),
])
def test_api_argument_errors_are_named_as_the_command_line_spells_them(key, reason,
                                                                        want_key, want_reason):
    out = args.as_cli(SceneError(API_SOURCE, key, reason), SPELLED)
    assert (out.file, out.key, out.reason) == (CLI_SOURCE, want_key, want_reason)


def test_errors_about_files_are_left_as_they_are():
    exc = SceneError("scene.json", "camera.resolution", "must be >= 1")
    assert args.as_cli(exc, SPELLED) is exc


def test_with_overrides_copies_and_leaves_the_scene_alone():
    scene = load_scene({"lights": [{"type": "environment"}], "render": {"realization": 3}})
    before = repr(scene.data)
    assert scene.with_overrides() is scene
    new = scene.with_overrides(spp=5, seed=9, resolution=(7, 4), tonemap="filmic")
    assert new.data["render"]["spp"] == 5 and new.data["render"]["seed"] == 9
    assert new.data["camera"]["resolution"] == [7, 4]
    assert new.data["render"]["tonemap"] == "filmic" and new.source == scene.source
    assert scene.with_overrides(realization="none").data["render"]["realization"] is None
    assert repr(scene.data) == before
