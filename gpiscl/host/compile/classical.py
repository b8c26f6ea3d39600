"""A GPIS shape's classical counterparts ("classical" on a gpis shape). "surface":
the mean's zero set as an ordinary shape with a microfacet BSDF of the micro-BSDF's kind
and the GP's slope law, Beckmann alpha = sqrt(2 lambda_2) / |grad mu|
(docs/design/classical-limits.md, Sec. 3). Built before compiling, so the counterpart
goes through the ordinary shape and material kinds and costs nothing on the device.

Zero sets written here: a sphere mean (a sphere) and a plane mean whose normal is an
axis of a box proxy (a rectangle filling the box's section). Every other mean (primitives,
CSG, transforms, mesh, grid and procedural means, other planes) becomes the triangle mesh
of its zero set inside the proxy (zero_set_mesh.py), one mesh shape per band of alpha
where |grad mu| varies over the surface (faces binned by alpha). "medium": checked here,
rendered by kernels_cl/lib/fs_classical.h (flights of Rice's entry rate at the local
mean, sigma and l: exponential where that is constant, tracked elsewhere)."""
from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..gp import classical as C
from ..gp.kernels import NonStationary
from ..kinds.conductors import eta_k
from ..kinds.materials import ROUGH_CONDUCTOR
from ..scene.gpis import FIELD_KEYS
from .gpis import build_kernel, build_mean, kernel_length_scale
from .sdf_bake import cache_dir
from .zero_set_mesh import write_obj, zero_set_mesh

_ROUGHNESS = ROUGH_CONDUCTOR.fields["roughness"].spec     # rough_conductor's range
MIN_ROUGHNESS, MAX_ROUGHNESS = _ROUGHNESS.ge, _ROUGHNESS.le
# a mirror without a conductor has no Fresnel term: a conductor with this k reflects
# 1 - 4/k^2 at every angle
_MIRROR_K = 1.0e4
# a zero-set mesh's faces share one material per band of alpha this wide (relative): each
# face's alpha is within the band of its material's; at most MAX_BANDS bands (wider ones
# where |grad mu| varies more)
ALPHA_BAND = 0.02
MAX_BANDS = 16


def counterpart_bsdf(micro: dict, alpha: float, source: str, where: str) -> dict:
    """The microfacet BSDF of the micro-BSDF's kind with the GP's Beckmann alpha. A rough
    micro-BSDF adds its own roughness in quadrature (the slopes' variances add: exact for
    the slope law, approximate for the BSDF). A diffuse micro-BSDF stays diffuse: facets
    of a Lambertian surface at small alpha (the Oren-Nayar correction is O(alpha^2))."""
    kind = micro["type"]
    if kind == "diffuse":
        return dict(micro)
    if kind == "mirror":
        fresnel = micro.get("material") is not None or micro.get("eta") is not None
        eta, k = eta_k(micro) if fresnel else ([1.0] * 3, [_MIRROR_K] * 3)
        rough = {"type": "rough_conductor", "material": "Cu", "eta": list(eta),
                 "k": list(k), "albedo": micro["albedo"]}
    elif kind == "rough_conductor":
        rough, alpha = dict(micro), math.hypot(alpha, micro["roughness"])
    else:
        raise SceneError(source, f"{where}.bsdf", f"no surface counterpart for a {kind} "
                         "micro-BSDF (diffuse, mirror and rough_conductor have one)")
    if not alpha <= MAX_ROUGHNESS:
        raise SceneError(source, f"{where}.classical", f"the GP's Beckmann alpha is "
                         f"{alpha:.4g}, beyond rough_conductor's {MAX_ROUGHNESS}: no "
                         "microfacet limit this rough (lower sigma / l)")
    rough["roughness"] = max(alpha, MIN_ROUGHNESS)
    return rough


def _plane_fits_box(mean: dict, proxy: dict) -> bool:
    n = np.abs(np.asarray(mean["normal"], float))
    return proxy["type"] == "box" and abs(n.max() / np.linalg.norm(n) - 1.0) <= 1e-9


