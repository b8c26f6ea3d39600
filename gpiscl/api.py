"""The Python API: load a scene, render it, get numpy images, write them, run uq; and what
the other commands do (devices, sample figures, convert-vdb).

Every argument is checked by host/scene/arguments.py: a bad one raises SceneError naming
it, before any work. The command line is a shell over these functions (gpiscl/cli/).

Only scene loading is imported here: the rest is imported by the function that needs it,
so that convert-vdb runs under a Python with numpy but no pyopencl or OpenEXR (the system
Python with Debian's python3-openvdb), and Dask is imported only for a cluster.
"""
from __future__ import annotations

import sys

from .host.errors import API_SOURCE, SceneError
from .host.scene import arguments
from .host.scene.loading import Scene, load_scene

__all__ = ["Scene", "SceneError", "load_scene", "render", "render_result", "write_image",
           "tonemap", "uq", "write_uq", "uq_merge", "check_output", "check_uq_output", "devices", "sample_figures",
           "convert_vdb"]


def render_result(scene, spp: int | None = None, seed: int | None = None,
                  resolution=None, device=None, batch_size: int | None = None,
                  time_limit: float | None = None, progress=None, realization=None,
                  stop=None, max_memory=None, aov=None, cluster=None, on_compiled=None,
                  settings=None):
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
        The most paths traced at once, in [1, 2**24]; below it, batches are sized to take
        about half a second each (default 16384 on a CPU, 262144 elsewhere).
    time_limit : float, optional
        Stop after this many seconds of rendering, in (0, 1e9]; holds to within one bounce
        of a batch (the first batch always completes).
    progress : callable or bool, optional
        progress(paths) after each batch (and progress(0) once the programs are compiled
        and the clock starts), or True for a progress bar in spp (a notebook widget under
        Jupyter; where stderr is neither, a plain line every 10 s). On, a compile the
        driver's cache does not answer prints one line saying so.
    realization : int or 'none', optional
        Render GPIS realization R in [0, 2**31) for every pixel (weight space only);
        'none' averages over realizations whatever the scene says.
    stop : callable, optional
        stop() -> bool, asked between bounces: True ends the render with the batches
        completed so far (stats.interrupted). Ctrl-C does the same.
    max_memory : int or str, optional
        Bytes the render may use (or a size like '8G'), instead of the estimate of free
        memory: the film must fit (SceneError naming camera.resolution otherwise) and
        batches shrink to fit beside it.
    aov : str or list of str, optional
        Also collect these first-hit AOVs: 'depth', 'normal', 'albedo', 'position' (or
        'depth,normal'); write_image adds them as EXR layers. How they are averaged over a
        pixel's samples: gpiscl.host.render.aov.
    cluster : distributed.Client or str, optional
        Trace the samples on a Dask cluster: a Client, a scheduler address
        ('tcp://HOST:8786') or 'local:N' (N worker processes for this call); the image is
        the local one bit for bit. Needs the extra: pip install 'gpiscl[distributed]'.
    on_compiled : callable, optional
        on_compiled(scene, where) once the scene is compiled, before the first sample:
        the resolved Scene to be rendered and where it renders (the device's name, or the
        cluster).
    settings : dict, optional
        Scene values by key path, applied before the arguments above: {"render.nee":
        False, "camera.fov": 30, "shapes[0].bsdf.albedo": [1, 0, 0]}. The scene schema
        checks them; a bad path or value is a SceneError naming settings['KEY'].

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
    from .host.render.memory import return_freed_pages

    checked = arguments.check(spp=spp, seed=seed, resolution=resolution,
                              realization=realization, batch_size=batch_size,
                              time_limit=time_limit, max_memory=max_memory)
    time_limit = checked.pop("time_limit", None)
    aovs = _aovs(aov)
    if aovs and cluster is not None:
        # cluster units ship each path's radiance only (distributed/cluster.py)
        raise SceneError(API_SOURCE, "aov", "not available with `cluster` yet")
    distributed = _dask(cluster) if cluster is not None else None
    from .host.render.device import announcing_compiles
    # with progress on, a cold compile says so rather than sit silent
    with announcing_compiles(sys.stderr if progress not in (None, False) else None):
        integrator, scene = prepare_render(scene, device=device, aov=bool(aovs),
                                           settings=settings, **checked)
        if on_compiled is not None:
            on_compiled(scene, _where(cluster, integrator.device))
        spp = scene.data["render"]["spp"]
        bar = None
        if progress is True:
            from .host.render.progress import spp_progress
            w, h = scene.data["camera"]["resolution"]
            progress = bar = spp_progress(spp, w * h, sys.stderr)
        elif progress is False:
            progress = None
        try:
            if distributed is not None:
                result = distributed.render_on_cluster(cluster, integrator, scene, spp,
                                                       time_limit, progress, stop)
            else:
                result = integrator.render(spp, time_limit=time_limit, progress=progress,
                                           stop=stop)
        finally:
            if bar is not None:
                bar.close()
    # The film is on the host now: drop the integrator, so that its device buffers (the
    # film's sums, the scene's records: on a CPU device the process's own memory, the
    # film's in the malloc heap) are freed and handed back before the output files'
    # buffers are allocated (docs/design/memory-budget.md, 'Host peaks').
    del integrator
    return_freed_pages()
    result.scene, result.aovs = scene, aovs
    return result


