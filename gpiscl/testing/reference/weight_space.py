"""Weight-space realizations in numpy: the twins of ws_features.h and ws_posterior.h that
the tests use as oracles (the tables the device samples live in gpiscl/host/gp/spectral.py).

The device regenerates feature i of a realization from Philox4x32-10 with counter
(key.x, key.y, object, i) and Philox key (call, WS_PHILOX_KEY1) (ws_features.h). Here:
  * philox4x32 and regenerate_features: the same streams in numpy (SE and periodic
    kinds; RQ's rejection sampler is compared through features dumped from the device);
  * evaluate / dense_scan_first_root: the reference realization and root finder of tests;
  * noise_normals / pathwise_sample: a posterior realization (ws_posterior.h) in numpy.
"""
from __future__ import annotations

import numpy as np

from ...host.gp.kernels import Kernel
from ...host.gp.spectral import RandomFeatures, periodic_order_cdf
from ...host.layout.constants import WS_CALL_MAIN, WS_CALL_NOISE, WS_CALL_ORDERS, WS_PHILOX_KEY1

_PHILOX_M = (0xD2511F53, 0xCD9E8D57)
_PHILOX_W = (0x9E3779B9, 0xBB67AE85)
_MASK = np.uint64(0xFFFFFFFF)
_2PI = 2.0 * np.pi


# --- the device's random streams in numpy ----------------------------------------------

def philox4x32(ctr, key0, key1=WS_PHILOX_KEY1, rounds: int = 10) -> np.ndarray:
    """Philox4x32-R of counters (..., 4) under key (key0, key1), as Random123 defines it."""
    c = [np.asarray(ctr, np.uint64)[..., j] for j in range(4)]
    k0, k1 = np.uint64(key0), np.uint64(key1)
    for r in range(rounds):
        if r:
            k0 = (k0 + np.uint64(_PHILOX_W[0])) & _MASK
            k1 = (k1 + np.uint64(_PHILOX_W[1])) & _MASK
        p0, p1 = np.uint64(_PHILOX_M[0]) * c[0], np.uint64(_PHILOX_M[1]) * c[2]
        c = [(p1 >> np.uint64(32)) ^ c[1] ^ k0, p1 & _MASK,
             (p0 >> np.uint64(32)) ^ c[3] ^ k1, p0 & _MASK]
    return np.stack(c, -1).astype(np.uint32)


def _u01(r, open_=False):
    r = (r >> np.uint32(8)).astype(np.float64)
    return (r + 1.0 if open_ else r) * 2.0**-24


def _normal2(r0, r1):
    rad = np.sqrt(-2.0 * np.log(_u01(r0, True)))
    ang = _2PI * _u01(r1)
    return rad * np.cos(ang), rad * np.sin(ang)


def regenerate_features(kernel: Kernel, key, obj: int, m: int, order_cdf=None):
    """theta (m, 3), tau (m,), w (m,) of ws_feature, in float64 (the device rounds to
    float32 along the way). SE, periodic and locally periodic kinds."""
    i = np.arange(m, dtype=np.uint64)
    ctr = np.stack(np.broadcast_arrays(np.uint64(key[0]), np.uint64(key[1]),
                                       np.uint64(obj), i), -1)
    r = philox4x32(ctr, WS_CALL_MAIN)
    g0, g1 = _normal2(r[:, 0], r[:, 1])
    g2, w = _normal2(r[:, 2], r[:, 3])
    low = ((r[:, 0] & 255) | ((r[:, 1] & 255) << 8) | ((r[:, 2] & 255) << 16)
           | (r[:, 3] << 24)).astype(np.uint32)
    tau = _2PI * _u01(low)
    z = np.stack([g0, g1, g2], -1)
    sa = np.sqrt(np.asarray(kernel.aniso, float))
    if kernel.kind == "squared_exponential":
        return sa * z / kernel.length_scale, tau, w
    if kernel.kind not in ("periodic", "locally_periodic"):
        raise ValueError(f"no numpy twin of the {kernel.kind} stream; dump it from the device")
    cdf = periodic_order_cdf(kernel.length_scale) if order_cdf is None else order_cdf
    q = philox4x32(ctr, WS_CALL_ORDERS)
    n = np.stack([np.searchsorted(cdf, _u01(q[:, j]).astype(np.float32), side="right")
                  for j in range(3)], -1).astype(float)
    n *= np.where((q[:, 3:4] >> np.arange(3, dtype=np.uint32)) & 1, -1.0, 1.0)
    theta = _2PI * kernel.w * sa * n
    if kernel.kind == "locally_periodic":
        theta = theta + sa * z / kernel.se_length_scale
    return theta, tau, w


