"""Weight-space GPIS throughput on the OpenCL device against numpy and a plain C loop.

    python tools/bench_weight_space.py [--features 256] [--points 65536] [--rays 4096]
                                       [--lanes 8,16] [--repeats 5] [--numpy-rays 128]

Feature evaluations: f and its gradient at many points of one realization with M features
(ws_eval; the device regenerates every feature from Philox at every point), per second of
(point, feature) terms. Intersection: first roots along camera-like rays through a
sphere-mean GPIS (the white-furnace GPIS: SE, sigma = l = 0.1, proxy sphere 1.6), one
realization per ray as in a render, rays per second. numpy and C (tools/ws_feature_loop.c,
built here with gcc -O3 -march=native -ffast-math -fopenmp on every core, called through
ctypes) run over the same data: the features dumped from the device as float32 arrays,
the same points, rays and search (same bound and step rules). All contestants run in
turn within each of --repeats rounds; rates are medians, ratios are medians of the
per-round ratios (the machines are shared and noisy: trust ratios over rates).
GFLOP/s: each evaluation loop's rate times FLOPS_PER_TERM, against the device's float peak
measured in the same run (bench_peak: independent float16 FMA chains).
"""
from __future__ import annotations

import argparse
import ctypes
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpiscl.host.render.device import Device
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources  # noqa: E402
from gpiscl.host.gp import Sphere, SquaredExponential  # noqa: E402
from gpiscl.host.gp import spectral  # noqa: E402
from gpiscl.host.layout.gp_records import pack_kernel, pack_mean  # noqa: E402

C_SOURCE = Path(__file__).resolve().parent / "ws_feature_loop.c"
KERNEL = SquaredExponential(sigma=0.1, length_scale=0.1)
RADIUS, PROXY, TOL = 1.0, 1.6, 1e-4 * 0.1
# the renderer's fixed work-group size (gpiscl/host/render/device.py). PoCL replicates
# bench_eval_cached's private feature cache per work-item (its loops have uniform trip
# counts) and overflows the stack from ~512 up; ws_first_root_counted's cache is not.
LOCAL = 64
MAX_ITER = 16384   # WS_MAX_ITER
# Useful flops per (point, feature) term of the evaluation loop, counted from its source
# (FMA = 2): phase 6, reduction 7, sin polynomial 8, cos polynomial 10, value and gradient
# sums 9. The same arithmetic in every contestant (numpy's and libm's sin/cos aside).
FLOPS_PER_TERM = 40
PEAK_FLOPS_PER_ITEM = 2 * 16 * 8 * 4096   # bench_peak
# the plain loops (gcc fuses sinf/cosf into scalar sincosf calls), and the same loops with
# sin and cos taken in separate passes, which gcc maps onto glibc's vector libm (libmvec)
C_VARIANTS = (("C plain", False), ("C libmvec", True))

