"""Every scene shipped in scenes/ loads strictly and renders without failed paths."""
from pathlib import Path

import numpy as np
import pytest

from gpiscl import load_scene, render_result

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.json"))


def test_there_are_example_scenes():
    assert len(SCENES) >= 5


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_example_scene_renders(device, path):
    scene = load_scene(path)
    assert scene.data["description"], "example scenes say what they show"
    res = render_result(scene, spp=1, resolution=(6, 6), device=device)
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0 and st.killed_paths == 0, st.summary()
    assert np.all(np.isfinite(res.image.mean)) and res.image.mean.max() > 0