def prepare_render(scene, spp=None, seed=None, resolution=None, device=None, batch_size=None,
                   realization=None, max_memory=None, aov=False, settings=None):
    """The compiled integrator and the resolved Scene with the overrides applied: the part
    of render_result before any sample is traced (the arguments already checked)."""
    from .host.compile.scene import compile_scene
    from .host.render.device_bakes import DeviceBakes
    from .host.render.integrator import WavefrontIntegrator
    from .host.render.memory import return_freed_pages

    scene = load_scene(scene).with_overrides(spp=spp, seed=seed, resolution=resolution,
                                             realization=realization, settings=settings)
    _check_realization(scene.data, scene.source)
    device = _device(device)
    compiled = compile_scene(scene.data, scene.source, DeviceBakes(device))
    # the compile's temporaries (a bake's samples read and checked, grid records packed)
    # are freed, but glibc keeps them in its heap; handed back, the programs and the film
    # do not come on top of them
    return_freed_pages()
    integrator = WavefrontIntegrator(device, compiled, scene.data["render"], batch_size,
                                     max_memory, scene.source, aov)
    return integrator, scene


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


def _aovs(aov) -> tuple:
    from .host.render.aov import parse
    return parse(aov, "aov") if aov else ()


def _device(device):
    from .host.render.device import Device, shared_device
    return device if isinstance(device, Device) else shared_device(device)


def _dask(cluster):
    """The cluster backend, imported and cluster's address checked before any work:
    without Dask, or with too many local workers, a one-line error."""
    from .host.distributed import cluster as backend
    backend.local_workers(cluster, API_SOURCE, "cluster")
    return backend


def _where(cluster, device) -> str:
    return f"the Dask cluster {cluster}" if cluster is not None else device.name


def render(scene, spp: int | None = None, seed: int | None = None, resolution=None,
           device=None, batch_size: int | None = None, time_limit: float | None = None,
           progress=None, realization=None, stop=None, max_memory=None, aov=None,
           cluster=None, settings=None):
    """Render a scene; its mean image.

    Parameters
    ----------
    scene, spp, seed, resolution, device, batch_size, time_limit, progress, realization,
    stop, max_memory, aov, cluster, settings
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
                         realization=realization, stop=stop, max_memory=max_memory,
                         aov=aov, cluster=cluster, settings=settings).image.mean


def check_output(output, scene, aov=None, exposure: float = 0.0) -> None:
    """SceneError now, before any work, unless write_image(output, result, exposure) could
    write a render of scene (with these AOVs): a long render must not end in 'cannot
    write'."""
    from .host.io.output_files import check_writable, scene_inputs
    from .host.render.output import output_paths

    arguments.check(exposure=exposure)
    paths = output_paths(output)
    if _aovs(aov) and paths["exr"] is None:
        raise SceneError(API_SOURCE, "aov", "AOVs are EXR layers: use NAME.exr")
    check_writable(paths.values(), "output", inputs=scene_inputs(load_scene(scene)))


