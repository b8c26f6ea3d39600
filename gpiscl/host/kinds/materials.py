"""The material (surface BSDF) kinds: one declaration each, the device code in
kernels_cl/lib/bsdf/<name>.h (docs/extending.md: "Adding a material").

A kind's packer turns its resolved scene object into Material record fields
(layout/records.py MATERIAL); the device reads the kind's own fields only in its file.
Traits:
  micro          usable as a GPIS micro-BSDF (scene/gpis.py takes these);
  delta          a delta BSDF on ordinary surfaces: no next-event estimation;
  pass_through   rays pass unchanged (a bounding proxy's surface): no BSDF at all;
  random_normal  how a function-space GPIS hit's normal law enters NEE and MIS
                 (RANDOM_NORMAL below; kernels_cl/lib/fs_random_normal.h).
"""
from __future__ import annotations

from .conductors import CONDUCTORS, eta_k
from .table import Kind, KindTable
from .values import ALBEDO, RGB
from ..schema import Enum, Field, Nullable, Number, Record

# fs_random_normal.h's modes
RANDOM_NORMAL = {"sampled": 0, "half_vector": 1, "pairs": 2}


def pack_albedo(bsdf: dict) -> dict:
    return {"albedo": bsdf["albedo"]}


def pack_nothing(bsdf: dict) -> dict:
    return {}


def pack_rough_conductor(bsdf: dict) -> dict:
    eta, k = eta_k(bsdf)
    return {"albedo": bsdf["albedo"], "eta": eta, "k": k, "roughness": bsdf["roughness"]}


def pack_mirror(bsdf: dict) -> dict:
    if bsdf["material"] is None and bsdf["eta"] is None:
        return {"albedo": bsdf["albedo"]}
    eta, k = eta_k(bsdf)
    return {"albedo": bsdf["albedo"], "eta": eta, "k": k, "fresnel": 1}


def _eta_k_together(b):
    if (b["eta"] is None) != (b["k"] is None):
        return ("k" if b["k"] is None else "eta"), "give both eta and k, or neither"
    return None


def _conductor_or_eta_k(b):
    if b["material"] is not None and b["eta"] is not None:
        return "eta", "give a preset `material` or eta and k, not both"
    return None


# A metal with a rough surface: Beckmann microfacets, D ~ exp(-tan^2(theta_m) / alpha^2)
# with alpha = `roughness` (the rms slope is alpha / sqrt(2) per axis), the exact
# unpolarised Fresnel term of the complex index eta + i k (a `material` preset,
# conductors.py, or explicit RGB eta and k), height-correlated Smith masking; `albedo`
# multiplies it. Single scattering: energy that would bounce between microfacets is lost
# (a few percent at roughness 0.5, less when smoother: docs/design/scene-key-costs.md,
# 'rough_conductor').
ROUGH_CONDUCTOR = Record({"material": Field(Enum(*CONDUCTORS), "Cu"),
                          "eta": Field(Nullable(RGB), None),
                          "k": Field(Nullable(RGB), None),
                          "roughness": Field(Number(ge=1e-3, le=1.0), 0.1),
                          "albedo": Field(ALBEDO, 1.0)}, [_eta_k_together])


# A perfect mirror. Without `material` (a conductor preset, conductors.py) or `eta` and
# `k` it reflects `albedo` at every angle; with either it reflects albedo x the exact
# unpolarised Fresnel term of that metal, as rough_conductor does.
MIRROR = Record({"albedo": Field(ALBEDO, 1.0),
                 "material": Field(Nullable(Enum(*CONDUCTORS)), None),
                 "eta": Field(Nullable(RGB), None),
                 "k": Field(Nullable(RGB), None)}, [_eta_k_together, _conductor_or_eta_k])


def _traits(micro, delta=False, pass_through=False, random_normal="sampled"):
    return {"micro": micro, "delta": delta, "pass_through": pass_through,
            "random_normal": RANDOM_NORMAL[random_normal]}


MATERIALS = KindTable("material", "MATERIAL", [
    Kind("diffuse", Record({"albedo": Field(ALBEDO, 0.8)}), "lib/bsdf/diffuse.h",
         _traits(micro=True), pack_albedo),
    Kind("mirror", MIRROR, "lib/bsdf/mirror.h",
         _traits(micro=True, delta=True, random_normal="half_vector"), pack_mirror),
    # pass-through, for bounding proxies: no device file, the pass_through trait is all
    Kind("null", Record({}), None, _traits(micro=False, pass_through=True), pack_nothing),
    Kind("rough_conductor", ROUGH_CONDUCTOR, "lib/bsdf/rough_conductor.h",
         _traits(micro=True, random_normal="pairs"), pack_rough_conductor),
], traits=("micro", "delta", "pass_through", "random_normal"), family="bsdf",
   shared_files=("lib/bsdf/fresnel.h",))

# What the scene's GPIS shapes take (scene/gpis.py).
MICRO_BSDFS = MATERIALS.schema_where("micro", "micro-BSDF")

_MATERIAL_PARAMS = "__global const Material* mat, float3 albedo, float3 n, float3 wo"
_NO_BSDF = "(*pdf = 0.0f, (float3)(0.0f))"


def c_declarations() -> list:
    """The ids, trait macros and random-normal modes (the generated layout header)."""
    modes = [f"#define RANDOM_NORMAL_{k.upper()} {v}" for k, v in RANDOM_NORMAL.items()]
    return MATERIALS.c_enum() + MATERIALS.c_traits() + modes


def device_source() -> str:
    """Every kind's BSDF file and the material_eval / material_sample dispatch."""
    kinds = [k.name for k in MATERIALS if k.device_file is not None]
    return "\n".join([
        MATERIALS.device_source(), '#line 1 "generated material dispatch"',
        MATERIALS.c_dispatch("eval", "inline float3", _MATERIAL_PARAMS + ", float3 l, float* pdf",
                             "mat, albedo, n, wo, l, pdf", _NO_BSDF, kinds),
        MATERIALS.c_dispatch("sample", "inline float3",
                             _MATERIAL_PARAMS + ", float2 u, float3* l, float* pdf",
                             "mat, albedo, n, wo, u, l, pdf", _NO_BSDF, kinds)])
