"""Where a cold start's OpenCL compile goes, per scene kind.

    python tools/bench_compile.py [SCENE ...]

For each scene, in a fresh process with an empty PoCL kernel cache (POCL_CACHE_DIR, a new
temporary folder) a 16x16, 1-spp render runs while this tool records:
  * the program sources: bytes and lines of each program the render builds (the stage
    program, the function-space one when used) and their -D options;
  * clBuildProgram (front end: preprocess, parse, LLVM IR, builtin library linked):
    seconds per program, timed around render.device.Program._build;
  * PoCL's work-group compiles, done when a kernel is first enqueued with a local size:
    one shared object per (kernel, local size, specialisation) in PoCL's cache, listed
    with its write time, so consecutive writes give each one's compile time (PoCL
    compiles them one at a time), and how many variants each kernel got;
  * the whole process wall time, for the rest (imports, scene preparation, rendering).
Run it twice with the same scene to see PoCL's cache hit path. The machines are shared:
compile times are single runs, trust their proportions more than their values.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, os, sys, time
t_start = time.perf_counter()
from gpiscl.host.render import device as D
builds = []
orig = D.Program._build
def timed(self, device, opts):
    t = time.perf_counter()
    out = orig(self, device, opts)
    builds.append({"bytes": len(self.source), "lines": self.source.count("\n"),
                   "options": [o for o in opts if o.startswith("-D")],
                   "kernels": len(out), "seconds": time.perf_counter() - t,
                   "at": time.time()})
    return out
D.Program._build = timed
from gpiscl import render_result
t_render = time.perf_counter()
res = render_result(sys.argv[1], resolution=(16, 16), spp=1)
print(json.dumps({"builds": builds, "render_call": time.perf_counter() - t_render,
                  "process": time.perf_counter() - t_start, "end": time.time()}))
"""


def main(argv=None):
    scenes = (argv if argv is not None else sys.argv[1:]) or ["scenes/ws_sphere_se.json"]
    for scene in scenes:
        with tempfile.TemporaryDirectory() as tmp:
            env = dict(os.environ, POCL_CACHE_DIR=tmp, PYTHONPATH=str(ROOT),
                       GPISCL_CACHE=os.environ.get("GPISCL_CACHE", str(Path(tmp) / "bakes")))
            t0 = time.time()
            p = subprocess.run([sys.executable, "-c", CHILD, str(Path(scene).resolve())],
                               cwd=ROOT, env=env, capture_output=True, text=True)
            if p.returncode:
                print(p.stdout, p.stderr)
                continue
            info = json.loads(p.stdout.strip().splitlines()[-1])
            objs = sorted((f.stat().st_mtime, f) for f in Path(tmp).rglob("*.so"))
            print(f"\n{scene}: process {info['process']:.2f} s, render call "
                  f"{info['render_call']:.2f} s (includes the builds and WG compiles)")
            for b in info["builds"]:
                print(f"  clBuildProgram {b['seconds']:6.2f} s  {b['bytes'] / 1024:7.1f} KiB "
                      f"{b['lines']:6d} lines  {b['kernels']:3d} kernels  {' '.join(b['options'])}")
            last = max(b["at"] for b in info["builds"]) if info["builds"] else t0
            per_kernel = {}
            prev = last
            for mtime, f in objs:
                name = f"{f.parent.parent.name} [{f.parent.name}]"
                per_kernel.setdefault(name, []).append(mtime - prev)
                prev = mtime
            total = sum(sum(v) for v in per_kernel.values())
            print(f"  work-group compiles: {len(objs)} shared objects, {total:.2f} s "
                  f"(write-time gaps after the last build)")
            for name, gaps in sorted(per_kernel.items(), key=lambda kv: -sum(kv[1])):
                print(f"    {name:40s} {len(gaps)} variant(s) {sum(gaps):6.2f} s")


if __name__ == "__main__":
    main()
