"""Spatially varying sigma(x) and l(x) (kernels.NonStationary, gp_kernel.h gp_cov_ns):
derivative covariances against finite differences, positive definiteness, the stationary
limit, device against numpy, joint samples against the model, Rice's rate where l(x) is
constant, the scene rules and a white furnace render."""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl import render_result
from gpiscl.host.gp import Constant
from gpiscl.host.gp import Matern32, Matern52, RationalQuadratic
from gpiscl.host.gp import Sphere
from gpiscl.host.gp import SquaredExponential
from gpiscl.host.layout import gp_records
from gpiscl.host.layout import function_space_records as FL
from gpiscl.host.render.program_sources import fs_sampler_options
from gpiscl.host.gp.kernels import (GridField, LinearField, LocallyPeriodic, NonStationary,
                                    Periodic, RadialField, ThinPlate, covariance_matrix)
from gpiscl.host.compile.gpis import build_kernel
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene
from gpiscl.testing.stats import assert_agree, z_threshold
from gpiscl.testing.flights import CAP_MAX, FLIGHT_WRAPPERS, WINDOW_MAX, flights
from gpiscl.testing.wrappers import GP_COVARIANCE_WRAPPER, sampler_program

EXTRA = GP_COVARIANCE_WRAPPER + r"""
/* One joint draw per item of n fixed observations (values and derivatives) through the
 * free-flight sampler's factor and row sampler. */
__kernel void joint(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                    __global const double* x, __global const double* u,
                    __global const int* kind, int n, uint seed, int first,
                    __global double* scratch, __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    for (int k = 0; k < n; ++k) S.rows[k] = fs_obs(vload3(k, x), vload3(k, u), kind[k], 0.0);
    int st = fs_factor(kp[0], mean, mc, S, 0, n);
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    for (int k = 0; k < n; ++k)
        out[(size_t)i * n + k] = st ? NAN
            : fs_sample_row(S.L, S.e, k, S.mu[k], fs_normal(rng, 0u, (uint)k));
}

/* The kernel's field multipliers (grid fields read from `nodes`) at x, and the four
 * covariances of test04 with them. */
__kernel void fields_at(__global const GpKernel* kp, __global const MeanNode* nodes,
                        __global const double* x, __global double* out)
{
    int i = get_global_id(0);
    GpFieldsAt f = fs_fields(kp[0], nodes, vload3(i, x));
    __global double* o = out + 8 * i;
    o[0] = f.ms;
    vstore3(f.gs, 0, o + 1);
    o[4] = f.ml;
    vstore3(f.gl, 0, o + 5);
}

/* The renewal memory's start at a vertex x with f(x) = 0 leaving along d: the slope it
 * draws (row 1 of the conditioning set) per item. */
__kernel void renewal_slope(__global const GpKernel* kp, __global const MeanNode* mean,
                            int mc, __global const double* xd, uint seed, int first,
                            __global double* scratch, __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    FsParams prm = {0, GPIS_MEMORY_RENEWAL, 8, 0, 0.0, 1e-5};
    double3 x = vload3(0, xd), d = vload3(1, xd);
    FsRay r = {x, d, 0.0, 1.0};
    FsVertex v = {0};
    v.pos = (float4)(convert_float3(x), 0.0f);
    v.valid = 1;
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    double f0;
    int outside, n_old;
    fs_begin(kp[0], mean, mc, prm, r, v, 0, rng, S, &f0, &outside, &n_old);
    out[i] = S.rows[1].value;
}

__kernel void covariances_at(__global const GpKernel* kp, __global const MeanNode* nodes,
                             __global const double* a, __global const double* u,
                             __global const double* b, __global const double* v,
                             __global double* out)
{
    int i = get_global_id(0);
    GpKernel p = kp[0];
    double3 A = vload3(i, a), U = vload3(i, u), B = vload3(i, b), V = vload3(i, v);
    GpFieldsAt fa = fs_fields(p, nodes, A), fb = fs_fields(p, nodes, B);
    __global double* o = out + 4 * i;
    for (int k = 0; k < 4; ++k) o[k] = gp_cov_at(p, A, U, k & 1, fa, B, V, k >> 1, fb);
}
"""

# Parameters exact in float32 (GpKernel stores float), so host and device agree to double.
ANISO = (1.0, 0.5, 2.0)
LIN = LinearField(value=1.0, gradient=(0.25, -0.125, 0.1875), origin=(0.125, 0.0, -0.25))
RAD = RadialField(center=(0.125, 0.25, -0.125), radius=0.625, width=0.25, inner=0.5,
                  outer=1.5)
