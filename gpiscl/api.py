"""The Python API: load a scene, render it, get numpy images, write them, run uq.

Every argument is checked as the command line checks it (host/scene/arguments.py): a bad one
raises SceneError naming it, before any work.
"""
from __future__ import annotations

import copy

import numpy as np

from .host.scene import arguments
from .host.render.device import Device, shared_device
from .host.render.device_bakes import DeviceBakes
from .host.render.integrator import RenderResult, WavefrontIntegrator
from .host.render.memory import return_freed_pages
from .host.scene.loading import Scene, load_scene
from .host.errors import SceneError
from .host.compile.scene import compile_scene
from .host.render.aov import parse as aov_names

__all__ = ["Scene", "SceneError", "load_scene", "render", "render_result", "write_image",
           "uq"]


def render_result(scene, spp: int | None = None, seed: int | None = None,
                  resolution=None, device: Device | str | None = None,
                  batch_size: int | None = None, time_limit: float | None = None,
                  progress=None, realization: int | None = None,
                  stop=None, max_memory: int | None = None, aov=None,
                  cluster=None) -> RenderResult:
    """Render a scene; the image with its standard errors, sample counts and statistics.

    Parameters
    ----------
    scene : str, os.PathLike, dict or Scene
        A scene file, a scene document, or a loaded Scene.
    spp : int, optional
        Samples per pixel, >= 1 (default: the scene's render.spp).
    seed : int, optional
        Random seed in [0, 2**32) (default: the scene's render.seed). A fixed seed gives
        the same image whatever the batch size and device.
    resolution : (int, int), optional
        (width, height), each in [1, 16384] (default: the scene's camera.resolution).
    device : Device or str, optional
        An OpenCL device, or 'P:D' indices / a name fragment (default: the first usable
        device, shared between calls).
    batch_size : int, optional
        The most paths traced at once, in [1, 2**24]; batches are sized to take about
        0.5 s each below it (default 16384 on a CPU, 262144 elsewhere).
    time_limit : float, optional
        Stop after this many seconds of rendering (> 0, finite); holds to within one batch.
    progress : callable or bool, optional
        progress(paths) after each batch, or True for a progress bar in spp (a notebook
        widget under Jupyter).
    realization : int, optional
        Render GPIS realization R in [0, 2**31) for every pixel (weight space only).
    stop : callable, optional
        stop() -> bool, asked between bounces: True ends the render with the batches
        completed so far (stats.interrupted). Ctrl-C does the same.
    max_memory : int, optional
        Bytes the render may use, instead of the estimate of free memory: the film must fit
        (SceneError naming camera.resolution otherwise) and batches shrink to fit beside it.
    aov : str or list of str, optional
        Also collect these first-hit AOVs: 'depth', 'normal', 'albedo', 'position' (or
        'depth,normal'); write_image adds them as EXR layers. How they are averaged over a
        pixel's samples: gpiscl.host.render.aov.
    cluster : distributed.Client or str, optional
        Trace the samples on a Dask cluster: a Client, a scheduler address
        ('tcp://HOST:8786') or 'local:N' (N worker processes for this call); the image is
        the local one bit for bit. Needs the extra: pip install 'gpiscl[distributed]'.

    Returns
    -------
    RenderResult
        .image.mean (H, W, 3) float32, .image.stderr, .image.count (samples per pixel: 0
        for pixels a stopped render never reached), .stats (paths, seconds, spp_reached,
        interrupted, time_limited), .scene (the resolved scene rendered).

    Raises
    ------
    SceneError
        For a mistake in the scene or in an argument, naming it.
    """
    checked = arguments.check(spp=spp, seed=seed, resolution=resolution,
                              realization=realization, batch_size=batch_size,
                              time_limit=time_limit, max_memory=max_memory)
    aovs = aov_names(aov, "aov") if aov else ()
    if aovs and cluster is not None:
        # cluster units ship each path's radiance only (commands/cluster.py)
        raise SceneError(arguments.API_SOURCE, "aov", "not available with cluster yet")
    integrator, scene = prepare_render(scene, device=device, aov=bool(aovs), **{
        k: v for k, v in checked.items() if k != "time_limit"})
    spp = scene.data["render"]["spp"]
    bar = None
    if progress is True:
        from .host.render.progress import SppBar
        w, h = scene.data["camera"]["resolution"]
        progress = bar = SppBar(spp, w * h, notebook=True)
    elif progress is False:
        progress = None
    try:
        if cluster is not None:
            from .host.commands.cluster import render_on_cluster
            result = render_on_cluster(cluster, integrator, scene, spp,
                                       checked.get("time_limit"), progress, stop)
        else:
            result = integrator.render(spp, time_limit=checked.get("time_limit"),
                                       progress=progress, stop=stop)
    finally:
        if bar is not None:
            bar.close()
    result.scene, result.aovs = scene, aovs
    return result


