"""Covariance kernels: closed-form derivative covariances, reference numbers, PSD, limits."""
import numpy as np
import pytest

from gpiscl.host.gp import (LocallyPeriodic, Matern32, Matern52, Periodic, RationalQuadratic,
                            SquaredExponential, ThinPlate, covariance_matrix)

ANISO = (1.0, 0.6, 1.7)
KERNELS = [
    SquaredExponential(sigma=1.3, length_scale=0.8, aniso=ANISO),
    RationalQuadratic(sigma=0.9, length_scale=1.1, alpha=0.7, aniso=ANISO),
    Periodic(sigma=1.2, length_scale=0.9, w=0.7, aniso=ANISO),
    LocallyPeriodic(sigma=0.8, length_scale=1.3, w=0.6, se_length_scale=1.5, aniso=ANISO),
    ThinPlate(sigma=0.7, radius=4.0, aniso=ANISO),
    Matern32(sigma=1.1, length_scale=0.9, aniso=ANISO),
    Matern52(sigma=0.9, length_scale=0.7, aniso=ANISO),
]
IDS = [k.kind for k in KERNELS]


def _pairs(rng, n, spread=0.8):
    a = rng.uniform(-spread, spread, (n, 3))
    b = rng.uniform(-spread, spread, (n, 3))
    u = rng.standard_normal((n, 3))
    v = rng.standard_normal((n, 3))
    return a, u / np.linalg.norm(u, axis=1)[:, None], b, v / np.linalg.norm(v, axis=1)[:, None]


@pytest.mark.parametrize("kernel", KERNELS, ids=IDS)
def test_derivative_covariances_match_finite_differences(kernel):
    rng = np.random.default_rng(1)
    a, u, b, v = _pairs(rng, 200)
    # Central differences: truncation eps^2 |k'''| / 6 and rounding 1e-16 |k| / eps
    # (one difference) or / eps^2 (two): eps = 1e-5 and 1e-4 keep both near 1e-8 times
    # the natural scale of each covariance (k(0) for values, the gradient variance for
    # derivatives, their geometric mean for mixed ones): far below the 1e-6 tolerance.
    # Lags stay in (0, R) for thin-plate, which is C^2 only away from rho = 0 and R.
    e1, e2, tol = 1e-5, 1e-4, 1e-6
    k = kernel.cov
    fd_dv = (k(a + e1 * u, b) - k(a - e1 * u, b)) / (2 * e1)
    fd_vd = (k(a, b + e1 * v) - k(a, b - e1 * v)) / (2 * e1)
    fd_dd = (k(a + e2 * u, b + e2 * v) - k(a + e2 * u, b - e2 * v)
             - k(a - e2 * u, b + e2 * v) + k(a - e2 * u, b - e2 * v)) / (4 * e2 * e2)
    grad_scale = kernel.gradient_variance().max()
    mixed = np.sqrt(kernel.variance * grad_scale)
    np.testing.assert_allclose(kernel.cov_dv(a, u, b), fd_dv, atol=tol * mixed)
    np.testing.assert_allclose(kernel.cov_vd(a, b, v), fd_vd, atol=tol * mixed)
    np.testing.assert_allclose(kernel.cov_dd(a, u, b, v), fd_dd, atol=tol * grad_scale)


@pytest.mark.parametrize("kernel", KERNELS, ids=IDS)
def test_values_at_zero_lag_are_finite_and_exact(kernel):
    x = np.array([0.3, -0.2, 0.1])
    e = np.eye(3)
    assert kernel.cov(x, x) == pytest.approx(kernel.variance)
    for i in range(3):
        assert kernel.cov_dv(x, e[i], x) == 0.0
        assert kernel.cov_vd(x, x, e[i]) == 0.0
    dd = np.array([[kernel.cov_dd(x, e[i], x, e[j]) for j in range(3)] for i in range(3)])
    assert np.all(np.isfinite(dd))
    np.testing.assert_allclose(dd, np.diag(kernel.gradient_variance()), atol=1e-12)