SE = SquaredExponential(sigma=1.25, length_scale=0.75, aniso=ANISO)
RQ = RationalQuadratic(sigma=0.875, length_scale=1.125, alpha=0.625, aniso=ANISO)
CASES = {
    "se-sigma-linear": NonStationary(SE, sigma_field=LIN),
    "se-l-radial": NonStationary(SE, length_scale_field=RAD),
    "se-both": NonStationary(SE, sigma_field=RAD, length_scale_field=LIN,
                             step_length_scale=0.25),
    "rq-both": NonStationary(RQ, sigma_field=LIN, length_scale_field=RAD),
    "periodic-sigma": NonStationary(Periodic(1.125, 0.875, 0.625, ANISO), sigma_field=RAD),
    "lp-sigma": NonStationary(LocallyPeriodic(0.75, 1.25, 0.5, 1.5, ANISO), sigma_field=LIN),
    "thin-plate-sigma": NonStationary(ThinPlate(0.5, 4.0, ANISO), sigma_field=RAD),
    "m32-sigma": NonStationary(Matern32(1.125, 0.875, ANISO), sigma_field=RAD),
    "m52-sigma": NonStationary(Matern52(0.75, 1.25, ANISO), sigma_field=LIN),
}


def _points(rng, n):
    """Pairs in [-1, 1]^3 (where LIN stays positive: its minimum there is 0.45) with
    random unit directions; a quarter of the pairs coincide (a = b: variances)."""
    a, b = rng.uniform(-1, 1, (2, n, 3))
    b[: n // 4] = a[: n // 4]
    u, v = rng.normal(size=(2, n, 3))
    return a, u / np.linalg.norm(u, axis=1)[:, None], b, v / np.linalg.norm(v, axis=1)[:, None]


@pytest.fixture(scope="module")
def prg(device):
    return sampler_program(device.ctx, FLIGHT_WRAPPERS + EXTRA,
                           fs_sampler_options(WINDOW_MAX, CAP_MAX))


def _buf(device, a):
    return cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(a))


def _device_cov(device, prg, kernel, a, u, b, v):
    n = len(a)
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 64 * n)
    prg["covariances"](device.queue, (n,), None, _buf(device, gp_records.pack_kernel(kernel)),
                       *(_buf(device, np.asarray(x, np.float64)) for x in (a, u, b, v)), out)
    res = np.empty((n, 8))
    cl.enqueue_copy(device.queue, res, out)
    return res


