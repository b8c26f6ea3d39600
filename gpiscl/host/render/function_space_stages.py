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

from ..compile.gpis import CompiledGpis
from ..layout import records as layouts
from ..layout import stages
from .program_sources import FS_HEADERS, FS_STAGE_FILES
from .device import Device, KernelTimings, Program
from .launch import launch
from ..layout import function_space_records as FL

# Bytes of global-model rings per batch (cap the batch). On a CPU the device's memory is
# the process's and every touched page stays resident, so the CPU cap is the smallest that
# keeps two cores as busy (docs/design/batches.md, "Rings and scratch").
BUDGET, CPU_BUDGET = 256 << 20, 8 << 20
# Bytes of scratch per launch (cap the work items launched, which stride over the rays).
# A CPU touches every scratch page.
SCRATCH_BUDGET, CPU_SCRATCH_BUDGET = 256 << 20, 4 << 20
# Work-groups per compute unit in one launch: its items loop over the rays (grid-stride),
# so the units finish together however the work per ray varies, and a few groups a unit
# keep them busy. Launches in chunks of the batch needed 16 groups a unit to balance the
# work (every chunk waited for its slowest ray). A GPU's many units reach SCRATCH_BUDGET
# first.
GROUPS_PER_UNIT = 4


def budget(device: Device) -> int:
    """Bytes of rings per batch on this device."""
    return CPU_BUDGET if device.is_cpu else BUDGET


def scratch_budget(device: Device) -> int:
    """Bytes of scratch per launch on this device."""
    return CPU_SCRATCH_BUDGET if device.is_cpu else SCRATCH_BUDGET


def max_batch(gpis: CompiledGpis, device: Device) -> int:
    """The largest batch whose rings fit the device's budget."""
    return max(1, budget(device) // (gpis.ring_stride * FL.FS_OBS.dtype.itemsize))


class FunctionSpaceStages:
    """The program and per-batch buffers of a scene's function-space objects (gpis)."""

    def __init__(self, device: Device, gpis: CompiledGpis, batch: int,
                 timings: KernelTimings | None = None):
        self.device, self.batch, self.timings = device, batch, timings
        self.stride = gpis.ring_stride
        self.local = 16 if device.is_cpu else 64
        self.work = None      # the per-batch buffers, allocated when a launch needs them
        fs = gpis.objects["sampler"] == layouts.GPIS_SAMPLERS["function_space"]
        self._build(gpis.window_max, int(gpis.objects["refine"][fs].max()),
                    int(gpis.posterior_rows[fs].max()))

    def _build(self, window_max: int, refine_max: int, post_rows: int):
        """Program and scratch: a posterior of n rows adds a v cache of n doubles per row
        (fs_sampling.h, FsScratch.v) to every scratch slice."""
        rows_cap = self.stride if self.stride > 1 else 2
        defines = FL.defines(window_max, rows_cap, refine_max, post_rows)
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
        launch(self.program, stage, n, local=self.local, max_items=self.items,
               num_rays=np.int32(n), **self._work_arguments(), **named)

    def gpis_function_space(self, n, **named):
        """Rays [0, n) of the `in` queue: hits moved to function-space crossings, vertices
        recorded; named: the stage's other arguments (layout/stages.py)."""
        self._launch(stages.GPIS_FUNCTION_SPACE, n, named)

    def gpis_shadow_function_space(self, n, **named):
        """Shadow records (at most n: up to three per hit) blocked by function-space
        crossings."""
        self._launch(stages.GPIS_SHADOW_FUNCTION_SPACE, n, named)
