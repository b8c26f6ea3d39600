"""The scene format's declarations: camera, render settings, BSDFs, shapes, lights.

A resolved scene (`Scene.data`) is plain JSON: every default filled in, every colour
three floats, every direction unit length, every file path absolute. Resolving is
idempotent, so a written resolved scene loads back to the same data.

To add an object kind, register a Record with SHAPES, LIGHTS or BSDFS (see below);
the renderer then finds it in `data` under its "type".
"""
from __future__ import annotations

import math

from .conductors import CONDUCTORS
from ..io.images import TONEMAPS
from ..io.meshes import mesh_problem
from ..schema import (Bool, Enum, Field, File, Int, ListOf, Nullable, String, Number, Record,
                     Tagged, Vector, show)

__all__ = ["SHAPES", "LIGHTS", "BSDFS", "ENVIRONMENT_TYPES", "SCENE"]


MAX_BATCH = 1 << 24       # paths: the queues' size at 16M paths is ~3 GiB already


# ---- small vector helpers for the cross-field checks (plain Python: no numpy needed)

def _sub(a, b):
    return [x - y for x, y in zip(a, b)]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _parallel(a, b) -> bool:
    # relative test: |a x b| is |a||b| sin(angle)
    return math.hypot(*_cross(a, b)) <= 1e-9 * math.hypot(*a) * math.hypot(*b)


# ---- value kinds

VEC3 = Vector()
NONZERO = Vector(nonzero=True)
DIRECTION = Vector(normalize=True)
RGB = Vector(broadcast=True, item=Number(ge=0))
ALBEDO = Vector(broadcast=True, item=Number(ge=0, le=1))


def _exr_problem(path):
    from ..io.images import read_exr_channel_names
    try:
        names = read_exr_channel_names(path)
    except Exception:
        return "cannot read as an OpenEXR image"
    missing = [c for c in "RGB" if c not in names]
    if missing:
        return (f"EXR image lacks channel(s) {', '.join(missing)} "
                f"(has: {', '.join(sorted(names)) or 'none'})")
    # the pixels too: a truncated file has a good header, and radiance must be >= 0 like
    # a light's radiance in the scene; the size and the memory to read it first
    from ..io.radiance_hdr import read_environment_rgb
    try:
        read_environment_rgb(path)
    except ValueError as exc:    # ours, naming the problem
        return str(exc).removeprefix(f"{path}: ")
    except Exception:  # OpenEXR reports damage as several types
        return "cannot read the pixels of this OpenEXR image (damaged or truncated?)"
    return None


def _envmap_problem(path):
    """OpenEXR, or Radiance .hdr (the authors' scenes use it)."""
    if path.lower().endswith(".hdr"):
        from ..io.radiance_hdr import hdr_problem
        return hdr_problem(path)
    return _exr_problem(path)


# ---- cross-field rules: each returns None or (key, reason)

def _camera_frame(c):
    forward = _sub(c["look_at"], c["position"])
    if not any(forward):
        return "look_at", f"must differ from position (both are {show(c['position'])})"
    if _parallel(forward, c["up"]):
        return "up", "must not be parallel to the view direction (look_at - position)"
    return None


def _rectangle_area(r):
    if _parallel(r["u"], r["v"]):
        return "v", "must not be parallel to u (the rectangle would have no area)"
    return None


def box_extent(b):
    for i, (lo, hi) in enumerate(zip(b["min"], b["max"])):
        if hi <= lo:
            return "max", (f"must be > min in every component "
                           f"(got max[{i}] = {hi:g} <= min[{i}] = {lo:g})")
    return None


# ---- declarations

CAMERA = Record({
    "position": Field(VEC3, [0, 1, 4]),
    "look_at": Field(VEC3, [0, 1, 0]),
    "up": Field(NONZERO, [0, 1, 0]),
    "fov": Field(Number(gt=0, lt=180), 40),
    "resolution": Field(Vector(2, Int(ge=1, le=16384)), [256, 256]),
}, checks=[_camera_frame])

RENDER = Record({
    "spp": Field(Int(ge=1, lt=2**31), 16),   # the device counts sample indices in int32
    "max_depth": Field(Int(ge=1), 8),
    "seed": Field(Int(ge=0, lt=2**32), 0),
    # the PNG preview's curve (io/images.tonemap_srgb8); the EXR keeps linear radiance
    "tonemap": Field(Enum(*TONEMAPS), "clamp"),
    # the most paths per batch (batching.py); null: 2^18
    "batch_size": Field(Nullable(Int(ge=1, le=MAX_BATCH)), None),
    "nee": Field(Bool(), True),  # false: BSDF sampling only (a reference for the tests)
    # an integer R: every path sees GPIS realization R (shows one sample of the geometry)
    "realization": Field(Nullable(Int(ge=0, lt=2**31)), None),
    "russian_roulette": Field(Record({
        "start_depth": Field(Int(ge=0), 3),
        "max_survival": Field(Number(gt=0, le=1), 0.95),
    }), {}),
})