@pytest.mark.parametrize("name", CASES)
def test01_derivative_covariances_are_derivatives_of_the_value_covariance(name):
    """Central differences of k(a, b) in a along u and in b along v (h = 1e-4: truncation
    and rounding both ~1e-8 of the scale sqrt(var_a var_b)); a quarter of the pairs have
    a = b, where the field terms of the variances are checked."""
    K = CASES[name]
    a, u, b, v = _points(np.random.default_rng(1), 64)
    h = 1e-4
    c = K.cov
    fd_dv = (c(a + h * u, b) - c(a - h * u, b)) / (2 * h)
    fd_vd = (c(a, b + h * v) - c(a, b - h * v)) / (2 * h)
    fd_dd = (c(a + h * u, b + h * v) - c(a + h * u, b - h * v)
             - c(a - h * u, b + h * v) + c(a - h * u, b - h * v)) / (4 * h * h)
    scale_v = np.sqrt(c(a, a) * c(b, b))
    scale_d = np.sqrt(K.cov_dd(a, u, a, u) * K.cov_dd(b, v, b, v))
    scale_m = np.sqrt(scale_v * scale_d)
    np.testing.assert_array_less(np.abs(fd_dv - K.cov_dv(a, u, b)), 1e-6 * scale_m)
    np.testing.assert_array_less(np.abs(fd_vd - K.cov_vd(a, b, v)), 1e-6 * scale_m)
    # thin-plate's and Matern 3/2's rho^3 terms have a Hessian of O(rho): at a = b
    # central differences err O(h)
    ok = slice(16, None) if "thin" in name or "m32" in name else slice(None)
    np.testing.assert_array_less(np.abs(fd_dd - K.cov_dd(a, u, b, v))[ok], 1e-5 * scale_d[ok])
    # symmetry: cov(d_u f(a), f(b)) = cov(f(b), d_u f(a))
    np.testing.assert_allclose(K.cov_dv(a, u, b), K.cov_vd(b, a, u), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", [n for n in CASES if "thin" not in n])
def test02_joint_value_gradient_covariances_are_positive_definite(name):
    """50 points (l(x) varies by 3x across them), 30 values and 20 derivative rows:
    Cholesky succeeds and the smallest eigenvalue is >= 0 to rounding."""
    K = CASES[name]
    rng = np.random.default_rng(2)
    for trial in range(5):
        x = rng.uniform(-1, 1, (50, 3)) * 1.5
        u = rng.normal(size=(50, 3))
        u /= np.linalg.norm(u, axis=1)[:, None]
        u[:30] = np.nan
        C = covariance_matrix(K, x, u1=u)
        np.testing.assert_allclose(C, C.T, rtol=1e-12, atol=1e-14)
        np.linalg.cholesky(C)
        w = np.linalg.eigvalsh(C)
        assert w[0] >= -1e-12 * w[-1], (trial, w[0], w[-1])


def test03_constant_fields_are_the_stationary_kernel(device, prg):
    """m = 1 reproduces the stationary kernel to rounding (host and device: the
    Paciorek-Schervish prefactor is exactly 1, the derivative terms take another
    algebraic path); a constant
    m_s = c gives c^2 k, a constant m_l = c the kernel with length scale c l."""
    a, u, b, v = _points(np.random.default_rng(3), 128)
    x = np.concatenate([a[:10], b[:10]])
    dirs = np.concatenate([u[:10], np.full((10, 3), np.nan)])
    one_lin, one_rad = LinearField(1.0), RadialField(radius=1.0, width=0.5, inner=1.0, outer=1.0)
    for base, cls in ((SE, SquaredExponential), (RQ, RationalQuadratic)):
        ns = NonStationary(base, sigma_field=one_rad, length_scale_field=one_lin,
                           step_length_scale=base.length_scale)
        ref = covariance_matrix(base, x, u1=dirs)
        np.testing.assert_allclose(covariance_matrix(ns, x, u1=dirs), ref, rtol=1e-13,
                                   atol=1e-14 * np.abs(ref).max())
        ref = _device_cov(device, prg, base, a, u, b, v)
        np.testing.assert_allclose(_device_cov(device, prg, ns, a, u, b, v), ref, rtol=1e-13,
                                   atol=1e-14 * np.abs(ref).max())
        c = 1.5
        scaled = NonStationary(base, sigma_field=LinearField(c),
                               length_scale_field=RadialField(radius=1.0, width=0.5,
                                                              inner=c, outer=c))
        params = {k: getattr(base, k) for k in base.__dataclass_fields__}
        ref = cls(**{**params, "sigma": c * base.sigma, "length_scale": c * base.length_scale})
        np.testing.assert_allclose(covariance_matrix(scaled, x, u1=dirs),
                                   covariance_matrix(ref, x, u1=dirs), rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("name", CASES)
def test04_device_matches_numpy(device, prg, name):
    """Double build, 256 random pairs: every entry to 1e-9 of its scale (the
    Cauchy-Schwarz bound sqrt(var_a var_b) of the same pair of observations)."""
    K = CASES[name]
    a, u, b, v = _points(np.random.default_rng(4), 256)
    dev = _device_cov(device, prg, K, a, u, b, v)
    vv, dv, vd, dd = K._terms(a, u, b, v)
    sa, sb = np.sqrt(K.cov(a, a)), np.sqrt(K.cov(b, b))
    ga, gb = np.sqrt(K.cov_dd(a, u, a, u)), np.sqrt(K.cov_dd(b, v, b, v))
    for j, (ref, scale) in enumerate([(vv, sa * sb), (dv, ga * sb), (vd, sa * gb),
                                      (dd, ga * gb)] * 2):
        err = np.abs(dev[:, j] - ref) / scale
        assert err.max() < 1e-9, (j, err.max())


def _kernel_and_nodes(kernel, mean=Constant(0.0)):
    """The packed kernel and a mean program followed by the kernel's grid-field records,
    laid out as the scene compiler does."""
    kp = gp_records.pack_kernel(kernel)
    nodes = gp_records.pack_mean(mean)
    grids = gp_records.pack_kernel_grids(kernel, kp, len(nodes))
    return kp, np.concatenate([nodes, *grids]), len(nodes)


def _joint(device, prg, kernel, x, u, kind, n_draws, seed):
    n = len(x)
    kp, nodes, mc = _kernel_and_nodes(kernel)
    stride = FL.scratch_doubles(FL.max_rows(WINDOW_MAX, CAP_MAX))
    assert n <= FL.max_rows(WINDOW_MAX, CAP_MAX)
    chunk = 1024
    scratch = cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE, 8 * stride * chunk)
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * n * chunk)
    args = [_buf(device, kp), _buf(device, nodes),
            np.int32(mc), _buf(device, x.astype(np.float64)),
            _buf(device, u.astype(np.float64)), _buf(device, kind.astype(np.int32)),
            np.int32(n), np.uint32(seed)]
    res = np.empty((n_draws, n))
    for first in range(0, n_draws, chunk):
        m = min(chunk, n_draws - first)
        prg["joint"](device.queue, (m,), None, *args, np.int32(first), scratch, out)
        cl.enqueue_copy(device.queue, res[first:first + m], out)
    return res


def _sampled(field, origin, h, n):
    """A grid field holding field's values at the samples of an n^3 grid."""
    idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1)
    return GridField(field.eval(np.asarray(origin) + h * idx)[0], tuple(origin), h)


_SIGMA_BLEND = RadialField((0.0, 0.0, 0.0), 0.75, 0.25, 2.0, 0.5)
_L_BLEND = RadialField((0.0, 0.25, 0.0), 0.5, 0.25, 0.5, 1.0)
JOINT_CASES = {
    "radial": (_SIGMA_BLEND, _L_BLEND),
    # the same blends sampled every 0.125 on [-2, 2]^3 (33^3 samples, trilinear)
    "grid": (_sampled(_SIGMA_BLEND, (-2.0,) * 3, 0.125, 33),
             _sampled(_L_BLEND, (-2.0,) * 3, 0.125, 33)),
}


