"""Image files: float32 OpenEXR (render output, environment maps) and an 8-bit PNG preview.

The PNG writer needs only zlib and struct so previews work without Pillow.
"""
from __future__ import annotations

import contextlib
import os
import struct
import sys
import zlib

import numpy as np

# OpenEXR is imported where it is used: a render that writes only a PNG and reads no EXR
# does not map the binding and its libraries


def write_exr(path, rgb, extra=None, attributes=None) -> None:
    """Write rgb (H,W,3) as float32 channels R, G, B plus extra {name: (H,W)} channels,
    and attributes {name: str | int | float} in the header.

    ZIP compression is lossless, so a read gives back the same bits.
    """
    import OpenEXR
    rgb = np.asarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"write_exr: rgb must have shape (H, W, 3), got {rgb.shape}")
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    for name, values in (extra or {}).items():
        values = np.ascontiguousarray(values, dtype=np.float32)
        if values.shape != rgb.shape[:2]:
            raise ValueError(f"write_exr: channel {name!r} has shape {values.shape}, "
                             f"expected {rgb.shape[:2]}")
        if name in channels:
            raise ValueError(f"write_exr: channel {name!r} given twice")
        channels[name] = values
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update(attributes or {})
    OpenEXR.File(header, channels).write(str(path))


@contextlib.contextmanager
def _library_output_muted():
    """OpenEXR's C++ core and binding print their own diagnostics of a damaged file
    straight to the file descriptors ("EXR_ERR_BAD_CHUNK_LEADER ..." on 2, "Warning:
    Exception raised reading pixel data ..." on 1), two lines besides the one-line error
    the caller raises: both point at /dev/null while the library reads (scene loading runs
    before any progress output). Python's buffers are flushed before they point back:
    the binding prints through sys.stdout, whose buffer held the warning until the
    process exited (the line reached a CLI's stdout unless PYTHONUNBUFFERED was set)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    try:
        with open(os.devnull, "w") as null:
            for fd in saved:
                os.dup2(null.fileno(), fd)
        yield
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)


def read_exr_attributes(path) -> dict:
    """The header attributes of an EXR file."""
    import OpenEXR
    with _library_output_muted():
        return dict(OpenEXR.File(str(path)).header())


def read_exr_channel_names(path) -> set:
    """The channel names of an EXR file, from its header where the binding can read a
    header alone (OpenEXR 3.2's File reads the pixels too)."""
    import OpenEXR
    with _library_output_muted():
        if hasattr(OpenEXR, "InputFile"):
            f = OpenEXR.InputFile(str(path))
            try:
                return set(f.header()["channels"])
            finally:
                f.close()
        return set(OpenEXR.File(str(path), separate_channels=True).channels())


def read_exr_size(path):
    """(width, height) of an EXR file from its header alone, or None where this binding
    reads no header alone (before OpenEXR 3.3) or the header is damaged."""
    import OpenEXR
    try:
        with _library_output_muted():
            header = OpenEXR.File(str(path), header_only=True).header()
        (x0, y0), (x1, y1) = header["dataWindow"]
    except Exception:  # TypeError: no header_only; damage: several types, read reports it
        return None
    return int(x1) - int(x0) + 1, int(y1) - int(y0) + 1


def read_exr(path) -> dict:
    """All channels of an EXR file as {name: (H,W) float32} (half channels are widened)."""
    import OpenEXR
    with _library_output_muted():
        f = OpenEXR.File(str(path), separate_channels=True)
        return {name: np.asarray(ch.pixels, dtype=np.float32)
                for name, ch in f.channels().items()}


def read_exr_rgb(path) -> np.ndarray:
    channels = read_exr(path)
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        raise ValueError(f"{path}: EXR file lacks channel(s) {', '.join(missing)} "
                         f"(has {', '.join(sorted(channels)) or 'none'})")
    return np.stack([channels[c] for c in "RGB"], axis=-1)


TONEMAPS = ("clamp", "filmic")


def tonemap_srgb8(rgb, exposure: float = 0.0, curve: str = "clamp") -> np.ndarray:
    """Linear radiance -> 8-bit display values, after scaling by 2**exposure:
      clamp   clamp to [0, 1], sRGB-encode
      filmic  Hejl and Burgess-Dawson's filmic curve (the authors' Tungsten "filmic"):
              x' = max(x - 0.004, 0), y = x' (6.2 x' + 0.5) / (x' (6.2 x' + 1.7) + 0.06),
              display-encoded already (its shape includes the gamma); highlights roll
              off instead of clipping
    """
    x = np.nan_to_num(np.asarray(rgb, dtype=np.float64) * 2.0 ** exposure, nan=0.0)
    if curve == "filmic":
        x = np.maximum(x - 0.004, 0.0)
        y = np.clip(x * (6.2 * x + 0.5) / (x * (6.2 * x + 1.7) + 0.06), 0.0, 1.0)
        return np.rint(y * 255.0).astype(np.uint8)
    if curve != "clamp":
        raise ValueError(f"unknown tonemap {curve!r} (expected one of {TONEMAPS})")
    x = np.clip(x, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.rint(srgb * 255.0).astype(np.uint8)


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + tag + data
            + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))


def write_png(path, rgb_uint8) -> None:
    """Write an (H,W,3) uint8 image as an 8-bit RGB PNG."""
    img = np.asarray(rgb_uint8)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"write_png: expected (H, W, 3) uint8, got {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    # every scanline starts with its filter type byte; 0 = no filter
    raw = np.zeros((h, 1 + 3 * w), np.uint8)
    raw[:, 1:] = img.reshape(h, 3 * w)
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)  # 8 bit, colour type 2 = RGB
    data = (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr)
            + _png_chunk(b"IDAT", zlib.compress(raw.tobytes(), 6))
            + _png_chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(data)
