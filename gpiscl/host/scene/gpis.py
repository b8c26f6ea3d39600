"""Scene declarations of GPIS objects: a random field f ~ GP(mean, kernel) inside a proxy.

    {"type": "gpis", "proxy": {...}, "mean": {...}, "kernel": {...},
     "sampler": {"type": "weight_space", "features": null}, "bsdf": {...}}
    sampler alternative: {"type": "function_space", "memory": "renewal_plus",
                          "memory_cap": 64, "miss_tolerance": 2e-6, "refine": 0}

The proxy must bound the object: a realization is only searched inside it, and a ray
that enters the proxy where f < 0 counts as starting inside (it must first come back out),
so an object cut by its proxy shows holes. Leave ~5 sigma between the mean's zero set and
the proxy.

Importing this module registers the "gpis" shape with the scene loader.
"""
from __future__ import annotations

from ..io.meshes import mesh_problem
from ..kinds.materials import MICRO_BSDFS
from ..kinds.values import VEC3
from .records import SHAPES, TRANSFORM, box_extent
from ..layout import function_space_records as FSL
from ..schema import (Bool, Enum, Field, File, Int, Nullable, Number, Record, Tagged,
                     child)
from .proxies import bounding_proxy, mesh_proxy_problem
from ..io.grids import load_field_grid, load_grid, problem_of
from ..kinds.gp_kernels import FIELD_KEYS, GP_KERNELS
from ..kinds.memory_models import MEMORY_MODELS
from ..kinds.means import MEAN_PRIMITIVES
from ..io.points import EXTENSIONS as POINT_FILES
from .observations import observations_problem, points_problem
from .colour_fields import COLOR, EMISSION


PROXIES = Tagged("proxy", {
    "box": Record({"min": Field(VEC3), "max": Field(VEC3)}, [box_extent]),
    "sphere": Record({"center": Field(VEC3, [0, 0, 0]), "radius": Field(Number(gt=0))}),
    # a closed convex mesh (scene/proxies.py), e.g. the authors' wedge prism
    "mesh": Record({"file": Field(File((".obj", ".ply", ".stl", ".off"), mesh_problem)),
                    "transform": Field(TRANSFORM, {})}),
    # unbounded: the scene's box (compile/scene.scene_box: every other shape and proxy,
    # positioned lights, the camera), e.g. a volume-type GPIS filling the scene, which
    # rays sample in progressive segments until they leave the scene
    "scene": Record({}),
})

# Means are signed distances, positive outside (gpiscl/host/gp/means.py). The primitives
# and the CSG operations (k > 0: smooth blend of width k) are declared in kinds/means.py;
# below, the scene forms that compile into them.
MEANS = MEAN_PRIMITIVES.schema
MEANS.register("transform", Record({"child": Field(MEANS), **TRANSFORM.fields}))
# Sampled means (mesh bakes, grids, procedural shapes) are interpolated "linear"
# (trilinear: stays within the samples' range, gradient jumps at cell faces, which a
# mirror micro-BSDF shows as facets) or "cubic" (the interpolating tricubic B-spline: C2,
# no facets, O(h^4) on smooth data; each evaluation reads 64 coefficients instead of 8
# samples, and its certified slope bound, from Bezier control points, is looser along a
# distance's ridges: renders are slower, docs/design/scene-key-costs.md, 'Interpolation').
_INTERPOLATION = Field(Enum("linear", "cubic"), "linear")
# Baked signed distance of a triangle mesh (gpiscl/host/compile/sdf_bake.py): `resolution`
# samples along the longest axis of the mesh bounds grown by `margin` per side (null:
# 0.1 of the largest extent); `band` clamps distances to [-band, band] (null: none);
# `transform` is applied to the vertices before baking, so distances stay exact.
MEANS.register("mesh", Record({"file": Field(File((".obj", ".ply", ".stl", ".off"),
                                                  mesh_problem)),
                               "resolution": Field(Int(ge=4, le=256), 128),
                               "margin": Field(Nullable(Number(gt=0)), None),
                               "band": Field(Nullable(Number(gt=0)), None),
                               "transform": Field(TRANSFORM, {}),
                               "interpolation": _INTERPOLATION}))
# A voxel grid of mean values (.npz with values (nx, ny, nz), origin, voxel_size).
MEANS.register("grid", Record({"file": Field(File((".npz",), problem_of(load_grid))),
                               "interpolation": _INTERPOLATION}))
