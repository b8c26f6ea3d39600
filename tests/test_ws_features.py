"""ws_features.h: weight-space realizations on the device against numpy and the GP kernels."""
import numpy as np
import pytest

from gpiscl.host.gp import (Box, LocallyPeriodic, Matern32, Matern52, Periodic, RationalQuadratic, Sphere,
                            SquaredExponential, Transform, Union)
from gpiscl.host.gp import spectral
from gpiscl.testing.reference import weight_space as ws
from gpiscl.host.layout.gp_records import pack_kernel
from gpiscl.testing.stats import z_threshold
from gpiscl.testing.weight_space import (EPS, ROT, build, dump, eval_tolerance, gp_args, keys_for,
                                         run)
from gpiscl.testing.wrappers import buffer

ANISO = (1.0, 0.5, 2.0)
KERNELS = [
    SquaredExponential(sigma=1.25, length_scale=0.5, aniso=ANISO),
    RationalQuadratic(sigma=0.875, length_scale=0.625, alpha=0.625, aniso=ANISO),  # a < 1: boost
    Periodic(sigma=1.125, length_scale=0.875, w=0.625, aniso=ANISO),
    LocallyPeriodic(sigma=0.75, length_scale=1.25, w=0.5, se_length_scale=1.5, aniso=ANISO),
    Matern32(sigma=1.0, length_scale=0.625, aniso=ANISO),    # Student-t, 3 dof
    Matern52(sigma=0.875, length_scale=0.75, aniso=ANISO),   # Student-t, 5 dof
]
MEAN = Union(Transform(Sphere(radius=0.75), np.concatenate([ROT, [[0.5], [0.0], [-0.25]]], 1)),
             Box(half_extents=(0.5, 0.25, 0.75), center=(-0.5, 0.25, 0.0)))

@pytest.fixture(scope="module")
def prg(device):
    return build(device)


def test_philox_lanes_match_random123(device, prg):
    """The vector Philox equals pyopencl's philox.cl and the numpy twin, bit for bit."""
    keys = np.random.default_rng(3).integers(0, 2**32, (300, 2), dtype=np.uint32)
    for call in (0, 1, 7):
        mine, ref = run(device, prg["ws_philox_check"], 300, buffer(device, keys), np.int32(5),
                        np.uint32(call), out_shapes=[((300, 4), np.uint32)] * 2)
        np.testing.assert_array_equal(mine, ref)
        ctr = np.stack([keys[:, 0], keys[:, 1], np.full(300, 5), np.arange(300)], -1)
        np.testing.assert_array_equal(ws.philox4x32(ctr, call), ref)


@pytest.mark.parametrize("kernel", [KERNELS[0], KERNELS[2], KERNELS[3]], ids=lambda k: k.kind)
def test_features_match_numpy_streams(device, prg, kernel):
    """Device features equal regenerate_features up to float32 rounding. A normal is
    rad cos(2 pi u), rad = sqrt(-2 log u) <= 6 for u >= 2^-24: log, sqrt and the reduced
    sin/cos polynomials err by <= 2 ulp each, so |dz| <= 4 eps (|z| + rad); the frequency
    scale sqrt(A)/l adds two roundings. Periodic orders are exact integers."""
    keys = keys_for(6)
    theta, tau, w = dump(device, prg, kernel, keys, 40, obj=3)
    length = getattr(kernel, "se_length_scale", kernel.length_scale)
    scale = 0.0 if kernel.kind == "periodic" else np.sqrt(ANISO) / length
    for r, key in enumerate(keys):
        t2, tau2, w2 = ws.regenerate_features(kernel, key, 3, 40)
        assert np.all(np.abs(theta[r] - t2) <= 8 * EPS * (np.abs(t2) + 6 * scale))
        assert np.all(np.abs(tau[r] - tau2) <= 4 * EPS * tau2)
        assert np.all(np.abs(w[r] - w2) <= 8 * EPS * (np.abs(w2) + 6))


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test_eval_matches_numpy(device, prg, kernel):
    m, per_key = 37, 64                        # 37: a partial last chunk of lanes
    keys = keys_for(4)
    theta, tau, w = dump(device, prg, kernel, keys, m)
    rng = np.random.default_rng(2)
    x = rng.uniform(-2, 2, (len(keys) * per_key, 3))
    x[:per_key] *= 10                          # |x| ~ 20: larger phases
    x = x.astype(np.float32)
    (out,) = run(device, prg["ws_eval_points"], len(x), *gp_args(device, kernel, MEAN),
                 np.int32(m), buffer(device, keys), np.int32(0), np.int32(per_key), buffer(device, x),
                 out_shapes=[((len(x), 4), np.float32)])
    for r in range(len(keys)):
        xs = x[r * per_key:(r + 1) * per_key].astype(np.float64)
        v, g = ws.evaluate(theta[r], tau[r], w[r], kernel.variance, xs, MEAN)
        tv, tg = eval_tolerance(theta[r], tau[r], w[r], kernel.variance, xs)
        o = out[r * per_key:(r + 1) * per_key]
        assert np.all(np.abs(o[:, 3] - v) <= tv), np.max(np.abs(o[:, 3] - v) / tv)
        assert np.all(np.abs(o[:, :3] - g) <= tg[:, None]), np.max(np.abs(o[:, :3] - g))


