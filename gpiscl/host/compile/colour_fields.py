"""Colour and emission fields (scene/colour_fields.py) packed as MeanNode records."""
from __future__ import annotations

import numpy as np

from ..kinds.colour_fields import COLOUR_FIELDS
from ..layout.gp_records import MEAN_NODE, pack_payload


def pack_field(field: dict) -> np.ndarray:
    """The MeanNode records of a resolved field: its record, then any grid payload.
    row0..row2: world -> the field's local coordinates; p0, p1: the colours a, b; a
    grid's p1.xyz: sample counts, flags: its payload records."""
    rec = MEAN_NODE.zeros(1)
    rec["kind"] = COLOUR_FIELDS.id(field["type"])
    m, a, b, samples = COLOUR_FIELDS[field["type"]].host.pack(field)
    if a is not None:
        rec["p0"][0, :3] = a
    if b is not None:
        rec["p1"][0, :3] = b
    if samples is not None:
        rec["p1"][0, :3] = samples.shape[:3]
        payload = pack_payload(samples)    # ((i ny + j) nz + k) 3 + channel
        rec["flags"] = len(payload)
    rec["row0"], rec["row1"], rec["row2"] = m
    rec["scale"] = 1.0
    if samples is not None:
        return np.concatenate([rec, payload])
    return rec
