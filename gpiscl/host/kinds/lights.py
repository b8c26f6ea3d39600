"""The light kinds: one declaration each, the device code in kernels_cl/lib/lights/<name>.h
(docs/extending.md: "Adding a light").

A kind's packer turns its resolved scene object into Light record fields (layout/records.py
LIGHT: radiance, p0, p1, p2, area, cos_max), plus "primitive": (primitive kind, p0, p1,
p2) for a light that rays can hit (compile/scene.py adds a black primitive carrying it),
and "environment_file" for the one environment map (compile/scene.py reads it last and
gives its texels to the power estimate as "environment_rgb"). Traits:
  environment  fills the scene's one environment slot (at most one per scene); a vertex
               may leave these to BSDF sampling (fs_random_normal.h);
  at_infinity  escaped rays look it up: has <name>_radiance;
  area         carried by a primitive that rays hit: has <name>_area_radiance and
               <name>_sample_point;
  positioned   the packer's p0 is a point of the scene (its bounding box takes it).
A kind's host is a LightHost: its packer, and its power estimate, by which next-event
estimation picks among the scene's lights (compile/light_selection.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .table import Kind, KindTable
from .values import DIRECTION, NONZERO, RGB, VEC3, rectangle_area
from ..schema import Bool, Field, File, Number, Record


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


# ---- packers

def pack_environment(lt):
    return {"radiance": lt["radiance"]}


def pack_environment_map(lt):
    # the texels are read at the end of the compile, when nothing else is held
    return {"radiance": [lt["scale"]] * 3, "p0": (math.radians(lt["rotation"]),),
            "environment_file": lt["file"]}


def pack_point(lt):
    return {"radiance": lt["intensity"], "p0": lt["position"]}


def pack_sphere(lt):
    sphere = (*lt["center"], lt["radius"])
    return {"radiance": lt["radiance"], "p0": sphere, "primitive": ("sphere", sphere)}


def pack_rectangle(lt):
    u, v = np.asarray(lt["u"], float), np.asarray(lt["v"], float)
    corner = np.asarray(lt["center"]) - 0.5 * u - 0.5 * v
    return {"radiance": lt["radiance"], "p0": corner, "p1": u,
            "p2": (*v, 1.0 if lt["two_sided"] else 0.0),
            "area": float(np.linalg.norm(np.cross(u, v))),
            "primitive": ("rectangle", corner, u, v)}


def pack_directional(lt):
    theta = math.radians(lt["angular_radius"])
    E = np.asarray(lt["irradiance"], dtype=np.float64)
    if theta == 0.0:
        return {"radiance": E, "p0": (*lt["direction"], 0.0), "cos_max": 1.0}
    # uniform radiance L over the cone delivers E = L * pi * sin^2(theta) on axis; the
    # device samples the cone by 1 - cos(theta) (p0.w, lights.h), computed as
    # 2 sin^2(theta / 2) so that float32 keeps its digits for a small sun
    return {"radiance": E / (math.pi * math.sin(theta) ** 2),
            "p0": (*lt["direction"], 2.0 * math.sin(theta / 2) ** 2),
            "cos_max": math.cos(theta)}


# ---- power estimates: what next-event estimation gains by sampling a light, in one unit
# for every kind, so that it can pick lights in proportion (compile/light_selection.py;
# docs/design/light-sampling.md has the derivation and the measurements). Finite lights:
# the emitted power. Lights at infinity: the greatest irradiance a plane in the scene
# receives from them, times the scene's cross-section pi R^2 (R: the radius of the
# scene's bounding sphere), times the chance that BSDF sampling misses them (bsdf_miss):
# a light that BSDF sampling finds by itself gains little from NEE's choices, which the
# concentrated lights need (a sun beside a sky on a diffuse floor, 'Measured' there).
# Arguments: the packer's fields, R, and the solid angle of the BSDF lobe the light
# competes with (pi: a cosine lobe; light_selection.NARROW_LOBE).

def brightness(rgb) -> float:
    """The scalar the estimates rank lights by: the mean of the RGB channels."""
    return float(np.mean(np.asarray(rgb, dtype=np.float64)[:3]))


def bsdf_miss(solid_angle: float, lobe: float = math.pi) -> float:
    """The chance that a direction from a BSDF lobe facing a light of this solid angle
    misses it. A cosine lobe (lobe = pi, a diffuse vertex): 1 - (the light's projected
    solid angle) / pi, taken as 1 - solid_angle / pi, 0 from pi sr on (a constant sky, a
    wide dome); a narrow lobe of `lobe` sr (a function-space mirror,
    light_selection.NARROW_LOBE): 1 - solid_angle / lobe."""
    return max(0.0, 1.0 - solid_angle / lobe)


def environment_power(f, radius, lobe=math.pi):
    """0 (it covers 4 pi sr): BSDF sampling already follows f cos L for a constant L;
    alone (every estimate 0) it is still chosen: selection_pmf falls back to uniform."""
    irradiance = math.pi * brightness(f["radiance"])
    return irradiance * math.pi * radius ** 2 * bsdf_miss(4.0 * math.pi, lobe)


# the normals over which a map's greatest plane irradiance is sought: the axes and the
# diagonals (a map's bright spot is at most 55 degrees from one of them: cos >= 0.57)
_PLANE_NORMALS = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1)
                           for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)], dtype=np.float64)
_PLANE_NORMALS /= np.linalg.norm(_PLANE_NORMALS, axis=1, keepdims=True)


def _coarse_luminance(rgb) -> np.ndarray:
    """The map's mean of R, G, B over blocks of step^2 pixels (about 128 rows: enough for a
    choice), a band of rows at a time: an 8k map is never copied whole."""
    h, w = rgb.shape[:2]
    step = max(1, h // 128)
    rows, cols = h // step, w // step
    out = np.empty((rows, cols))
    for i in range(rows):
        band = rgb[i * step:(i + 1) * step, :cols * step, :3]
        out[i] = band.sum(axis=(0, 2), dtype=np.float64).reshape(cols, step).sum(1)
    return out / (3 * step * step)


def environment_map_power(f, radius, lobe=math.pi):
    """Its solid angle for bsdf_miss: that of a patch as bright as the map's brightest
    pixel holding all its radiance (a sun drawn into the map: small; a smooth sky:
    large)."""
    lum = _coarse_luminance(f["environment_rgb"])
    h, w = lum.shape
    theta = ((np.arange(h) + 0.5) * math.pi / h)[:, None]
    phi = ((np.arange(w) + 0.5) * 2.0 * math.pi / w)[None, :]
    # lat-long as lights/environment_map.h reads it (theta from +y); the rotation about y
    # does not change which plane is best enough to matter for a choice
    d = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.cos(theta),
                                     np.sin(theta) * np.sin(phi)), -1).reshape(-1, 3)
    weight = (lum * np.sin(theta) * (2.0 * math.pi ** 2 / (w * h))).reshape(-1)
    if not weight.sum() > 0.0:
        return 0.0
    irradiance = (np.maximum(d @ _PLANE_NORMALS.T, 0.0) * weight[:, None]).sum(0).max()
    solid_angle = float(weight.sum() / lum.max())
    return (brightness(f["radiance"]) * float(irradiance) * math.pi * radius ** 2
            * bsdf_miss(solid_angle, lobe))


def point_power(f, radius, lobe=math.pi):
    return 4.0 * math.pi * brightness(f["radiance"])


def sphere_power(f, radius, lobe=math.pi):
    r = f["p0"][3]
    return math.pi * brightness(f["radiance"]) * 4.0 * math.pi * r * r


def rectangle_power(f, radius, lobe=math.pi):
    sides = 2.0 if f["p2"][3] else 1.0
    return math.pi * brightness(f["radiance"]) * f["area"] * sides


def directional_power(f, radius, lobe=math.pi):
    omc = f["p0"][3]   # 1 - cos(angular radius): radiance * pi sin^2 is the irradiance
    irradiance = brightness(f["radiance"]) * (math.pi * omc * (2.0 - omc) if omc else 1.0)
    return irradiance * math.pi * radius ** 2 * bsdf_miss(2.0 * math.pi * omc, lobe)


@dataclass(frozen=True)
class LightHost:
    """A light kind's host side. pack: resolved scene object -> Light record fields (see
    the top); power: (those fields, the scene's radius[, the BSDF lobe's solid angle,
    pi when not given]) -> the power estimate above."""
    pack: Callable[[dict], dict]
    power: Callable[..., float]

    def __call__(self, lt: dict) -> dict:
        return self.pack(lt)


def _traits(environment=False, at_infinity=False, area=False, positioned=False):
    return {"environment": environment, "at_infinity": at_infinity, "area": area,
            "positioned": positioned}


LIGHTS = KindTable("light", "LIGHT", [
    Kind("environment", Record({"radiance": Field(RGB, 1.0)}), "lib/lights/environment.h",
         _traits(environment=True, at_infinity=True),
         LightHost(pack_environment, environment_power)),
    Kind("environment_map", Record({
        "file": Field(File((".exr", ".hdr"), _envmap_problem)),
        "scale": Field(Number(ge=0), 1.0),
        "rotation": Field(Number(), 0.0),  # degrees about +y
    }), "lib/lights/environment_map.h", _traits(environment=True, at_infinity=True),
        LightHost(pack_environment_map, environment_map_power)),
    Kind("point", Record({"position": Field(VEC3), "intensity": Field(RGB)}),
         "lib/lights/point.h", _traits(positioned=True),
         LightHost(pack_point, point_power)),
    Kind("sphere", Record({"center": Field(VEC3), "radius": Field(Number(gt=0)),
                           "radiance": Field(RGB)}),
         "lib/lights/sphere.h", _traits(area=True), LightHost(pack_sphere, sphere_power)),
    Kind("rectangle", Record({  # emits towards cross(u, v) unless two-sided
        "center": Field(VEC3), "u": Field(NONZERO), "v": Field(NONZERO),
        "radiance": Field(RGB), "two_sided": Field(Bool(), False),
    }, checks=[rectangle_area]), "lib/lights/rectangle.h", _traits(area=True),
        LightHost(pack_rectangle, rectangle_power)),
    Kind("directional", Record({
        "direction": Field(DIRECTION),  # towards the light
        "irradiance": Field(RGB),
        "angular_radius": Field(Number(ge=0, lt=90), 0.265),  # degrees; the sun's is 0.265
    }), "lib/lights/directional.h", _traits(at_infinity=True),
        LightHost(pack_directional, directional_power)),
], traits=("environment", "at_infinity", "area", "positioned"), family="light")

_SAMPLE = "__global const Light* l, EnvMap m, float3 x, float2 u, float3* wi, float* dist, float* pdf"
_RADIANCE = "__global const Light* l, EnvMap m, float3 d, float* pdf"
_AREA = "__global const Light* l, float3 from, float3 x, float3 n, float3 d, float* pdf"
_POINT = "__global const Light* l, float2 u, float3* y, float3* n, float* pdf_area"
_NO_LIGHT = "(*pdf = 0.0f, (float3)(0.0f))"


def c_declarations() -> list:
    """The ids and trait macros (the generated layout header)."""
    return LIGHTS.c_enum() + LIGHTS.c_traits()


def device_source() -> str:
    """Every kind's light file and the light_sample / light_radiance /
    light_area_radiance / light_sample_point dispatch (lights.h, the shared part, comes
    before)."""
    return "\n".join([
        LIGHTS.device_source(), '#line 1 "generated light dispatch"',
        LIGHTS.c_dispatch("sample", "inline float3", _SAMPLE, "l, m, x, u, wi, dist, pdf",
                          "(*dist = T_INFINITY, *pdf = 0.0f, (float3)(0.0f))"),
        LIGHTS.c_dispatch("radiance", "inline float3", _RADIANCE, "l, m, d, pdf", _NO_LIGHT,
                          LIGHTS.with_trait("at_infinity")),
        LIGHTS.c_dispatch("area_radiance", "inline float3", _AREA, "l, from, x, n, d, pdf",
                          _NO_LIGHT, LIGHTS.with_trait("area")),
        LIGHTS.c_dispatch("sample_point", "void", _POINT, "l, u, y, n, pdf_area",
                          kinds=LIGHTS.with_trait("area"))])