@pytest.mark.parametrize("fields", JOINT_CASES)
def test05_joint_samples_have_the_model_variance_and_covariance(device, prg, fields):
    """Values and slopes at 24 fixed points along a ray through a sigma(x) and l(x)
    blend (analytic, or trilinear grid fields read from the mean-node array), jointly
    drawn by the free-flight factor/sampler in 20000 items: the per-point variance
    matches sigma(x)^2 (resp. the slope variance), and the draws whitened by the numpy
    covariance are uncorrelated standard normals (chi-square over all entries)."""
    sf, lf = JOINT_CASES[fields]
    K = NonStationary(SquaredExponential(1.0, 0.5), sigma_field=sf, length_scale_field=lf)
    t = np.linspace(-1.5, 1.5, 16)
    line = np.stack([t, np.full(16, 0.125), np.zeros(16)], 1)
    x = np.concatenate([line, line[::2]])         # values at 16 points, slopes at 8
    d = np.array([1.0, 0.0, 0.0])
    u = np.tile(d, (len(x), 1))
    kind = np.r_[np.zeros(16, int), np.ones(8, int)]
    n_draws = 20000
    f = _joint(device, prg, K, x, u, kind, n_draws, seed=5 + len(fields))
    assert np.all(np.isfinite(f))
    C = covariance_matrix(K, x, u1=np.where(kind[:, None] == 1, u, np.nan))
    var = np.diag(C)
    sigma2 = K.cov(x[:16], x[:16])
    m_s = K.sigma_field.eval(x[:16])[0]
    np.testing.assert_allclose(sigma2, m_s**2, rtol=1e-12)   # sigma = 1: var = m_s(x)^2
    # sample variance: (n-1) s^2 / var ~ chi2(n-1), ~normal with sd var sqrt(2 / (n-1))
    z = (f.var(axis=0, ddof=1) - var) / (var * math.sqrt(2.0 / (n_draws - 1)))
    tz = z_threshold(len(x) + 2)
    assert np.abs(z).max() < tz, z
    assert np.abs(f.mean(axis=0) / np.sqrt(var / n_draws)).max() < tz
    L = np.linalg.cholesky(C + 1e-12 * np.mean(var) * np.eye(len(x)))
    w = np.linalg.solve(L, f.T)                   # (n, draws): standard normal, independent
    cov_w = w @ w.T / n_draws
    off = cov_w[np.triu_indices(len(x), 1)] * math.sqrt(n_draws)
    assert np.abs(off).max() < tz * 1.2, np.abs(off).max()   # Bonferroni over ~n^2/2: loose
    chi2 = np.sum(w * w)
    dof = w.size
    assert abs(chi2 - dof) < tz * math.sqrt(2 * dof), (chi2, dof)


def test06_step_rule_uses_the_smallest_length_scale_on_the_segment(device, prg):
    """sigma(x) alone keeps the stationary step; l(x) steps with the smallest l on the ray's
    segment (linear: at an end; radial: nearest to or farthest from the centre), never
    below ls_step; a grid field with its smallest sample."""
    d = np.array([0.6, 0.0, 0.8]) * 1.5
    base = SquaredExponential(1.0, 0.75)
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8)
    far = np.array([3.0, 0.0, 0.0])              # a segment away from RAD's centre
    grid = _sampled(LIN, (-1.0, -1.0, -1.0), 0.5, 5)
    cases = [
        (NonStationary(base, sigma_field=RAD), np.zeros(3), 0.75),
        # through RAD's inner ball (inner 0.5 < outer 1.5): the minimum is nearest its centre
        (NonStationary(base, length_scale_field=RAD), np.zeros(3),
         0.75 * float(RAD.eval(np.zeros(3) + d * np.clip(
             np.dot(np.asarray(RAD.center), d) / np.dot(d, d), 0, 1))[0])),
        (NonStationary(base, length_scale_field=RAD), far,
         0.75 * float(RAD.eval(far)[0])),
        # linear: the smaller end, above ls_step = 0.25
        (NonStationary(base, length_scale_field=LIN, step_length_scale=0.25), np.zeros(3),
         0.75 * min(float(LIN.eval(np.zeros(3))[0]), float(LIN.eval(d)[0]))),
        (NonStationary(base, length_scale_field=grid), np.zeros(3), 0.75 * grid.minimum()),
    ]
    for kern, o, l in cases:
        kp = gp_records.pack_kernel(kern)
        prg["step_rule"](device.queue, (1,), None, _buf(device, kp),
                         _buf(device, np.r_[o, d]), np.float64(0.9), out)
        dt = np.empty(1)
        cl.enqueue_copy(device.queue, dt, out)
        assert abs(dt[0] - l * math.sqrt(-2 * math.log(0.9)) / 1.5) < 1e-6 * dt[0], (kern, l)


