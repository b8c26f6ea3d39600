"""Allocations checked before they are made; uq batches merged only when they belong
together."""
import json

import numpy as np
import pytest

from gpiscl import SceneError, render_result
from gpiscl.cli import main
from gpiscl.api import prepare_render
from gpiscl.host.render.memory import bytes_per_path
from gpiscl.host.scene.arguments import parse_size
from gpiscl.host.render.integrator import default_batch
from gpiscl.host.uq.files import load_partial

TINY = {"lights": [{"type": "environment"}], "camera": {"resolution": [4, 3]},
        "render": {"spp": 2}}


def test_sizes_parse():
    assert parse_size("8G") == 8 << 30 and parse_size("512m") == 512 << 20
    assert parse_size("1.5GiB") == 3 << 29 and parse_size("1000") == 1000
    for bad in ("", "-1G", "8X", "0"):
        with pytest.raises(ValueError):
            parse_size(bad)


def test_a_film_that_does_not_fit_is_refused_before_allocating(device):
    with pytest.raises(SceneError, match="camera.resolution.*GiB for the film.*max-memory"):
        render_result(TINY, resolution=(16384, 16384), device=device, max_memory=1 << 30)


def test_batches_shrink_to_fit_beside_the_film(device):
    budget = 16 << 20     # the queues' quarter holds ~9,500 paths: below every default cap
    integrator, _ = prepare_render(TINY, spp=1 << 20, device=device, max_memory=budget)
    assert integrator.batch * bytes_per_path() <= budget / 4
    assert 1000 <= integrator.batch < default_batch(integrator.device)
    roomy, _ = prepare_render(TINY, spp=1 << 20, device=device)
    assert roomy.batch == default_batch(roomy.device)   # the default cap where memory is plenty


SCENE = {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "resolution": [4, 3]},
         "lights": [{"type": "environment"}],
         "shapes": [{"type": "gpis", "proxy": {"type": "sphere", "radius": 2},
                     "mean": {"type": "sphere", "radius": 1},
                     "kernel": {"type": "squared_exponential", "sigma": 0.1,
                                "length_scale": 0.3}}]}


