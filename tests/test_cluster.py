"""render and uq on a Dask cluster (host/distributed/cluster.py): the EXR is the local render's bit
for bit, on 1 and 2 worker processes, in any completion order, and with a worker killed
mid-run; a stop or a lost scheduler keeps exactly the units merged; a bad --cluster is one
line. Real Dask throughout: LocalClusters of worker processes started by the tests."""
import json
import os
import random
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from distributed import Client, LocalCluster

import gpiscl
from gpiscl.api import prepare_render
from gpiscl.host.distributed import cluster as cm
from gpiscl.host.uq.sums import UqSums
from gpiscl.host.io.images import read_exr

ROOT = Path(__file__).resolve().parent.parent
SCENE = str(ROOT / "scenes" / "ws_sphere_se.json")
RENDER = dict(spp=6, resolution=(20, 14), seed=11)       # 1680 paths
UNIT_PATHS = 97          # ~18 units, aligned with neither rows nor passes
UQ = dict(realizations=5, spp=3, resolution=(10, 8), seed=4)


def _env():
    """Worker processes import this checkout's gpiscl, whatever is installed."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get(
        "PYTHONPATH", "").split(os.pathsep) if p])
    return env


@pytest.fixture(scope="module")
def workers_env():
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = _env()["PYTHONPATH"]    # LocalCluster's workers inherit it
    yield
    if old is None:
        del os.environ["PYTHONPATH"]
    else:
        os.environ["PYTHONPATH"] = old


@pytest.fixture(scope="module")
def client(workers_env):
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as lc, Client(lc) as c:
        yield c


@pytest.fixture
def small_units(monkeypatch):
    """Units of UNIT_PATHS paths and one realization, so a tiny image is many units."""
    monkeypatch.setattr(cm, "MAX_UNIT_BYTES", 12 * UNIT_PATHS)


@pytest.fixture(scope="module")
def local_render():
    return gpiscl.render_result(SCENE, **RENDER)


def _same_film(a, b):
    for name in ("sum", "sum_sq", "count", "mean", "stderr"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name


def _same_exr(tmp_path, local, distributed):
    gpiscl.write_image(tmp_path / "local.exr", local)
    gpiscl.write_image(tmp_path / "cluster.exr", distributed)
    a, b = read_exr(tmp_path / "local.exr"), read_exr(tmp_path / "cluster.exr")
    assert sorted(a) == sorted(b)
    for name in a:
        assert np.array_equal(a[name], b[name]), name


def _same_sums(a: UqSums, b: UqSums):
    assert a.n == b.n
    for name in ("mean", "m2", "m3", "m4", "c1", "c2", "u", "uu"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test01_render_on_two_workers_is_the_local_exr_bit_for_bit(client, small_units, local_render,
                                                              tmp_path):
    result = gpiscl.render_result(SCENE, cluster=client, **RENDER)
    assert result.stats.units >= 15 and not result.stats.interrupted
    assert result.stats.paths == local_render.stats.paths
    assert result.stats.rays == local_render.stats.rays    # counts add up once per unit
    _same_film(local_render.image, result.image)
    _same_exr(tmp_path, local_render, result)


def test02_render_on_one_worker_local_form(workers_env, small_units, local_render, tmp_path):
    result = gpiscl.render_result(SCENE, cluster="local:1", **RENDER)
    assert "tcp://" in result.stats.kernel_table     # the per-worker table: one worker
    assert result.stats.kernel_table.count("tcp://") == 1
    _same_film(local_render.image, result.image)
    _same_exr(tmp_path, local_render, result)


def test03_any_completion_order_gives_the_same_film(client, local_render):
    """Units computed by the workers, then handed to the merge in a shuffled order, one
    of them twice (a rescheduled unit whose first run also finished)."""
    integrator, scene = prepare_render(SCENE, **RENDER)
    payload = cm.scene_payload(scene)
    total = integrator.num_pixels * RENDER["spp"]
    starts = list(range(0, total, UNIT_PATHS))
    futures = [client.submit(cm.render_unit, payload, integrator.batch, s,
                             min(UNIT_PATHS, total - s), pure=False) for s in starts]
    results = list(enumerate(client.gather(futures)))
    order = results + [results[3]]
    random.Random(5).shuffle(order)
    stats = cm.ClusterStats(pixels=integrator.num_pixels)
    merge = cm.InOrder(cm.FilmMerge(integrator, stats))
    for index, result in order:
        merge.add(index, result)
    assert stats.units == len(starts) and stats.paths == total
    _same_film(local_render.image, integrator.film.read())


def test04_uq_on_one_and_two_workers_and_shuffled_is_the_local_run(client, small_units,
                                                                    workers_env, tmp_path):
    local = gpiscl.uq(SCENE, output=tmp_path / "local.exr", **UQ)
    two = gpiscl.uq(SCENE, output=tmp_path / "two.exr", cluster=client, **UQ)
    one = gpiscl.uq(SCENE, cluster="local:1", **UQ)
    for run in (two, one):
        _same_sums(local.sums, run.sums)
        assert run.ids == local.ids and run.meta == local.meta and run.paths == local.paths
    a, b = read_exr(tmp_path / "local.exr"), read_exr(tmp_path / "two.exr")
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    assert sum(w.units for w in two.cluster.workers.values()) == UQ["realizations"]
    # the realizations of units finished in a shuffled order
    scene, data, seed = cm.prepare_realizations(SCENE, UQ["realizations"], UQ["spp"],
                                                UQ["seed"], 0, UQ["resolution"])
    payload = cm.scene_payload(cm.Scene.resolved(data, scene.source, scene.base_dir))
    futures = [client.submit(cm.uq_unit, payload, UQ["spp"], seed, 0, None, i, 1, pure=False)
               for i in range(UQ["realizations"])]
    order = list(enumerate(client.gather(futures)))
    random.Random(1).shuffle(order)
    w, h = UQ["resolution"]
    merged = cm.RealizationMerge((h, w, 3))
    merge = cm.InOrder(merged)
    for index, result in order:
        merge.add(index, result)
    _same_sums(local.sums, merged.sums)


def test05_a_stop_keeps_exactly_the_units_merged(client, small_units):
    """stop() (what Ctrl-C sets on the command line) after a few units: the film holds the
    first paths in order, exactly as tracing just those paths locally gives."""
    merged = []
    result = gpiscl.render_result(SCENE, cluster=client, progress=merged.append,
                                  stop=lambda: len(merged) >= 3, **RENDER)
    st = result.stats
    assert st.interrupted and st.paths == sum(merged) and 3 <= len(merged) < st.units + 1
    assert st.spp_reached == st.paths / st.pixels and result.image.count.sum() == st.paths
    integrator, _ = prepare_render(SCENE, batch_size=st.paths, **RENDER)
    assert integrator.render_batch(0, 0, st.paths)
    _same_film(integrator.film.read(), result.image)


def test06_a_worker_killed_mid_run_still_gives_the_local_image(client, small_units,
                                                             local_render, tmp_path):
    spec = dict(RENDER, spp=16)
    local = gpiscl.render_result(SCENE, **spec)
    before = client.run(os.getpid)
    killed = []

    def kill_a_busy_worker(_paths):
        if killed:
            return
        busy = [w for w, keys in client.processing().items() if keys and w in before]
        if busy:
            os.kill(before[busy[0]], signal.SIGKILL)
            killed.append(busy[0])

    result = gpiscl.render_result(SCENE, cluster=client, progress=kill_a_busy_worker, **spec)
    assert killed, "no worker was busy to kill"
    assert not result.stats.interrupted and result.stats.paths == local.stats.paths
    _same_film(local.image, result.image)
    _same_exr(tmp_path, local, result)
    client.wait_for_workers(2, timeout=60)    # the nanny restarts it for the next tests
    assert before[killed[0]] not in client.run(os.getpid).values()


def test07_a_lost_scheduler_keeps_the_units_merged(small_units, tmp_path):
    """The scheduler process dies mid-run: the run ends with the units merged before it."""
    with dask_processes(tmp_path) as (address, started):
        merged = []

        def kill_scheduler_after_two(paths):
            merged.append(paths)
            if len(merged) == 2:
                started[0].kill()

        with Client(address, timeout=3) as c:
            c.wait_for_workers(1, timeout=60)
            t0 = time.perf_counter()
            result = gpiscl.render_result(SCENE, cluster=c, progress=kill_scheduler_after_two,
                                          **RENDER)
            assert time.perf_counter() - t0 < 60
    st = result.stats
    assert st.interrupted and st.lost and "scheduler" in st.lost
    assert st.paths == sum(merged) and result.image.count.sum() == st.paths
    assert st.paths < RENDER["spp"] * 20 * 14


def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "gpiscl", *args], capture_output=True,
                          text=True, cwd=ROOT, env=_env(), timeout=timeout)


@pytest.mark.parametrize("command", ["render", "uq"])
@pytest.mark.parametrize("address", ["tcp://127.0.0.1:9", "not an address", "local:0"])
def test08_a_bad_cluster_is_one_line(command, address, tmp_path):
    t0 = time.perf_counter()
    p = _cli(command, SCENE, "--cluster", address, "--resolution", "4x4", "--spp", "2",
             "-o", str(tmp_path / "x.exr"))
    assert p.returncode == 2, p.stderr
    errors = [line for line in p.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--cluster" in errors[0] and "Traceback" not in p.stderr
    assert time.perf_counter() - t0 < 40
    assert not (tmp_path / "x.exr").exists()


def test08b_aovs_with_a_cluster_are_refused_before_any_work(tmp_path):
    """Cluster units carry radiance only: --aov with --cluster (and aov= with cluster=)
    is one line, not an image whose AOV layers are silently empty."""
    p = _cli("render", SCENE, "--cluster", "local:1", "--aov", "depth", "--resolution", "4x4",
             "--spp", "1", "-o", str(tmp_path / "x.exr"))
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert "--aov" in p.stderr and "--cluster" in p.stderr
    with pytest.raises(gpiscl.SceneError, match="aov"):
        gpiscl.render_result(SCENE, spp=1, resolution=(4, 4), aov="depth", cluster="local:1")


def _local_exr(path, resolution, spp, seed):
    """The EXR `gpiscl render SCENE` writes (cli/render.py: render_result, then
    write_image), in this process: a CLI start-up less per comparison."""
    gpiscl.write_image(path, gpiscl.render_result(SCENE, resolution=resolution, spp=spp,
                                                  seed=seed))
    return read_exr(path)


def test09_cli_local_cluster_writes_the_local_exr(tmp_path):
    common = [SCENE, "--resolution", "12x10", "--spp", "4", "--seed", "9", "--stats"]
    p = _cli("render", *common, "--cluster", "local:2", "-o", str(tmp_path / "cluster.exr"))
    assert p.returncode == 0, p.stderr
    assert "per worker" in p.stderr and "paths/s" in p.stderr
    a = _local_exr(tmp_path / "local.exr", (12, 10), 4, 9)
    b = read_exr(tmp_path / "cluster.exr")
    assert sorted(a) == sorted(b)
    for name in a:
        assert np.array_equal(a[name], b[name]), name


def test10_without_cluster_dask_is_never_imported(tmp_path):
    code = ("import sys; from gpiscl.cli import main; "
            f"rc = main(['render', {SCENE!r}, '--resolution', '4x4', '--spp', '1', '-o', "
            f"{str(tmp_path / 'x.exr')!r}]); "
            "print(rc, sorted(m for m in sys.modules if m.split('.')[0] in "
            "('dask', 'distributed')))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=ROOT, env=_env(), timeout=120)
    assert p.stdout.split() == ["0", "[]"], p.stdout + p.stderr


def test11_workers_get_the_scene_files_not_their_paths():
    """A worker needs no shared file system: every file the scene reads travels with it,
    written to the worker's own folder, and the data it compiles names only those."""
    scene = gpiscl.load_scene(str(ROOT / "scenes" / "bunny_grid.json"))
    payload = cm.scene_payload(scene)
    assert len(payload.files) >= 4
    ws = cm.WorkerScene(payload)
    try:
        text = repr(ws.data)
        assert not any(path in text for path in payload.files)
        found = [v for v in cm.scene_inputs(cm.Scene.resolved(ws.data, "x", ws.dir))[1:]]
        assert len(found) == len(payload.files) and all(p.startswith(ws.dir) for p in found)
        assert sorted(Path(p).read_bytes() for p in found) == sorted(payload.files.values())
    finally:
        ws.close()
    assert not Path(ws.dir).exists()


