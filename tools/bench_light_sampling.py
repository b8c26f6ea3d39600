"""Light sampling (docs/design/light-sampling.md) against earlier trees, same run.

    python tools/bench_light_sampling.py [--baseline /work/wt/baseline ...] [--rounds 1]
        [--resolution 32] [--spp 64] [--reference-spp 2048] [--cornell-spp 16] [scenes...]

Each tree renders in its own process (PYTHONPATH = that tree). Per scene: a converged
reference (this tree, --reference-spp, its own seed); per tree, at --spp: the per-sample
variance svar (mean over pixels and channels of stderr^2 * spp), MSE*spp against the
reference (less the reference's own variance), and paths per second of the render's own
process CPU time (PoCL's threads run in it: steadier than wall time on a shared machine).
Ratios are base / new (> 1: the new tree is better); each --baseline (repeatable) is
compared with this tree. The MSE at equal time is MSE*spp times CPU seconds per path,
i.e. the error each tree reaches in the same time (the renders are too short on this
shared machine for a fixed time limit to be fair to both). --rounds N renders every tree
N times, the trees interleaved (their order rotates each round), round r with seed 1 + r,
and prints the median over rounds of each per-round ratio, with its range. Fireflies: in
the default Cornell box at its own resolution and --cornell-spp, the share of pixels whose
luminance is more than 3x the median of their 5x5 neighbourhood. The image means against
the reference (z, from both standard errors) check that the trees agree.
Scenes: "cornell" (the built-in default scene), "sun_sky_floor" and "mirror_ball_map"
(below; the latter not by default), or scene files.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("cornell", "scenes/fs_sphere_se.json", "scenes/knob.json",
          "scenes/csg_two_spheres.json", "sun_sky_floor")


def mirror_ball_map() -> dict:
    """fs_mirror_ball_sun's function-space mirror ball under the sky map instead."""
    scene = json.loads((ROOT / "scenes" / "fs_mirror_ball_sun.json").read_text())
    scene["lights"] = [{"type": "environment_map",
                        "file": str(ROOT / "scenes" / "assets" / "sky.exr")}]
    return scene


def _scene(name: str):
    if name == "sun_sky_floor":
        from gpiscl.testing.scenes import sun_sky_floor
        return sun_sky_floor(resolution=32, seed=1, max_depth=6)
    if name == "mirror_ball_map":
        return mirror_ball_map()
    if name == "cornell":
        from gpiscl.scenes import default_scene
        return default_scene()
    return str(ROOT / name)


def worker(args):
    """In the tree on PYTHONPATH: render and save mean, stderr, seconds, paths."""
    from gpiscl import render_result
    res = None if args.full_resolution else (args.resolution, args.resolution)
    render_result(_scene(args.scene), spp=1, seed=7, resolution=(8, 8))   # compile
    t = time.process_time()
    r = render_result(_scene(args.scene), spp=args.spp, seed=args.seed, resolution=res)
    seconds = time.process_time() - t
    np.savez(args.out, mean=r.image.mean, stderr=r.image.stderr, seconds=seconds,
             paths=r.stats.paths)


def _render(tree: Path, scene, spp, seed, resolution, full=False):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.npz"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--scene", scene,
               "--spp", str(spp), "--seed", str(seed), "--resolution", str(resolution),
               "--out", str(out)] + (["--full-resolution"] if full else [])
        env = dict(os.environ, PYTHONPATH=str(tree))
        subprocess.run(cmd, check=True, env=env, cwd=str(tree))
        with np.load(out) as z:
            return {k: z[k] for k in z.files}


def fireflies(mean) -> float:
    lum = mean.mean(axis=2)
    h, w = lum.shape
    pad = np.pad(lum, 2, mode="edge")
    windows = np.stack([pad[i:i + h, j:j + w] for i in range(5) for j in range(5)])
    med = np.median(windows, axis=0)
    return float(np.mean(lum > 3.0 * np.maximum(med, 1e-6)))


def metrics(r, ref, spp) -> dict:
    svar = float((r["stderr"] ** 2).mean() * spp)
    mse = float(((r["mean"] - ref["mean"]) ** 2 - ref["stderr"] ** 2).mean())
    sec_per_path = float(r["seconds"]) / float(r["paths"])
    diff = float(r["mean"].mean() - ref["mean"].mean())
    se = float(np.sqrt(((r["stderr"].sum(-1) ** 2).sum()
                        + (ref["stderr"].sum(-1) ** 2).sum())) / r["mean"].size)
    return {"svar": svar, "mse_spp": mse * spp, "paths_s": 1 / sec_per_path,
            "mse_time": mse * spp * sec_per_path, "z": diff / se}


RATIOS = {"var_ratio": lambda b, n: b["svar"] / n["svar"],
          "mse_spp_ratio": lambda b, n: b["mse_spp"] / n["mse_spp"],
          "mse_time_ratio": lambda b, n: b["mse_time"] / n["mse_time"],
          "speed_ratio": lambda b, n: n["paths_s"] / b["paths_s"]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--baseline", action="append", default=None,
                    help="an earlier tree (repeatable; default /work/wt/baseline)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--reference-spp", type=int, default=2048)
    ap.add_argument("--cornell-spp", type=int, default=16)
    ap.add_argument("--worker", action="store_true")
    ap.add_argument("--full-resolution", action="store_true")
    ap.add_argument("--scene"), ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out")
    args = ap.parse_args()
    if args.worker:
        return worker(args)
    bases = [Path(b) for b in (args.baseline or ["/work/wt/baseline"])]
    trees = {**{str(b): b for b in bases}, "new": ROOT}
    names = list(trees)
    rows = []
    for scene in args.scenes:
        ref = _render(ROOT, scene, args.reference_spp, 99, args.resolution)
        runs = {name: [] for name in names}
        for k in range(args.rounds):
            for name in names[k % len(names):] + names[:k % len(names)]:
                r = _render(trees[name], scene, args.spp, 1 + k, args.resolution)
                runs[name].append(metrics(r, ref, args.spp))
        med = statistics.median
        for base in names[:-1]:
            row = {"scene": scene, "base": base, "rounds": args.rounds,
                   "base_runs": runs[base], "new_runs": runs["new"]}
            for key, ratio in RATIOS.items():
                per_round = [ratio(b, n) for b, n in zip(runs[base], runs["new"])]
                row[key] = med(per_round)
                row[key + "_range"] = (min(per_round), max(per_round))
            rows.append(row)
            zb = med(x["z"] for x in runs[base])
            zn = med(x["z"] for x in runs["new"])
            print(f"{scene:30s} vs {base}: var {row['var_ratio']:6.2f}x  MSE@spp "
                  f"{row['mse_spp_ratio']:6.2f}x  MSE@time {row['mse_time_ratio']:7.2f}x  "
                  f"paths/s {row['speed_ratio']:5.3f} ({row['speed_ratio_range'][0]:.3f}-"
                  f"{row['speed_ratio_range'][1]:.3f})  z base {zb:+.2f} new {zn:+.2f}",
                  flush=True)
    if "cornell" in args.scenes:
        for name, tree in trees.items():
            r = _render(tree, "cornell", args.cornell_spp, 1, 0, full=True)
            print(f"cornell fireflies ({name}, {args.cornell_spp} spp): "
                  f"{100 * fireflies(r['mean']):.3f} % of pixels", flush=True)
    print(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
