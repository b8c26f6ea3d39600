"""The weight-space sampler as a test harness: wrapper kernels over ws_features.h,
ws_posterior.h and ws_intersect.h (feature dumps, evaluations, bounds and roots), and the
host helpers that launch them and bound their float32 error."""
import numpy as np
import pyopencl as cl

from gpiscl.host.gp import Constant
from gpiscl.host.gp import spectral
from gpiscl.testing.reference import weight_space as ws
from gpiscl.host.layout.gp_records import pack_kernel, pack_mean
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources

from .wrappers import buffer, program

EPS = float(np.finfo(np.float32).eps)
ROT = np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]])


WS_WRAPPERS = r"""
__kernel void ws_dump(__global const GpKernel* kp, __global const float* cdf, int nc, int M,
                      __global const uint2* keys, int object, __global float* out)
{
    int r = get_global_id(0);
    for (int i = 0; i < M; ++i) {
        float3 th;
        float tau, w;
        ws_feature(kp[0], cdf, nc, keys[r], object, i, &th, &tau, &w);
        vstore3(th, 0, out + 5 * (r * M + i));
        out[5 * (r * M + i) + 3] = tau;
        out[5 * (r * M + i) + 4] = w;
    }
}

__kernel void ws_eval_points(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                             __global const float* cdf, int nc, int M, __global const uint2* keys,
                             int object, int per_key, __global const float* x,
                             __global float4* out)
{
    int i = get_global_id(0);
    float3 g;
    float v = ws_eval(kp[0], mean, mc, cdf, nc, M, keys[i / per_key], object, vload3(i, x), &g);
    out[i] = (float4)(g, v);
}

__kernel void ws_philox_check(__global const uint2* keys, int object, uint call,
                              __global uint4* mine, __global uint4* random123)
{
    int i = get_global_id(0);
    wsu r0, r1, r2, r3;
    ws_draw(keys[i], object, (wsi)i, call, &r0, &r1, &r2, &r3);
    mine[i] = (uint4)(ws_lane0(r0), ws_lane0(r1), ws_lane0(r2), ws_lane0(r3));
    philox4x32_ctr_t c = {{keys[i].x, keys[i].y, (uint)object, (uint)i}};
    philox4x32_key_t k = {{call, WS_PHILOX_KEY1}};
    philox4x32_ctr_t r = philox4x32(c, k);
    random123[i] = (uint4)(r.v[0], r.v[1], r.v[2], r.v[3]);
}

__kernel void ws_sincos_k(__global const float* x, __global float2* out)
{
    int i = get_global_id(0);
    wsf c, s = ws_sincos((wsf)x[i], &c);
    out[i] = (float2)(ws_lane0(s), ws_lane0(c));
}

/* ws_affine over [tm - h, tm + h] from regenerated features and from a filled cache */
__kernel void ws_affine_both(__global const GpKernel* kp, __global const float* cdf, int nc,
                             int M, __global const uint2* keys, __global const float* o,
                             __global const float* d, __global const float2* tmh,
                             __global float4* regen, __global float4* cached)
{
    int r = get_global_id(0);
    float cache[WS_CACHE_FLOATS];
    ws_fill_cache(kp[0], cdf, nc, keys[r], 0, M, cache);
    float3 O = vload3(r, o), D = vload3(r, d);
    WsAffine a = ws_affine(0, kp[0], cdf, nc, M, keys[r], 0, O, D, tmh[r].x, tmh[r].y);
    WsAffine b = ws_affine(cache, kp[0], cdf, nc, M, keys[r], 0, O, D, tmh[r].x, tmh[r].y);
    regen[r] = (float4)(a.f0, a.f1, a.err, a.round);
    cached[r] = (float4)(b.f0, b.f1, b.err, b.round);
}

__kernel void ws_lambda2_k(__global const GpKernel* kp, __global const float* d,
                           __global float* out)
{
    out[get_global_id(0)] = ws_lambda2(kp[0], vload3(get_global_id(0), d));
}
"""


def build(device, extra="", options=(), lanes=8):
    """The ws headers, WS_WRAPPERS and extra kernels as one program: name -> kernel
    (built once per device, source and options)."""
    src = join_sources(
        (), ("ws_features.h", "ws_posterior.h", "ws_intersect.h")) + WS_WRAPPERS + extra
    return program(device.ctx, src, [f"-I{PYOPENCL_CL_DIR}", f"-DWS_LANES={lanes}", *options])


def run(device, kernel, n, *args, out_shapes):
    """Launch kernel over n items with args, then output buffers; returns the outputs."""
    outs = [np.empty(s, dt) for s, dt in out_shapes]
    bufs = [cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, o.nbytes) for o in outs]
    kernel(device.queue, (n,), None, *args, *bufs)
    for o, b in zip(outs, bufs):
        cl.enqueue_copy(device.queue, o, b)
    return outs


