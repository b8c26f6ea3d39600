"""gpiscl render: api.render_result, then api.write_image; a stop signal after compiling
ends the render and the samples so far are written (gpiscl/signals.py)."""
from __future__ import annotations

import sys

from .. import api, signals
from .args import add_scene_options, int_or_none, scene_of, settings_of


def add_parser(sub):
    r = sub.add_parser("render", help="render a scene to EXR + PNG")
    add_scene_options(r, "samples")
    r.add_argument("-o", "--output", default="out.exr",
                   help="NAME.exr: EXR + PNG preview + NAME.scene.json; NAME.png: the PNG "
                   "preview + NAME.scene.json (default out.exr)")
    r.add_argument("--spp", type=int, help="samples per pixel")
    r.add_argument("--realization", type=int_or_none, metavar="R",
                   help="render one fixed GPIS realization R for every pixel (weight space); "
                   "'none' averages over realizations whatever the scene says")
    r.add_argument("--time-limit", type=float, metavar="SECONDS",
                   help="stop after this many seconds of rendering, up to 1e9 (to within "
                   "one bounce of a batch, well under a second)")
    r.add_argument("--batch-size", type=int, metavar="N",
                   help="the most paths in flight per batch (batches are sized to take "
                   "~0.5 s each below it; default 16384 on a CPU, 262144 elsewhere)")
    r.add_argument("--tonemap", choices=("clamp", "filmic"),
                   help="PNG preview curve (default: the scene's render.tonemap)")
    r.add_argument("--stats", action="store_true", help="print per-kernel timings")
    r.add_argument("--aov", metavar="LIST",
                   help="also write first-hit AOVs as EXR layers, for denoisers: any of "
                   "depth,normal,albedo,position")
    r.add_argument("--max-memory", metavar="SIZE",
                   help="memory the render may use (e.g. 8G), instead of the estimate of "
                   "free memory it is checked against before rendering")
    return r


def run(a) -> int:
    scene = scene_of(a).with_overrides(tonemap=a.tonemap)
    api.check_output(a.output, scene, a.aov, a.exposure)   # before any work
    with signals.rendering() as compiled:
        def banner(scene, where):
            w, h = scene.data["camera"]["resolution"]
            print(f"rendering {scene.source} at {w}x{h}, {scene.data['render']['spp']} spp "
                  f"on {where}", file=sys.stderr)
            compiled()   # after compiling: a scene refused there is still one line

        result = api.render_result(
            scene, spp=a.spp, seed=a.seed, resolution=a.resolution, device=a.device,
            batch_size=a.batch_size, time_limit=a.time_limit, progress=True,
            realization=a.realization, stop=signals.requested, max_memory=a.max_memory,
            aov=a.aov, cluster=a.cluster, on_compiled=banner, settings=settings_of(a))
        st, stopped_by = result.stats, signals.received()
        if st.paths == 0:
            print(f"interrupted by {signals.name(stopped_by)} before the first samples: "
                  f"nothing written", file=sys.stderr)
            return signals.exit_code(stopped_by)
        with signals.writing():
            paths = api.write_image(a.output, result, a.exposure)
        # still noting: a signal now only changes the exit code, the files are written
        return report(result, paths, signals.received(), a.stats)


def report(result, paths: dict, stopped_by, kernel_table: bool) -> int:
    st = result.stats
    reached = f"{st.spp_reached:.4g} of {st.spp_requested} spp"
    if stopped_by is not None:
        print(f"interrupted by {signals.name(stopped_by)} at {reached}", file=sys.stderr)
    elif st.time_limited:
        print(f"time limit: stopped at {reached}", file=sys.stderr)
    elif st.interrupted:
        print(f"interrupted at {reached}", file=sys.stderr)
    uncovered = int((result.image.count == 0).sum())
    if uncovered:
        print(f"{uncovered} of {result.image.count.size} pixels have no sample yet: 0 in the "
              "EXR's 'samples' channel, magenta in the PNG preview", file=sys.stderr)
    print(st.summary(), file=sys.stderr)
    if kernel_table:
        print(st.kernel_table, file=sys.stderr)
    print("wrote " + ", ".join(str(p) for p in paths.values() if p is not None),
          file=sys.stderr)
    if getattr(st, "lost", None):    # the cluster failed: the image is what it merged
        return 1
    return 0 if stopped_by is None else signals.exit_code(stopped_by)
