"""fs_linalg.h / fs_sampling.h conditioning on the device against numpy: conditional mean
and covariance of random value + directional-derivative systems, and whitened samples."""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp import Periodic
from gpiscl.host.gp import RationalQuadratic
from gpiscl.host.gp import Sphere
from gpiscl.host.gp import SquaredExponential
from gpiscl.host.gp import ThinPlate
from gpiscl.host.layout import gp_records
from gpiscl.testing.reference import function_space as FS
from gpiscl.host.layout import function_space_records as FL
from gpiscl.host.render.program_sources import fs_sampler_options
from gpiscl.testing.stats import chi2_threshold
from gpiscl.testing.wrappers import sampler_program

WRAPPERS = r"""
/* System s: rows [s * n, s * n + n) of `obs`, the first m observed. Out: conditional
 * means of the n - m targets, then their covariance (row-major), then status. */
__kernel void conditional(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                          __global const FsObs* obs, int n, int m, __global double* scratch,
                          __global double* out)
{
    int s = get_global_id(0), k = n - m;
    FsScratch S = fs_scratch(scratch, s);
    for (int i = 0; i < n; ++i) S.rows[i] = obs[s * n + i];
    __global double* o = out + s * (k + k * k + 1);
    int st = fs_factor(kp[0], mean, mc, S, 0, n);
    o[k + k * k] = st;
    if (st) return;
    for (int i = 0; i < m; ++i) fs_whiten_row(S.L, S.e, i, S.rows[i].value, S.mu[i]);
    for (int i = 0; i < k; ++i) {
        o[i] = fs_conditional_mean(S.L, S.e, m, m + i, S.mu[m + i]);
        for (int j = 0; j < k; ++j) o[k + i * k + j] = fs_conditional_cov(S.L, m, m + i, m + j);
    }
}

/* One system, draw `count` joint samples of its targets (one per work item). */
__kernel void draw(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                   __global const FsObs* obs, int n, int m, uint seed,
                   __global double* scratch, __global double* out)
{
    int s = get_global_id(0), k = n - m;
    FsScratch S = fs_scratch(scratch, s);
    for (int i = 0; i < n; ++i) S.rows[i] = obs[i];
    FsRng rng = {seed, (uint)s, 0u, 0u, 0u};
    if (fs_factor(kp[0], mean, mc, S, 0, n)) { out[s * k] = NAN; return; }
    for (int i = 0; i < m; ++i) fs_whiten_row(S.L, S.e, i, S.rows[i].value, S.mu[i]);
    for (int i = 0; i < k; ++i)
        out[s * k + i] = fs_sample_row(S.L, S.e, m + i, S.mu[m + i], fs_normal(rng, 0u, i));
}
"""
N_ROWS, N_OBSERVED = 12, 8
KERNELS = [SquaredExponential(1.0, 0.7, (1.0, 0.5, 2.0)), RationalQuadratic(0.5, 0.6, 0.75),
           ThinPlate(1.0, 2.5), Periodic(1.0, 1.5, 0.3)]
MEAN = Sphere(center=(0.1, -0.2, 0.3), radius=0.6)


@pytest.fixture(scope="module")
def prg(device):
    return sampler_program(device.ctx, WRAPPERS, fs_sampler_options(N_ROWS, 2, 0))


def random_systems(rng, kernel, count):
    """Observed rows drawn from the prior (so the values are typical), targets after."""
    x = rng.uniform(-1, 1, (count, N_ROWS, 3))
    u = rng.normal(size=(count, N_ROWS, 3))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    deriv = rng.random((count, N_ROWS)) < 0.4
    obs = FL.FS_OBS.zeros(count * N_ROWS).reshape(count, N_ROWS)
    laws = []
    for s in range(count):
        K, mu = FS.observation_matrix(kernel, MEAN, x[s], u[s], deriv[s])
        y = mu + np.linalg.cholesky(FS.jittered(K)) @ rng.standard_normal(N_ROWS)
        o = obs[s]
        for j, name in enumerate(("px", "py", "pz")):
            o[name] = x[s, :, j]
        for j, name in enumerate(("ux", "uy", "uz")):
            o[name] = u[s, :, j]
        o["kind"] = deriv[s].astype(np.int32)
        o["value"] = y
        laws.append((K, mu, y))
    return obs, laws


