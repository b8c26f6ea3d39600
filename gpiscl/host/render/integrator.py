"""The wavefront path tracer: one host method per stage, one named kernel per stage
(layout/stages.py declares each kernel's parameters; launches pass them by name).

The host reads one counter per bounce (how many rays continue), both to stop and to
size the next launches; all other counts stay on the device.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from . import function_space_stages
from . import kriging_cache, memory
from .occupancy_boxes import occupancy_cells
from ..layout import records as layouts
from ..layout.constants import WS_MAX_LANES
from ..layout import stages
from .batching import BatchSizer, PixelCosts
from .device import Device, Program, slow_compile_notice, to_device
from .film import Film, FilmImage
from .launch import launch
from .program_sources import GPIS_HEADERS, STAGE_FILES
from .queues import DeviceQueue
from ..compile.scene import CompiledScene

# The most paths in flight unless asked otherwise (queue memory, ~440 bytes a path, ~560
# with function space's vertex records). On a CPU the queues are the process's own memory
# and every touched page stays resident, so the cap is the smallest batch that keeps the
# cores as busy as larger ones (docs/design/batches.md has the measurements).
DEFAULT_BATCH, CPU_DEFAULT_BATCH = 1 << 18, 1 << 14


# Renders that a batch of at least TRUSTED_SECONDS says need more than COSTS_AFTER_SECONDS
# size their batches by what their pixels cost too (batching.PixelCosts; shorter ones, like
# most uq realizations, are a few batches anyway), probing at most PROBES_PER_BATCH paths
# ahead. A shorter batch's rate is its launches' overhead: judged by the first 64 paths,
# short renders probed and shrank their way to several times their length.
COSTS_AFTER_SECONDS, PROBES_PER_BATCH, PATHS_PER_PROBE, PROBE_SHARE = 2.0, 32, 4, 0.1
TRUSTED_SECONDS = 0.1
# ... and only where paths are dear (below COSTLY_RATE paths/s, far below the example
# scenes' rates), where its probes and smaller batches cost less than they save
# (docs/design/batches.md, 'When cost-per-pixel sizing is on')
COSTLY_RATE = 5000.0

# The relative threshold of the roulette on shadow rays whose light sample picked the
# normal at a function-space mirror or conductor (fs_random_normal.h): measured in
# docs/design/light-sampling.md, "fs_mirror_ball_sun's paths/s".
SHADOW_ROULETTE = 0.1


# PATH_STATE's first-hit fields (aov.py): one element each when no AOV is asked for, as
# every kernel's access is guarded by params->aov
AOV_FIELDS = ("aov_position", "aov_normal", "aov_albedo")


def default_batch(device: Device) -> int:
    return CPU_DEFAULT_BATCH if device.is_cpu else DEFAULT_BATCH


def ws_defines(device: Device) -> dict:
    """Weight-space features run WS_LANES per work-item in vector types: what makes the
    feature loop SIMD on CPU runtimes; GPUs vectorise across work-items instead."""
    # the native float width: faster than 8 lanes on a 16-wide CPU (docs/design/batches.md)
    lanes = min(WS_MAX_LANES, max(1, device.device.native_vector_width_float))
    return {"WS_LANES": lanes if device.is_cpu else 1}


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
    gpis_failed: int = 0       # GPIS flights that failed: undecided root, capped track (no hit)
    depth_cut_paths: int = 0   # paths that would have scattered again but reached max_depth
    fs_flights: int = 0        # function space: free flights through one object
    fs_samples: int = 0        # ... GP values they drew, and step-rule moment evaluations
    fs_evals: int = 0
    seconds: float = 0.0
    interrupted: bool = False
    time_limited: bool = False   # stopped by the time limit
    spp_requested: int = 0
    batches: int = 0
    pixels: int = 0
    kernel_table: str = ""

    @property
    def spp_reached(self) -> float:
        """Samples per pixel rendered, as a fraction: paths run in pixel order, so every
        pixel has the floor or the ceiling of it."""
        return 0.0 if not self.pixels else self.paths / self.pixels

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
                         f"{self.gpis_failed} failed GPIS flights (an undecided root search "
                         "or a classical medium's capped track)")
        return "\n".join(lines)


@dataclass
class RenderResult:
    """image: the film (mean, stderr, per-pixel count); stats: how the render went; scene:
    the resolved Scene rendered (set by the API, so write_image can record it)."""
    image: FilmImage
    stats: RenderStats = field(default_factory=RenderStats)
    scene: object = None
    aovs: tuple = ()   # the AOVs asked for (aov.py); their sums are image.aov


class WavefrontIntegrator:
    def __init__(self, device: Device, scene: CompiledScene, settings: dict,
                 batch_size: int | None = None, max_memory: int | None = None,
                 source: str = "<scene>", aov: bool = False):
        self.device, self.scene, self.settings = device, scene, settings
        ctx = device.ctx
        self.width, self.height = scene.resolution
        self.num_pixels = self.width * self.height
        # the most paths per batch: batches are sized in time below it (batching.py), and
        # no larger than the whole render, so the queues are sized to the work
        self.batch = int(batch_size or settings.get("batch_size") or default_batch(device))
        self.batch = max(1, min(self.batch, self.num_pixels * int(settings.get("spp", 1))))
        # before any allocation: the film must fit, and the batch shrinks to fit beside it
        # a hit's shadow records: its light sample's, and a manifold NEE sample's two
        # segments where the scene has mirror spheres and area lights (lib/caustics.h);
        # not a scene key: caustic_nee off is the baseline of tests/test_caustics.py
        caustics = (len(scene.caustic_spheres) if settings.get("nee", True)
                    and settings.get("caustic_nee", True) else 0)
        self.shadow_per_hit = 3 if caustics else 1
        self.batch = memory.plan(device, self.num_pixels, self.batch, max_memory, source,
                                 aov=aov, shadow_per_path=self.shadow_per_hit)
        self.program = stage_program(device)
        # the scene's buffers, by the kernels' parameter names
        arrays = scene.device_arrays()
        self.scene_buffers = {name: to_device(device, array) for name, array in arrays.items()}
        gpis = scene.gpis
        # the occupancy clip's boxes and cells, found with the uploaded mean programs (the
        # compiled scene's own records stay as they are)
        records, cells = self.gpis_occupancy_boxes(arrays[stages.GPIS.name])
        self.scene_buffers[stages.GPIS.name] = to_device(device, records)
        self.scene_buffers[stages.GPIS_TABLES[-1].name] = to_device(device, cells)
        self.weight_space = gpis.uses("weight_space")
        if self.weight_space:   # a posterior's kept weights fit their budget
            self.batch = min(self.batch, kriging_cache.max_batch(gpis.objects, device))
        self.function_space = None
        if gpis.uses("function_space"):
            self.batch = min(self.batch, function_space_stages.max_batch(gpis, device))
            self.function_space = function_space_stages.FunctionSpaceStages(
                device, gpis, self.batch, self.program.timings)
        self.paths = None     # the work queues: _allocate_work, release_work
        # not a scene key: off, every ray solves for its posterior weights (the baseline
        # of tests/test_kriging_cache.py). Kept across release_work: its tags are zeroed
        # once, its slots stay valid (keyed by realization) and a batch touches only its paths'.
        self.kriging = kriging_cache.KrigingCache(device, gpis.objects, self.batch,
                                                  settings.get("kriging_cache", True))
        self.counters_host = np.zeros(layouts.NUM_COUNTERS, np.int32)
        self.counters = to_device(device, self.counters_host, writable=True)
        self.params_host = layouts.RENDER_PARAMS.zeros(1)
        self.params = cl.Buffer(ctx, cl.mem_flags.READ_ONLY, self.params_host.nbytes)
        self.film = Film(ctx, device.queue, self.width, self.height, aov=aov)
        # what every launch may take besides its queues (_launch picks what a stage names)
        self.render_arguments = {**self.scene_buffers, "params": self.params,
                                 "counters": self.counters, "post": self.kriging.arguments,
                                 "film": self.film.arguments}
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
        p["aov"] = 1 if aov else 0
        # not a scene key: the baseline of tools/bench_mirror_nee.py
        p["fs_nee"] = 1 if settings.get("fs_nee", True) else 0
        # not a scene key: 0 turns the shadow rays' roulette off (tools/bench_light_sampling.py)
        p["shadow_roulette"] = settings.get("shadow_roulette", SHADOW_ROULETTE)
        p["num_caustic_spheres"] = caustics
        # null surfaces do not count as bounces, so allow extra iterations for them
        self.max_iterations = 4 * settings["max_depth"] + 64
        self.stats = RenderStats(pixels=self.num_pixels)

    # --- the work queues of one batch ------------------------------------------------

    def _allocate_work(self) -> None:
        """The queues, sized for one batch (allocated on first use after release_work)."""
        if self.paths is not None:
            return
        ctx, cap = self.device.ctx, self.batch
        # the first-hit AOV fields are written and read only when params.aov is set
        unused = () if self.params_host[0]["aov"] else AOV_FIELDS
        self.paths = DeviceQueue(ctx, layouts.PATH_STATE, cap, unused)
        self.rays = [DeviceQueue(ctx, layouts.RAY_QUEUE, cap) for _ in range(2)]
        self.hits = DeviceQueue(ctx, layouts.INDEX_QUEUE, cap)
        self.escaped = DeviceQueue(ctx, layouts.INDEX_QUEUE, cap)
        self.shadow = DeviceQueue(ctx, layouts.SHADOW_QUEUE, cap * self.shadow_per_hit)

    def release_work(self) -> None:
        """Free the queues and the function-space stages' per-batch buffers: render()
        does it before reading the film, so the film's host copies and the output files'
        buffers do not come on top of them (on a CPU device they are the process's own
        memory, and every example scene's peak came at the end: docs/design/memory-budget.md,
        'Host peaks')."""
        if self.paths is not None:
            for queue in (self.paths, *self.rays, self.hits, self.escaped, self.shadow):
                queue.release()
            self.paths = self.rays = self.hits = self.escaped = self.shadow = None
        if self.function_space is not None:
            self.function_space.release()
        memory.return_freed_pages()

    # --- one method per stage -------------------------------------------------------

    def _upload_params(self, **values):
        for k, v in values.items():
            self.params_host[0][k] = v
        cl.enqueue_copy(self.device.queue, self.params, self.params_host)

    def _stage_arguments(self, stage: stages.Stage) -> dict:
        """The render-wide arguments `stage` takes (params, counters, scene buffers ...)."""
        return {k: v for k, v in self.render_arguments.items() if k in stage.host_names}

    def _launch(self, stage: stages.Stage, n: int, **queues):
        launch(self.program, stage, n, **self._stage_arguments(stage), **queues)

    def gpis_occupancy_boxes(self, objects):
        """(records, cell masks): occupancy_boxes.occupancy_cells of the GPIS records."""
        return occupancy_cells(self.program, self.scene_buffers, objects)

    def generate_camera_rays(self, n):
        self._launch(stages.GENERATE_CAMERA_RAYS, n, path=self.paths, out=self.rays[0])

    def intersect(self, rays, n):
        self._launch(stages.INTERSECT, n, num_rays=np.int32(n), in_=rays)

    def gpis_weight_space(self, rays, n):
        """Moves hits to the first weight-space GPIS crossing before them (the path's
        realization)."""
        self._launch(stages.GPIS_WEIGHT_SPACE, n, num_rays=np.int32(n), path=self.paths,
                     in_=rays)

    def gpis_function_space(self, rays, n):
        """Moves hits to the first function-space GPIS crossing before them."""
        self.function_space.gpis_function_space(
            n, **self._stage_arguments(stages.GPIS_FUNCTION_SPACE), path=self.paths, in_=rays)

    def queue_hits(self, rays, n):
        self._launch(stages.QUEUE_HITS, n, num_rays=np.int32(n), in_=rays, hits=self.hits,
                     escaped=self.escaped)

    def escaped_rays(self, rays, n):
        self._launch(stages.ESCAPED_RAYS, n, path=self.paths, in_=rays, escaped=self.escaped)

    def emission(self, rays, n):
        self._launch(stages.EMISSION, n, path=self.paths, in_=rays, hits=self.hits)

    def scatter(self, rays, out, n):
        self._launch(stages.SCATTER, n, path=self.paths, in_=rays, out=out, hits=self.hits,
                     shadow=self.shadow)

    def gpis_shadow_weight_space(self, n):
        """Blocks shadow rays that cross a weight-space GPIS object of the path's
        realization."""
        self._launch(stages.GPIS_SHADOW_WEIGHT_SPACE, n, path=self.paths, shadow=self.shadow)

    def gpis_shadow_function_space(self, n):
        """Blocks shadow rays that cross a function-space GPIS object."""
        self.function_space.gpis_shadow_function_space(
            n, **self._stage_arguments(stages.GPIS_SHADOW_FUNCTION_SPACE), path=self.paths,
            shadow=self.shadow)

    def shadow_rays(self, n):
        self._launch(stages.SHADOW_RAYS, n, path=self.paths, shadow=self.shadow)

    def accumulate(self):
        self._launch(stages.ACCUMULATE, self.num_pixels, path=self.paths)

    def batch_radiance(self, n: int) -> np.ndarray:
        """(n, 4) float32: the radiance of the last batch's first n paths, as accumulate
        reads it (what a cluster worker sends back: distributed/cluster.py)."""
        out = np.empty((n, 4), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.paths.buffers["radiance"])
        return out

    def accumulate_paths(self, path_base: int, radiance: np.ndarray) -> None:
        """Add paths traced elsewhere to the film with the accumulate kernel itself, so the
        film's arithmetic is the local render's by construction: radiance (n, 4) float32 of
        paths path_base .. path_base+n-1 (global path indices, n <= self.batch)."""
        self._allocate_work()
        cl.enqueue_copy(self.device.queue, self.paths.buffers["radiance"],
                        np.ascontiguousarray(radiance, np.float32))
        self._upload_params(path_base=path_base % self.num_pixels, num_paths=len(radiance))
        self.accumulate()

    # --- the loop -------------------------------------------------------------------

    def render_batch(self, sample_base: int, path_base: int, num_paths: int,
                     stop=None, keep: bool = True) -> bool:
        """Trace paths path_base .. path_base+num_paths-1 of samples from sample_base.

        stop() is asked between bounces: True abandons the batch (nothing of it reaches the
        film) so a stop request waits for one bounce, not for the whole batch. keep=False
        traces the batch and drops it (a probe: _probe). Returns whether the batch was
        completed and accumulated.
        """
        queue = self.device.queue
        self._allocate_work()
        self._upload_params(sample_base=sample_base, path_base=path_base,
                            num_paths=num_paths, bounce=0)
        self.generate_camera_rays(num_paths)
        n, cur, nxt = num_paths, self.rays[0], self.rays[1]
        for bounce in range(self.max_iterations):
            cl.enqueue_fill_buffer(queue, self.counters, np.int32(0), 0, 16)  # queue sizes
            self._upload_params(bounce=bounce)
            self.intersect(cur, n)
            if self.weight_space:
                self.gpis_weight_space(cur, n)
            if self.function_space:
                self.gpis_function_space(cur, n)
            self.queue_hits(cur, n)
            self.escaped_rays(cur, n)
            self.emission(cur, n)
            self.scatter(cur, nxt, n)
            shadows = n * self.shadow_per_hit
            if self.weight_space:
                self.gpis_shadow_weight_space(shadows)
            if self.function_space:
                self.gpis_shadow_function_space(shadows)
            self.shadow_rays(shadows)
            cl.enqueue_copy(queue, self.counters_host, self.counters)
            self._sum_bounce_counters()
            self.stats.rays += n
            self.stats.shadow_rays += int(self.counters_host[layouts.COUNTERS["shadow"]])
            n = int(self.counters_host[layouts.COUNTERS["rays_out"]])
            cur, nxt = nxt, cur
            if n == 0:
                break
            if stop is not None and stop():
                return False
        else:
            self.stats.truncated_paths += n
        if not keep:
            queue.finish()
            return False
        self.accumulate()
        queue.finish()   # so the batch's time is measured whole, accumulate included
        self.stats.paths += num_paths
        self.stats.batches += 1
        return True

    # RenderStats fields read from device counters that count over the whole render
    DEVICE_TOTALS = {"nan_paths": "nan_paths", "killed_paths": "killed",
                     "gpis_failed": "gpis_failed", "depth_cut_paths": "depth_cut"}

    def _sum_bounce_counters(self):
        """Add the bounce's work counters (just copied to counters_host) into stats and
        zero them on the device (layouts.BOUNCE_SUMMED: int32 would wrap over a render)."""
        first = layouts.COUNTERS[layouts.BOUNCE_SUMMED[0]]
        for k, name in enumerate(layouts.BOUNCE_SUMMED):
            assert layouts.COUNTERS[name] == first + k   # one contiguous fill below
            setattr(self.stats, name, getattr(self.stats, name) + int(self.counters_host[first + k]))
        cl.enqueue_fill_buffer(self.device.queue, self.counters, np.int32(0), 4 * first,
                               4 * len(layouts.BOUNCE_SUMMED))

    def read_counters(self):
        """Bring the device's whole-render counters into stats (after the last batch)."""
        cl.enqueue_copy(self.device.queue, self.counters_host, self.counters)
        for stat, name in self.DEVICE_TOTALS.items():
            setattr(self.stats, stat, int(self.counters_host[layouts.COUNTERS[name]]))

    def _dropped(self, trace) -> float:
        """Seconds of trace(), whose batches reach neither the film nor the statistics:
        the counters the device sums over the render are put back as they were."""
        queue = self.device.queue
        saved_stats, saved = dataclasses.replace(self.stats), np.empty_like(self.counters_host)
        cl.enqueue_copy(queue, saved, self.counters)
        t0 = time.perf_counter()
        trace()
        seconds = time.perf_counter() - t0
        cl.enqueue_copy(queue, self.counters, saved)
        queue.finish()
        self.stats = saved_stats
        return seconds

    def _warm_up(self) -> None:
        """A path traced and dropped before the clock starts: PoCL compiles each kernel for
        its work-group size at its first launch (seconds, cold), which would count as
        rendering (docs/design/batches.md, 'Batches sized by what their pixels cost')."""
        with slow_compile_notice():
            self._dropped(lambda: self.render_batch(0, 0, 1, keep=False))

    def _shrunk(self, costs: PixelCosts, start: int, n: int) -> int:
        """n paths from path index start, fewer if the pixels they cover cost more than a
        batch's time (batching.PixelCosts). Where it covers pixels no batch has yet (the
        first pass), paths at up to PROBES_PER_BATCH points spread over it (one per
        PATHS_PER_PROBE, for PROBE_SHARE of a batch's time) are probed first, traced and
        dropped: sized from sky rows alone, a batch can land on the object and overrun."""
        n, spent = costs.limit(start, n), 0.0
        for k in range(PROBES_PER_BATCH):
            if k >= n // PATHS_PER_PROBE or spent >= PROBE_SHARE * costs.target:
                break   # the probes take a small share of the batch's paths and time
            pixel = costs.probe_point(start, n)
            if costs.known(pixel):
                continue
            seconds = self._dropped(lambda: self.render_batch(0, pixel, 1, keep=False))
            costs.probed(pixel, seconds)
            spent += seconds
            n = costs.limit(start, n)
        return n

    def render(self, spp: int, time_limit: float | None = None, progress=None,
               stop=None) -> RenderResult:
        """Render spp samples per pixel, fewer if time_limit (seconds), stop() or Ctrl-C
        ends it early.

        Batches are sized to take about batching.TARGET_SECONDS each (from a probe of the
        image's costs, batching.py), so progress(paths) is called about once a second or
        more (progress(0) once when the clock starts, after the programs' first-launch
        compiles), and stop() and the time limit are asked between bounces: both hold to
        within one bounce, except that the first batch always completes. Paths run in pixel
        order, so a render stopped during its first pass leaves the later pixels with no
        sample: their film count is 0 (see FilmImage.count).
        """
        if time_limit is not None and not (math.isfinite(time_limit) and time_limit > 0):
            raise ValueError(f"time_limit must be a finite number of seconds > 0 "
                             f"(got {time_limit})")
        total = self.num_pixels * spp
        self.stats.spp_requested = spp
        done, start = 0, time.perf_counter()
        try:
            self._warm_up()
            start = time.perf_counter()    # the render alone: not the compiles
            deadline = None if time_limit is None else start + time_limit
            if progress is not None:
                progress(0)
            sizer, costs = BatchSizer(self.batch), None

            def ended() -> bool:
                """A stop, or the time limit once there is an image to keep."""
                if stop is not None and stop():
                    return True
                return done > 0 and deadline is not None and time.perf_counter() >= deadline

            while done < total:
                if stop is not None and stop():
                    self.stats.interrupted = True
                    break
                left = None if deadline is None else deadline - time.perf_counter()
                n = sizer.next(total - done, left)
                if costs is not None and n > 0 and done < self.num_pixels:
                    # the first pass, where a pixel's cost is not yet known to the
                    # sizer's rates; later passes keep the rates it learnt there
                    n = self._shrunk(costs, done, n)
                # the first batch always runs: a limit shorter than one batch still gives
                # an image
                if done and (n == 0 or (left is not None and left <= 0)):
                    self.stats.time_limited = True
                    break
                t0 = time.perf_counter()
                if not self.render_batch(done // self.num_pixels, done % self.num_pixels, n,
                                         ended):
                    if stop is not None and stop():
                        self.stats.interrupted = True
                    else:
                        self.stats.time_limited = True
                    break
                seconds = time.perf_counter() - t0
                sizer.record(n, seconds)
                if costs is None and seconds >= TRUSTED_SECONDS and sizer.rate < COSTLY_RATE \
                        and (total - done - n) / sizer.rate > COSTS_AFTER_SECONDS:
                    costs = PixelCosts(self.num_pixels)   # a long render
                if costs is not None:
                    costs.record(done, n, seconds)
                done += n
                if progress is not None:
                    progress(n)
        except KeyboardInterrupt:
            self.stats.interrupted = True
        self.device.queue.finish()
        self.read_counters()
        self.stats.seconds = time.perf_counter() - start
        self.stats.kernel_table = self.program.timings.table()
        self.release_work()
        return RenderResult(self.film.read(), self.stats)
