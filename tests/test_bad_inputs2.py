"""The second round of bad inputs and faults: an environment map without pixels, memory
limits other than free RAM, an 8k environment map's compile, a mesh mean without extent
and a Scene edited after loading. Each refusal is one line naming the file, the key path
and the reason, before any work."""
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gpiscl.host.errors import SceneError
from gpiscl.host.io.memory_budget import memory_budget, process_limits
from gpiscl.host.scene.loading import load_scene

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
FLOOR_AND_BLOB = [
    {"type": "rectangle", "center": [0, -1, 0], "u": [6, 0, 0], "v": [0, 0, -6]},
    {"type": "gpis", "proxy": {"type": "sphere", "radius": 1.4},
     "mean": {"type": "sphere", "radius": 0.8},
     "kernel": {"type": "squared_exponential", "sigma": 0.05, "length_scale": 0.15},
     "sampler": {"type": "weight_space", "features": 64}}]


def write_scene(folder, shapes=FLOOR_AND_BLOB, lights=None, resolution=(12, 12)):
    doc = {"camera": {"position": [0, 0.3, 4], "look_at": [0, 0, 0],
                      "resolution": list(resolution)},
           "render": {"spp": 1}, "shapes": list(shapes),
           "lights": lights or [{"type": "environment", "radiance": 0.6}]}
    path = Path(folder) / "scene.json"
    path.write_text(json.dumps(doc))
    return path


def render_cli(scene, out, preexec_fn=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "gpiscl", "render", str(scene), "-o",
                           str(out), "--spp", "1"], capture_output=True, text=True, env=ENV,
                          cwd=ROOT, preexec_fn=preexec_fn, timeout=timeout)


def assert_refused_in_one_line(r, *fragments):
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "Traceback" not in r.stderr and all(f in r.stderr for f in fragments), r.stderr


# ---- E01: a .hdr whose header says 0 x 0 decodes to an empty array; the device read past it

def empty_hdr(width, height):
    return f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {height} +X {width}\n".encode()


@pytest.mark.parametrize("width,height", [(0, 0), (5, 0), (0, 1)])
def test_an_environment_map_without_pixels_is_refused_at_load(tmp_path, width, height):
    (tmp_path / "empty.hdr").write_bytes(empty_hdr(width, height))
    scene = write_scene(tmp_path, lights=[{"type": "environment_map", "file": "empty.hdr"}])
    with pytest.raises(SceneError) as info:
        load_scene(str(scene))
    assert info.value.key == "lights[0].file", str(info.value)
    assert f"has no pixels ({width} x {height})" in info.value.reason
    assert str(tmp_path / "empty.hdr") in info.value.reason


def test_the_command_line_refuses_an_empty_environment_map_and_writes_nothing(tmp_path):
    (tmp_path / "empty.hdr").write_bytes(empty_hdr(0, 0))
    scene = write_scene(tmp_path, lights=[{"type": "environment_map", "file": "empty.hdr"}])
    r = render_cli(scene, tmp_path / "out.exr")
    assert_refused_in_one_line(r, f"{scene}: lights[0].file: the image has no pixels (0 x 0)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.hdr", "scene.json"]


# ---- E02: the memory check saw only free RAM, not the process's or its cgroup's limits

def test_a_film_beyond_the_address_space_limit_is_one_line_not_an_opencl_traceback(tmp_path):
    """Under `ulimit -v 3G` an 8192^2 film (~14 GiB) failed in create_buffer."""
    scene = write_scene(tmp_path, resolution=(8192, 8192))

    def limit_address_space():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, resource.RLIM_INFINITY))
    r = render_cli(scene, tmp_path / "out.exr", preexec_fn=limit_address_space)
    assert_refused_in_one_line(r, f"{scene}: camera.resolution: 67108864 pixels need",
                               "RLIMIT_AS (ulimit -v) of 3 GiB")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


def fake_tree(tmp_path, cgroup_lines, files):
    """A /proc with 20 GiB free and the given /proc/self/cgroup, and a cgroup root holding
    files {relative path: text}."""
    proc, root = tmp_path / "proc", tmp_path / "cgroup"
    (proc / "self").mkdir(parents=True)
    (proc / "meminfo").write_text(f"MemTotal: {32 << 20} kB\nMemAvailable: {20 << 20} kB\n")
    (proc / "self" / "cgroup").write_text("".join(line + "\n" for line in cgroup_lines))
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return proc, root


