"""The surface counterpart of means without a closed-form zero set: the zero set inside the
proxy by marching cubes (compile/zero_set_mesh.py) as mesh shapes with the microfacet BSDF
(compile/classical.py). Against the analytic sphere counterpart (z per 4x4 block and over
the image, tolerances from the films' standard errors, the mesh's own error checked below
the noise), on its mean's zero set, and in a white furnace.
docs/design/classical-limits.md, Sec. 4 and 5."""
import math

import numpy as np
import pytest

from gpiscl import render_result
from gpiscl.host.compile.classical import ALPHA_BAND, MAX_BANDS, with_counterparts
from gpiscl.host.compile.gpis import build_mean
from gpiscl.host.compile.zero_set_mesh import zero_set_mesh
from gpiscl.host.errors import SceneError
from gpiscl.host.io.meshes import closed_mesh, load_mesh
from gpiscl.host.scene.loading import load_scene
from gpiscl.testing.scenes import classical_stage
from gpiscl.testing.stats import assert_agree, block_means, image_mean_se, z_threshold

MIRROR = {"type": "mirror", "albedo": 1.0}
SE = {"type": "squared_exponential", "sigma": 0.01, "length_scale": 0.1}   # alpha 0.1414
SPHERE = {"type": "sphere", "center": [0, 0, 0], "radius": 1.0}
# the same sphere through the mesh path: a transform has no closed-form counterpart
SPHERE_MESHED = {"type": "transform", "child": SPHERE}
# a smooth CSG of a box and a sphere, rotated and squashed: |grad mu| varies (1 to 1/0.7)
CSG = {"type": "transform", "scale": [1.0, 0.7, 1.0], "rotate": [20, 30, 0],
       "child": {"type": "union", "k": 0.1,
                 "left": {"type": "box", "half_extents": [0.6, 0.4, 0.5]},
                 "right": {"type": "sphere", "center": [0.4, 0.3, 0.2], "radius": 0.45}}}
ROUNDED = {"type": "transform", "rotate": [30, 40, 0],
           "child": {"type": "rounded_box", "half_extents": [0.7, 0.5, 0.6], "radius": 0.2}}
PROXY = {"type": "sphere", "center": [0, 0, 0], "radius": 1.1}


def scene(mean, micro=MIRROR, spp=256, light="rectangle", proxy=PROXY):
    g = {"type": "gpis", "proxy": proxy, "mean": mean, "kernel": SE, "bsdf": micro,
         "classical": "surface"}
    return classical_stage(g, spp, 5, light)


def counterparts(doc):
    return with_counterparts(load_scene(doc).data, "<test>")["shapes"]


def host_mean(mean):
    """The host model of a scene mean (defaults filled in by the loader)."""
    return build_mean(load_scene(scene(mean)).data["shapes"][0]["mean"])


def face_errors(mean, zs):
    """(max |mu| at the face centroids: how far the flat faces sit off the zero set,
    RMS angle between each face's normal and grad mu at its centroid)."""
    tri = zs.vertices[zs.faces]
    c = tri.mean(axis=1)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    value, grad = mean.value_and_gradient(c)
    cos = np.einsum("ij,ij->i", n, grad) / np.linalg.norm(n, axis=1) / np.linalg.norm(grad, axis=1)
    return float(np.abs(value).max()), float(np.sqrt(np.mean(np.arccos(np.clip(cos, -1, 1)) ** 2)))


