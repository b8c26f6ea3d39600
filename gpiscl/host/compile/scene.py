"""Turns a resolved scene (scene.py) into the flat arrays the device traverses."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinds.lights import LIGHTS
from ..kinds.materials import MATERIALS
from ..layout import records as layouts
from ..layout import stages
from .bvh import build_bvh
from .camera import compile_camera
from .envmap import compile_envmap, no_envmap
from .classical import with_counterparts
from .gpis import CompiledGpis, compile_gpis
from .light_selection import light_choice
from ..scene.proxies import bounding_proxy
from ..scene.transforms import mesh_triangles
from ..errors import SceneError

PRIM = layouts.PRIM_KINDS


@dataclass
class CompiledScene:
    camera: np.ndarray
    primitives: np.ndarray
    materials: np.ndarray
    lights: np.ndarray
    light_choice: np.ndarray    # LIGHT_CHOICE: which light NEE picks (light_selection.py)
    caustic_spheres: np.ndarray  # CAUSTIC_SPHERES: int32 primitive ids (caustic_spheres())
    bvh_nodes: np.ndarray
    env_texels: np.ndarray      # (H*W, 4) float32, a dummy texel when no map
    env_marginal: np.ndarray
    env_conditional: np.ndarray
    env_size: tuple             # (width, height), (1, 1) when no map
    gpis: CompiledGpis

    @property
    def resolution(self) -> tuple:
        return int(self.camera["width"][0]), int(self.camera["height"][0])

    def device_arrays(self) -> dict:
        """The arrays the stage kernels read, by their parameter names (layout/stages.py):
        the render uploads each once and launches take them by name."""
        pairs = ((stages.CAMERA, self.camera), (stages.NODES, self.bvh_nodes),
                 (stages.PRIMS, self.primitives), (stages.MATERIALS, self.materials),
                 (stages.LIGHTS, self.lights), (stages.LIGHT_CHOICE, self.light_choice),
                 (stages.CAUSTIC_SPHERES, self.caustic_spheres),
                 (stages.GPIS, self.gpis.objects),
                 (stages.KERNELS, self.gpis.kernels), (stages.MEAN_NODES, self.gpis.mean_nodes),
                 (stages.ORDER_TABLE, self.gpis.order_table),
                 (stages.FIELD_NODES, self.gpis.field_nodes),
                 # the last table, the occupancy cells, is the render's (occupancy_boxes.py)
                 *zip(stages.GPIS_TABLES, (self.gpis.proxy_planes, self.gpis.posterior_obs,
                                           self.gpis.posterior_doubles)),
                 *zip(stages.ENV_MAP, (self.env_texels, self.env_marginal,
                                       self.env_conditional)))
        return {param.name: array for param, array in pairs}


class _Builder:
    def __init__(self):
        self.prims, self.materials, self.lights = [], [], []
        self.light_fields = []   # each light's packed fields, for its power estimate
        self.black = self.material({"type": "diffuse", "albedo": [0.0, 0.0, 0.0]})

    def material(self, bsdf: dict) -> int:
        m = layouts.MATERIAL.zeros(1)[0]
        m["kind"] = MATERIALS.id(bsdf["type"])
        _fill(m, MATERIALS[bsdf["type"]].host(bsdf))
        self.materials.append(m)
        return len(self.materials) - 1

    def prim(self, kind, material, p0=(0, 0, 0, 0), p1=(0, 0, 0, 0), p2=(0, 0, 0, 0),
             light=-1):
        p = layouts.PRIMITIVE.zeros(1)[0]
        p["kind"], p["material"], p["light"], p["medium"] = PRIM[kind], material, light, -1
        p["p0"], p["p1"], p["p2"] = _vec4(p0), _vec4(p1), _vec4(p2)
        self.prims.append(p)

    def light(self, kind, radiance, p0=(0, 0, 0, 0), p1=(0, 0, 0, 0), p2=(0, 0, 0, 0),
              area=0.0, cos_max=1.0) -> int:
        rec = layouts.LIGHT.zeros(1)[0]
        rec["kind"], rec["radiance"][:3] = LIGHTS.id(kind), radiance
        rec["p0"], rec["p1"], rec["p2"] = _vec4(p0), _vec4(p1), _vec4(p2)
        rec["area"], rec["cos_max"], rec["primitive"] = area, cos_max, -1
        self.lights.append(rec)
        return len(self.lights) - 1


def _fill(record, fields: dict):
    """A kind packer's fields into a record: vectors fill a float4's first components."""
    for name, value in fields.items():
        if record[name].shape:
            record[name][:len(value)] = value
        else:
            record[name] = value


def _vec4(v):
    v = list(v)
    return np.array(v + [0.0] * (4 - len(v)), dtype=np.float32)


def _rectangle(b: _Builder, center, u, v, material, light=-1):
    corner = np.asarray(center) - 0.5 * np.asarray(u) - 0.5 * np.asarray(v)
    b.prim("rectangle", material, corner, u, v, light=light)


def _box(b: _Builder, lo, hi, material):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dx, dy, dz = hi - lo
    X, Y, Z = np.array([dx, 0, 0]), np.array([0, dy, 0]), np.array([0, 0, dz])
    # corner, u, v with cross(u, v) pointing out of the box
    faces = [(lo, Z, Y), ((hi[0], lo[1], lo[2]), Y, Z), (lo, X, Z),
             ((lo[0], hi[1], lo[2]), Z, X), (lo, Y, X), ((lo[0], lo[1], hi[2]), X, Y)]
    for corner, u, v in faces:
        b.prim("rectangle", material, corner, u, v)


def _mesh(b: _Builder, shape, material):
    tris = mesh_triangles(shape).astype(np.float32)
    base = layouts.PRIMITIVE.zeros(len(tris))
    base["kind"], base["material"], base["light"], base["medium"] = PRIM["triangle"], material, -1, -1
    for k, field in enumerate(("p0", "p1", "p2")):
        base[field][:, :3] = tris[:, k]
    b.prims.extend(base)


def _add_shape(b: _Builder, s: dict):
    mat = b.material(s["bsdf"])
    kind = s["type"]
    if kind == "sphere":
        b.prim("sphere", mat, (*s["center"], s["radius"]))
    elif kind == "rectangle":
        _rectangle(b, s["center"], s["u"], s["v"], mat)
    elif kind == "box":
        _box(b, s["min"], s["max"], mat)
    elif kind == "disk":
        b.prim("disk", mat, (*s["center"], s["radius"]), s["normal"])
    elif kind == "mesh":
        _mesh(b, s, mat)
    else:  # the schema admits only the kinds above
        raise AssertionError(kind)


def _add_light(b: _Builder, lt: dict, env: dict):
    packed = dict(LIGHTS[lt["type"]].host(lt))
    b.light_fields.append((lt["type"], dict(packed)))
    if "environment_file" in packed:
        env["file"] = packed.pop("environment_file")
    carrier = packed.pop("primitive", None)
    li = b.light(lt["type"], **packed)
    if carrier is not None:  # a light rays can hit: a black primitive carries it
        b.prim(carrier[0], b.black, *carrier[1:], light=li)


def _bounds(prims: np.ndarray):
    p0, p1, p2 = (prims[f][:, :3].astype(np.float64) for f in ("p0", "p1", "p2"))
    kind = prims["kind"]
    r = prims["p0"][:, 3:4].astype(np.float64)
    lo = np.minimum(np.minimum(p0, p1), p2)
    hi = np.maximum(np.maximum(p0, p1), p2)
    sph = kind == PRIM["sphere"]
    lo[sph], hi[sph] = p0[sph] - r[sph], p0[sph] + r[sph]
    rect = kind == PRIM["rectangle"]
    corners = np.stack([p0, p0 + p1, p0 + p2, p0 + p1 + p2])[:, rect]
    lo[rect], hi[rect] = corners.min(0), corners.max(0)
    disk = kind == PRIM["disk"]
    ext = r[disk] * np.sqrt(np.clip(1.0 - p1[disk] ** 2, 0.0, 1.0))
    lo[disk], hi[disk] = p0[disk] - ext, p0[disk] + ext
    # pad so flat, axis-aligned primitives never get zero-thickness boxes
    pad = 1e-5 * (1.0 + np.abs(np.concatenate([lo, hi], 1)).max(1, keepdims=True))
    return lo - pad, hi + pad


def scene_box(data: dict, prims: np.ndarray | None = None):
    """(lo, hi) of everything bounded in the scene: primitives (area lights included),
    bounded GPIS proxies, point lights and the camera, grown by 0.01 of the diagonal. A
    path that leaves it meets nothing but infinitely far lights. prims: the compiled
    primitives, or None to build them."""
    if prims is None:
        b = _Builder()
        for s in data.get("shapes", []):
            if s["type"] != "gpis":
                _add_shape(b, s)
        for lt in data["lights"]:
            if LIGHTS[lt["type"]].traits["area"]:
                _add_light(b, lt, {})
        prims = np.array(b.prims, dtype=layouts.PRIMITIVE.dtype)
    pts = [np.asarray(data["camera"]["position"], float)[None]]
    if len(prims):
        pts += list(_bounds(prims))
    for s in data.get("shapes", []):
        if s["type"] == "gpis" and s["proxy"]["type"] != "scene":
            box = bounding_proxy(s["proxy"])
            if box["type"] == "box":
                pts.append(np.asarray([box["min"], box["max"]], float))
            else:
                pts.append(np.asarray(box["center"], float) + box["radius"] * np.array([[-1.0], [1.0]]))
    pts += [np.asarray(LIGHTS[lt["type"]].host(lt)["p0"][:3], float)[None]
            for lt in data["lights"] if LIGHTS[lt["type"]].traits["positioned"]]
    pts = np.concatenate(pts)
    lo, hi = pts.min(0), pts.max(0)
    grow = 0.01 * float(np.linalg.norm(hi - lo)) + 1e-3
    return lo - grow, hi + grow


def bound_scene_proxies(data: dict, prims: np.ndarray | None = None) -> list:
    """The gpis shapes with every "scene" proxy replaced by the scene's box (scene_box)."""
    shapes = [s for s in data.get("shapes", []) if s["type"] == "gpis"]
    if not any(s["proxy"]["type"] == "scene" for s in shapes):
        return shapes
    lo, hi = scene_box(data, prims)
    box = {"type": "box", "min": lo.tolist(), "max": hi.tolist()}
    return [dict(s, proxy=box) if s["proxy"]["type"] == "scene" else s for s in shapes]


