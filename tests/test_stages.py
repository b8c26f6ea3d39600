"""Each kernel's parameters are declared once (layout/stages.py): the device's own account of
every built kernel matches its Stage, and a launch with a wrong argument fails naming the
kernel and the parameter before it reaches OpenCL."""
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest

from gpiscl import load_scene
from gpiscl.host.compile.scene import compile_scene
from gpiscl.host.layout import records, stages
from gpiscl.host.render.device import to_device
from gpiscl.host.render.device_bakes import DeviceBakes
from gpiscl.host.render.function_space_stages import FunctionSpaceStages
from gpiscl.host.render.integrator import WavefrontIntegrator, stage_program
from gpiscl.host.render.launch import LaunchError, launch
from gpiscl.host.render.program_sources import BAKE_FILES, FS_STAGE_FILES, STAGE_FILES
from gpiscl.host.render.queues import DeviceQueue

ROOT = Path(__file__).resolve().parent.parent
BY_NAME = {s.name: s for s in stages.STAGES}


def _programs(device) -> dict:
    """Every program the renderer builds: the stages, the function-space stages (built
    from a scene that uses them) and the bakes."""
    fs_scene = compile_scene(load_scene(ROOT / "scenes" / "fs_sphere_se.json").data)
    fs = FunctionSpaceStages(device, fs_scene.gpis, 64)
    return {"stages": stage_program(device), "function space": fs.program,
            "bakes": DeviceBakes(device).program}


def test_file_kernel_and_stage_share_one_name_and_integrator_stages_their_method():
    files = [f[:-3] for f in (*STAGE_FILES, *FS_STAGE_FILES, *BAKE_FILES)]
    assert sorted(files) == sorted(BY_NAME)
    for name in (*STAGE_FILES, *FS_STAGE_FILES):
        assert callable(getattr(WavefrontIntegrator, name[:-3], None)), name


def test_every_built_kernel_has_its_stages_argument_names_and_types(device):
    """Built with -cl-kernel-arg-info, each kernel reports its arguments: their count,
    names and types are the Stage's, and each Stage's kernel is built in one program."""
    built = {}
    for label, program in _programs(device).items():
        prg = cl.Program(device.ctx, program.source).build(
            options=program.options + ["-cl-kernel-arg-info"])
        for kernel in prg.all_kernels():
            assert kernel.function_name not in built, kernel.function_name
            built[kernel.function_name] = label
            stage = BY_NAME[kernel.function_name]
            info = cl.kernel_arg_info
            names = [kernel.get_arg_info(i, info.NAME) for i in range(kernel.num_args)]
            types = [kernel.get_arg_info(i, info.TYPE_NAME).replace(" ", "")
                     for i in range(kernel.num_args)]
            assert names == stage.c_names, stage.name
            assert types == [p.type_name for _, _, p, _ in stage.flat], stage.name
    assert sorted(built) == sorted(BY_NAME)


@pytest.fixture(scope="module")
def queue_hits_arguments(device):
    """A valid launch of queue_hits over one ray: every argument by name."""
    ctx = device.ctx
    rays = DeviceQueue(ctx, records.RAY_QUEUE, 1)
    cl.enqueue_fill_buffer(device.queue, rays["hit_prim"], np.int32(-1), 0, 4)
    counters = to_device(device, np.zeros(records.NUM_COUNTERS, np.int32), writable=True)
    return counters, dict(num_rays=np.int32(1), in_=rays,
                          hits=DeviceQueue(ctx, records.INDEX_QUEUE, 1),
                          escaped=DeviceQueue(ctx, records.INDEX_QUEUE, 1), counters=counters)


def test_a_launch_by_name_runs_the_kernel(device, queue_hits_arguments):
    counters, named = queue_hits_arguments
    program = stage_program(device)
    launch(program, stages.QUEUE_HITS, 1, **named)
    out = np.empty(records.NUM_COUNTERS, np.int32)
    cl.enqueue_copy(device.queue, out, counters)
    assert out[records.COUNTERS["escaped"]] == 1 and out[records.COUNTERS["hits"]] == 0


@pytest.mark.parametrize("change, parameter", [
    (dict(num_rays=np.float32(1)), "num_rays"),         # a float for an int
    (dict(num_rays=1), "num_rays"),                     # a Python int: which width?
    (dict(num_rays=np.int64(1)), "num_rays"),
    (dict(counters=np.int32(0)), "counters"),           # a scalar for a buffer
    (dict(num_rays=None), "num_rays"),                  # missing
    (dict(counters=None), "counters"),
    (dict(hits={}), "hits_ray"),                        # a queue without its buffer
    (dict(rays=np.int32(1)), "rays"),                   # unknown
    (dict(hits={"ray": None, "rank": None}), "hits_rank"),
], ids=["float", "python int", "int64", "scalar for buffer", "missing scalar",
        "missing buffer", "missing queue field", "unknown", "unknown queue field"])
def test_a_wrong_argument_is_an_error_naming_the_kernel_and_the_parameter(
        device, queue_hits_arguments, change, parameter):
    _, named = queue_hits_arguments
    named = {k: v for k, v in {**named, **change}.items() if v is not None}
    with pytest.raises(LaunchError, match=rf"kernel queue_hits: .*{parameter}"):
        launch(stage_program(device), stages.QUEUE_HITS, 1, **named)


def test_the_scene_hands_over_exactly_the_buffers_stages_name():
    """CompiledScene.device_arrays is keyed by parameter names that some stage takes."""
    scene = compile_scene(load_scene(ROOT / "scenes" / "ws_sphere_se.json").data)
    taken = {name for s in stages.STAGES for name in s.host_names}
    assert set(scene.device_arrays()) <= taken
    assert {"prims", "env_texels", "mean_nodes", "order_table"} <= set(scene.device_arrays())


def test_kernels_are_launched_only_through_stages():
    """No positional kernel argument list is left on the host: only the launcher calls
    Program.enqueue, and only Program.enqueue sets arguments and enqueues kernels."""
    host = ROOT / "gpiscl" / "host"
    found = {}
    for path in host.rglob("*.py"):
        text = path.read_text()
        for call in (".enqueue(", "set_args(", "enqueue_nd_range_kernel("):
            if call in text:
                found.setdefault(call, []).append(path.name)
    assert found == {".enqueue(": ["launch.py"], "set_args(": ["device.py"],
                     "enqueue_nd_range_kernel(": ["device.py"]}


def test_a_queue_of_another_layout_or_released_is_an_error(device, queue_hits_arguments):
    _, named = queue_hits_arguments
    rays = DeviceQueue(device.ctx, records.RAY_QUEUE, 1)
    with pytest.raises(LaunchError, match=r"kernel queue_hits: unknown .*hits_o"):
        launch(stage_program(device), stages.QUEUE_HITS, 1, **{**named, "hits": rays})
    rays.release()
    with pytest.raises(LaunchError, match=r"kernel queue_hits: missing argument 'in_o'"):
        launch(stage_program(device), stages.QUEUE_HITS, 1, **{**named, "in_": rays})
