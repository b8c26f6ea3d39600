"""The renderer's structs and SoA queues shared by host and device, and the C header
of every shared layout.

Each layout yields both a numpy dtype (host) and C text (device), so the two cannot
drift apart; tests/test_layouts.py checks the offsets on the device itself.
"""
from __future__ import annotations


from ..kinds import lights, materials
from . import constants, random_slots
from . import function_space_records, gp_records
from ..kinds.memory_models import MEMORY_MODELS
from .gp_records import c_declarations as gp_declarations
from .struct import Queue, Struct

# --- structs --------------------------------------------------------------------------

CAMERA = Struct("Camera", (
    ("float4", "position"),
    ("float4", "forward"),    # unit vector towards look_at
    ("float4", "right"),      # scaled by tan(fov/2) * aspect
    ("float4", "up"),         # scaled by tan(fov/2)
    ("int", "width"),
    ("int", "height"),
))

# Every surface primitive in one array so one BVH covers them all.
# sphere: p0 = (center, radius); rectangle: p0 = corner, p1 = edge u, p2 = edge v;
# disk: p0 = (center, radius), p1 = unit normal; triangle: p0, p1, p2 = vertices.
PRIMITIVE = Struct("Primitive", (
    ("float4", "p0"),
    ("float4", "p1"),
    ("float4", "p2"),
    ("int", "kind"),
    ("int", "material"),
    ("int", "light"),        # index into the light array if emissive, else -1
    ("int", "medium"),       # GPIS object enclosed by this proxy, else -1
))

MATERIAL = Struct("Material", (
    ("float4", "albedo"),
    ("float4", "eta"),       # conductors: complex index eta + i k (RGB)
    ("float4", "k"),
    ("int", "kind"),
    ("float", "roughness"),  # rough_conductor: Beckmann alpha
    ("int", "fresnel"),      # mirror: 1 reflects F of eta + i k, 0 the albedo alone
))

# Lights: the meaning of the vectors depends on kind (see lib/lights/<kind>.h).
LIGHT = Struct("Light", (
    ("float4", "radiance"),  # radiance, intensity (point) or in-cone radiance (sun)
    ("float4", "p0"),
    ("float4", "p1"),
    ("float4", "p2"),
    ("int", "kind"),
    ("int", "primitive"),    # area lights: the primitive that carries the emission
    ("float", "area"),
    ("float", "cos_max"),    # sun: cos of the angular radius (the device samples by p0.w = 1 - cos)
))

# Which light next-event estimation picks (compile/light_selection.py), one per light.
LIGHT_CHOICE = Struct("LightChoice", (
    ("float", "pmf"),        # probability of choosing this light
    ("float", "threshold"),  # alias table: keep this light when the fraction is below
    ("int", "alias"),        # alias table: the light chosen otherwise
    ("int", "pad"),
))

BVH_NODE = Struct("BvhNode", (
    ("float4", "lo"),
    ("float4", "hi"),
    ("int", "left_or_first"),  # inner: index of left child (right = left + 1); leaf: first prim
    ("int", "count"),          # 0 for inner nodes
))

# A GPIS object: a random field inside an analytic proxy (box or sphere). The proxy is
# clipped analytically by the GPIS stage, so it needs no primitive in the BVH.
GPIS_OBJECT = Struct("GpisObject", (
    ("float4", "proxy_p0"),    # box: min corner; sphere: (centre, radius)
    ("float4", "proxy_p1"),    # box: max corner
    ("int", "proxy_kind"),     # GPIS_PROXY_*
    ("int", "sampler"),        # GPIS_SAMPLER_*
    ("int", "mean_first"),     # its mean program: MeanNode records [first, first+count)
    ("int", "mean_count"),
    ("int", "features"),       # weight space: number of random Fourier features M
    ("int", "material"),       # micro-BSDF
    ("int", "memory"),         # function space: GPIS_MEMORY_*
    ("int", "window"),         # function space: samples conditioned on besides memory
    ("int", "order_first"),    # weight space: its periodic-order CDF in the order table
    ("int", "order_count"),
    ("float", "tolerance"),    # root refinement tolerance (world units)
    ("int", "memory_cap"),     # function space, global memory: observations kept
    ("int", "refine"),         # function space: root-search points forced in a crossing bracket
    ("float", "step_corr"),    # function space: > 0 the uniform baseline step (benchmarks)
    ("int", "color_field"),    # albedo multiplier: its record in the field table, 0 = none
    ("int", "emission_field"), # emitted radiance: the same (scene/colour_fields.py)
    ("float", "occupancy_level"),  # z sigma_max: mean above it = occupancy below the
                                   # object's epsilon (gpis_proxy.h); 0: bounds off
    ("float", "occupancy_step"),   # world length: the bound's marches stop below it
    ("int", "proxy_first"),    # mesh proxy: its face planes (float4 n, w: n.x <= w) in
    ("int", "proxy_count"),    # the proxy-plane table: the first and how many
    ("float", "miss_tolerance"),   # function space: expected missed crossings per l_d
    ("int", "general"),        # function space: 1 keeps the general conditional sampler
                               # where the Markov one applies (tests, benchmarks; no scene key)
    # a posterior (compile/posterior.py): its n observations in the posterior-row table
    # (FsObs) and, in the posterior-double table from posterior_doubles on, alpha (n), the
    # packed lower factor L (n(n+1)/2) and the noise deviations (n); n = 0: the prior
    ("int", "posterior_first"),
    ("int", "posterior_count"),
    ("int", "posterior_doubles"),
    # the occupancy box (render/occupancy_boxes.py): outside [occ_p0, occ_p1].xyz the
    # prior mean exceeds occupancy_level; occ_p0.w = 1 when set (0: no box, clip nothing)
    ("float4", "occ_p0"),
    ("float4", "occ_p1"),
))

