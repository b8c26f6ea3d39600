"""Device wrappers of fs_markov.h for tests/test_fs_markov.py and tools/bench_markov.py:
the transition, state paths, bridge draws, the step rule's ratio, and flights continued through their hits with
either sampler (Markov or the general one of fs_march.h) on the same random streams."""
import functools

import numpy as np
import pyopencl as cl

from gpiscl.host.layout import function_space_records as FL
from gpiscl.host.layout import gp_records
from gpiscl.host.layout.records import GPIS_MEMORIES
from gpiscl.host.render.program_sources import fs_sampler_options, fs_sampler_source

WRAPPERS = r"""
/* A(h), Q(h) along unit direction dir: out[0..9) A, out[9..18) Q (row-major 3 x 3) */
__kernel void mk_transition(__global const GpKernel* kp, __global const double* dir,
                            double h, __global double* out)
{
    FsMarkov m = fs_markov_of(kp[0], vload3(0, dir));
    double A[3][3] = {{0.0}}, Q[3][3] = {{0.0}};
    fs_mk_transition(m, h, A, Q);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) { out[3 * i + j] = A[i][j]; out[9 + 3 * i + j] = Q[i][j]; }
}

/* A stationary state path at us[0..n) (world lengths along dir): Y(u0) ~ N(0, sigma^2),
 * the rest by fs_mk_start, then fs_mk_advance; out: n states of 3 per item. */
__kernel void mk_path(__global const GpKernel* kp, __global const double* dir,
                      __global const double* us, int n, uint seed, __global double* out)
{
    int i = get_global_id(0);
    FsMarkov m = fs_markov_of(kp[0], vload3(0, dir));
    FsRng rng = {seed, (uint)i, 0u, 0u, 0u};
    double x[3] = {0.0, 0.0, 0.0}, A[3][3], Q[3][3];
    x[0] = sqrt(m.s2) * fs_normal(rng, 0, FS_SLOT_TESTS);
    fs_mk_start(m, x, 0, rng);
    __global double* o = out + (size_t)3 * n * i;
    for (int k = 0; k < n; ++k) {
        if (k > 0) {
            fs_mk_transition(m, us[k] - us[k - 1], A, Q);
            fs_mk_advance(m, A, Q, x, rng, (uint)k, 0u);
        }
        for (int j = 0; j < 3; ++j) o[3 * k + j] = x[j];
    }
}

/* Bridge draws of the state h1 after xa and h2 before xb (3 doubles per item), and
 * (one item is enough) the slope's conditional mean and sd given Y = y0 there. */
__kernel void mk_bridge(__global const GpKernel* kp, __global const double* dir, double h1,
                        double h2, __global const double* ends, double y0, uint seed,
                        __global double* out, __global double* slope)
{
    int i = get_global_id(0);
    FsMarkov m = fs_markov_of(kp[0], vload3(0, dir));
    FsRng rng = {seed, (uint)i, 0u, 0u, 0u};
    double xa[3], xb[3], x[3] = {0.0, 0.0, 0.0}, sd;
    for (int j = 0; j < 3; ++j) { xa[j] = ends[j]; xb[j] = ends[3 + j]; }
    fs_mk_bridge_sample(m, h1, h2, xa, xb, rng, 0u, FS_SLOT_REFINE, x);
    for (int j = 0; j < 3; ++j) out[3 * i + j] = x[j];
    if (i == 0) {
        slope[0] = fs_mk_bridge_slope(m, h1, h2, xa, xb, y0, &sd);
        slope[1] = sd;
    }
}

/* The step rule's ratio (fs_mk_rule_ratio) and scale * fs_return_rate for moments rows
 * (m, m1, s, r, g) (fs_march.h's FsMoments, as Q's block: v = s^2, c = r s, w = g^2 + r^2)
 * with the side `outside` (0, 1) and a scale per row: out[2 i], out[2 i + 1] */
__kernel void mk_rule(__global const double* mom, __global const int* outside,
                      __global const double* scales, __global double* out)
{
    int i = get_global_id(0);
    double scale = scales[i];
    double s = mom[5 * i + 2], r = mom[5 * i + 3], g = mom[5 * i + 4];
    double Q[3][3] = {{s * s, r * s, 0.0}, {r * s, g * g + r * r, 0.0}, {0.0, 0.0, 0.0}};
    float X, gam;
    out[2 * i] = fs_mk_rule_ratio(mom[5 * i], mom[5 * i + 1], Q, outside[i], scale, 1.0f, &X,
                                  &gam);
    out[2 * i + 1] = scale * fs_return_rate(fs_mk_moments(mom[5 * i], mom[5 * i + 1], Q),
                                            outside[i]);
}

/* Rays along one line, continued straight through every hit from the vertex record up
 * to `restarts` times, with the Markov (markov = 1) or the general sampler. Per item:
 * first hit t (-1: none), its gradient, hits, status, samples, evaluations, and the sum
 * of the along-ray slope and of its square over hits after the first. */
__kernel void mk_flights(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                         int markov, int memory, int refine, double tol,
                         __global const double* ray, uint seed, int first, int restarts,
                         __global double* scratch, __global FsObs* rings,
                         __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    FsParams prm = {0, memory, 1, refine, 0.0, tol};
    FsRay r = {vload3(0, ray), vload3(1, ray), ray[6], ray[7]};
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    FsVertex v = {0};
    __global double* o = out + 10 * i;
    o[0] = -1.0;
    for (int k = 1; k < 10; ++k) o[k] = 0.0;
    for (int b = 0; b <= restarts; ++b) {
        rng.bounce = (uint)b;
        FsResult res = markov ? fs_markov_free_flight(kp[0], mean, mc, prm, r, v, rng, S)
                              : fs_free_flight(kp[0], mean, mc, prm, r, v, rings + i, rng, S);
        o[6] += res.samples;
        o[7] += res.evals;
        if (res.status) { o[5] = res.status; break; }
        if (!res.hit) break;
        if (b == 0) { o[0] = res.t; vstore3(res.grad, 0, o + 1); }
        else {
            double s = dot(res.grad, r.d) / length(r.d);
            o[8] += s;
            o[9] += s * s;
        }
        o[4] += 1.0;
        v = fs_vertex_at_hit(prm, r, res, v, rings + i, S);
        r.o = r.o + res.t * r.d;
        r.t1 -= res.t;
        r.t0 = 0.0;
    }
}
"""
WINDOW_MAX, CAP_MAX = 16, 2


