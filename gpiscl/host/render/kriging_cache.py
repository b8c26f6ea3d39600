"""The batch's kept weight-space posterior weights: one slot per path and posterior object.

A weight-space posterior's realization needs v = (K + N)^-1 (y - f(X) - e) and its norm
bound rho (ws_posterior.h), n prior evaluations and two n x n triangular solves that
depend only on the path's realization (key, object). The first search of a path that
needs them computes them and keeps them in the path's slot; its later rays and shadow rays
read them back (ws_post_weights). Layout (ws_objects.h, WsPostCache): per path,
tags_per_path 16-byte tags (one per posterior object) and doubles_per_path values (rho
and the n weights of each posterior object, in object order); table[k] = (tag index,
value offset) of object k, or -1.

Memory: (n + 1) doubles a path and object, up to 4 KB at WS_MAX_ROWS. The batch is capped
so that the values fit the device's budget. On a CPU the buffer is the process's memory,
but only the pages of the paths a batch holds are touched (the tags, 16 bytes a path and
object, are zeroed once), and batches are sized in time (batching.py), so a batch touches
a small part of the budget (docs/design/memory-budget.md, 'Kriging cache').
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..layout import records as layouts
from .device import Device

TAG_BYTES = 16        # uint4 (key.x, key.y, object + 1, 0): ws_post_tag
# Bytes of kept values per batch, as function_space_stages.BUDGET: a GPU's holds the
# default 2^18-path batch of 100-row weights; a CPU's holds more of those paths than one
# time-sized batch traces (docs/design/memory-budget.md, 'Kriging cache').
BUDGET, CPU_BUDGET = 256 << 20, 16 << 20


def budget(device: Device) -> int:
    """Bytes of kept weights per batch on this device."""
    return CPU_BUDGET if device.is_cpu else BUDGET


def layout(objects: np.ndarray) -> tuple[np.ndarray, int, int]:
    """(table int32 (len(objects), 2), tags_per_path, doubles_per_path) for the
    weight-space objects (GpisObject records) with a posterior."""
    rows = objects["posterior_count"]
    ws = objects["sampler"] == layouts.GPIS_SAMPLERS["weight_space"]
    table = np.full((len(objects), 2), -1, np.int32)
    tags = doubles = 0
    for k in np.flatnonzero(ws & (rows > 0)):
        table[k] = tags, doubles
        tags += 1
        doubles += int(rows[k]) + 1   # rho, then v
    return table, tags, doubles


def max_batch(objects: np.ndarray, device: Device) -> int:
    """The largest batch whose kept weights fit the device's budget."""
    _, tags, doubles = layout(objects)
    per_path = 8 * doubles + TAG_BYTES * tags
    return max(1, budget(device) // per_path) if per_path else 1 << 62


class KrigingCache:
    """The cache's buffers for a batch of `batch` paths. enabled=False: every table entry
    -1, so each search solves for its own weights (the uncached baseline of the tests and
    tools/bench_scenes.py)."""

    def __init__(self, device: Device, objects: np.ndarray, batch: int, enabled: bool = True):
        table, self.tags_per_path, self.doubles_per_path = layout(objects)
        if not enabled:
            table[:] = -1
        mf, ctx = cl.mem_flags, device.ctx
        # at least one entry each, so kernels always get valid buffers
        table = table if len(table) else np.full((1, 2), -1, np.int32)
        self.table = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=table)
        tag_bytes = TAG_BYTES * max(1, self.tags_per_path * batch)
        self.tags = cl.Buffer(ctx, mf.READ_WRITE, tag_bytes)
        cl.enqueue_fill_buffer(device.queue, self.tags, np.uint32(0), 0, tag_bytes)
        self.values = cl.Buffer(ctx, mf.READ_WRITE, 8 * max(1, self.doubles_per_path * batch))

    @property
    def arguments(self) -> dict:
        """The weight-space stages' post group (layout/stages.py WS_POST_CACHE)."""
        return {"tags": self.tags, "values": self.values, "table": self.table,
                "tags_per_path": np.int32(self.tags_per_path),
                "doubles_per_path": np.int32(self.doubles_per_path)}
