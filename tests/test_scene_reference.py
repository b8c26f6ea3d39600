"""docs/scene-format.md is the page the schema generates: a new key, kind or default
that is not in the committed page fails here (regenerate: python tools/make_scene_reference.py)."""
from pathlib import Path

from gpiscl.host.scene.reference import scene_reference

PAGE = Path(__file__).resolve().parent.parent / "docs" / "scene-format.md"


def test_the_scene_reference_is_generated_from_the_schema():
    assert PAGE.read_text() == scene_reference(), \
        "docs/scene-format.md is stale: run python tools/make_scene_reference.py"


def test_the_reference_names_every_shape_light_and_kernel():
    page = scene_reference()
    for name in ("gpis", "sphere", "mesh", "environment_map", "directional",
                 "squared_exponential", "matern52", "function_space", "renewal_plus"):
        assert f"`{name}`" in page, name
