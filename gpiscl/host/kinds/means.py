"""Mean primitives and the CSG operations over them: the one declaration of each.

Means are signed distances, positive outside (gp/means.py, the host model). A primitive
names its scene fields, its host class with the scene-key -> argument map that builds it
(compile/gpis.py build_mean), the packer of its MeanNode parameters (layout/gp_records.py:
the leaf's centre, folded into its map, and p0, p1) and its device file
kernels_cl/lib/gp_means/<name>.h, which defines
    float <name>_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                      float3* g)
the value at local point y and its local gradient; gp_mean.h calls it through the
generated switch. Scene forms that compile into these (transform, mesh, grid and
procedural, which become a grid leaf) are declared in scene/gpis.py.

Leaf parameters (local coordinates, centre folded into the map) are listed in each
primitive's packer below; the grid leaf's layout is documented in layout/gp_records.py.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..gp import means as M
from ..schema import Field, Number, Record, Vector
from .table import KERNELS_CL, Kind, KindTable, device_text

VEC3 = Vector()
DIRECTION = Vector(normalize=True)
POSITIVE3 = Vector(broadcast=True, item=Number(gt=0))
_F32_MAX = float(np.finfo(np.float32).max)


@dataclass(frozen=True)
class MeanHost:
    """cls: the host class; args: scene key -> its argument; pack(node) -> (centre or
    None, p0, p1) of the device leaf (None: packed by layout, the grid)."""
    cls: type
    args: dict
    pack: Callable | None

    def build(self, m: dict) -> M.Mean:
        return self.cls(**{arg: tuple(m[key]) if isinstance(m[key], list) else m[key]
                           for key, arg in self.args.items()})


def _params(p0=(), p1=()):
    a, b = np.zeros(4), np.zeros(4)
    a[:len(p0)], b[:len(p1)] = p0, p1
    return a, b


def _pack_plane(node):
    # value max(scale (n.y - d), min): p0 = (d, scale, min), p1.xyz = unit normal
    n = np.asarray(node.normal, float) / np.linalg.norm(node.normal)
    return (None, *_params((np.dot(n, node.point), node.scale,
                            max(node.min_value, -_F32_MAX)), n))


def primitive(name: str, fields: dict, cls: type, args: dict, pack: Callable) -> Kind:
    return Kind(name, Record(fields), f"lib/gp_means/{name}.h", {}, MeanHost(cls, args, pack))


_C = {"center": Field(VEC3, [0, 0, 0])}
MEAN_PRIMITIVES = KindTable("mean primitive", "GP_MEAN", [
    primitive("constant", {"value": Field(Number(), 0.0)}, M.Constant, {"value": "offset"},
              lambda n: (None, *_params((n.offset,)))),   # p0.x = value
    primitive("plane", {"point": Field(VEC3, [0, 0, 0]), "normal": Field(DIRECTION, [0, 1, 0]),
                        "scale": Field(Number(gt=0), 1.0)},
              M.Plane, {"point": "point", "normal": "normal", "scale": "scale"}, _pack_plane),
    primitive("sphere", {**_C, "radius": Field(Number(gt=0), 1.0)},
              M.Sphere, {"center": "center", "radius": "radius"},
              lambda n: (n.center, *_params((n.radius,)))),   # p0.x = radius
    primitive("box", {**_C, "half_extents": Field(POSITIVE3, 1.0)},
              M.Box, {"half_extents": "half_extents", "center": "center"},
              lambda n: (n.center, *_params((), n.half_extents))),   # p1.xyz = half extents
    primitive("rounded_box", {**_C, "half_extents": Field(POSITIVE3, 1.0),
                              "radius": Field(Number(gt=0), 0.1)},
              M.RoundedBox, {"half_extents": "half_extents", "radius": "radius",
                             "center": "center"},
              lambda n: (n.center, *_params((n.radius,), n.half_extents))),
    primitive("torus", {**_C, "major": Field(Number(gt=0), 1.0),
                        "minor": Field(Number(gt=0), 0.25)},
              M.Torus, {"major": "major", "minor": "minor", "center": "center"},
              lambda n: (n.center, *_params((n.major, n.minor)))),
    primitive("capsule", {"a": Field(VEC3, [0, -0.5, 0]), "b": Field(VEC3, [0, 0.5, 0]),
                          "radius": Field(Number(gt=0), 0.25)},
              M.Capsule, {"a": "a", "b": "b", "radius": "radius"},   # p0 = (a, radius), p1 = b
              lambda n: (None, *_params((*n.a, n.radius), n.b))),
    # sampled means (scene forms mesh, grid, procedural): no scene record of its own
    Kind("grid", None, "lib/gp_means/grid.h", {}, MeanHost(M.GridMean, {}, None)),
], family="mean")

# Operations pop two (value, gradient) entries and push one; their ids follow the
# primitives' at GP_MEAN_FIRST_OP. k > 0: a smooth blend of width k.
MEAN_OPS = KindTable("mean operation", "GP_MEAN", [
    Kind(name, host=cls) for name, cls in
    (("union", M.Union), ("intersection", M.Intersection), ("difference", M.Difference))
], first_id=16, schema=MEAN_PRIMITIVES.schema)
for _op in MEAN_OPS:
    MEAN_PRIMITIVES.schema.register(_op.name, Record({
        "left": Field(MEAN_PRIMITIVES.schema), "right": Field(MEAN_PRIMITIVES.schema),
        "k": Field(Number(ge=0), 0.0)}))


def primitive_of(node: M.Mean) -> Kind:
    """The primitive whose host class node is (exactly: RoundedBox is no Box)."""
    for kind in MEAN_PRIMITIVES:
        if type(node) is kind.host.cls:
            return kind
    raise TypeError(f"no device form for mean {type(node).__name__}")


def op_of(node: M.Mean) -> Kind | None:
    for kind in MEAN_OPS:
        if type(node) is kind.host:
            return kind
    return None


def device_source(part: str = "leaves") -> str:
    """Every primitive's device file, then gp_mean_leaf_of, the switch over them: what
    replaces the `@kinds gp_means leaves` line of gp_mean.h."""
    out = []
    for kind in MEAN_PRIMITIVES:
        out.append(f'#line 1 "{kind.device_file}"')
        out.append(device_text(KERNELS_CL / kind.device_file))
    out.append(MEAN_PRIMITIVES.c_dispatch(
        "mean", "float", "GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1, "
        "float3* g", "n, y, p0, p1, g", "NAN", name="gp_mean_leaf_of"))
    return "\n".join(out) + "\n"
