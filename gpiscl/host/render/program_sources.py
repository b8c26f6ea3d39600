"""Which device sources make each program, in the one fixed order they are joined.

gpiscl/kernels_cl/lib/ holds the shared device library (.h), gpiscl/kernels_cl/stages/
one .cl per wavefront stage (file, kernel, host method and timing label share a name).
Sources are concatenated, not #included: the generated layout header and every stage's
parameter list (layout/stages.py) come first, then the library in the order below (each
header uses only those before it), then stages.
"""
from __future__ import annotations

import re
from pathlib import Path

import pyopencl as cl

from ..kinds import gp_kernels, lights, materials, means
from ..kinds.table import device_text
from ..layout import records, stages
from ..layout.function_space_records import c_declarations, defines

KERNEL_DIR = Path(__file__).resolve().parent.parent.parent / "kernels_cl"
PYOPENCL_CL_DIR = Path(cl.__file__).resolve().parent / "cl"

# The library every program starts with. A kind table stands for its kinds' device files
# and generated dispatch (host/kinds/), joined at build time: a test's own kind shows.
SHARED_HEADERS = ("compat.h", "rng.h", "geometry.h", "bvh.h", "lights.h", lights,
                  materials, "caustics.h", "gp_kernel.h", "gp_mean.h")
# The path tracer's stages, and the weight-space GPIS library they need.
STAGE_FILES = ("generate_camera_rays.cl", "intersect.cl", "gpis_weight_space.cl",
               "queue_hits.cl", "escaped_rays.cl", "emission.cl", "scatter.cl",
               "gpis_shadow_weight_space.cl", "shadow_rays.cl", "accumulate.cl",
               "gpis_occupancy_boxes.cl")
GPIS_HEADERS = ("gpis_proxy.h", "ws_features.h", "ws_posterior.h", "ws_intersect.h",
                "ws_objects.h", "gpis_fields.h", "fs_normal_pdf.h", "fs_random_normal.h")
# The function-space stages (a second program, built only for scenes that use them).
FS_STAGE_FILES = ("gpis_function_space.cl", "gpis_shadow_function_space.cl")
FS_HEADERS = ("gpis_proxy.h", "fs_linalg.h", "fs_sampling.h", "fs_memory.h", "fs_march.h",
              "fs_markov.h", "fs_posterior.h", "fs_classical.h", "fs_objects.h")
# Scene preparation on the device (device_bakes.py: built only when a bake is not cached).
BAKE_FILES = ("bake_procedural.cl", "bake_grid_slopes.cl")
BAKE_HEADERS = ("knob_sdf.h",)
# The function-space sampler alone, for tests and benchmarks.
FS_SAMPLER_HEADERS = ("compat.h", "rng.h", "gp_kernel.h", "gp_mean.h", "fs_linalg.h",
                      "fs_sampling.h", "fs_memory.h", "fs_march.h", "fs_markov.h")


# `/* @kinds <axis> <part> */` lines in a header stand for that part of every kind's
# device file and the dispatch generated over them (host/kinds/).
KIND_PARTS = {"gp_kernels": gp_kernels.device_source, "gp_means": means.device_source}
_KIND_LINE = re.compile(r"^/\* @kinds (\w+) (\w+) \*/$", re.M)


def kernel_source(name: str) -> str:
    """The text of one device source file: lib/ for headers, stages/ for stages, with
    its kinds' device code joined in (the kinds' tables may change between calls: a
    test's own kind)."""
    text = device_text(KERNEL_DIR / ("lib" if name.endswith(".h") else "stages") / name)
    if "@kinds" not in text:
        return text

    def expand(m):
        line = text.count("\n", 0, m.end()) + 2   # of the line after the marker
        return f'{KIND_PARTS[m[1]](m[2])}#line {line} "{name}"'
    return _KIND_LINE.sub(expand, text)


def _marked(name) -> str:
    # #line markers keep compiler messages pointing at the real files
    if not isinstance(name, str):  # a kind module (host/kinds/)
        return name.device_source()
    return f'#line 1 "{name}"\n{kernel_source(name)}'


def join_sources(stage_files, extra_headers=(), extra_c="") -> str:
    """The whole program text: generated layouts and parameter lists, shared headers, then
    stages."""
    parts = [records.c_header(), stages.c_declarations(), extra_c]
    parts += [_marked(name) for name in (*SHARED_HEADERS, *extra_headers, *stage_files)]
    return "\n".join(parts)


def fs_sampler_source(wrappers: str = "") -> str:
    """Stand-alone source of the function-space sampler plus `wrappers` (tests and
    benchmarks; the renderer builds FS_STAGE_FILES through render.device.Program)."""
    parts = [records.c_header(), c_declarations()]
    parts += [_marked(h) for h in FS_SAMPLER_HEADERS]
    return "\n".join(parts) + '\n#line 1 "wrappers"\n' + wrappers


def fs_sampler_options(window_max: int, memory_cap: int, refine: int | None = None) -> list:
    """Build options of fs_sampler_source."""
    d = defines(window_max, memory_cap) if refine is None else \
        defines(window_max, memory_cap, refine)
    return [f"-I{PYOPENCL_CL_DIR}"] + [f"-D{k}={v}" for k, v in sorted(d.items())]
