"""numpy twin of the rough conductor of kernels_cl/lib/bsdf/rough_conductor.h (Beckmann
microfacets, exact conductor Fresnel, height-correlated Smith masking): the reference the
tests hold the device to."""
from __future__ import annotations

import math

import numpy as np

_erfc = np.vectorize(math.erfc, otypes=[float])


def fresnel_conductor(c, eta, k):
    """Unpolarised reflectance for incidence cosine c (...,) and RGB eta, k: (..., 3)."""
    c = np.clip(np.asarray(c, float), 0.0, 1.0)[..., None]
    eta, k = np.asarray(eta, float), np.asarray(k, float)
    c2, s2 = c * c, 1.0 - c * c
    t0 = eta * eta - k * k - s2
    a2b2 = np.sqrt(t0 * t0 + 4 * eta * eta * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    rs = (a2b2 + c2 - 2 * a * c) / (a2b2 + c2 + 2 * a * c)
    t1, t2 = c2 * a2b2 + s2 * s2, 2 * a * c * s2
    return 0.5 * (rs + rs * (t1 - t2) / (t1 + t2))


def beckmann_lambda(c, alpha):
    c = np.asarray(c, float)
    s = np.sqrt(np.maximum(1.0 - c * c, 0.0))
    q = c / (alpha * np.where(s > 0, s, 1.0))
    lam = 0.5 * (np.exp(-q * q) / (q * math.sqrt(math.pi)) - _erfc(q))
    return np.where(s > 0, lam, 0.0)


def beckmann_d(cm, alpha):
    c2, a2 = np.asarray(cm, float) ** 2, alpha * alpha
    return np.exp(-(1 - c2) / (c2 * a2)) / (math.pi * a2 * c2 * c2)


def eval_fcos(albedo, eta, k, alpha, n, v, l):
    """f(v, l) cos(l) (..., 3) and the sampling pdf of l (...,), as rough_conductor_eval."""
    n, v, l = (np.asarray(a, float) for a in (n, v, l))
    cv, cl = np.sum(n * v, -1), np.sum(n * l, -1)
    m = v + l
    m = m / np.linalg.norm(m, axis=-1, keepdims=True)
    cm, vm = np.sum(n * m, -1), np.sum(v * m, -1)
    ok = (cv > 0) & (cl > 0) & (cm > 0) & (vm > 0)
    cm_s = np.where(ok, cm, 1.0)
    D = beckmann_d(cm_s, alpha)
    G = 1.0 / (1.0 + beckmann_lambda(np.where(ok, cv, 1.0), alpha)
               + beckmann_lambda(np.where(ok, cl, 1.0), alpha))
    pdf = np.where(ok, D * cm_s / (4 * np.where(ok, vm, 1.0)), 0.0)
    f = (np.asarray(albedo, float) * fresnel_conductor(np.where(ok, vm, 1.0), eta, k)
         * (D * G / (4 * np.where(ok, cv, 1.0)))[..., None])
    return np.where(ok[..., None], f, 0.0), pdf
