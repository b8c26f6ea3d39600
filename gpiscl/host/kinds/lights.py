"""The light kinds: one declaration each, the device code in kernels_cl/lib/lights/<name>.h
(docs/extending.md: "Adding a light").

A kind's packer turns its resolved scene object into Light record fields (layout/records.py
LIGHT: radiance, p0, p1, p2, area, cos_max), plus "primitive": (primitive kind, p0, p1,
p2) for a light that rays can hit (compile/scene.py adds a black primitive carrying it),
and "environment_file" for the one environment map. Traits:
  environment  fills the scene's one environment slot (at most one per scene); a vertex
               may leave these to BSDF sampling (fs_random_normal.h);
  at_infinity  escaped rays look it up: has <name>_radiance;
  area         carried by a primitive that rays hit: has <name>_area_radiance;
  positioned   the packer's p0 is a point of the scene (its bounding box takes it).
"""
from __future__ import annotations

import math

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


def _traits(environment=False, at_infinity=False, area=False, positioned=False):
    return {"environment": environment, "at_infinity": at_infinity, "area": area,
            "positioned": positioned}


LIGHTS = KindTable("light", "LIGHT", [
    Kind("environment", Record({"radiance": Field(RGB, 1.0)}), "lib/lights/environment.h",
         _traits(environment=True, at_infinity=True), pack_environment),
    Kind("environment_map", Record({
        "file": Field(File((".exr", ".hdr"), _envmap_problem)),
        "scale": Field(Number(ge=0), 1.0),
        "rotation": Field(Number(), 0.0),  # degrees about +y
    }), "lib/lights/environment_map.h", _traits(environment=True, at_infinity=True),
        pack_environment_map),
    Kind("point", Record({"position": Field(VEC3), "intensity": Field(RGB)}),
         "lib/lights/point.h", _traits(positioned=True), pack_point),
    Kind("sphere", Record({"center": Field(VEC3), "radius": Field(Number(gt=0)),
                           "radiance": Field(RGB)}),
         "lib/lights/sphere.h", _traits(area=True), pack_sphere),
    Kind("rectangle", Record({  # emits towards cross(u, v) unless two-sided
        "center": Field(VEC3), "u": Field(NONZERO), "v": Field(NONZERO),
        "radiance": Field(RGB), "two_sided": Field(Bool(), False),
    }, checks=[rectangle_area]), "lib/lights/rectangle.h", _traits(area=True),
        pack_rectangle),
    Kind("directional", Record({
        "direction": Field(DIRECTION),  # towards the light
        "irradiance": Field(RGB),
        "angular_radius": Field(Number(ge=0, lt=90), 0.265),  # degrees; the sun's is 0.265
    }), "lib/lights/directional.h", _traits(at_infinity=True), pack_directional),
], traits=("environment", "at_infinity", "area", "positioned"), family="light")

_SAMPLE = "__global const Light* l, EnvMap m, float3 x, float2 u, float3* wi, float* dist, float* pdf"
_RADIANCE = "__global const Light* l, EnvMap m, float3 d, float* pdf"
_AREA = "__global const Light* l, float3 from, float3 x, float3 n, float3 d, float* pdf"
_NO_LIGHT = "(*pdf = 0.0f, (float3)(0.0f))"


def c_declarations() -> list:
    """The ids and trait macros (the generated layout header)."""
    return LIGHTS.c_enum() + LIGHTS.c_traits()


def device_source() -> str:
    """Every kind's light file and the light_sample / light_radiance /
    light_area_radiance dispatch (lights.h, the shared part, comes before)."""
    return "\n".join([
        LIGHTS.device_source(), '#line 1 "generated light dispatch"',
        LIGHTS.c_dispatch("sample", "inline float3", _SAMPLE, "l, m, x, u, wi, dist, pdf",
                          "(*dist = T_INFINITY, *pdf = 0.0f, (float3)(0.0f))"),
        LIGHTS.c_dispatch("radiance", "inline float3", _RADIANCE, "l, m, d, pdf", _NO_LIGHT,
                          LIGHTS.with_trait("at_infinity")),
        LIGHTS.c_dispatch("area_radiance", "inline float3", _AREA, "l, from, x, n, d, pdf",
                          _NO_LIGHT, LIGHTS.with_trait("area"))])
