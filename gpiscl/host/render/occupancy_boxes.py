"""Occupancy cells: per GPIS object with an occupancy bound, the cells of a lattice over
its proxy (OCC_CELLS^3) where its prior mean may reach the occupancy level, found on the
render's device before the first launch (stages/gpis_occupancy_boxes.cl). The occupancy
clip (gpis_proxy.h) takes the slab of the set cells' box, then walks the lattice from
either end of the ray to the first set cell, and only then marches: the marches proved
the same thing step by step through the empty part of a loose proxy (the knob's box
proxies are 3 units wide around knobs of 1.4 and 2.3: over half of their march
evaluations were there; docs/design/grid-means.md, "Occupancy boxes").

The box is the set cells' index range padded by a quarter cell for the float arithmetic
of the corners, and open (infinite) on every side where it reaches the lattice's edge: the
proxy clips there anyway.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..layout import stages
from ..layout.constants import OCC_CELLS, OCC_WORDS
from ..layout.records import GPIS_PROXIES
from .device import Program, to_device
from .launch import launch


def proxy_bounds(objects: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), (n, 3) each: the bounding box of every object's proxy (a mesh proxy's
    p0 / p1 are its bounding box, compile/gpis.py), as gpis_occ_lattice takes it."""
    p0 = objects["proxy_p0"].astype(np.float64)
    p1 = objects["proxy_p1"].astype(np.float64)
    sphere = (objects["proxy_kind"] == GPIS_PROXIES["sphere"])[:, None]
    lo = np.where(sphere, p0[:, :3] - p0[:, 3:], p0[:, :3])
    hi = np.where(sphere, p0[:, :3] + p0[:, 3:], p1[:, :3])
    return lo, hi


def occupancy_cells(program: Program, buffers: dict, objects: np.ndarray):
    """(records, cells): a copy of the GpisObject records with occ_p0 / occ_p1 set for
    every object with an occupancy bound (occ_p0.w = 1), and the uint32 cell masks,
    OCC_WORDS per object (all clear for objects without a bound, which never read them).
    `buffers` holds the scene's uploaded arrays by parameter name. An object whose mean
    nowhere reaches its level gets an empty box."""
    n = len(objects)
    out = objects.copy()
    cells = np.zeros(max(n, 1) * OCC_WORDS, np.uint32)
    if not n or not (objects["occupancy_level"] > 0.0).any():
        return out, cells
    ranges = np.tile(np.array([OCC_CELLS] * 3 + [-1] * 3 + [0, 0], np.int32), (n, 1))
    boxes = to_device(program.device, ranges, writable=True)
    masks = to_device(program.device, cells, writable=True)
    launch(program, stages.GPIS_OCCUPANCY_BOXES, n * OCC_CELLS ** 3,
           gpis=buffers[stages.GPIS.name], mean_nodes=buffers[stages.MEAN_NODES.name],
           num_gpis=np.int32(n), boxes=boxes, cells=masks)
    cl.enqueue_copy(program.device.queue, ranges, boxes)   # blocking
    cl.enqueue_copy(program.device.queue, cells, masks)
    lo, hi = proxy_bounds(objects)
    h = (hi - lo) / OCC_CELLS
    a = lo + (ranges[:, :3] - 0.25) * h
    b = lo + (ranges[:, 3:6] + 1.25) * h
    a = np.where(ranges[:, :3] <= 0, -np.inf, a)
    b = np.where(ranges[:, 3:6] >= OCC_CELLS - 1, np.inf, b)
    empty = (ranges[:, 3:6] < ranges[:, :3]).any(axis=1)
    a[empty], b[empty] = np.inf, np.inf   # a degenerate slab at infinity: no ray enters
    on = objects["occupancy_level"] > 0.0
    out["occ_p0"][on, :3], out["occ_p1"][on, :3] = a[on], b[on]
    out["occ_p0"][on, 3] = 1.0
    return out, cells
