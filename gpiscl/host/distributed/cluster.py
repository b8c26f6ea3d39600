"""render and uq on a Dask cluster (dask.distributed), bit-identical to a local render.

Work units are contiguous ranges of the local render's own order: paths for render (path p
is sample p // pixels of pixel p % pixels, the order WavefrontIntegrator.render traces
them in) and realizations for uq. Why the image is the local one bit for bit, for any
worker count and completion order:

  render  a worker traces its range with render_batch, as the local loop does, and sends
          back each path's float32 radiance: exactly what the film receives. The client adds
          the units to its own film in unit order with the accumulate kernel itself
          (WavefrontIntegrator.accumulate_paths), so every pixel gets the same double
          additions in the same order as locally. Merging partial film sums would not do:
          a sum of partial sums rounds differently from the sequential sum.
  uq      a worker renders each realization of its range as render_realizations does and
          sends back its mean and within-realization variance; the client merges them one
          realization at a time in realization order: the local loop's merge sequence.

Units finishing out of order wait until every unit before them is merged (InOrder), and a
unit is merged once however often it ran. The scene is sent once: its resolved data and
the bytes of every file it reads, so workers need no shared file system; each worker
process compiles it and builds its programs once and keeps them (WorkerScene). A unit
whose worker dies is rescheduled by Dask; Ctrl-C (stop()), a time limit or a lost
scheduler end the run with the units merged so far.

Imported only for --cluster / cluster=: without them Dask is never imported.
"""
from __future__ import annotations

import atexit
import hashlib
import json
import logging
import os
import re
import shutil
import signal
import tempfile
import threading
import time
import uuid
import warnings
from collections import OrderedDict, defaultdict
from concurrent.futures import CancelledError
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..errors import API_SOURCE, SceneError

try:
    from distributed import Client, KilledWorker, LocalCluster, get_worker, wait
except ImportError:   # an optional extra: say how to get it, in one line
    raise SceneError("<install>", "cluster", "rendering on a cluster needs Dask: "
                     "pip install 'gpiscl[distributed]'") from None
from ..io.output_files import scene_inputs
from ..render.batching import BatchSizer
from ..render.device import shared_device
from ..render.device_bakes import DeviceBakes
from ..render.integrator import RenderResult, RenderStats, WavefrontIntegrator
from ..scene.loading import Scene
from ..compile.scene import compile_scene
from ..uq.files import run_meta
from ..uq.realizations import UqRun, prepare_realizations, render_realization
from ..uq.sums import UqSums, iter_realizations

CONNECT_TIMEOUT = 3         # s: a wrong address is a prompt one-line error, not a hang
UNIT_SECONDS = 2.0          # per unit: long next to Dask's per-task overhead (~ms), short
                            # enough that progress moves, a stop acts and a lost worker
                            # costs little
FIRST_UNIT_PATHS = 4096     # units grow from here as BatchSizer measures them
MAX_UNIT_BYTES = 64 << 20   # of a unit's result (radiance or realization images)
IN_FLIGHT_PER_WORKER = 2    # units queued per worker: it starts the next one at once
POLL_SECONDS = 0.2          # how often stop(), the time limit and the scheduler are checked
LOCAL = re.compile(r"local:(\d+)")


# ---- connecting -------------------------------------------------------------------------

