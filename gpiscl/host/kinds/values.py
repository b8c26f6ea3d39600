"""The value kinds and vector checks that scene objects of every axis share (the scene
format's colours, albedos and directions), so that each kind declaration and the rest of
the scene schema (scene/records.py) name one definition."""
from __future__ import annotations

import math

from ..schema import Number, Vector

VEC3 = Vector()
NONZERO = Vector(nonzero=True)
DIRECTION = Vector(normalize=True)
RGB = Vector(broadcast=True, item=Number(ge=0))
ALBEDO = Vector(broadcast=True, item=Number(ge=0, le=1))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def parallel(a, b) -> bool:
    # relative test: |a x b| is |a||b| sin(angle)
    return math.hypot(*cross(a, b)) <= 1e-9 * math.hypot(*a) * math.hypot(*b)


def rectangle_area(r):
    """Check of a record with edges u and v: None, or (key, reason)."""
    if parallel(r["u"], r["v"]):
        return "v", "must not be parallel to u (the rectangle would have no area)"
    return None