def test_the_budget_reads_a_v2_cgroup_limit_less_its_working_set(tmp_path):
    proc, root = fake_tree(tmp_path, ["0::/job/step"], {
        "job/step/memory.max": "max\n", "job/step/memory.current": str(1 << 30),
        "job/memory.max": str(2 << 30), "job/memory.current": str(3 << 29),
        "job/memory.stat": f"anon 100\ninactive_file {1 << 28}\nactive_file 5\n"})
    budget = memory_budget(proc, root)
    # 2 GiB less (1.5 GiB used, of which 0.25 GiB inactive page cache the kernel reclaims)
    assert budget.bytes == (2 << 30) - (3 << 29) + (1 << 28)
    assert str(root / "job" / "memory.max") in budget.limit


def test_the_tightest_level_of_a_v1_memory_hierarchy_binds(tmp_path):
    proc, root = fake_tree(tmp_path, ["4:memory:/outer/inner", "0::/"], {
        "memory/memory.limit_in_bytes": "9223372036854771712",     # v1's "unlimited"
        "memory/memory.usage_in_bytes": str(5 << 30),
        "memory/outer/memory.limit_in_bytes": str(4 << 30),
        "memory/outer/memory.usage_in_bytes": str(1 << 30),
        "memory/outer/inner/memory.limit_in_bytes": str(2 << 30),
        "memory/outer/inner/memory.usage_in_bytes": str(1 << 30),
        "memory/outer/inner/memory.stat": f"cache 9\ntotal_inactive_file {1 << 29}\n"})
    budget = memory_budget(proc, root)
    assert budget.bytes == (1 << 30) + (1 << 29)
    assert "inner/memory.limit_in_bytes" in budget.limit


def test_a_cgroup_without_a_limit_leaves_free_ram_and_the_rlimits(tmp_path):
    proc, root = fake_tree(tmp_path, ["0::/"], {"memory.max": "max\n",
                                                "memory.current": str(30 << 30)})
    rlimits = [b.bytes for b in process_limits(proc)]   # none where the shell set none
    assert memory_budget(proc, root).bytes == min([20 << 30] + rlimits)


# ---- E05: an 8192 x 4096 map peaked at 2.7 GB (~80 bytes a texel) and was a MemoryError
# traceback under a 3 GiB address-space limit

RSS_PROBE = """
import sys
from gpiscl.host.compile.envmap import compile_envmap
from gpiscl.host.io.images import read_exr_rgb
read_exr_rgb(sys.argv[2])       # a small map: the reader's own first-use allocations
def status(key):
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) * 1024 for l in f if l.startswith(key + ":"))
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")                # the peak (VmHWM) starts again from here
before = status("VmRSS")
env = compile_envmap(sys.argv[1])
print((status("VmHWM") - before) / len(env.texels))
"""