N_REALIZATIONS = 40_000
A, B = np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.1, -0.2])
U, V = np.array([0.6, 0.0, 0.8]), np.array([0.0, 0.28, 0.96])
NUM_COV_TESTS = len(KERNELS) * 6


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test_realizations_have_the_kernel_covariances(device, prg, kernel):
    """Over independent realization keys, E[f] = mean and the value and gradient
    covariances are k and its closed-form derivatives, exactly for any M (here 24)."""
    mean = Sphere(radius=0.5)
    x = np.tile(np.stack([A, B]), (N_REALIZATIONS, 1)).astype(np.float32)
    (out,) = run(device, prg["ws_eval_points"], len(x), *gp_args(device, kernel, mean),
                 np.int32(24), buffer(device, keys_for(N_REALIZATIONS, 11)), np.int32(2),
                 np.int32(2), buffer(device, x), out_shapes=[((len(x), 4), np.float32)])
    out = out.astype(np.float64).reshape(N_REALIZATIONS, 2, 4)
    mv, mg = mean.value_and_gradient(np.stack([A, B]))
    fa, fb = out[:, 0, 3] - mv[0], out[:, 1, 3] - mv[1]
    da, db = (out[:, 0, :3] - mg[0]) @ U, (out[:, 1, :3] - mg[1]) @ V
    db_at_a = (out[:, 0, :3] - mg[0]) @ V
    checks = {"mean": (fa, 0.0), "vv": (fa * fb, kernel.cov(A, B)),
              "dv": (da * fb, kernel.cov_dv(A, U, B)), "vd": (fa * db, kernel.cov_vd(A, B, V)),
              "dd": (da * db, kernel.cov_dd(A, U, B, V)),
              "dd0": (da * db_at_a, kernel.cov_dd(A, U, A, V))}
    for name, (samples, target) in checks.items():
        z = abs(samples.mean() - target) / (samples.std(ddof=1) / np.sqrt(N_REALIZATIONS))
        assert z < z_threshold(NUM_COV_TESTS), (name, samples.mean(), target, z)


def test_lanes_do_not_change_the_realization(device, prg):
    """WS_LANES only regroups work: features are equal and values agree to rounding."""
    kernel, keys, m = KERNELS[3], keys_for(3), 21
    ref = dump(device, prg, kernel, keys, m)
    x = np.random.default_rng(4).uniform(-2, 2, (3 * 8, 3)).astype(np.float32)
    def values(p):
        return run(device, p["ws_eval_points"], len(x), *gp_args(device, kernel, MEAN),
                   np.int32(m), buffer(device, keys), np.int32(0), np.int32(8), buffer(device, x),
                   out_shapes=[((len(x), 4), np.float32)])[0]
    v8 = values(prg)
    for lanes in (1, 16):
        p = build(device, lanes=lanes)
        for a, b in zip(dump(device, p, kernel, keys, m), ref):
            np.testing.assert_allclose(a, b, rtol=2 * EPS, atol=2 * EPS)
        # only the order of the M-term sums differs: gamma_M of the absolute terms
        np.testing.assert_allclose(values(p), v8, rtol=0, atol=m * EPS * 8)


def test_lambda2_is_the_spectral_second_moment(device, prg):
    d = np.random.default_rng(1).normal(size=(16, 3)).astype(np.float32)
    for kernel in KERNELS:
        (out,) = run(device, prg["ws_lambda2_k"], 16, buffer(device, pack_kernel(kernel)),
                     buffer(device, d), out_shapes=[((16,), np.float32)])
        ref = [ws.spectral_moment2(kernel, di) for di in d.astype(np.float64)]
        np.testing.assert_allclose(out, ref, rtol=8 * EPS)


