"""Whole-process costs of example scenes, for one or more source trees in the same run:
render paths/s, peak resident memory, and time to first pixel cold and warm.

    python tools/bench_scenes.py [SCENE ...] [--trees DIR,DIR] [--repeats 3] [--spp 4]
                                 [--modes render,first,cold,warm]

Every measurement is a fresh `python -m gpiscl render` process (PYTHONPATH = the tree),
so imports, scene preparation, OpenCL compiles and caches count as a user sees them:
  render  the scene at its own resolution, --spp samples: paths/s as the CLI prints it
          (its own timer), paths per CPU second of the whole process (ru_utime + ru_stime:
          steadier than wall time on a shared, oversubscribed machine; startup included,
          ~0.7 s of it), and peak RSS (the process's ru_maxrss); PoCL's and the bake
          cache warm (a 1-spp render of each scene at its own resolution fills them
          first: PoCL builds another variant of a kernel for a large launch, e.g. the
          accumulate kernel over a 256x256 film, which a 16x16 render never makes, and
          that compile inside the measured render added 13 MB to the knob's peak, 184
          against 171 MB the next round);
  first   time to first pixel with nothing cached: an empty PoCL kernel cache, pyopencl's
          cache off, an empty bake cache ($GPISCL_CACHE): process start to the end of a
          16x16, 1-spp render (an upper bound on the first sample accumulated);
  cold    the same with the OpenCL programs already compiled (PoCL's cache warm) but the
          bake cache empty: the first run of a new scene after the first-ever compile;
  warm    both caches warm: the second run of the same scene.
Scenes default to the issue-16 set: ws_sphere_se, ws_sphere_rq, the posterior sphere
(ws_sphere_se conditioned on 100 points of the unit sphere, written to a temporary folder)
and the knob. Trees default to this checkout; pass a second worktree at an older commit to
get before/after ratios from the same run (the machines are shared and noisy: rounds
interleave the trees, numbers are medians, ratios are medians of per-round ratios).

Measured (2026-12-02, PoCL CPU, 2 cores shared with other jobs at load 7-10; --modes
render --repeats 3; before = 40b0be2, after = the per-path kriging cache of
render/kriging_cache.py; same run):
  scene              paths/s before -> after     paths/CPU-s before -> after   peak RSS
  posterior sphere   1783 -> 2197 (x1.29)        2918 -> 3360 (x1.16)          144 -> 147 MB
  ws_sphere_se       16450 -> 19590 (x1.06)      27900 -> 27930 (x1.01)        144 -> 145 MB
An earlier run of the same at load ~8 gave x1.09 (posterior sphere) and x0.92
(ws_sphere_se, whose code did not change: the wall-time noise). Solves of the posterior's
weights per path: 2.21 -> 0.88 (64x64, 4 spp; every ray that searched the object solved);
their share of the posterior sphere's render CPU before: ~31% (a build solving twice per
search took 3.3 s more CPU on 10.5 s, 128x128, 2 spp, medians of 3).

Peak RSS, every example scene, 4 spp at its own resolution (same run, medians of 3, MB):
before = 40b0be2, after = a5d5692 (render() frees its queues, function-space scratch and
rings before reading the film, malloc_trim, film.read in place: the peak was at the end):
  ws_* (7 scenes)           143-148 -> 141-142     fs_mirror_ball_sun     152 -> 147
  fs_sphere_matern32 / 52   159 / 161 -> 148 / 149  fs_sphere_se           166 -> 155
  csg_two_spheres / baked   170 / 169 -> 159 / 157  bunny_grid             175 -> 161
  wedge_volume              173 -> 162             fs_volume_room_global  174 -> 163
  knob_no_csg / knob        178 / 189 -> 168 / 178
The peak is now inside the render: ~133 MB before the first batch (fs_sphere_se: 81 MB of
file pages, libLLVM's text 42 of them, and 52 MB anonymous), then the queues (~12 MB
touched at 2^15 paths) and function-space scratch (15 MB allocated at 16 groups a unit).

Peak RSS, every example scene, 4 spp at its own resolution (2026-12-03, MB; before =
6d13af0, after = af7da05: function-space stages grid-stride at 4 groups a unit and 4 MB of
scratch, AOV queue fields of one element without AOVs, OpenEXR imported on use). ONE run
per scene and tree, same session, load ~4 (a full test suite alongside; the 3-round run was
cut short by the time limit; ws_sphere_rq/se and ws_volume_room by /usr/bin/time):
  ws_* (7 scenes)           140-142 -> 137-140     fs_mirror_ball_sun     150 -> 140
  fs_sphere_matern32 / 52   147 / 148 -> 144 / 144  fs_sphere_se           152 -> 144
  csg_two_spheres / baked   159 / 156 -> 149 / 153  bunny_grid             173 -> 165
  wedge_volume              162 -> 149             fs_volume_room_global  162 -> 153
  knob_no_csg / knob        167 / 180 -> 162 / 172
Queue pages touched follow the batch, which BatchSizer sizes from the throughput, so the
peak moves by a few MB with the machine's load. The knob's floor (measured in-process):
~116 MB after the Device (libLLVM 51 MB resident of which 8 relocated, libclang-cpp 17),
its grid records 18 MB (compile also peaks 20 MB above its result: HWM 162), ~6 MB per
built PoCL program (two), the film 4 MB, then ~11 MB in the render.

Peak RSS, every example scene, 4 spp at its own resolution (2026-12-03, MB, medians of 3,
same run, load 1.5-3.5; before = dbf1396, after = the render command dropping its
integrator before writing; both measured with the warm-up at the scene's own resolution,
so the before column is the steady state: bunny_grid's 165 above was a kernel compiled
inside its one measured round):
  ws_* (7 scenes)           137-139 -> 133-135     fs_mirror_ball_sun     137 -> 137
  fs_sphere_matern32 / 52   144 / 144 -> 143 / 144  fs_sphere_se           144 -> 146
  csg_two_spheres / baked   148 / 153 -> 150 / 148  bunny_grid             153 -> 153
  wedge_volume              148 -> 149             fs_volume_room_global  153 -> 153
  knob_no_csg / knob        162 / 171 -> 162 / 170
(+-2 MB between rounds of one tree; paths/CPU-s x0.94-1.06, noise: the render is the same
code.) The write phase was the peak of the ws_* scenes and csg_baked: the film's device
buffers and the scene's records stayed allocated under the PNG/EXR buffers. Every other
peak is inside the render (VmHWM at stages: the knob 115 MB after the Device, 142 after
compile (records 18.4, all tracemalloc finds kept), 158 after the two programs and the
film, 170 at the last batch: 21 MB of queues, rings and scratch at 2^15 paths). What did
not lower it: a fixed malloc mmap threshold (MALLOC_MMAP_THRESHOLD_=131072: the knob's
compile peak 162 -> 152 and its end 152 -> 134, the render's 170 unchanged: the queues
reuse the heap's free pages otherwise), MALLOC_ARENA_MAX=1, malloc_trim before the first
batch, building the programs from their binaries (no clang preprocessing: -1 MB a
program), the stage program without the weight-space kernels (-1 MB). A profiler that
imports pyopencl before gpiscl loads PyPI's PoCL as well (+21 MB: opencl_vendors.py).

Peak RSS, every example scene, 4 spp at its own resolution (2026-12-03, MB, medians of 3,
same run, load ~1-2; before = 0528d5b, after = CPU batch cap 2^14, global rings 8 MB, the
compile's freed heap handed back before the programs, grid checks and evaluations without
a float64 copy of the whole grid): paths per CPU s x0.97-1.05 (bunny_grid x0.92 here, x0.99
in a render-only A/B of 3 rounds at 8 spp):
  ws_* (7 scenes)           133-142 -> 133-141     fs_mirror_ball_sun     146 -> 141
  fs_sphere_matern32 / 52   151 / 150 -> 147 / 147  fs_sphere_se           153 -> 147
  csg_two_spheres / baked   159 / 150 -> 152 / 149  bunny_grid             156 -> 149
  wedge_volume              149 -> 142             fs_volume_room_global  153 -> 144
  knob_no_csg / knob        168 / 182 -> 162 / 172
(the before column is higher than the table above's: a quieter machine sizes larger
batches). What stays above 150 is fixed before the first path (in-process VmRSS): the
runtime 114 MB (Python + numpy + pyopencl 37, PoCL's LLVM 15 and clang mapped and
relocated 77: libLLVM 42-51 MB resident from its load alone), ~8 MB of libraries a compile
touches (OpenEXR for the sky, libcrypto for the bake keys), the grid records (knob 19.3 MB,
knob_no_csg 9.7), the two programs' LLVM modules (~6.5 MB each: PoCL keeps a program's
bitcode parsed while it lives) and the film (4 MB): 149 MB for knob_no_csg and 159 MB for
the knob before any queue. PyPI's PoCL 3.0 (LLVM linked in, 21 MB resident) builds this
project's programs with no kernels on this machine (render/device.py now says so).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENES = ("scenes/ws_sphere_se.json", "scenes/ws_sphere_rq.json", "posterior_sphere",
                  "scenes/knob.json")


def posterior_sphere(folder: Path) -> Path:
    """ws_sphere_se with its mean widened to radius 1.1 and conditioned on 100 points of
    the unit sphere (noise 5% of sigma): a weight-space posterior like
    tests/test_ws_posterior.py renders."""
    scene = json.loads((ROOT / "scenes/ws_sphere_se.json").read_text())
    g = next(s for s in scene["shapes"] if s["type"] == "gpis")
    n = 100
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z * z)
    pts = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    np.savetxt(folder / "posterior_sphere.xyz", pts)
    g["mean"]["radius"] = 1.1
    g["observations"] = {"file": str(folder / "posterior_sphere.xyz"),
                         "noise": 0.05 * g["kernel"]["sigma"]}
    path = folder / "posterior_sphere.json"
    path.write_text(json.dumps(scene))
    return path


def run(tree: Path, scene: Path, args: list, env: dict, out: Path):
    """(wall seconds, peak RSS MB, CLI output, CPU seconds) of one render process."""
    env = dict(os.environ, **env, PYTHONPATH=str(tree))
    t = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "gpiscl", "render", str(scene), *args,
                          "-o", str(out)], cwd=tree, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    text = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode:
        raise RuntimeError(f"{scene} in {tree} failed:\n{text}")
    return wall, usage.ru_maxrss / 1024.0, text, usage.ru_utime + usage.ru_stime


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=DEFAULT_SCENES)
    ap.add_argument("--trees", default=str(ROOT), help="comma-separated source trees")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spp", type=int, default=4, help="samples per pixel of 'render'")
    ap.add_argument("--modes", default="render,first,cold,warm")
    args = ap.parse_args(argv)
    trees = [Path(t).resolve() for t in args.trees.split(",")]
    modes = args.modes.split(",")
    tmp = Path(tempfile.mkdtemp(prefix="gpiscl-bench-scenes-"))
    try:
        scenes = [posterior_sphere(tmp) if s == "posterior_sphere" else Path(s).resolve()
                  for s in args.scenes]
        # per tree: a PoCL cache kept warm across rounds, and a bake cache for 'warm'
        caches = {t: (tmp / f"pocl{i}", tmp / f"bake{i}") for i, t in enumerate(trees)}
        results = {}   # (scene, mode, tree) -> list of (value, rss)
        cpu_rates = {}   # (scene, tree) -> paths per CPU second of each 'render' round
        small = ["--resolution", "16x16", "--spp", "1"]
        if "render" in modes:
            # 'render' is the steady state: the first-ever PoCL compile (~150 MB of LLVM
            # and 10 s) and the bakes are the 'first' and 'cold' modes' business, so a
            # render per scene and tree fills both caches before the rounds. At the
            # scene's own resolution: the accumulate kernel spans every pixel, and PoCL
            # builds another variant of a kernel for a large launch (its cache held
            # accumulate twice, "64-1-1-goffs0" and "...-smallgrid").
            for scene in scenes:
                for tree in trees:
                    pocl, bake = caches[tree]
                    run(tree, scene, ["--spp", "1"], {"POCL_CACHE_DIR": str(pocl),
                                                      "GPISCL_CACHE": str(bake)},
                        tmp / "out.png")
        for rnd in range(args.repeats):
            for scene in scenes:
                for mode in modes:
                    for tree in trees:
                        pocl, bake = caches[tree]
                        out = tmp / "out.png"
                        extra = ""
                        if mode == "render":
                            env = {"POCL_CACHE_DIR": str(pocl), "GPISCL_CACHE": str(bake)}
                            wall, rss, text, cpu = run(tree, scene, ["--spp", str(args.spp)],
                                                       env, out)
                            m = re.search(r"paths/s: ([0-9.e+]+)", text)
                            value = float(m.group(1))
                            paths = int(re.search(r"paths: ([0-9]+)", text).group(1))
                            cpu_rates.setdefault((scene, tree), []).append(paths / cpu)
                            extra = f", {paths / cpu:.4g} paths/CPU-s"
                        else:
                            fresh = tmp / f"fresh{rnd}"
                            shutil.rmtree(fresh, ignore_errors=True)
                            env = {"POCL_CACHE_DIR": str(fresh / "pocl" if mode == "first"
                                                         else pocl),
                                   "GPISCL_CACHE": str(bake if mode == "warm"
                                                       else fresh / "bake")}
                            if mode == "first":
                                env["PYOPENCL_NO_CACHE"] = "1"
                            if mode != "first":   # PoCL's cache (and, warm, the bakes')
                                run(tree, scene, small, env, out)   # holds this scene
                                shutil.rmtree(fresh / "bake", ignore_errors=True)
                            value, rss, _, _ = run(tree, scene, small, env, out)
                        results.setdefault((scene, mode, tree), []).append((value, rss))
                        print(f"  round {rnd} {scene.name} {mode} {tree.name}: {value:.4g} "
                              f"{'paths/s' if mode == 'render' else 's'}, {rss:.0f} MB{extra}",
                              file=sys.stderr)
        print(f"medians of {args.repeats} rounds; trees: "
              + ", ".join(f"[{i}] {t}" for i, t in enumerate(trees)))
        for scene in scenes:
            for mode in modes:
                cells = []
                for i, tree in enumerate(trees):
                    vals = results[(scene, mode, tree)]
                    v = statistics.median(x for x, _ in vals)
                    rss = statistics.median(r for _, r in vals)
                    unit = "paths/s" if mode == "render" else "s"
                    cell = f"[{i}] {v:9.4g} {unit} {rss:5.0f} MB"
                    if i > 0:
                        base = results[(scene, mode, trees[0])]
                        ratio = statistics.median(x / b for (x, _), (b, _) in zip(vals, base))
                        cell += f" (x{ratio:.2f} of [0])"
                    cells.append(cell)
                print(f"{scene.name:24s} {mode:6s} " + "   ".join(cells))
            if "render" in modes:
                cells = []
                for i, tree in enumerate(trees):
                    vals = cpu_rates[(scene, tree)]
                    cell = f"[{i}] {statistics.median(vals):9.4g} paths/CPU-s"
                    if i > 0:
                        ratio = statistics.median(
                            x / b for x, b in zip(vals, cpu_rates[(scene, trees[0])]))
                        cell += f" (x{ratio:.2f} of [0])"
                    cells.append(cell)
                print(f"{scene.name:24s} {'cpu':6s} " + "   ".join(cells))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
