"""Pinhole camera: the resolved scene's camera block as a device Camera struct."""
from __future__ import annotations

import math

import numpy as np

from ..layout.records import CAMERA


def compile_camera(cam: dict) -> np.ndarray:
    pos = np.asarray(cam["position"], dtype=np.float64)
    forward = np.asarray(cam["look_at"], dtype=np.float64) - pos
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(cam["up"], dtype=np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    width, height = cam["resolution"]
    tan_half = math.tan(math.radians(cam["fov"]) / 2.0)
    out = CAMERA.zeros(1)
    out["position"][0, :3] = pos
    out["forward"][0, :3] = forward
    out["right"][0, :3] = right * tan_half * width / height
    out["up"][0, :3] = up * tan_half
    out["width"], out["height"] = width, height
    return out