def keys_for(n, stream=7):
    return np.stack([np.arange(n), np.full(n, stream)], -1).astype(np.uint32)


def gp_args(device, kernel, mean=Constant(0.0)):
    """Device arguments (kernel, mean nodes, count, order table, count) of a GPIS."""
    nodes, cdf = pack_mean(mean), spectral.order_table(kernel)
    return (buffer(device, pack_kernel(kernel)), buffer(device, nodes), np.int32(len(nodes)),
            buffer(device, cdf), np.int32(len(cdf)))


def dump(device, prg, kernel, keys, m, obj=0):
    """theta (R, M, 3), tau (R, M), w (R, M) of realizations keys, as the device draws them."""
    kp, _, _, cdf, nc = gp_args(device, kernel)
    (out,) = run(device, prg["ws_dump"], len(keys), kp, cdf, nc, np.int32(m), buffer(device, keys),
                 np.int32(obj), out_shapes=[((len(keys), m, 5), np.float32)])
    out = out.astype(np.float64)
    return out[..., :3], out[..., 3], out[..., 4]


def eval_tolerance(theta, tau, w, variance, x):
    """Float32 error bound of ws_eval: phase = 3 products + 3 sums (gamma_6 of its absolute
    terms), cos/sin polynomials ~4 eps absolute, M-term summation gamma_M."""
    m = theta.shape[-2]
    amp = np.sqrt(2 * variance / m)
    phase_terms = np.abs(x[:, None, :] * theta[None]).sum(-1) + tau[None]       # (P, M)
    e = 6 * EPS * phase_terms + 4 * EPS
    aw = np.abs(w)[None]
    value = amp * (aw * e).sum(-1) + amp * m * EPS * aw.sum(-1)
    grad = amp * (aw * e * np.linalg.norm(theta, axis=-1)[None]).sum(-1) * (1 + m * EPS)
    mean = 8 * EPS * (2 + np.abs(x).sum(-1))     # float distance of O(1) means at |x|
    return value + mean, grad + 4 * mean


WS_BOUND_WRAPPERS = r"""
__kernel void ws_tents_k(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                         __global const float* cdf, int nc, int M, __global const uint2* keys,
                         __global const float* o, __global const float* d,
                         __global const float2* ab, int npts, __global float* tents,
                         __global float2* vals)
{
    int r = get_global_id(0);
    float3 O = vload3(r, o), D = vload3(r, d), g;
    float a = ab[r].x, b = ab[r].y;
    WsTents T = ws_tents(kp[0], mean, mc, cdf, nc, M, keys[r], 0, O, D, a, b,
                         ws_mean_lipschitz(mean, mc));
    float t9[9] = {T.lo_k, T.lo_a, T.lo_m, T.lo_b, T.hi_k, T.hi_a, T.hi_m, T.hi_b, T.round};
    for (int j = 0; j < 9; ++j) tents[9 * r + j] = t9[j];
    for (int j = 0; j < npts; ++j) {
        float t = j == npts - 1 ? b : a + (b - a) * ((float)j / (float)(npts - 1));
        vals[r * npts + j] = (float2)(t, ws_eval(kp[0], mean, mc, cdf, nc, M, keys[r], 0,
                                                 O + t * D, &g));
    }
}

__kernel void ws_roots_k(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                         __global const float* cdf, int nc, int M, __global const uint2* keys,
                         __global const float* o, __global const float* d, float t0, float t1,
                         float tol, __global float4* hit, __global int2* st)
{
    int r = get_global_id(0), status, its;
    float3 n;
    float t = ws_first_root_counted(kp[0], mean, mc, cdf, nc, M, keys[r], 0, vload3(r, o),
                                    vload3(r, d), t0, t1, tol, &n, &status, &its);
    hit[r] = (float4)(n, t);
    st[r] = (int2)(status, its);
}

/* every hit along (t0, t1]: each search restarts at the last hit, where f < 0 */
__kernel void ws_count_k(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                         __global const float* cdf, int nc, int M, __global const uint2* keys,
                         __global const float* o, __global const float* d, float t1, float tol,
                         __global int2* out)
{
    int r = get_global_id(0), n = 0, status = 0;
    float t = 0.0f;
    float3 nrm;
    for (;;) {
        t = ws_first_root(kp[0], mean, mc, cdf, nc, M, keys[r], 0, vload3(r, o), vload3(r, d),
                          t, t1, tol, &nrm, &status);
        if (status != WS_STATUS_OK || t >= T_INFINITY) break;
        ++n;
    }
    out[r] = (int2)(n, status);
}

/* a first root from outside, then a second search leaving it: origin x = root - inset n,
 * direction at cos(angle) u.x to the normal n, azimuth 2 pi u.y, length u.w */
__kernel void ws_restart_k(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                           __global const float* cdf, int nc, int M, __global const uint2* keys,
                           __global const float* o, __global const float* d, float t1, float tol,
                           __global const float4* u, __global float* x_out,
                           __global float* d_out, __global float* hit, __global int4* st)
{
    int r = get_global_id(0), status, status2 = 0, evals2 = 0;
    float3 n, n2;
    float t = ws_first_root(kp[0], mean, mc, cdf, nc, M, keys[r], 0, vload3(r, o),
                           vload3(r, d), 0.0f, t1, tol, &n, &status);
    float3 x = vload3(r, o) + t * vload3(r, d), dir = n;
    float t2 = T_INFINITY;
    if (status == WS_STATUS_OK && t < T_INFINITY) {
        float4 ur = u[r];
        float3 e1 = normalize(cross(fabs(n.x) > 0.5f ? (float3)(0, 1, 0) : (float3)(1, 0, 0), n));
        float3 e2 = cross(n, e1);
        float s = sqrt(fmax(1.0f - ur.x * ur.x, 0.0f)), phi = 6.28318531f * ur.y;
        dir = ur.x * n + s * (cos(phi) * e1 + sin(phi) * e2);
        x -= ur.z * n;
        t2 = ws_first_root_counted(kp[0], mean, mc, cdf, nc, M, keys[r], 0, x, dir, 0.0f, ur.w,
                                   tol, &n2, &status2, &evals2);
    }
    vstore3(x, r, x_out);
    vstore3(dir, r, d_out);
    hit[r] = t2;
    st[r] = (int4)(status, t < T_INFINITY, status2, evals2);
}

__kernel void ws_lipschitz_k(__global const MeanNode* mean, int mc, __global float* out)
{
    out[0] = ws_mean_lipschitz(mean, mc);
}
"""