def prepare_render(scene, spp=None, seed=None, resolution=None, device=None, batch_size=None,
             realization=None, max_memory=None, aov=False):
    """The compiled integrator and the resolved Scene with the overrides applied: the part
    of render_result before any sample is traced (the command line renders in between)."""
    scene = load_scene(scene)
    data = copy.deepcopy(scene.data)
    settings = data["render"]
    for key, value in (("spp", spp), ("seed", seed), ("realization", realization)):
        if value is not None:
            settings[key] = value
    if resolution is not None:
        data["camera"]["resolution"] = list(resolution)
    _check_realization(data, scene.source)
    if not isinstance(device, Device):
        device = shared_device(device)
    compiled = compile_scene(data, scene.source, DeviceBakes(device))
    # the compile's temporaries (a bake's samples read and checked, grid records packed)
    # are freed, but glibc keeps them in its heap; handed back, the programs and the film
    # do not come on top of them
    return_freed_pages()
    integrator = WavefrontIntegrator(device, compiled, settings, batch_size, max_memory,
                                     scene.source, aov)
    return integrator, Scene.resolved(data, scene.source, scene.base_dir)


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


def render(scene, spp: int | None = None, seed: int | None = None, resolution=None,
           device: Device | str | None = None, batch_size: int | None = None,
           time_limit: float | None = None, progress=None,
           realization: int | None = None, stop=None,
           max_memory: int | None = None) -> np.ndarray:
    """Render a scene; its mean image.

    Parameters
    ----------
    scene, spp, seed, resolution, device, batch_size, time_limit, progress, realization,
    stop, max_memory
        As for render_result.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float32 linear radiance; pixels a stopped render never reached are 0 (use
        render_result and its image.count to tell them apart).

    Raises
    ------
    SceneError
        For a mistake in the scene or in an argument, naming it.
    """
    return render_result(scene, spp=spp, seed=seed, resolution=resolution, device=device,
                         batch_size=batch_size, time_limit=time_limit, progress=progress,
                         realization=realization, stop=stop,
                         max_memory=max_memory).image.mean


def write_image(path, result: RenderResult, exposure: float = 0.0) -> dict:
    """Write a render as the command line does.

    Parameters
    ----------
    path : str or os.PathLike
        NAME.exr (EXR with standard errors, sample counts, the AOVs the render collected
        and how it was made, a PNG preview and NAME.scene.json) or NAME.png (the preview
        and NAME.scene.json).
    result : RenderResult
        From render_result.
    exposure : float
        Preview exposure in stops.

    Returns
    -------
    dict
        {"exr", "png", "scene"}: the paths written (None for one not written).

    Raises
    ------
    SceneError
        For an unknown extension or a path that cannot be written, before anything is
        written; each file is written whole or not at all.
    """
    from .host.render.output import output_paths, write_outputs
    from .host.io.output_files import check_writable, scene_inputs

    if not isinstance(result, RenderResult) or result.scene is None:
        raise SceneError(arguments.API_SOURCE, "result",
                         "expected the RenderResult of render_result()")
    exposure = arguments.check(exposure=exposure)["exposure"]
    check_writable(output_paths(path).values(), "path", inputs=scene_inputs(result.scene))
    return write_outputs(result.image, result.scene, path, exposure, result.stats, result.aovs)


