"""Does a change move an image beyond noise? The same scene rendered by two source trees
(one process each, the same seed), compared per image and per block.

    python tools/paired_renders.py TREE_A TREE_B [--scenes ...] [--resolution 24]
        [--spp 2048] [--seeds 11 12] [--block 4]

Per scene and seed: each tree's image mean, B / A - 1, the z of the difference with
each image's own standard error (independent errors assumed: paths that take the same
steps in both trees are correlated, so this z is conservative) and the largest |z| over
blocks x blocks tiles with the Bonferroni threshold for their count (stats.z_threshold).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gpiscl.testing.stats import block_means, image_mean_se, z_threshold  # noqa: E402

CHILD = r"""
import copy, sys
import numpy as np
from gpiscl.host.render.device import Device
from gpiscl.host.render.integrator import WavefrontIntegrator
from gpiscl.host.scene.loading import load_scene
from gpiscl.host.compile.scene import compile_scene
path, res, spp, seed, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
data = copy.deepcopy(load_scene(path).data)
data["camera"]["resolution"] = [res, res]
data["render"]["seed"] = seed
image = WavefrontIntegrator(Device(None), compile_scene(load_scene(data).data), data["render"],
                            None).render(spp).image
np.savez(out, mean=image.mean.mean(axis=2), stderr=image.stderr.mean(axis=2))
"""


def render(tree: Path, scene: str, res: int, spp: int, seed: int, folder: str):
    out = os.path.join(folder, f"{tree.name}-{Path(scene).stem}-{seed}.npz")
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, "-c", CHILD, str(tree / scene), str(res), str(spp),
                    str(seed), out], check=True, env=env, cwd=str(tree),
                   stderr=subprocess.DEVNULL)
    d = np.load(out)
    return d["mean"], d["stderr"]


def compare(a, b, block):
    (ma, sa), (mb, sb) = a, b
    mean_a, mean_b = float(ma.mean()), float(mb.mean())
    se = float(np.hypot(image_mean_se(sa), image_mean_se(sb)))
    ba, bsa = block_means(ma, sa, block)
    bb, bsb = block_means(mb, sb, block)
    zb = (bb - ba) / np.maximum(np.hypot(bsa, bsb), 1e-30)
    return {"mean_a": mean_a, "mean_b": mean_b, "rel": mean_b / mean_a - 1.0,
            "z": (mean_b - mean_a) / se, "block_z_max": float(np.abs(zb).max()),
            "block_threshold": z_threshold(zb.size)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs=2, type=Path)
    ap.add_argument("--scenes", nargs="*", default=["scenes/knob.json"])
    ap.add_argument("--resolution", type=int, default=24)
    ap.add_argument("--spp", type=int, default=2048)
    ap.add_argument("--seeds", type=int, nargs="*", default=[11, 12])
    ap.add_argument("--block", type=int, default=4)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for scene in args.scenes:
            for seed in args.seeds:
                a, b = (render(t.resolve(), scene, args.resolution, args.spp, seed, folder)
                        for t in args.trees)
                r = compare(a, b, args.block)
                print(f"{Path(scene).stem} seed {seed}: A {r['mean_a']:.6g}  B {r['mean_b']:.6g}"
                      f"  B/A-1 {r['rel']:+.4%}  z {r['z']:+.2f}  block |z| max "
                      f"{r['block_z_max']:.2f} (threshold {r['block_threshold']:.2f})",
                      flush=True)
                print(json.dumps({"scene": scene, "seed": seed, **r}), file=sys.stderr)


if __name__ == "__main__":
    main()