# Per-launch constants of the integrator.
RENDER_PARAMS = Struct("RenderParams", (
    ("uint", "seed"),
    ("int", "max_depth"),
    ("int", "rr_start_depth"),
    ("float", "rr_max_survival"),
    ("int", "num_lights"),
    ("int", "env_light"),      # index of the environment map light, or -1
    ("int", "num_pixels"),
    ("int", "bounce"),         # wavefront iteration: one key of the random numbers
    ("int", "sample_base"),    # first sample index of this batch's first path
    ("int", "path_base"),      # first path id of this batch
    ("int", "num_paths"),      # paths in this batch
    ("int", "env_width"),
    ("int", "env_height"),
    ("int", "nee"),            # 1: next-event estimation with MIS; 0: BSDF sampling only
    ("int", "num_gpis"),
    ("int", "realization"),    # >= 0: every path uses this one GPIS realization
    ("int", "aov"),            # 1: record first hits (aov.py) and add them to the film
    ("int", "fs_nee"),         # 1: NEE at function-space hits may pick the normal
                               # (fs_normal_pdf.h); 0: only the sampled one, the mirror
                               # delta (the benchmarks' baseline, tools/bench_mirror_nee.py)
    ("float", "shadow_roulette"),  # > 0: the relative threshold of the roulette on shadow
                               # rays of light samples that pick the normal (fs_random_normal.h)
                               # and of manifold NEE samples (lib/caustics.h)
    ("int", "num_caustic_spheres"),  # classical mirror spheres that the manifold NEE
                               # reflects area lights off (lib/caustics.h); 0: none
))

# --- queues ---------------------------------------------------------------------------

PATH_STATE = Queue("path", (
    ("int", "pixel"),
    ("int", "sample"),
    ("float4", "beta"),       # throughput
    ("float4", "radiance"),   # radiance gathered so far
    ("float4", "prev_pos"),   # last scattering vertex, for emitter pdfs (w = bsdf pdf, 0 = delta)
    ("int", "prev_env_nee"),  # how that vertex's light sampling treats environments
                              # (ENV_NEE_*, lib/lights.h; set by scatter.cl)
    # a function-space rough conductor vertex (fs_normal_pdf.h, fs_conductor_light_pdf):
    ("float4", "prev_n"),     # its sampled normal n0, w = p_Omega(n0) (0: any other vertex)
    ("float4", "prev_v"),     # v = -(incoming direction), w = the Beckmann alpha
    ("int", "caustic"),       # CAUSTIC_* (CAUSTIC_STATES below; set by scatter.cl)
    ("int", "depth"),         # scattering events so far
    ("int", "medium"),        # GPIS object the ray travels in, or -1
    # the first scattering event, for AOVs (aov.py; written only when params.aov is set)
    ("float4", "aov_position"),  # world position; w = distance from the camera
    ("float4", "aov_normal"),    # unit normal facing the camera; w = 1 (a hit)
    ("float4", "aov_albedo"),    # albedo there
))

RAY_QUEUE = Queue("ray", (
    ("float4", "o"),          # w = tmin
    ("float4", "d"),          # w = tmax
    ("int", "path"),
    ("float", "hit_t"),
    ("int", "hit_prim"),      # >= 0 surface, -1 none, GPIS_HIT_BASE - k: GPIS object k
    ("float4", "hit_n"),      # GPIS hits: the sampled unit normal (outward)
    # function-space GPIS hits: the law the normal was drawn from (FsResult.law_*,
    # fs_normal_pdf.h): xyz the tangential mean law_m, w the slope law_s; law_a; law_b
    ("float4", "hit_law_m"),
    ("float4", "hit_law_a"),
    ("float4", "hit_law_b"),
))

INDEX_QUEUE = Queue("index", (
    ("int", "ray"),
))

SHADOW_QUEUE = Queue("shadow", (
    ("float4", "o"),
    ("float4", "d"),          # w = distance to the light sample
    ("float4", "contribution"),   # w: SHADOW_* (SHADOW_SEGMENTS below)
    ("int", "path"),
    # w = 1: xyz is the gradient the light sample's normal implies at a function-space
    # vertex (fs_normal_pdf.h), which the shadow ray conditions on instead of the sampled
    # one; w = 0: the vertex's own record
    ("float4", "grad"),
))

