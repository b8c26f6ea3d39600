"""Function space against weight space along one fresh ray: with many features the
weight-space realization is (nearly) Gaussian, and its first root and normal must have
the law of the function-space free flight with the same start condition f(t0) >= 0."""
import numpy as np

from gpiscl.host.gp import Plane, SquaredExponential
from gpiscl.testing.flights import flights
from gpiscl.testing.stats import ks_two_sample
from gpiscl.testing.weight_space import build, gp_args, keys_for, run
from gpiscl.testing.wrappers import buffer

WS_FRESH = r"""
/* f(t0) (the start condition is applied on the host by rejection) and the first root. */
__kernel void ws_fresh(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                       __global const float* cdf, int nc, int M, __global const uint2* keys,
                       float t0, float t1, float tol, __global float* f0,
                       __global float4* hit)
{
    int r = get_global_id(0), status;
    float3 o = (float3)(0.0f), d = (float3)(1.0f, 0.0f, 0.0f), g, n;
    f0[r] = ws_eval(kp[0], mean, mc, cdf, nc, M, keys[r], 0, o + t0 * d, &g);
    float t = ws_first_root(kp[0], mean, mc, cdf, nc, M, keys[r], 0, o, d, t0, t1, tol, &n,
                            &status);
    hit[r] = status ? (float4)(NAN) : (float4)(n, t);
}
"""
M_FEATURES, N = 1024, 10_000
SE = SquaredExponential(sigma=1.0, length_scale=0.5)
# mean 3 - x along the ray (0,0,0) + t (1,0,0): the surface sits near t = 3
RAMP = Plane(point=(3.0, 0.0, 0.0), normal=(-1.0, 0.0, 0.0))


def test01_first_hit_and_normal_match_weight_space(device, flight_prg):
    """Two-sample KS on the hit distance and the three normal components (Bonferroni over
    4), global memory at the default adaptive step against M = 1024 features; a window
    of 6 samples (at least 3 kept) so that most rays slide it."""
    ws = build(device, WS_FRESH)
    f0, hit = run(device, ws["ws_fresh"], N, *gp_args(device, SE, RAMP), np.int32(M_FEATURES),
                  buffer(device, keys_for(N, 31)), np.float32(0.0), np.float32(6.0),
                  np.float32(1e-5), out_shapes=[((N,), np.float32), ((N, 4), np.float32)])
    assert not np.isnan(hit).any(), "weight-space root search failed"
    keep = f0 >= 0.0
    t_ws = np.where(hit[keep, 3] < 1e29, hit[keep, 3], -1.0)
    out = flights(device, flight_prg, SE, RAMP, N, memory="global", window=6, cap=64, seed=33)
    print(f"rays sliding the window: {np.mean(out[:, 6] - 6 > 6):.3f}")
    assert np.mean(out[:, 6] - 6 > 6) > 0.3, "most hits should slide the window"
    t_fs = out[:, 0]
    D, crit = ks_two_sample(t_fs, t_ws, 4)
    print(f"hit distance KS {D:.4f} (critical {crit:.4f})")
    assert D < crit
    hit_fs, hit_ws = t_fs >= 0, t_ws >= 0
    n_fs = out[hit_fs, 1:4] / np.linalg.norm(out[hit_fs, 1:4], axis=1, keepdims=True)
    for j in range(3):
        D, crit = ks_two_sample(n_fs[:, j], hit[keep][hit_ws, j], 4)
        assert D < crit, (j, D, crit)