def max_local_workers() -> int:
    """The most local:N workers: one per CPU this process may use (at least 4, so that a
    small machine can still test the units' merge order). Each worker is a process with
    its own OpenCL runtime (docs/design/startup.md, 'Drivers') whose kernels already spread
    over every core, so more only compete for the cores and memory."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return max(4, cpus)


def local_workers(cluster, source: str, key: str):
    """N of a 'local:N' cluster (None for anything else), checked: SceneError naming key
    for N outside [1, max_local_workers()]. Called before any work (api.py) and again
    when connecting."""
    if isinstance(cluster, Client):
        return None
    spec = str(cluster).strip()
    local = LOCAL.fullmatch(spec)
    if not local:
        return None
    n, most = int(local.group(1)), max_local_workers()
    if not 1 <= n <= most:
        raise SceneError(source, key, f"local:N needs 1 <= N <= {most}, the CPUs this "
                         f"process may use (got {spec!r}): each worker is a process with "
                         "its own OpenCL runtime")
    return n


@contextmanager
def connect(cluster, source: str, key: str):
    """A Client for cluster: a Client (used as is), 'local:N' (a LocalCluster of N
    single-threaded worker processes for this run) or a scheduler address."""
    if isinstance(cluster, Client):
        yield cluster
        return
    spec = str(cluster).strip()
    n = local_workers(cluster, source, key)
    if n is not None:
        # one thread each: a worker process runs one unit at a time anyway (_LOCK), and
        # the OpenCL runtime spreads each kernel over the cores itself; the dashboard on
        # any free port (8787 may be another cluster's)
        lc = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                          dashboard_address=":0", preload=[__name__],
                          # its warnings are about units cancelled by a stop: expected
                          silence_logs=logging.ERROR)
        client = Client(lc)
        try:
            yield client
        finally:
            client.close()
            lc.close()
        return
    try:
        client = Client(spec, timeout=CONNECT_TIMEOUT)
    except Exception as exc:   # refused, timed out, not an address: all one line
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SceneError(source, key, f"cannot reach a Dask scheduler at {spec!r} "
                         f"({reason}); expected 'local:N' or an address such as "
                         "tcp://HOST:8786") from None
    with _quiet_client_log():     # closing a client that lost its scheduler logs too
        try:
            yield client
        finally:
            client.close()


@contextmanager
def _quiet_client_log():
    """A lost scheduler is reported in one line (ClusterStats.lost); the Client's own
    log of it is tracebacks of its reconnect attempt, so that log is muted meanwhile."""
    log = logging.getLogger("distributed.client")
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(level)


def dask_setup(worker):
    """Run by each local:N worker process as it starts (Dask's preload): Ctrl-C in the
    terminal reaches these processes too, and the client already owns it (it keeps the
    units merged and closes the cluster); without this each worker dies with a traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# ---- the scene, sent once -------------------------------------------------------------

@dataclass
class ScenePayload:
    """A resolved scene and the files it reads: all a worker needs."""
    data: dict          # resolved: every file path absolute (on the client)
    source: str
    files: dict         # client path -> bytes
    digest: str         # names the scene in each worker's cache

    @property
    def nbytes(self) -> int:
        return len(json.dumps(self.data)) + sum(len(b) for b in self.files.values())


def scene_payload(scene: Scene) -> ScenePayload:
    files = {}
    for path in scene_inputs(scene)[1:]:     # [0] is the scene file: its data is here
        with open(path, "rb") as f:
            files[path] = f.read()
    h = hashlib.sha256(json.dumps(scene.data, sort_keys=True).encode())
    for path in sorted(files):
        h.update(path.encode())
        h.update(files[path])
    return ScenePayload(scene.data, str(scene.source), files, h.hexdigest()[:16])


def _replace_paths(value, moved: dict):
    if isinstance(value, dict):
        return {k: _replace_paths(v, moved) for k, v in value.items()}
    if isinstance(value, list):
        return [_replace_paths(v, moved) for v in value]
    if isinstance(value, str):
        return moved.get(value, value)
    return value


class WorkerScene:
    """A scene in one worker process: its files written to a private folder, compiled
    once, and (for render) one integrator whose programs and queues serve every unit."""

    def __init__(self, payload: ScenePayload):
        self.dir = tempfile.mkdtemp(prefix="gpiscl-cluster-")
        moved = {}
        for i, (path, content) in enumerate(sorted(payload.files.items())):
            # a folder per file: two assets may share a base name
            local = os.path.join(self.dir, str(i), os.path.basename(path))
            os.makedirs(os.path.dirname(local))
            with open(local, "wb") as f:
                f.write(content)
            moved[path] = local
        self.data = _replace_paths(payload.data, moved)
        self.source = payload.source
        self.device = shared_device(None)    # PYOPENCL_CTX on the worker picks another
        self.compiled = compile_scene(self.data, self.source, DeviceBakes(self.device))
        self._integrator = None
        self.sizer = None

    def integrator(self, batch_size: int) -> WavefrontIntegrator:
        if self._integrator is None or self._integrator.batch > batch_size:
            self._integrator = WavefrontIntegrator(self.device, self.compiled,
                                                   self.data["render"], batch_size,
                                                   source=self.source)
            # kept across units, so batches are not relearnt from 64 paths every unit
            self.sizer = BatchSizer(self._integrator.batch)
        return self._integrator

    def close(self):
        shutil.rmtree(self.dir, ignore_errors=True)


_SCENES: "OrderedDict[str, WorkerScene]" = OrderedDict()
CACHED_SCENES = 2
# One unit at a time per process: units share the process's integrator, queues and
# device, and a `dask worker` has as many threads as cores unless told --nthreads 1.
_LOCK = threading.Lock()


def _worker_scene(payload: ScenePayload) -> WorkerScene:
    ws = _SCENES.get(payload.digest)
    if ws is None:
        ws = _SCENES[payload.digest] = WorkerScene(payload)
        while len(_SCENES) > CACHED_SCENES:
            _SCENES.popitem(last=False)[1].close()
    _SCENES.move_to_end(payload.digest)
    return ws


@atexit.register
def _remove_scene_files():
    for ws in _SCENES.values():
        ws.close()


def _worker_name() -> str:
    try:
        return get_worker().address
    except ValueError:     # not in a worker (a direct call)
        return f"pid {os.getpid()}"


# ---- units, run on the workers ------------------------------------------------------------

# every count of RenderStats a unit reports: the integrator's own, summed over units
COUNTED = ("paths", "rays", "shadow_rays", "truncated_paths", "fs_flights", "fs_samples",
           "fs_evals", *WavefrontIntegrator.DEVICE_TOTALS)


@dataclass
class UnitResult:
    """What a unit sends back. render: radiance (count, 3) float32 of paths start ..
    start+count-1. uq: ids, means and within variances of realizations start .. start+count-1
    (indices from the run's first)."""
    start: int
    count: int
    worker: str
    seconds: float
    counts: dict
    radiance: np.ndarray = None
    ids: list = None
    means: list = None
    within: list = None

    @property
    def nbytes(self) -> int:
        arrays = [self.radiance] if self.radiance is not None else self.means + self.within
        return sum(a.nbytes for a in arrays)


def _counts(integ: WavefrontIntegrator) -> dict:
    integ.read_counters()
    return {k: getattr(integ.stats, k) for k in COUNTED}


def render_unit(payload: ScenePayload, batch_size: int, start: int, count: int) -> UnitResult:
    """Trace paths start .. start+count-1 (global indices) and return their radiance."""
    with _LOCK:
        ws = _worker_scene(payload)
        integ = ws.integrator(batch_size)
        # after the set-up, paid once per process: the unit's rate sizes the next units
        t0 = time.perf_counter()
        before = _counts(integ)
        pixels = integ.num_pixels
        radiance = np.empty((count, 3), np.float32)
        done = 0
        while done < count:
            n = ws.sizer.next(count - done)
            p = start + done
            t = time.perf_counter()
            integ.render_batch(p // pixels, p % pixels, n)
            radiance[done:done + n] = integ.batch_radiance(n)[:, :3]
            ws.sizer.record(n, time.perf_counter() - t)
            done += n
        after = _counts(integ)
        return UnitResult(start, count, _worker_name(), time.perf_counter() - t0,
                          {k: after[k] - before[k] for k in COUNTED}, radiance=radiance)


def uq_unit(payload: ScenePayload, spp: int, seed: int, first: int, batch_size,
            start: int, count: int) -> UnitResult:
    """Render realizations first+start .. first+start+count-1 of the run."""
    with _LOCK:
        ws = _worker_scene(payload)
        t0 = time.perf_counter()
        ids, means, within = [], [], []
        counts = dict.fromkeys(COUNTED, 0)
        for rid, rseed in iter_realizations(seed, first + start, count):
            result = render_realization(ws.device, ws.compiled, ws.data, spp, rid, rseed,
                                        batch_size)
            sums = UqSums.from_film(result.image)
            ids.append(rid)
            means.append(sums.mean)
            within.append(sums.u)
            for k in COUNTED:
                counts[k] += getattr(result.stats, k)
        return UnitResult(start, count, _worker_name(), time.perf_counter() - t0, counts,
                          ids=ids, means=means, within=within)


# ---- the client: units out, results merged in order -----------------------------------------

class InOrder:
    """Calls merge(result) in unit index order whatever order units finish in; a unit that
    arrives again (a rescheduled unit whose first run also finished) is merged once."""

    def __init__(self, merge):
        self.merge = merge
        self.next = 0
        self.waiting = {}

    def add(self, index: int, result) -> None:
        if index < self.next or index in self.waiting:
            return
        self.waiting[index] = result
        while self.next in self.waiting:
            self.merge(self.waiting.pop(self.next))
            self.next += 1


class FilmMerge:
    """merge() for render units: adds a unit's paths to integrator's film with the
    accumulate kernel (at most one batch of paths per launch, as the local loop's batches)
    and its counts to stats."""

    def __init__(self, integrator: WavefrontIntegrator, stats: RenderStats, progress=None):
        self.integrator, self.stats, self.progress = integrator, stats, progress
        self.rgba = np.zeros((integrator.batch, 4), np.float32)

    def __call__(self, r: UnitResult) -> None:
        batch = self.integrator.batch
        for k in range(0, r.count, batch):
            chunk = r.radiance[k:k + batch]
            self.rgba[:len(chunk), :3] = chunk
            self.integrator.accumulate_paths(r.start + k, self.rgba[:len(chunk)])
        for name in COUNTED:
            setattr(self.stats, name, getattr(self.stats, name) + r.counts[name])
        self.stats.units += 1
        if self.progress is not None:
            self.progress(r.count)


class RealizationMerge:
    """merge() for uq units: each realization merged on its own, in order, from the
    numbers UqSums.from_film made on the worker (from_film is from_realization of them),
    so the sums go through the local loop's sequence of merges."""

    def __init__(self, shape, progress=None):
        self.sums = UqSums.empty(shape)
        self.ids, self.paths, self.progress = [], 0, progress

    def __call__(self, r: UnitResult) -> None:
        for rid, mean, within in zip(r.ids, r.means, r.within):
            self.sums = self.sums.merge(UqSums.from_realization(mean, within))
            self.ids.append(rid)
            if self.progress is not None:
                self.progress(1)
        self.paths += r.counts["paths"]


@dataclass
class WorkerLoad:
    units: int = 0
    paths: int = 0
    seconds: float = 0.0     # busy in units, on the worker


@dataclass
class Outcome:
    stopped: str = None      # None, "signal", "time limit" or why the cluster was lost
    lost: bool = False
    workers: dict = field(default_factory=lambda: defaultdict(WorkerLoad))
    units_done: int = 0      # finished, merged or not
    unit_bytes: int = 0      # of the results of the finished units

    def table(self) -> str:
        rows = [f"{'worker':<32}{'units':>8}{'paths':>14}{'busy [s]':>10}{'paths/s':>12}"]
        for name, w in sorted(self.workers.items()):
            rate = w.paths / w.seconds if w.seconds > 0 else 0.0
            rows.append(f"{name:<32}{w.units:>8}{w.paths:>14}{w.seconds:>10.2f}{rate:>12.4g}")
        return "\n".join(rows)


def run_units(client: Client, submit, total: int, sizer: BatchSizer, merger: InOrder,
              stop=None, time_limit: float | None = None) -> Outcome:
    """Cut [0, total) into units sized by sizer (items per second of worker time), keep
    IN_FLIGHT_PER_WORKER per worker queued, merge them in order; until done, stop(), the
    time limit, Ctrl-C or a lost scheduler. submit(index, start, count) -> Future."""
    out = Outcome()
    pending = {}
    issued = index = 0
    failed = None      # a unit's own error: raised as it is, after the cancelling
    t0 = time.perf_counter()
    try:
        while failed is None:
            if stop is not None and stop():
                out.stopped = "signal"
                break
            # as locally, a time limit keeps at least the first unit
            if (time_limit is not None and merger.next > 0
                    and time.perf_counter() - t0 >= time_limit):
                out.stopped = "time limit"
                break
            if client.status != "running":
                raise CancelledError("the client is no longer connected")
            if issued < total:
                slots = IN_FLIGHT_PER_WORKER * max(1, len(client.nthreads()))
                # units finished behind a late one wait in memory: at most slots of them
                # (the late one, rescheduled, runs first: the lowest index has the highest
                # priority)
                while issued < total and len(pending) < slots and len(merger.waiting) < slots:
                    n = sizer.next(total - issued)
                    pending[submit(index, issued, n)] = index
                    index, issued = index + 1, issued + n
            if not pending:
                break
            try:
                done, _ = wait(list(pending), timeout=POLL_SECONDS,
                               return_when="FIRST_COMPLETED")
            except TimeoutError:
                continue
            for fut in done:
                if fut.status == "error":
                    failed = fut.exception()
                    break
                result = fut.result()      # CancelledError when the scheduler is gone
                unit = pending.pop(fut)
                sizer.record(result.count, result.seconds)
                load = out.workers[result.worker]
                load.units += 1
                load.paths += result.counts["paths"]
                load.seconds += result.seconds
                out.units_done += 1
                out.unit_bytes += result.nbytes
                merger.add(unit, result)
    except KeyboardInterrupt:
        out.stopped = "signal"
    except (OSError, CancelledError) as exc:
        # every call above but a unit's own result talks to the scheduler: a closed
        # connection, a refused reconnect or futures cancelled by the Client all mean it
        # is gone
        out.stopped, out.lost = f"lost the scheduler ({type(exc).__name__})", True
    finally:
        if pending:
            try:
                client.cancel(list(pending))
            except Exception:   # the scheduler is gone: nothing left to cancel
                pass
    if isinstance(failed, KilledWorker):
        out.stopped, out.lost = f"a unit killed every worker it ran on ({failed})", True
    elif failed is not None:
        raise failed
    return out


def _unit_cap(bytes_per_item: int, cap: int | None) -> int:
    return max(1, min(cap or MAX_UNIT_BYTES // bytes_per_item,
                      MAX_UNIT_BYTES // bytes_per_item))


@dataclass
class ClusterStats(RenderStats):
    """RenderStats of a cluster render, with how the cluster did (per-worker throughput
    in kernel_table, which --stats prints)."""
    units: int = 0
    lost: str = None

    def summary(self) -> str:
        text = super().summary()
        if self.lost:
            text += f"\ncluster: {self.lost}; kept the {self.units} units merged before it"
        return text


def render_on_cluster(cluster, integrator: WavefrontIntegrator, scene: Scene, spp: int,
                      time_limit: float | None = None, progress=None, stop=None,
                      source: str = API_SOURCE, key: str = "cluster",
                      unit_paths: int | None = None) -> RenderResult:
    """integrator.render(spp, ...) with the paths traced on a Dask cluster: the same
    image, merged into integrator's film. unit_paths caps the paths per unit."""
    pixels, batch = integrator.num_pixels, integrator.batch
    stats = ClusterStats(pixels=pixels, spp_requested=spp)
    payload = scene_payload(scene)
    run = uuid.uuid4().hex[:8]
    with connect(cluster, source, key) as client:
        start = time.perf_counter()   # the rendering, not starting a local:N cluster
        scene_future = submit_scene(client, payload, run)
        cap = _unit_cap(12, unit_paths)
        sizer = BatchSizer(cap, UNIT_SECONDS, first=min(cap, FIRST_UNIT_PATHS))
        submit = lambda i, s, n: client.submit(render_unit, scene_future, batch, s, n,
                                               key=f"gpiscl-render-{run}-{i}", priority=-i)
        out = run_units(client, submit, pixels * spp, sizer,
                        InOrder(FilmMerge(integrator, stats, progress)), stop, time_limit)
        scene_future.release()
    if out.lost and stats.units == 0:
        raise SceneError(source, key, f"{out.stopped} before the first unit finished: "
                         "nothing rendered")
    integrator.device.queue.finish()
    stats.seconds = time.perf_counter() - start
    stats.batches = stats.units
    stats.interrupted = out.stopped is not None and out.stopped != "time limit"
    stats.time_limited = out.stopped == "time limit"
    stats.lost = out.stopped if out.lost else None
    stats.kernel_table = (f"per worker ({out.units_done} units, "
                          f"{out.unit_bytes / max(out.units_done, 1) / 1e6:.3g} MB back "
                          f"per unit, scene {payload.nbytes / 1e6:.3g} MB once per "
                          f"worker):\n{out.table()}\nmerging on the client:\n"
                          f"{integrator.program.timings.table()}")
    return RenderResult(integrator.film.read(), stats)


def uq_on_cluster(cluster, scene, realizations: int, spp: int, seed: int | None = None,
                  first: int = 0, resolution=None, batch_size=None, progress=None,
                  stop=None, source: str = API_SOURCE, key: str = "cluster",
                  unit_realizations: int | None = None) -> UqRun:
    """render_realizations(...) with the realizations rendered on a Dask cluster: the
    same sums. run.cluster is the Outcome (per-worker throughput)."""
    scene, data, seed = prepare_realizations(scene, realizations, spp, seed, first,
                                             resolution)
    w, h = data["camera"]["resolution"]
    payload = scene_payload(scene)
    run = uuid.uuid4().hex[:8]
    merged = RealizationMerge((h, w, 3), progress)
    with connect(cluster, source, key) as client:
        start = time.perf_counter()   # the rendering, not starting a local:N cluster
        scene_future = submit_scene(client, payload, run)
        cap = _unit_cap(2 * 3 * 8 * w * h, unit_realizations)
        sizer = BatchSizer(cap, UNIT_SECONDS, first=1)
        submit = lambda i, s, n: client.submit(uq_unit, scene_future, spp, seed, first,
                                               batch_size, s, n,
                                               key=f"gpiscl-uq-{run}-{i}", priority=-i)
        out = run_units(client, submit, realizations, sizer, InOrder(merged), stop)
        scene_future.release()
    result = UqRun(merged.sums, merged.ids, time.perf_counter() - start, merged.paths,
                   out.stopped is not None, run_meta(data, seed, spp, first, len(merged.ids)),
                   scene)
    result.cluster = out
    return result


def submit_scene(client: Client, payload: ScenePayload, run: str):
    """The scene as a task of its own, not scattered data: should every worker holding it
    die, the scheduler can make it again. Units take its future, so each worker receives
    it once."""
    with warnings.catch_warnings():
        # Dask warns of a large graph and advises not repeating data in it: this is the
        # one copy
        warnings.filterwarnings("ignore", message="Sending large graph")
        return client.submit(_identity, payload, key=f"gpiscl-scene-{run}")


def _identity(x):
    return x