BENCH_KERNELS = r"""
__kernel void bench_eval(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                         __global const float* cdf, int nc, int M, uint2 key,
                         __global const float* x, __global float4* out)
{
    int i = get_global_id(0);
    float3 g;
    float v = ws_eval(kp[0], mean, mc, cdf, nc, M, key, 0, vload3(i, x), &g);
    out[i] = (float4)(g, v);
}

/* one realization at PER points per work-item, its features generated once into the
 * private cache a root search uses (ws_fill_cache): regeneration amortised over PER */
#define PER 64
__kernel void bench_eval_cached(__global const GpKernel* kp, __global const MeanNode* mean,
                                int mc, __global const float* cdf, int nc, int M, uint2 key,
                                __global const float* x, __global float4* out)
{
    float cache[WS_CACHE_FLOATS];
    ws_fill_cache(kp[0], cdf, nc, key, 0, M, cache);
    for (int i = get_global_id(0) * PER; i < (get_global_id(0) + 1) * PER; ++i) {
        float3 g;
        float v = ws_eval_cached(cache, kp[0], mean, mc, cdf, nc, M, key, 0, vload3(i, x), &g);
        out[i] = (float4)(g, v);
    }
}

/* ws_eval's loop over stored features (the C loops' data): the device's evaluation code
 * alone, without regenerating features */
__kernel void bench_eval_stored(int M, __global const float* tx, __global const float* ty,
                                __global const float* tz, __global const float* tau,
                                __global const float* w, float amp, __global const float* x,
                                __global float4* out)
{
    int i = get_global_id(0);
    float3 p = vload3(i, x);
    wsf v = 0.0f, gx = 0.0f, gy = 0.0f, gz = 0.0f;
    for (int i0 = 0; i0 < M; i0 += WS_LANES) {
        wsf ax = WS_LOAD(i0, tx), ay = WS_LOAD(i0, ty), az = WS_LOAD(i0, tz), wv = WS_LOAD(i0, w);
        wsf c, s = ws_sincos(ax * p.x + ay * p.y + az * p.z + WS_LOAD(i0, tau), &c);
        v += wv * c;
        s *= wv;
        gx -= s * ax;
        gy -= s * ay;
        gz -= s * az;
    }
    float r = length(p);
    out[i] = (float4)(amp * (float3)(ws_hsum(gx), ws_hsum(gy), ws_hsum(gz)) + p / r,
                      amp * ws_hsum(v) + r - 1.0f);
}

/* the device's float peak: 8 independent float16 FMA chains per work-item (enough to
 * cover the FMA latency), PEAK_ITERS steps: 2 * 16 * 8 * PEAK_ITERS flops per work-item */
#define PEAK_ITERS 4096
__kernel void bench_peak(float a, float b, __global float* out)
{
    /* named accumulators, not an array: PoCL keeps a private array on the stack */
    float16 x = (float16)a, y = (float16)b, g = (float16)(float)get_global_id(0);
    float16 c0 = g, c1 = g + 1.0f, c2 = g + 2.0f, c3 = g + 3.0f, c4 = g + 4.0f,
            c5 = g + 5.0f, c6 = g + 6.0f, c7 = g + 7.0f;
    for (int i = 0; i < PEAK_ITERS; ++i) {
        c0 = fma(c0, x, y); c1 = fma(c1, x, y); c2 = fma(c2, x, y); c3 = fma(c3, x, y);
        c4 = fma(c4, x, y); c5 = fma(c5, x, y); c6 = fma(c6, x, y); c7 = fma(c7, x, y);
    }
    float16 s = ((c0 + c1) + (c2 + c3)) + ((c4 + c5) + (c6 + c7));
    out[get_global_id(0)] = s.s0 + s.s5 + s.sa + s.sf;
}

__kernel void bench_dump(__global const GpKernel* kp, __global const float* cdf, int nc, int M,
                         __global const uint2* keys, __global float* out)
{
    int r = get_global_id(0) / M, i = get_global_id(0) % M;
    float3 th;
    float tau, w;
    ws_feature(kp[0], cdf, nc, keys[r], 0, i, &th, &tau, &w);
    __global float* p = out + 5 * ((size_t)r * M + i);
    p[0] = th.x; p[1] = th.y; p[2] = th.z; p[3] = tau; p[4] = w;
}

__kernel void bench_roots(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                          __global const float* cdf, int nc, int M, __global const uint2* keys,
                          __global const float* o, __global const float* d,
                          __global const float2* t01, float tol, __global float* t_out,
                          __global int* evals)
{
    int r = get_global_id(0), status, n;
    float3 nrm;
    float t = ws_first_root_counted(kp[0], mean, mc, cdf, nc, M, keys[r], 0, vload3(r, o),
                                    vload3(r, d), t01[r].x, t01[r].y, tol, &nrm, &status, &n);
    t_out[r] = status == WS_STATUS_OK ? t : -1.0f;
    evals[r] = n;
}
"""


# --- the C baseline ----------------------------------------------------------------------

def build_c(workdir: str, split: bool):
    lib = Path(workdir) / f"ws_feature_loop{'_split' if split else ''}.so"
    cmd = ["gcc", "-O3", "-march=native", "-ffast-math", "-fopenmp", "-shared", "-fPIC",
           *(["-DWS_SPLIT_SINCOS"] if split else []), str(C_SOURCE), "-o", str(lib), "-lm"]
    subprocess.run(cmd, check=True)
    c = ctypes.CDLL(str(lib))
    f32 = np.ctypeslib.ndpointer(np.float32, flags="C")
    i32 = np.ctypeslib.ndpointer(np.int32, flags="C")
    c.ws_eval_points.argtypes = [ctypes.c_int, f32, ctypes.c_int, f32, f32, f32, f32, f32,
                                 ctypes.c_float, ctypes.c_float, f32]
    c.ws_first_roots.argtypes = [ctypes.c_int, f32, f32, f32, ctypes.c_float, ctypes.c_int,
                                 f32, f32, f32, f32, f32, ctypes.c_float, ctypes.c_float,
                                 ctypes.c_float, ctypes.c_int, f32, i32]
    return c, " ".join(cmd[:5])


