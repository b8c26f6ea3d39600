"""Device-resident SoA queues built from the layouts in layout/records.py."""
from __future__ import annotations

import pyopencl as cl

from ..layout.records import Queue


class DeviceQueue:
    """One buffer per field of a Queue layout, in the order the C macro lists them.
    unused: fields no kernel touches in this render (their launches are guarded, e.g. by
    params->aov), given one element only."""

    def __init__(self, ctx: cl.Context, layout: Queue, capacity: int, unused=()):
        self.layout = layout
        self.capacity = capacity
        self.buffers = {}
        for _, fname in layout.fields:
            n = 1 if fname in unused else max(capacity, 1)
            nbytes = layout.numpy_dtype(fname).itemsize * n
            self.buffers[fname] = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, nbytes)

    @property
    def args(self) -> list:
        return [self.buffers[f] for _, f in self.layout.fields]

    def release(self) -> None:
        for buf in self.buffers.values():
            buf.release()
        self.buffers = {}