# the authors' procedural shapes (gp/knob.py), sampled on a grid like a baked mesh
MEANS.register("procedural", Record({
    "function": Field(Enum("knob", "knob_inner", "knob_outer")),
    "resolution": Field(Int(ge=16, le=512), 128),
    "interpolation": _INTERPOLATION,
}))

# The kernels and their sigma(x) / l(x) fields are declared in kinds/gp_kernels.py.
KERNELS = GP_KERNELS.schema


def field_minimum(field: dict, proxy: dict) -> float:
    """The smallest multiplier of a resolved field over a resolved proxy (exact for
    linear fields over boxes and spheres, a lower bound over a mesh's bounding box;
    min(inner, outer) for radial ones, the smallest sample of a grid)."""
    if field["type"] == "radial":
        return min(field["inner"], field["outer"])
    if field["type"] == "grid":
        return load_field_grid(field["file"]).minimum()
    if proxy["type"] == "scene":   # checked: a linear field there has no gradient
        return field["value"]
    proxy = bounding_proxy(proxy)
    g, o, v = field["gradient"], field["origin"], field["value"]
    if proxy["type"] == "box":
        return v + sum(min(gi * (lo - oi), gi * (hi - oi))
                       for gi, lo, hi, oi in zip(g, proxy["min"], proxy["max"], o))
    c, r = proxy["center"], proxy["radius"]
    return (v + sum(gi * (ci - oi) for gi, ci, oi in zip(g, c, o))
            - r * sum(gi * gi for gi in g) ** 0.5)

class _FunctionSpaceSampler(Record):
    """Keys of the segment sampler that are gone fail with what replaces them (a silent
    alias would change old scenes' meaning without a word)."""
    REMOVED = {
        "step_corr": "removed: the step is adaptive now; use miss_tolerance (expected missed "
                     f"crossings per length scale, default {FSL.DEFAULT_MISS_TOLERANCE:g})",
        "samples": "removed: values are sampled one at a time along the ray, with no "
                   "segments; delete the key",
    }

    def resolve(self, value, path, ctx, extra_keys=()):
        for key, why in self.REMOVED.items():
            if isinstance(value, dict) and key in value:
                ctx.fail(child(path, key), why)
        return super().resolve(value, path, ctx, extra_keys)


SAMPLERS = Tagged("sampler", {
    "weight_space": Record({"features": Field(Nullable(Int(ge=1, le=65536)), None)}),
    # Values of f sampled one at a time along rays, each conditioned on the memory and the
    # ray's previous samples, with an adaptive step (fs_march.h pins the rule): the memory
    # model, the global model's observation cap, the expected missed crossings per
    # along-ray length scale, and root-search points forced in a crossing bracket (0: the
    # root width alone decides).
    "function_space": _FunctionSpaceSampler({
        "memory": Field(Enum(*MEMORY_MODELS.names), "renewal_plus"),
        "memory_cap": Field(Int(ge=8, le=512), FSL.DEFAULT_GLOBAL_CAP),
        "miss_tolerance": Field(Number(ge=1e-9, le=0.1), FSL.DEFAULT_MISS_TOLERANCE),
        "refine": Field(Int(ge=0, le=20), FSL.DEFAULT_REFINE),
    }),
})



def _weight_space_kernel(g):
    if g["sampler"]["type"] == "weight_space":
        for key in FIELD_KEYS:
            if g["kernel"].get(key) is not None:
                return f"kernel.{key}", ("a spatially varying kernel is not stationary, and "
                                         "weight space samples stationary kernels only (random "
                                         "Fourier features of one spectral density); use the "
                                         "function_space sampler")
        kind = GP_KERNELS[g["kernel"]["type"]]
        if not kind.traits["spectral"]:
            return "kernel.type", (f"{kind.name} has no spectral density, so weight space "
                                   "cannot sample it; use the function_space sampler")
        if g["sampler"]["features"] is None:  # resolve "auto" so the written scene is explicit
            g["sampler"]["features"] = kind.host.features
    return None