def test07_rice_rate_where_the_length_scale_is_constant(device, prg):
    """l(x) = 0.25 inside a sphere of radius 6 and 0.5 outside (blend width 0.2): a
    continued ray (global memory, mean 0) inside the sphere, and one far outside it, each
    cross level 0 at Rice's rate L / (2 pi l_local) per ray (+1/4 from f(0) >= 0) at the
    default miss tolerance. Outside, the rays are also traced with the stationary kernel
    at l = 0.5 and the same random numbers: the adaptive rule sees the same conditional
    moments, so the counts agree ray by ray but for rounding-level flips at near-tangent
    crossings."""
    K = NonStationary(SquaredExponential(1.0, 0.5),
                      length_scale_field=RadialField((0.0, 0.0, 0.0), 6.0, 0.2, 0.5, 1.0))
    n, L = 600, 8.0
    for o, l_local in (((-4.0, 0.0, 0.0), 0.25), ((-4.0, 9.0, 0.0), 0.5)):
        out = flights(device, prg, K, Constant(0.0), n, memory="global", cap=64, o=o, t1=L,
                      seed=21, restarts=200)
        counts = out[:, 4]
        rate = L / (2 * math.pi * l_local) + 0.25
        se = counts.std(ddof=1) / math.sqrt(n)
        z = z_threshold(2)
        print(f"l = {l_local}: crossings per ray {counts.mean():.3f} +- {se:.3f}, "
              f"Rice {rate:.3f}")
        assert abs(counts.mean() - rate) < z * se
    ref = flights(device, prg, SquaredExponential(1.0, 0.5), Constant(0.0), n, memory="global",
                  cap=64, o=o, t1=L, seed=21, restarts=200)
    same = np.mean(ref[:, 4] == counts)
    print(f"same count as the stationary kernel on {same:.1%} of the rays")
    assert same > 0.95


def _gpis(sampler, kernel, proxy=None):
    g = {"type": "gpis", "proxy": proxy or {"type": "box", "min": [-1.1] * 3, "max": [1.1] * 3},
         "mean": {"type": "sphere", "radius": 0.7}, "kernel": kernel, "sampler": sampler}
    return {"shapes": [g], "lights": [{"type": "environment"}]}


def test08_scene_rules():
    field = {"type": "radial", "radius": 0.5, "width": 0.1, "inner": 0.5, "outer": 1.0}
    kern = {"type": "squared_exponential", "sigma": 0.3, "length_scale": 0.2}
    for key in ("sigma_field", "length_scale_field"):
        with pytest.raises(SceneError) as e:
            load_scene(_gpis({"type": "weight_space"}, {**kern, key: field}))
        assert e.value.key == f"shapes[0].kernel.{key}"
        assert "weight space samples stationary kernels only" in e.value.reason
    # a linear field must stay positive over the proxy (min over the box: 1 - 0.5*1.1*3)
    lin = {"type": "linear", "value": 1.0, "gradient": [0.5, 0.5, 0.5]}
    with pytest.raises(SceneError) as e:
        load_scene(_gpis({"type": "function_space"}, {**kern, "sigma_field": lin}))
    assert e.value.key == "shapes[0].kernel.sigma_field" and "-0.65" in e.value.reason
    with pytest.raises(SceneError) as e:          # no l(x) on thin-plate
        load_scene(_gpis({"type": "function_space"},
                         {"type": "thin_plate", "radius": 4.0, "length_scale_field": field}))
    assert e.value.key == "shapes[0].kernel.length_scale_field"
    lin = {"type": "linear", "value": 1.0, "gradient": [0.25, 0.0, 0.0]}
    s = load_scene(_gpis({"type": "function_space"}, {**kern, "length_scale_field": lin}))
    g = s.data["shapes"][0]
    k = build_kernel(g["kernel"], g["proxy"])
    assert abs(k.step_length_scale - 0.2 * (1 - 0.25 * 1.1)) < 1e-12
    assert gp_records.pack_kernel(k)["ls_field"] == gp_records.FIELD_KINDS["linear"]


@pytest.mark.parametrize("bsdf, memory", [("mirror", "renewal_plus"), ("diffuse", "global")])
def test09_white_furnace_with_a_varying_sigma(device, bsdf, memory):
    """A rough ball whose sigma(x) = 0.3 + 0.1 x (0.19..0.41 in the proxy) and l(x)
    blends 0.15 -> 0.25: albedo 1 in a unit environment gives 1, with no failed solve.
    The mirror gives exactly 1 per path; the diffuse BSDF (NEE + MIS, shadow rays through
    the same memory) is z-tested per 4x4 block."""
    kern = {"type": "squared_exponential", "sigma": 1.0, "length_scale": 1.0,
            "sigma_field": {"type": "linear", "value": 0.3, "gradient": [0.1, 0.0, 0.0]},
            "length_scale_field": {"type": "radial", "center": [0.3, 0.3, 0.3], "radius": 0.5,
                                   "width": 0.2, "inner": 0.15, "outer": 0.25}}
    scene = _gpis({"type": "function_space", "memory": memory}, kern)
    scene["shapes"][0]["bsdf"] = {"type": bsdf, "albedo": 1.0}
    scene["camera"] = {"position": [0, 0, 3.0], "look_at": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 40, "resolution": [12, 12]}
    scene["render"] = {"spp": 4, "seed": 3, "max_depth": 256,
                       "russian_roulette": {"start_depth": 100000}}
    res = render_result(scene, device=device)
    st = res.stats
    assert st.gpis_failed == 0 and st.nan_paths == 0 and st.truncated_paths == 0, st.summary()
    assert st.killed_paths == 0, st.summary()
    assert st.rays > 1.5 * st.paths, st.summary()     # the ball is hit
    if bsdf == "mirror":
        np.testing.assert_allclose(res.image.mean, 1.0, rtol=1e-5)
        assert np.all(res.image.stderr == 0)
    else:
        img = res.image
        assert_agree(img.mean, img.stderr, np.ones_like(img.mean), block=4, what="furnace")


