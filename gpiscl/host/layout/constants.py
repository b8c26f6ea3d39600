"""Every number the host and the device must agree on, written once: Python reads the
names below, the device gets them as #defines at the top of every program (c_defines,
through records.c_header). A header never restates one (tests/test_constants.py).

Floats are emitted as Python's repr, which a C compiler reads back to the same double.
Limits that depend on the scene (FS_MAX_ROWS, FS_SCRATCH_DOUBLES, FS_MAX_WINDOW,
FS_POST_MAX, WS_LANES) are not here: the host passes them as build options
(function_space_records.defines, render/integrator.ws_defines), and the headers stop
with #error without them.

Imports nothing from gpiscl: every layer may read it (tests/test_layering.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Const:
    """One #define: `ctype` "int", "uint" (hex when `hex`) or "double"."""

    name: str
    value: int | float
    doc: str
    ctype: str = "int"
    hex: bool = False

    def c_literal(self) -> str:
        if self.ctype == "double":
            return repr(float(self.value))
        text = f"0x{self.value:x}" if self.hex else str(self.value)
        return text + ("u" if self.ctype == "uint" else "")

    def c_define(self) -> str:
        return f"#define {self.name} {self.c_literal()}   /* {self.doc} */"


CONSTANTS: list = []


def _const(name, value, doc, ctype="int", hex=False):
    CONSTANTS.append(Const(name, value, doc, ctype, hex))
    return value


# --- GPIS posterior (compile/posterior.py) ----------------------------------------------

# a ray's solve vector lives in private memory (8 bytes a row)
WS_POST_MAX = _const("WS_POST_MAX", 512, "observation rows of a weight-space posterior")

# --- procedural bakes (knob_sdf.h, render/device_bakes.py) ------------------------------

KNOB_FUNCTIONS = {"knob": 0, "knob_inner": 1, "knob_outer": 2}
for _name, _id in KNOB_FUNCTIONS.items():
    _const(f"KNOB_FUNCTION_{_name.upper()}", _id, f"bake_procedural's function {_name}")

# --- occupancy cells (render/occupancy_boxes.py, gpis_proxy.h) ------------------------------

