"""Scene preparation on the render's own device: procedural means baked to grids and the
slope bounds of trilinear grid means, one work item per sample or brick.

The numpy forms stay as the twins (gp/knob.py knob_grid, compile/sdf_bake.py's slabs over
gp/means.py), and the device gives the same numbers bit for bit (tests/test_device_bakes.py),
so the bake cache's entries do not depend on which computed them (costs:
docs/design/bakes.md, 'On the device'); cached scenes never build this program.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..gp import knob, means
from ..gp.means import GridMean
from ..layout.constants import KNOB_FUNCTIONS
from ..layout import stages
from .device import Device, Program, to_device
from .launch import launch
from .program_sources import BAKE_FILES, BAKE_HEADERS

FUNCTIONS = KNOB_FUNCTIONS   # KNOB_FUNCTION_* ids


def _hex(x: float) -> str:
    return float(x).hex()     # a C99 hex literal: the host's double exactly


def _defines() -> dict:
    """The constants knob.py computes with numpy, as exact literals."""
    out = {"KNOB_PI_3": _hex(np.pi / 3)}
    for name, degrees in (("M90", -90), ("P90", 90), ("M45", -45)):
        a = np.radians(degrees)
        out[f"KNOB_COS_{name}"], out[f"KNOB_SIN_{name}"] = _hex(np.cos(a)), _hex(np.sin(a))
    return out


class DeviceBakes:
    """What compile/sdf_bake.py asks of a baker (its numpy default: sdf_bake.NumpyBakes),
    on one device. The program is built on first use only."""

    def __init__(self, device: Device):
        self.device = device
        self._program = None

    @property
    def built(self) -> bool:
        """Whether the bake program was built (a warm bake cache never needs it)."""
        return self._program is not None

    @property
    def program(self) -> Program:
        if self._program is None:
            self._program = Program(self.device, BAKE_FILES, defines=_defines(),
                                    extra_headers=BAKE_HEADERS)
        return self._program

    def procedural(self, function: str, resolution: int) -> GridMean:
        """knob.knob_grid(function, resolution), every sample on the device."""
        lo, voxel, n = knob.grid_placement(function, resolution)
        axes = [lo[i] + voxel * np.arange(n[i]) for i in range(3)]
        total = int(np.prod(n))
        values = np.empty(tuple(n), np.float32)
        out = cl.Buffer(self.device.ctx, cl.mem_flags.WRITE_ONLY, values.nbytes)
        # held until the copy has waited for the kernel (the buffers use the arrays' memory)
        inputs = [to_device(self.device, a) for a in axes]
        nx, ny, nz = (np.int32(c) for c in n)
        launch(self.program, stages.BAKE_PROCEDURAL, total, which=np.int32(FUNCTIONS[function]),
               nx=nx, ny=ny, nz=nz, ax=inputs[0], ay=inputs[1], az=inputs[2], values=out)
        cl.enqueue_copy(self.device.queue, values, out)   # blocking
        return GridMean(values, tuple(lo), voxel)

    def linear_slopes(self, values: np.ndarray, h: float, brick: int):
        """(brick bounds, lipschitz) of a trilinear GridMean with these samples and voxel
        size: means.brick_slope_bounds(grid, brick) and grid.lipschitz."""
        v = np.ascontiguousarray(values, np.float64)
        cells = [s - 1 for s in v.shape]
        nb = [-(-c // brick) for c in cells]
        c2 = np.empty(tuple(nb), np.float64)
        out = cl.Buffer(self.device.ctx, cl.mem_flags.WRITE_ONLY, c2.nbytes)
        samples = to_device(self.device, v)   # held until the blocking copy below
        nx, ny, nz = (np.int32(s) for s in v.shape)
        launch(self.program, stages.BAKE_GRID_SLOPES, c2.size, nx=nx, ny=ny, nz=nz,
               brick=np.int32(brick), v=samples, brick_c2=out)
        cl.enqueue_copy(self.device.queue, c2, out)
        return np.sqrt(c2) / h, means.grid_slope_bound(values, h, float(c2.max()))