# --- grid fields ------------------------------------------------------------------------

GRID_ORIGIN, GRID_H = (-0.8, -0.9, -0.7), 0.4     # 5 x 6 x 4 samples: [-0.8, 0.8] x ...


def _random_grid(seed, lo, hi):
    rng = np.random.default_rng(seed)
    return GridField(rng.uniform(lo, hi, (5, 6, 4)), GRID_ORIGIN, GRID_H)


def _device_fields(device, prg, kernel, x):
    kp, nodes, _ = _kernel_and_nodes(kernel)
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 64 * len(x))
    prg["fields_at"](device.queue, (len(x),), None, _buf(device, kp), _buf(device, nodes),
                     _buf(device, np.asarray(x, np.float64)), out)
    res = np.empty((len(x), 8))
    cl.enqueue_copy(device.queue, res, out)
    return res


def test10_grid_fields_are_trilinear_with_the_border_held(device, prg):
    """Host: a grid sampled from a linear field reproduces it (value and gradient) inside
    the sample box, and outside holds the clamped point's value with a zero gradient
    along every clamped axis; the gradient inside equals central differences. Device
    (fs_fields, float samples): the host's values to 1e-6 of the largest sample and the
    gradients to 1e-6 of the largest sample per voxel (float32 storage, ~10 roundings)."""
    lin = LinearField(1.0, (0.25, -0.5, 0.375), (0.1, 0.2, -0.3))
    grid = _sampled(lin, GRID_ORIGIN, GRID_H, 5)
    rng = np.random.default_rng(10)
    inside = np.asarray(GRID_ORIGIN) + rng.uniform(0, 4 * GRID_H, (200, 3))
    m, g = grid.eval(inside)
    ml, gl = lin.eval(inside)
    np.testing.assert_allclose(m, ml, rtol=1e-12)
    np.testing.assert_allclose(g, gl, rtol=1e-12)
    far = inside.copy()
    far[:, 0] = 5.0                               # beyond the +x face
    m_far, g_far = grid.eval(far)
    clamp = inside.copy()
    clamp[:, 0] = GRID_ORIGIN[0] + 4 * GRID_H
    np.testing.assert_allclose(m_far, grid.eval(clamp)[0], rtol=1e-12)
    assert np.all(g_far[:, 0] == 0) and np.allclose(g_far[:, 1:], gl[:, 1:], rtol=1e-12)

    rough = _random_grid(11, 0.5, 2.0)
    h = 1e-6
    fd = np.stack([(rough.eval(inside + h * e)[0] - rough.eval(inside - h * e)[0]) / (2 * h)
                   for e in np.eye(3)], 1)
    # a point within h of a cell face may difference across it: skip those
    u = (inside - np.asarray(GRID_ORIGIN)) / GRID_H
    away = np.all(np.abs(u - np.round(u)) > 1e-4, axis=1)
    np.testing.assert_allclose(fd[away], rough.eval(inside[away])[1], rtol=1e-6, atol=1e-6)

    K = NonStationary(SE, sigma_field=rough, length_scale_field=_random_grid(12, 0.25, 1.5))
    pts = rng.uniform(-1.5, 1.5, (400, 3))       # half of them outside the sample box
    dev = _device_fields(device, prg, K, pts)
    for field, cols in ((K.sigma_field, slice(0, 4)), (K.length_scale_field, slice(4, 8))):
        m, g = field.eval(pts)
        top = field.maximum()
        assert np.abs(dev[:, cols][:, 0] - m).max() < 1e-6 * top
        assert np.abs(dev[:, cols][:, 1:] - g).max() < 1e-6 * top / GRID_H