def soa(feats):
    """(..., M, 5) features -> contiguous float32 theta_x, theta_y, theta_z, tau, w."""
    return [np.ascontiguousarray(feats[..., j], np.float32) for j in range(5)]


# --- numpy baselines -----------------------------------------------------------------------

def numpy_eval(feats, amp, x, chunk=2048):
    tx, ty, tz, tau, w = soa(feats)
    theta = np.stack([tx, ty, tz], -1)
    out = np.empty((len(x), 4), np.float32)
    for s in range(0, len(x), chunk):
        xs = x[s:s + chunk]
        p = xs @ theta.T + tau
        ws_ = np.sin(p) * w
        r = np.linalg.norm(xs, axis=1)
        out[s:s + chunk, 3] = amp * (np.cos(p) @ w) + r - RADIUS
        out[s:s + chunk, :3] = -amp * (ws_ @ theta) + xs / r[:, None]
    return out


def numpy_first_roots(feats, amp, h0, o, d, t01, tol):
    """ws_first_root_counted vectorised over rays: every pass evaluates the bound of all
    still-active rays at once ((R, M) arrays); the step rules are those of the device."""
    tx, ty, tz, tau, w = (a.astype(np.float64) for a in soa(feats))
    o, d = o.astype(np.float64), d.astype(np.float64)
    n, eps = len(o), float(np.finfo(np.float32).eps)

    def eval_at(idx, t):
        x = o[idx] + t[:, None] * d[idx]
        p = tx[idx] * x[:, :1] + ty[idx] * x[:, 1:2] + tz[idx] * x[:, 2:] + tau[idx]
        s = np.sin(p) * w[idx]
        r = np.linalg.norm(x, axis=1)
        g = -amp * np.stack([(s * tx[idx]).sum(1), (s * ty[idx]).sum(1), (s * tz[idx]).sum(1)], 1)
        return amp * (np.cos(p) * w[idx]).sum(1) + r - RADIUS, g + x / r[:, None]

    def tents(idx, a, b):
        tm, h = 0.5 * (a + b), 0.5 * (b - a)
        oi, di = o[idx], d[idx]
        xm = oi + tm[:, None] * di
        xabs = np.abs(oi) + (np.abs(tm) + h)[:, None] * np.abs(di)
        txi, tyi, tzi, wi = tx[idx], ty[idx], tz[idx], w[idx]
        beta = txi * di[:, :1] + tyi * di[:, 1:2] + tzi * di[:, 2:]
        p = txi * xm[:, :1] + tyi * xm[:, 1:2] + tzi * xm[:, 2:] + tau[idx]
        c, s = np.cos(p), np.sin(p)
        bh = np.abs(beta) * h[:, None]
        q = 0.5 * bh * bh
        A, B = c * (1 - 0.5 * q), -s * beta
        E = 0.5 * np.abs(c) * q + np.abs(s) * q * bh / 3
        triv = np.abs(B) * h[:, None] + E > 1
        f0 = amp * (wi * np.where(triv, 0, A)).sum(1)
        f1 = amp * (wi * np.where(triv, 0, B)).sum(1)
        err = amp * (np.abs(wi) * np.where(triv, 1, E)).sum(1)
        e = 2 * (np.abs(txi) * xabs[:, :1] + np.abs(tyi) * xabs[:, 1:2]
                 + np.abs(tzi) * xabs[:, 2:]) + tau[idx] + 2
        rnd = 4 * amp * eps * np.sqrt((wi * wi * e * e).sum(1) + feats.shape[-2] * (wi * wi).sum(1))
        ma = np.linalg.norm(oi + a[:, None] * di, axis=1) - RADIUS
        mb = np.linalg.norm(oi + b[:, None] * di, axis=1) - RADIUS
        lt = np.linalg.norm(di, axis=1)
        sx = (np.abs(oi) + np.maximum(np.abs(a), np.abs(b))[:, None] * np.abs(di)).sum(1)
        rnd = rnd + 8 * eps * (np.abs(ma) + np.abs(mb) + sx)
        r = err + rnd
        lo_k = np.clip(tm + (ma - mb) * 0.5 / lt, a, b)
        hi_k = np.clip(tm + (mb - ma) * 0.5 / lt, a, b)
        c0, c1 = f0 - f1 * h, f0 + f1 * h
        lo = (c0 - r + np.maximum(ma, mb - lt * (b - a)),
              f0 + f1 * (lo_k - tm) - r + np.maximum(ma - lt * (lo_k - a), mb - lt * (b - lo_k)),
              c1 - r + np.maximum(ma - lt * (b - a), mb))
        hi = (c0 + r + np.minimum(ma, mb + lt * (b - a)),
              f0 + f1 * (hi_k - tm) + r + np.minimum(ma + lt * (hi_k - a), mb + lt * (b - hi_k)),
              c1 + r + np.minimum(ma + lt * (b - a), mb))
        return lo_k, lo, hi_k, hi, rnd

    def first_negative(a, pa, k, pk, b, pb):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(pa < 0, a, np.where(pk < 0, a + (k - a) * (pa / (pa - pk)),
                            np.where(pb < 0, k + (b - k) * (pk / (pk - pb)), np.inf)))

    t0, t1 = t01[:, 0].astype(np.float64), t01[:, 1].astype(np.float64)
    tres = 4 * eps * (np.abs(t0) + np.abs(t1)
                      + np.linalg.norm(o, axis=1) / np.linalg.norm(d, axis=1))
    tol = np.maximum(tol, 2 * tres)
    hmin = 0.875 * tol
    idx = np.arange(n)
    f, g = eval_at(idx, t0)
    evals = np.ones(n, np.int64)
    sgn = np.where(f < 0, -1.0, 1.0)
    phi, dphi = sgn * f, sgn * (g * d).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        step = np.where(dphi < 0, np.clip(phi / -dphi, hmin, h0), h0)
    a, c, hit = t0.copy(), np.full(n, np.inf), np.full(n, np.inf)
    noise, walk, g_at_c = np.zeros(n), np.zeros(n, bool), np.zeros(n, bool)
    active = np.ones(n, bool)
    for _ in range(MAX_ITER):
        # bracket resolved: a hit, or back outside
        br = active & (c - a <= tol)
        done_hit = br & (sgn > 0)
        hit[done_hit] = c[done_hit]
        evals[done_hit & ~g_at_c] += 1          # the normal's evaluation
        active &= ~done_hit
        flip = br & (sgn < 0)
        sgn[flip], a[flip], c[flip], step[flip] = 1.0, c[flip], np.inf, hmin[flip]
        g_at_c[flip] = False
        active &= ~(a >= t1)
        if not active.any():
            break
        # within the rounding floor: point evaluations decide intervals narrower than tol
        j = np.flatnonzero(active & ~flip & walk)
        if len(j):
            b = np.minimum(np.minimum(a[j] + hmin[j], t1[j]), c[j])
            fb, _ = eval_at(j, b)
            evals[j] += 1
            to_c = np.where(sgn[j] > 0, fb < 0, fb > noise[j])
            c[j] = np.where(to_c, b, c[j])
            a[j] = np.where(to_c, a[j], b)
            g_at_c[j] = to_c
            walk[j] = sgn[j] * fb <= 2 * noise[j]
        idx = np.flatnonzero(active & ~flip & ~np.isin(np.arange(n), j))
        if len(idx) == 0:
            continue
        ai, ci = a[idx], c[idx]
        b = np.minimum(np.minimum(ai + np.maximum(step[idx], hmin[idx]), t1[idx]), ci)
        lo_k, lo, hi_k, hi, rnd = tents(idx, ai, b)
        evals[idx] += 1
        noise[idx] = rnd
        s = sgn[idx]
        pos = s > 0
        x_safe = np.where(pos, first_negative(ai, lo[0], lo_k, lo[1], b, lo[2]),
                          first_negative(ai, -hi[0], hi_k, -hi[1], b, -hi[2]))
        x_opp = np.where(pos, first_negative(ai, hi[0], hi_k, hi[1], b, hi[2]),
                         first_negative(ai, -lo[0], lo_k, -lo[1], b, -lo[2]))
        g_at_c[idx] &= ~(x_opp < ci)
        ci = np.minimum(ci, x_opp)
        whole = x_safe >= b
        m = np.where(pos, np.minimum(np.minimum(lo[0], lo[1]), lo[2]),
                     -np.maximum(np.maximum(hi[0], hi[1]), hi[2]))
        e = 0.5 * np.maximum(hi[0] - lo[0], hi[2] - lo[2]) - rnd
        with np.errstate(divide="ignore", invalid="ignore"):
            grow = np.where(e > 0, np.clip(np.sqrt(np.maximum(0.25 * m / e, 0)), 2, 8), 8)
        width = b - ai
        na = np.where(whole, b, x_safe)
        rest = b - na
        nstep = np.where(whole, width * grow, 0.0)
        left = np.minimum(ci, b) - na
        nstep = np.where(~whole, np.where(left <= 0.5 * width, left, 0.5 * left), nstep)
        # intervals narrower than tol: the sign at their end decides
        pe = ~whole & (ci - na > tol[idx]) & (rest <= tol[idx])
        if pe.any():
            j = idx[pe]
            fb, _ = eval_at(j, b[pe])
            evals[j] += 1
            to_c = np.where(s[pe] > 0, fb < 0, fb > rnd[pe])
            cb, ab = ci[pe], na[pe]
            ci[pe] = np.where(to_c, b[pe], cb)
            na[pe] = np.where(to_c, ab, b[pe])
            nstep[pe] = hmin[j]
            g_at_c[j] = to_c
            walk[j] = s[pe] * fb <= 2 * rnd[pe]
        a[idx], c[idx], step[idx] = na, ci, nstep
    hit[active] = -1.0
    return hit, evals


