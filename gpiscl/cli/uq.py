"""gpiscl uq: api.uq (a stop signal keeps the completed realizations) then api.write_uq;
or api.uq_merge of partial sums from earlier runs."""
from __future__ import annotations

import sys

from .. import api, signals
from .args import add_scene_options, scene_of, settings_of


def add_parser(sub):
    u = sub.add_parser("uq", help="per-pixel mean and variance over GPIS realizations",
                       description="Render N weight-space realizations with K samples each; "
                       "write the mean, the unbiased between-realization variance (Monte "
                       "Carlo noise removed, not clamped), std and standard errors.")
    add_scene_options(u, "realizations")
    u.add_argument("-o", "--output", default="uq.exr", help="output EXR (default uq.exr)")
    u.add_argument("--realizations", type=int, default=16, metavar="N",
                   help="number of realizations (default 16)")
    u.add_argument("--spp", type=int, default=16, metavar="K",
                   help="samples per pixel per realization, >= 2 (default 16)")
    u.add_argument("--first", type=int, default=0, metavar="I",
                   help="index of the first realization: batches [I, I+N) of one seed "
                   "merge with --merge (default 0)")
    u.add_argument("--merge", nargs="+", metavar="NPZ", dest="partials",
                   help="merge these .uq.npz partial sums (and render nothing)")
    u.add_argument("--batch-size", type=int, metavar="N",
                   help="the most paths in flight per batch")
    return u


def run(a) -> int:
    if a.partials:
        sums, paths = api.uq_merge(a.partials, a.output, a.exposure)
        print(f"merged {sums.n} realizations; wrote {', '.join(map(str, paths.values()))}",
              file=sys.stderr)
        return 0
    scene = scene_of(a)
    api.check_uq_output(a.output, scene, a.exposure)   # before any work
    with signals.rendering() as started:
        def banner(scene, where):
            print(f"uq: {a.realizations} realizations x {a.spp} spp of {scene.source} on "
                  f"{where}", file=sys.stderr)
            started()

        run = api.uq(scene, a.realizations, a.spp, seed=a.seed,
                     first=a.first, resolution=a.resolution, device=a.device,
                     batch_size=a.batch_size, exposure=a.exposure, stop=signals.requested,
                     cluster=a.cluster, progress=True, on_started=banner,
                     settings=settings_of(a))
        n, stopped_by = run.sums.n, signals.received()
        code = 0 if stopped_by is None else signals.exit_code(stopped_by)
        if run.interrupted:
            print(f"interrupted: keeping the {n} completed realizations", file=sys.stderr)
        if n == 0:
            if stopped_by is not None:
                print("no realization completed: nothing written", file=sys.stderr)
            return code or 1
        print(f"{n} realizations in {run.seconds:.2f} s ({n / run.seconds:.3g} "
              f"realizations/s, {run.paths / run.seconds:.4g} paths/s)", file=sys.stderr)
        if a.cluster:
            print(run.cluster.table(), file=sys.stderr)
        with signals.writing():
            paths = api.write_uq(a.output, run, a.exposure)
        if n < 2:
            print(f"one realization has no variance; wrote its partial sums {paths['sums']} "
                  "(combine with: uq --merge)", file=sys.stderr)
        else:
            print(f"wrote {', '.join(map(str, paths.values()))}", file=sys.stderr)
        return code
