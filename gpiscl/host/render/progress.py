"""Progress of a render in samples per pixel, with ETA and paths/s: a bar on a terminal
or in a notebook, plain lines anywhere else (a log file, a pipe, a batch job's output).

tqdm redraws only when it is updated; a slow batch would freeze the elapsed time and ETA,
which reads as a hang. A daemon thread redraws it every TICK_SECONDS in between. Outside a
terminal a bar's carriage returns are noise, and without them a long render printed nothing
between `rendering ...` and the end: ProgressLines prints one line every LINE_SECONDS instead.
"""
from __future__ import annotations

import sys
import threading
import time

TICK_SECONDS = 0.5
LINE_SECONDS = 10.0
BAR_FORMAT = ("{desc}{percentage:3.0f}%|{bar}| {n:.4g}/{total:.4g} spp "
              "[{elapsed}<{remaining}{postfix}]")


class SppBar:
    """progress(paths) for WavefrontIntegrator.render, drawn in spp.

    notebook=True draws a Jupyter widget (tqdm.auto picks it when one is available).
    """

    def __init__(self, spp: int, pixels: int, file=None, notebook: bool = False):
        if notebook:
            from tqdm.auto import tqdm
        else:
            from tqdm import tqdm
        self.pixels = pixels
        self.paths = 0
        self.start = time.perf_counter()
        self.bar = tqdm(total=spp, file=file, bar_format=BAR_FORMAT, smoothing=0.1,
                        mininterval=0.0, dynamic_ncols=True)
        self._closed = threading.Event()
        self._ticker = threading.Thread(target=self._tick, daemon=True)
        self._ticker.start()

    def __call__(self, paths: int) -> None:
        if paths == 0 and self.paths == 0:   # the render's clock starts: not the compile
            self.start = time.perf_counter()
            self.bar.reset()
            return
        self.paths += paths
        seconds = time.perf_counter() - self.start
        rate = self.paths / seconds if seconds > 0 else 0.0
        self.bar.set_postfix_str(f"{rate:.3g} paths/s", refresh=False)
        self.bar.update(paths / self.pixels)

    def _tick(self):
        while not self._closed.wait(TICK_SECONDS):
            self.bar.refresh()

    def close(self) -> None:
        self._closed.set()
        self._ticker.join()
        self.bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def duration(seconds: float) -> str:
    """`12 s`, `3 min 05 s`, `2 h 07 min`, `549 d 20 h`."""
    s = int(round(min(seconds, 1e15)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    if s < 86400:
        return f"{s // 3600} h {s % 3600 // 60:02d} min"
    return f"{s // 86400} d {s % 86400 // 3600} h"


class ProgressLines:
    """progress(done) as a plain line every `every` seconds (none for a run that ends
    sooner), e.g. `rendering: 12.5/64 spp (20 %), 41 s, ETA 2 min 44 s, 1.23e+04 paths/s`.
    done counts items (paths), `per` items make one unit of total (pixels per spp). The
    clock starts at progress(0), which a render calls once its programs are compiled."""

    def __init__(self, what: str, total: int, unit: str, per: int = 1, items: str = "",
                 file=None, every: float = LINE_SECONDS):
        self.what, self.total, self.unit, self.per = what, total, unit, per
        self.items = items or unit
        self.file, self.every = file, every
        self.done = 0
        self.start = self.last = time.perf_counter()

    def __call__(self, done: int) -> None:
        now = time.perf_counter()
        if done == 0 and self.done == 0:
            self.start = self.last = now
            return
        self.done += done
        if now - self.last < self.every:
            return
        self.last = now
        elapsed = now - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        whole = self.total * self.per
        eta = duration((whole - self.done) / rate) if rate > 0 else "?"
        print(f"{self.what}: {self.done / self.per:.4g}/{self.total} {self.unit} "
              f"({100 * self.done / whole:.0f} %), {duration(elapsed)}, ETA {eta}, "
              f"{rate:.4g} {self.items}/s", file=self.file, flush=True)

    def close(self) -> None:
        pass


def spp_progress(spp: int, pixels: int, file):
    """A bar where one can be drawn (a terminal, a notebook), lines elsewhere."""
    if draws_bars(file):
        return SppBar(spp, pixels, file=file, notebook=True)
    return ProgressLines("rendering", spp, "spp", pixels, "paths", file)


def draws_bars(file) -> bool:
    try:
        if file.isatty():
            return True
    except (AttributeError, ValueError):
        pass
    return "ipykernel" in sys.modules     # Jupyter: tqdm.auto draws a widget
