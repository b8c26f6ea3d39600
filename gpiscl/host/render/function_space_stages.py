"""Function-space GPIS stages of the integrator: free flight and shadow rays.

They form a second program because fs_sampling.h needs gp_kernel.h in double
(-DGP_REAL=double) while the weight-space stages stay in float; it is built only when a
scene has function-space objects. Per-path state (the vertex record, its object and the
global model's ring) is indexed by path id; scratch is per work item and the stages run
in chunks, so its size does not grow with the batch.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..layout import records as layouts
from .program_sources import FS_HEADERS, FS_STAGE_FILES
from .device import Device, KernelTimings, Program
from ..layout import function_space_records as FL

# Bytes of global-model rings per batch (cap the batch) and of scratch per launch (cap the
# chunk). On a CPU the device's memory is the process's and every page a batch or a chunk
# touches stays resident, while 16 MB already keeps two cores busy: the global-memory room
# (4 KB of ring a path, 58 KB of scratch per item) held 59 MB of scratch and 32 MB of
# rings at 256 MB budgets, 16 + 16 MB at these, at the same paths/s (tools/bench_scenes.py, same run).
BUDGET, CPU_BUDGET = 256 << 20, 16 << 20
# Work-groups per compute unit in one chunk: enough that the units finish together (the
# work per ray varies by several times), few enough that the scratch stays small. A CPU
# touches every scratch page a chunk uses: chunks of the whole batch (up to ~15,000 items
# of 17.7 KB each for the knob) held ~250 MB resident where 16 groups a unit hold ~9 MB
# on two cores, at the same paths/s (tools/bench_scenes.py). A GPU's many units still
# reach BUDGET first.
GROUPS_PER_UNIT = 16


def _fs_objects(objects: np.ndarray) -> np.ndarray:
    return objects[objects["sampler"] == layouts.GPIS_SAMPLERS["function_space"]]


def ring_stride(objects: np.ndarray) -> int:
    """Observations per path ring: the largest cap of a global-memory object, else 1."""
    fs = _fs_objects(objects)
    glob = fs[fs["memory"] == layouts.GPIS_MEMORIES["global"]]
    return int(glob["memory_cap"].max()) if len(glob) else 1


def budget(device: Device) -> int:
    """Bytes of rings per batch, and of scratch per launch, on this device."""
    return CPU_BUDGET if device.is_cpu else BUDGET


def max_batch(objects: np.ndarray, device: Device) -> int:
    """The largest batch whose rings fit the device's budget."""
    return max(1, budget(device)
               // (ring_stride(objects) * FL.FS_OBS.dtype.itemsize))


def posterior_rows_on_device(device: Device, objects: np.ndarray, means) -> int:
    """The most observation rows of any function-space object's posterior, read from the
    header records just before the mean programs in the device's mean buffer
    (fs_posterior.h): the stages are built from GpisObject records alone, which do not
    carry it, and one record per object is all that is read."""
    from ..layout.gp_records import MEAN_NODE
    from ..compile.posterior import POSTERIOR_KIND
    size, best = MEAN_NODE.dtype.itemsize, 0
    for first in _fs_objects(objects)["mean_first"]:
        if first <= 0:
            continue
        rec = MEAN_NODE.zeros(1)
        cl.enqueue_copy(device.queue, rec, means, src_offset=int(first - 1) * size)
        if rec["kind"][0] == POSTERIOR_KIND:
            best = max(best, int(rec["p0"][0][0]))
    return best


class FunctionSpaceStages:
    """mean_nodes: the host mean-node array, to size the posterior cache now. Without it
    the stages are built for the prior and, if the first launch finds a posterior in the
    device's mean buffer, rebuilt then (its compilation then counts as render time)."""

    def __init__(self, device: Device, objects: np.ndarray, batch: int,
                 timings: KernelTimings | None = None, mean_nodes: np.ndarray | None = None):
        self.device, self.objects, self.batch, self.timings = device, objects, batch, timings
        self.stride = ring_stride(objects)
        self.local = 16 if device.is_cpu else 64
        self.checked = mean_nodes is not None
        rows = 0
        if mean_nodes is not None:
            from ..compile.posterior import posterior_rows
            rows = int(posterior_rows(mean_nodes, objects).max(initial=0))
        self.work = None      # the per-batch buffers, allocated when a launch needs them
        self._build(rows)

    def _check_posterior(self, means):
        if not self.checked:
            self.checked = True
            rows = posterior_rows_on_device(self.device, self.objects, means)
            if rows > self.post_rows:
                self._build(rows)

    def _build(self, post_rows: int):
        """Program and scratch: a posterior of n rows adds a v cache of n doubles per row
        (fs_sampling.h, FsScratch.v) to every scratch slice."""
        fs = _fs_objects(self.objects)
        rows_cap = self.stride if self.stride > 1 else 2
        self.post_rows = post_rows
        defines = FL.defines(int(fs["window"].max()), rows_cap, int(fs["refine"].max()),
                             post_rows)
        self.program = Program(self.device, FS_STAGE_FILES, defines=defines,
                               extra_headers=FS_HEADERS, extra_c=FL.c_declarations())
        if self.timings is not None:   # one kernel table for both programs
            self.program.timings = self.timings
        slice_bytes = 8 * defines["FS_SCRATCH_DOUBLES"]
        parallel = int(self.device.device.max_compute_units) * self.local * GROUPS_PER_UNIT
        chunk = max(1, min(self.batch, budget(self.device) // (2 * slice_bytes), parallel))
        self.chunk = int(-(-chunk // self.local) * self.local)
        self.scratch_bytes = 2 * slice_bytes * self.chunk
        self.release()        # a rebuilt program may need a larger scratch

    def _work(self) -> tuple:
        """(vertex, vertex_object, rings, scratch): the path-indexed vertex records and
        rings of one batch and the chunk's scratch, allocated on first use after release."""
        if self.work is None:
            mf, ctx, batch = cl.mem_flags, self.device.ctx, self.batch
            self.work = (cl.Buffer(ctx, mf.READ_WRITE, FL.FS_VERTEX.dtype.itemsize * batch),
                         cl.Buffer(ctx, mf.READ_WRITE, 4 * batch),
                         cl.Buffer(ctx, mf.READ_WRITE,
                                   FL.FS_OBS.dtype.itemsize * self.stride * batch),
                         cl.Buffer(ctx, mf.READ_WRITE, self.scratch_bytes))
        return self.work

    def release(self) -> None:
        """Free the per-batch buffers (between renders: the vertex records and rings only
        live within a batch); the next launch allocates them again."""
        for buf in self.work or ():
            buf.release()
        self.work = None

    def _args(self) -> tuple:
        vertex, vertex_object, rings, scratch = self._work()
        return vertex, vertex_object, rings, np.int32(self.stride), scratch

    def _chunks(self, name, n, head, tail):
        """Launch over [0, n) in chunks with a fixed local size: PoCL compiles a kernel
        once per work-group size, and these kernels take seconds to compile."""
        kernel, queue = self.program.kernels[name], self.device.queue
        for first in range(0, n, self.chunk):
            m = min(self.chunk, n - first)
            kernel.set_args(*head, np.int32(first), np.int32(first + m), *tail)
            padded = -(-m // self.local) * self.local
            event = cl.enqueue_nd_range_kernel(queue, kernel, (padded,), (self.local,))
            self.program.timings.record(name, m, event)

    def free_flight(self, params, paths, rays, n, gpis_objects, kernels, means, counters):
        """Rays [0, n) of `rays`: hits moved to function-space crossings, vertices recorded."""
        self._check_posterior(means)
        self._chunks("gpis_function_space", n, (params,),
                     (*paths.args, *rays.args, gpis_objects, kernels, means, *self._args(),
                      counters))

    def shadow(self, params, paths, shadow, n, gpis_objects, kernels, means, counters):
        """Shadow rays (at most n: one per hit) blocked by function-space crossings."""
        self._check_posterior(means)
        self._chunks("gpis_shadow_function_space", n, (params,),
                     (*paths.args, *shadow.args, gpis_objects, kernels, means, *self._args(),
                      counters))
