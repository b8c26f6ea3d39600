"""The scene format's declarations: camera, render settings, BSDFs, shapes, lights.

A resolved scene (`Scene.data`) is plain JSON: every default filled in, every colour
three floats, every direction unit length, every file path absolute. Resolving is
idempotent, so a written resolved scene loads back to the same data.

Shapes are registered with SHAPES below; BSDFs and lights are kinds, declared once in
host/kinds/materials.py and host/kinds/lights.py (docs/extending.md), whose tables hold
the BSDFS and LIGHTS schemas used here.
"""
from __future__ import annotations

from ..io.images import TONEMAPS
from ..io.meshes import mesh_problem
from ..kinds.lights import LIGHTS as LIGHT_TABLE
from ..kinds.materials import MATERIALS
from ..kinds.values import DIRECTION, NONZERO, VEC3, parallel, rectangle_area
from ..schema import (Bool, Enum, Field, File, Int, ListOf, Nullable, String, Number, Record,
                     Tagged, Vector, show)

__all__ = ["SHAPES", "LIGHTS", "BSDFS", "SCENE"]


MAX_BATCH = 1 << 24       # paths: the queues of 16M paths already take several GiB


def _sub(a, b):
    return [x - y for x, y in zip(a, b)]


# ---- cross-field rules: each returns None or (key, reason)

def _camera_frame(c):
    forward = _sub(c["look_at"], c["position"])
    if not any(forward):
        return "look_at", f"must differ from position (both are {show(c['position'])})"
    if parallel(forward, c["up"]):
        return "up", "must not be parallel to the view direction (look_at - position)"
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

BSDFS = MATERIALS.schema
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
                                    "v": Field(NONZERO, [0, 0, -1])}, [rectangle_area]))
SHAPES.register("box", shape({"min": Field(VEC3), "max": Field(VEC3)}, [box_extent]))
SHAPES.register("disk", shape({"center": Field(VEC3, [0, 0, 0]),
                               "normal": Field(DIRECTION, [0, 1, 0]),
                               "radius": Field(Number(gt=0), 1.0)}))
SHAPES.register("mesh", shape({"file": Field(File((".obj", ".ply", ".stl"), mesh_problem)),
                               "transform": Field(TRANSFORM, {})}))

LIGHTS = LIGHT_TABLE.schema

# The renderer has one environment slot (rays that escape the scene look it up).
def _one_environment(scene):
    found = [i for i, lt in enumerate(scene["lights"])
             if LIGHT_TABLE[lt["type"]].traits["environment"]]
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
