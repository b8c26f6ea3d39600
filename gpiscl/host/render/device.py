"""OpenCL device selection, the one program builder, and named, timed launches."""
from __future__ import annotations

import contextlib
import functools
import os
import sys
import tempfile
import threading
import time
import warnings
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from ..errors import DeviceError
from .program_sources import PYOPENCL_CL_DIR, join_sources

def list_devices():
    """(platform index, device index, platform, device) for every OpenCL device."""
    found = []
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return found
    for pi, plat in enumerate(platforms):
        for di, dev in enumerate(plat.get_devices()):
            found.append((pi, di, plat, dev))
    return found


def _pick(spec: str | None):
    devices = list_devices()
    if not devices:
        raise DeviceError("no OpenCL platform found; install the CPU runtime with "
                          "pip install 'pyopencl[pocl]'" + _drivers_limited())
    if spec:
        parts = spec.split(":")
        if ":" in spec and all(p.isdigit() for p in parts):
            if len(parts) != 2:
                raise DeviceError(f"--device {spec}: expected P:D, a platform and a device "
                                  "index (see: python -m gpiscl devices)")
            pi, di = (int(p) for p in parts)
            for p_i, d_i, _, dev in devices:
                if (p_i, d_i) == (pi, di):
                    return dev
            raise DeviceError(f"no OpenCL device {spec} (see: python -m gpiscl devices)")
        if spec.lower() in DEVICE_TYPES:   # the types `gpiscl devices` prints
            of_type = [d for _, _, _, d in devices if d.type & DEVICE_TYPES[spec.lower()]]
            if not of_type:
                raise DeviceError(f"no OpenCL device of type '{spec}' (see: python -m gpiscl "
                                  "devices)")
            return next((d for d in of_type if compiles(d)), of_type[0])
        for _, _, plat, dev in devices:
            if spec.lower() in f"{plat.name} {dev.name}".lower():
                return dev
        raise DeviceError(f"no OpenCL device matches '{spec}' (see: python -m gpiscl devices)")
    # PoCL's CPU device is the default. Several PoCLs may be installed (PyPI's, the
    # distribution's): take the first that can compile for this CPU. PyPI's PoCL 3.0 is
    # built on LLVM 14, which does not know CPUs newer than it (e.g. AMD Zen 5: "unknown
    # target CPU 'generic'") and fails on every program.
    pocls = [dev for _, _, plat, dev in devices
             if "portable computing language" in plat.name.lower()]
    for dev in pocls:
        if compiles(dev):
            return dev
    if pocls:
        raise DeviceError("no PoCL device here can compile for this CPU (PyPI's PoCL 3.0 "
                          "predates it); install the distribution's PoCL (Debian, Ubuntu: "
                          "apt-get install pocl-opencl-icd) or choose another --device"
                          + _drivers_limited())
    return devices[0][3]


DEVICE_TYPES = {"cpu": cl.device_type.CPU, "gpu": cl.device_type.GPU,
                "accelerator": cl.device_type.ACCELERATOR}


def _drivers_limited() -> str:
    """The clause that says OCL_ICD_VENDORS chose the drivers (gpiscl/opencl_vendors.py
    sets it to the system's when the system has a PoCL, leaving PyPI's out)."""
    chosen = os.environ.get("OCL_ICD_VENDORS")
    return f" (only the drivers in OCL_ICD_VENDORS={chosen} were loaded)" if chosen else ""


@functools.lru_cache(maxsize=None)
def compiles(dev) -> bool:
    """Whether a one-line program builds on dev (PoCL caches it: cheap after the first)."""
    try:
        cl.Program(cl.Context([dev]), "__kernel void probe(__global int *a) { a[0] = 1; }"
                   ).build()
        return True
    except (cl.Error, RuntimeError):
        return False