def test01_sphere_mesh_renders_like_the_analytic_sphere(device):
    """The meshed sphere and the analytic sphere counterpart agree per 4x4 block and over
    the image. The mesh's own error is checked to be below the noise first: its faces lie
    up to d inside the sphere and their normals are off by e RMS, which widens the
    Beckmann lobe to sqrt(alpha^2 + e^2); the analytic sphere with both changes, rendered
    with the same random numbers, moves no block by more than half its error (measured
    0.25: it moves a block's z by 0.18 at most, against a threshold of 3.9)."""
    [shape] = counterparts(scene(SPHERE_MESHED))
    alpha = shape["bsdf"]["roughness"]
    assert shape["type"] == "mesh" and math.isclose(alpha, math.sqrt(2) * 0.1, rel_tol=1e-12)
    zs = zero_set_mesh(host_mean(SPHERE_MESHED), PROXY, SE["length_scale"])
    d, e = face_errors(host_mean(SPHERE), zs)
    a = render_result(scene(SPHERE_MESHED), device=device).image
    b = render_result(scene(SPHERE), device=device).image
    worse = scene(SPHERE)
    [sphere] = counterparts(worse)
    sphere["radius"] -= d
    sphere["bsdf"]["roughness"] = math.hypot(alpha, e)
    worse["shapes"] = [sphere]
    c = render_result(worse, device=device).image
    mb, sb = block_means(b.mean, b.stderr, 4)
    shift = np.abs(block_means(c.mean, c.stderr, 4)[0] - mb)
    noisy = sb > 0.0        # blocks of the environment alone are exact
    print(f"mesh: {len(zs.faces)} faces, cell {zs.cell[0]:.4f}, d {d:.2e}, e {e:.4f} rad; "
          f"its shift / se: max {(shift[noisy] / sb[noisy]).max():.3f}")
    assert np.all(shift[noisy] < 0.5 * sb[noisy]) and np.all(shift[~noisy] < 1e-6)
    z = assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=4, what="mesh vs sphere")
    gap = float(a.mean.mean() - b.mean.mean())
    whole = gap / image_mean_se(a.stderr, b.stderr)
    print(f"max |z| {z.max():.2f} over {z.size} blocks; image means {a.mean.mean():.5f} "
          f"{b.mean.mean():.5f} (z {whole:.2f})")
    assert abs(whole) < z_threshold(1)


def test02_csg_mesh_lies_on_the_zero_set_and_renders(device):
    """A rotated, squashed smooth CSG (|grad mu| from 1 to 1/0.7, a distance bound: lip 1):
    every vertex within one cell of the zero set (|mu| <= cell * lip), the mesh closed
    and wound outward, each face's alpha within its band's, and the render finite and
    lit."""
    mean = host_mean(CSG)
    zs = zero_set_mesh(mean, PROXY, SE["length_scale"])
    assert np.abs(mean.value(zs.vertices)).max() <= zs.cell.max() * 1.0
    assert closed_mesh(zs.vertices[zs.faces])
    shapes = counterparts(scene(CSG))
    assert len(shapes) > 1 and all(s["type"] == "mesh" for s in shapes)
    unit = math.sqrt(2) * 0.1
    slopes = np.linalg.norm(mean.gradient(zs.vertices[zs.faces].mean(axis=1)), axis=1)
    width = max(math.log1p(ALPHA_BAND), float(np.log(slopes.max() / slopes.min())) / MAX_BANDS)
    for s in shapes:
        verts, faces = load_mesh(s["file"])
        tri = verts[faces]
        alpha = unit / np.linalg.norm(mean.gradient(tri.mean(axis=1)), axis=1)
        assert np.all(np.abs(np.log(alpha / s["bsdf"]["roughness"])) <= width * (1 + 1e-6))
        # wound outward: face normals follow grad mu (area-weighted; at the box's sharp
        # edges marching cubes cuts chamfers whose normals are far from either side's)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        g = mean.gradient(tri.mean(axis=1))
        cos = np.einsum("ij,ij->i", n, g / np.linalg.norm(g, axis=1)[:, None])
        assert cos.sum() > 0.9 * np.linalg.norm(n, axis=1).sum()   # measured 0.983
    img = render_result(scene(CSG, spp=16), device=device).image.mean
    assert np.all(np.isfinite(img)) and img.max() > 1.0


def test03_white_furnace(device):
    """A white diffuse micro-BSDF on a convex closed mesh (a rotated rounded box) under a
    unit environment: every path sees radiance 1 (z per 4x4 block)."""
    [shape] = counterparts(scene(ROUNDED, {"type": "diffuse", "albedo": 1.0}, light="furnace"))
    assert closed_mesh(np.asarray(load_mesh(shape["file"])[0])[load_mesh(shape["file"])[1]])
    img = render_result(scene(ROUNDED, {"type": "diffuse", "albedo": 1.0}, spp=64,
                              light="furnace"), device=device).image
    # a pixel's mean of 64 float32 samples near 1 is exact to 64 * 2^-24 at worst: nearly
    # deterministic pixels (se ~1e-8) would otherwise fail on rounding
    floor = 64 * 2.0 ** -24
    z = assert_agree(img.mean, np.hypot(img.stderr, floor), np.ones_like(img.mean), block=4,
                     what="furnace")
    print(f"furnace: mean {img.mean.mean():.5f}, max |z| {z.max() if z.size else 0:.2f}")


