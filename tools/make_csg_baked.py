"""Writes the grids of scenes/csg_baked.json: the authors' single-GP, moment-matched
approximation of their CSG test (gp-csg-test/baked-32.json, baked-64.json).

The union of two independent GPIS is f = min(f_a, f_b). At each grid point its mean and
standard deviation follow in closed form for independent Gaussians (Clark 1961; with
theta = sqrt(s_a^2 + s_b^2), alpha = (m_b - m_a) / theta):
    E[min]   = m_a Phi(alpha) + m_b Phi(-alpha) - theta phi(alpha)
    E[min^2] = (m_a^2 + s_a^2) Phi(alpha) + (m_b^2 + s_b^2) Phi(-alpha)
               - (m_a + m_b) theta phi(alpha)
The authors sampled the union instead (tools bake-csg: pointwise sample mean and
deviation); the closed form is their estimate's limit. The baked GP keeps the leaves'
SE kernel (l = 0.5) with sigma 1 and the deviation as its sigma(x) multiplier, as their
`nonstationary` kernel does: the one-point law of f is exact, its correlations are the
kernel's, not those of the min (the approximation the scene shows).

    python tools/make_csg_baked.py [--resolution 32]

Output: scenes/assets/csg_baked_mean.npz and csg_baked_sigma.npz (origin and voxel size
as the authors': the process box [-1.5, 1.5] x [-0.499, 2.501] x [-1.5, 1.5]).
"""
import argparse
import math
from pathlib import Path

import numpy as np

_erfc = np.vectorize(math.erfc, otypes=[float])


def ndtr(z):
    """The standard normal CDF (erfc keeps the lower tail accurate)."""
    return 0.5 * _erfc(-np.asarray(z) / math.sqrt(2.0))

ASSETS = Path(__file__).resolve().parent.parent / "scenes" / "assets"
# the authors' leaves (gp-csg-test/standard.json): sphere centre, radius, sigma
LEAVES = (((-0.4, 0.8, 0.0), 0.8, 0.1), ((0.4, 0.8, 0.0), 0.5, 0.001))
ORIGIN = np.array([-1.5, -0.499, -1.5])
EXTENT = 3.0


def min_moments(m_a, s_a, m_b, s_b):
    """Mean and standard deviation of min(A, B), A ~ N(m_a, s_a^2), B ~ N(m_b, s_b^2)
    independent (Clark 1961)."""
    theta = np.sqrt(s_a**2 + s_b**2)
    alpha = (m_b - m_a) / theta
    pdf = np.exp(-0.5 * alpha**2) / np.sqrt(2 * np.pi)
    cdf, ccdf = ndtr(alpha), ndtr(-alpha)
    mean = m_a * cdf + m_b * ccdf - theta * pdf
    second = (m_a**2 + s_a**2) * cdf + (m_b**2 + s_b**2) * ccdf - (m_a + m_b) * theta * pdf
    return mean, np.sqrt(np.maximum(second - mean**2, 0.0))


def bake(resolution: int):
    h = EXTENT / resolution
    axes = [ORIGIN[a] + h * np.arange(resolution + 1) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    (ca, ra, sa), (cb, rb, sb) = LEAVES
    m_a = np.linalg.norm(x - np.asarray(ca), axis=-1) - ra
    m_b = np.linalg.norm(x - np.asarray(cb), axis=-1) - rb
    return min_moments(m_a, sa, m_b, sb), h


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=32, help="voxels per axis (32 or 64 "
                    "as the authors)")
    args = ap.parse_args()
    (mean, sd), h = bake(args.resolution)
    for name, values in (("mean", mean), ("sigma", sd)):
        np.savez_compressed(ASSETS / f"csg_baked_{name}.npz", values=values.astype(np.float32),
                            origin=ORIGIN, voxel_size=np.float64(h))
    print(f"grids {mean.shape}, voxel {h:.4g}; sigma multiplier {sd.min():.3g}..{sd.max():.3g}")


if __name__ == "__main__":
    main()