@pytest.mark.parametrize("base", [SE, RQ])
def test11_grid_field_covariances_on_the_device_match_numpy(device, prg, base):
    """Random grid fields for sigma(x) and l(x) (a factor 4 and 6 across the grid), pairs
    inside and outside the sample box: every covariance entry to 1e-5 of its
    Cauchy-Schwarz scale. The fields agree to ~1e-6 relative (test10); a covariance's
    logarithmic sensitivity to them is 1 per m_s and 3/2 + 2 s/S per m_l, <= 10 here."""
    K = NonStationary(base, sigma_field=_random_grid(13, 0.5, 2.0),
                      length_scale_field=_random_grid(14, 0.25, 1.5))
    a, u, b, v = _points(np.random.default_rng(15), 256)
    a, b = 1.4 * a, 1.4 * b
    kp, nodes, _ = _kernel_and_nodes(K)
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 32 * len(a))
    prg["covariances_at"](device.queue, (len(a),), None, _buf(device, kp), _buf(device, nodes),
                          *(_buf(device, np.asarray(x, np.float64)) for x in (a, u, b, v)),
                          out)
    dev = np.empty((len(a), 4))
    cl.enqueue_copy(device.queue, dev, out)
    vv, dv, vd, dd = K._terms(a, u, b, v)
    sa, sb = np.sqrt(K.cov(a, a)), np.sqrt(K.cov(b, b))
    ga, gb = np.sqrt(K.cov_dd(a, u, a, u)), np.sqrt(K.cov_dd(b, v, b, v))
    for j, (ref, scale) in enumerate([(vv, sa * sb), (dv, ga * sb), (vd, sa * gb),
                                      (dd, ga * gb)]):
        err = np.abs(dev[:, j] - ref) / scale
        assert err.max() < 1e-5, (j, err.max())
    C = covariance_matrix(K, np.concatenate([a[:40], b[:20]]),
                          u1=np.concatenate([np.full((40, 3), np.nan), v[:20]]))
    assert np.linalg.eigvalsh(C)[0] >= -1e-12 * np.abs(C).max()   # PD with kinks in m


def _save_field_grid(path, values, origin=(-1.2, -1.2, -1.2), h=0.6):
    np.savez(path, values=values, origin=np.asarray(origin, float), voxel_size=np.float64(h))
    return str(path)


def test12_grid_field_scene_rules(tmp_path):
    """Bad grids name the file key and the reason; weight space refuses a grid field;
    the occupancy bound uses the grid's largest sigma and the step rule its smallest l."""
    from gpiscl.host.compile.gpis import occupancy_level
    kern = {"type": "squared_exponential", "sigma": 0.3, "length_scale": 0.2}
    good = np.full((5, 5, 5), 1.0)
    bad = {"shape": (np.ones((5, 5)), "3-D (nx, ny, nz)"),
           "nan": (np.where(np.arange(125).reshape(5, 5, 5) == 7, np.nan, good), "NaN"),
           "negative": (good - 1.5, "must be > 0"),
           "zero": (np.zeros((5, 5, 5)), "must be > 0")}
    for key in ("sigma_field", "length_scale_field"):
        for name, (values, reason) in bad.items():
            path = _save_field_grid(tmp_path / f"{key}_{name}.npz", values)
            with pytest.raises(SceneError) as e:
                load_scene(_gpis({"type": "function_space"},
                                 {**kern, key: {"type": "grid", "file": path}}))
            assert e.value.key == f"shapes[0].kernel.{key}.file", (name, e.value.key)
            assert reason in e.value.reason, (name, e.value.reason)
    values = good.copy()
    values[1, 2, 3], values[3, 1, 0] = 2.5, 0.4
    path = _save_field_grid(tmp_path / "ok.npz", values)
    with pytest.raises(SceneError) as e:
        load_scene(_gpis({"type": "weight_space"},
                         {**kern, "sigma_field": {"type": "grid", "file": path}}))
    assert "weight space samples stationary kernels only" in e.value.reason
    s = load_scene(_gpis({"type": "function_space"},
                         {**kern, "sigma_field": {"type": "grid", "file": path},
                          "length_scale_field": {"type": "grid", "file": path}}))
    g = s.data["shapes"][0]
    stationary = occupancy_level({**g, "kernel": kern})
    assert abs(occupancy_level(g) / stationary - 2.5) < 1e-6
    k = build_kernel(g["kernel"], g["proxy"])
    assert abs(k.step_length_scale - 0.2 * 0.4) < 1e-12
    packed = gp_records.pack_kernel(k)
    assert packed["sigma_field"] == packed["ls_field"] == gp_records.FIELD_KINDS["grid"]


