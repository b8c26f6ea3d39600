"""matplotlib for the figures, an optional extra: one line naming the extra where it is
missing, and a backend that needs no display."""
from __future__ import annotations

from ..errors import SceneError

PLOTS_MISSING = ("figures need it, as the optional extra: pip install -e '.[plots]' "
                 "(or pip install matplotlib)")


def pyplot():
    """matplotlib.pyplot on the Agg backend, or a SceneError saying how to install it."""
    try:
        import matplotlib
    except ImportError:
        raise SceneError("matplotlib is not installed", "", PLOTS_MISSING) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt
