"""Same-run A/B of render speed between source trees: paths per CPU second of the render
alone (time.process_time around WavefrontIntegrator.render: PoCL's CPU threads run in the
process), each tree in its own process per round, rounds interleaving the trees.

    python tools/ab_render_rate.py TREE_A TREE_B [--scenes ...] [--resolution 32]
        [--spp 8] [--rounds 3] [--step-corr C]

Prints per scene the median paths per CPU s of each tree and the median of the per-round
ratios B / A (the machines are shared: ratios from one round are steadier than rates).
--step-corr C puts every function-space object on the uniform step of correlation C.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

SCENES = ("scenes/knob.json", "scenes/knob_no_csg.json", "scenes/csg_baked.json",
          "scenes/bunny_grid.json")

CHILD = r"""
import copy, sys, time
from gpiscl.host.layout import records as layouts
from gpiscl.host.render.device import Device
from gpiscl.host.render.integrator import WavefrontIntegrator
from gpiscl.host.scene.loading import load_scene
from gpiscl.host.compile.scene import compile_scene
path, res, spp, corr = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
data = copy.deepcopy(load_scene(path).data)
data["camera"]["resolution"] = [res, res]
scene = compile_scene(load_scene(data).data)
if corr > 0:
    objs = scene.gpis.objects
    objs["step_corr"][objs["sampler"] == layouts.GPIS_SAMPLERS["function_space"]] = corr
dev = Device(None)
WavefrontIntegrator(dev, scene, data["render"], None).render(1)
integ = WavefrontIntegrator(dev, scene, data["render"], None)
t = time.process_time()
r = integ.render(spp)
print(r.stats.paths / (time.process_time() - t))
"""


def rate(tree: Path, scene: Path, args) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(args.resolution),
                          str(args.spp), str(args.step_corr)], env=env, cwd=tree,
                         capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs=2, type=Path)
    ap.add_argument("--scenes", nargs="*", default=SCENES)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--step-corr", type=float, default=0.0)
    args = ap.parse_args()
    a, b = (t.resolve() for t in args.trees)
    for s in args.scenes:
        ra, rb, ratio = [], [], []
        for _ in range(args.rounds):
            x, y = rate(a, a / s, args), rate(b, b / s, args)
            ra.append(x)
            rb.append(y)
            ratio.append(y / x)
        med = statistics.median
        print(f"{Path(s).stem:14s} A {med(ra):.4g}  B {med(rb):.4g}  B/A {med(ratio):.3f} "
              f"({min(ratio):.2f}-{max(ratio):.2f})", flush=True)


if __name__ == "__main__":
    main()
