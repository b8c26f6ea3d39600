"""Device-resident SoA queues built from the layouts in layout/records.py."""
from __future__ import annotations

from collections.abc import Mapping

import pyopencl as cl

from ..layout.records import Queue


class DeviceQueue(Mapping):
    """One buffer per field of a Queue layout, by field name: a launch takes the queue as
    it is (render/launch.py, a queue group of layout/stages.py).
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
        # in the layout's order: what a launch takes without a check per buffer
        self.in_layout_order = list(self.buffers.values())

    def __getitem__(self, fname: str) -> cl.Buffer:
        return self.buffers[fname]

    def get(self, fname: str, default=None):   # dict's, not Mapping's slower one: per launch
        return self.buffers.get(fname, default)

    def __iter__(self):
        return iter(self.buffers)

    def __len__(self) -> int:
        return len(self.buffers)

    def release(self) -> None:
        for buf in self.buffers.values():
            buf.release()
        self.buffers, self.in_layout_order = {}, None
