"""A progress bar in samples per pixel, with ETA and paths/s, whose clock keeps ticking.

tqdm redraws only when it is updated; a slow batch would freeze the elapsed time and ETA,
which reads as a hang. A daemon thread redraws it every TICK_SECONDS in between.
"""
from __future__ import annotations

import threading
import time

TICK_SECONDS = 0.5
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