def write_image(path, result, exposure: float = 0.0) -> dict:
    """Write a render as the command line does.

    Parameters
    ----------
    path : str or os.PathLike
        NAME.exr (EXR with standard errors, sample counts, the AOVs the render collected
        and how it was made, a PNG preview and NAME.scene.json) or NAME.png (the preview
        and NAME.scene.json).
    result : RenderResult or numpy.ndarray
        From render_result; or an (H, W, 3) linear image such as render() returns, written
        as the EXR's R, G, B and the preview (clamp curve), without a scene file.
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
    from .host.io.output_files import check_writable, scene_inputs, write_atomically
    from .host.render.integrator import RenderResult
    from .host.render.output import output_paths, write_outputs

    exposure = arguments.check(exposure=exposure)["exposure"]
    if isinstance(result, RenderResult) and result.scene is not None:
        check_writable(output_paths(path, "path").values(), "path",
                       inputs=scene_inputs(result.scene))
        return write_outputs(result.image, result.scene, path, exposure, result.stats,
                             result.aovs, "path")
    from .host.io.images import write_exr, write_png
    rgb = _rgb(result, "result", "the RenderResult of render_result() or an (H, W, 3) image")
    paths = dict(output_paths(path, "path"), scene=None)
    check_writable(paths.values(), "path")
    if paths["exr"] is not None:
        write_atomically(paths["exr"], lambda tmp: write_exr(tmp, rgb.astype("float32")))
    preview = tonemap(rgb, exposure)
    write_atomically(paths["png"], lambda tmp: write_png(tmp, preview))
    return paths


def tonemap(image, exposure: float = 0.0, curve: str = "clamp"):
    """The 8-bit sRGB preview of a linear (H, W, 3) image, as the PNG a render writes:
    scaled by 2**exposure, then the curve ('clamp': clip and sRGB-encode; 'filmic': roll
    the highlights off, the scene's render.tonemap). Returns (H, W, 3) uint8."""
    from .host.io.images import TONEMAPS, tonemap_srgb8

    exposure = arguments.check(exposure=exposure)["exposure"]
    if curve not in TONEMAPS:
        raise SceneError(API_SOURCE, "curve", f"expected one of {', '.join(TONEMAPS)} (got "
                         f"{curve!r:.40})")
    return tonemap_srgb8(_rgb(image, "image", "an (H, W, 3) image"), exposure, curve)


def _rgb(image, name: str, expected: str):
    import numpy as np
    try:
        rgb = np.asarray(image, dtype=np.float64)
    except (TypeError, ValueError):
        rgb = None
    if rgb is None or rgb.ndim != 3 or rgb.shape[2] != 3 or 0 in rgb.shape:
        raise SceneError(API_SOURCE, name, f"expected {expected} (got "
                         f"{getattr(image, 'shape', type(image).__name__)})")
    return rgb


def uq(scene, realizations: int = 16, spp: int = 16, seed: int | None = None,
       first: int = 0, resolution=None, device=None, batch_size: int | None = None,
       output=None, exposure: float = 0.0, stop=None, cluster=None, progress=None,
       on_started=None, settings=None):
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
    resolution, device, batch_size, stop, settings
        As for render_result.
    output : str or os.PathLike, optional
        NAME.exr: checked writable before any work, then written as write_uq does; needs
        N >= 2 in all.
    exposure : float
        Preview exposure in stops.
    cluster : distributed.Client or str, optional
        Render the realizations on a Dask cluster, as for render_result: the same sums.
    progress : callable or bool, optional
        progress(1) after each realization, or True for a progress bar (where stderr is
        not a terminal or a notebook, a plain line every 10 s).
    on_started : callable, optional
        on_started(scene, where) once the arguments and the scene are checked, before any
        realization is compiled or rendered (as render_result's on_compiled).

    Returns
    -------
    UqRun
        .sums (UqSums: .mean, .variance, .std, .mean_stderr, .variance_stderr, .n),
        .ids, .seconds, .paths, .interrupted, .scene (the resolved scene rendered).

    Raises
    ------
    SceneError
        For a mistake in the scene or an argument, naming it.
    """
    from .host.uq.realizations import check_uq_scene, render_realizations

    checked = arguments.check(arguments.UQ_SPECS, realizations=realizations, spp=spp,
                              first=first, seed=seed, resolution=resolution,
                              batch_size=batch_size, exposure=exposure)
    if checked["first"] + checked["realizations"] > 2**31:
        # ids are distinct only modulo 2^31
        raise SceneError(API_SOURCE, "realizations",
                         "`first` + `realizations` must be <= 2**31")
    distributed = _dask(cluster) if cluster is not None else None
    scene = load_scene(scene).with_overrides(settings=settings)
    check_uq_scene(scene.data, scene.source)
    if output is not None:
        check_uq_output(output, scene)
    if distributed is None:
        device = _device(device)
    if on_started is not None:
        on_started(scene, _where(cluster, device if distributed is None else None))
    bar = None
    if progress is True:
        from .host.render.progress import ProgressLines, draws_bars
        if draws_bars(sys.stderr):
            from tqdm.auto import tqdm
            bar = tqdm(total=checked["realizations"], unit="realization", file=sys.stderr,
                       desc="realizations")
            progress = bar.update
        else:
            progress = bar = ProgressLines("uq", checked["realizations"], "realizations",
                                           file=sys.stderr)
    elif progress is False:
        progress = None
    kw = dict(seed=checked.get("seed"), first=checked["first"],
              resolution=checked.get("resolution"), batch_size=checked.get("batch_size"),
              progress=progress, stop=stop)
    from .host.render.device import announcing_compiles
    try:
        with announcing_compiles(sys.stderr if bar is not None else None):
            if distributed is not None:
                run = distributed.uq_on_cluster(cluster, scene, checked["realizations"],
                                                checked["spp"], **kw)
            else:
                run = render_realizations(scene, checked["realizations"], checked["spp"],
                                          device=device, **kw)
    finally:
        if bar is not None:
            bar.close()
    if output is not None:
        if run.sums.n < 2:
            raise SceneError(API_SOURCE, "output",
                             f"needs >= 2 realizations to write (got {run.sums.n})")
        write_uq(output, run, checked["exposure"])
    return run


def check_uq_output(output, scene, exposure: float = 0.0) -> None:
    """SceneError now, before any work, unless write_uq(output, run, exposure) could write
    a uq run of scene."""
    from .host.io.output_files import check_writable, scene_inputs
    from .host.uq.files import uq_output_paths

    arguments.check(exposure=exposure)
    check_writable(uq_output_paths(output).values(), "output",
                   inputs=scene_inputs(load_scene(scene)))


def write_uq(output, run, exposure: float = 0.0) -> dict:
    """Write a uq run: with N >= 2 realizations the EXR (mean, variance, std and their
    standard errors), the previews, NAME.uq.npz (partial sums for merging) and the
    resolved scene; with one, only NAME.uq.npz (it has no variance yet: merge it with
    other batches, uq_merge). Returns {name: path} of the files written."""
    from .host.io.output_files import write_atomically
    from .host.uq.files import uq_output_paths, with_digest, write_uq_outputs

    exposure = arguments.check(exposure=exposure)["exposure"]
    if run.sums.n < 1:
        raise SceneError(API_SOURCE, "run", "no realization completed: nothing to write")
    if run.sums.n < 2:
        path = uq_output_paths(output)["sums"]
        write_atomically(path, lambda tmp: run.sums.save(tmp, with_digest(run.sums,
                                                                           run.meta)))
        return {"sums": path}
    return write_uq_outputs(run.sums, run.scene, output, exposure, run.meta)


def uq_merge(partials, output, exposure: float = 0.0):
    """Merge the partial sums (NAME.uq.npz) of uq runs of one scene and seed, and write
    the EXR, previews and merged sums to output (NAME.exr) as write_uq does (no scene
    file: the partial sums do not carry the scene). Batches that overlap or do not
    belong together are refused, naming the file. Returns (UqSums, {name: path})."""
    from .host.io.output_files import check_writable
    from .host.uq.files import merge_partials, uq_output_paths, write_uq_outputs

    exposure = arguments.check(exposure=exposure)["exposure"]
    sums, meta = merge_partials(partials)
    if sums.n < 2:
        raise SceneError(API_SOURCE, "partials", "needs >= 2 realizations in all")
    check_writable(uq_output_paths(output).values(), "output", inputs=partials)
    return sums, write_uq_outputs(sums, None, output, exposure, meta)


def devices() -> list:
    """The OpenCL devices present: dicts with "index" ('P:D', for device=), "platform",
    "name", "type" ('cpu', 'gpu' or 'accelerator', also for device=), "compute_units"
    and "default" (the one a render picks without device=)."""
    from .host.errors import DeviceError
    from .host.render.device import DEVICE_TYPES, Device, list_devices

    try:
        default = Device().device
    except DeviceError:
        default = None
    return [{"index": f"{pi}:{di}", "platform": plat.name.strip(), "name": dev.name.strip(),
             # the names device= takes; PoCL's CPU also has the DEFAULT bit, which
             # pyopencl's to_string showed as "all | cpu"
             "type": " | ".join(t for t, bit in DEVICE_TYPES.items() if dev.type & bit)
             or "other",
             "compute_units": dev.max_compute_units,
             "default": default is not None and dev.int_ptr == default.int_ptr}
            for pi, di, plat, dev in list_devices()]


def sample_figures(target: str, output="figures", object: int = 0,
                   features=(10, 100, 1000), realizations: int = 4, resolution: int = 128,
                   seed: int = 0, observations=None, noise: float = 1e-2) -> list:
    """PNG figures of GPIS realizations into the folder output (needs matplotlib): lines,
    slices, weight-space features vs exact samples, prior occupancy, and with
    observations (a file of surface points) the posterior, each point observed on the
    surface with standard deviation noise (world units, as a scene's observations.noise).
    target: a kernel type, a kernel JSON object or a scene file (its GPIS number object).
    Returns the paths."""
    from .host.figures.samples import load_observations, resolve_target, write_figures

    checked = arguments.check(arguments.SAMPLE_SPECS, object=object, features=features,
                              realizations=realizations, resolution=resolution, seed=seed,
                              noise=noise)
    found = resolve_target(target, checked["object"])
    # a deviation, as in scene files; the posterior takes variances
    obs = load_observations(observations, checked["noise"] ** 2) if observations else None
    return write_figures(found, output, tuple(checked["features"]), checked["realizations"],
                         checked["seed"], checked["resolution"], observations=obs)


def convert_vdb(input, output, grid: str | None = None) -> dict:
    """Copy one float grid of an OpenVDB file (needs OpenVDB's Python binding) to an .npz
    grid usable as a grid mean; returns {"grid", "shape", "voxel_size", "origin"}."""
    from .host.io.vdb import convert_vdb as convert
    return convert(input, output, grid)


def convert_tungsten(scene, output, environment=None, grid_dir=None) -> list:
    """Convert the GPIS subset of a scene of the authors' Tungsten-based renderer into a
    gpiscl scene file; returns the notes on lossy mappings. environment substitutes the
    scene's environment: a radiance (number) or an .exr/.hdr map's path. Nothing is
    written on an error (SceneError: file, key path, reason); the mapping is documented
    in gpiscl/host/scene/tungsten.py, the output guarantees in docs/design/tungsten-import.md."""
    from .host.scene.tungsten_convert import convert_file, environment_option
    return convert_file(scene, output, environment_option(
        None if environment is None else str(environment)), grid_dir)


def density(scene, object: int = 0, output="density", ray=None, paths: int = 20000,
            bounces: int = 2, seed: int = 1, device=None) -> list:
    """The GPIS density of GPIS number `object` of a scene file: free flights and first-hit
    normals of `paths` device flights per memory model and of the classical medium
    counterpart (docs/design/classical-limits.md), written to the folder `output` as
    flights.csv, summary.csv, free_flight.png and, for a mean with a gradient along the
    ray, normals.png. Needs matplotlib (the `plots` extra). ray: 'ox,oy,oz,dx,dy,dz,length'
    or None (through the proxy's centre, against the mean's gradient there). Returns the
    paths written."""
    from .host.figures.density import parse_ray, write_density
    from .host.schema import Int

    checked = arguments.check({"object": Int(ge=0, lt=2**31), "paths": Int(ge=1, le=10**8),
                               "bounces": Int(ge=1, le=64), "seed": Int(ge=0, lt=2**32)},
                              object=object, paths=paths, bounces=bounces, seed=seed)
    return write_density(str(scene), checked["object"], output,
                         parse_ray(ray) if ray else None, checked["paths"],
                         checked["bounces"], checked["seed"], device)
