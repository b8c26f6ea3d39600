"""Writes scenes/assets/sky.exr: the substitute environment map of the example scenes.

The authors' scenes light their objects with "FlowCheck.hdr", whose content is missing from
their public repository (the file is listed there, but its data is not). This is
a procedural stand-in with the same role: a bright sky gradient over a darker ground, a
warm patch around the sun direction and a few soft "windows", so mirror micro-facets show
structured reflections. Lat-long layout of gpiscl/host/compile/envmap.py (row 0 = +y).

    python tools/make_sky.py [--width 512]
"""
import argparse
from pathlib import Path

import numpy as np

from gpiscl.host.io.images import write_exr

SUN = np.array([0.6, 0.7, 0.4])


def sky(width: int) -> np.ndarray:
    h = width // 2
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.cos(T), np.sin(T) * np.sin(P)], -1)
    up = d[..., 1]
    zenith, horizon = np.array([0.25, 0.45, 0.9]), np.array([0.9, 0.95, 1.0])
    t = np.clip(up, 0, 1)[..., None] ** 0.5
    rgb = np.where(up[..., None] > 0, horizon * (1 - t) + zenith * t,
                   np.array([0.25, 0.22, 0.2]) * (1 + 0.5 * up[..., None]))
    sun = SUN / np.linalg.norm(SUN)
    c = np.clip(d @ sun, -1, 1)
    rgb = rgb + np.array([8.0, 6.5, 4.5]) * np.exp((c - 1) / 0.002)[..., None]   # sun disc
    rgb = rgb + np.array([0.8, 0.6, 0.4]) * np.exp((c - 1) / 0.05)[..., None]    # its glow
    for az in (0.0, 2.1, 4.2):  # three soft windows near the horizon
        w = np.exp(-((P - az) ** 2) / 0.02 - ((T - 1.2) ** 2) / 0.02)
        rgb = rgb + 3.0 * w[..., None]
    return rgb.astype(np.float32)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("-o", "--output", default=str(Path(__file__).resolve().parent.parent
                                                  / "scenes" / "assets" / "sky.exr"))
    args = ap.parse_args()
    write_exr(args.output, sky(args.width))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
