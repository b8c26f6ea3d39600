"""The wavefront path tracer: one host method per stage, one named kernel per stage.

The host reads one counter per bounce (how many rays continue), both to stop and to
size the next launches; all other counts stay on the device.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from . import gpis_function_space, layouts
from .device import Device, Program, to_device
from .film import Film, FilmImage
from .queues import DeviceQueue
from .scene_compile import CompiledScene

STAGE_FILES = ("generate_camera_rays.cl", "intersect.cl", "gpis_weight_space.cl", "queue_hits.cl",
               "escaped_rays.cl", "emission.cl", "scatter.cl", "gpis_shadow_weight_space.cl",
               "shadow_rays.cl", "accumulate.cl")
GPIS_HEADERS = ("gpis_proxy.h", "ws_features.h", "ws_posterior.h", "ws_intersect.h",
                "ws_objects.h", "gpis_fields.h")
DEFAULT_BATCH = 1 << 18


def ws_defines(device: Device) -> dict:
    """Weight-space features run WS_LANES per work-item in vector types: what makes the
    feature loop SIMD on CPU runtimes; GPUs vectorise across work-items instead."""
    is_cpu = bool(device.device.type & cl.device_type.CPU)
    # the native float width measured 1.3-1.6x faster than 8 lanes on a 16-wide CPU
    return {"WS_LANES": min(16, max(1, device.device.native_vector_width_float)) if is_cpu else 1}


def stage_program(device: Device) -> Program:
    """The one program holding every stage kernel of the integrator."""
    return Program(device, STAGE_FILES, defines=ws_defines(device), extra_headers=GPIS_HEADERS)


@dataclass
class RenderStats:
    paths: int = 0
    rays: int = 0
    shadow_rays: int = 0
    nan_paths: int = 0
    truncated_paths: int = 0
    killed_paths: int = 0      # GPIS hits whose sampled normal faced away from the ray
    gpis_failed: int = 0       # GPIS root searches that could not decide (counted, no hit)
    depth_cut_paths: int = 0   # paths that would have scattered again but reached max_depth
    fs_flights: int = 0        # function space: free flights through one object
    fs_samples: int = 0        # ... GP values they drew, and step-rule moment evaluations
    fs_evals: int = 0
    seconds: float = 0.0
    interrupted: bool = False
    kernel_table: str = ""

    def summary(self) -> str:
        rate = self.paths / self.seconds if self.seconds > 0 else 0.0
        lines = [f"paths: {self.paths}  rays: {self.rays}  shadow rays: {self.shadow_rays}  "
                 f"time: {self.seconds:.2f} s  paths/s: {rate:.4g}"]
        if (self.nan_paths or self.truncated_paths or self.killed_paths or self.gpis_failed
                or self.depth_cut_paths):
            lines.append(f"failed paths: {self.nan_paths} non-finite (recorded as 0), "
                         f"{self.truncated_paths} cut at the wavefront iteration limit, "
                         f"{self.depth_cut_paths} ended by max_depth, "
                         f"{self.killed_paths} killed at a GPIS normal facing away; "
                         f"{self.gpis_failed} undecided GPIS root searches")
        return "\n".join(lines)


@dataclass
class RenderResult:
    image: FilmImage
    stats: RenderStats = field(default_factory=RenderStats)


class WavefrontIntegrator:
    def __init__(self, device: Device, scene: CompiledScene, settings: dict,
                 batch_size: int | None = None):
        self.device, self.scene, self.settings = device, scene, settings
        ctx = device.ctx
        self.width, self.height = scene.resolution
        self.num_pixels = self.width * self.height
        self.batch = int(batch_size or settings.get("batch_size") or DEFAULT_BATCH)
        self.program = stage_program(device)
        # scene buffers
        self.camera = to_device(device, scene.camera)
        self.nodes = to_device(device, scene.bvh_nodes)
        self.prims = to_device(device, scene.primitives)
        self.materials = to_device(device, scene.materials)
        self.lights = to_device(device, scene.lights)
        self.env = [to_device(device, scene.env_texels), to_device(device, scene.env_marginal),
                    to_device(device, scene.env_conditional)]
        gpis = scene.gpis
        self.gpis_objects = to_device(device, gpis.objects)
        self.gpis_model = [to_device(device, gpis.kernels), to_device(device, gpis.mean_nodes),
                           to_device(device, gpis.order_table)]
        self.weight_space = gpis.uses("weight_space")
        self.function_space = None
        if gpis.uses("function_space"):
            self.batch = min(self.batch, gpis_function_space.max_batch(gpis.objects))
            self.function_space = gpis_function_space.FunctionSpaceStages(
                device, gpis.objects, self.batch, self.program.timings,
                mean_nodes=gpis.mean_nodes)   # sizes a posterior's program up front
        # work queues, sized for one batch
        cap = self.batch
        self.paths = DeviceQueue(ctx, layouts.PATH_STATE, cap)
        self.rays = [DeviceQueue(ctx, layouts.RAY_QUEUE, cap) for _ in range(2)]
        self.hits = DeviceQueue(ctx, layouts.INDEX_QUEUE, cap)
        self.escaped = DeviceQueue(ctx, layouts.INDEX_QUEUE, cap)
        self.shadow = DeviceQueue(ctx, layouts.SHADOW_QUEUE, cap)
        self.counters_host = np.zeros(layouts.NUM_COUNTERS, np.int32)
        self.counters = to_device(device, self.counters_host, writable=True)
        self.params_host = layouts.RENDER_PARAMS.zeros(1)
        self.params = cl.Buffer(ctx, cl.mem_flags.READ_ONLY, self.params_host.nbytes)
        self.film = Film(ctx, device.queue, self.width, self.height)
        rr = settings["russian_roulette"]
        p = self.params_host[0]
        p["seed"], p["max_depth"] = settings["seed"], settings["max_depth"]
        p["rr_start_depth"], p["rr_max_survival"] = rr["start_depth"], rr["max_survival"]
        p["num_lights"], p["num_pixels"] = len(scene.lights), self.num_pixels
        p["env_width"], p["env_height"] = scene.env_size
        p["nee"] = 1 if settings.get("nee", True) else 0
        p["num_gpis"] = len(gpis.objects)
        realization = settings.get("realization")
        p["realization"] = -1 if realization is None else realization
        # null surfaces do not count as bounces, so allow extra iterations for them
        self.max_iterations = 4 * settings["max_depth"] + 64
        self.stats = RenderStats()

    # --- one method per stage -------------------------------------------------------

    def _upload_params(self, **values):
        for k, v in values.items():
            self.params_host[0][k] = v
        cl.enqueue_copy(self.device.queue, self.params, self.params_host)

    def generate_camera_rays(self, n):
        self.program.launch("generate_camera_rays", n, self.params, self.camera,
                            *self.paths.args, *self.rays[0].args)

    def intersect(self, rays, n):
        self.program.launch("intersect", n, self.params, np.int32(n), *rays.args,
                            self.nodes, self.prims, self.materials)

    def gpis_free_flight(self, rays, n):
        """Moves hits to the first GPIS crossing before them (the path's realization)."""
        if self.weight_space:
            self.program.launch("gpis_weight_space", n, self.params, np.int32(n),
                                *self.paths.args, *rays.args, self.gpis_objects,
                                *self.gpis_model, self.counters)
        if self.function_space:
            self.function_space.free_flight(self.params, self.paths, rays, n, self.gpis_objects,
                                            *self.gpis_model[:2], self.counters)

    def gpis_shadow(self, n):
        """Blocks shadow rays that cross a GPIS object of the path's realization."""
        if self.weight_space:
            self.program.launch("gpis_shadow_weight_space", n, self.params, *self.paths.args,
                                *self.shadow.args, self.gpis_objects, *self.gpis_model,
                                self.counters)
        if self.function_space:
            self.function_space.shadow(self.params, self.paths, self.shadow, n, self.gpis_objects,
                                       *self.gpis_model[:2], self.counters)

    def queue_hits(self, rays, n):
        self.program.launch("queue_hits", n, np.int32(n), *rays.args, *self.hits.args,
                            *self.escaped.args, self.counters)

    def escaped_rays(self, rays, n):
        self.program.launch("escaped_rays", n, self.params, *self.paths.args, *rays.args,
                            *self.escaped.args, self.counters, self.lights, *self.env)

    def emission(self, rays, n):
        self.program.launch("emission", n, self.params, *self.paths.args, *rays.args,
                            *self.hits.args, self.counters, self.prims, self.lights,
                            self.gpis_objects, self.gpis_model[1])

    def scatter(self, rays, out, n):
        self.program.launch("scatter", n, self.params, *self.paths.args, *rays.args,
                            *out.args, *self.hits.args, *self.shadow.args, self.counters,
                            self.prims, self.materials, self.lights, *self.env, self.gpis_objects,
                            self.gpis_model[1])

    def shadow_rays(self, n):
        self.program.launch("shadow_rays", n, self.params, *self.paths.args,
                            *self.shadow.args, self.counters, self.nodes, self.prims,
                            self.materials)

    def accumulate(self):
        self.program.launch("accumulate", self.num_pixels, self.params, *self.paths.args,
                            self.counters, *self.film.args)

    # --- the loop -------------------------------------------------------------------

    def render_batch(self, sample_base: int, path_base: int, num_paths: int):
        """Trace paths path_base .. path_base+num_paths-1 of samples from sample_base."""
        queue = self.device.queue
        self._upload_params(sample_base=sample_base, path_base=path_base,
                            num_paths=num_paths, bounce=0)
        self.generate_camera_rays(num_paths)
        n, cur, nxt = num_paths, self.rays[0], self.rays[1]
        for bounce in range(self.max_iterations):
            cl.enqueue_fill_buffer(queue, self.counters, np.int32(0), 0, 16)  # per-bounce counters
            self._upload_params(bounce=bounce)
            self.intersect(cur, n)
            self.gpis_free_flight(cur, n)
            self.queue_hits(cur, n)
            self.escaped_rays(cur, n)
            self.emission(cur, n)
            self.scatter(cur, nxt, n)
            self.gpis_shadow(n)
            self.shadow_rays(n)
            cl.enqueue_copy(queue, self.counters_host, self.counters)
            self.stats.rays += n
            self.stats.shadow_rays += int(self.counters_host[layouts.COUNTERS["shadow"]])
            n = int(self.counters_host[layouts.COUNTERS["rays_out"]])
            cur, nxt = nxt, cur
            if n == 0:
                break
        else:
            self.stats.truncated_paths += n
        self.accumulate()
        self.stats.paths += num_paths

    def render(self, spp: int, time_limit: float | None = None, progress=None) -> RenderResult:
        """Render spp samples per pixel (fewer if time_limit or Ctrl-C stops it early)."""
        start = time.perf_counter()
        total = self.num_pixels * spp
        done = 0
        try:
            while done < total:
                n = min(self.batch, total - done)
                self.render_batch(done // self.num_pixels, done % self.num_pixels, n)
                done += n
                if progress is not None:
                    progress(n)
                # stop on time only once every pixel has at least one sample
                if (time_limit is not None and done >= self.num_pixels
                        and time.perf_counter() - start > time_limit):
                    break
        except KeyboardInterrupt:
            self.stats.interrupted = True
        self.device.queue.finish()
        cl.enqueue_copy(self.device.queue, self.counters_host, self.counters)
        count = lambda name: int(self.counters_host[layouts.COUNTERS[name]])
        self.stats.nan_paths = count("nan_paths")
        self.stats.killed_paths = count("killed")
        self.stats.gpis_failed = count("gpis_failed")
        self.stats.depth_cut_paths = count("depth_cut")
        self.stats.fs_flights = count("fs_flights")
        self.stats.fs_samples = count("fs_samples")
        self.stats.fs_evals = count("fs_evals")
        self.stats.seconds = time.perf_counter() - start
        self.stats.kernel_table = self.program.timings.table()
        return RenderResult(self.film.read(), self.stats)