def _plane_in_box(mean: dict, proxy: dict, source: str, where: str) -> dict:
    n = np.asarray(mean["normal"], float)
    n = n / np.linalg.norm(n)
    axis = int(np.argmax(np.abs(n)))
    lo, hi = np.asarray(proxy["min"], float), np.asarray(proxy["max"], float)
    level = float(np.asarray(mean["point"], float)[axis])
    if not lo[axis] < level < hi[axis]:
        raise SceneError(source, f"{where}.classical", "the plane mean's zero set misses "
                         "its box proxy")
    center = (lo + hi) / 2
    center[axis] = level
    u_axis, v_axis = [i for i in range(3) if i != axis]
    u, v = np.zeros(3), np.zeros(3)
    u[u_axis], v[v_axis] = hi[u_axis] - lo[u_axis], hi[v_axis] - lo[v_axis]
    if np.dot(np.cross(u, v), n) < 0:      # the rectangle's normal is the mean's outward one
        u, v = v, u
    return {"type": "rectangle", "center": center.tolist(), "u": u.tolist(), "v": v.tolist()}


def alpha_bands(alpha: np.ndarray, weight: np.ndarray) -> tuple:
    """(band of each face, each band's alpha): faces binned by log alpha in bands of
    relative width ALPHA_BAND (wider if that makes more than MAX_BANDS); a band's alpha
    is sqrt of its faces' area-weighted mean alpha^2 (slope variances average), which is
    exact where |grad mu| is constant (SDF means)."""
    log_a = np.log(alpha)
    width = max(math.log1p(ALPHA_BAND), float(np.ptp(log_a)) / MAX_BANDS * (1 + 1e-9))
    _, band = np.unique(np.floor((log_a - log_a.min()) / width), return_inverse=True)
    band = band.reshape(-1)
    a2 = np.bincount(band, weight * alpha ** 2) / np.bincount(band, weight)
    return band, np.sqrt(a2)


def _field_scale(kernel, x: np.ndarray) -> np.ndarray:
    """The factor sigma(x) / l(x) puts on the slope's sd, relative to the base kernel's
    (local stationarity, as the medium counterpart: docs/design/classical-limits.md 4.2);
    1 without fields."""
    scale = np.ones(len(x))
    if isinstance(kernel, NonStationary):
        if kernel.sigma_field is not None:
            scale = scale * np.asarray(kernel.sigma_field.eval(x)[0], float)
        if kernel.length_scale_field is not None:
            scale = scale / np.asarray(kernel.length_scale_field.eval(x)[0], float)
    return scale


def _mesh_counterparts(shape: dict, proxy: dict, kernel, alpha_unit: float, source: str,
                       where: str) -> list:
    """The zero set of any mean inside its proxy as mesh shapes, one per alpha band."""
    if proxy["type"] == "scene":    # its box is known only once the scene is compiled
        raise SceneError(source, f"{where}.proxy", "the surface counterpart's mesh needs a "
                         "bounded proxy (box, sphere or mesh) to extract the zero set in")
    try:
        mean = build_mean(shape["mean"])
    except ValueError as exc:
        raise SceneError(source, f"{where}.mean", str(exc)) from None
    zs = zero_set_mesh(mean, proxy, kernel_length_scale(shape["kernel"]))
    if not len(zs.faces):
        lo, hi = zs.value_range
        raise SceneError(source, f"{where}.mean", f"no zero set inside the proxy for the "
                         f"surface counterpart: the mean ranges over [{lo:.4g}, {hi:.4g}] "
                         "there")
    if not zs.slopes.min() > 0.0:
        raise SceneError(source, f"{where}.mean", "the mean's gradient vanishes on its zero "
                         "set: no surface counterpart (its Beckmann alpha is infinite)")
    tri = zs.vertices[zs.faces]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=-1)
    if shape["bsdf"]["type"] == "diffuse":    # alpha does not enter: one mesh
        band, alphas = np.zeros(len(zs.faces), np.int64), np.array([alpha_unit])
    else:
        scale = _field_scale(kernel, tri.mean(axis=1))
        band, alphas = alpha_bands(alpha_unit * scale / zs.slopes, area)
    folder = cache_dir("surface")
    shapes = []
    for b, alpha in enumerate(alphas):
        faces = zs.faces[band == b]
        used = np.unique(faces)
        try:
            path = write_obj(zs.vertices[used], np.searchsorted(used, faces), folder)
        except (OSError, SceneError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) else exc.reason
            raise SceneError(source, f"{where}.classical", f"cannot write the surface "
                             f"counterpart's mesh in {folder} ({reason}); set "
                             "GPISCL_CACHE to a writable folder") from None
        shapes.append({"type": "mesh", "file": str(path), "transform": {},
                       "bsdf": counterpart_bsdf(shape["bsdf"], float(alpha), source, where)})
    return shapes


