"""Occupancy boxes: per GPIS object with an occupancy bound, the axis-aligned box outside
which its prior mean stays above the occupancy level, found on the render's device before
the first launch. The occupancy marches (gpis_proxy.h) start where a ray enters the box,
and a ray that misses it leaves the object after one slab test: the marches proved the
same thing step by step, through the empty part of a loose proxy (the knob's box proxies
are 3 units wide around a knob of 1.4-2: half of its march evaluations were there;
docs/design/grid-means.md, "Occupancy boxes").

The box is the index range of the cells of a CELLS^3 lattice over the proxy's bounding box
that the device could not prove above the level (stages/gpis_occupancy_boxes.cl), padded
by a quarter cell for the float arithmetic of the cells' corners, and open (infinite) on
every side where it reaches the lattice's edge: the proxy clips there anyway.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..layout import stages
from ..layout.records import GPIS_PROXIES
from .device import Program, to_device
from .launch import launch

CELLS = 32   # per axis: the boxes of the knob's objects are within 3% of a 128^3 lattice's


def proxy_bounds(objects: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), (n, 3) each: the bounding box of every object's proxy (a mesh proxy's
    p0 / p1 are its bounding box, compile/gpis.py)."""
    p0 = objects["proxy_p0"].astype(np.float64)
    p1 = objects["proxy_p1"].astype(np.float64)
    sphere = (objects["proxy_kind"] == GPIS_PROXIES["sphere"])[:, None]
    lo = np.where(sphere, p0[:, :3] - p0[:, 3:], p0[:, :3])
    hi = np.where(sphere, p0[:, :3] + p0[:, 3:], p1[:, :3])
    return lo, hi


def with_occupancy_boxes(program: Program, buffers: dict, objects: np.ndarray) -> np.ndarray:
    """A copy of the GpisObject records with occ_p0 / occ_p1 set for every object with an
    occupancy bound (occ_p0.w = 1); `buffers` holds the scene's uploaded arrays by
    parameter name. An object whose mean nowhere reaches its level gets an empty box."""
    out = objects.copy()
    if not len(objects) or not (objects["occupancy_level"] > 0.0).any():
        return out
    n = len(objects)
    ranges = np.tile(np.array([CELLS, CELLS, CELLS, -1, -1, -1, 0, 0], np.int32), (n, 1))
    boxes = to_device(program.device, ranges, writable=True)
    launch(program, stages.GPIS_OCCUPANCY_BOXES, n * CELLS ** 3,
           gpis=buffers[stages.GPIS.name], mean_nodes=buffers[stages.MEAN_NODES.name],
           num_gpis=np.int32(n), cells=np.int32(CELLS), boxes=boxes)
    cl.enqueue_copy(program.device.queue, ranges, boxes)   # blocking
    lo, hi = proxy_bounds(objects)
    h = (hi - lo) / CELLS
    a = lo + (ranges[:, :3] - 0.25) * h
    b = lo + (ranges[:, 3:6] + 1.25) * h
    a = np.where(ranges[:, :3] <= 0, -np.inf, a)
    b = np.where(ranges[:, 3:6] >= CELLS - 1, np.inf, b)
    empty = (ranges[:, 3:6] < ranges[:, :3]).any(axis=1)
    a[empty], b[empty] = np.inf, np.inf   # a degenerate slab at infinity: no ray enters
    on = objects["occupancy_level"] > 0.0
    out["occ_p0"][on, :3], out["occ_p1"][on, :3] = a[on], b[on]
    out["occ_p0"][on, 3] = 1.0
    return out
