"""Paths per second of this tree's CLI against an earlier release's, each rendering its
own copy of the scene file (the release's files may differ; its CLI is the only interface
both trees share), rounds interleaving the trees (their order alternates).

    python tools/bench_against_release.py RELEASE_TREE [--scenes ...] [--spp 8]
        [--rounds 3]

Prints per scene each tree's median of the CLI's "paths/s" (render wall time: run it on
an otherwise idle machine) and the median of the per-round ratios this / release. Issue
33 measured the release before the exact default, 2771e1d: `git worktree add --detach
/tmp/rel 2771e1d`.
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("scenes/knob.json", "scenes/knob_no_csg.json", "scenes/csg_baked.json",
          "scenes/bunny_grid.json")


def rate(tree: Path, scene: str, spp: int, out: Path) -> float:
    """The CLI's paths/s for `scene` (relative to tree) rendered by tree's gpiscl."""
    r = subprocess.run([sys.executable, "-m", "gpiscl", "render", scene, "--spp", str(spp),
                        "-o", str(out)], cwd=tree, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(tree)))
    found = re.search(r"paths/s: ([0-9.e+-]+)", r.stdout + r.stderr)
    if r.returncode or not found:
        sys.exit(f"{tree}: {scene} failed (exit {r.returncode}):\n{r.stderr[-2000:]}")
    return float(found.group(1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("release", type=Path)
    ap.add_argument("--scenes", nargs="*", default=SCENES)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    trees = {"this": ROOT, "release": args.release.resolve()}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in args.scenes:
            rates = {name: [] for name in trees}
            for k in range(args.rounds):
                order = list(trees) if k % 2 == 0 else list(trees)[::-1]
                for name in order:
                    rates[name].append(rate(trees[name], scene, args.spp,
                                            Path(tmp) / f"{name}.exr"))
            ratios = [a / b for a, b in zip(rates["this"], rates["release"])]
            print(f"{Path(scene).stem:14s} this {statistics.median(rates['this']):.3e}  "
                  f"release {statistics.median(rates['release']):.3e}  this / release "
                  f"{statistics.median(ratios):.3f} ({min(ratios):.2f}-{max(ratios):.2f})",
                  flush=True)


if __name__ == "__main__":
    main()
