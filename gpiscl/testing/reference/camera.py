"""Independent numpy twins of the camera model, for reference images in tests."""
import math

import numpy as np


def pixel_rays(cam: dict, sub: int):
    """Camera rays through a sub x sub grid inside every pixel: origins, (H, W, sub*sub, 3)."""
    w, h = cam["resolution"]
    pos = np.asarray(cam["position"], float)
    fwd = np.asarray(cam["look_at"], float) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, cam["up"])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    t = math.tan(math.radians(cam["fov"]) / 2)
    offs = (np.arange(sub) + 0.5) / sub
    px = np.arange(w)[None, :, None, None] + offs[None, None, None, :]
    py = np.arange(h)[:, None, None, None] + offs[None, None, :, None]
    sx = (2 * px / w - 1) * t * w / h
    sy = (1 - 2 * py / h) * t
    sx, sy = np.broadcast_arrays(sx, sy)
    d = fwd + sx[..., None] * right + sy[..., None] * up
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return pos, d.reshape(h, w, sub * sub, 3)


def hit_sphere(o, d, c, r):
    """Distance to the sphere along unit rays d from o (inf where missed)."""
    oc = o - np.asarray(c, float)
    b = d @ oc
    disc = b * b - (oc @ oc - r * r)
    t = -b - np.sqrt(np.maximum(disc, 0))
    return np.where((disc > 0) & (t > 0), t, np.inf)


def hit_plane_y(o, d, y):
    t = (y - o[1]) / d[..., 1]
    return np.where(t > 0, t, np.inf)
