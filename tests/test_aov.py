"""First-hit AOVs (depth, normal, albedo, position) as EXR layers, for denoisers."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gpiscl
from gpiscl import SceneError
from gpiscl.host.io.images import read_exr

ROOT = Path(__file__).resolve().parents[1]
SPHERE = {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "fov": 40,
                     "resolution": [21, 21]},
          "render": {"spp": 4},
          "shapes": [{"type": "sphere", "radius": 1,
                      "bsdf": {"type": "diffuse", "albedo": [0.2, 0.4, 0.6]}}],
          "lights": [{"type": "environment", "radiance": 0.5}]}


def test_aovs_of_a_sphere_seen_head_on(device, tmp_path):
    res = gpiscl.render_result(SPHERE, device=device, aov="depth,normal,albedo,position")
    paths = gpiscl.write_image(tmp_path / "s.exr", res)
    ch = read_exr(paths["exr"])
    c = 10                                           # the centre pixel looks at (0, 0, 1)
    assert ch["depth.Z"][c, c] == pytest.approx(3.0, abs=0.02)
    np.testing.assert_allclose([ch[f"normal.{k}"][c, c] for k in "XYZ"], [0, 0, 1], atol=0.07)  # pixel jitter
    np.testing.assert_allclose([ch[f"position.{k}"][c, c] for k in "XYZ"], [0, 0, 1],
                               atol=0.07)
    np.testing.assert_allclose([ch[f"albedo.{k}"][c, c] for k in "RGB"], [0.2, 0.4, 0.6],
                               rtol=1e-6)
    assert ch["hits.A"][c, c] == 1.0 and ch["hits.A"][0, 0] == 0.0   # a corner sees sky
    assert ch["depth.Z"][0, 0] == 0.0 and ch["albedo.R"][0, 0] == 0.0


def test_aovs_change_nothing_else_and_do_not_depend_on_the_batch_size(device):
    plain = gpiscl.render_result(SPHERE, device=device, seed=2)
    a = gpiscl.render_result(SPHERE, device=device, seed=2, aov=["normal"], batch_size=7)
    b = gpiscl.render_result(SPHERE, device=device, seed=2, aov=["normal"])
    np.testing.assert_array_equal(plain.image.mean, a.image.mean)
    np.testing.assert_array_equal(a.image.aov, b.image.aov)
    assert plain.image.aov is None


def test_gpis_hits_give_their_sampled_normals(device):
    scene = dict(SPHERE, shapes=[{"type": "gpis", "proxy": {"type": "sphere", "radius": 1.5},
                                  "mean": {"type": "sphere", "radius": 1},
                                  "kernel": {"type": "squared_exponential", "sigma": 0.05,
                                             "length_scale": 0.3}}])
    res = gpiscl.render_result(scene, device=device, spp=8, aov="normal,depth")
    from gpiscl.host.render.aov import channels
    ch = channels(res.image.aov, res.image.count, res.aovs)
    n = np.stack([ch[f"normal.{k}"][10, 10] for k in "XYZ"])
    assert 0.8 < np.linalg.norm(n) <= 1.0 + 1e-6 and n[2] > 0.8   # averaged, unit-ish
    assert 2.7 < ch["depth.Z"][10, 10] < 3.3


def test_aov_names_and_format_are_checked(tmp_path):
    with pytest.raises(SceneError, match="unknown AOV 'colour'"):
        gpiscl.render_result(SPHERE, aov="depth,colour")
    path = tmp_path / "s.json"
    path.write_text(json.dumps(SPHERE))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for out, why in (("x.png", "EXR layers"), ("x.exr", "unknown AOV")):
        aov = "depth" if out.endswith("png") else "dept"
        r = subprocess.run([sys.executable, "-m", "gpiscl", "render", str(path), "-o",
                            str(tmp_path / out), "--aov", aov], capture_output=True,
                           text=True, cwd=ROOT, env=env)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and why in r.stderr, r.stderr