# --- reference realization and root finder ----------------------------------------------

def evaluate(theta, tau, w, variance: float, x, mean=None):
    """Value (...) and gradient (..., 3) of the realization at x (..., 3), in float64."""
    theta = np.asarray(theta, float)
    feats = RandomFeatures(theta, np.asarray(tau, float), float(np.sqrt(variance)))
    value, grad = feats.evaluate(np.asarray(w, float), x)
    if mean is not None:
        mv, mg = mean.value_and_gradient(np.asarray(x, float))
        value, grad = value + mv, grad + mg
    return value, grad


def evaluate_value(theta, tau, w, variance: float, x, mean=None):
    """evaluate()'s value alone, the same numbers (RandomFeatures.evaluate's formula):
    dense scans need no gradient, whose sines and product were half their cost."""
    theta, tau = np.asarray(theta, float), np.asarray(tau, float)
    c = float(np.sqrt(variance)) * np.sqrt(2.0 / len(tau))
    value = c * np.cos(np.asarray(x, dtype=np.float64) @ theta.T + tau) @ np.asarray(w, float)
    if mean is not None:
        value = value + mean.value(np.asarray(x, float))
    return value


def dense_scan_first_root(values, t, leave_above=None):
    """First one-sided crossing in sampled values (..., n) at parameters t (n,).

    Returns the bracket (t_lo, t_hi] per ray, with t_hi = inf where there is none: the
    first sample < 0 after one >= 0 (a ray starting inside must first come back out).
    leave_above (broadcast to values): count only samples above it as back out, as the
    device does (it leaves the inside only where f clears its rounding noise).
    """
    values = np.asarray(values)
    out = values >= 0.0 if leave_above is None else values > leave_above
    seen = np.maximum.accumulate(out, axis=-1)
    hit = (values < 0.0) & np.concatenate([np.zeros_like(seen[..., :1]), seen[..., :-1]], -1)
    any_hit = hit.any(axis=-1)
    k = np.argmax(hit, axis=-1)
    t = np.asarray(t, float)
    t_hi = np.where(any_hit, t[k], np.inf)
    t_lo = np.where(any_hit, t[np.maximum(k - 1, 0)], np.inf)
    return t_lo, t_hi


def spectral_moment2(kernel: Kernel, d) -> float:
    """E[(theta . d)^2] = Var(d/dt f(o + t d)) / k(0): Rice's lambda_2 / lambda_0."""
    d = np.asarray(d, float)
    return float(kernel.cov_dd(np.zeros(3), d, np.zeros(3), d) / kernel.variance)


# --- posterior realizations (pathwise conditioning) --------------------------------------

def noise_normals(key, obj: int, n: int) -> np.ndarray:
    """The standard normals z_j (n,) that scale observation row j's noise draw e_j = sd_j z_j
    in realization `key` of object `obj` (ws_post_prepare), in float64."""
    i = np.arange(n, dtype=np.uint64)
    ctr = np.stack(np.broadcast_arrays(np.uint64(key[0]), np.uint64(key[1]),
                                       np.uint64(obj), i), -1)
    r = philox4x32(ctr, WS_CALL_NOISE)
    return _normal2(r[:, 0], r[:, 1])[0]


class _Draws:
    """An rng whose standard normals are given (PathwiseSample draws its noise from one)."""

    def __init__(self, z):
        self.z = np.asarray(z, float)

    def standard_normal(self, n):
        assert n == len(self.z)
        return self.z


def pathwise_sample(post, theta, tau, w, key, obj: int = 0):
    """The posterior realization the device builds for `key` from these features (e.g.
    dumped from the device): Matheron's rule with the device's noise draws, in float64."""
    feats = RandomFeatures(np.asarray(theta, float), np.asarray(tau, float),
                           float(np.sqrt(post.kernel.variance)))
    return post.pathwise(feats, w, _Draws(noise_normals(key, obj, len(post.obs))))