# --- enumerations shared with the device (emitted as #defines) ----------------------

PRIM_KINDS = {"sphere": 0, "rectangle": 1, "disk": 2, "triangle": 3}
# A shadow record's contribution.w (SHADOW_QUEUE): a segment of its own, or the two
# segments of one light path that a manifold NEE sample needs (x -> mirror -> light,
# lib/caustics.h), written as consecutive records: the head adds the contribution where
# neither record was blocked.
SHADOW_SEGMENTS = {"single": 0, "head": 1, "tail": -1}
# A path's `caustic` (PATH_STATE): none; the last vertex reflected area lights off the
# mirror spheres by manifold NEE; the path was then reflected by one of those spheres, so
# an area light it hits next was counted by that NEE already (emission.cl gives it 0).
CAUSTIC_STATES = {"none": 0, "vertex": 1, "reflected": 2}
# Device-side counters, int32. The host reads them after every bounce; the first four are
# the bounce's queue sizes, the rest counts of failures and work.
COUNTERS = {"rays_out": 0, "hits": 1, "escaped": 2, "shadow": 3, "nan_paths": 4,
            "killed": 5, "gpis_failed": 6, "depth_cut": 7,
            # function-space work: flights (one object along one ray), GP values drawn,
            # step-rule moment evaluations (fs_march.h)
            "fs_flights": 8, "fs_samples": 9, "fs_evals": 10}
# fs_march.h's profile (built with FS_PROFILE only, tools/profile_grid_scenes.py): whole
# render, int32
FS_PROFILE_COUNTERS = ("fs_steps", "fs_tries", "fs_cap_mean", "fs_cap_field", "fs_cap_hmax",
                       "fs_cap_grow", "fs_cap_end", "fs_hops", "fs_lip_scans", "fs_mean_evals",
                       "fs_near_steps", "fs_mono_scans", "fs_mono_steps", "fs_cert_steps",
                       "fs_var_walks", "fs_occ_entries", "fs_occ_marches", "fs_occ_evals")
COUNTERS.update({name: len(COUNTERS) + k for k, name in enumerate(FS_PROFILE_COUNTERS)})
NUM_COUNTERS = len(COUNTERS)
# Counters the host adds up into Python ints after each bounce and zeroes on the device, so
# they cannot wrap however long the render (GP values drawn pass 2^31 at ~512^2 x 256 spp).
BOUNCE_SUMMED = ("fs_flights", "fs_samples", "fs_evals")
GPIS_PROXIES = {"box": 0, "sphere": 1, "mesh": 2}
GPIS_SAMPLERS = {"weight_space": 0, "function_space": 1}
GPIS_MEMORIES = {name: MEMORY_MODELS.id(name) for name in MEMORY_MODELS.names}
GPIS_HIT_BASE = -2


def _defines() -> str:
    lines = []
    for prefix, table in (("PRIM", PRIM_KINDS), ("COUNT", COUNTERS),
                          ("SHADOW", SHADOW_SEGMENTS), ("CAUSTIC", CAUSTIC_STATES),
                          ("GPIS_PROXY", GPIS_PROXIES), ("GPIS_SAMPLER", GPIS_SAMPLERS)):
        lines += [f"#define {prefix}_{k.upper()} {v}" for k, v in table.items()]
    lines += [f"#define FS_PROF_{k[3:].upper()} {i}" for i, k in enumerate(FS_PROFILE_COUNTERS)]
    lines += [f"#define FS_PROF_COUNT {len(FS_PROFILE_COUNTERS)}"]
    lines += MEMORY_MODELS.c_enum() + MEMORY_MODELS.c_traits()
    # the kind tables' ids and traits, read at each call: a test's temporary kind shows
    lines += materials.c_declarations() + lights.c_declarations()
    lines.append(f"#define NUM_COUNTERS {NUM_COUNTERS}")
    lines.append(f"#define GPIS_HIT_BASE ({GPIS_HIT_BASE})")
    return "\n".join(lines) + "\n"


STRUCTS = (CAMERA, PRIMITIVE, MATERIAL, LIGHT, LIGHT_CHOICE, BVH_NODE, GPIS_OBJECT, RENDER_PARAMS)
# every struct host and device share (tests/test_layouts.py measures each on the device)
ALL_STRUCTS = STRUCTS + gp_records.STRUCTS + function_space_records.STRUCTS


def c_header() -> str:
    """The device-side declarations of every shared layout."""
    parts = ["/* Generated from gpiscl/host/layout/records.py: do not edit. */\n", _defines(),
             constants.c_defines(), random_slots.c_defines()]
    parts += [s.c_declaration() for s in STRUCTS]
    # the posterior-row table's type and its kinds, which every GPIS stage reads
    parts.append(function_space_records.obs_declarations())
    parts.append(gp_declarations())
    return "\n".join(parts)
