"""Importance sampling of a lat-long environment map, with numpy reference samplers.

Convention (shared with kernels_cl/lib/lights.h):
    d = (sin(theta) cos(phi), cos(theta), sin(theta) sin(phi)),
    theta in [0, pi] measured from +y, phi = atan2(z, x) in [0, 2 pi).
    Column x covers phi in [2 pi x / W, 2 pi (x+1) / W); row y covers
    theta in [pi y / H, pi (y+1) / H); row 0 is the top (+y).

A pixel is chosen with a discrete probability proportional to
luminance * sin(theta at the row centre); the position inside the pixel is uniform in
(theta, phi), so the solid-angle density is
    pdf(d) = p_pixel * W * H / (2 pi^2 sin(theta(d))).

The tables are float32 CDFs, and the device reads pixel probabilities as differences of
those CDFs, so pixel_pdf is defined the same way: host references and device agree to
the last bit on which pixels can be sampled.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class EnvmapTables:
    marginal_cdf: np.ndarray      # (H+1,) float32 over rows
    conditional_cdf: np.ndarray   # (H, W+1) float32 over columns, one CDF per row
    pixel_pdf: np.ndarray         # (H, W) float32 discrete probability of each pixel

    @property
    def shape(self) -> tuple:
        return self.pixel_pdf.shape


def _cdf(weights: np.ndarray) -> np.ndarray:
    """Normalised CDFs along the last axis (float64 weights, each row's sum > 0)."""
    c = np.cumsum(weights, axis=-1)
    c = c / c[..., -1:]
    out = np.zeros(weights.shape[:-1] + (weights.shape[-1] + 1,), np.float32)
    out[..., 1:] = c
    out[..., -1] = 1.0  # exactly, so a search for u < 1 always lands inside
    return out


def build_envmap_tables(rgb) -> EnvmapTables:
    """Sampling tables for rgb (H,W,3); negative or non-finite luminance weighs zero.

    A black row gets a uniform conditional CDF and a black map is sampled uniformly over
    the sphere, so the tables always describe a valid sampler.
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    h, w = rgb.shape[:2]
    lum = np.nan_to_num(rgb[..., :3] @ LUMINANCE, nan=0.0, posinf=0.0, neginf=0.0)
    lum = np.maximum(lum, 0.0)
    if not lum.any():
        # a black map is still a valid light to sample: uniform over the sphere
        lum = np.ones_like(lum)
    sin_theta = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    weight = lum * sin_theta[:, None]
    row_sum = weight.sum(axis=1)
    # rows that cannot be chosen still need a valid CDF to search in
    cond_weight = np.where(row_sum[:, None] > 0, weight, 1.0)
    conditional = _cdf(cond_weight)
    marginal = _cdf(row_sum)
    pixel = (np.diff(marginal.astype(np.float64))[:, None]
             * np.diff(conditional.astype(np.float64), axis=1))
    return EnvmapTables(marginal, conditional, pixel.astype(np.float32))


def _pixel_prob(tables: EnvmapTables, row, col) -> np.ndarray:
    """The same arithmetic as env_pixel_prob on the device."""
    m = tables.marginal_cdf.astype(np.float64)
    c = tables.conditional_cdf.astype(np.float64)
    return (m[row + 1] - m[row]) * (c[row, col + 1] - c[row, col])


def _search(cdfs: np.ndarray, which: np.ndarray, u: np.ndarray):
    """cdf_search of lights.h, per sample k on the CDF cdfs[which[k]] (each n+1 long).

    Returns the largest i < n with cdf[i] <= u and u's fraction inside bin i. That i is
    never a zero-width bin since cdf[n] = 1 > u.
    """
    cdfs = np.asarray(cdfs, dtype=np.float64)
    n = cdfs.shape[-1] - 1
    lo = np.zeros(len(u), np.int64)
    hi = np.full(len(u), n, np.int64)
    while np.any(hi - lo > 1):
        mid = (lo + hi) // 2
        below = cdfs[which, mid] <= u
        active = hi - lo > 1
        lo = np.where(active & below, mid, lo)
        hi = np.where(active & ~below, mid, hi)
    width = cdfs[which, lo + 1] - cdfs[which, lo]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(width > 0, np.clip((u - cdfs[which, lo]) / width, 0.0, 1.0), 0.5)
    return lo, frac


def sample_envmap(tables: EnvmapTables, u1, u2):
    """Directions (n,3) and their solid-angle pdfs (n,) for uniform numbers u1, u2 in [0,1)."""
    h, w = tables.shape
    u1 = np.atleast_1d(np.asarray(u1, dtype=np.float64))
    u2 = np.atleast_1d(np.asarray(u2, dtype=np.float64))
    u1, u2 = np.broadcast_arrays(u1, u2)
    row, fr = _search(tables.marginal_cdf[None], np.zeros(len(u1), np.int64), u1)
    col, fc = _search(tables.conditional_cdf, row, u2)
    theta = np.pi * (row + fr) / h
    phi = 2.0 * np.pi * (col + fc) / w
    s = np.sin(theta)
    d = np.stack([s * np.cos(phi), np.cos(theta), s * np.sin(phi)], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        pdf = np.where(s > 0, _pixel_prob(tables, row, col) * w * h
                       / (2.0 * np.pi**2 * s), 0.0)
    return d, pdf


def direction_to_pixel(directions, height: int, width: int):
    """(row, col, sin_theta) of the pixel each direction falls in."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    theta = np.arccos(np.clip(d[:, 1], -1.0, 1.0))
    phi = np.arctan2(d[:, 2], d[:, 0])
    phi = np.where(phi < 0, phi + 2.0 * np.pi, phi)
    row = np.clip((theta / np.pi * height).astype(np.int64), 0, height - 1)
    col = np.clip((phi / (2.0 * np.pi) * width).astype(np.int64), 0, width - 1)
    return row, col, np.sin(theta)


def envmap_pdf(tables: EnvmapTables, directions) -> np.ndarray:
    """Solid-angle pdf with which sample_envmap produces each direction."""
    h, w = tables.shape
    row, col, s = direction_to_pixel(directions, h, w)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0, _pixel_prob(tables, row, col) * w * h
                        / (2.0 * np.pi**2 * s), 0.0)


def envmap_lookup(rgb, directions) -> np.ndarray:
    """Radiance (n,3) of the pixel each direction falls in (no filtering)."""
    rgb = np.asarray(rgb)
    row, col, _ = direction_to_pixel(directions, *rgb.shape[:2])
    return rgb[row, col, :3]
