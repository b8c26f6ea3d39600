"""Every kernel's parameters, declared once: the C parameter list (`#define SCATTER_PARAMS
...`, so a kernel reads `__kernel void scatter(SCATTER_PARAMS)`) and the order and checks of
the host's launch (render/launch.py) both come from the Stage table below.

A Param is one kernel argument; a Group is several that one host object hands over together
(a queue's buffers, the film, the kriging cache): the kernel names them prefix_field and the
host passes prefix=<mapping of field to value>.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .records import INDEX_QUEUE, PATH_STATE, RAY_QUEUE, SHADOW_QUEUE
from .struct import Queue

# the scalar C types a kernel may take, and the numpy scalar the host must pass for each
SCALAR_DTYPES = {"int": np.int32, "uint": np.uint32, "float": np.float32,
                 "double": np.float64}
_QUALIFIERS = ("__global", "__constant", "const", "restrict")


@dataclass(frozen=True)
class Param:
    """One kernel argument: a scalar ("int") or a buffer ("__global const float4*")."""

    name: str
    ctype: str

    @cached_property
    def is_buffer(self) -> bool:
        return "*" in self.ctype

    @cached_property
    def dtype(self) -> np.dtype:
        """The numpy dtype a scalar argument must have."""
        return np.dtype(SCALAR_DTYPES[self.ctype])

    @property
    def type_name(self) -> str:
        """The type without address space and qualifiers, as the device reports it."""
        return "".join(w for w in self.ctype.replace("*", " * ").split()
                       if w not in _QUALIFIERS)


@dataclass(frozen=True)
class Group:
    """Parameters that one host object hands over together, named prefix_field."""

    prefix: str
    params: tuple
    queue: Queue | None = None    # the layout whose buffers these are, if a queue's


def queue(prefix: str, layout: Queue) -> Group:
    """A structure-of-arrays queue's buffers (render/queues.py), in its field order."""
    return Group(prefix, tuple(Param(f, f"__global {c}* restrict") for c, f in layout.fields),
                 layout)


@dataclass(frozen=True)
class Stage:
    """A kernel: its name (= its .cl file, host method and timing label) and parameters."""

    name: str
    params: tuple     # Param or Group, in the kernel's order

    @cached_property
    def flat(self) -> tuple:
        """(host name, group field or None, Param, C name) per kernel argument, in order:
        a group member's C name is prefix_field."""
        out = []
        for p in self.params:
            if isinstance(p, Group):
                out += [(p.prefix, q.name, q, f"{p.prefix}_{q.name}") for q in p.params]
            else:
                out.append((p.name, None, p, p.name))
        return tuple(out)

    @property
    def c_names(self) -> list:
        return [c_name for *_, c_name in self.flat]

    @cached_property
    def host_names(self) -> frozenset:
        """The keywords a launch takes: parameter names and group prefixes."""
        return frozenset(p.prefix if isinstance(p, Group) else p.name for p in self.params)

    def c_macro(self) -> str:
        decls = [f"{p.ctype} {c_name}" for _, _, p, c_name in self.flat]
        return f"#define {self.name.upper()}_PARAMS \\\n    " + ", \\\n    ".join(decls) + "\n"


# --- what several stages share ---------------------------------------------------------

PARAMS = Param("params", "__constant RenderParams*")
COUNTERS = Param("counters", "__global int*")
NUM_RAYS = Param("num_rays", "int")       # rays in the input queue (the launch pads past it)
CAMERA = Param("camera", "__constant Camera*")
NODES = Param("nodes", "__global const BvhNode*")
PRIMS = Param("prims", "__global const Primitive*")
MATERIALS = Param("materials", "__global const Material*")
LIGHTS = Param("lights", "__global const Light*")
LIGHT_CHOICE = Param("light_choice", "__global const LightChoice*")   # compile/light_selection.py
# the primitives the manifold NEE reflects area lights off (compile/scene.py, lib/caustics.h)
CAUSTIC_SPHERES = Param("caustic_spheres", "__global const int*")
ENV_MAP = (Param("env_texels", "__global const float4*"),
           Param("env_marginal", "__global const float*"),
           Param("env_conditional", "__global const float*"))
GPIS = Param("gpis", "__global const GpisObject*")
KERNELS = Param("kernels", "__global const GpKernel*")
MEAN_NODES = Param("mean_nodes", "__global const MeanNode*")
ORDER_TABLE = Param("order_table", "__global const float*")
# The GPIS objects' side tables (GpisObject says where each object's part starts): mesh
# proxies' face planes, posteriors' observations and their solve (compile/gpis.py)
GPIS_TABLES = (Param("proxy_planes", "__global const float4*"),
               Param("posterior_obs", "__global const FsObs*"),
               Param("posterior_doubles", "__global const double*"),
               # per object OCC_WORDS bits: its occupancy cells (render/occupancy_boxes.py)
               Param("occupancy_cells", "__global const uint*"))
# Colour and emission fields, which GpisObject's color_field / emission_field index (0: none)
FIELD_NODES = Param("field_nodes", "__global const MeanNode*")
# The batch's kept weight-space posterior weights (render/kriging_cache.py, ws_objects.h)
WS_POST_CACHE = Group("post", (Param("tags", "__global uint4*"),
                               Param("values", "__global double*"),
                               Param("table", "__global const int2*"),
                               Param("tags_per_path", "int"),
                               Param("doubles_per_path", "int")))
# Per-pixel sums in double (render/film.py)
FILM = Group("film", tuple(Param(f, "__global double*")
                           for f in ("sum", "sum_sq", "count", "aov")))


