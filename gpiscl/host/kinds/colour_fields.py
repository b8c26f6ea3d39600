"""Colour and emission fields of GPIS objects (scene/colour_fields.py documents them): the
one declaration of each kind.

A kind gives its scene record for a value spec (albedo for "color", any RGB for
"emission"), and its packer: the world -> field map, the colours a and b, and any samples
(compile/colour_fields.py stores them as payload records). The ids start at 64, above
every mean kind, so a field record can never pass for a mean node; gpis_fields.h's
gpis_field_eval switches on them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..io.grids import load_rgb_grid, problem_of
from ..schema import Field, File, Number, Record, Vector
from .table import Kind, KindTable

VEC3 = Vector()


@dataclass(frozen=True)
class FieldHost:
    """schema(value_spec, upper) -> Record; pack(field) -> (3x4 world -> local map, a, b,
    samples (nx, ny, nz, 3) or None)."""
    schema: Callable
    pack: Callable


def _gradient_length(g):
    if all(a == b for a, b in zip(g["start"], g["end"])):
        return "end", "must differ from start (the gradient needs a direction)"
    return None


def _pack_checker(f):
    m = np.concatenate([np.eye(3), np.asarray(f["offset"], float)[:, None]], 1)
    return m / f["scale"], f["a"], f["b"], None


def _pack_gradient(f):
    p0, d = np.asarray(f["start"], float), np.subtract(f["end"], f["start"])
    m = np.zeros((3, 4))
    m[0, :3] = d / (d @ d)                  # y.x = t, 0 at start and 1 at end
    m[0, 3] = -(p0 @ d) / (d @ d)
    return m, f["a"], f["b"], None


def _pack_grid(f):
    values, origin, h = load_rgb_grid(f["file"])
    return np.concatenate([np.eye(3) / h, -origin[:, None] / h], 1), None, None, values


COLOUR_FIELDS = KindTable("colour field", "GPIS_FIELD", [
    Kind("constant", host=FieldHost(lambda v, upper: Record({"value": Field(v)}),
                                    lambda f: (np.eye(3, 4), f["value"], None, None))),
    Kind("checker", host=FieldHost(
        lambda v, upper: Record({"scale": Field(Number(gt=0)), "a": Field(v), "b": Field(v),
                                 "offset": Field(VEC3, [0, 0, 0])}), _pack_checker)),
    Kind("gradient", host=FieldHost(
        lambda v, upper: Record({"start": Field(VEC3), "end": Field(VEC3), "a": Field(v),
                                 "b": Field(v)}, [_gradient_length]), _pack_gradient)),
    Kind("grid", host=FieldHost(
        lambda v, upper: Record({"file": Field(File((".npz",), problem_of(
            lambda path: load_rgb_grid(path, upper))))}), _pack_grid)),
], first_id=64)