@contextmanager
def dask_processes(tmp_path):
    """(address, [scheduler, worker]): `dask scheduler` and one `dask worker`, as the README
    starts them on several machines."""
    info = tmp_path / "scheduler.json"
    dask = [sys.executable, "-m", "dask"]     # the `dask` command of this Python
    quiet = dict(env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    started = [subprocess.Popen(dask + ["scheduler", "--scheduler-file", str(info), "--port",
                                        "0", "--dashboard-address", ":0"], **quiet)]
    try:
        deadline = time.time() + 60
        while not info.exists() and time.time() < deadline:
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        started.append(subprocess.Popen(dask + ["worker", address, "--nworkers", "1",
                                                "--nthreads", "1"], **quiet))
        yield address, started
    finally:
        for proc in reversed(started):
            proc.terminate()
            proc.wait(timeout=30)


def test12_the_readme_commands_dask_scheduler_and_dask_worker(tmp_path):
    """The several-machine form on one machine: --cluster ADDRESS gives the local EXR."""
    with dask_processes(tmp_path) as (address, _):
        with Client(address, timeout=30) as c:
            c.wait_for_workers(1, timeout=60)
        common = [SCENE, "--resolution", "10x8", "--spp", "3", "--seed", "2"]
        p = _cli("render", *common, "--cluster", address, "-o", str(tmp_path / "c.exr"))
        assert p.returncode == 0, p.stderr
    a, b = _local_exr(tmp_path / "l.exr", (10, 8), 3, 2), read_exr(tmp_path / "c.exr")
    assert sorted(a) == sorted(b) and all(np.array_equal(a[k], b[k]) for k in a)


def test13_a_unit_error_is_raised_as_itself(client):
    """A unit that fails (here a SceneError, as a worker that cannot load the scene
    raises) ends the run with that error, one line on the command line."""
    from gpiscl.host.errors import SceneError

    def fail(*_):
        raise SceneError("<worker>", "scene", "cannot read it")

    submit = lambda i, s, n: client.submit(fail, i, s, n, pure=False)
    with pytest.raises(SceneError, match="cannot read it"):
        cm.run_units(client, submit, 10, cm.BatchSizer(1, first=1),
                     cm.InOrder(lambda r: None))


def test14_a_time_limit_keeps_the_units_merged(client):
    result = gpiscl.render_result(SCENE, cluster=client, time_limit=1.0,
                                  **dict(RENDER, spp=100000))
    st = result.stats
    assert st.time_limited and not st.interrupted and 0 < st.paths < 100000 * 20 * 14
    assert result.image.count.sum() == st.paths and st.seconds < 30
