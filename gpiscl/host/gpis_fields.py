"""Colour and emission fields of GPIS objects: declarations, grid files, device packing.

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

Device form: one MeanNode record per field (kinds GPIS_FIELD_* in gpis_fields.h), appended
after every object's mean program in the mean-node array, so no buffer is added and the
mean walkers never see them; a grid's interleaved RGB samples follow as payload records
in the layout of grid means (device_layout.py). GpisObject.color_field / emission_field
hold the record's index, 0 for none: fields follow at least one mean program, so no
field record is ever at index 0.
"""
from __future__ import annotations

import numpy as np

from .gp.device_layout import MEAN_NODE, pack_payload
from .sdf_bake import check_grid_values, problem_of, read_grid_arrays
from .scene_schema import (Field, File, Number, Record, Spec, Tagged, Vector, _is_number,
                           _is_sequence)

# as in scene.py, which imports this module (through gpis_schema) while it loads
VEC3 = Vector()
RGB = Vector(broadcast=True, item=Number(ge=0))
ALBEDO = Vector(broadcast=True, item=Number(ge=0, le=1))

# GPIS_FIELD_* in gpis_fields.h (tests/test_gpis_fields.py checks they agree); above every
# mean kind, so a field record can never pass for a mean node
FIELD_KINDS = {"constant": 64, "checker": 65, "gradient": 66, "grid": 67}
GRID_FIELD_KEYS = ("values", "origin", "voxel_size")


# ---- grid files ---------------------------------------------------------------------------

def load_rgb_grid(path, upper: float | None = None):
    """(values (nx, ny, nz, 3) float64, origin (3,), voxel_size) of an RGB grid file;
    ValueError naming the array when it is unusable. upper: the largest allowed value."""
    arrays = read_grid_arrays(path, GRID_FIELD_KEYS)
    v = arrays["values"]
    values = check_grid_values(v, v.ndim == 4 and v.shape[3] == 3 and min(v.shape[:3]) >= 2,
                               "(nx, ny, nz, 3): RGB per sample, every n >= 2")
    if values.min() < 0.0:
        raise ValueError(f"grid array 'values' must be >= 0 (min {values.min():.4g})")
    if upper is not None and values.max() > upper:
        raise ValueError(f"grid array 'values' must be <= {upper:g}: a colour multiplies "
                         f"the albedo, which must stay <= 1 (max {values.max():.4g})")
    return values, arrays["origin"].astype(np.float64), float(arrays["voxel_size"].item())


def save_rgb_grid(path, values, origin, voxel_size):
    np.savez_compressed(path, values=np.asarray(values, np.float32),
                        origin=np.asarray(origin, np.float64),
                        voxel_size=np.float64(voxel_size))


# ---- declarations -------------------------------------------------------------------------

def _field_family(name: str, value_spec, upper) -> Tagged:
    def gradient_length(g):
        if all(a == b for a, b in zip(g["start"], g["end"])):
            return "end", "must differ from start (the gradient needs a direction)"
        return None

    return Tagged(name, {
        "constant": Record({"value": Field(value_spec)}),
        "checker": Record({"scale": Field(Number(gt=0)), "a": Field(value_spec),
                           "b": Field(value_spec), "offset": Field(VEC3, [0, 0, 0])}),
        "gradient": Record({"start": Field(VEC3), "end": Field(VEC3), "a": Field(value_spec),
                            "b": Field(value_spec)}, [gradient_length]),
        "grid": Record({"file": Field(File((".npz",), problem_of(
            lambda path: load_rgb_grid(path, upper))))}),
    })


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
        if _is_number(value) or _is_sequence(value):
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


# ---- device packing -----------------------------------------------------------------------

def pack_field(field: dict) -> np.ndarray:
    """The MeanNode records of a resolved field: its record, then any grid payload.
    row0..row2: world -> the field's local coordinates; p0, p1: the colours a, b."""
    rec = MEAN_NODE.zeros(1)
    rec["kind"] = FIELD_KINDS[field["type"]]
    m = np.eye(3, 4)
    kind = field["type"]
    if kind == "constant":
        rec["p0"][0, :3] = field["value"]
    elif kind == "checker":
        m = np.concatenate([np.eye(3), np.asarray(field["offset"], float)[:, None]], 1)
        m /= field["scale"]
        rec["p0"][0, :3], rec["p1"][0, :3] = field["a"], field["b"]
    elif kind == "gradient":
        p0, d = np.asarray(field["start"], float), np.subtract(field["end"], field["start"])
        m = np.zeros((3, 4))
        m[0, :3] = d / (d @ d)                  # y.x = t, 0 at start and 1 at end
        m[0, 3] = -(p0 @ d) / (d @ d)
        rec["p0"][0, :3], rec["p1"][0, :3] = field["a"], field["b"]
    else:
        values, origin, h = load_rgb_grid(field["file"])
        m = np.concatenate([np.eye(3) / h, -origin[:, None] / h], 1)
        rec["p1"][0, :3] = values.shape[:3]
        payload = pack_payload(values)    # ((i ny + j) nz + k) 3 + channel
        rec["flags"] = len(payload)
    rec["row0"], rec["row1"], rec["row2"] = m
    rec["scale"] = 1.0
    if kind == "grid":
        return np.concatenate([rec, payload])
    return rec
