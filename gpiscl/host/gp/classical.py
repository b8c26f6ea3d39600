"""Closed forms of a GPIS's classical limits (derived in docs/design/classical-limits.md):
the participating medium (Rice's entry rate as extinction, the visible-normal phase
function) and the microfacet surface (Beckmann alpha from the gradient variance).

f = mu + g with the inside at f < 0; levels are the mean's value mu at the point."""
from __future__ import annotations

import math

import numpy as np
from .kernels import Kernel, NonStationary


def slope_variance(kernel: Kernel, d=(1.0, 0.0, 0.0)) -> float:
    """lambda_2 along d: Var(d . grad g) = d' Lambda d for the unit direction d."""
    d = np.asarray(d, float)
    d = d / np.linalg.norm(d)
    lam2 = float(kernel.cov_dd(np.zeros(3), d, np.zeros(3), d))
    if not math.isfinite(lam2) or lam2 <= 0.0:
        raise ValueError(f"{kernel.kind}: no finite slope variance (its realizations are "
                         "not differentiable): no Rice rate and no Beckmann limit")
    return lam2


def _normal_pdf(z):
    return np.exp(-0.5 * np.square(z)) / math.sqrt(2.0 * math.pi)


_erfc = np.vectorize(math.erfc, otypes=[np.float64])


def _normal_cdf(z):
    return 0.5 * _erfc(-np.asarray(z, float) / math.sqrt(2.0))


def crossing_rate(kernel: Kernel, level, d=(1.0, 0.0, 0.0), mean_slope=0.0):
    """Rice: down-crossings (f >= 0 -> f < 0) per unit length along unit d at a point where
    the mean is `level` and its slope along d is `mean_slope` (Eq. 2 of the note)."""
    sigma = math.sqrt(kernel.variance)
    s = math.sqrt(slope_variance(kernel, d))
    m = np.asarray(mean_slope, float)
    negative_part = s * _normal_pdf(m / s) - m * _normal_cdf(-m / s)   # E[(-f')^+]
    return _normal_pdf(np.asarray(level, float) / sigma) / sigma * negative_part


def entry_rate(kernel: Kernel, level, d=(1.0, 0.0, 0.0), mean_slope=0.0):
    """The medium counterpart's extinction: entries per unit length travelled outside,
    crossing_rate / P(f > 0) (Eq. 3)."""
    sigma = math.sqrt(kernel.variance)
    return crossing_rate(kernel, level, d, mean_slope) / _normal_cdf(np.asarray(level) / sigma)


def local_extinction(kernel: Kernel, mean, points, d) -> np.ndarray:
    """The heterogeneous medium counterpart's sigma_t at each of `points` (n, 3) for light
    travelling along unit d: Eq. 3 with Rice's rate (2) at the local mean, its slope along
    d, and (local stationarity) sigma(x) = sigma m_s(x), Lambda(x) = (m_s / m_l)^2 Lambda
    of the stationary base; fs_classical.h's fs_cl_rate is its device twin."""
    x = np.atleast_2d(np.asarray(points, float))
    d = np.asarray(d, float) / np.linalg.norm(d)
    base = kernel.base if isinstance(kernel, NonStationary) else kernel
    ms = ml = np.ones(len(x))
    if isinstance(kernel, NonStationary) and kernel.sigma_field is not None:
        ms = np.asarray(kernel.sigma_field.eval(x)[0], float)
    if isinstance(kernel, NonStationary) and kernel.length_scale_field is not None:
        ml = np.asarray(kernel.length_scale_field.eval(x)[0], float)
    mu, grad = mean.value_and_gradient(x)
    sigma = math.sqrt(base.variance) * ms
    s = ms * math.sqrt(slope_variance(base, d)) / ml
    m = np.asarray(grad, float) @ d
    negative_part = s * _normal_pdf(m / s) - m * _normal_cdf(-m / s)    # E[(-f')^+]
    z = np.asarray(mu, float) / sigma
    return _normal_pdf(z) / sigma * negative_part / _normal_cdf(z)