def test13_a_grid_sampled_from_a_linear_field_renders_like_it(device, tmp_path):
    """sigma(x) = 0.3 + 0.1 x and l(x) = 0.2 + 0.05 y given analytically, and as grids of
    their samples (trilinear reproduces them exactly up to float32 storage). With the
    same l grid, the sigma grid and the linear sigma draw the same realizations from the
    same seed, so the renders agree pixel by pixel far more closely than independent
    renders could; the linear l steps by its own segment minimum, so against it only the
    law is compared (per-pixel z-test). Also proves that the scene compiler's grid
    offsets reach the sampler (a wrong offset reads mean samples)."""
    sig = LinearField(0.3, (0.1, 0.0, 0.0))
    ls = LinearField(0.2, (0.0, 0.05, 0.0))
    paths = {}
    for name, f in (("sigma", sig), ("ls", ls)):
        grid = _sampled(f, (-1.2,) * 3, 0.3, 9)
        paths[name] = _save_field_grid(tmp_path / f"{name}.npz", grid.values, (-1.2,) * 3, 0.3)
    forms = {"sigma linear": {"type": "linear", "value": 0.3, "gradient": [0.1, 0, 0]},
             "sigma grid": {"type": "grid", "file": paths["sigma"]},
             "l linear": {"type": "linear", "value": 0.2, "gradient": [0, 0.05, 0]},
             "l grid": {"type": "grid", "file": paths["ls"]}}
    images = {}
    for s_form, l_form in (("sigma linear", "l grid"), ("sigma grid", "l grid"),
                           ("sigma grid", "l linear")):
        kern = {"type": "squared_exponential", "sigma": 1.0, "length_scale": 1.0,
                "sigma_field": forms[s_form], "length_scale_field": forms[l_form]}
        # the proxy is the grid's box: the occupancy bound's largest sigma is then the
        # same for both forms, hence the samples
        scene = _gpis({"type": "function_space"}, kern,
                      {"type": "box", "min": [-1.2] * 3, "max": [1.2] * 3})
        scene["camera"] = {"position": [0, 0, 3.0], "look_at": [0, 0, 0], "up": [0, 1, 0],
                           "fov": 40, "resolution": [16, 16]}
        scene["render"] = {"spp": 4, "seed": 7, "max_depth": 8}
        res = render_result(scene, device=device)
        assert res.stats.gpis_failed == 0 and res.stats.nan_paths == 0, res.stats.summary()
        images[s_form, l_form] = res.image
    a, b = images["sigma linear", "l grid"], images["sigma grid", "l grid"]
    # Same realizations: independent renders would differ by sqrt(2) x their standard
    # error (rms); float32 field values perturb the joint covariances by ~1e-7, which the
    # factorisation of strongly correlated samples amplifies into small continuous shifts
    # of hits (measured: rms 0.005 x stderr), so 0.05 separates the two ~10x either way.
    rms = np.sqrt(np.mean((a.mean - b.mean) ** 2) / np.mean(a.stderr**2))
    print(f"rms difference / standard error: {rms:.2g}")
    assert rms < 0.05
    assert_agree(a.mean, a.stderr, b.mean, block=4, what="sigma grid vs linear")
    c = images["sigma grid", "l linear"]
    assert_agree(c.mean, c.stderr, b.mean, b.stderr, what="l grid vs linear")


def test14_renewal_slope_at_a_vertex_follows_the_conditional_law(device, prg):
    """Renewal memory at a vertex x (f(x) = 0) draws the slope along the new direction
    from its law given f(x) = 0, truncated to >= 0. A sigma(x) field correlates the two:
    cov(f, d_d f) = m(x) (d . grad m(x)) k0(0), which shifts the conditional mean by
    -cov / var(f) mu(x). The draws' mean and variance match the truncated normal's
    (z-tests, 40000 draws); the same law without the correlation is rejected."""
    from statistics import NormalDist
    K = NonStationary(SquaredExponential(1.0, 0.5),
                      sigma_field=LinearField(1.0, (0.8, 0.0, 0.0)))
    mean = Sphere(radius=0.5)
    x, d = np.array([0.9, 0.1, 0.0]), np.array([1.0, 0.0, 0.0])
    kp, nodes, mc = _kernel_and_nodes(K, mean)
    n, chunk = 40000, 1000
    stride = FL.scratch_doubles(FL.max_rows(WINDOW_MAX, CAP_MAX))
    scratch = cl.Buffer(device.ctx, cl.mem_flags.READ_WRITE, 8 * stride * chunk)
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * chunk)
    args = [_buf(device, kp), _buf(device, nodes), np.int32(mc), _buf(device, np.r_[x, d]),
            np.uint32(14)]
    s = np.empty(n)
    for first in range(0, n, chunk):
        prg["renewal_slope"](device.queue, (chunk,), None, *args, np.int32(first), scratch,
                             out)
        cl.enqueue_copy(device.queue, s[first:first + chunk], out)
    mf, gm = mean.value(x), mean.gradient(x)
    vf, c, vs = K.cov(x, x), K.cov_vd(x, x, d), K.cov_dd(x, d, x, d)
    assert abs(c) > 0.1 * math.sqrt(vf * vs)          # the field does correlate them
    z = z_threshold(4)

    def moments(m, v):
        """mean and variance of N(m, v) truncated to >= 0"""
        sd = math.sqrt(v)
        a = -m / sd
        lam = math.exp(-0.5 * a * a) / math.sqrt(2 * math.pi) / (1 - NormalDist().cdf(a))
        return m + sd * lam, v * (1 + a * lam - lam * lam)

    def agree(m, v):
        mu, var = moments(m, v)
        z_mean = (s.mean() - mu) / math.sqrt(var / n)
        z_var = (s.var(ddof=1) - var) / (var * math.sqrt(2.0 / (n - 1)))  # ~normal s^2
        return max(abs(z_mean), abs(z_var))

    ms = float(gm @ d)
    print(agree(ms - c / vf * mf, vs - c * c / vf), agree(ms, vs))
    assert agree(ms - c / vf * mf, vs - c * c / vf) < z
    assert agree(ms, vs) > z