def _buf(device, a):
    return cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(a))


def _gp(device, kernel):
    nodes = gp_records.pack_mean(MEAN)
    return (_buf(device, gp_records.pack_kernel(kernel)), _buf(device, nodes),
            np.int32(len(nodes)))


def _scratch(device, items):
    stride = FL.scratch_doubles(FL.max_rows(N_ROWS, 2, 0))
    assert stride >= FL.scratch_doubles(N_ROWS)
    return cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE, 8 * stride * items)


@pytest.mark.parametrize("kernel", KERNELS, ids=["se-aniso", "rq", "thin_plate", "periodic"])
def test01_conditional_mean_and_covariance_match_numpy(device, prg, kernel):
    """200 random systems of 8 observed (values and derivatives, each with its own
    direction) and 4 targets: 1e-6 relative to the prior standard deviations."""
    count, k = 200, N_ROWS - N_OBSERVED
    obs, laws = random_systems(np.random.default_rng(3), kernel, count)
    out = np.empty((count, k + k * k + 1))
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["conditional"](device.queue, (count,), None, *_gp(device, kernel), _buf(device, obs),
                       np.int32(N_ROWS), np.int32(N_OBSERVED), _scratch(device, count), ob)
    cl.enqueue_copy(device.queue, out, ob)
    assert np.all(out[:, -1] == 0), "a solve failed"
    for s, (K, mu, y) in enumerate(laws):
        mean, cov = FS.conditional(K, mu, y[:N_OBSERVED], N_OBSERVED)
        scale = np.sqrt(np.diag(K)[N_OBSERVED:])
        np.testing.assert_allclose(out[s, :k] / scale, mean / scale, rtol=0, atol=1e-6)
        np.testing.assert_allclose(out[s, k:-1].reshape(k, k) / np.outer(scale, scale),
                                   cov / np.outer(scale, scale), rtol=0, atol=1e-6)


@pytest.mark.parametrize("kernel", KERNELS[:2], ids=["se-aniso", "rq"])
def test02_whitened_samples_are_standard_normal(device, prg, kernel):
    """Device draws of the targets, whitened with numpy's conditional law: each whitened
    coordinate and the quadratic form z'z ~ chi2(4) are checked by binned chi-square
    tests on equiprobable bins."""
    from statistics import NormalDist
    draws, k = 50_000, N_ROWS - N_OBSERVED
    obs, laws = random_systems(np.random.default_rng(5), kernel, 1)
    out = np.empty((draws, k))
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["draw"](device.queue, (draws,), None, *_gp(device, kernel), _buf(device, obs[0]),
                np.int32(N_ROWS), np.int32(N_OBSERVED), np.uint32(9), _scratch(device, draws),
                ob)
    cl.enqueue_copy(device.queue, out, ob)
    K, mu, y = laws[0]
    mean, cov = FS.conditional(K, mu, y[:N_OBSERVED], N_OBSERVED)
    z = np.linalg.solve(np.linalg.cholesky(cov), (out - mean).T).T
    bins, tests = 20, k + 1
    nd = NormalDist()
    pits = [np.array([nd.cdf(v) for v in z[:, j]]) for j in range(k)]
    q = np.sum(z * z, axis=1)   # chi2(4): survival (1 + q/2) exp(-q/2)
    pits.append(1.0 - (1.0 + q / 2) * np.exp(-q / 2))
    for pit in pits:
        counts = np.bincount(np.minimum((pit * bins).astype(int), bins - 1), minlength=bins)
        chi2 = np.sum((counts - draws / bins) ** 2 / (draws / bins))
        assert chi2 < chi2_threshold(bins - 1, tests * len(KERNELS[:2]))
    assert abs(np.corrcoef(z.T)[np.triu_indices(k, 1)]).max() < 5 / math.sqrt(draws)