def assert_tents_contain(tents, ab, t, *values):
    """Each ray's piecewise-linear bounds (ws_tents_k's 9 numbers on [a, b]) contain every
    one of the given value arrays (rays x points at parameters t)."""
    for r in range(len(tents)):
        (lk, la, lm, lb, hk, ha, hm, hb, _), (a_, b_) = tents[r].astype(float), ab[r]
        lo = np.interp(t[r], [a_, lk, b_], [la, lm, lb])
        hi = np.interp(t[r], [a_, hk, b_], [ha, hm, hb])
        for v in values:
            assert np.all((lo <= v[r]) & (v[r] <= hi)), (r, np.min(v[r] - lo), np.min(hi - v[r]))


def random_rays(rng, n, spread=2.0):
    o = rng.uniform(-spread, spread, (n, 3))
    d = rng.normal(size=(n, 3))
    return o.astype(np.float32), (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


def host_values(theta, tau, w, kernel, mean, o, d, t):
    """f in float64 along rays: (R, T) values at parameters t (R, T) or (T,)."""
    t = np.broadcast_to(t, (len(o), np.shape(t)[-1]))
    x = o[:, None, :].astype(float) + t[..., None] * d[:, None, :].astype(float)
    return np.stack([ws.evaluate_value(theta[r], tau[r], w[r], kernel.variance, x[r], mean)
                     for r in range(len(o))])


def roots_and_scan(device, prg, kernel, mean, o, d, keys, m, t0, t1, tol):
    """The device's first roots of realizations `keys` along rays o + t d, t in [t0, t1]
    (every search decided), and a dense float64 scan of the same realizations (spacing
    l / 200): hit (n, 4: normal, t), the scan's brackets t_lo, t_hi, its points ts, and
    the features (theta, tau, w)."""
    n = len(o)
    hit, st = run(device, prg["ws_roots_k"], n, *gp_args(device, kernel, mean), np.int32(m),
                  buffer(device, keys), buffer(device, o), buffer(device, d), np.float32(t0),
                  np.float32(t1), np.float32(tol),
                  out_shapes=[((n, 4), np.float32), ((n, 2), np.int32)])
    assert np.all(st[:, 0] == 0)
    theta, tau, w = dump(device, prg, kernel, keys, m)
    ts = np.linspace(t0, t1, int((t1 - t0) / (kernel.length_scale / 200)) + 1)
    t_lo, t_hi = ws.dense_scan_first_root(host_values(theta, tau, w, kernel, mean, o, d, ts), ts)
    return hit, t_lo, t_hi, ts, (theta, tau, w)
