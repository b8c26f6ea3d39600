"""Dask cluster throughput: samples/s of a render on 1 and 2 local worker processes against
the plain render in the same run, the overhead per unit, the data sent per unit, and from
them a paper estimate of the time to converge a scene on 16 and 64 such workers.

    python tools/bench_cluster.py [--scene scenes/knob.json] [--resolution 96] [--spp 16]
                                  [--target 0.01] [--full 512]

Each rate is measured after a warm-up render of the same scene (the worker processes
compile the scene and build their programs once per run; the warm-up's time is shown). The estimate: the spp for a median relative standard error of
--target per pixel, from the plain render's film (1/sqrt(spp)); the paths of a --full
square image at that spp; divided by the measured 1-worker rate times the workers, the
unit efficiency (work / (work + overhead) at UNIT_SECONDS per unit), and capped by how fast
the client can merge (its accumulate kernel) and by a 1 Gbit/s link into it.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ["PYTHONPATH"] = os.pathsep.join(      # the workers import this checkout too
    [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])

from distributed import Client, LocalCluster  # noqa: E402

from gpiscl.api import prepare_render, render_result  # noqa: E402
from gpiscl.host.distributed import cluster as cm  # noqa: E402

LINK_BYTES_PER_S = 125e6     # 1 Gbit/s into the client


def film_convergence(image, target: float) -> tuple:
    """(median relative stderr per pixel, spp factor to reach target) of a film."""
    mean = image.mean.astype(np.float64).mean(axis=-1)
    err = image.stderr.astype(np.float64).mean(axis=-1)
    ok = mean > 1e-6
    rel = float(np.median(err[ok] / mean[ok]))
    return rel, (rel / target) ** 2


def client_merge_rate(scene, spp, resolution, paths=1 << 20) -> float:
    """Paths/s the client adds to its film (FilmMerge: unit radiance -> accumulate)."""
    integrator, _ = prepare_render(scene, spp=spp, resolution=resolution)
    stats = cm.ClusterStats(pixels=integrator.num_pixels)
    merge = cm.FilmMerge(integrator, stats)
    rng = np.random.default_rng(0)
    unit = cm.UnitResult(0, paths, "bench", 0.0, dict.fromkeys(cm.COUNTED, 0),
                         radiance=rng.random((paths, 3), dtype=np.float32))
    merge(unit)     # warm-up
    integrator.device.queue.finish()
    t0 = time.perf_counter()
    merge(unit)
    integrator.device.queue.finish()
    return paths / (time.perf_counter() - t0)


def on_cluster(n: int, scene, kw, overhead_scene, overhead_kw, unit_paths):
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as lc, Client(lc) as client:
        # warm-up: the same scene (so the same digest) cut short, so the workers have
        # compiled it and built their programs; a run pays that once per worker
        t0 = time.perf_counter()
        render_result(scene, cluster=client, time_limit=0.1, **kw)
        setup = time.perf_counter() - t0
        result = render_result(scene, cluster=client, **kw)
        st = result.stats
        # per-unit overhead: many tiny units of a cheap scene, wall time minus worker time
        integrator, resolved = prepare_render(overhead_scene, **overhead_kw)
        cm.render_on_cluster(client, integrator, resolved, overhead_kw["spp"],
                             unit_paths=unit_paths)                        # warm-up
        integrator, resolved = prepare_render(overhead_scene, **overhead_kw)
        t0 = time.perf_counter()
        small = cm.render_on_cluster(client, integrator, resolved, overhead_kw["spp"],
                                     unit_paths=unit_paths)
        wall = time.perf_counter() - t0
    busy = _busy(small.stats.kernel_table)
    overhead = (wall * n - busy) / small.stats.units
    return st, overhead, small.stats.units, setup


def _busy(table: str) -> float:
    """Worker busy seconds summed over the per-worker table of ClusterStats."""
    total = 0.0
    for line in table.splitlines():
        if line.startswith("tcp://"):
            total += float(line.split()[3])
    return total


def _unit_bytes(table: str) -> float:
    return float(table.split(" MB back per unit")[0].rsplit(", ", 1)[1]) * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "knob.json"))
    ap.add_argument("--resolution", type=int, default=96)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--target", type=float, default=0.01,
                    help="median relative standard error per pixel that counts as converged")
    ap.add_argument("--full", type=int, default=512, help="resolution of the estimate")
    args = ap.parse_args()
    kw = dict(spp=args.spp, resolution=(args.resolution, args.resolution), seed=1)
    cheap = str(ROOT / "scenes" / "ws_sphere_se.json")
    cheap_kw = dict(spp=4, resolution=(64, 64), seed=1)

    render_result(args.scene, **dict(kw, spp=1))                      # warm-up
    plain = render_result(args.scene, **kw)
    rate0 = plain.stats.paths / plain.stats.seconds
    print(f"{args.scene} at {args.resolution}x{args.resolution}, {args.spp} spp "
          f"({plain.stats.paths} paths)")
    print(f"  plain render          {rate0:10.4g} samples/s  ({plain.stats.seconds:.2f} s)")
    rates = {}
    for n in (1, 2):
        st, overhead, units, setup = on_cluster(n, args.scene, kw, cheap, cheap_kw, 64)
        rates[n] = st.paths / st.seconds
        print(f"  {n} local worker{'s' if n > 1 else ' '}       {rates[n]:10.4g} samples/s  "
              f"({st.seconds:.2f} s, {st.units} units, x{rates[n] / rate0:.2f} the plain "
              f"render; {_unit_bytes(st.kernel_table) / 1e6:.3g} MB back per unit)")
        print(f"      first unit, set-up included {setup:6.3g} s (scene compiled and programs "
              f"built on each worker, once per run)")
        print(f"      in units           {st.paths / _busy(st.kernel_table):10.4g} samples/s "
              f"of worker time (busy), per worker")
        print(f"      per-unit overhead {overhead * 1e3:8.3g} ms  (wall x workers - worker "
              f"time, over {units} units of 64 paths)")
        rates[f"overhead{n}"] = overhead

    merge_rate = client_merge_rate(args.scene, args.spp, (args.resolution, args.resolution))
    print(f"  client merge          {merge_rate:10.4g} samples/s (accumulate, 12 B a sample)")
    rel, factor = film_convergence(plain.image, args.target)
    spp_needed = int(np.ceil(args.spp * factor))
    paths = args.full * args.full * spp_needed
    print(f"\nconvergence: median relative stderr {rel:.3g} at {args.spp} spp -> "
          f"{spp_needed} spp for {args.target:g}; {args.full}x{args.full}: {paths:.3g} paths")
    per_worker = rates[1]
    overhead = rates["overhead1"]
    efficiency = cm.UNIT_SECONDS / (cm.UNIT_SECONDS + overhead)
    link = LINK_BYTES_PER_S / 12
    print(f"one such worker: {per_worker:.4g} samples/s; unit efficiency {efficiency:.4f} "
          f"at {cm.UNIT_SECONDS:g} s units; client caps: merge {merge_rate:.3g}, "
          f"1 Gbit/s link {link:.3g} samples/s")
    for workers in (1, 16, 64):
        rate = min(workers * per_worker * efficiency, merge_rate, link)
        hours = paths / rate / 3600
        print(f"  {workers:3d} workers: {rate:10.4g} samples/s -> {hours:8.3g} h")
    return 0


if __name__ == "__main__":
    sys.exit(main())
