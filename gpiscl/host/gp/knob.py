"""The authors' "material test knob" signed distance (their SdfFunctions.cpp in
daseyb/gpis-light-transport), vectorised in numpy.

Reproduced as written, including what is not a true distance (the cone's c = (pi/3, pi/3)
is not a unit (sin, cos) pair and 0.7 scales the base): these are bounds-free shapes that
the GPIS only uses as a mean, baked to a grid whose interpolant's slope is measured.
"""
from __future__ import annotations

import functools

import numpy as np


def _len(*c):
    return np.sqrt(sum(ci * ci for ci in c))


def _rot_x(p, degrees):
    """Right-handed rotation about +x applied to points (..., 3)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack([x, c * y - s * z, s * y + c * z], -1)


def _sphere(p, r):
    return _len(p[..., 0], p[..., 1], p[..., 2]) - r


def _torus(p, big, small):
    return _len(_len(p[..., 0], p[..., 2]) - big, p[..., 1]) - small


def _cone(p, c):
    return c[0] * _len(p[..., 0], p[..., 1]) + c[1] * p[..., 2]


def _capped_cylinder(p, h, r):
    qx = _len(p[..., 0], p[..., 2]) - h
    qy = np.abs(p[..., 1]) - r
    return np.minimum(np.maximum(qx, qy), 0.0) + _len(np.maximum(qx, 0.0), np.maximum(qy, 0.0))


def _tri_prism(p, h1, h2):
    q = np.abs(p)
    return np.maximum(q[..., 2] - h2,
                      np.maximum(0.866025 * q[..., 0] + 0.5 * p[..., 1], -p[..., 1]) - 0.5 * h1)


def _smooth_union(d1, d2, k):
    h = np.clip(0.5 + 0.5 * (d2 - d1) / k, 0.0, 1.0)
    return d2 + (d1 - d2) * h - k * h * (1.0 - h)


def _ssub(d1, d2, k):
    h = np.clip(0.5 - 0.5 * (d2 + d1) / k, 0.0, 1.0)
    return d2 + (-d1 - d2) * h + k * h * (1.0 - h)


def _base(p):
    c = (np.pi / 3, np.pi / 3)
    up, down = np.array([0.0, 0.9, 0.0]), np.array([0.0, 0.9, 0.0])
    b = _smooth_union(_cone(_rot_x(p + up, -90), c), _cone(_rot_x(p - down, 90), c), 0.02)
    b = 0.7 * np.maximum(b, _capped_cylinder(p, 1.1, 0.25))
    b = np.maximum(-_capped_cylinder(p, 0.6, 0.3), b)
    return np.maximum(-_tri_prism(_rot_x(p + np.array([0.0, 0.0, -1.0]), 90), 1.2, 0.3), b)


def _knob0(p, outer: bool):
    S = _sphere(p, 1.0)
    C = _sphere(p - np.array([0.0, 0.5, 0.5]), 0.7)
    E = _torus(_rot_x(p - np.array([0.0, 0.2, 0.2]), -45), 1.0, 0.05)
    inner = _sphere(p, 0.75)
    d = _ssub(C, S, 0.1)
    d = np.maximum(d, -inner) if outer else np.minimum(d, inner)
    d = np.maximum(-E, d)
    return np.minimum(_ssub(S, _base(p - np.array([0.0, -0.775, 0.0])), 0.1), d)


def knob(p):
    p = np.asarray(p, float)
    return 0.8 * _knob0(p / 0.8, outer=False)


def knob_outer(p):
    p = np.asarray(p, float)
    return 0.8 * _knob0(p / 0.8, outer=True)


def knob_inner(p):
    p = np.asarray(p, float)
    return _sphere(p, 0.6)


FUNCTIONS = {"knob": knob, "knob_inner": knob_inner, "knob_outer": knob_outer}
# Where each function's zero set lies (object space), with room for the GP to move it.
BOUNDS = {"knob": (np.array([-1.1, -1.0, -1.1]), np.array([1.1, 1.0, 1.0])),
          "knob_outer": (np.array([-1.1, -1.0, -1.1]), np.array([1.1, 1.0, 1.0])),
          "knob_inner": (np.array([-0.8, -0.8, -0.8]), np.array([0.8, 0.8, 0.8]))}


def grid_placement(function: str, resolution: int):
    """(origin, voxel size, sample counts) of knob_grid (and of its device twin)."""
    lo, hi = BOUNDS[function]
    voxel = float(np.max(hi - lo)) / (resolution - 1)
    return lo, voxel, np.ceil((hi - lo) / voxel).astype(int) + 1


@functools.lru_cache(maxsize=8)
def knob_grid(function: str, resolution: int = 128):
    """The function sampled on a grid over its bounds (longest side `resolution` samples):
    a GridMean the device interpolates, like any baked signed distance."""
    from .means import GridMean

    lo, voxel, n = grid_placement(function, resolution)
    axes = [lo[i] + voxel * np.arange(n[i]) for i in range(3)]
    values = np.empty(tuple(n), np.float32)
    # in slabs of a few x planes (~60k points): the function's dozens of elementwise
    # temporaries then stay in cache (docs/design/bakes.md, 'Slabs'), and
    # every sample is computed by the same float64 operations (the same values)
    for i in range(0, n[0], _SLAB):
        points = np.stack(np.meshgrid(axes[0][i:i + _SLAB], axes[1], axes[2], indexing="ij"),
                          -1)
        values[i:i + _SLAB] = FUNCTIONS[function](points)
    return GridMean(values, tuple(lo), voxel)


_SLAB = 4   # x planes per knob_grid pass
