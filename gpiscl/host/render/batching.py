"""Batches sized in time, not in paths.

A fixed path count per batch is seconds on a fast scene and minutes on a slow one
(docs/design/batches.md, 'Batches sized in time'); progress, time limits and interrupts
can only act between batches (or bounces), so every batch must be short. BatchSizer
starts small, measures each batch's throughput and sizes the next one to take about
TARGET_SECONDS, never more than the time left. The image does not depend on how the paths
are split (the film adds each pixel's paths in sample order), so this changes nothing but
responsiveness.

Paths run in pixel order, so consecutive batches cover different rows whose cost can differ
by orders of magnitude (sky against a large GPIS): sized from cheap sky rows, a batch that
then lands on the object overruns a time limit by a whole bounce (docs/design/batches.md,
'Batches sized by what their pixels cost'). BatchSizer's rate is the slowest of the last
RATE_WINDOW batches, which helps within a pass only; PixelCosts then shrinks each batch to
what the pixels it will cover cost: known from the batches that covered them before, and
in the first pass, where nothing is known yet, by probing one path ahead (the render loop:
integrator.py).
"""
from __future__ import annotations

import math
from collections import deque

TARGET_SECONDS = 0.5      # per batch: the bar moves, and a stop acts, at least once a second
FIRST_BATCH = 64          # paths: about a second on the slowest scenes (docs/design/batches.md)
MAX_GROWTH = 2            # per batch: small batches are overhead-bound, so their rate is low
RATE_WINDOW = 8
COST_CELLS = 1024         # runs of pixels whose cost PixelCosts keeps
GOLDEN = 0.6180339887498949


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
            # compared as floats: a huge time left is no limit, not an overflow
            fits = self.rate * max(remaining_seconds, 0.0)
            if fits < n:
                n = math.floor(fits)
        return max(0, n)


class PixelCosts:
    """Seconds per path by pixel, learned from the batches that covered each run of pixels
    (COST_CELLS runs of the image, in path order) and from one-path probes where no batch
    has been yet. Only shrinks batches: BatchSizer still bounds their growth."""

    def __init__(self, num_pixels: int, target: float = TARGET_SECONDS):
        self.pixels = int(num_pixels)
        self.cells = min(COST_CELLS, self.pixels)
        self.target = float(target)
        self.cost = [None] * self.cells        # seconds per path; None: never measured
        self.overhead = None                   # of a one-path batch: its launches
        self.probes = 0

    def _cell(self, pixel: int) -> int:
        return pixel * self.cells // self.pixels

    def _runs(self, start: int, paths: int):
        """(cell, paths in it) of paths start .. start+paths-1, in order (one pass at most)."""
        p, left = start % self.pixels, min(paths, self.pixels)
        while left > 0:
            c = self._cell(p)
            end = min(self.pixels, -(-(c + 1) * self.pixels // self.cells))   # cell's end
            k = min(left, end - p)
            yield c, k
            p, left = (p + k) % self.pixels, left - k

    def record(self, start: int, paths: int, seconds: float) -> None:
        """A batch's seconds, shared among the cells it covered in proportion to what they
        were thought to cost (_filled): the relative costs the probes found are kept, their
        scale becomes the real batches'."""
        if paths <= 0 or seconds <= 0:
            return
        # what every batch pays whatever its size (the launches and their waits: ~ms a
        # bounce on a GPU) is not the paths' cost: counted in, a small batch looks dear
        # per path and the next one is sized smaller still
        seconds = max(seconds - (self.overhead or 0.0), 0.1 * seconds)
        runs, filled = list(self._runs(start, paths)), self._filled()
        scale = sum(k * filled[c] for c, k in runs) * max(1, paths // self.pixels)
        for c, _ in runs:
            self.cost[c] = (filled[c] * seconds / scale if scale > 0
                            else seconds / paths)

    def probe_point(self, start: int, paths: int) -> int:
        """The pixel of the next probe among paths start .. start+paths-1: golden-ratio
        points, so that rows and columns both vary (batches are often whole rows, and
        dyadic points would put every early probe in column 0, beside a centred object)."""
        self.probes += 1
        return (start + int((self.probes * GOLDEN) % 1.0 * paths)) % self.pixels

    def known(self, pixel: int) -> bool:
        return self.cost[self._cell(pixel % self.pixels)] is not None

    def probed(self, pixel: int, seconds: float) -> None:
        """A one-path batch at pixel took seconds: its cell costs that, less the launches
        every such batch pays (the cheapest one-path batch seen), which a real batch shares
        among its paths. A share of them left in the path's cost (a GPU's launch latency)
        would keep every first-pass batch at a few hundred paths."""
        self.overhead = seconds if self.overhead is None else min(self.overhead, seconds)
        c = self._cell(pixel % self.pixels)
        if self.cost[c] is None:
            self.cost[c] = max(seconds - self.overhead, 0.0)

    def _filled(self) -> list:
        """Every cell's cost: a cell never measured takes the cost of the nearest measured
        cell (in path order, wrapping; the dearer at a tie): costs vary smoothly over most
        of an image, so a probe on an object stands for the pixels around it, and the
        pixels just past the last batch cost about what it did."""
        cells, cost = self.cells, self.cost
        known = [c for c in range(cells) if cost[c] is not None]
        if not known:
            return [0.0] * cells
        before = [None] * cells      # (distance, cost) of the nearest known cell before
        at = (cells - known[-1], cost[known[-1]])    # wrapping round from the end
        for c in range(cells):
            at = (0, cost[c]) if cost[c] is not None else (at[0] + 1, at[1])
            before[c] = at
        filled = list(cost)
        at = (known[0] + 1, cost[known[0]])            # wrapping round from the start
        for c in reversed(range(cells)):
            at = (0, cost[c]) if cost[c] is not None else (at[0] + 1, at[1])
            if cost[c] is None:
                (db, cb), (da, ca) = before[c], at
                filled[c] = cb if db < da else ca if da < db else max(cb, ca)
        return filled

    def limit(self, start: int, paths: int) -> int:
        """The most of paths from start (at least 1) whose costs (_filled) add up to no
        more than the target."""
        cost = self._filled()
        whole, spent, n = paths // self.pixels, 0.0, 0
        if whole:
            per_pass = sum(k * cost[c] for c, k in self._runs(0, self.pixels))
            if per_pass * whole <= self.target:
                spent, n = per_pass * whole, whole * self.pixels
            elif per_pass <= self.target:
                return int(self.target / per_pass) * self.pixels
            else:
                paths = self.pixels
        for c, k in self._runs(start + n, paths - n):
            if spent + cost[c] * k > self.target:
                return max(1, n + int((self.target - spent) / cost[c]))
            spent, n = spent + cost[c] * k, n + k
        return max(1, n)
