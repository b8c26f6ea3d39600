"""What a render will allocate, checked against what there is before anything is allocated.

A legal 16384^2 camera needs ~15 GiB of film on the device and more on the host to read it
back; a 10^8-path batch needs ~23 GiB of queues. Allocating first and failing later gave
MemoryError tracebacks (or a segfault in the OpenCL runtime) minutes into a run. Here:
  film    56 bytes a pixel on the device (sum, sum of squares, count, in double), and
          HOST_BYTES_PER_PIXEL on the host to read it back, convert and write it
  queues  the per-path queues of one batch (layout/records.py), sized to the batch cap
The batch cap shrinks until the queues take at most a quarter of the memory left (a smaller
batch is only slower); the film cannot shrink, so a film that does not fit is an error
naming the resolution, with --max-memory to override the estimate of what is available.
"""
from __future__ import annotations

import ctypes
import os

from ..layout import records as layouts
from ..errors import SceneError

FILM_BYTES_PER_PIXEL = 7 * 8          # film.py: 3 sums, 3 sums of squares, 1 count
# film.read's float64 copies and results, the float32 mean/stderr, the EXR and PNG buffers
HOST_BYTES_PER_PIXEL = 7 * 8 * 2 + 6 * 4 * 2 + 3 * 4 + 3
AOV_BYTES_PER_PIXEL = 12 * 8         # aov.py: first-hit sums, in double
QUEUE_SHARE = 0.25


def gib(n: float) -> str:
    return f"{n / (1 << 30):.3g} GiB"


# the queues integrator.py allocates per batch slot: path state, two ray queues, the hit
# and escaped index queues, the shadow rays
QUEUES = (layouts.PATH_STATE, layouts.RAY_QUEUE, layouts.RAY_QUEUE, layouts.INDEX_QUEUE,
          layouts.INDEX_QUEUE, layouts.SHADOW_QUEUE)


def bytes_per_path() -> int:
    """Device bytes of one path in flight."""
    return sum(layout.numpy_dtype(f).itemsize for layout in QUEUES for _, f in layout.fields)


def host_available() -> int:
    """MemAvailable of /proc/meminfo (free RAM a new allocation can get), else all RAM."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 1 << 62   # unknown: do not refuse


def plan(device, num_pixels: int, batch: int, max_memory: int | None = None,
         source: str = "<scene>", key: str = "camera.resolution", aov: bool = False) -> int:
    """The batch cap that fits (<= batch); SceneError when the film itself does not fit.

    max_memory: the bytes the render may use, instead of the estimate of what is free
    (the device's global memory, and the host's available memory, whichever is smaller;
    on a CPU device both are the same RAM, so their needs add up)."""
    dev = device.device
    is_cpu = device.is_cpu
    film_device = num_pixels * (FILM_BYTES_PER_PIXEL + (AOV_BYTES_PER_PIXEL if aov else 0))
    film_host = num_pixels * (HOST_BYTES_PER_PIXEL + (2 * AOV_BYTES_PER_PIXEL if aov else 0))
    if max_memory is not None:
        available = max_memory
    else:
        available = min(int(dev.global_mem_size), host_available())
    per_buffer = int(dev.max_mem_alloc_size)
    biggest_film_buffer = num_pixels * 3 * 8
    film = film_device + film_host if is_cpu or max_memory is not None else film_device
    if film > available or biggest_film_buffer > per_buffer:
        limit = (f"{gib(available)} available" if film > available else
                 f"the device allocates at most {gib(per_buffer)} at once")
        raise SceneError(source, key, f"{num_pixels} pixels need about {gib(film)} for the "
                         f"film; {limit} (render fewer pixels, or set --max-memory if the "
                         "estimate is wrong)")
    per_path = bytes_per_path()
    room = max(available - film, 0) * QUEUE_SHARE
    fits = int(room // per_path)
    widest = max(layout.numpy_dtype(f).itemsize for layout in QUEUES for _, f in layout.fields)
    fits = min(fits, per_buffer // widest)   # each queue field is one buffer
    if fits < 1:
        raise SceneError(source, key, f"no memory left for even one path after the film "
                         f"({gib(film)} of {gib(available)})")
    return max(1, min(batch, fits))


def return_freed_pages() -> None:
    """Hand the heap's free pages back to the system after large buffers are released.

    PoCL's CPU device allocates buffers with malloc. A queue's per-field buffers (128 KB
    each at 2^15 paths) fall below glibc's dynamic mmap threshold, so their pages stay in
    the heap after release and the process keeps them resident; malloc_trim returns every
    free page (measured: 11 MB of queues at 2^15 paths). A no-op without glibc."""
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return
    trim(0)