def _thin_plate_span(g):
    """Thin-plate covariances are positive definite only among points within `radius`
    (anisotropic distance); function space samples anywhere in the proxy, so the proxy's
    diameter must fit (a conservative bound through the largest aniso weight)."""
    k = g["kernel"]
    if k["type"] != "thin_plate" or g["sampler"]["type"] != "function_space":
        return None
    if g["proxy"]["type"] == "scene":
        return "proxy.type", ("thin_plate is a covariance only within its radius, so it "
                              "needs a bounded proxy (box, sphere or mesh)")
    proxy = bounding_proxy(g["proxy"])
    if proxy["type"] == "box":
        diameter = sum((b - a) ** 2 for a, b in zip(proxy["min"], proxy["max"])) ** 0.5
    else:
        diameter = 2.0 * proxy["radius"]
    span = diameter * max(k["aniso"]) ** 0.5
    if k["radius"] < span:
        return "kernel.radius", (f"thin_plate is a covariance only within its radius; the "
                                 f"proxy spans {span:.4g} (diameter x sqrt(max aniso)), so "
                                 f"radius must be >= {span:.4g} (got {k['radius']:.4g})")
    return None


def _fields_positive(g):
    """A linear field may cross zero somewhere; where rays sample it must not."""
    for key in FIELD_KEYS:
        f = g["kernel"].get(key)
        if (f is not None and f["type"] == "linear" and g["proxy"]["type"] == "scene"
                and any(f["gradient"])):
            return f"kernel.{key}", ("a linear field with a gradient turns negative somewhere "
                                     "in an unbounded ('scene') proxy; bound the proxy")
        if f is not None and f["type"] == "linear":
            m = field_minimum(f, g["proxy"])
            if not m > 0.0:
                return f"kernel.{key}", (f"the linear field falls to {m:.4g} inside the proxy; "
                                         "a multiplier of sigma or l must stay positive there")
    return None


# Occupancy bounds (gpis_proxy.h): rays sample only between the first and last points
# inside the proxy where P(f(x) <= 0) can reach `occupancy` (epsilon); null: the whole
# proxy. Realizations with f < 0 only where the occupancy is below epsilon are ignored
# (about epsilon per correlation length of clipped ray); 1e-4 (mean > 3.72 sigma) keeps
# that far below a render's noise. On for both samplers: function space saves samples,
# weight space is about even (its search already strides where |f| >> sigma;
# docs/design/scene-key-costs.md, 'Occupancy').
# >= 1e-12: below ~1e-16, 1 - epsilon rounds to 1 and has no normal quantile
DEFAULT_OCCUPANCY = 1e-4
BOUNDS = Record({"occupancy": Field(Nullable(Number(ge=1e-12, lt=0.5)),
                                   DEFAULT_OCCUPANCY)})

# Posterior GPIS (compile/posterior.py): f conditioned on points observed on the surface,
# f = 0 with standard deviation `noise` (world units), and with "normals": true also
# grad f = n (three derivative rows per point, deviation `normal_noise`). Function space
# conditions exactly; weight space pathwise (SE and RQ kernels, compile/posterior.py); the
# file holds rows "x y z [nx ny nz]" (.xyz/.txt) or an (n, 3|6) .npy.
OBSERVATIONS = Record({
    "file": Field(File(POINT_FILES, points_problem)),
    "noise": Field(Number(ge=0), 1e-3),
    "normals": Field(Bool(), False),
    "normal_noise": Field(Number(ge=0), 1e-2),
})

GPIS = SHAPES.register("gpis", Record({
    "proxy": Field(PROXIES),
    "mean": Field(MEANS),
    "kernel": Field(KERNELS),
    "sampler": Field(SAMPLERS, {"type": "weight_space"}),
    "bsdf": Field(MICRO_BSDFS, {"type": "diffuse"}),
    # albedo multiplier and emitted radiance over space (scene/colour_fields.py); null: none
    "color": Field(COLOR, None),
    "emission": Field(EMISSION, None),
    "bounds": Field(BOUNDS, {}),
    "observations": Field(Nullable(OBSERVATIONS), None),
    # true: the proxy cuts the object on purpose (a medium's container, the authors'
    # wedge prism); false: compile/proxy_cut.py warns where the object reaches it
    "clip": Field(Bool(), False),
    # render the classical counterpart instead (compile/classical.py and
    # docs/design/classical-limits.md): "surface", the mean's zero set with the GP's
    # Beckmann slopes; "medium", flights of Rice's entry rate at the local mean and fields
    "classical": Field(Nullable(Enum("surface", "medium")), None),
}, checks=[mesh_proxy_problem, _weight_space_kernel, _thin_plate_span, _fields_positive,
           observations_problem]))