def extinction_profile(kernel: Kernel, mean, origin, d, t0: float, t1: float,
                       nodes: int = 20001) -> tuple:
    """(s, sigma_t, optical depth from t0) on `nodes` points of [t0, t1] along origin + s d
    (unit d), by the trapezoidal rule. Deep inside a mean (mu / sigma < -37) Phi underflows
    and the rate comes out inf or nan where the device takes its series (fs_cl_hazard):
    taken as inf, and depths capped at 800, past exp's underflow (745), where a ray from
    outside has long lost its light (it gathered more than 600 getting there)."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    s = np.linspace(float(t0), float(t1), nodes)
    with np.errstate(all="ignore"):
        rate = local_extinction(kernel, mean, np.asarray(origin, float) + s[:, None] * d, d)
    rate = np.where(np.isfinite(rate), rate, np.inf)
    steps = 0.5 * (rate[1:] + rate[:-1]) * np.diff(s)
    depth = np.minimum(np.concatenate([[0.0], np.cumsum(steps)]), 800.0)
    return s, rate, depth


def optical_depth(kernel: Kernel, mean, origin, d, t, nodes: int = 20001) -> np.ndarray:
    """int_0^t sigma_t along origin + s d (unit d) at each distance in t, on `nodes` points
    up to max(t) (extinction_profile): the reference of the tracked flights."""
    s, _, depth = extinction_profile(kernel, mean, origin, d, 0.0, float(np.max(t)), nodes)
    return np.interp(np.asarray(t, float), s, depth)


def beckmann_alpha(kernel: Kernel, tangent=(1.0, 0.0, 0.0), mean_gradient_norm=1.0) -> float:
    """The surface counterpart's Beckmann roughness along `tangent`: sqrt(2 lambda_2) / |grad mu|
    (sqrt(2) sigma / l for SE and RQ, sqrt(6) sigma / l for Matern 3/2, sqrt(10/3) sigma / l
    for Matern 5/2, at a unit mean slope)."""
    return math.sqrt(2.0 * slope_variance(kernel, tangent)) / float(mean_gradient_norm)


def beckmann_tan2_survival(x, alpha):
    """P(tan^2 theta_m > x) of the Beckmann normal law D(m) cos theta_m (the visible law at
    normal incidence): tan^2 theta_m / alpha^2 is exponential with mean 1."""
    return np.exp(-np.asarray(x, float) / (alpha * alpha))


def beckmann_cos_pdf(c, alpha):
    """Density of cos theta_m under D(m) cos theta_m (isotropic Beckmann), for plots."""
    c = np.asarray(c, float)
    t2 = (1.0 - c * c) / (c * c)
    return 2.0 * np.exp(-t2 / (alpha * alpha)) / (alpha * alpha * c ** 3)


def smith_lambda(cos_theta, alpha):
    """Smith's Lambda of the Beckmann distribution for a direction at cos_theta to the
    macro normal: G1 = 1 / (1 + Lambda)."""
    c = np.clip(np.asarray(cos_theta, float), 1e-12, 1.0)
    a = c / np.sqrt(np.maximum(1.0 - c * c, 1e-300)) / alpha
    erf = np.vectorize(math.erf, otypes=[np.float64])
    return 0.5 * (erf(a) - 1.0) + np.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))


def smith_rehit_fraction(alpha: float, n: int, rng) -> float:
    """Under Smith's model: the fraction of paths that meet the surface again after a
    Lambertian bounce off the facet a ray straight down the macro normal hit first (facet
    normals: Beckmann slopes; below the macro plane: always; above: 1 - G1 = Lambda /
    (1 + Lambda), since the start height is uniform in its CDF). Monte Carlo, n draws."""
    slopes = rng.normal(0.0, alpha / math.sqrt(2.0), (n, 2))
    m = np.c_[-slopes, np.ones(n)]
    m /= np.linalg.norm(m, axis=1)[:, None]
    u = rng.random((n, 2))
    r, phi = np.sqrt(u[:, 0]), 2.0 * math.pi * u[:, 1]
    helper = np.where(np.abs(m[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(m, helper)
    t /= np.linalg.norm(t, axis=1)[:, None]
    b = np.cross(m, t)
    up = (r * np.cos(phi)) * t[:, 2] + (r * np.sin(phi)) * b[:, 2] + np.sqrt(1.0 - u[:, 0]) * m[:, 2]
    lam = smith_lambda(up, alpha)
    return float(np.mean(np.where(up <= 0.0, 1.0, lam / (1.0 + lam))))


def beckmann_single_scatter_bins(theta_i: float, alpha: float, edges, n_theta: int = 400,
                                  n_phi: int = 720) -> np.ndarray:
    """For a white mirror microsurface (F = 1) lit at theta_i (radians): the fraction of
    the incident energy the single-scattering Beckmann BRDF with height-correlated Smith
    G2 = 1 / (1 + Lambda_i + Lambda_o) (rough_conductor's) sends into each bin of
    theta_o between `edges` (radians), over every phi: the midpoint rule on a grid."""
    si, ci = math.sin(theta_i), math.cos(theta_i)
    lam_i = smith_lambda(ci, alpha)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        th = lo + (np.arange(n_theta) + 0.5) * (hi - lo) / n_theta
        ph = (np.arange(n_phi) + 0.5) * 2.0 * math.pi / n_phi
        T, P = th[:, None], ph[None, :]
        # the half vector's cos theta_h = (cos theta_o + cos theta_i) / |wo + wi|, with
        # |wo + wi|^2 = 2 (1 + wo . wi): scalars per node, no 3-vectors
        c = (np.cos(T) + ci) / np.sqrt(2.0 * (1.0 + np.sin(T) * np.cos(P) * si + np.cos(T) * ci))
        d = np.exp(-(1.0 - c * c) / (c * c * alpha * alpha)) / (math.pi * alpha ** 2 * c ** 4)
        # Lambda_o depends on theta_o alone: one erf per row, not per (theta, phi) node
        g2 = 1.0 / (1.0 + lam_i + smith_lambda(np.cos(th), alpha)[:, None])
        f_cos = d * g2 / (4.0 * ci)                      # f_r cos theta_o
        out.append(float(np.sum(f_cos * np.sin(T)) * (hi - lo) / n_theta * 2 * math.pi / n_phi))
    return np.array(out)


def lambert_sphere_phase(theta):
    """Phase function (per steradian) of a cloud of diffuse spheres, theta the deflection
    angle: the medium counterpart of a diffuse micro-BSDF (Sec. 2.3 of the note)."""
    theta = np.asarray(theta, float)
    return 2.0 / (3.0 * math.pi ** 2) * (np.sin(theta) - theta * np.cos(theta))


def ks_to_exponential(t, rate) -> float:
    """One-sample Kolmogorov-Smirnov distance of the samples t to Exp(rate)."""
    t = np.sort(np.asarray(t, float))
    n = len(t)
    cdf = -np.expm1(-rate * t)
    i = np.arange(1, n + 1)
    return float(max(np.max(i / n - cdf), np.max(cdf - (i - 1) / n)))


def ks_to_cdf(x, cdf) -> float:
    """One-sample Kolmogorov-Smirnov distance of the samples x to a distribution function."""
    x = np.sort(np.asarray(x, float))
    n = len(x)
    c = cdf(x)
    i = np.arange(1, n + 1)
    return float(max(np.max(i / n - c), np.max(c - (i - 1) / n)))


def ks_critical(n: int, alpha: float = 1e-3) -> float:
    """Asymptotic one-sample KS critical value at level alpha."""
    return math.sqrt(-math.log(alpha / 2.0) / 2.0) / math.sqrt(n)
