"""The realization loop of a uq run: N weight-space realizations of one scene, each with
its own geometry id and path seed (sums.py says why), merged into UqSums as they finish."""
from __future__ import annotations

import time
from dataclasses import dataclass

from ..errors import SceneError
from .files import run_meta
from .sums import UqSums, iter_realizations


def check_uq_scene(data: dict, source: str = "<scene>") -> None:
    """A fixed realization is a weight-space notion: every GPIS must use that sampler."""
    for i, s in enumerate(data.get("shapes", [])):
        if s.get("type") == "gpis" and s["sampler"]["type"] != "weight_space":
            raise SceneError(source, f"shapes[{i}].sampler.type",
                             "uq renders fixed realizations, which needs weight_space "
                             f"(got {s['sampler']['type']})")


@dataclass
class UqRun:
    sums: UqSums
    ids: list          # geometry ids of the completed realizations, in render order
    seconds: float
    paths: int
    interrupted: bool = False
    meta: dict = None  # provenance of the sums (see files.merge_partials)
    scene: object = None  # the resolved Scene rendered (resolution applied)


def prepare_realizations(scene, realizations: int, spp: int, seed: int | None = None,
                         first: int = 0, resolution=None):
    """(scene, data, seed): the scene loaded, with the resolution applied (data is its
    data), and the seed resolved; what every realization of a run is rendered from, here
    or on a cluster (distributed/cluster.py). The arguments are checked by the caller
    (scene/arguments.py UQ_SPECS, as api.uq does)."""
    from ..scene.loading import load_scene

    scene = load_scene(scene)
    check_uq_scene(scene.data, scene.source)
    scene = scene.with_overrides(resolution=resolution)
    seed = scene.data["render"]["seed"] if seed is None else int(seed)
    return scene, scene.data, seed


def render_realization(device, compiled, data: dict, spp: int, rid: int, rseed: int,
                       batch_size=None, stop=None):
    """The RenderResult of one realization: geometry id rid, path seed rseed."""
    from ..render.integrator import WavefrontIntegrator

    settings = dict(data["render"], spp=int(spp), seed=rseed, realization=rid)
    return WavefrontIntegrator(device, compiled, settings, batch_size).render(int(spp),
                                                                              stop=stop)


def render_realizations(scene, realizations: int, spp: int, seed: int | None = None,
                        first: int = 0, resolution=None, device=None, batch_size=None,
                        progress=None, stop=None) -> UqRun:
    """Render realizations first .. first+realizations-1 with spp samples each; stop()
    (asked between bounces) or Ctrl-C ends it, keeping the completed realizations."""
    from ..render.device import Device, shared_device
    from ..render.device_bakes import DeviceBakes
    from ..compile.scene import compile_scene

    scene, data, seed = prepare_realizations(scene, realizations, spp, seed, first,
                                             resolution)
    if not isinstance(device, Device):
        device = shared_device(device)
    # once: only the ids and seeds change
    compiled = compile_scene(data, scene.source, DeviceBakes(device))
    w, h = data["camera"]["resolution"]
    sums = UqSums.empty((h, w, 3))
    paths, done, interrupted = 0, [], False
    start = time.perf_counter()
    try:
        for rid, rseed in iter_realizations(seed, first, realizations):
            result = render_realization(device, compiled, data, spp, rid, rseed, batch_size,
                                        stop)
            if result.stats.interrupted:   # Ctrl-C: fewer than K samples, so not used
                interrupted = True
                break
            sums = sums.merge(UqSums.from_film(result.image))
            paths += result.stats.paths
            done.append(rid)
            if progress is not None:
                progress(1)
    except KeyboardInterrupt:
        interrupted = True
    meta = run_meta(data, seed, spp, first, len(done))
    return UqRun(sums, done, time.perf_counter() - start, paths, interrupted, meta, scene)
