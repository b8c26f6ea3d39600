"""Function-space GPIS stages of the integrator: free flight and shadow rays.

They form a second program because fs_sampling.h needs gp_kernel.h in double
(-DGP_REAL=double) while the weight-space stages stay in float; it is built only when a
scene has function-space objects. Per-path state (the vertex record, its object and the
global model's ring) is indexed by path id; scratch is per work item and a launch's items
stride over the rays, so its size does not grow with the batch.
"""
from __future__ import annotations

import os

import numpy as np
import pyopencl as cl

from ..kinds.memory_models import MEMORY_MODELS
from ..layout import records as layouts
from ..layout import stages
from .program_sources import FS_HEADERS, FS_STAGE_FILES
from .device import Device, KernelTimings, Program
from .launch import launch
from ..layout import function_space_records as FL

# Bytes of global-model rings per batch (cap the batch). On a CPU the device's memory is
# the process's and every page a batch touches stays resident, while 8 MB already keeps
# two cores busy: the global-memory room (4 KB of ring a path) held 32 MB of rings at
# 256 MB and 16 MB at 16 MB, at the same paths/s (tools/bench_scenes.py, same run); 8 MB
# (2048 paths) against 16 MB: paths per CPU s x1.03 / x1.01 / x1.00 in 3 alternating
# rounds, peak RSS 152 -> 143 MB.
BUDGET, CPU_BUDGET = 256 << 20, 8 << 20
# Bytes of scratch per launch (cap the work items launched, which stride over the rays).
# A CPU touches every scratch page: 16 MB of it held 15 MB resident for the knob.
SCRATCH_BUDGET, CPU_SCRATCH_BUDGET = 256 << 20, 4 << 20
# Work-groups per compute unit in one launch: its items loop over the rays (grid-stride),
# so the units finish together however the work per ray varies, and a few groups a unit
# keep them busy. Launches in chunks of the batch needed 16 groups a unit to balance the
# work (every chunk waited for its slowest ray). A GPU's many units reach SCRATCH_BUDGET
# first.
GROUPS_PER_UNIT = 4


def _fs_objects(objects: np.ndarray) -> np.ndarray:
    return objects[objects["sampler"] == layouts.GPIS_SAMPLERS["function_space"]]


def ring_stride(objects: np.ndarray) -> int:
    """Observations per path ring: the largest cap of an object whose memory model keeps
    a ring, else 1."""
    fs = _fs_objects(objects)
    ids = [MEMORY_MODELS.id(name) for name in MEMORY_MODELS.with_trait("ring")]
    ring = fs[np.isin(fs["memory"], ids)]
    return int(ring["memory_cap"].max()) if len(ring) else 1


def budget(device: Device) -> int:
    """Bytes of rings per batch on this device."""
    return CPU_BUDGET if device.is_cpu else BUDGET


def scratch_budget(device: Device) -> int:
    """Bytes of scratch per launch on this device."""
    return CPU_SCRATCH_BUDGET if device.is_cpu else SCRATCH_BUDGET


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
        if os.environ.get("GPISCL_FS_PROFILE"):   # fs_march.h's work counters (off: no code)
            defines["FS_PROFILE"] = 1
        self.program = Program(self.device, FS_STAGE_FILES, defines=defines,
                               extra_headers=FS_HEADERS, extra_c=FL.c_declarations())
        if self.timings is not None:   # one kernel table for both programs
            self.program.timings = self.timings
        slice_bytes = 8 * defines["FS_SCRATCH_DOUBLES"]
        parallel = int(self.device.device.max_compute_units) * self.local * GROUPS_PER_UNIT
        items = max(1, min(self.batch, scratch_budget(self.device) // (2 * slice_bytes),
                           parallel))
        self.items = int(-(-items // self.local) * self.local)   # work items a launch
        self.scratch_bytes = 2 * slice_bytes * self.items
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

    def _work_arguments(self) -> dict:
        vertex, vertex_object, rings, scratch = self._work()
        return {"vertex": vertex, "vertex_object": vertex_object, "rings": rings,
                "ring_stride": np.int32(self.stride), "scratch": scratch}

    def _launch(self, stage: stages.Stage, n: int, named: dict):
        """One launch of at most self.items work items striding over [0, n), with a fixed
        local size: PoCL compiles a kernel once per work-group size, and these kernels
        take seconds to compile."""
        self._check_posterior(named["mean_nodes"])
        launch(self.program, stage, n, local=self.local, max_items=self.items,
               num_rays=np.int32(n), **self._work_arguments(), **named)

    def gpis_function_space(self, n, **named):
        """Rays [0, n) of the `in` queue: hits moved to function-space crossings, vertices
        recorded; named: the stage's other arguments (layout/stages.py)."""
        self._launch(stages.GPIS_FUNCTION_SPACE, n, named)

    def gpis_shadow_function_space(self, n, **named):
        """Shadow rays (at most n: one per hit) blocked by function-space crossings."""
        self._launch(stages.GPIS_SHADOW_FUNCTION_SPACE, n, named)
