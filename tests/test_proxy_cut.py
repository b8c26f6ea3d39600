"""A proxy that cuts its object warns (compile/proxy_cut.py): the boundary samples lie on
the proxy's surface, spread by area; a tight proxy warns once, naming the file and the key
path; a loose one and "clip": true do not."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gpiscl.host.compile.proxy_cut import BOUNDARY_POINTS, boundary_points
from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.scene.loading import load_scene
from gpiscl.host.scene.proxies import analyse
from gpiscl.scenes import default_scene

ROOT = Path(__file__).resolve().parent.parent


def test_box_points_lie_on_its_faces_in_proportion_to_their_areas():
    lo, hi = np.array([-0.5, -1.0, -2.0]), np.array([0.5, 1.0, 2.0])   # sizes 1, 2, 4
    x = boundary_points({"type": "box", "min": lo.tolist(), "max": hi.tolist()})
    on = np.isclose(x, lo) | np.isclose(x, hi)
    assert np.all(on.sum(1) >= 1) and np.all((x >= lo - 1e-12) & (x <= hi + 1e-12))
    # faces normal to x: area 2 * (2 * 4) of 2 * (8 + 4 + 2): a binomial share
    share, p = np.mean(on[:, 0]), 8.0 / 14.0
    assert abs(share - p) < 4.0 * math.sqrt(p * (1 - p) / BOUNDARY_POINTS)


def test_sphere_and_mesh_points_lie_on_their_surfaces():
    x = boundary_points({"type": "sphere", "center": [1.0, 2.0, 3.0], "radius": 0.7})
    assert np.allclose(np.linalg.norm(x - [1.0, 2.0, 3.0], axis=1), 0.7)
    assert abs(np.mean(x[:, 2] > 3.0) - 0.5) < 4.0 * 0.5 / math.sqrt(BOUNDARY_POINTS)
    wedge = load_scene(str(ROOT / "scenes/wedge_volume.json")).data
    proxy = next(sh for sh in wedge["shapes"] if sh["type"] == "gpis")["proxy"]
    assert proxy["type"] == "mesh"
    planes = analyse(proxy)[0].astype(np.float64)
    gap = boundary_points(proxy) @ planes[:, :3].T - planes[:, 3]
    assert gap.shape == (BOUNDARY_POINTS, len(planes))
    assert np.all(np.abs(gap.max(1)) < 1e-5)   # inside every face plane, on one of them
    assert boundary_points({"type": "scene"}) is None


def sphere_scene(proxy_radius, clip=None):
    s = default_scene()
    s["camera"]["resolution"] = [8, 8]
    s["render"]["spp"] = 1
    g = next(sh for sh in s["shapes"] if sh["type"] == "gpis")
    g["mean"] = {"type": "sphere", "radius": 1.0}
    g["kernel"] = {"type": "squared_exponential", "sigma": 0.06, "length_scale": 0.15}
    g["proxy"] = {"type": "sphere", "radius": proxy_radius}
    if clip is not None:
        g["clip"] = clip
    return s, s["shapes"].index(g)


@pytest.mark.parametrize("radius, clip, warns", [(1.1, None, True), (1.1, True, False),
                                                 (1.35, None, False)])
def test_a_tight_proxy_warns_unless_clip_says_the_cut_is_meant(capsys, radius, clip, warns):
    """Mean 1 - |x|, sigma 0.06: the occupancy level is 3.72 sigma = 0.22, so a proxy of
    radius 1.1 (mean -0.1 on its boundary) cuts the object, 1.35 (-0.35) does not."""
    scene, _ = sphere_scene(radius, clip)
    compile_scene(load_scene(scene).data)
    err = capsys.readouterr().err
    assert ("cuts the object" in err) == warns, err


def test_the_cli_names_the_file_and_key_path_in_one_line_and_still_renders(tmp_path):
    scene, k = sphere_scene(1.1)
    path = tmp_path / "tight.json"
    path.write_text(json.dumps(scene))
    run = subprocess.run([sys.executable, "-m", "gpiscl", "render", str(path), "-o",
                          str(tmp_path / "out.exr")], capture_output=True, text=True,
                         cwd=tmp_path, timeout=600)
    assert run.returncode == 0, run.stderr
    lines = [ln for ln in run.stderr.splitlines() if "cuts the object" in ln]
    assert len(lines) == 1, run.stderr
    assert "tight.json" in lines[0] and f"shapes[{k}].proxy" in lines[0]
    assert f"shapes[{k}].clip" in lines[0] and "100%" in lines[0]
    assert (tmp_path / "out.exr").exists()


def test_no_shipped_scene_warns(capsys):
    for path in sorted((ROOT / "scenes").glob("*.json")):
        compile_scene(load_scene(str(path)).data)
        assert "cuts the object" not in capsys.readouterr().err, path.name