def _fs_work(const: str) -> tuple:
    """The function-space stages' path-indexed vertex records and rings, and scratch
    (render/function_space_stages.py); the shadow stage only reads the records."""
    return (Param("vertex", f"__global {const}FsVertex*"),
            Param("vertex_object", f"__global {const}int*"),
            Param("rings", f"__global {const}FsObs*"), Param("ring_stride", "int"),
            Param("scratch", "__global double*"))


# --- the stages, in the order a bounce runs them ---------------------------------------

GENERATE_CAMERA_RAYS = Stage("generate_camera_rays", (
    PARAMS, CAMERA, queue("path", PATH_STATE), queue("out", RAY_QUEUE)))
INTERSECT = Stage("intersect", (
    PARAMS, NUM_RAYS, queue("in", RAY_QUEUE), NODES, PRIMS, MATERIALS))
GPIS_WEIGHT_SPACE = Stage("gpis_weight_space", (
    PARAMS, NUM_RAYS, queue("path", PATH_STATE), queue("in", RAY_QUEUE), GPIS, KERNELS,
    MEAN_NODES, *GPIS_TABLES, ORDER_TABLE, COUNTERS, WS_POST_CACHE))
GPIS_FUNCTION_SPACE = Stage("gpis_function_space", (
    PARAMS, NUM_RAYS, queue("path", PATH_STATE), queue("in", RAY_QUEUE), GPIS, KERNELS,
    MEAN_NODES, *GPIS_TABLES, *_fs_work(""), COUNTERS))
QUEUE_HITS = Stage("queue_hits", (
    NUM_RAYS, queue("in", RAY_QUEUE), queue("hits", INDEX_QUEUE),
    queue("escaped", INDEX_QUEUE), COUNTERS))
ESCAPED_RAYS = Stage("escaped_rays", (
    PARAMS, queue("path", PATH_STATE), queue("in", RAY_QUEUE), queue("escaped", INDEX_QUEUE),
    COUNTERS, LIGHTS, *ENV_MAP, LIGHT_CHOICE))
EMISSION = Stage("emission", (
    PARAMS, queue("path", PATH_STATE), queue("in", RAY_QUEUE), queue("hits", INDEX_QUEUE),
    COUNTERS, PRIMS, LIGHTS, GPIS, FIELD_NODES, LIGHT_CHOICE))
SCATTER = Stage("scatter", (
    PARAMS, queue("path", PATH_STATE), queue("in", RAY_QUEUE), queue("out", RAY_QUEUE),
    queue("hits", INDEX_QUEUE), queue("shadow", SHADOW_QUEUE), COUNTERS, PRIMS, MATERIALS,
    LIGHTS, *ENV_MAP, GPIS, FIELD_NODES, LIGHT_CHOICE, CAUSTIC_SPHERES))
GPIS_SHADOW_WEIGHT_SPACE = Stage("gpis_shadow_weight_space", (
    PARAMS, queue("path", PATH_STATE), queue("shadow", SHADOW_QUEUE), GPIS, KERNELS,
    MEAN_NODES, *GPIS_TABLES, ORDER_TABLE, COUNTERS, WS_POST_CACHE))
GPIS_SHADOW_FUNCTION_SPACE = Stage("gpis_shadow_function_space", (
    PARAMS, NUM_RAYS, queue("path", PATH_STATE), queue("shadow", SHADOW_QUEUE), GPIS,
    KERNELS, MEAN_NODES, *GPIS_TABLES, *_fs_work("const "), COUNTERS))
SHADOW_RAYS = Stage("shadow_rays", (
    PARAMS, queue("path", PATH_STATE), queue("shadow", SHADOW_QUEUE), COUNTERS, NODES,
    PRIMS, MATERIALS))
ACCUMULATE = Stage("accumulate", (PARAMS, queue("path", PATH_STATE), COUNTERS, FILM))
# Render preparation (render/occupancy_boxes.py): per object, the cells of a lattice over
# its proxy where the mean may reach its occupancy level, as a bit mask (OCC_WORDS uints)
# and index ranges (int8: s012 the lowest, s345 the highest)
GPIS_OCCUPANCY_BOXES = Stage("gpis_occupancy_boxes", (
    GPIS, MEAN_NODES, Param("num_gpis", "int"), Param("boxes", "__global int8*"),
    Param("cells", "__global uint*")))

# Scene preparation (render/device_bakes.py): grid sizes and the sample axes or samples
_GRID = tuple(Param(n, "int") for n in ("nx", "ny", "nz"))
BAKE_PROCEDURAL = Stage("bake_procedural", (
    Param("which", "int"), *_GRID,
    *(Param(a, "__global const double*") for a in ("ax", "ay", "az")),
    Param("values", "__global float*")))
BAKE_GRID_SLOPES = Stage("bake_grid_slopes", (
    *_GRID, Param("brick", "int"), Param("v", "__global const double*"),
    Param("brick_c2", "__global double*")))

STAGES = (GENERATE_CAMERA_RAYS, INTERSECT, GPIS_WEIGHT_SPACE, GPIS_FUNCTION_SPACE, QUEUE_HITS,
          ESCAPED_RAYS, EMISSION, SCATTER, GPIS_SHADOW_WEIGHT_SPACE, GPIS_SHADOW_FUNCTION_SPACE,
          SHADOW_RAYS, ACCUMULATE, GPIS_OCCUPANCY_BOXES, BAKE_PROCEDURAL, BAKE_GRID_SLOPES)


def c_declarations() -> str:
    """The parameter-list macro of every stage."""
    return "".join(s.c_macro() for s in STAGES)