def test_gradient_variances_in_closed_form():
    a = np.array(ANISO)
    se, rq, per, tp = KERNELS[0], KERNELS[1], KERNELS[2], KERNELS[4]
    np.testing.assert_allclose(se.gradient_variance(), se.variance * a / se.length_scale**2)
    np.testing.assert_allclose(rq.gradient_variance(), rq.variance * a / rq.length_scale**2)
    np.testing.assert_allclose(per.gradient_variance(),
                               4 * np.pi**2 * per.w**2 * per.variance * a / per.length_scale**2)
    np.testing.assert_allclose(tp.gradient_variance(), 6 * tp.radius * tp.sigma**2 * a)


def test_reference_table_10_1():
    """REFERENCE-ALGORITHMS 10.1: sigma = l = 1, a = 0, b = e_x."""
    a, b = np.zeros(3), np.array([1.0, 0.0, 0.0])
    ex, ey = np.eye(3)[0], np.eye(3)[1]
    table = {SquaredExponential(): (0.6065, 0.6065, 0.0000, 0.6065, 1.0),
             RationalQuadratic(alpha=1.0): (0.6667, 0.4444, -0.1481, 0.4444, 1.0)}
    for kern, (k, dv, dxx, dyy, var) in table.items():
        got = (kern.cov(a, b), kern.cov_dv(a, ex, b), kern.cov_dd(a, ex, b, ex),
               kern.cov_dd(a, ey, b, ey), kern.cov_dd(a, ex, a, ex))
        np.testing.assert_allclose(got, (k, dv, dxx, dyy, var), atol=5e-5)  # 4 decimals


@pytest.mark.parametrize("kernel", KERNELS, ids=IDS)
def test_joint_value_gradient_covariance_is_symmetric_psd(kernel):
    rng = np.random.default_rng(7)
    # thin-plate is PSD only on small domains: this cube's diameter in the metric of A is
    # 0.65 R (kernels.py: balls up to 0.8 R passed, R failed)
    half = kernel.radius / (4 * np.sqrt(3)) if kernel.kind == "thin_plate" else 1.0
    for _ in range(5):
        x = rng.uniform(-half, half, (16, 3))
        pts = np.concatenate([x, x, x, x])
        dirs = np.concatenate([np.full((16, 3), np.nan), np.eye(3).repeat(16, 0)])
        C = covariance_matrix(kernel, pts, u1=dirs)
        np.testing.assert_allclose(C, C.T, atol=1e-12 * kernel.variance)
        ev = np.linalg.eigvalsh(C)
        assert ev.min() >= -1e-8 * ev.max()


def test_cross_covariance_swaps_arguments():
    rng = np.random.default_rng(3)
    a, u, b, v = _pairs(rng, 50)
    for kern in KERNELS:
        np.testing.assert_allclose(kern.cov_dv(a, u, b), kern.cov_vd(b, a, u), atol=1e-14)
        np.testing.assert_allclose(kern.cov_dd(a, u, b, v), kern.cov_dd(b, v, a, u),
                                   atol=1e-14)


def test_euclidean_periodic_is_not_psd_in_3d():
    """Why our periodic kernel is a product over axes (kernels.py docstring)."""
    x = np.random.default_rng(0).uniform(-1, 1, (200, 3))
    r = np.linalg.norm(x[:, None] - x[None], axis=-1)
    assert np.linalg.eigvalsh(np.exp(-2 * np.sin(np.pi * r) ** 2)).min() < -1.0