def surface_counterpart(shape: dict, source: str, where: str) -> list:
    """The ordinary shapes standing for a resolved gpis shape with "classical": "surface"
    (one, except a zero-set mesh in several alpha bands)."""
    for key in ("color", "emission", "observations"):
        if shape.get(key) is not None:
            raise SceneError(source, f"{where}.{key}", "not supported together with "
                             '"classical": "surface"')
    mean, proxy = shape["mean"], shape["proxy"]
    fields = [k for k in FIELD_KEYS if shape["kernel"].get(k) is not None]
    kernel = build_kernel(shape["kernel"], proxy)
    base = kernel.base if isinstance(kernel, NonStationary) else kernel
    lam = base.gradient_variance()
    if not np.allclose(lam, lam[0], rtol=1e-9):
        raise SceneError(source, f"{where}.kernel.aniso", "the surface counterpart is an "
                         "isotropic Beckmann BSDF: give an isotropic kernel")
    try:
        alpha_unit = C.beckmann_alpha(base, (1.0, 0.0, 0.0), 1.0)   # at |grad mu| = 1
    except ValueError as exc:
        raise SceneError(source, f"{where}.kernel", str(exc)) from None
    if fields:          # the roughness varies over the surface: the mesh's alpha bands
        return _mesh_counterparts(shape, proxy, kernel, alpha_unit, source, where)
    if mean["type"] == "sphere":
        geometry, slope = {"type": "sphere", "center": list(mean["center"]),
                           "radius": mean["radius"]}, 1.0
    elif mean["type"] == "plane" and _plane_fits_box(mean, proxy):
        geometry, slope = _plane_in_box(mean, proxy, source, where), mean["scale"]
    else:
        return _mesh_counterparts(shape, proxy, kernel, alpha_unit, source, where)
    return [{**geometry, "bsdf": counterpart_bsdf(shape["bsdf"], alpha_unit / slope,
                                                  source, where)}]


def check_medium(shape: dict, source: str, where: str) -> None:
    """What the medium counterpart (kernels_cl/lib/fs_classical.h) needs: it runs in the
    function-space stage and takes Rice's rate (2) at the local mean, sigma(x) and l(x),
    so any mean the sampler takes and any field are fine; the kernel needs a finite
    slope variance, and colours, emission and observations have no medium meaning."""
    if shape["sampler"]["type"] != "function_space":
        raise SceneError(source, f"{where}.sampler", '"classical": "medium" runs in the '
                         'function-space stage: give "sampler": {"type": "function_space"}')
    for key in ("color", "emission", "observations"):
        if shape.get(key) is not None:
            raise SceneError(source, f"{where}.{key}", "not supported together with "
                             '"classical": "medium"')
    kernel = build_kernel(shape["kernel"], shape["proxy"])
    try:
        C.slope_variance(kernel.base if isinstance(kernel, NonStationary) else kernel)
    except ValueError as exc:
        raise SceneError(source, f"{where}.kernel", str(exc)) from None


def with_counterparts(data: dict, source: str = "<scene>") -> dict:
    """data with every gpis shape marked "classical": "surface" replaced by its counterpart
    (the same dict when there is none); shapes marked "medium" are checked and stay (the
    function-space stage runs them, compile/gpis.py marks their memory). A counterpart of
    several shapes takes its shape's place with the first and appends the others, so
    every other shape keeps its index (errors name shapes[i])."""
    shapes = data.get("shapes", [])
    for i, s in enumerate(shapes):
        if s["type"] == "gpis" and (s.get("classical") == "medium"
                                    or s["sampler"].get("memory") == "classical_medium"):
            check_medium(s, source, f"shapes[{i}]")
    if not any(s["type"] == "gpis" and s.get("classical") == "surface" for s in shapes):
        return data
    kept, extra = [], []
    for i, s in enumerate(shapes):
        if s["type"] == "gpis" and s.get("classical") == "surface":
            first, *rest = surface_counterpart(s, source, f"shapes[{i}]")
            kept.append(first)
            extra += rest
        else:
            kept.append(s)
    return {**data, "shapes": kept + extra}

