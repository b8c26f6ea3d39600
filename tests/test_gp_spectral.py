"""Spectral samplers: E[cos(omega . r)] = k(r) / k(0), checked by Monte Carlo with CLT bounds."""
import numpy as np
import pytest

from gpiscl.host.gp import (LocallyPeriodic, Matern32, Matern52, Periodic, RandomFeatures, RationalQuadratic,
                            SquaredExponential, ThinPlate, periodic_order_weights,
                            sample_frequencies)
from gpiscl.testing.stats import z_threshold

ANISO = (1.0, 0.5, 2.0)
KERNELS = [
    SquaredExponential(sigma=1.3, length_scale=0.8),
    SquaredExponential(sigma=1.0, length_scale=0.6, aniso=ANISO),
    RationalQuadratic(sigma=1.0, length_scale=1.0, alpha=1.0),     # the reference's 0.445 case
    RationalQuadratic(sigma=0.7, length_scale=0.7, alpha=0.4, aniso=ANISO),
    RationalQuadratic(sigma=1.0, length_scale=0.9, alpha=6.0, aniso=ANISO),
    Periodic(sigma=1.0, length_scale=0.8, w=0.5),
    Periodic(sigma=1.1, length_scale=0.3, w=0.9, aniso=ANISO),
    Periodic(sigma=1.0, length_scale=4.0, w=1.5, aniso=ANISO),
    LocallyPeriodic(sigma=1.0, length_scale=0.9, w=0.7, se_length_scale=1.2, aniso=ANISO),
    Matern32(sigma=1.0, length_scale=0.8),
    Matern32(sigma=0.7, length_scale=0.6, aniso=ANISO),
    Matern52(sigma=1.2, length_scale=0.9),
    Matern52(sigma=0.8, length_scale=0.5, aniso=ANISO),
]
LAGS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, -0.4, 0.5], [0.0, 0.9, 0.0],
                 [0.7, 0.7, -0.2], [1.5, -0.3, 1.1]])
N = 200_000
NUM_TESTS = len(KERNELS) * len(LAGS)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: f"{k.kind}")
def test_cosine_mean_equals_normalised_kernel(kernel):
    rng = np.random.default_rng(11)
    omega = sample_frequencies(kernel, N, rng)
    c = np.cos(omega @ LAGS.T)                   # (N, lags)
    target = kernel.cov(np.zeros(3), LAGS) / kernel.variance
    se = c.std(axis=0, ddof=1) / np.sqrt(N)
    # at r = 0 cos is 1 exactly: no variance, an exact check
    exact = se == 0
    np.testing.assert_allclose(c.mean(axis=0)[exact], target[exact], rtol=1e-12)
    z = np.abs(c.mean(axis=0)[~exact] - target[~exact]) / se[~exact]
    assert z.max() < z_threshold(NUM_TESTS), (z, target)


def test_reference_rq_case():
    """alpha = l = 1, r = e_x: the target is 2/3 (the reference's 3-D sampler gave 0.445)."""
    k = RationalQuadratic(alpha=1.0)
    assert k.cov(np.zeros(3), [1.0, 0, 0]) == pytest.approx(2 / 3)


def test_periodic_spectrum_reproduces_the_kernel_exactly():
    """The discrete spectrum is exact: the cosine series sums to the 1-D kernel."""
    t = np.linspace(-2, 2, 101)
    for l in (0.1, 0.5, 1.0, 3.0):
        q = periodic_order_weights(l)
        assert q[0] == pytest.approx(np.exp(-1 / l**2) * np.i0(1 / l**2), rel=1e-12)
        w = 0.8
        series = np.cos(2 * np.pi * w * np.outer(t, np.arange(len(q)))) @ q
        np.testing.assert_allclose(series, np.exp(-2 * np.sin(np.pi * w * t) ** 2 / l**2),
                                   atol=1e-13)


def test_periodic_frequencies_lie_on_the_lattice():
    k = Periodic(length_scale=0.5, w=0.9, aniso=ANISO)
    omega = sample_frequencies(k, 1000, np.random.default_rng(0))
    n = omega / (2 * np.pi * k.w * np.sqrt(ANISO))
    np.testing.assert_allclose(n, np.round(n), atol=1e-9)
    assert np.all(n.min(axis=0) < 0) and np.all(n.max(axis=0) > 0)   # both signs per axis


