"""Batches sized in time, not in paths.

A fixed path count per batch is seconds on a fast scene and minutes on a slow one (a
1024-feature rational-quadratic GPIS traces ~6,000 paths/s on a CPU, so 2^18 paths are 40 s);
progress, time limits and interrupts can only act between batches, so every batch must be
short. BatchSizer starts small, measures each batch's throughput and sizes the next one to
take about TARGET_SECONDS, never more than the time left. The image does not depend on how
the paths are split (the film adds each pixel's paths in sample order), so this changes
nothing but responsiveness.

Paths run in pixel order, so consecutive batches cover different rows whose cost differs
by several times (sky against a GPIS); the next batch is sized from the slowest rate of the
last RATE_WINDOW batches, not the last one, so a run of cheap rows does not size a batch
that then lands on expensive ones.
"""
from __future__ import annotations

import math
from collections import deque

TARGET_SECONDS = 0.5      # per batch: the bar moves, and a stop acts, at least once a second
FIRST_BATCH = 64          # paths: ~1 s on the slowest scenes measured (~60 paths/s)
MAX_GROWTH = 2            # per batch: small batches are overhead-bound, so their rate is low
RATE_WINDOW = 8


class BatchSizer:
    """Paths per batch from the measured throughput, between 1 and cap."""

    def __init__(self, cap: int, target: float = TARGET_SECONDS, first: int = FIRST_BATCH):
        self.cap = max(1, int(cap))
        self.target = float(target)
        self.size = min(self.cap, first)
        self.rate = None   # paths/s: the slowest of the recent batches, once measured
        self._rates = deque(maxlen=RATE_WINDOW)

    def record(self, paths: int, seconds: float) -> None:
        """Note how long a batch of paths took; sizes the next one."""
        if seconds <= 0 or paths <= 0:
            return
        self._rates.append(paths / seconds)
        self.rate = min(self._rates)
        wanted = int(self.rate * self.target)
        self.size = max(1, min(self.cap, wanted, self.size * MAX_GROWTH))

    def next(self, remaining_paths: int, remaining_seconds: float | None = None) -> int:
        """Paths for the next batch: 0 when the time left cannot hold even one path."""
        n = min(self.size, remaining_paths)
        if remaining_seconds is not None and self.rate is not None:
            fits = math.floor(self.rate * max(remaining_seconds, 0.0))
            n = min(n, fits)
        return max(0, n)