def test_order_tables():
    for l in (0.1, 0.875, 4.0):
        cdf = spectral.periodic_order_cdf(l)
        assert cdf.dtype == np.float32 and cdf[-1] == 1.0 and np.all(np.diff(cdf) >= 0)
        q = spectral.periodic_order_weights(l)
        np.testing.assert_allclose(np.diff(cdf, prepend=0)[:-1], q[:len(cdf) - 1], atol=2 * EPS)
        assert 1.0 - np.cumsum(q)[len(cdf) - 2] > 2.0**-26   # nothing resolvable was cut
    table, first, count = spectral.pack_order_tables(KERNELS)
    assert list(count[:2]) == [1, 1] and first[-1] == first[-2] + count[-2]
    np.testing.assert_array_equal(table[first[2]:first[2] + count[2]],
                                  spectral.periodic_order_cdf(KERNELS[2].length_scale))


def header_constant(name):
    """A float #define of ws_features.h (the tests check the values the device uses)."""
    import re
    from gpiscl.host.render.program_sources import KERNEL_DIR
    text = (KERNEL_DIR / "lib" / "ws_features.h").read_text()
    return float(re.search(rf"#define {name} ([0-9.e+-]+)f", text).group(1))


def sincos_polynomials(r):
    """ws_sincos_quadrant's polynomials with its float32 coefficients, evaluated in
    float64: their approximation error alone."""
    f, z = np.float32, r * r
    s = r + r * z * ((f(-1.9515295891e-4) * z + f(8.3321608736e-3)) * z - f(1.6666654611e-1))
    c = (1 - 0.5 * z + z * z * ((f(2.443315711809948e-5) * z - f(1.388731625493765e-3)) * z
                                + f(4.166664568298827e-2)))
    return s.astype(np.float64), c.astype(np.float64)


def test_sincos_error_is_within_its_bound(device, prg):
    """WS_SINCOS_ERR (folded into ws_affine's err) bounds the polynomials' own error on the
    reduced range; the device's sin/cos, reduction and float32 evaluation included, are
    within it plus a few ulp (ws_affine's round) for phases up to 2^15."""
    bound = header_constant("WS_SINCOS_ERR")
    r = np.linspace(-np.pi / 4, np.pi / 4, 2_000_001)
    s, c = sincos_polynomials(r)
    assert np.max(np.abs(s - np.sin(r))) <= bound
    assert np.max(np.abs(c - np.cos(r))) <= bound
    rng = np.random.default_rng(8)
    x = np.concatenate([rng.uniform(-7, 7, 1 << 16), rng.uniform(-2.0**15, 2.0**15, 1 << 16),
                        np.arange(-64, 65) * np.pi / 4]).astype(np.float32)
    (out,) = run(device, prg["ws_sincos_k"], len(x), buffer(device, x),
                 out_shapes=[((len(x), 2), np.float32)])
    xd = x.astype(np.float64)
    # the reduction's last part rounds at eps |x| 2^-24 (exact parts above it)
    allow = bound + 3 * EPS + EPS * np.abs(xd) * 2.0**-20
    assert np.all(np.abs(out[:, 0] - np.sin(xd)) <= allow)
    assert np.all(np.abs(out[:, 1] - np.cos(xd)) <= allow)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test_cached_affine_equals_regenerated(device, prg, kernel):
    """A search's cached bound (features and rounding moments computed once per ray)
    equals the bound from regenerated features bit for bit: same features, same sums."""
    n, m = 64, 45
    rng = np.random.default_rng(9)
    o = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    tmh = np.stack([rng.uniform(0, 2, n), 10.0 ** rng.uniform(-4, 0.5, n)], -1)
    a, b = run(device, prg["ws_affine_both"], n, *gp_args(device, kernel)[:1],
               *gp_args(device, kernel)[3:], np.int32(m), buffer(device, keys_for(n)),
               buffer(device, o), buffer(device, d), buffer(device, tmh.astype(np.float32)),
               out_shapes=[((n, 4), np.float32)] * 2)
    np.testing.assert_array_equal(a, b)
    assert np.all(np.isfinite(a)) or kernel.kind == "thin_plate"