def uq(scene, realizations: int = 16, spp: int = 16, seed: int | None = None,
       first: int = 0, resolution=None, device: Device | str | None = None,
       batch_size: int | None = None, output=None, exposure: float = 0.0, stop=None,
       cluster=None):
    """Per-pixel mean and unbiased variance over GPIS realizations (as `gpiscl uq`).

    Parameters
    ----------
    scene : str, os.PathLike, dict or Scene
        A scene whose GPIS objects all use the weight_space sampler.
    realizations : int
        N >= 1 realizations, each with its own geometry and its own samples.
    spp : int
        K >= 2 samples per pixel per realization (the within-realization variance needs 2).
    seed : int, optional
        Picks the realizations and their samples, in [0, 2**32).
    first : int
        Index of the first realization (>= 0): runs [I, I+N) of one seed merge exactly.
    resolution, device, batch_size, stop
        As for render_result.
    output : str or os.PathLike, optional
        NAME.exr: also write the EXR (mean, variance, std and their standard errors), the
        previews, NAME.uq.npz (partial sums for merging) and the resolved scene; needs
        N >= 2 in all.
    exposure : float
        Preview exposure in stops.
    cluster : distributed.Client or str, optional
        Render the realizations on a Dask cluster, as for render_result: the same sums.

    Returns
    -------
    UqRun
        .sums (UqSums: .mean, .variance, .std, .mean_stderr, .variance_stderr, .n),
        .ids, .seconds, .paths, .interrupted.

    Raises
    ------
    SceneError
        For a mistake in the scene or an argument, naming it.
    """
    from .host.io.output_files import check_writable, scene_inputs
    from .host.schema import Context, Int
    from .host.commands.uq import check_uq_scene, render_realizations, uq_output_paths, write_uq_outputs

    ctx = Context(arguments.API_SOURCE, ".")
    realizations = Int(ge=1, le=2**31).resolve(realizations, "realizations", ctx)
    spp = Int(ge=2, lt=2**31).resolve(spp, "spp", ctx)
    first = Int(ge=0, lt=2**31).resolve(first, "first", ctx)
    checked = arguments.check(seed=seed, resolution=resolution, batch_size=batch_size,
                              exposure=exposure)
    scene = load_scene(scene)
    check_uq_scene(scene.data, scene.source)
    if output is not None:
        check_writable(uq_output_paths(output).values(), "output", inputs=scene_inputs(scene))
    if cluster is not None:
        from .host.commands.cluster import uq_on_cluster
        run = uq_on_cluster(cluster, scene, realizations, spp, seed=checked.get("seed"),
                            first=first, resolution=checked.get("resolution"),
                            batch_size=checked.get("batch_size"), stop=stop)
    else:
        run = render_realizations(scene, realizations, spp, seed=checked.get("seed"),
                                  first=first, resolution=checked.get("resolution"),
                                  device=device, batch_size=checked.get("batch_size"),
                                  stop=stop)
    if output is not None:
        if run.sums.n < 2:
            raise SceneError(arguments.API_SOURCE, "output",
                             f"needs >= 2 realizations to write (got {run.sums.n})")
        data = copy.deepcopy(scene.data)
        if "resolution" in checked:
            data["camera"]["resolution"] = checked["resolution"]
        write_uq_outputs(run.sums, Scene.resolved(data, scene.source, scene.base_dir),
                         output, checked["exposure"], run.meta)
    return run


def density(scene, obj: int = 0, output="density", ray=None, paths: int = 20000,
            bounces: int = 2, seed: int = 1, device: Device | None = None) -> list:
    """The GPIS density of GPIS number `obj` of a scene file: free flights and first-hit
    normals of `paths` device flights per memory model (docs/design/classical-limits.md),
    written to the folder `output` as flights.csv, summary.csv, free_flight.png and, for a
    mean with a gradient along the ray, normals.png. Needs matplotlib (the `plots` extra).

    ray: 'ox,oy,oz,dx,dy,dz,length' or None (through the proxy's centre, against the
    mean's gradient there). Returns the written paths."""
    from .host.commands.density import parse_ray, write_density
    from .host.schema import Context, Int

    ctx = Context(arguments.API_SOURCE, ".")
    paths = Int(ge=1, le=10**8).resolve(paths, "paths", ctx)
    bounces = Int(ge=1, le=64).resolve(bounces, "bounces", ctx)
    obj = Int(ge=0).resolve(obj, "obj", ctx)
    checked = arguments.check(seed=seed)
    return write_density(str(scene), obj, output, parse_ray(ray) if ray else None, paths,
                         bounces, checked["seed"], device)