@pytest.mark.parametrize("mean, proxy, key, reason", [
    ({"type": "constant", "value": 1.0}, PROXY, "mean", "no zero set inside the proxy"),
    ({"type": "transform", "child": {**SPHERE, "radius": 3.0}}, PROXY, "mean",
     "no zero set inside the proxy"),                                   # all inside
    (CSG, {"type": "scene"}, "proxy", "needs a bounded proxy"),
])
def test04_refusals_name_the_key(mean, proxy, key, reason):
    with pytest.raises(SceneError, match=rf"shapes\[0\]\.{key}: .*{reason}"):
        counterparts(scene(mean, proxy=proxy))


def test05_box_proxy_cuts_the_surface_open():
    """A plane mean at an angle in a box: the zero set ends on the box's faces (an open
    mesh, as the GPIS has no face where its proxy cuts it)."""
    box = {"type": "box", "min": [-1, -1, -1], "max": [1, 1, 1]}
    plane = {"type": "plane", "point": [0, 0.1, 0], "normal": [0.3, 1, 0.2]}
    [shape] = counterparts(scene(plane, proxy=box))
    verts, faces = load_mesh(shape["file"])
    assert verts.min() >= -1 - 1e-12 and verts.max() <= 1 + 1e-12 and not closed_mesh(verts[faces])
    n = np.asarray(plane["normal"]) / np.linalg.norm(plane["normal"])
    assert np.abs((verts - plane["point"]) @ n).max() < 1e-9


def test06_sigma_and_length_fields_scale_each_faces_roughness():
    """With sigma(x) and l(x) fields the slope's sd is sigma m_s(x) / (l m_l(x)) (local
    stationarity): each face's alpha carries m_s / m_l at its centroid. A constant sigma
    field of 2 on half the sigma gives the analytic sphere's alpha (one band); a radial
    sigma field from 1 (inside radius 0.6 about (0, 0.8, 0)) to 3 (outside) spreads the
    bands over that range; an l field of 2 halves the alpha."""
    alpha = counterparts(scene(SPHERE))[0]["bsdf"]["roughness"]   # sigma 0.01, l 0.1

    def with_kernel(kernel):
        g = dict(scene(SPHERE)["shapes"][0], kernel=kernel,
                 sampler={"type": "function_space"})
        return counterparts(dict(scene(SPHERE), shapes=[g]))

    shapes = with_kernel(dict(SE, sigma=0.005, sigma_field={
        "type": "linear", "value": 2.0, "gradient": [0.0, 0.0, 0.0]}))
    assert len(shapes) == 1 and shapes[0]["type"] == "mesh"
    assert shapes[0]["bsdf"]["roughness"] == pytest.approx(alpha, rel=2e-2)
    shapes = with_kernel(dict(SE, length_scale_field={
        "type": "linear", "value": 2.0, "gradient": [0.0, 0.0, 0.0]}))
    assert shapes[0]["bsdf"]["roughness"] == pytest.approx(alpha / 2.0, rel=2e-2)
    shapes = with_kernel(dict(SE, sigma=0.005, sigma_field={
        "type": "radial", "center": [0.0, 0.8, 0.0], "radius": 0.6, "width": 0.2,
        "inner": 1.0, "outer": 3.0}))
    rough = sorted(s["bsdf"]["roughness"] for s in shapes)
    assert len(shapes) > 3
    # alpha at m_s = 1 is alpha / 2 here; the faces' fields span about [1, 3]
    assert 0.49 * alpha < rough[0] < 0.7 * alpha and 1.25 * alpha < rough[-1] < 1.51 * alpha, \
        (rough, alpha)
