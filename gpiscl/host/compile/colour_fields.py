"""Colour and emission fields (scene/colour_fields.py) packed as MeanNode records."""
from __future__ import annotations

import numpy as np

from ..io.grids import load_rgb_grid
from ..layout.gp_records import MEAN_NODE, pack_payload

# GPIS_FIELD_* in gpis_fields.h (tests/test_gpis_fields.py checks they agree); above every
# mean kind, so a field record can never pass for a mean node
FIELD_KINDS = {"constant": 64, "checker": 65, "gradient": 66, "grid": 67}


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
