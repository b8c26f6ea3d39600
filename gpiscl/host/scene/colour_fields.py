"""Colour and emission fields of GPIS objects: declarations and their numpy evaluation.

A GPIS shape may carry
    "color":    an albedo multiplier in [0, 1], applied to the micro-BSDF's albedo at the
                hit point (both in next-event estimation and in the continuation weight)
    "emission": radiance emitted by the surface at the hit point (every direction)
each a number (grey), three numbers, or an object:
    {"type": "constant", "value": rgb}
    {"type": "checker", "scale": s, "a": rgb, "b": rgb, "offset": [0, 0, 0]}
        a 3-D checkerboard of cubes of side s: `a` where floor((x + offset) / s) has an
        even component sum, `b` elsewhere
    {"type": "gradient", "start": p0, "end": p1, "a": rgb, "b": rgb}
        a at p0, b at p1, linear in the projection onto p1 - p0, constant beyond either end
    {"type": "grid", "file": "f.npz"}
        trilinear in an .npz with values (nx, ny, nz, 3) (x index first, every n >= 2;
        values[i, j, k] at origin + voxel_size (i, j, k)), origin (3,), voxel_size > 0;
        outside the sample box the nearest border value
null (the default) is no field: colour 1, emission 0. Fields are functions of world
position, evaluated where a path meets the realization, so both samplers get them.

GPIS emission is not in the light list, so next-event estimation never samples it and
shadow rays are blocked by it: it is found by BSDF-sampled rays only, which count it with
MIS weight 1 (emission.cl). Bright small emitters are therefore noisy; use lights for
illumination and emission for glowing detail.

Device form: one MeanNode record per field (kinds: kinds/colour_fields.py), appended
after every object's mean program in the mean-node array, so no buffer is added and the
mean walkers never see them; a grid's interleaved RGB samples follow as payload records
in the layout of grid means (layout/gp_records.py). GpisObject.color_field / emission_field
hold the record's index, 0 for none: fields follow at least one mean program, so no
field record is ever at index 0.
"""
from __future__ import annotations

import numpy as np

from ..io.grids import load_rgb_grid
from ..kinds.colour_fields import COLOUR_FIELDS
from ..kinds.values import ALBEDO, RGB
from ..schema import Spec, Tagged, is_number, is_sequence


# ---- declarations -------------------------------------------------------------------------

def _field_family(name: str, value_spec, upper) -> Tagged:
    return Tagged(name, {k.name: k.host.schema(value_spec, upper) for k in COLOUR_FIELDS})


class ColourField(Spec):
    """A number or three numbers (a constant field), an object of the family, or null.
    Resolves to null or the object form, so resolved scenes reload unchanged."""

    def __init__(self, family: Tagged, value_spec):
        self.family, self.value_spec = family, value_spec
        self.expected = (f"a number, a list of 3 numbers, a {family.family} object "
                         f"({', '.join(family.variants)}) or null")

    def resolve(self, value, path, ctx):
        if value is None:
            return None
        if is_number(value) or is_sequence(value):
            return {"type": "constant", "value": self.value_spec.resolve(value, path, ctx)}
        if not isinstance(value, dict):
            self.wrong_type(value, path, ctx)
        return self.family.resolve(value, path, ctx)


COLOR = ColourField(_field_family("color", ALBEDO, 1.0), ALBEDO)
EMISSION = ColourField(_field_family("emission", RGB, None), RGB)


# ---- host evaluation (the device's reference) ---------------------------------------------

def evaluate(field: dict | None, x, default=1.0) -> np.ndarray:
    """The resolved field's RGB at points x (..., 3); `default` where field is None."""
    x = np.asarray(x, np.float64)
    if field is None:
        return np.full(x.shape, default, np.float64)
    kind = field["type"]
    if kind == "constant":
        return np.broadcast_to(np.asarray(field["value"], float), x.shape).copy()
    if kind == "checker":
        c = np.floor((x + np.asarray(field["offset"])) / field["scale"]).sum(-1)
        odd = (c.astype(np.int64) & 1).astype(bool)[..., None]
        return np.where(odd, np.asarray(field["b"], float), np.asarray(field["a"], float))
    if kind == "gradient":
        p0, p1 = np.asarray(field["start"], float), np.asarray(field["end"], float)
        d = p1 - p0
        t = np.clip(((x - p0) @ d) / (d @ d), 0.0, 1.0)[..., None]
        return np.asarray(field["a"], float) * (1 - t) + np.asarray(field["b"], float) * t
    values, origin, h = load_rgb_grid(field["file"])
    hi = np.asarray(values.shape[:3], float) - 1.0
    c = np.clip((x - origin) / h, 0.0, hi)
    cell = np.minimum(np.floor(c), hi - 1.0)
    t = c - cell
    i, j, k = (cell[..., a].astype(np.intp) for a in range(3))
    out = 0.0
    for a in (0, 1):
        for b in (0, 1):
            for e in (0, 1):
                w = ((t[..., 0] if a else 1 - t[..., 0]) * (t[..., 1] if b else 1 - t[..., 1])
                     * (t[..., 2] if e else 1 - t[..., 2]))
                out = out + w[..., None] * values[i + a, j + b, k + e]
    return out