@functools.lru_cache(maxsize=None)
def program(ctx):
    p = cl.Program(ctx, fs_sampler_source(WRAPPERS)).build(
        options=fs_sampler_options(WINDOW_MAX, CAP_MAX))
    return {k.function_name: k for k in p.all_kernels()}


def buf(ctx, a):
    return cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(a))


def transition(device, kernel, h, direction=(1.0, 0.0, 0.0)):
    """Device A(h), Q(h) (3 x 3, zero padded for Matern 3/2)."""
    out = np.zeros(18)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * 18)
    program(device.ctx)["mk_transition"](
        device.queue, (1,), None, buf(device.ctx, gp_records.pack_kernel(kernel)),
        buf(device.ctx, np.asarray(direction, np.float64)), np.float64(h), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out[:9].reshape(3, 3), out[9:].reshape(3, 3)


def paths(device, kernel, us, n, seed, direction=(1.0, 0.0, 0.0)):
    """n stationary state paths at world lengths us: (n, len(us), 3)."""
    us = np.asarray(us, np.float64)
    out = np.zeros((n, len(us), 3))
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program(device.ctx)["mk_path"](
        device.queue, (n,), None, buf(device.ctx, gp_records.pack_kernel(kernel)),
        buf(device.ctx, np.asarray(direction, np.float64)), buf(device.ctx, us),
        np.int32(len(us)), np.uint32(seed), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out


def bridge(device, kernel, h1, h2, xa, xb, y0, n, seed, direction=(1.0, 0.0, 0.0)):
    """n bridge draws (n, 3) and the slope's (mean, sd) given Y = y0 at the point."""
    out, slope = np.zeros((n, 3)), np.zeros(2)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    sb = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 16)
    ends = np.zeros(6)
    ends[:len(xa)], ends[3:3 + len(xb)] = xa, xb
    program(device.ctx)["mk_bridge"](
        device.queue, (n,), None, buf(device.ctx, gp_records.pack_kernel(kernel)),
        buf(device.ctx, np.asarray(direction, np.float64)), np.float64(h1), np.float64(h2),
        buf(device.ctx, ends), np.float64(y0), np.uint32(seed), ob, sb)
    cl.enqueue_copy(device.queue, out, ob)
    cl.enqueue_copy(device.queue, slope, sb)
    return out, slope


def rule_ratios(device, moments, outside, scale):
    """(fs_mk_rule_ratio, scale * fs_return_rate) per row of moments (n, 5); scale: one
    or one per row."""
    moments = np.asarray(moments, np.float64)
    out = np.zeros((len(moments), 2))
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    scales = np.broadcast_to(np.asarray(scale, np.float64), (len(moments),))
    program(device.ctx)["mk_rule"](
        device.queue, (len(moments),), None, buf(device.ctx, moments),
        buf(device.ctx, np.asarray(outside, np.int32)), buf(device.ctx, scales), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out


def flights(device, kernel, mean, n, markov, memory="none", refine=6,
            tol=FL.DEFAULT_MISS_TOLERANCE, o=(0, 0, 0), d=(1, 0, 0), t0=0.0, t1=6.0,
            seed=1, restarts=0):
    """Per ray (n, 10): first hit t (-1: none), gradient (3), hits, status, samples,
    evaluations, sums of the slope and its square over hits after the first."""
    q, ctx = device.queue, device.ctx
    stride = FL.scratch_doubles(FL.max_rows(WINDOW_MAX, CAP_MAX))
    chunk = max(1, min(n, (128 << 20) // (8 * stride)))
    mean_nodes = gp_records.pack_mean(mean)
    kp, mb = buf(ctx, gp_records.pack_kernel(kernel)), buf(ctx, mean_nodes)
    rb = buf(ctx, np.array([*o, *d, t0, t1], np.float64))
    scratch = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 8 * stride * chunk)
    rings = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, FL.FS_OBS.dtype.itemsize * chunk)
    out = np.zeros((n, 10))
    k = program(ctx)["mk_flights"]
    for first in range(0, n, chunk):
        m = min(chunk, n - first)
        ob = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, 80 * m)
        k(q, (m,), None, kp, mb, np.int32(len(mean_nodes)), np.int32(1 if markov else 0),
          np.int32(GPIS_MEMORIES[memory]), np.int32(refine), np.float64(tol), rb,
          np.uint32(seed), np.int32(first), np.int32(restarts), scratch, rings, ob)
        cl.enqueue_copy(q, out[first:first + m], ob)
    return out
