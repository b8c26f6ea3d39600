"""gpiscl: a wavefront path tracer for Gaussian Process Implicit Surfaces (OpenCL)."""
__version__ = "0.1.0"
__all__ = ["Scene", "load_scene", "render", "render_result"]


def __getattr__(name):
    # Lazy, so `python -m gpiscl devices` and the tests of small parts stay light.
    if name in __all__:
        from . import api
        return getattr(api, name)
    raise AttributeError(name)