# --- the device ------------------------------------------------------------------------

def build_device(device, lanes):
    load = (f"#define WS_LOAD(i0, p) vload{lanes}(i0 / {lanes}, p)\n" if lanes > 1
            else "#define WS_LOAD(i0, p) (p)[i0]\n")
    src = join_sources(
        (), ("ws_features.h", "ws_posterior.h", "ws_intersect.h")) + load + BENCH_KERNELS
    prg = cl.Program(device.ctx, src).build(options=[f"-I{PYOPENCL_CL_DIR}", f"-DWS_LANES={lanes}"])
    return {k.function_name: k for k in prg.all_kernels()}


def gp_buffers(device):
    mf = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    nodes, cdf = pack_mean(Sphere(radius=RADIUS)), spectral.order_table(KERNEL)
    return (cl.Buffer(device.ctx, mf, hostbuf=pack_kernel(KERNEL)),
            cl.Buffer(device.ctx, mf, hostbuf=nodes), np.int32(len(nodes)),
            cl.Buffer(device.ctx, mf, hostbuf=cdf), np.int32(len(cdf)))


def camera_rays(n, rng):
    """Rays from 4 units away into the unit sphere's neighbourhood, clipped to the proxy."""
    o = np.tile([0.0, 0.0, 4.0], (n, 1))
    target = np.concatenate([rng.uniform(-1.1, 1.1, (n, 2)), np.zeros((n, 1))], 1)
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = (o * d).sum(1)
    disc = b * b - ((o * o).sum(1) - PROXY**2)
    s = np.sqrt(np.maximum(disc, 0))
    t01 = np.stack([np.maximum(-b - s, 0), np.where(disc > 0, -b + s, 0)], 1)
    return o.astype(np.float32), d.astype(np.float32), t01.astype(np.float32)


def local(n):
    return (LOCAL,) if n % LOCAL == 0 else None


def interleaved(contestants: dict, repeats: int) -> dict:
    """Seconds per run of each contestant, run in turn within every repeat, so that load
    from other processes hits all of them alike: name -> list of times."""
    times = {name: [] for name in contestants}
    for _ in range(repeats):
        for name, fn in contestants.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    return times


def report(title, unit, work, times, ref_names, extra=None):
    """Median rate of each contestant and, per OpenCL build, its median ratio to each
    reference taken repeat by repeat."""
    print(f"\n{title}")
    for name, ts in times.items():
        line = f"  {name:28s} {statistics.median(work[name] / t for t in ts):10.3e} {unit}"
        if name.startswith("OpenCL"):
            ratios = []
            for ref in ref_names:
                per_round = [work[name] * tr / (work[ref] * t) for t, tr in zip(ts, times[ref])]
                ratios.append(f"/{ref} {statistics.median(per_round):.2f}")
            line += "   " + "  ".join(ratios)
        if extra and name in extra:
            line += "   " + extra[name]
        print(line)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--features", type=int, default=256)
    ap.add_argument("--points", type=int, default=1 << 16)
    ap.add_argument("--rays", type=int, default=4096)
    ap.add_argument("--numpy-points", type=int, default=8192)
    ap.add_argument("--numpy-rays", type=int, default=128)
    ap.add_argument("--lanes", default="8,16",
                    help="WS_LANES of the OpenCL builds to compare, comma-separated")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    m, lanes = args.features, [int(v) for v in args.lanes.split(",")]
    device = Device(args.device)
    rng = np.random.default_rng(1)
    amp = float(np.sqrt(2 * KERNEL.variance / m))
    h0 = 0.5 * KERNEL.length_scale
    dv = device.device
    print(f"device: {dv.name.strip()} ({dv.max_compute_units} compute units, native float "
          f"vector width {dv.native_vector_width_float}); M = {m}; {os.cpu_count()} CPUs")
    prgs = {f"OpenCL WS_LANES={n}": build_device(device, n) for n in lanes}
    prg = next(iter(prgs.values()))
    mf, q = cl.mem_flags, device.queue
    gp = gp_buffers(device)
    with tempfile.TemporaryDirectory() as tmp:
        clibs = {name: build_c(tmp, split)[0] for name, split in C_VARIANTS}
        print(f"C: gcc -O3 -march=native -ffast-math -fopenmp, {os.cpu_count()} threads; "
              f"medians of {args.repeats} interleaved repeats; ratios are OpenCL / reference")

        # --- feature evaluations: f and gradient at N points of one realization ---
        n, n_np = args.points, min(args.points, args.numpy_points)
        x = rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32)
        key = np.array([12345, 0xffffffff], np.uint32)
        x_buf = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
        out_buf = cl.Buffer(device.ctx, mf.WRITE_ONLY, 16 * n)
        keys1 = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=key[None])
        feat_buf = cl.Buffer(device.ctx, mf.WRITE_ONLY, 20 * m)
        prg["bench_dump"](q, (m,), None, gp[0], gp[3], gp[4], np.int32(m), keys1, feat_buf)
        feats = np.empty((m, 5), np.float32)
        cl.enqueue_copy(q, feats, feat_buf)
        fx = soa(feats)
        out_c = np.empty((n, 4), np.float32)

        def dev_eval(p):
            def run():
                p["bench_eval"](q, (n,), local(n), *gp, np.int32(m), key.view(cl.cltypes.uint2)[0],
                                x_buf, out_buf)
                q.finish()
            return run

        contestants = {name: dev_eval(p) for name, p in prgs.items()}
        fx_bufs = [cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in fx]
        stored_buf = cl.Buffer(device.ctx, mf.WRITE_ONLY, 16 * n)

        def dev_stored(p):
            def run():
                p["bench_eval_stored"](q, (n,), local(n), np.int32(m), *fx_bufs, np.float32(amp),
                                       x_buf, stored_buf)
                q.finish()
            return run

        def dev_cached(p):
            def run():
                p["bench_eval_cached"](q, (n // 64,), (LOCAL,), *gp, np.int32(m),
                                       key.view(cl.cltypes.uint2)[0], x_buf, stored_buf)
                q.finish()
            return run

        if m <= 1024 and n % (64 * LOCAL) == 0:
            contestants.update({f"{name}, cached": dev_cached(p) for name, p in prgs.items()})
        if m % max(lanes) == 0:
            contestants.update({f"{name}, stored": dev_stored(p) for name, p in prgs.items()})
        for name, lib in clibs.items():
            contestants[name] = (lambda lib: lambda: lib.ws_eval_points(
                n, x, m, *fx, amp, RADIUS, out_c))(lib)
        contestants["numpy"] = lambda: numpy_eval(feats, amp, x[:n_np])
        for fn in contestants.values():   # warm-up (first launches, caches)
            fn()
        times = interleaved(contestants, args.repeats)
        work = {name: (n_np if name == "numpy" else n) * m for name in contestants}
        out_dev = np.empty((n, 4), np.float32)
        cl.enqueue_copy(q, out_dev, out_buf)
        diff = np.max(np.abs(out_dev[:, 3] - out_c[:, 3]))
        report(f"feature evaluations: value + gradient at {n} points x {m} features "
               f"(OpenCL regenerates each feature from Philox at every point; ', cached' "
               f"once per 64 points, as a root search does per ray; ', stored', C and numpy "
               f"read the same features from arrays)",
               "/s", work, times, [name for name, _ in C_VARIANTS] + ["numpy"])
        print(f"  max |f_OpenCL - f_C| = {diff:.2e} (sigma = {KERNEL.sigma})")
        # GFLOP/s of the loops against the device's measured FMA peak, same run
        peak_out = cl.Buffer(device.ctx, mf.WRITE_ONLY, 4 * 4096)
        def peak():
            prg["bench_peak"](q, (4096,), (LOCAL,), np.float32(0.999), np.float32(1e-3),
                              peak_out)
            q.finish()
        peak()
        peak_times = interleaved({"peak": peak}, args.repeats)["peak"]
        peak_rate = 4096 * PEAK_FLOPS_PER_ITEM / statistics.median(peak_times)
        print(f"  device float peak (float16 FMA chains): {peak_rate / 1e9:.1f} GFLOP/s; "
              f"loops at {FLOPS_PER_TERM} flops per term:")
        for name, ts in times.items():
            rate = statistics.median(work[name] / t for t in ts) * FLOPS_PER_TERM
            print(f"    {name:28s} {rate / 1e9:7.1f} GFLOP/s  {rate / peak_rate:6.1%} of peak")

        # --- intersection: first roots along camera rays, one realization per ray ---
        r, rn = args.rays, min(args.rays, args.numpy_rays)
        o, d, t01 = camera_rays(r, rng)
        keys = np.stack([np.arange(r), np.full(r, 99)], -1).astype(np.uint32)
        bufs = [cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
                for a in (keys, o, d, t01)]
        t_buf, e_buf = (cl.Buffer(device.ctx, mf.WRITE_ONLY, 4 * r) for _ in range(2))
        dump_buf = cl.Buffer(device.ctx, mf.WRITE_ONLY, 20 * m * r)
        prg["bench_dump"](q, (r * m,), None, gp[0], gp[3], gp[4], np.int32(m), bufs[0], dump_buf)
        rf = np.empty((r, m, 5), np.float32)
        cl.enqueue_copy(q, rf, dump_buf)
        rfx = soa(rf)
        t_c, ev_c = np.empty(r, np.float32), np.empty(r, np.int32)

        def dev_roots(p):
            def run():
                p["bench_roots"](q, (r,), local(r), *gp, np.int32(m), *bufs, np.float32(TOL),
                                 t_buf, e_buf)
                q.finish()
            return run

        contestants = {name: dev_roots(p) for name, p in prgs.items()}
        for name, lib in clibs.items():
            contestants[name] = (lambda lib: lambda: lib.ws_first_roots(
                r, o, d, t01, TOL, m, *rfx, amp, RADIUS, h0, MAX_ITER, t_c, ev_c))(lib)
        numpy_out = []
        contestants["numpy"] = lambda: numpy_out.append(
            numpy_first_roots(rf[:rn], amp, h0, o[:rn], d[:rn], t01[:rn], TOL))
        for name, fn in contestants.items():
            if name != "numpy":
                fn()
        times = interleaved(contestants, args.repeats)
        t_d, ev_d = np.empty(r, np.float32), np.empty(r, np.int32)
        cl.enqueue_copy(q, t_d, t_buf)
        cl.enqueue_copy(q, ev_d, e_buf)
        t_n, ev_n = numpy_out[-1]
        hit_d = t_d < 1e29

        def agree(t_other, k):
            hit_o = t_other < 1e29
            close = np.abs(t_d[:k] - t_other) <= 2 * TOL
            return np.mean((hit_d[:k] == hit_o) & (~hit_d[:k] | close))

        work = {name: rn if name == "numpy" else r for name in contestants}
        extra = {name: f"{np.mean(ev_d):.1f} evaluations/ray, {np.sum(t_d < 0)} undecided"
                 for name in prgs}
        extra.update({name: f"{np.mean(ev_c):.1f} evaluations/ray, same root {agree(t_c, r):.1%}"
                      for name in clibs})
        extra["numpy"] = (f"{np.mean(ev_n):.1f} evaluations/ray ({np.mean(ev_d[:rn]):.1f} on "
                          f"OpenCL), same root {agree(t_n, rn):.1%}")
        report(f"first roots: {r} camera rays ({np.mean(hit_d):.0%} hit), one realization per "
               f"ray, M = {m}, tol = {TOL:g}", "rays/s", work, times,
               [name for name, _ in C_VARIANTS] + ["numpy"], extra)


if __name__ == "__main__":
    main()
