"""gpiscl: a wavefront path tracer for Gaussian Process Implicit Surfaces (OpenCL).

    import gpiscl
    result = gpiscl.render_result("scene.json", spp=64)   # or render(): the mean image
    gpiscl.write_image("out.exr", result)

See help(gpiscl.render_result), gpiscl.write_image, gpiscl.uq, gpiscl.load_scene.
"""
from .version import __version__  # noqa: F401
from .opencl_vendors import prefer_system_pocl

# before anything imports pyopencl (every gpiscl module is imported after this package)
prefer_system_pocl()
__all__ = ["Scene", "SceneError", "load_scene", "render", "render_result", "write_image",
           "tonemap", "uq"]


def __getattr__(name):
    # Lazy, so `python -m gpiscl devices` and the tests of small parts stay light.
    if name in __all__:
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module 'gpiscl' has no attribute {name!r}")


def __dir__():
    # the lazy names too, so tab completion and dir() show the API
    return sorted(set(globals()) | set(__all__))
