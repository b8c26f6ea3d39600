"""Many free flights of one GPIS along one ray, drawn by the renderer's own function-space
sampler (fs_free_flight and fs_vertex_at_hit of kernels_cl/lib): the data of the GPIS
density (docs/design/classical-limits.md). After each hit the path scatters off a
Lambertian facet (cosine-weighted about the sampled normal; or reflects as a mirror) and
flies again from the vertex, so the second and later flights show what each memory model
remembers. The "memory" classical_medium runs the medium counterpart's flight
(fs_classical.h) instead. A scene object's flights are clipped to its proxy, as the
renderer's are (pack_scene_object)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ..compile.gpis import compile_gpis
from ..gp.kernels import Kernel
from ..gp.means import Mean
from ..layout import function_space_records as FL
from ..layout import gp_records
from ..layout.records import GPIS_MEMORIES, GPIS_OBJECT, GPIS_PROXIES
from .device import Device, build_quietly
from .program_sources import fs_sampler_options, fs_sampler_source, kernel_source

WINDOW_MAX, CAP_MAX = 32, 128
PER_FLIGHT = 5          # t (-1: no hit), grad x, y, z, solver status

# The scatter directions come from Philox stream 1; the sampler's own draws use stream 0.
_WRAPPER = r"""
__kernel void theory_flights(__global const GpKernel* kp, __global const MeanNode* mean,
                             int mc, int window, int memory, int cap, int refine, double tol,
                             __global const double* ray, uint seed, int first, int bounces,
                             int mirror, int clip, __global const GpisObject* obj,
                             __global const float4* planes,
                             __global double* scratch, __global FsObs* rings,
                             __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    FsParams prm = {window, memory, cap, refine, 0.0, tol};
    FsRay r = {vload3(0, ray), vload3(1, ray), ray[6], ray[7]};
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    FsRng turn = {seed, (uint)(first + i), 0u, 0u, 1u};
    FsVertex v = {0};
    __global double* o = out + (size_t)5 * bounces * i;
    for (int b = 0; b < bounces; ++b) {
        o[5 * b] = -1.0; o[5 * b + 1] = o[5 * b + 2] = o[5 * b + 3] = o[5 * b + 4] = 0.0;
    }
    for (int b = 0; b < bounces; ++b) {
        rng.bounce = turn.bounce = (uint)b;
        if (clip) {     /* the renderer's clip (gpis_proxy.h), before any flight */
            float t0 = (float)r.t0, t1 = (float)r.t1;
            if (!gpis_proxy_clip(obj, planes, convert_float3(r.o), convert_float3(r.d),
                                 &t0, &t1)) break;
            if (t0 > (float)r.t0) r.t0 = t0;
            if (t1 < (float)r.t1) r.t1 = t1;
        }
        FsResult res = GPIS_MEMORY_IS_EXPONENTIAL(memory)
            ? fs_classical_flight(kp[0], mean, mc, r, rng)
            : fs_free_flight(kp[0], mean, mc, prm, r, v, rings + (size_t)i * cap, rng, S);
        if (res.status) { o[5 * b + 4] = res.status; break; }
        if (!res.hit) break;
        o[5 * b] = res.t;
        vstore3(res.grad, 0, o + 5 * b + 1);
        v = fs_vertex_at_hit(prm, r, res, v, rings + (size_t)i * cap, S);
        double3 n = normalize(res.grad), t, bt;
        fs_frame(n, &t, &bt);
        double2 u = fs_uniform2(turn, 0u, 0u);
        double rad = sqrt(u.x), phi = 2.0 * M_PI * u.y;
        r.o = r.o + res.t * r.d;
        r.d = mirror ? r.d - 2.0 * dot(r.d, n) * n
                     : rad * cos(phi) * t + rad * sin(phi) * bt + sqrt(fmax(0.0, 1.0 - u.x)) * n;
        r.t0 = 0.0;
        r.t1 = ray[8];
    }
}
"""


_BUILT: dict = {}      # by context: one (slow) build per process


def _kernel(device: Device):
    if device.ctx not in _BUILT:
        source = fs_sampler_source(f'#line 1 "fs_classical.h"\n{kernel_source("fs_classical.h")}'
                                   f'\n#line 1 "gpis_proxy.h"\n{kernel_source("gpis_proxy.h")}'
                                   f'\n#line 1 "flight_samples.py"\n{_WRAPPER}')
        _BUILT[device.ctx] = build_quietly(device, source,
                                           fs_sampler_options(WINDOW_MAX, CAP_MAX)).theory_flights
    return _BUILT[device.ctx]


def _buf(device, a):
    return cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(a))


@dataclass
class PackedGpis:
    """What the device reads of one GPIS object, as the renderer lays it out."""
    kernel: np.ndarray      # its GpKernel record (1,)
    nodes: np.ndarray       # MeanNode records: the mean program, then the kernel's grid
                            # fields at the record's sigma_grid / ls_grid offsets
    mean_count: int         # records of the mean program
    obj: np.ndarray | None = None   # its GpisObject record (1,): flights are clipped to
    planes: np.ndarray | None = None    # its proxy (gpis_proxy_clip; a mesh proxy's
                                        # face planes), None: not clipped

    def interval(self, origin, direction, length: float) -> tuple:
        """(t0, t1) of origin + t direction (unit), t in [0, length], that the wrapper's
        clip keeps (t0 >= t1: none): gpis_proxy_clip's arithmetic in double, for the
        counterpart's closed-form law over the same stretch."""
        o, d = np.asarray(origin, float), np.asarray(direction, float)
        t0, t1 = 0.0, float(length)
        if self.obj is None:
            return t0, t1
        g = self.obj[0]
        p0, p1 = np.asarray(g["proxy_p0"], float), np.asarray(g["proxy_p1"], float)
        if g["proxy_kind"] == GPIS_PROXIES["sphere"]:
            oc = o - p0[:3]
            b, c = float(oc @ d), float(oc @ oc) - p0[3] ** 2
            disc = b * b - c
            if disc < 0.0:
                return 0.0, 0.0
            return max(t0, -b - disc ** 0.5), min(t1, -b + disc ** 0.5)
        if g["proxy_kind"] == GPIS_PROXIES["mesh"]:
            planes = np.asarray(self.planes, float)[g["proxy_first"]:][:g["proxy_count"]]
            dn, gap = planes[:, :3] @ d, planes[:, 3] - planes[:, :3] @ o
            if np.any((dn == 0.0) & (gap < 0.0)):
                return 0.0, 0.0
            with np.errstate(divide="ignore", invalid="ignore"):
                hit = gap / dn
            return (max(t0, *hit[dn < 0.0]) if np.any(dn < 0.0) else t0,
                    min(t1, *hit[dn > 0.0]) if np.any(dn > 0.0) else t1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (p0[:3] - o) / d, (p1[:3] - o) / d
        # nan: along a face (0 / 0), which the slab does not limit (as fmin on the device)
        return (float(np.nanmax([t0, *np.fmin(ta, tb)])),
                float(np.nanmin([t1, *np.fmax(ta, tb)])))


def pack_scene_object(shape: dict, source: str, key: str) -> PackedGpis:
    """The records the renderer compiles for a resolved "gpis" shape (compile_gpis on that
    shape alone): the kernel built with its proxy (a linear l field's step), grid means'
    payloads and the kernel's grid fields. source and key name it in compile errors.
    Flights are clipped to the proxy by the renderer's gpis_proxy_clip. Observations are
    left out (the flights are the prior's), and so is the proxy-cut warning (the flights
    ask for no image)."""
    shape = dict(shape, clip=True, observations=None)
    c = compile_gpis([shape], lambda bsdf: 0, source, [key])
    return PackedGpis(c.kernels[:1], c.mean_nodes, int(c.objects[0]["mean_count"]),
                      c.objects[:1], c.proxy_planes)


def pack_model(kernel: Kernel, mean: Mean) -> PackedGpis:
    """pack_scene_object's records for host kernel and mean objects: compile_object's own
    steps (the mean program, then the kernel's grid fields after it)."""
    record = gp_records.pack_kernel(kernel)
    parts = gp_records.pack_mean_parts(mean)
    count = sum(len(p) for p in parts)
    parts += gp_records.pack_kernel_grids(kernel, record, count)
    return PackedGpis(record, np.concatenate(parts), count)


def flights(device: Device, kernel, mean, origin, direction, length: float, n: int,
            memory: str = "renewal", bounces: int = 2, seed: int = 1, cap: int = 64,
            refine: int = 0, tol: float = FL.DEFAULT_MISS_TOLERANCE,
            later_length: float | None = None, mirror: bool = False,
            packed: PackedGpis | None = None) -> np.ndarray:
    """(n, bounces, 5): per path and flight the hit distance (-1: none, and every later
    flight -1), the sampled gradient at the hit and the solver status (0: fine). The
    first flight runs along origin + t direction, t in [0, length]; later ones are
    later_length (default: length) long from the previous hit. mirror: each hit reflects
    the ray about its sampled normal instead of the Lambertian turn. packed: the object's
    records and proxy (pack_scene_object); None packs kernel and mean (pack_model) and
    clips nothing."""
    if memory not in GPIS_MEMORIES:
        raise ValueError(f"memory must be one of {sorted(GPIS_MEMORIES)}, got {memory!r}")
    if not 1 <= cap <= CAP_MAX:
        raise ValueError(f"cap must be in [1, {CAP_MAX}], got {cap}")
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    q = device.queue
    later = float(length if later_length is None else later_length)
    ray = _buf(device, np.array([*np.asarray(origin, float), *d, 0.0, float(length), later]))
    packed = packed or pack_model(kernel, mean)
    kp, mb = _buf(device, packed.kernel), _buf(device, packed.nodes)
    clip = packed.obj is not None
    obj = _buf(device, packed.obj if clip else GPIS_OBJECT.zeros(1))
    planes = packed.planes if clip and len(packed.planes) else np.zeros((1, 4), np.float32)
    planes = _buf(device, planes)
    stride = FL.scratch_doubles(FL.max_rows(WINDOW_MAX, CAP_MAX))
    chunk = max(1, min(n, (256 << 20) // (8 * stride)))
    scratch = cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE, 8 * stride * chunk)
    rings = cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE,
                      FL.FS_OBS.dtype.itemsize * cap * chunk)
    run = _kernel(device)
    out = np.zeros((n, bounces, PER_FLIGHT))
    for first in range(0, n, chunk):
        m = min(chunk, n - first)
        ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * PER_FLIGHT * bounces * m)
        run(q, (m,), None, kp, mb, np.int32(packed.mean_count), np.int32(0),
            np.int32(GPIS_MEMORIES[memory]), np.int32(cap), np.int32(refine),
            np.float64(tol), ray, np.uint32(seed), np.int32(first), np.int32(bounces),
            np.int32(mirror), np.int32(clip), obj, planes, scratch, rings, ob)
        cl.enqueue_copy(q, out[first:first + m], ob)
    return out