def test_an_environment_map_compiles_in_under_30_bytes_a_texel(tmp_path):
    from gpiscl.host.io.images import write_exr
    rgb = np.random.default_rng(1).random((1024, 2048, 3), dtype=np.float32)
    write_exr(tmp_path / "sky.exr", rgb)
    write_exr(tmp_path / "small.exr", rgb[:4, :8])
    del rgb
    r = subprocess.run([sys.executable, "-c", RSS_PROBE, str(tmp_path / "sky.exr"),
                        str(tmp_path / "small.exr")],
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    # 12 (the decoded RGB) + 16 (the float4 texels) at the peak; the tables come after the
    # RGB is freed. The whole-map double code took ~80.
    assert float(r.stdout) < 30, r.stdout


LOAD_UNDER_A_LIMIT = """
import resource, sys
import OpenEXR
from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene
with open("/proc/self/status") as f:
    vm = next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:"))
resource.setrlimit(resource.RLIMIT_AS, (vm + (96 << 20), resource.RLIM_INFINITY))
try:
    load_scene(sys.argv[1])
except SceneError as e:
    print(e)
"""


def test_a_map_the_memory_budget_cannot_hold_is_refused_before_reading(tmp_path):
    """4096 x 2048 texels need ~200 MB to read; 96 MB of address space is left."""
    from gpiscl.host.io.images import write_exr
    write_exr(tmp_path / "big.exr", np.ones((2048, 4096, 3), np.float32))
    scene = write_scene(tmp_path, lights=[{"type": "environment_map", "file": "big.exr"}])
    r = subprocess.run([sys.executable, "-c", LOAD_UNDER_A_LIMIT, str(scene)],
                       capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300)
    assert r.returncode == 0 and r.stdout.count("\n") == 1, r.stdout + r.stderr
    assert r.stdout.startswith(f"{scene}: lights[0].file: a 4096 x 2048 environment map "
                               "needs about 192 MiB"), r.stdout
    assert "RLIMIT_AS" in r.stdout and r.stdout.rstrip().endswith("big.exr")


def test_the_compile_refuses_a_map_emptied_after_the_scene_was_checked(tmp_path):
    """The device never gets an empty map, even when the checks were passed earlier."""
    from gpiscl.host.compile.scene import compile_scene
    from gpiscl.host.io.radiance_hdr import write_hdr
    sky = tmp_path / "sky.hdr"
    write_hdr(sky, np.ones((4, 8, 3), np.float32))
    scene = write_scene(tmp_path, lights=[{"type": "environment_map", "file": "sky.hdr"}])
    data = load_scene(str(scene)).data
    sky.write_bytes(empty_hdr(0, 0))
    with pytest.raises(SceneError) as info:
        compile_scene(data, str(scene))
    assert info.value.key == "lights[0].file"
    assert info.value.reason == f"the image has no pixels (0 x 0): {sky}"


# ---- E14: a mesh mean without extent said "grid voxel_size must be positive (got 0.0)"

CUBE = """v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8
f 3 8 7\nf 4 1 5\nf 4 5 8\n"""
POINT = "v 0.1 0.1 0.1\nv 0.1 0.1 0.1\nv 0.1 0.1 0.1\nf 1 2 3\n"


def mesh_mean_blob(file, **mean):
    blob = json.loads(json.dumps(FLOOR_AND_BLOB[1]))
    blob["proxy"]["radius"] = 2.5
    blob["mean"] = {"type": "mesh", "file": file, "resolution": 16, **mean}
    return [FLOOR_AND_BLOB[0], blob]


def test_a_mesh_whose_vertices_are_one_point_is_refused_naming_the_file(tmp_path):
    (tmp_path / "point.obj").write_text(POINT)
    scene = write_scene(tmp_path, mesh_mean_blob("point.obj"))
    r = render_cli(scene, tmp_path / "out.exr")
    assert_refused_in_one_line(r, f"{scene}: shapes[1].mean.file: the mesh has no extent "
                                  f"(all vertices at one point): {tmp_path / 'point.obj'}")
    assert not (tmp_path / "out.exr").exists()
    # the same file as a mesh shape shows nothing: refused alike
    scene = write_scene(tmp_path, [{"type": "mesh", "file": "point.obj"}])
    with pytest.raises(SceneError, match="no extent") as info:
        load_scene(str(scene))
    assert info.value.key == "shapes[0].file"


def test_a_mesh_mean_too_small_to_bake_is_refused_naming_the_file(tmp_path):
    """A cube scaled by 1e-30 collapses when the bake merges corners closer than 1e-8."""
    from gpiscl.host.compile.scene import compile_scene
    (tmp_path / "cube.obj").write_text(CUBE)
    scene = write_scene(tmp_path, mesh_mean_blob("cube.obj", transform={"scale": 1e-30}))
    with pytest.raises(SceneError) as info:
        compile_scene(load_scene(str(scene)).data, str(scene))
    assert info.value.key == "shapes[1].mean", str(info.value)
    assert info.value.reason.startswith("the mesh has no extent once corners closer than "
                                        "1e-08 are merged (its size after the transform is "
                                        "1e-30)")
    assert info.value.reason.endswith(str(tmp_path / "cube.obj"))


# ---- E13: a Scene whose data was edited after its checks crashed in the film (OpenCL's
# INVALID_BUFFER_SIZE); the Scene is validated again (test_bad_inputs2_commands.py), and
# the film's own check before allocating names camera.resolution too

def test_a_film_without_pixels_is_a_scene_error_not_an_opencl_error(device):
    import gpiscl
    from gpiscl.scenes import furnace_sphere
    doc = furnace_sphere()
    doc["camera"]["resolution"] = [8, 8]
    scene = gpiscl.load_scene(doc)
    scene.data["camera"]["resolution"] = [0, 0]      # edited after validation
    with pytest.raises(SceneError) as info:
        gpiscl.render(scene, spp=1, device=device)
    assert info.value.key.startswith("camera.resolution"), str(info.value)


def test_the_header_size_of_a_radiance_file_is_read_in_either_order(tmp_path):
    from gpiscl.host.io.radiance_hdr import hdr_size, write_hdr
    write_hdr(tmp_path / "a.hdr", np.ones((3, 5, 3), np.float32))
    assert hdr_size(tmp_path / "a.hdr") == (5, 3)
    (tmp_path / "b.hdr").write_bytes(b"#?RGBE\nEXPOSURE=1\n\n+X 7 -Y 2\n")
    assert hdr_size(tmp_path / "b.hdr") == (7, 2)
    (tmp_path / "c.hdr").write_bytes(b"#?RGBE\n-Y 2 +X 7\n")     # no blank line: no size
    assert hdr_size(tmp_path / "c.hdr") is None
