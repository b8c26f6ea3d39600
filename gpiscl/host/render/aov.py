"""Arbitrary output variables: what each pixel's camera rays first hit, for denoisers.

Each path records its first scattering event (scatter.cl, depth 0: null surfaces such as a
volume's boundary are passed through, GPIS hits count with the normal their realization
sampled there) in three float4s of its state; the film adds them per pixel in sample order
in double, like the radiance, so AOVs are deterministic and independent of batch size.

Averaging, per pixel, over its samples:
  normal    sum of first-hit unit normals (facing the camera) / all samples: a rough GPIS
            gives a shorter mean normal where realizations disagree; a sample that hits
            nothing adds 0 (as OpenImageDenoise expects for the background)
  albedo    sum of first-hit albedos / all samples (background: 0)
  depth     sum of camera-to-hit distances / samples that hit (0 where none hit)
  position  sum of world-space hit points / samples that hit (0 where none hit)
  hits      the fraction of samples that hit something (written with depth or position,
            so that 0 there is not mistaken for a surface at the camera)
EXR layers: depth.Z, normal.X/Y/Z, albedo.R/G/B, position.X/Y/Z, hits.A.
"""
from __future__ import annotations

import numpy as np

from ..errors import SceneError, argument_source

AOVS = ("depth", "normal", "albedo", "position")
# film layout: 12 doubles a pixel = position xyz + distance, normal xyz + hit, albedo xyz + 0
FLOATS_PER_PIXEL = 12


def parse(text, option: str = "--aov") -> tuple:
    """'depth,normal' (or a list) -> ('depth', 'normal'); SceneError for an unknown name."""
    names = [n.strip().lower() for n in (text.split(",") if isinstance(text, str) else text)]
    unknown = [n for n in names if n not in AOVS]
    if unknown or not names:
        raise SceneError(argument_source(option), option,
                         f"unknown AOV {', '.join(map(repr, unknown)) or '(none)'} "
                         f"(choose from {', '.join(AOVS)})")
    return tuple(dict.fromkeys(names))


def channels(sums: np.ndarray, count: np.ndarray, names) -> dict:
    """EXR channels {name: (H, W) float32} of the AOVs asked for, from the film's per-pixel
    sums (H, W, 12) and sample counts (H, W)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        hits = sums[..., 7]
        per_hit = np.where(hits > 0, 1.0 / np.maximum(hits, 1e-300), 0.0)[..., None]
        per_sample = np.where(count > 0, 1.0 / np.maximum(count, 1e-300), 0.0)[..., None]
    out = {}
    if "depth" in names:
        out["depth.Z"] = sums[..., 3] * per_hit[..., 0]
    if "normal" in names:
        for i, c in enumerate("XYZ"):
            out[f"normal.{c}"] = sums[..., 4 + i] * per_sample[..., 0]
    if "albedo" in names:
        for i, c in enumerate("RGB"):
            out[f"albedo.{c}"] = sums[..., 8 + i] * per_sample[..., 0]
    if "position" in names:
        for i, c in enumerate("XYZ"):
            out[f"position.{c}"] = sums[..., i] * per_hit[..., 0]
    if "depth" in names or "position" in names:
        out["hits.A"] = hits * per_sample[..., 0]
    return {k: v.astype(np.float32) for k, v in out.items()}
