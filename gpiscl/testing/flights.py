"""The function-space sampler's free flight as a test harness: wrapper kernels that run
fs_free_flight along one line (first hits, restarts through the vertex record, crossing
counts) and `flights`, which launches them in chunks and returns one row per ray."""
import numpy as np
import pyopencl as cl

from gpiscl.host.compile.gpis import sampler_window
from gpiscl.host.gp import Constant
from gpiscl.host.layout import function_space_records as FL
from gpiscl.host.layout.records import GPIS_MEMORIES
from gpiscl.host.render.flight_samples import pack_model
from gpiscl.host.render.program_sources import fs_sampler_options

from .wrappers import buffer, sampler_program

FLIGHT_WRAPPERS = r"""
__kernel void tn_draw(double mu, double s, uint seed, __global double* out)
{
    int i = get_global_id(0);
    FsRng rng = {seed, (uint)i, 0u, 0u, 0u};
    out[i] = fs_truncnorm_pos(mu, s, rng, 0u, FS_U_START);
}

/* the step of the ray segment o + t d, t in [0, 1] (ray: o then d) */
__kernel void step_rule(__global const GpKernel* kp, __global const double* ray, double c,
                   __global double* out)
{
    FsRay r = {vload3(0, ray), vload3(1, ray), 0.0, 1.0};
    out[0] = fs_step(kp[0], r, c);
}

/* Rays along one line, one per item; after a hit the ray goes straight on from the hit
 * (a continuation with the vertex record) up to `restarts` times. */
__kernel void flight(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                     int window, int memory, int cap, int refine, double c, double tol,
                     __global const double* ray, uint seed, int first, int restarts,
                     __global double* scratch, __global FsObs* rings, __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    FsParams prm = {window, memory, cap, refine, c, tol};
    FsRay r = {vload3(0, ray), vload3(1, ray), ray[6], ray[7]};
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    FsVertex v = {0};
    __global double* o = out + 8 * i;
    o[0] = -1.0; o[1] = o[2] = o[3] = 0.0; o[4] = 0.0; o[5] = 0.0; o[6] = 0.0; o[7] = 0.0;
    for (int b = 0; b <= restarts; ++b) {
        rng.bounce = (uint)b;
        FsResult res = fs_free_flight(kp[0], mean, mc, prm, r, v, rings + (size_t)i * cap,
                                      rng, S);
        o[7] += res.samples;
        if (res.status) { o[5] = res.status; break; }
        if (!res.hit) break;
        if (b == 0) { o[0] = res.t; vstore3(res.grad, 0, o + 1); o[6] = res.samples; }
        o[4] += 1.0;
        v = fs_vertex_at_hit(prm, r, res, v, rings + (size_t)i * cap, S);
        r.o = r.o + res.t * r.d;
        r.t1 -= res.t;
        r.t0 = 0.0;
    }
}

/* The slope at a down-crossing (fs_march.h), one draw per item. */
__kernel void slope_draw(double mean, double sd, uint seed, __global double* out)
{
    int i = get_global_id(0);
    FsRng rng = {seed, (uint)i, 0u, 0u, 0u};
    out[i] = fs_downcrossing_slope(mean, sd, fs_uniform2(rng, 0u, FS_U_SLOPE));
}

/* A ray going straight on through every hit (continuations from the vertex record) over
 * [0, ray[7]]: per item hits, the sums of the along-ray slope and its square over hits
 * after the first (far from the start condition), GP samples, moment evaluations and
 * the status. */
__kernel void crossings(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                        int window, int memory, int cap, int refine, double c, double tol,
                        __global const double* ray, uint seed, int first,
                        __global double* scratch, __global FsObs* rings, __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    FsParams prm = {window, memory, cap, refine, c, tol};
    FsRay r = {vload3(0, ray), vload3(1, ray), 0.0, ray[7]};
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    FsVertex v = {0};
    __global double* o = out + 6 * i;
    for (int k = 0; k < 6; ++k) o[k] = 0.0;
    for (int b = 0; b < 100000; ++b) {
        rng.bounce = (uint)b;
        FsResult res = fs_free_flight(kp[0], mean, mc, prm, r, v, rings + (size_t)i * cap,
                                      rng, S);
        o[3] += res.samples;
        o[4] += res.evals;
        if (res.status) { o[5] = res.status; break; }
        if (!res.hit) break;
        o[0] += 1.0;
        double s = dot(res.grad, r.d) / length(r.d);
        if (b > 0) { o[1] += s; o[2] += s * s; }
        v = fs_vertex_at_hit(prm, r, res, v, rings + (size_t)i * cap, S);
        r.o = r.o + res.t * r.d;
        r.t1 -= res.t;
        r.t0 = 0.0;
    }
}
"""