def test_uq_merge_refuses_batches_that_do_not_belong_together(tmp_path, capsys):
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(SCENE))

    def run(name, *extra):
        assert main(["uq", str(scene), "--realizations", "2", "--spp", "2", "-o",
                     str(tmp_path / f"{name}.exr"), *extra]) == 0
        return str(tmp_path / f"{name}.uq.npz")
    a, b, c = run("a"), run("b", "--first", "2"), run("c", "--seed", "5")
    other = dict(SCENE, camera=dict(SCENE["camera"], fov=30))
    scene.write_text(json.dumps(other))
    d = run("d", "--first", "4")
    capsys.readouterr()
    for files, why in (((a, a), "also in"),
                       ((a, c), "seed"), ((a, d), "scene"), ((a, b, b), "also in")):
        assert main(["uq", "--merge", *files, "-o", str(tmp_path / "m.exr")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and why in err[0], err
    assert main(["uq", "--merge", b, a, "-o", str(tmp_path / "ab.exr")]) == 0
    sums, meta = load_partial(tmp_path / "ab.uq.npz")
    assert sums.n == 4 and meta["ranges"] == [(0, 2), (2, 4)]


def test_uq_merge_refuses_damaged_partial_sums(tmp_path, capsys):
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(SCENE))
    assert main(["uq", str(scene), "--realizations", "2", "--spp", "2", "-o",
                 str(tmp_path / "a.exr")]) == 0
    a = tmp_path / "a.uq.npz"
    z = dict(np.load(a))
    for name, change in (("n_float", {"n": np.array(2.7)}), ("n_vec", {"n": np.array([2, 2])}),
                         ("nan", {"m2": np.full_like(z["m2"], np.nan)}),
                         ("old", {"meta": None})):
        bad = {k: v for k, v in dict(z, **change).items() if v is not None}
        np.savez(tmp_path / f"{name}.uq.npz", **bad)
    (tmp_path / "empty.uq.npz").write_bytes(b"")
    capsys.readouterr()
    for name in ("n_float", "n_vec", "nan", "old", "empty"):
        assert main(["uq", "--merge", str(a), str(tmp_path / f"{name}.uq.npz"), "-o",
                     str(tmp_path / "m.exr")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"{name}.uq.npz" in err[0], err


def test_cpu_scene_buffers_share_the_arrays_and_scratch_follows_the_units(device):
    """On a CPU the device's memory is the process's: read-only scene arrays are used in
    place (no second copy), and the function-space scratch is sized to the compute units,
    not to the batch (whole-batch chunks held ~250 MB resident for the knob)."""
    import pyopencl as cl
    from gpiscl.host.render import function_space_stages as fs
    from gpiscl.host.render.device import to_device
    from gpiscl.host.layout.gp_records import MEAN_NODE
    a = MEAN_NODE.page_aligned_zeros(1000)
    assert a.ctypes.data % 4096 == 0
    shared, copied = to_device(device, a), to_device(device, a, writable=True)
    cpu = bool(device.device.type & cl.device_type.CPU)
    assert (shared.hostbuf is a) == cpu
    assert bool(shared.flags & cl.mem_flags.USE_HOST_PTR) == cpu
    assert not copied.flags & cl.mem_flags.USE_HOST_PTR
    unaligned = a.view(np.uint8)[4:4 + 4000]   # 4 bytes past a page: copied
    assert not to_device(device, unaligned).flags & cl.mem_flags.USE_HOST_PTR
    integrator, _ = prepare_render({**TINY, "shapes": [{
        "type": "gpis", "proxy": {"type": "sphere", "radius": 1.0},
        "mean": {"type": "sphere", "radius": 0.5},
        "kernel": {"type": "squared_exponential", "sigma": 0.1, "length_scale": 0.5},
        "sampler": {"type": "function_space"}}]}, resolution=(256, 256), spp=64,
        device=device)
    stages = integrator.function_space
    assert integrator.batch == default_batch(device)
    units = device.device.max_compute_units * stages.local * fs.GROUPS_PER_UNIT
    assert stages.items <= max(units, stages.local) < integrator.batch


def test_function_space_images_do_not_depend_on_the_work_items_launched(device, monkeypatch):
    """The function-space stages' work items stride over the rays (grid-stride launches,
    scratch sized to the items): one work-group of items and the default count give
    bit-identical images, since random numbers are keyed by pixel, sample, bounce and
    dimension, never by the item. Global memory (rings) and shadow rays included."""
    from gpiscl.host.render import function_space_stages as fs
    scene = {"lights": [{"type": "point", "position": [2, 3, 2], "intensity": [20, 20, 20]},
                        {"type": "environment"}],
             "camera": {"resolution": [24, 16]}, "render": {"spp": 3, "seed": 5,
                                                             "max_depth": 4},
             "shapes": [{
                 "type": "gpis", "proxy": {"type": "box", "min": [-0.8, -0.8, -0.8],
                                           "max": [0.8, 0.8, 0.8]},
                 "mean": {"type": "sphere", "radius": 0.6},
                 "kernel": {"type": "squared_exponential", "sigma": 0.1,
                            "length_scale": 0.3},
                 "sampler": {"type": "function_space", "memory": "global",
                             "memory_cap": 8}}]}
    images, items = [], []
    for groups in (fs.GROUPS_PER_UNIT, None):
        if groups is None:   # a scratch budget that holds one work-group's slices
            probe, _ = prepare_render(scene, device=device)
            one = probe.function_space.scratch_bytes // probe.function_space.items
            monkeypatch.setattr(fs, "CPU_SCRATCH_BUDGET", one * probe.function_space.local)
            monkeypatch.setattr(fs, "SCRATCH_BUDGET", one * probe.function_space.local)
        integrator, _ = prepare_render(scene, device=device)
        items.append(integrator.function_space.items)
        result = integrator.render(3)
        assert result.stats.fs_flights > 0 and result.stats.shadow_rays > 0
        images.append(result.image.sum)
    assert items[1] == integrator.function_space.local < items[0], items
    assert np.count_nonzero(images[0]) > 100
    np.testing.assert_array_equal(images[0], images[1])


def _rss_anon_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("RssAnon")) / 1024


def test_a_render_frees_its_work_buffers_before_the_film_and_gets_them_back(device):
    """render() releases the queues and the function-space scratch and rings before it
    reads the film (on a CPU they are the process's memory, and the film's copies and the
    output buffers came on top of them: every scene's peak RSS was at its end); a later
    batch allocates them again and traces exactly what a fresh integrator traces."""
    import pyopencl as cl
    scene = {**TINY, "camera": {"resolution": [64, 64]}, "shapes": [{
        "type": "gpis", "proxy": {"type": "box", "min": [-0.8, -0.8, -0.8],
                                  "max": [0.8, 0.8, 0.8]},
        "mean": {"type": "constant", "value": 1.0},
        "kernel": {"type": "squared_exponential", "sigma": 1.0, "length_scale": 0.2},
        "sampler": {"type": "function_space", "memory": "global", "memory_cap": 8}}],
        "render": {"spp": 8, "seed": 3}}
    used, _ = prepare_render(scene, device=device)
    assert used.render_batch(0, 0, used.batch)     # every queue and scratch page touched
    # no AOV asked for: their path fields hold one element (every access is guarded)
    assert all(used.paths.buffers[f].size == 16 for f in ("aov_position", "aov_normal",
                                                          "aov_albedo"))
    work = sum(b.size for b in used.function_space.work)
    work += sum(b.size for q in (used.paths, *used.rays, used.hits, used.escaped, used.shadow)
                for b in q.buffers.values())
    before = _rss_anon_mb()
    used.release_work()
    freed = before - _rss_anon_mb()
    assert used.paths is None and used.function_space.work is None
    if device.device.type & cl.device_type.CPU:
        # only the touched pages count, and which scratch pages the pthread device's work
        # groups touch depends on how many threads ran at once (0.3 of the work freed on an
        # idle machine was missed once under load): a tenth still fails if nothing is freed
        assert freed >= 0.1 * work / 2**20, (freed, work / 2**20)
    n = 1000
    assert used.render_batch(0, 0, n)
    fresh, _ = prepare_render(scene, device=device)
    assert fresh.render_batch(0, 0, n)
    again = used.batch_radiance(n)
    assert np.count_nonzero(again[:, :3]) > 100
    np.testing.assert_array_equal(again, fresh.batch_radiance(n))
    used.render(1)
    assert used.paths is None and used.function_space.work is None


def test_the_command_line_frees_the_integrator_before_writing_the_outputs(tmp_path,
                                                                          monkeypatch):
    """render drops the integrator (its film and scene buffers: the process's memory on a
    CPU) once the film is read, so the output files' buffers do not come on top of them
    (csg_baked's peak RSS was there)."""
    import weakref
    import gpiscl.api
    import gpiscl.host.render.output as output
    refs, alive = [], []
    prepare, write = gpiscl.api.prepare_render, output.write_outputs

    def prepare_and_watch(*args, **kwargs):
        integrator, scene = prepare(*args, **kwargs)
        refs.append(weakref.ref(integrator))
        return integrator, scene

    def write_and_look(*args, **kwargs):
        alive.append(refs[0]() is not None)
        return write(*args, **kwargs)
    monkeypatch.setattr(gpiscl.api, "prepare_render", prepare_and_watch)
    monkeypatch.setattr(output, "write_outputs", write_and_look)
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(TINY))
    assert main(["render", str(scene), "-o", str(tmp_path / "out.png")]) == 0
    assert alive == [False]
