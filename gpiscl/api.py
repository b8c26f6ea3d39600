"""The Python API: load a scene, render it, get numpy images."""
from __future__ import annotations

import copy

import numpy as np

from .host.device import Device, shared_device
from .host.integrator import RenderResult, WavefrontIntegrator
from .host.scene import Scene, SceneError, load_scene
from .host.scene_compile import compile_scene


def render_result(scene, spp: int | None = None, seed: int | None = None,
                  resolution=None, device: Device | str | None = None,
                  batch_size: int | None = None, time_limit: float | None = None,
                  progress=None, realization: int | None = None) -> RenderResult:
    """Render a scene (path, dict or Scene); arguments override its render block."""
    integrator, settings = _prepare(scene, spp=spp, seed=seed, resolution=resolution,
                                   device=device, batch_size=batch_size,
                                   realization=realization)
    return integrator.render(settings["spp"], time_limit=time_limit, progress=progress)


def _prepare(scene, spp=None, seed=None, resolution=None, device=None, batch_size=None,
            realization=None):
    """The compiled integrator for a render and its resolved render settings: the part
    of render_result before any sample is traced (the command line renders in between)."""
    scene = load_scene(scene)
    data = copy.deepcopy(scene.data)
    settings = data["render"]
    if spp is not None:
        settings["spp"] = int(spp)
    if seed is not None:
        settings["seed"] = int(seed)
    if realization is not None:
        settings["realization"] = int(realization)
    if resolution is not None:
        data["camera"]["resolution"] = [int(resolution[0]), int(resolution[1])]
    _check_realization(data, scene.source)
    if not isinstance(device, Device):
        device = shared_device(device)
    integrator = WavefrontIntegrator(device, compile_scene(data, scene.source), settings,
                                     batch_size)
    return integrator, settings


def _check_realization(data: dict, source: str):
    """A fixed realization exists only in weight space: function space samples f along
    each ray as it goes, so there is no realization to hold fixed."""
    if data["render"]["realization"] is None:
        return
    for i, shape in enumerate(data["shapes"]):
        if shape["type"] == "gpis" and shape["sampler"]["type"] != "weight_space":
            raise SceneError(source, "render.realization",
                             f"shapes[{i}] uses the {shape['sampler']['type']} sampler, which "
                             "has no global realization to fix; use weight_space to render "
                             "one realization")


def render(scene, spp: int | None = None, **kwargs) -> np.ndarray:
    """Render and return the mean image, float32 (H, W, 3)."""
    return render_result(scene, spp=spp, **kwargs).image.mean


__all__ = ["Scene", "load_scene", "render", "render_result"]
