"""Environment maps (importance sampled) and triangle meshes (BVH) in full renders."""
import math

import numpy as np

from gpiscl import render_result
from gpiscl.host.io.images import write_exr
from gpiscl.testing.stats import assert_agree


def _scene(lights, shapes, res=24, spp=64, nee=True):
    return {"camera": {"position": [0, 1.2, 3.5], "look_at": [0, 0.4, 0], "fov": 40,
                       "resolution": [res, res]},
            "render": {"spp": spp, "seed": 3, "max_depth": 32, "nee": nee},
            "shapes": shapes, "lights": lights}


def _sky(tmp_path, constant=None):
    h, w = 16, 32
    if constant is not None:
        rgb = np.full((h, w, 3), constant, np.float32)
    else:
        theta = (np.arange(h) + 0.5) / h * math.pi
        phi = (np.arange(w) + 0.5) / w * 2 * math.pi
        rgb = np.zeros((h, w, 3), np.float32)
        rgb[..., 2] = 0.3 + np.cos(theta)[:, None].clip(0)          # bluish sky
        rgb[..., 0] = 0.2 + 4.0 * (np.abs(phi - 1.0) < 0.3)[None, :] * (theta < 1.2)[:, None]
        rgb[..., 1] = 0.25
    path = tmp_path / "sky.exr"
    write_exr(path, rgb)
    return str(path)


SHAPES = [{"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
           "bsdf": {"type": "diffuse", "albedo": 1.0}},
          {"type": "disk", "center": [0, 0, 0], "normal": [0, 1, 0], "radius": 3,
           "bsdf": {"type": "diffuse", "albedo": 1.0}}]


def test_constant_environment_map_is_a_white_furnace(device, tmp_path):
    """A map of constant radiance c behaves as the constant environment c: a convex
    albedo-1 sphere is invisible (the floor would trap paths below, so it is left out)."""
    scene = _scene([{"type": "environment_map", "file": _sky(tmp_path, 0.7), "rotation": 30}],
                   SHAPES[:1], spp=32)
    img = render_result(scene, device=device).image
    assert_agree(img.mean, img.stderr, np.full_like(img.mean, 0.7), block=4, what="map furnace")


def test_environment_map_importance_sampling_agrees_with_bsdf_sampling(device, tmp_path):
    sky = _sky(tmp_path)
    lights = [{"type": "environment_map", "file": sky, "scale": 1.5, "rotation": 40}]
    a = render_result(_scene(lights, SHAPES, spp=64), device=device).image
    b = render_result(_scene(lights, SHAPES, spp=256, nee=False), device=device).image
    assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=4, what="envmap NEE vs BSDF")


def test_triangle_mesh_renders_like_the_same_box_primitive(device, tmp_path):
    import trimesh
    # extents 1.0 x 0.6 x 0.8, turned 90 degrees about y, cover the box below
    trimesh.creation.box(extents=[1.0, 0.6, 0.8]).export(tmp_path / "box.obj")
    lights = [{"type": "environment", "radiance": [0.3, 0.4, 0.5]},
              {"type": "sphere", "center": [1, 2, 1], "radius": 0.2, "radiance": 30}]
    bsdf = {"type": "diffuse", "albedo": [0.8, 0.5, 0.3]}
    floor = SHAPES[1]
    box = {"type": "box", "min": [-0.4 + 0.1, 0, -0.5], "max": [0.4 + 0.1, 0.6, 0.5], "bsdf": bsdf}
    as_mesh = {"type": "mesh", "file": str(tmp_path / "box.obj"), "bsdf": bsdf,
               "transform": {"translate": [0.1, 0.3, 0], "rotate": [0, 90, 0], "scale": 1}}
    a = render_result(_scene(lights, [floor, box]), device=device).image
    b = render_result(_scene(lights, [floor, as_mesh]), device=device, seed=4).image
    assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=2, what="mesh vs box")
