"""Small OpenCL programs for tests: the device headers plus a few wrapper kernels that
expose one device function each, built once per (context, source, options)."""
import functools

import numpy as np
import pyopencl as cl

from gpiscl.host.render.program_sources import fs_sampler_source


@functools.lru_cache(maxsize=None)
def _built(ctx, source: str, options: tuple) -> dict:
    program = cl.Program(ctx, source).build(options=list(options))
    return {k.function_name: k for k in program.all_kernels()}


def program(ctx, source: str, options=()) -> dict:
    """The kernels of `source` by name; a second call with the same arguments reuses the
    build (PoCL compiles take seconds to a minute)."""
    return _built(ctx, source, tuple(options))


def sampler_program(ctx, wrappers: str, options) -> dict:
    """The function-space sampler's headers (fs_sampler_source) with `wrappers` after
    them, built with `options` (fs_sampler_options and extra -D defines)."""
    return program(ctx, fs_sampler_source(wrappers), options)


def buffer(device, array, rw=False):
    """A device copy of `array` (C-contiguous), read-only unless rw."""
    flags = cl.mem_flags.READ_WRITE if rw else cl.mem_flags.READ_ONLY
    return cl.Buffer(device.ctx, flags | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(array))


# gp_kernel.h's covariances between values and directional derivatives, per item
GP_COVARIANCE_WRAPPER = r"""
__kernel void covariances(__global const GpKernel* kp, __global const GP_REAL* a,
                          __global const GP_REAL* u, __global const GP_REAL* b,
                          __global const GP_REAL* v, __global GP_REAL* out)
{
    int i = get_global_id(0);
    GpKernel p = kp[0];
    GP_REAL3 A = vload3(i, a), U = vload3(i, u), B = vload3(i, b), V = vload3(i, v);
    __global GP_REAL* o = out + 8 * i;
    o[0] = gp_cov_vv(p, A, B);
    o[1] = gp_cov_dv(p, A, U, B);
    o[2] = gp_cov_vd(p, A, B, V);
    o[3] = gp_cov_dd(p, A, U, B, V);
    o[4] = gp_cov(p, A, U, 0, B, V, 0);
    o[5] = gp_cov(p, A, U, 1, B, V, 0);
    o[6] = gp_cov(p, A, U, 0, B, V, 1);
    o[7] = gp_cov(p, A, U, 1, B, V, 1);
}
"""


# gp_mean.h's value and gradient at one point per item
GP_MEAN_WRAPPER = r"""
__kernel void mean_eval(__global const MeanNode* nodes, int count, __global const float* x,
                        __global float4* out)
{
    int i = get_global_id(0);
    float3 g;
    float value = gp_mean_eval(nodes, count, vload3(i, x), &g);
    out[i] = (float4)(g, value);
}
"""


# gpis_proxy.h's proxy clip and occupancy clip of one ray per item
OCCUPANCY_CLIP_WRAPPER = r"""
__kernel void occ_clip_k(__global const GpisObject* g, __global const MeanNode* means,
                         __global const uint* cells, __global const float4* planes,
                         __global const float* o,
                         __global const float* d, int clip_start, __global float4* out)
{
    int r = get_global_id(0);
    float3 O = vload3(r, o), D = vload3(r, d);
    float t0 = 0.0f, t1 = 1e30f;
    int in_proxy = gpis_proxy_clip(g, planes, O, D, &t0, &t1);
    float p0 = t0, p1 = t1;
    int keep = in_proxy && gpis_occupancy_clip(g, means, cells, O, D, &t0, &t1, clip_start);
    out[r] = (float4)(p0, p1, keep ? t0 : NAN, keep ? t1 : NAN);
    if (!in_proxy) out[r] = (float4)(NAN);
}
"""