OCC_CELLS = _const("OCC_CELLS", 32, "occupancy lattice cells per axis over a proxy's bounds")
OCC_WORDS = _const("OCC_WORDS", OCC_CELLS ** 3 // 32, "uint words of one object's cell mask")

# --- function-space step rule (fs_march.h) ------------------------------------------------

FS_WINDOW = _const("FS_WINDOW", 16, "samples conditioned on besides the memory, by default")
FS_H_MAX = _const("FS_H_MAX", 2.0, "largest step, in l_d", "double")
FS_H_MIN = _const("FS_H_MIN", 1e-3, "smallest step, l_d: a floor for degenerate starts", "double")
FS_ELL_CORR = _const("FS_ELL_CORR", math.exp(-0.5),
                     "e^-1/2: SE's lag is exactly l / sqrt(d'Ad)", "double")
FS_RULE_SAMPLES = _const("FS_RULE_SAMPLES", 4, "the step rule conditions on the last 4-8 samples")
# The three-point Gauss-Radau rule on [0, 1] with its fixed node at 0 (where the rate is
# 0, so its weight 1/9 drops out): exact for degree 4, two evaluations per accepted try;
# the free node nearer the end first. The literals are
# the device's since the rule was written (NODE1 is one ulp from (6 - sqrt 6) / 10 as
# Python rounds it), kept so that images do not change.
FS_RULE_NODE0 = _const("FS_RULE_NODE0", 0.8449489742783178, "(6 + sqrt 6) / 10", "double")
FS_RULE_WEIGHT0 = _const("FS_RULE_WEIGHT0", 0.37640306270046727, "(16 - sqrt 6) / 36", "double")
FS_RULE_NODE1 = _const("FS_RULE_NODE1", 0.3550510257216822, "(6 - sqrt 6) / 10", "double")
FS_RULE_WEIGHT1 = _const("FS_RULE_WEIGHT1", 0.5124858261884216, "(16 + sqrt 6) / 36", "double")
FS_RULE = ((FS_RULE_NODE0, FS_RULE_WEIGHT0), (FS_RULE_NODE1, FS_RULE_WEIGHT1))

# Far from its zero set a flight's steps are the prior mean's: where |mean| >= FS_MEAN_Z sd
# a crossing needs a residual of that size (rate ~ e^(-Z^2 / 2) / l, far below any
# tolerance), so fs_mean_step sphere-traces the mean to that level (its far balls), and the
# occupancy marches hand function-space flights over near it (compile/gpis.py
# occupancy_step).
FS_MEAN_Z = _const("FS_MEAN_Z", 6.0, "the far zone's |mean|, prior sds", "double")
# Near its zero set the prior mean may move by at most FS_MEAN_KAPPA sd over a step: the
# rule sees it only at its nodes (paired renders chose 6: docs/design/function-space-march.md,
# "The mean cap").
FS_MEAN_KAPPA = _const("FS_MEAN_KAPPA", 6.0, "the mean cap's move near the zero set, prior sds",
                       "double")

# A stretch over which the prior mean's slope along the ray keeps one sign with
# |dm/dt| >= FS_MONO_R g (g the prior slope's sd along the ray) takes the growth ladder's
# step, not the mean cap's: its expected crossings missed are <= psi(r) / r with
# psi(r) = phi(r) - r Phi(-r), 1e-17 at 8 (2.6e-11 at 6 leaves room for rows shifting the
# slope's mean by 2 g). docs/design/grid-means.md, "The monotone stretch".
FS_MONO_R = _const("FS_MONO_R", 8.0, "the monotone stretch's slope, prior slope sds", "double")

# A trilinear grid mean's slope jumps at cell faces: a minimum of the mean near its zero
# set sits at a face, sharper than the rule's nodes see (a 0.05-voxel parabola 2 sd above
# 0 lost 18% of its hits). A try past the certified stretch ends at a face where the jump
# times the try's length is at least FS_MEAN_KINK prior sds (gp_mean_kink_reach): the
# bend is then at most ~0.4 sd; 3 missed it. docs/design/grid-means.md, "Kinks of a
# trilinear mean".
FS_MEAN_KINK = _const("FS_MEAN_KINK", 1.5, "a trilinear mean's slope jump that ends a try, "
                      "prior sds per try length", "double")
# A trilinear sigma grid's slope jumps at cell faces too, and f = mean + sigma e bends there
# by the jump times e: a dip to 0 and back at a face between the rule's nodes went unseen
# (sigma ramps of a few cells lost 2% of their hits). A try ends at a face where the jump
# of sigma's slope along the ray, times the try's length, is at least FS_FIELD_KINK times
# sigma at its start (fs_grid_field_reach): the bend stays below ~0.4 sd for |e| <= 3.
# 1 missed the ramp's kinks. docs/design/grid-means.md, "Sigma fields along the ray".
FS_FIELD_KINK = _const("FS_FIELD_KINK", 0.5, "a sigma grid's slope jump that ends a try, "
                       "start sigmas per try length", "double")

# --- function-space root search (fs_root_point) ----------------------------------------

FS_ROOT_WIDTH = _const("FS_ROOT_WIDTH", 1e-2, "final bracket, l_d", "double")
FS_ROOT_OFFSET = _const("FS_ROOT_OFFSET", 0.45,
                        "regula falsi's point moved toward the midpoint, root widths", "double")
FS_ROOT_SLACK = _const("FS_ROOT_SLACK", 2, "points allowed beyond bisection's worst case")


def root_budget(w0: float, width: float) -> int:
    """Points the root search may need from a bracket of width w0 (fs_root_budget)."""
    return max(math.ceil(math.log2(w0 / width)), 0) + FS_ROOT_SLACK


FS_MIN_BISECT = _const("FS_MIN_BISECT", root_budget(FS_H_MAX, FS_ROOT_WIDTH),
                       "rows reserved for the root search: its worst case from an FS_H_MAX step")

# --- function-space conditioning (fs_linalg.h) ----------------------------------------

FS_JITTER = _const("FS_JITTER", 1e-10, "relative nugget: K_ii (1 + FS_JITTER)", "double")

# --- heterogeneous medium counterpart (fs_classical.h) -----------------------------------

FS_CL_STRETCH = _const("FS_CL_STRETCH", 0.375, "a majorant stretch: the mean moves by at most "
                       "this many sigma over it", "double")
FS_CL_FAR = _const("FS_CL_FAR", 0.5, "a majorant stretch outside the zero level may also be as "
                   "long as the mean falls by this fraction of itself", "double")

# --- Philox streams ---------------------------------------------------------------------

# SHA-256 IV word 2 (rng.h's stream uses word 0)
WS_PHILOX_KEY1 = _const("WS_PHILOX_KEY1", 0x3C6EF372, "weight-space key word", "uint", hex=True)
FS_PHILOX_KEY = _const("FS_PHILOX_KEY", WS_PHILOX_KEY1, "function-space key word", "uint", hex=True)
WS_CALL_MAIN = _const("WS_CALL_MAIN", 0, "3 normals (frequency), w, tau", "uint")
WS_CALL_ORDERS = _const("WS_CALL_ORDERS", 1, "periodic orders and signs", "uint")
WS_CALL_GAMMA = _const("WS_CALL_GAMMA", 2, "first RQ gamma call; two trials per lane per call",
                       "uint")
WS_GAMMA_CALLS = _const("WS_GAMMA_CALLS", 24, "P(48 trials all rejected) < 0.05^48")
WS_CALL_NOISE = _const("WS_CALL_NOISE", WS_CALL_GAMMA + WS_GAMMA_CALLS,
                       "a posterior's noise, after the gamma calls", "uint")

# --- weight-space vector lanes (render/integrator.ws_defines) ---------------------------

WS_MAX_LANES = 16   # ws_features.h's widest vector type (float16)


def c_defines() -> str:
    lines = ["/* Generated from gpiscl/host/layout/constants.py: do not edit. */"]
    return "\n".join(lines + [c.c_define() for c in CONSTANTS]) + "\n"
