"""The scene format: declarations for the strict JSON loader, and the loader itself.

A resolved scene (`Scene.data`) is plain JSON: every default filled in, every colour
three floats, every direction unit length, every file path absolute. Resolving is
idempotent, so a written resolved scene loads back to the same data.

To add an object kind, register a Record with SHAPES, LIGHTS or BSDFS (see below);
the renderer then finds it in `data` under its "type".
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

from .conductors import CONDUCTORS
from .imageio import TONEMAPS
from .batching import MAX_BATCH
from .scene_schema import (Bool, Context, Enum, Field, File, Int, ListOf, Nullable, String,
                           Number, Record, SceneError, Tagged, Vector, array_problem, kind_of,
                           show)

__all__ = ["SceneError", "Scene", "load_scene", "write_resolved",
           "SHAPES", "LIGHTS", "BSDFS", "ENVIRONMENT_TYPES", "SCENE"]


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


def _mesh_problem(path):
    import trimesh
    problem = _obj_index_problem(path)
    if problem:
        return problem
    try:
        # process=False: processing drops the faces of NaN vertices without a word
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a corrupt file
        # the type only: a message may quote the file, which can be anything a scene names
        return f"cannot read mesh ({type(exc).__name__})"
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        return "mesh has no triangles"
    return array_problem(mesh.vertices, "mesh")


def _obj_index_problem(path):
    """OBJ indices start at 1 (negative: from the end); trimesh reads 0 as the last vertex."""
    if not path.lower().endswith(".obj"):
        return None
    with open(path, "rb") as f:
        for number, line in enumerate(f, 1):
            if line.startswith(b"f ") and any(t.split(b"/")[0] in (b"0", b"-0")
                                              for t in line.split()[1:]):
                return f"OBJ face on line {number} uses vertex index 0 (indices start at 1)"
    return None


def _exr_problem(path):
    import OpenEXR
    try:
        if hasattr(OpenEXR, "InputFile"):
            f = OpenEXR.InputFile(path)
            names = set(f.header()["channels"])
            f.close()
        else:
            names = set(OpenEXR.File(path, separate_channels=True).channels())
    except Exception:
        return "cannot read as an OpenEXR image"
    missing = [c for c in "RGB" if c not in names]
    if missing:
        return (f"EXR image lacks channel(s) {', '.join(missing)} "
                f"(has: {', '.join(sorted(names)) or 'none'})")
    # the pixels too: a truncated file has a good header, and radiance must be >= 0 like
    # a light's radiance in the scene
    try:
        from .imageio import read_exr_rgb
        rgb = read_exr_rgb(path)
    except Exception:  # OpenEXR reports damage as several types
        return "cannot read the pixels of this OpenEXR image (damaged or truncated?)"
    return array_problem(rgb, "environment map", nonnegative=True)


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


def _box_extent(b):
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
    "spp": Field(Int(ge=1), 16),
    "max_depth": Field(Int(ge=1), 8),
    "seed": Field(Int(ge=0, lt=2**32), 0),
    # the PNG preview's curve (imageio.tonemap_srgb8); the EXR keeps linear radiance
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
SHAPES.register("box", shape({"min": Field(VEC3), "max": Field(VEC3)}, [_box_extent]))
SHAPES.register("disk", shape({"center": Field(VEC3, [0, 0, 0]),
                               "normal": Field(DIRECTION, [0, 1, 0]),
                               "radius": Field(Number(gt=0), 1.0)}))
SHAPES.register("mesh", shape({"file": Field(File((".obj", ".ply", ".stl"), _mesh_problem)),
                               "transform": Field(TRANSFORM, {})}))

LIGHTS = Tagged("light")
LIGHTS.register("environment", Record({"radiance": Field(RGB, 1.0)}))
LIGHTS.register("environment_map", Record({
    "file": Field(File((".exr",), _exr_problem)),
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


from . import gpis_schema  # noqa: E402,F401  (registers the "gpis" shape)

# ---- loading

@dataclass
class Scene:
    """A validated, resolved scene (see load_scene).

    Parameters
    ----------
    data : dict
        The scene document; Scene(data) validates and resolves it exactly as a scene file
        is (SceneError on any mistake), so no Scene holds unchecked data.
    source : str
        Where it came from, for error messages.
    base_dir : str
        The folder relative file paths are resolved against.
    """
    data: dict
    source: str = "<dict>"
    base_dir: str = field(default_factory=os.getcwd)

    def __post_init__(self):
        self.data = SCENE.resolve(self.data, "", Context(self.source, self.base_dir))

    @classmethod
    def resolved(cls, data: dict, source: str, base_dir: str) -> "Scene":
        """A Scene of data that is already resolved (load_scene's result, edited only with
        values checked on their own): skips validating again, which would reread every
        mesh and image the scene names."""
        scene = object.__new__(cls)
        scene.data, scene.source, scene.base_dir = data, source, base_dir
        return scene

    def __repr__(self):
        return (f"Scene(source={self.source!r}, {len(self.data.get('shapes', []))} shapes, "
                f"{len(self.data.get('lights', []))} lights)")


class _JsonObject(dict):
    """A parsed JSON object that remembers keys it saw twice (json keeps the last)."""
    duplicate_keys = ()


def _object_pairs(pairs):
    obj, dups = _JsonObject(), []
    for key, value in pairs:
        if key in obj:
            dups.append(key)
        obj[key] = value
    if dups:
        obj.duplicate_keys = dups
    return obj


MAX_SCENE_BYTES = 64 << 20   # a scene names its big data in files; more is a mistake


def _read_json(path: str, ctx: Context):
    try:
        # a FIFO would block forever and /dev/zero fill memory: regular files only, bounded
        if os.path.exists(path) and not os.path.isdir(path) and not os.path.isfile(path):
            ctx.fail("", "not a regular file")
        if os.path.isfile(path) and os.path.getsize(path) > MAX_SCENE_BYTES:
            ctx.fail("", f"larger than {MAX_SCENE_BYTES >> 20} MiB: not a scene file")
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        ctx.fail("", "file not found")
    except IsADirectoryError:
        ctx.fail("", "is a directory, not a scene file")
    except UnicodeDecodeError:
        ctx.fail("", "not UTF-8 text")
    except OSError as exc:
        ctx.fail("", f"cannot read file ({exc.strerror or exc})")
    try:
        return json.loads(text, object_pairs_hook=_object_pairs)
    except json.JSONDecodeError as exc:
        ctx.fail("", f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}")
    except RecursionError:
        ctx.fail("", "invalid JSON: nested too deeply")
    except ValueError as exc:  # e.g. an integer literal with too many digits
        ctx.fail("", f"invalid JSON: {exc}")


def load_scene(source) -> Scene:
    """Validate and resolve a scene.

    Parameters
    ----------
    source : str, os.PathLike, dict or Scene
        A scene file (relative asset paths resolve against its real folder, also through
        a link), a scene document (relative paths resolve against the working folder), or
        a Scene, returned as is.

    Returns
    -------
    Scene
        Every default filled in, every colour three floats, every file path absolute.

    Raises
    ------
    SceneError
        For any mistake in the scene, naming the file, the key path and the reason. A given
        dict is never changed.
    """
    if isinstance(source, Scene):
        return source
    if isinstance(source, dict):
        ctx = Context("<dict>", os.getcwd())
        doc = source
    elif isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        # relative asset paths are relative to the scene file itself, also through a link
        ctx = Context(path, os.path.dirname(os.path.realpath(path)))
        doc = _read_json(path, ctx)
        if not isinstance(doc, dict):
            ctx.fail("", f"top level must be a JSON object (got {kind_of(doc)})")
    else:
        raise TypeError(f"load_scene takes a path, a dict or a Scene, not {type(source).__name__}")
    _check_nesting(doc, ctx)
    return Scene.resolved(SCENE.resolve(doc, "", ctx), ctx.file, ctx.base_dir)


MAX_NESTING = 100   # levels of objects and lists: the resolver recurses, and a CSG tree
                    # anywhere near this deep is far beyond the device's stack anyway


def _check_nesting(doc, ctx: Context):
    """A clear error for a document nested too deeply, before the recursive resolver
    meets it (a 600-deep union chain was a RecursionError). Iterative, so any depth."""
    stack = [(doc, 1, "")]
    while stack:
        value, depth, path = stack.pop()
        if depth > MAX_NESTING:
            shown = path if len(path) <= 80 else path[:60] + "..."
            ctx.fail(shown, f"nested more than {MAX_NESTING} levels deep")
        if isinstance(value, dict):
            stack.extend((v, depth + 1, f"{path}.{k}" if path else str(k))
                         for k, v in value.items())
        elif isinstance(value, (list, tuple)):
            stack.extend((v, depth + 1, f"{path}[{i}]") for i, v in enumerate(value))


def write_resolved(scene, path) -> None:
    """Write the resolved scene as indented JSON; loading it gives the same data."""
    scene = load_scene(scene)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(scene.data, f, indent=2, allow_nan=False)
        f.write("\n")
