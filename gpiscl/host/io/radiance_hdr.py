"""Radiance RGBE (.hdr) images, the environment-map format of the authors' scenes, read
and written through imagecodecs (a maintained codec library; its rgbe codec is Bruce
Walter's reference rgbe.c), and the one reader for environment-map files of either kind.

RGBE stores an 8-bit mantissa per channel and one shared exponent per pixel: a channel
decodes to m 2^(e - 136), so a channel much dimmer than its pixel's brightest keeps few
digits. Rows are stored top first ("-Y H +X W"), the orientation gpiscl's lat-long maps
use (row 0 is +y).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .float_range import array_problem
from .images import read_exr_rgb, read_exr_size
from .memory_budget import memory_budget, size_text

# bytes a texel takes while read: an EXR's three float32 channels and their stacked copy
# (a .hdr decodes straight to 12)
DECODE_BYTES_PER_TEXEL = 24
_RESOLUTION = re.compile(rb"([-+])([XY]) (\d+) ([-+])([XY]) (\d+)")


def _codecs():
    import imagecodecs
    return imagecodecs


def read_hdr_rgb(path) -> np.ndarray:
    """(H, W, 3) float32 radiance of a Radiance .hdr file; ValueError naming the problem."""
    data = Path(path).read_bytes()
    if not data:
        raise ValueError(f"{path}: empty file (not a Radiance .hdr image)")
    try:
        rgb = _codecs().rgbe_decode(data)
    except Exception as exc:  # imagecodecs raises RgbeError or ValueError on bad data
        raise ValueError(f"{path}: cannot read as a Radiance .hdr image ({exc})") from None
    rgb = np.asarray(rgb, np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"{path}: expected an RGB image, got shape {rgb.shape}")
    return rgb


def write_hdr(path, rgb) -> None:
    """Write (H, W, 3) non-negative radiance as a run-length encoded Radiance .hdr file."""
    rgb = np.ascontiguousarray(rgb, np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"write_hdr: rgb must have shape (H, W, 3), got {rgb.shape}")
    if not np.all(np.isfinite(rgb)) or rgb.min() < 0:
        raise ValueError("write_hdr: RGBE stores finite, non-negative values only")
    Path(path).write_bytes(_codecs().rgbe_encode(rgb))


def environment_texels_problem(rgb) -> str | None:
    """Why decoded (H, W, 3) radiance cannot be an environment map, or None: no pixels (a
    .hdr header may say 0 x 0 and decode to an empty array, which the device would read
    past), or numbers the device cannot take."""
    height, width = rgb.shape[:2]
    if height < 1 or width < 1:
        return f"the image has no pixels ({width} x {height})"
    return array_problem(rgb, "environment map", nonnegative=True)


def hdr_size(path):
    """(width, height) from a .hdr file's header (text lines, a blank line, then e.g.
    "-Y 512 +X 1024"), or None where it has none (the decoder then says why)."""
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    _, blank, rest = head.partition(b"\n\n")
    match = _RESOLUTION.match(rest) if blank else None
    if not match or match[2] == match[5]:
        return None
    sizes = {match[2]: int(match[3]), match[5]: int(match[6])}
    return sizes[b"X"], sizes[b"Y"]


def environment_size(path):
    """(width, height) of an environment map from its header, or None if unknown."""
    if str(path).lower().endswith(".hdr"):
        return hdr_size(path)
    return read_exr_size(path)


def read_environment_rgb(path, bytes_per_texel: int = DECODE_BYTES_PER_TEXEL) -> np.ndarray:
    """An environment map's (H, W, 3) float32 radiance, from .hdr or OpenEXR; ValueError
    naming the file when it cannot be one, or, before decoding, when its header's size
    times bytes_per_texel (what the caller holds per texel at its peak) is more memory
    than the process can get (io/memory_budget.py)."""
    size = environment_size(path)
    if size is not None:
        width, height = size
        if width < 1 or height < 1:
            raise ValueError(f"{path}: the image has no pixels ({width} x {height})")
        need, budget = width * height * bytes_per_texel, memory_budget()
        if need > budget.bytes:
            raise ValueError(f"{path}: a {width} x {height} environment map needs about "
                             f"{size_text(need)}; {size_text(budget.bytes)} available, under "
                             f"{budget.limit}")
    if str(path).lower().endswith(".hdr"):
        rgb = read_hdr_rgb(path)
    else:
        rgb = read_exr_rgb(path)
    problem = environment_texels_problem(rgb)
    if problem:
        raise ValueError(f"{path}: {problem}")
    return rgb


def hdr_problem(path) -> str | None:
    """Why a .hdr file cannot serve as an environment map, or None (for the scene
    loader's File checks)."""
    try:
        read_environment_rgb(path)
    except (OSError, ValueError) as exc:
        return str(exc).removeprefix(f"{path}: ")
    return None
