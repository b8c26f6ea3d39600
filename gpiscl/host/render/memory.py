"""What a render will allocate, checked against what there is before anything is allocated.

A legal 16384^2 camera needs tens of GiB of film on the device and on the host to read it
back, and a 10^8-path batch as much of queues. Allocating first and failing later gave
MemoryError tracebacks (or a segfault in the OpenCL runtime) minutes into a run. Here:
  film    56 bytes a pixel on the device (sum, sum of squares, count, in double), and
          HOST_BYTES_PER_PIXEL on the host to read it back, convert and write it
  queues  the per-path queues of one batch (layout/records.py), sized to the batch cap
The batch cap shrinks until the queues take at most a quarter of the memory left (a smaller
batch is only slower); the film cannot shrink, so a film that does not fit is an error
naming the resolution and the limit that binds, with --max-memory to override the estimate
of what is available. What the host can give is io/memory_budget.py's tightest limit (free
RAM, the process's rlimits, its cgroup's memory limit), not free RAM alone.
"""
from __future__ import annotations

import ctypes

from ..errors import SceneError
from ..io.memory_budget import Budget, memory_budget, size_text
from ..layout import records as layouts

FILM_BYTES_PER_PIXEL = 7 * 8          # film.py: 3 sums, 3 sums of squares, 1 count
# film.read's float64 copies and results, the float32 mean/stderr, the EXR and PNG buffers
HOST_BYTES_PER_PIXEL = 7 * 8 * 2 + 6 * 4 * 2 + 3 * 4 + 3
AOV_BYTES_PER_PIXEL = 12 * 8         # aov.py: first-hit sums, in double
QUEUE_SHARE = 0.25


# the queues integrator.py allocates per batch slot: path state, two ray queues, the hit
# and escaped index queues, the shadow rays
QUEUES = (layouts.PATH_STATE, layouts.RAY_QUEUE, layouts.RAY_QUEUE, layouts.INDEX_QUEUE,
          layouts.INDEX_QUEUE, layouts.SHADOW_QUEUE)


def bytes_per_path(shadow_per_path: int = 1) -> int:
    """Device bytes of one path in flight, with shadow_per_path shadow records."""
    extra = (shadow_per_path - 1) * sum(layouts.SHADOW_QUEUE.numpy_dtype(f).itemsize
                                        for _, f in layouts.SHADOW_QUEUE.fields)
    return extra + sum(layout.numpy_dtype(f).itemsize for layout in QUEUES
                       for _, f in layout.fields)


def plan(device, num_pixels: int, batch: int, max_memory: int | None = None,
         source: str = "<scene>", key: str = "camera.resolution", aov: bool = False,
         shadow_per_path: int = 1) -> int:
    """The batch cap that fits (<= batch); SceneError when the film itself does not fit.

    max_memory: the bytes the render may use, instead of the estimate of what is free.
    The estimate: on a CPU device the device's memory is the host's, so the film's device
    and host parts add up against the device's global memory and the host's budget,
    whichever is smaller; on a GPU the device part is held against the device's memory
    and the host part (the read-back) against the host's budget."""
    if num_pixels < 1:   # OpenCL has no empty buffers (a Scene's data edited after checks)
        raise SceneError(source, key, f"the film has no pixels ({num_pixels}): the camera's "
                         "resolution must be at least 1 x 1")
    dev = device.device
    film_device = num_pixels * (FILM_BYTES_PER_PIXEL + (AOV_BYTES_PER_PIXEL if aov else 0))
    film_host = num_pixels * (HOST_BYTES_PER_PIXEL + (2 * AOV_BYTES_PER_PIXEL if aov else 0))
    device_memory = Budget(int(dev.global_mem_size), "the device's global memory")
    if max_memory is not None:
        checks = [(film_device + film_host, Budget(max_memory, "--max-memory"))]
    elif device.is_cpu:
        checks = [(film_device + film_host, min(device_memory, memory_budget(),
                                                key=lambda b: b.bytes))]
    else:
        checks = [(film_device, device_memory), (film_host, memory_budget())]
    per_buffer = int(dev.max_mem_alloc_size)
    for need, budget in checks:
        if need > budget.bytes:
            raise SceneError(source, key, f"{num_pixels} pixels need about {size_text(need)} for "
                             f"the film; {size_text(budget.bytes)} available, under {budget.limit} "
                             "(render fewer pixels, or set --max-memory if the estimate is "
                             "wrong)")
    if num_pixels * 3 * 8 > per_buffer:      # the film's biggest buffer
        raise SceneError(source, key, f"{num_pixels} pixels need about {size_text(film_device)} "
                         f"for the film; the device allocates at most {size_text(per_buffer)} at "
                         "once (render fewer pixels)")
    film, budget = checks[0]    # the queues live where the film's first part does
    per_path = bytes_per_path(shadow_per_path)
    room = max(budget.bytes - film, 0) * QUEUE_SHARE
    fits = int(room // per_path)
    widest = max(layout.numpy_dtype(f).itemsize for layout in QUEUES for _, f in layout.fields)
    fits = min(fits, per_buffer // (widest * shadow_per_path))   # a field is one buffer
    if fits < 1:
        raise SceneError(source, key, f"no memory left for even one path after the film "
                         f"({size_text(film)} of {size_text(budget.bytes)})")
    return max(1, min(batch, fits))


def return_freed_pages() -> None:
    """Hand the heap's free pages back to the system after large buffers are released.

    PoCL's CPU device allocates buffers with malloc. At a CPU's batch sizes a queue's
    per-field buffers fall below glibc's dynamic mmap threshold, so their pages stay in
    the heap after release and the process keeps them resident; malloc_trim returns every
    free page (docs/design/memory-budget.md, 'Host peaks'). A no-op without glibc."""
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return
    trim(0)