@dataclass
class Device:
    """A context and a profiling queue on one OpenCL device."""

    spec: str | None = None
    ctx: cl.Context = field(init=False)
    queue: cl.CommandQueue = field(init=False)
    device: cl.Device = field(init=False)

    def __post_init__(self):
        spec = self.spec
        if spec is None and os.environ.get("PYOPENCL_CTX"):
            spec = os.environ["PYOPENCL_CTX"]
        self.device = _pick(spec)
        self.ctx = cl.Context([self.device])
        self.queue = cl.CommandQueue(
            self.ctx, properties=cl.command_queue_properties.PROFILING_ENABLE)
        if not self.device.double_fp_config:
            raise DeviceError(f"device '{self.device.name}' lacks double precision, which "
                              "the film needs for batch-independent accumulation")

    @property
    def is_cpu(self) -> bool:
        """A CPU device: its memory is the process's, and it vectorises within work-items."""
        return bool(self.device.type & cl.device_type.CPU)

    @property
    def name(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"


@functools.lru_cache(maxsize=None)
def shared_device(spec: str | None = None) -> "Device":
    """One Device per spec for the Python API: the program cache below keeps every context
    it has built for alive, so a fresh context per render call would grow without bound."""
    return Device(spec)


WORK_GROUP = 64
# Built programs by (context, source, options): even a PoCL cache hit costs a noticeable
# build call (docs/design/startup.md, 'OpenCL builds'), paid by every integrator (one per
# UQ realization, one per test render) without this.
_BUILT: dict = {}


# A build the driver's cache answers is quick; one still running after this compiles
SLOW_COMPILE_SECONDS = 2.0
COMPILE_NOTICE = "compiling OpenCL programs (first run only)"
_notice = {"to": None, "said": False}   # announcing_compiles: where, and whether said


@contextlib.contextmanager
def announcing_compiles(file):
    """While on (file: a text stream; None: off), a compile that outlasts
    SLOW_COMPILE_SECONDS prints COMPILE_NOTICE to file, once per process: a cold start is
    otherwise silent for a whole cold compile (docs/design/startup.md, 'OpenCL builds').
    The command line turns it on, the API only with progress."""
    previous, _notice["to"] = _notice["to"], file
    try:
        yield
    finally:
        _notice["to"] = previous


@contextlib.contextmanager
def slow_compile_notice(fd: int | None = None):
    """Around a build or a program's first launches: COMPILE_NOTICE once they outlast
    SLOW_COMPILE_SECONDS (the drivers' caches answer well within it). fd: the stderr to
    write to while file descriptor 2 is redirected (build_quietly)."""
    file = _notice["to"]
    if file is None or _notice["said"]:
        yield
        return

    def say():
        _notice["said"] = True
        if fd is None:
            print(COMPILE_NOTICE, file=file, flush=True)
        else:
            os.write(fd, (COMPILE_NOTICE + "\n").encode())

    timer = threading.Timer(SLOW_COMPILE_SECONDS, say)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        timer.join()


def build_quietly(device: Device, source: str, opts) -> cl.Program:
    """Builds source; a non-empty build log (clang's notes on vector types a CPU lacks, say)
    is not printed: pyopencl would warn (CompilerWarning) on every run. With
    GPISCL_BUILD_LOG=1 the log goes to a temporary file named on stderr."""
    with warnings.catch_warnings(), tempfile.TemporaryFile("w+") as driver_says:
        warnings.simplefilter("ignore", cl.CompilerWarning)
        with _stderr_into(driver_says) as stderr, slow_compile_notice(stderr):
            prg = cl.Program(device.ctx, source).build(options=opts)
        driver_says.seek(0)
        said = driver_says.read().strip()
    log = prg.get_build_info(device.device, cl.program_build_info.LOG).strip()
    if (log or said) and os.environ.get("GPISCL_BUILD_LOG"):
        _save_build_log("\n".join(filter(None, (log, said))))
    return prg


@contextlib.contextmanager
def _stderr_into(file):
    """PoCL's clang writes its summary ("47 warnings generated.") to file descriptor 2
    itself, past Python's sys.stderr: point the descriptor at `file` meanwhile."""
    sys.stderr.flush()
    saved = os.dup(2)
    os.dup2(file.fileno(), 2)
    try:
        yield saved   # the real stderr, meanwhile
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _save_build_log(log: str):
    fd, path = tempfile.mkstemp(prefix="gpiscl-build-", suffix=".log")
    with os.fdopen(fd, "w") as f:
        f.write(log + "\n")
    print(f"gpiscl: OpenCL build log ({len(log.splitlines())} lines) in {path}",
          file=sys.stderr)


class Program:
    """Builds one program once and hands out its kernels, each launch named and timed."""

    def __init__(self, device: Device, stage_files, defines: dict | None = None,
                 extra_headers=(), extra_c=""):
        self.device = device
        self.source = join_sources(stage_files, extra_headers, extra_c)
        opts = [f"-I{PYOPENCL_CL_DIR}"]
        opts += [f"-D{k}={v}" for k, v in sorted((defines or {}).items())]
        self.options = opts
        key = (device.ctx.int_ptr, self.source, tuple(opts))
        if key not in _BUILT:
            _BUILT[key] = self._build(device, opts)
        self.kernels = _BUILT[key]
        self.timings = KernelTimings()

    def _build(self, device: Device, opts) -> dict:
        try:
            prg = build_quietly(device, self.source, opts)
        except cl.Error as exc:
            fd, path = tempfile.mkstemp(prefix="gpiscl-build-", suffix=".cl")
            with os.fdopen(fd, "w") as f:
                f.write(self.source)
            raise DeviceError(f"OpenCL build failed on '{device.name}' with options "
                              f"{' '.join(opts)}; source saved to {path}:\n{exc}") from None
        kernels = {k.function_name: k for k in prg.all_kernels()}
        if not kernels:
            # PyPI's PoCL 3.0-rc2 does this on this project's programs on CPUs newer than
            # its LLVM (docs/design/startup.md, 'Drivers'): a build that "succeeds" with
            # no kernels, which would otherwise end in a KeyError at the first launch
            raise DeviceError(f"the OpenCL build on '{device.name}' returned no kernels (a "
                              "fault of this OpenCL driver); install the distribution's PoCL "
                              "(Debian, Ubuntu: apt-get install pocl-opencl-icd) or choose "
                              "another --device" + _drivers_limited())
        return kernels

    def enqueue(self, name: str, global_size: int, args, local: int | None = None,
                max_items: int | None = None):
        """Enqueue kernel `name` over global_size items (timed under its name) with the
        arguments in kernel order (render/launch.py orders and checks them); returns the
        event. max_items: launch at most this many work items (a multiple of local), for
        kernels whose items stride over the rest."""
        if global_size <= 0:
            return None
        kernel = self.kernels[name]
        kernel.set_args(*args)
        # One fixed work-group size: PoCL compiles a work-group function per local size,
        # so letting it pick one per global size recompiles big kernels every bounce
        # (seconds each). Kernels bound-check their index, so padding is harmless.
        local = local or min(WORK_GROUP, self.device.device.max_work_group_size)
        padded = -(-int(global_size) // local) * local
        if max_items is not None:
            padded = min(padded, max_items)
        event = cl.enqueue_nd_range_kernel(self.device.queue, kernel, (padded,), (local,))
        self.timings.record(name, int(global_size), event)
        return event


class KernelTimings:
    """Per-kernel device time from profiling events, resolved lazily."""

    def __init__(self):
        self.pending = []
        self.seconds = defaultdict(float)
        self.items = defaultdict(int)
        self.launches = defaultdict(int)
        self.wall_start = time.perf_counter()

    def record(self, name, items, event):
        self.pending.append((name, items, event))
        if len(self.pending) > 4096:
            self.resolve()

    def resolve(self):
        for name, items, event in self.pending:
            event.wait()
            self.seconds[name] += (event.profile.end - event.profile.start) * 1e-9
            self.items[name] += items
            self.launches[name] += 1
        self.pending.clear()

    def table(self) -> str:
        self.resolve()
        rows = [f"{'kernel':<24}{'launches':>10}{'time [s]':>12}{'items':>14}{'items/s':>14}"]
        for name in sorted(self.seconds, key=self.seconds.get, reverse=True):
            s, n = self.seconds[name], self.items[name]
            rate = n / s if s > 0 else float("inf")
            rows.append(f"{name:<24}{self.launches[name]:>10}{s:>12.4f}{n:>14}{rate:>14.3e}")
        total = sum(self.seconds.values())
        rows.append(f"{'total':<24}{'':>10}{total:>12.4f}")
        return "\n".join(rows)


def to_device(device: Device, array: np.ndarray, writable=False) -> cl.Buffer:
    """Upload an array (a 1-element dummy for empty arrays, which OpenCL cannot hold).

    A read-only buffer on a CPU device uses the array's own memory when it is aligned as
    the device aligns its buffers (USE_HOST_PTR; the buffer keeps the array alive): a copy
    would be the same RAM twice, e.g. the knob's grid records, which the compiler
    allocates page-aligned for this (docs/design/memory-budget.md, 'Host copies'). The
    array must then not change while the buffer lives, which holds for the compiled
    scene's arrays.
    Unaligned arrays (vector loads would straddle cache lines) and GPUs get a copy."""
    mf = cl.mem_flags
    if array.size == 0:
        array = np.zeros(1, dtype=array.dtype)
    array = np.ascontiguousarray(array)
    align = max(int(device.device.mem_base_addr_align) // 8, 16)
    if not writable and device.is_cpu and array.ctypes.data % align == 0:
        return cl.Buffer(device.ctx, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=array)
    flags = (mf.READ_WRITE if writable else mf.READ_ONLY) | mf.COPY_HOST_PTR
    return cl.Buffer(device.ctx, flags, hostbuf=array)