CAP_MAX, WINDOW_MAX = 128, 32


def flight_program(ctx) -> dict:
    """FLIGHT_WRAPPERS built for WINDOW_MAX rows and CAP_MAX memory (once per context)."""
    return sampler_program(ctx, FLIGHT_WRAPPERS, fs_sampler_options(WINDOW_MAX, CAP_MAX))


def sampler_buffers(device, kernel, mean, cap, chunk):
    """The kernel, mean program, per-work-item scratch and global-memory rings of a
    function-space wrapper launched `chunk` rays at a time: (kp, mb, mean count, scratch,
    rings)."""
    packed = pack_model(kernel, mean)     # the mean program, then the kernel's grid fields
    kp, mb = buffer(device, packed.kernel), buffer(device, packed.nodes)
    stride = FL.scratch_doubles(FL.max_rows(WINDOW_MAX, CAP_MAX))
    scratch = cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE, 8 * stride * chunk)
    rings = cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE, FL.FS_OBS.dtype.itemsize * cap * chunk)
    return kp, mb, packed.mean_count, scratch, rings


def flights(device, prg, kernel, mean, n, memory="global", window=0, cap=64, refine=6,
            c=0.0, tol=FL.DEFAULT_MISS_TOLERANCE, o=(0, 0, 0), d=(1, 0, 0), t0=0.0, t1=6.0,
            seed=1, restarts=0):
    """Per ray: first-hit t (-1: none), gradient, hits, status, GP samples drawn on the
    first flight, on all flights. c > 0: the uniform baseline step (correlation c),
    else the adaptive rule with tolerance tol; window 0: the default."""
    q = device.queue
    rb = buffer(device, np.array([*o, *d, t0, t1], np.float64))
    stride = FL.scratch_doubles(FL.max_rows(WINDOW_MAX, CAP_MAX))
    chunk = max(1, min(n, (256 << 20) // (8 * stride)))
    kp, mb, n_mean, scratch, rings = sampler_buffers(device, kernel, mean, cap, chunk)
    out = np.zeros((n, 8))
    for first in range(0, n, chunk):
        m = min(chunk, n - first)
        ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 64 * m)
        prg["flight"](q, (m,), None, kp, mb, np.int32(n_mean), np.int32(window),
                      np.int32(GPIS_MEMORIES[memory]), np.int32(cap), np.int32(refine),
                      np.float64(c), np.float64(tol), rb, np.uint32(seed), np.int32(first),
                      np.int32(restarts),
                      scratch, rings, ob)
        cl.enqueue_copy(q, out[first:first + m], ob)
    assert np.all(out[:, 5] == 0), f"solver status {np.unique(out[:, 5])}"
    return out


def run_crossings(device, prg, kernel, mu, n, L, memory="global", refine=6, c=0.0,
                  tol=FL.DEFAULT_MISS_TOLERANCE, seed=1, cap=64, window=None):
    """Per ray (out of n): hits, sum and sum of squares of slopes after the first hit,
    GP samples, moment evaluations (the crossings wrapper above). The window is the one
    scenes compile for the kernel unless given."""
    if window is None:
        window = sampler_window({"type": kernel.kind})
    q = device.queue
    rb = buffer(device, np.array([0, 0, 0, 1, 0, 0, 0, L], np.float64))
    chunk = max(1, min(n, 4096))
    kp, mb, n_mean, scratch, rings = sampler_buffers(device, kernel, Constant(mu), cap, chunk)
    out = np.zeros((n, 6))
    for first in range(0, n, chunk):
        m = min(chunk, n - first)
        ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 48 * m)
        prg["crossings"](q, (m,), None, kp, mb, np.int32(n_mean), np.int32(window),
                         np.int32(GPIS_MEMORIES[memory]), np.int32(cap), np.int32(refine),
                         np.float64(c), np.float64(tol), rb, np.uint32(seed), np.int32(first),
                         scratch, rings, ob)
        cl.enqueue_copy(q, out[first:first + m], ob)
    assert np.all(out[:, 5] == 0), f"solver status {np.unique(out[:, 5])}"
    return out
