"""Importance sampling of a lat-long environment map, with numpy reference samplers.

Convention (shared with kernels_cl/lib/lights/environment_map.h):
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

Memory (an 8192 x 4096 map is 33.5M texels): the device's float4 texels (16 bytes a
texel) are filled from the decoded float32 RGB (12), which is then dropped; the tables are
built from the texels a band of rows at a time. Luminance, weights and CDFs stay in
double, with the same operations in the same order as the whole-map code they replace, so
the tables (and every image) are bit for bit what they were: a row's CDF sums up to 8192
weights spanning many decades, where float32 would lose the dim texels' share (and change
the tables of the shipped sky). The peak is 28 bytes a texel (the RGB beside the texels),
checked against the memory budget before reading; the whole-map double copies peaked at
~80 (docs/design/memory-budget.md, 'Environment maps').
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.radiance_hdr import read_environment_rgb
from ..layout.struct import PAGE

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
# the decoded RGB (12 bytes a texel) beside the device's float4 texels (16)
COMPILE_BYTES_PER_TEXEL = 12 + 16
# texels per band of rows: its double temporaries take a few MB, whatever the map's size
BAND_TEXELS = 1 << 18


@dataclass
class EnvmapTables:
    marginal_cdf: np.ndarray      # (H+1,) float32 over rows
    conditional_cdf: np.ndarray   # (H, W+1) float32 over columns, one CDF per row

    @property
    def shape(self) -> tuple:
        return self.conditional_cdf.shape[0], self.conditional_cdf.shape[1] - 1

    @property
    def pixel_pdf(self) -> np.ndarray:
        """(H, W) float32 discrete probability of each pixel, as the device reads it
        (a reference for tests: the device needs only the CDFs)."""
        pixel = (np.diff(self.marginal_cdf.astype(np.float64))[:, None]
                 * np.diff(self.conditional_cdf.astype(np.float64), axis=1))
        return pixel.astype(np.float32)


@dataclass
class DeviceEnvmap:
    texels: np.ndarray            # (H*W, 4) float32 radiance, page-aligned (used in place)
    marginal: np.ndarray          # (H+1,) float32
    conditional: np.ndarray       # (H*(W+1),) float32, page-aligned
    size: tuple                   # (W, H)


def _page_aligned_float32(shape) -> np.ndarray:
    """Zeros starting on a page: a CPU device uses such an array in place
    (render.device.to_device), where an unaligned one (numpy's large arrays start 16
    bytes past a page) would be copied: the texels twice."""
    n = int(np.prod(shape))
    raw = np.zeros(4 * n + PAGE, np.uint8)
    start = -raw.ctypes.data % PAGE
    return raw[start:start + 4 * n].view(np.float32).reshape(shape)


def compile_envmap(path) -> DeviceEnvmap:
    """The device's arrays for the environment map file at path; ValueError (naming the
    file) for a map without pixels or one the memory budget cannot hold."""
    rgb = read_environment_rgb(path, COMPILE_BYTES_PER_TEXEL)
    h, w = rgb.shape[:2]
    texels = _page_aligned_float32((h * w, 4))
    texels[:, :3] = rgb.reshape(-1, 3)
    del rgb                       # the caller holds no reference: 12 bytes a texel freed
    tables = build_envmap_tables(texels.reshape(h, w, 4), aligned=True)
    return DeviceEnvmap(texels, tables.marginal_cdf, tables.conditional_cdf.reshape(-1),
                        (w, h))


def no_envmap() -> DeviceEnvmap:
    """The device's arrays where a scene has no environment map: one black texel."""
    return DeviceEnvmap(np.zeros((1, 4), np.float32), np.array([0.0, 1.0], np.float32),
                        np.array([0.0, 1.0], np.float32), (1, 1))


def _cdf(weights: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Normalised float32 CDFs along the last axis (float64 weights, each row's sum > 0),
    into out when given."""
    c = np.cumsum(weights, axis=-1)
    c = c / c[..., -1:]
    if out is None:
        out = np.zeros(weights.shape[:-1] + (weights.shape[-1] + 1,), np.float32)
    out[..., 0] = 0.0
    out[..., 1:] = c
    out[..., -1] = 1.0  # exactly, so a search for u < 1 always lands inside
    return out


def _luminance(band) -> np.ndarray:
    """Luminance of a band of rows (rows, W, 3 or 4), in double; negative or non-finite
    luminance weighs zero."""
    lum = np.asarray(band[..., :3], dtype=np.float64) @ LUMINANCE
    lum = np.nan_to_num(lum, nan=0.0, posinf=0.0, neginf=0.0)
    return np.maximum(lum, 0.0)


def build_envmap_tables(rgb, aligned: bool = False) -> EnvmapTables:
    """Sampling tables for rgb (H,W,3) or (H,W,4) (the fourth channel ignored); negative
    or non-finite luminance weighs zero. aligned: the conditional CDFs page-aligned, for
    the device to use in place.

    A black row gets a uniform conditional CDF and a black map is sampled uniformly over
    the sphere, so the tables always describe a valid sampler.
    """
    h, w = np.shape(rgb)[:2]
    if h < 1 or w < 1:   # nothing to sample: the device would read past an empty map
        raise ValueError(f"an environment map needs at least one pixel (got {w} x {h})")
    sin_theta = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    rows_per_band = max(1, BAND_TEXELS // w)
    bands = [slice(r, min(r + rows_per_band, h)) for r in range(0, h, rows_per_band)]
    conditional = (_page_aligned_float32((h, w + 1)) if aligned
                   else np.zeros((h, w + 1), np.float32))
    row_sum = np.zeros(h)

    def add_band(rows, lum):
        weight = lum * sin_theta[rows, None]
        row_sum[rows] = weight.sum(axis=1)
        # rows that cannot be chosen still need a valid CDF to search in
        _cdf(np.where(row_sum[rows, None] > 0, weight, 1.0), conditional[rows])

    lit = False
    for rows in bands:
        lum = _luminance(rgb[rows])
        lit = lit or bool(lum.any())
        add_band(rows, lum)
    if not lit:
        # a black map is still a valid light to sample: uniform over the sphere
        for rows in bands:
            add_band(rows, np.ones((rows.stop - rows.start, w)))
    return EnvmapTables(_cdf(row_sum), conditional)


def _pixel_prob(tables: EnvmapTables, row, col) -> np.ndarray:
    """The same arithmetic as env_pixel_prob on the device."""
    m = tables.marginal_cdf.astype(np.float64)
    c = tables.conditional_cdf.astype(np.float64)
    return (m[row + 1] - m[row]) * (c[row, col + 1] - c[row, col])


def _search(cdfs: np.ndarray, which: np.ndarray, u: np.ndarray):
    """cdf_search of lights/environment_map.h, per sample k on the CDF cdfs[which[k]] (each n+1 long).

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
