"""Device layouts of the function-space sampler (fs_linalg.h, fs_sampling.h).

FsObs is one Gaussian observation: a value f(x) or a directional derivative u . grad f(x),
each derivative with its own direction (the reference shared one direction, the Elephant
bug). Rows of a ray's conditioning system and the per-path ring of the `global` memory model
both hold FsObs.

FsVertex is the immutable record of a GPIS vertex (a hit). Every outgoing ray (the
continuation and each shadow ray) builds its conditioning set from it and from the path's
ring; nothing traced from a vertex writes to it, so shadow rays never change a path's
memory (the reference mutated the shared context in place).

Scratch: each work item owns a slice of a __global double buffer (PoCL's CPU device
crashes on private arrays of a few KiB at its automatic work-group sizes, see
fs_linalg.h). `scratch_doubles` sizes the slice.
"""
from __future__ import annotations

from . import constants as C
from .struct import Struct

FS_OBS = Struct("FsObs", (
    ("double", "px"), ("double", "py"), ("double", "pz"),
    ("double", "ux"), ("double", "uy"), ("double", "uz"),   # derivative direction (unit)
    ("double", "value"),
    ("int", "kind"),        # FS_OBS_VALUE or FS_OBS_DERIV
    ("int", "pad"),
))

FS_VERTEX = Struct("FsVertex", (
    ("float4", "pos"),       # xyz: the vertex (outgoing rays start here), w: f there (0)
    ("float4", "grad"),      # xyz: the sampled gradient of f at the vertex
    ("int", "valid"),        # 0: no memory (fresh entry from free space or a surface)
    ("int", "obs_end"),      # global model: observations ever appended to the path's ring
    ("int", "obs_count"),    # global model: how many of them the ring still holds
    ("int", "implied"),      # 1: grad is the gradient a shadow ray's normal implies, not
                             # the sampled one (fs_normal_pdf.h; shadow rays only)
))

OBS_KINDS = {"value": 0, "deriv": 1}
STATUS = {"ok": 0, "not_pd": 1, "nan": 2, "rows": 3, "steps": 4, "track_cap": 5,
          "majorant": 6}
STRUCTS = (FS_OBS, FS_VERTEX)

DEFAULT_WINDOW = C.FS_WINDOW   # samples conditioned on besides the memory (fs_march.h)
DEFAULT_MISS_TOLERANCE = 2e-6   # expected missed crossings per along-ray length scale: fs_march.h
DEFAULT_REFINE = 0        # root-search points forced in a crossing bracket besides those
                          # that narrow it to the root width (fs_march.h, "Hit")
DEFAULT_GLOBAL_CAP = 64   # observations the global model keeps
HIT_ROWS = 4              # f(x_h), d_d f, d_T f, d_B f appended at a hit
MIN_BISECT = C.FS_MIN_BISECT   # rows reserved for the root search
RULE_MEMORY = 4           # the step rule's own small system (fs_march.h): memory rows,
RULE_ROWS = RULE_MEMORY + 2 * C.FS_RULE_SAMPLES + 2   # its latest samples and one
                                                      # (value, slope) pair


def obs_declarations() -> str:
    """FsObs and its kinds: every program has them (records.c_header), as the scene's
    posterior observations are FsObs rows."""
    lines = [f"#define FS_OBS_{k.upper()} {v}" for k, v in OBS_KINDS.items()]
    return "\n".join(lines) + "\n" + FS_OBS.c_declaration()


def c_declarations() -> str:
    """#defines and structs fs_linalg.h / fs_sampling.h assume (the lead adds this to the
    generated header, or passes it as Program(extra_c=...))."""
    lines = ["/* Generated from gpiscl/host/layout/function_space_records.py: do not edit. */"]
    lines += [f"#define FS_STATUS_{k.upper()} {v}" for k, v in STATUS.items()]
    lines.append(f"#define FS_HIT_ROWS {HIT_ROWS}")
    lines.append(f"#define FS_RULE_MEMORY {RULE_MEMORY}")
    lines.append(f"#define FS_RULE_ROWS {RULE_ROWS}")
    # FsObs: every program's header has it (records.c_header: the posterior-row table)
    return "\n".join(lines) + "\n" + FS_VERTEX.c_declaration()


def max_rows(window: int, memory_cap: int, refine: int = DEFAULT_REFINE) -> int:
    """Rows of the largest system (fs_march.h): memory (<= max(cap, 2)), the window, the
    root search (at least MIN_BISECT: fs_march.h narrows every bracket) and the
    hit rows; the step rule's small system takes the last RULE_ROWS rows of the slice."""
    return max(memory_cap, 2) + window + max(refine, MIN_BISECT) + HIT_ROWS + RULE_ROWS


def scratch_doubles(rows: int, post_rows: int = 0) -> int:
    """Doubles per work item for `rows` rows: FsObs rows (8 doubles each), the packed
    lower triangle, the whitened vector e, the prior means, the rows' kernel-field
    multipliers (8 doubles each) and, for a posterior of `post_rows` observation rows,
    each row's cached solve against them (FsScratch in fs_sampling.h)."""
    return 8 * rows + rows * (rows + 1) // 2 + 2 * rows + 8 * rows + rows * post_rows


def defines(window_max: int, memory_cap: int, refine: int = DEFAULT_REFINE,
            post_rows: int = 0) -> dict:
    """-D options of a program that includes fs_sampling.h (post_rows: the largest
    posterior's observation rows, 0 without one)."""
    rows = max_rows(window_max, memory_cap, refine)
    return {"GP_REAL": "double", "FS_MAX_ROWS": rows, "FS_MAX_WINDOW": window_max,
            "FS_POST_MAX": post_rows, "FS_SCRATCH_DOUBLES": scratch_doubles(rows, post_rows)}