def test_thin_plate_is_rejected():
    with pytest.raises(ValueError, match="thin_plate has no spectral density"):
        sample_frequencies(ThinPlate(), 10, np.random.default_rng(0))


@pytest.mark.parametrize("kernel", [KERNELS[1], KERNELS[3], KERNELS[8], KERNELS[10],
                                    KERNELS[12]],
                         ids=lambda k: k.kind)
def test_random_feature_realizations_have_the_kernel_covariances(kernel):
    """Over independent bases, value and gradient covariances of weight-space realizations
    are k and its closed-form derivative covariances, for any number of features M."""
    rng = np.random.default_rng(5)
    a, b = np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.1, -0.2])
    u, v = np.array([0.6, 0.0, 0.8]), np.array([0.0, 0.28, 0.96])
    n, m = 50_000, 4
    # n independent realizations, each its own basis of M features (RandomFeatures.evaluate
    # vectorised over realizations; its agreement with evaluate() is tested below)
    omega = sample_frequencies(kernel, n * m, rng).reshape(n, m, 3)
    phase = rng.uniform(0, 2 * np.pi, (n, m))
    w = rng.standard_normal((n, m)) * kernel.sigma * np.sqrt(2 / m)
    arg_a, arg_b = omega @ a + phase, omega @ b + phase
    fa, fb = np.sum(w * np.cos(arg_a), 1), np.sum(w * np.cos(arg_b), 1)
    da = -np.sum(w * np.sin(arg_a) * (omega @ u), 1)
    db = -np.sum(w * np.sin(arg_b) * (omega @ v), 1)
    pairs = {"vv": (fa * fb, kernel.cov(a, b)), "dv": (da * fb, kernel.cov_dv(a, u, b)),
             "vd": (fa * db, kernel.cov_vd(a, b, v)), "dd": (da * db, kernel.cov_dd(a, u, b, v))}
    for name, (prod, target) in pairs.items():
        z = abs(prod.mean() - target) / (prod.std(ddof=1) / np.sqrt(n))
        assert z < z_threshold(4 * 3), (name, prod.mean(), target)


def test_random_features_gradient_is_exact():
    kern = SquaredExponential(sigma=1.2, length_scale=0.7, aniso=ANISO)
    rng = np.random.default_rng(5)
    feats = RandomFeatures.sample(kern, 64, rng)
    x = rng.uniform(-1, 1, (5, 3))
    w = rng.standard_normal(64)
    v, g = feats.evaluate(w, x)
    phi = np.cos(x @ feats.omega.T + feats.phase) * kern.sigma * np.sqrt(2 / 64)
    np.testing.assert_allclose(v, phi @ w, atol=1e-12)
    dphi = -np.sin(x @ feats.omega.T + feats.phase) * kern.sigma * np.sqrt(2 / 64)
    np.testing.assert_allclose(g, (dphi * w) @ feats.omega, atol=1e-12)
    # central differences: truncation eps^2 |omega|^3 ~ 1e-10, rounding 1e-16 / eps
    eps = 1e-6
    fd = np.stack([(feats.evaluate(w, x + eps * e)[0] - feats.evaluate(w, x - eps * e)[0])
                   / (2 * eps) for e in np.eye(3)], -1)
    np.testing.assert_allclose(g, fd, atol=1e-7)


@pytest.mark.parametrize("kernel", [KERNELS[10], KERNELS[12]], ids=lambda k: k.kind)
def test_matern_second_moment_is_minus_k2(kernel):
    """E[omega omega^T] = -Hess k(0) / k(0): nu / (nu - 1) A / l^2 (3 A / l^2 and
    5 A / (3 l^2)), the lambda_2 of Rice's formula. 5/2 has a finite 4th moment, so a CLT
    bound applies; 3/2's omega^2 has infinite variance, so there a loose relative check."""
    rng = np.random.default_rng(17)
    omega = sample_frequencies(kernel, N, rng)
    target = kernel.gradient_variance() / kernel.variance
    sq = omega**2
    if kernel.kind == "matern52":
        z = np.abs(sq.mean(0) - target) / (sq.std(0, ddof=1) / np.sqrt(N))
        assert z.max() < z_threshold(3), z
    else:
        np.testing.assert_allclose(np.median(sq.reshape(100, -1, 3).mean(1), axis=0), target,
                                   rtol=0.1)
