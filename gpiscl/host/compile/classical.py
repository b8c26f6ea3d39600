"""A GPIS shape's classical counterparts ("classical" on a gpis shape). "surface":
the mean's zero set as an ordinary shape with a microfacet BSDF of the micro-BSDF's kind
and the GP's slope law, Beckmann alpha = sqrt(2 lambda_2) / |grad mu|
(docs/design/classical-limits.md, Sec. 3). Built before compiling, so the counterpart
goes through the ordinary shape and material kinds and costs nothing on the device.

Zero sets written here: a sphere mean (a sphere) and a plane mean whose normal is an
axis of a box proxy (a rectangle filling the box's section). Other means would need the
zero set extracted (a mesh); they are refused with that reason. "medium": checked here,
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
from .gpis import build_kernel

_ROUGHNESS = ROUGH_CONDUCTOR.fields["roughness"].spec     # rough_conductor's range
MIN_ROUGHNESS, MAX_ROUGHNESS = _ROUGHNESS.ge, _ROUGHNESS.le
# a mirror without a conductor has no Fresnel term: a conductor with this k reflects
# 1 - 4/k^2 at every angle
_MIRROR_K = 1.0e4


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


def _plane_in_box(mean: dict, proxy: dict, source: str, where: str) -> dict:
    n = np.asarray(mean["normal"], float)
    n = n / np.linalg.norm(n)
    axis = int(np.argmax(np.abs(n)))
    if proxy["type"] != "box" or abs(abs(n[axis]) - 1.0) > 1e-9:
        raise SceneError(source, f"{where}.classical", "a plane mean's surface counterpart "
                         "needs a box proxy and a normal along an axis")
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


def surface_counterpart(shape: dict, source: str, where: str) -> dict:
    """The ordinary shape standing for a resolved gpis shape with "classical": "surface"."""
    for key in ("color", "emission", "observations"):
        if shape.get(key) is not None:
            raise SceneError(source, f"{where}.{key}", "not supported together with "
                             '"classical": "surface"')
    mean = shape["mean"]
    fields = [k for k in FIELD_KEYS if shape["kernel"].get(k) is not None]
    if fields:
        raise SceneError(source, f"{where}.kernel.{fields[0]}", "the surface counterpart has "
                         "one roughness: give constant sigma and length_scale")
    kernel = build_kernel(shape["kernel"])
    if mean["type"] == "sphere":
        geometry = {"type": "sphere", "center": list(mean["center"]), "radius": mean["radius"]}
        slope, tangent = 1.0, (1.0, 0.0, 0.0)
    elif mean["type"] == "plane":
        geometry = _plane_in_box(mean, shape["proxy"], source, where)
        slope, tangent = mean["scale"], geometry["u"]
    else:
        raise SceneError(source, f"{where}.classical", f"no surface counterpart for a "
                         f"{mean['type']} mean yet (sphere and axis-aligned plane means)")
    lam = kernel.gradient_variance()
    if not np.allclose(lam, lam[0], rtol=1e-9):
        raise SceneError(source, f"{where}.kernel.aniso", "the surface counterpart is an "
                         "isotropic Beckmann BSDF: give an isotropic kernel")
    try:
        alpha = C.beckmann_alpha(kernel, tangent, slope)
    except ValueError as exc:
        raise SceneError(source, f"{where}.kernel", str(exc)) from None
    return {**geometry, "bsdf": counterpart_bsdf(shape["bsdf"], alpha, source, where)}


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
    function-space stage runs them, compile/gpis.py marks their memory)."""
    shapes = data.get("shapes", [])
    for i, s in enumerate(shapes):
        if s["type"] == "gpis" and (s.get("classical") == "medium"
                                    or s["sampler"].get("memory") == "classical_medium"):
            check_medium(s, source, f"shapes[{i}]")
    if not any(s["type"] == "gpis" and s.get("classical") == "surface" for s in shapes):
        return data
    return {**data, "shapes": [surface_counterpart(s, source, f"shapes[{i}]")
                               if s["type"] == "gpis" and s.get("classical") == "surface"
                               else s for i, s in enumerate(shapes)]}