def caustic_spheres(prims: np.ndarray, materials: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """The primitives the manifold NEE reflects area lights off (lib/caustics.h): classical
    mirror spheres that are no light, where the scene has an area light (else none)."""
    area = [LIGHTS.id(k) for k in LIGHTS.with_trait("area")]
    if not np.isin(lights["kind"], area).any():
        return np.zeros(0, np.int32)
    mirror = materials["kind"][prims["material"]] == MATERIALS.id("mirror")
    listed = (prims["kind"] == PRIM["sphere"]) & mirror & (prims["light"] < 0)
    return np.nonzero(listed)[0].astype(np.int32)


def compile_scene(data: dict, source: str = "<scene>", bakes=None) -> CompiledScene:
    """source: the scene's file, for errors found only while compiling (e.g. a mesh bake);
    bakes: the render device's bakes (render/device_bakes.py), numpy's when None."""
    data = with_counterparts(data, source)
    b = _Builder()
    env = {}
    for s in data.get("shapes", []):
        if s["type"] != "gpis":
            _add_shape(b, s)
    for lt in data["lights"]:
        _add_light(b, lt, env)
    prims = np.array(b.prims, dtype=layouts.PRIMITIVE.dtype)
    gpis_at = [i for i, s in enumerate(data.get("shapes", [])) if s["type"] == "gpis"]
    gpis = compile_gpis(bound_scene_proxies(data, prims), b.material, source,
                        [f"shapes[{i}]" for i in gpis_at], bakes)
    if len(prims):
        nodes, order = build_bvh(*_bounds(prims))
        prims = prims[order]
    else:
        nodes, _ = build_bvh(np.zeros((0, 3)), np.zeros((0, 3)))
    lights = np.array(b.lights, dtype=layouts.LIGHT.dtype)
    # area lights need to know their primitive after the BVH reordering
    for pi in np.nonzero(prims["light"] >= 0)[0]:
        lights["primitive"][prims["light"][pi]] = pi
    envmap = no_envmap()
    if "file" in env:
        try:
            envmap = compile_envmap(env["file"])
        except ValueError as exc:    # a Scene edited after its checks, or memory since
            key = next(f"lights[{i}].file" for i, lt in enumerate(data["lights"])
                       if lt["type"] == "environment_map")
            raise SceneError(source, key, str(exc).removeprefix(f"{env['file']}: ")
                             + f": {env['file']}") from None
        for _, fields in b.light_fields:    # the map's power estimate reads its texels
            if "environment_file" in fields:
                w, h = envmap.size
                fields["environment_rgb"] = envmap.texels.reshape(h, w, 4)[..., :3]
    lo, hi = scene_box(data, prims)
    choice = light_choice([f for _, f in b.light_fields], [k for k, _ in b.light_fields],
                          0.5 * float(np.linalg.norm(hi - lo)))
    materials = np.array(b.materials, dtype=layouts.MATERIAL.dtype)
    return CompiledScene(compile_camera(data["camera"]), prims, materials, lights, choice,
                         caustic_spheres(prims, materials, lights),
                         nodes, envmap.texels, envmap.marginal, envmap.conditional, envmap.size,
                         gpis)
