"""Which numbers the device can take: every number of a scene and every coordinate or
sample of the files it names (meshes, grids, images) is checked against these."""
from __future__ import annotations

import numpy as np

# The device computes in float32 and squares lengths (3.4e38 overflows, and a 1e20-wide
# floor vanished): every number of a scene, and every coordinate or sample of the files it
# names, must stay within +-MAGNITUDE.
MAGNITUDE = 1e18
TINY = 1e-30     # float32 keeps ~1e-38; products of two such numbers must not vanish either
WHY_MAGNITUDE = "the device computes in float32, where its square would overflow"


def array_problem(a, what: str, nonnegative: bool = False):
    """None, or why the numbers of array a (a mesh's vertices, an image's texels, a
    grid's samples) cannot go to the device: non-finite, out of range, or negative."""
    a = np.asarray(a)
    if a.dtype.kind != "f":   # floats as they are: a float32 grid needs no double copy
        a = a.astype(np.float64)
    if not a.size:
        return None
    # the extremes alone decide, without a temporary per number (docs/design/memory-budget.md,
    # 'Host copies'): a NaN propagates into both, an infinity is one
    lo, hi = a.min(), a.max()
    if not (np.isfinite(lo) and np.isfinite(hi)):
        bad = np.count_nonzero(~np.isfinite(a))
        return f"{what} has {bad} NaN or infinite value(s)"
    if max(-lo, hi) > MAGNITUDE:
        return f"{what} has values beyond +-{MAGNITUDE:g} ({WHY_MAGNITUDE})"
    if nonnegative and lo < 0:
        return f"{what} has negative values (min {lo:g})"
    return None