def test_rational_quadratic_tends_to_squared_exponential():
    rng = np.random.default_rng(5)
    a, u, b, v = _pairs(rng, 100)
    se = SquaredExponential(sigma=1.1, length_scale=0.9, aniso=ANISO)
    alpha = 1e8
    rq = RationalQuadratic(sigma=1.1, length_scale=0.9, alpha=alpha, aniso=ANISO)
    # log k_RQ = -x + x^2 / (2 alpha) + O(x^3 / alpha^2) with x = s / (2 l^2): the relative
    # gap is bounded by x^2 / alpha, and the derivative factors differ by O(x / alpha)
    s = np.sum(np.array(ANISO) * (b - a) ** 2, axis=1)
    x_max = s.max() / (2 * 0.9**2)
    rel = 4 * (1 + x_max) ** 2 / alpha
    for f in ("cov", "cov_dv", "cov_vd", "cov_dd"):
        args = {"cov": (a, b), "cov_dv": (a, u, b), "cov_vd": (a, b, v),
                "cov_dd": (a, u, b, v)}[f]
        np.testing.assert_allclose(getattr(rq, f)(*args), getattr(se, f)(*args),
                                   rtol=rel, atol=rel * se.variance)


def test_thin_plate_beyond_radius_is_zero_and_c1():
    tp = ThinPlate(sigma=1.0, radius=2.0)
    a = np.zeros(3)
    ex = np.eye(3)[0]
    for d in (2.0, 2.5, 10.0):
        b = d * ex
        assert tp.cov(a, b) == 0.0 and tp.cov_dv(a, ex, b) == 0.0
    # just inside: k = (R - rho)^2 (2 rho + R) -> 3 R d^2 and -2 k'(s) rho = 6 rho (R - rho)
    # -> 6 R d, both vanishing continuously at R (a C^1 join)
    d, R = 1e-6, 2.0
    inside = (R - d) * ex
    np.testing.assert_allclose(tp.cov(a, inside), 3 * R * d * d, rtol=1e-5)
    np.testing.assert_allclose(tp.cov_dv(a, ex, inside), 6 * R * d, rtol=1e-5)


def test_invalid_parameters_are_rejected():
    with pytest.raises(ValueError, match="length_scale"):
        SquaredExponential(length_scale=0.0)
    with pytest.raises(ValueError, match="alpha"):
        RationalQuadratic(alpha=-1.0)
    with pytest.raises(ValueError, match="aniso"):
        Periodic(aniso=(1.0, 0.0, 1.0))


@pytest.mark.parametrize("nu", [1.5, 2.5])
def test_matern_closed_forms(nu):
    """The half-integer forms against the general Bessel form, -k''(0) in closed form
    (3 sigma^2 A / l^2 for 3/2, 5 sigma^2 A / (3 l^2) for 5/2), and the Hessian's limit
    at r = 0 equals the gradient variance (continuity, checked at a tiny lag)."""
    from math import gamma
    from scipy.special import kv
    cls = Matern32 if nu == 1.5 else Matern52
    sig, l = 1.3, 0.8
    k = cls(sigma=sig, length_scale=l, aniso=ANISO)
    r = np.random.default_rng(3).uniform(-1, 1, (50, 3))
    x = np.sqrt(2 * nu * np.sum(np.asarray(ANISO) * r * r, -1)) / l
    bessel = sig**2 * 2 ** (1 - nu) / gamma(nu) * x**nu * kv(nu, x)
    np.testing.assert_allclose(k.value(r), bessel, rtol=1e-12)
    factor = 3.0 if nu == 1.5 else 5.0 / 3.0
    np.testing.assert_allclose(k.gradient_variance(), factor * sig**2 * np.asarray(ANISO) / l**2,
                               rtol=1e-14)
    tiny = np.array([1e-7, -2e-7, 1.5e-7])
    e = np.eye(3)
    dd = np.array([[k.cov_dd(np.zeros(3), e[i], tiny, e[j]) for j in range(3)]
                   for i in range(3)])
    # 3/2: the Hessian is continuous but not differentiable at 0, off by O(c^3 |r|)
    np.testing.assert_allclose(dd, np.diag(k.gradient_variance()), atol=1e-4)