def _eta_k_together(b):
    if (b["eta"] is None) != (b["k"] is None):
        return ("k" if b["k"] is None else "eta"), "give both eta and k, or neither"
    return None


# A metal with a rough surface: Beckmann microfacets, D ~ exp(-tan^2(theta_m) / alpha^2)
# with alpha = `roughness` (the rms slope is alpha / sqrt(2) per axis), the exact unpolarised Fresnel term of the complex index eta + i k (a `material`
# preset, conductors.py, or explicit RGB eta and k), height-correlated Smith masking;
# `albedo` multiplies it. Single scattering: energy that would bounce between
# microfacets is lost (a few percent at roughness 0.5, ~0.1% at 0.1).
ROUGH_CONDUCTOR = Record({"material": Field(Enum(*CONDUCTORS), "Cu"),
                          "eta": Field(Nullable(RGB), None),
                          "k": Field(Nullable(RGB), None),
                          "roughness": Field(Number(ge=1e-3, le=1.0), 0.1),
                          "albedo": Field(ALBEDO, 1.0)}, [_eta_k_together])

BSDFS = Tagged("bsdf", {
    "diffuse": Record({"albedo": Field(ALBEDO, 0.8)}),
    "mirror": Record({"albedo": Field(ALBEDO, 1.0)}),
    "rough_conductor": ROUGH_CONDUCTOR,
    "null": Record({}),  # pass-through, for bounding proxies
})
DEFAULT_BSDF = {"type": "diffuse", "albedo": [0.8, 0.8, 0.8]}


def shape(fields: dict, checks=()) -> Record:
    """A shape Record: the given fields plus the "bsdf" every shape takes."""
    return Record({**fields, "bsdf": Field(BSDFS, DEFAULT_BSDF)}, checks)


TRANSFORM = Record({  # applied as scale, then rotate (x, then y, then z), then translate
    "scale": Field(Vector(broadcast=True, item=Number(gt=0)), 1.0),
    "rotate": Field(VEC3, [0, 0, 0]),
    "translate": Field(VEC3, [0, 0, 0]),
})

SHAPES = Tagged("shape")
SHAPES.register("sphere", shape({"center": Field(VEC3, [0, 0, 0]),
                                 "radius": Field(Number(gt=0), 1.0)}))
SHAPES.register("rectangle", shape({"center": Field(VEC3, [0, 0, 0]),
                                    "u": Field(NONZERO, [1, 0, 0]),
                                    "v": Field(NONZERO, [0, 0, -1])}, [_rectangle_area]))
SHAPES.register("box", shape({"min": Field(VEC3), "max": Field(VEC3)}, [box_extent]))
SHAPES.register("disk", shape({"center": Field(VEC3, [0, 0, 0]),
                               "normal": Field(DIRECTION, [0, 1, 0]),
                               "radius": Field(Number(gt=0), 1.0)}))
SHAPES.register("mesh", shape({"file": Field(File((".obj", ".ply", ".stl"), mesh_problem)),
                               "transform": Field(TRANSFORM, {})}))

LIGHTS = Tagged("light")
LIGHTS.register("environment", Record({"radiance": Field(RGB, 1.0)}))
LIGHTS.register("environment_map", Record({
    "file": Field(File((".exr", ".hdr"), _envmap_problem)),
    "scale": Field(Number(ge=0), 1.0),
    "rotation": Field(Number(), 0.0),  # degrees about +y
}))
LIGHTS.register("point", Record({"position": Field(VEC3), "intensity": Field(RGB)}))
LIGHTS.register("sphere", Record({"center": Field(VEC3), "radius": Field(Number(gt=0)),
                                  "radiance": Field(RGB)}))
LIGHTS.register("rectangle", Record({  # emits towards cross(u, v) unless two-sided
    "center": Field(VEC3), "u": Field(NONZERO), "v": Field(NONZERO),
    "radiance": Field(RGB), "two_sided": Field(Bool(), False),
}, checks=[_rectangle_area]))
LIGHTS.register("directional", Record({
    "direction": Field(DIRECTION),  # towards the light
    "irradiance": Field(RGB),
    "angular_radius": Field(Number(ge=0, lt=90), 0.265),  # degrees; the sun's is 0.265
}))

# The renderer has one environment slot (rays that escape the scene look it up).
ENVIRONMENT_TYPES = {"environment", "environment_map"}


def _one_environment(scene):
    found = [i for i, lt in enumerate(scene["lights"]) if lt["type"] in ENVIRONMENT_TYPES]
    if len(found) > 1:
        return (f"lights[{found[1]}]", f"at most one environment light per scene "
                                       f"(lights[{found[0]}] is one already)")
    return None


SCENE = Record({
    "description": Field(String(), ""),  # free text for people; the renderer ignores it
    "camera": Field(CAMERA, {}),
    "render": Field(RENDER, {}),
    "shapes": Field(ListOf(SHAPES), []),
    "lights": Field(ListOf(LIGHTS, min_len=1, too_short="at least one light is required "
                                                        "(a scene without lights renders black)")),
}, checks=[_one_environment])
