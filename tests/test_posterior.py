"""Posterior GPIS on the host: exact conditioning against a dense reference built from
the kernels' pairwise covariances, and pathwise (Matheron) samples against the exact
posterior."""
import math

import numpy as np
import pytest

from gpiscl.host.gp import RationalQuadratic, Sphere, SquaredExponential
from gpiscl.host.gp.posterior import (Observations, Posterior, solve_triangular,
                                      surface_observations)
from gpiscl.host.gp.spectral import RandomFeatures

from gpiscl.testing.oracles import dense_reference
from gpiscl.testing.stats import z_threshold

KERNELS = [SquaredExponential(sigma=0.5, length_scale=0.6),
           RationalQuadratic(sigma=0.4, length_scale=0.5, alpha=1.5, aniso=(1.0, 0.5, 2.0))]
MEAN = Sphere(radius=1.0)


def sphere_points(n, radius, rng):
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return radius * d, d


def test01_blocked_triangular_solve_matches_numpy():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((300, 300))
    L = np.linalg.cholesky(A @ A.T + 300 * np.eye(300))
    B = rng.standard_normal((300, 4))
    np.testing.assert_allclose(solve_triangular(L, B, block=64), np.linalg.solve(L, B),
                               rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(solve_triangular(L, B[:, 0], transpose=True, block=7),
                               np.linalg.solve(L.T, B[:, 0]), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test02_posterior_matches_dense_regression_with_values_normals_and_inside(kernel):
    rng = np.random.default_rng(1)
    p, nrm = sphere_points(12, 0.8, rng)
    obs = surface_observations(p, nrm, noise=1e-4, normal_noise=1e-2,
                               inside=[[0.0, 0.0, 0.0]], outside=[[1.5, 0.0, 0.0]], offset=0.3)
    assert len(obs) == 12 * 4 + 2
    post = Posterior(kernel, MEAN, obs)
    probes = rng.uniform(-1.2, 1.2, (40, 3))
    mu, var = dense_reference(kernel, MEAN, obs, probes)
    np.testing.assert_allclose(post.mean(probes), mu, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(post.variance(probes), var, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(np.diag(post.covariance(probes)), var, rtol=1e-6, atol=1e-9)
    # the data are honoured: f ~ 0 at the surface points, grad f ~ n there
    assert np.abs(post.mean(p)).max() < 0.02
    assert np.abs(post.mean_gradient(p) - nrm).max() < 0.2
    assert post.variance(p).max() < 0.01 * kernel.variance


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test03_pathwise_samples_have_the_posterior_mean_and_covariance(kernel):
    """Matheron's rule on random-feature priors (features redrawn per sample, so the
    prior's first two moments are exact): mean and covariance at probes match."""
    rng = np.random.default_rng(2)
    p, nrm = sphere_points(10, 0.8, rng)
    obs = surface_observations(p, nrm, noise=1e-3, normal_noise=1e-2)
    post = Posterior(kernel, MEAN, obs)
    probes = np.array([[0.0, 0.0, 0.0], [0.9, 0.1, 0.0], [0.0, -1.1, 0.3], [0.5, 0.5, 0.5]])
    n, m = 3000, 64
    vals = np.empty((n, len(probes)))
    for i in range(n):
        feats = RandomFeatures.sample(kernel, m, rng)
        vals[i] = post.pathwise(feats, rng.standard_normal(m), rng)(probes)
    mu, C = post.mean(probes), post.covariance(probes)
    t = z_threshold(len(probes) + len(probes) * (len(probes) + 1) // 2)
    z_mean = (vals.mean(0) - mu) / (vals.std(0, ddof=1) / math.sqrt(n))
    assert np.abs(z_mean).max() < t, np.round(z_mean, 2)
    d = vals - mu
    iu = np.triu_indices(len(probes))
    prods = (d[:, :, None] * d[:, None, :])[:, iu[0], iu[1]]
    z_cov = (prods.mean(0) - C[iu]) / (prods.std(0, ddof=1) / math.sqrt(n))
    assert np.abs(z_cov).max() < t, np.round(z_cov, 2)


def test04_reconstruction_tightens_as_the_noise_shrinks():
    """A sphere of radius 0.7 from 200 noisy points under a wrong prior (radius 1):
    the posterior mean's zero level approaches 0.7 as the point noise shrinks."""
    rng = np.random.default_rng(4)
    kernel = SquaredExponential(sigma=0.3, length_scale=0.4)
    dirs = sphere_points(30, 1.0, rng)[1]
    t = np.linspace(0.3, 1.2, 400)
    errors = []
    for sd in (0.05, 0.01):
        p, nrm = sphere_points(200, 0.7, rng)
        p = p + sd * rng.standard_normal(p.shape)
        post = Posterior(kernel, MEAN, surface_observations(p, noise=sd**2 + 1e-6))
        f = post.mean((dirs[:, None, :] * t[None, :, None]).reshape(-1, 3)).reshape(len(dirs), -1)
        r = t[np.argmax(f >= 0.0, axis=1)]          # first radius where the mean is outside
        errors.append(np.abs(r - 0.7).mean())
    assert errors[1] < 0.6 * errors[0] and errors[1] < 0.01, errors


def test05_duplicate_points_without_noise_are_handled_by_jitter():
    kernel = KERNELS[0]
    obs = Observations.values([[0.1, 0.2, 0.3]] * 3 + [[0.5, 0.0, 0.0]], 0.0, noise=0.0)
    post = Posterior(kernel, MEAN, obs)
    assert post.jitter > 0.0
    assert abs(post.mean([[0.1, 0.2, 0.3]])[0]) < 1e-3
