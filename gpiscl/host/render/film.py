"""Per-pixel sum, sum of squares and sample count, accumulated in double on the device."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl


@dataclass
class FilmImage:
    """Mean radiance and the standard error of that mean, per pixel and channel."""

    mean: np.ndarray       # (H, W, 3) float32
    stderr: np.ndarray     # (H, W, 3) float32
    count: np.ndarray      # (H, W) float64
    sum: np.ndarray        # (H, W, 3) float64
    sum_sq: np.ndarray     # (H, W, 3) float64
    aov: np.ndarray | None = None   # (H, W, 12) float64 first-hit sums (aov.py), if asked


class Film:
    def __init__(self, ctx: cl.Context, queue: cl.CommandQueue, width: int, height: int,
                 aov: bool = False):
        self.width, self.height = width, height
        self.queue = queue
        n = width * height
        mf = cl.mem_flags
        zeros3 = np.zeros(3 * n, np.float64)
        self.sum = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=zeros3)
        self.sum_sq = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=zeros3)
        self.count = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR,
                               hostbuf=np.zeros(n, np.float64))
        # the kernel takes the argument either way: one unused double without AOVs
        self.has_aov = aov
        self.aov = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR,
                             hostbuf=np.zeros(12 * n if aov else 1, np.float64))

    @property
    def arguments(self) -> dict:
        """The accumulate kernel's film group (layout/stages.py FILM)."""
        return {"sum": self.sum, "sum_sq": self.sum_sq, "count": self.count, "aov": self.aov}

    def read(self) -> FilmImage:
        h, w = self.height, self.width
        s = np.empty((h, w, 3), np.float64)
        q = np.empty((h, w, 3), np.float64)
        c = np.empty((h, w), np.float64)
        cl.enqueue_copy(self.queue, s, self.sum)
        cl.enqueue_copy(self.queue, q, self.sum_sq)
        cl.enqueue_copy(self.queue, c, self.count)
        # in place: an image's worth of float64 per step, not one per temporary (the end
        # of a render is its peak of memory); the same operations in the same order
        n = c[..., None]
        empty, single = ~(n > 0), ~(n > 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = s / n
            mean[np.broadcast_to(empty, mean.shape)] = 0.0
            var = n * mean                     # unbiased variance of one sample
            var *= mean
            np.subtract(q, var, out=var)
            np.maximum(var, 0.0, out=var)
            var /= n - 1
            var[np.broadcast_to(single, var.shape)] = 0.0
            var /= n                           # ... of the mean: its standard error
            var[np.broadcast_to(empty, var.shape)] = 0.0
            stderr = np.sqrt(var, out=var)
        aov = None
        if self.has_aov:
            aov = np.empty((h, w, 12), np.float64)
            cl.enqueue_copy(self.queue, aov, self.aov)
        return FilmImage(mean.astype(np.float32), stderr.astype(np.float32), c, s, q, aov)
