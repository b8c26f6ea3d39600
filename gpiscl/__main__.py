"""Command line: python -m gpiscl render|uq|sample|devices ..."""
from __future__ import annotations

if __name__ == "__main__":
    # first, so that a signal during the imports below (pyopencl, numpy: ~1 s) already
    # finds the handlers: one line and exit code 130/143/129, not a traceback
    from . import signals as _signals
    _signals.install()

import argparse
import importlib
import copy
import math
import sys
from pathlib import Path

from . import __version__
# Only what every command needs: each command imports the rest, so that convert-vdb runs
# under a Python that has numpy and an OpenVDB binding but no pyopencl or OpenEXR (the
# system Python with Debian's python3-openvdb).
from .host.errors import DeviceError, SceneError


def _resolution(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 512x512 (got {text!r})")


NO_REALIZATION = "none"


def _realization(text: str):
    if text.lower() == NO_REALIZATION:
        return NO_REALIZATION
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer or 'none', got '{text}'") from None


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer (got {text!r})")
    return v


def _seconds(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0 (got {text!r})")
    return v


def _size(text: str) -> int:
    from .host.render.memory import parse_size
    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _batch_size(text: str) -> int:
    from .host.scene.records import MAX_BATCH
    v = _positive_int(text)
    if v > MAX_BATCH:
        raise argparse.ArgumentTypeError(f"expected at most {MAX_BATCH} paths (got {text!r})")
    return v


class _Parser(argparse.ArgumentParser):
    """Usage mistakes as one line, like every other error (argparse prints the whole
    usage first); exit code 2 as before."""

    def error(self, message):
        self.exit(2, f"error: {self.prog}: {message} (see --help)\n")


def _parser() -> argparse.ArgumentParser:
    # the console script is `gpiscl`; `python -m gpiscl` runs this file
    prog = "gpiscl" if Path(sys.argv[0]).name == "gpiscl" else "python -m gpiscl"
    ap = _Parser(prog=prog, description="Render Gaussian Process Implicit Surfaces.")
    ap.add_argument("--version", action="version", version=f"gpiscl {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene to EXR + PNG")
    r.add_argument("scene", nargs="?", help="scene JSON file (default: the built-in scene)")
    r.add_argument("-o", "--output", default="out.exr",
                   help="NAME.exr: EXR + PNG preview + NAME.scene.json; NAME.png: the PNG "
                   "preview + NAME.scene.json (default out.exr)")
    r.add_argument("--spp", type=_positive_int, help="samples per pixel")
    r.add_argument("--seed", type=int, help="random seed")
    r.add_argument("--realization", type=_realization, metavar="R",
                   help="render one fixed GPIS realization R for every pixel (weight space); "
                   "'none' averages over realizations whatever the scene says")
    r.add_argument("--resolution", type=_resolution, help="WIDTHxHEIGHT")
    r.add_argument("--time-limit", type=_seconds, metavar="SECONDS",
                   help="stop after this many seconds of rendering (to within one batch, "
                   "~0.5 s)")
    r.add_argument("--device", help="OpenCL device: 'P:D' indices or a name fragment")
    r.add_argument("--batch-size", type=_batch_size, metavar="N",
                   help="the most paths in flight per batch (batches are sized to take "
                   "~0.5 s each below it; default 16384 on a CPU, 262144 elsewhere)")
    r.add_argument("--exposure", type=float, default=0.0, help="PNG preview exposure (stops)")
    r.add_argument("--tonemap", choices=("clamp", "filmic"),
                   help="PNG preview curve (default: the scene's render.tonemap)")
    r.add_argument("--stats", action="store_true", help="print per-kernel timings")
    r.add_argument("--aov", metavar="LIST",
                   help="also write first-hit AOVs as EXR layers, for denoisers: any of "
                   "depth,normal,albedo,position")
    r.add_argument("--max-memory", type=_size, metavar="SIZE",
                   help="memory the render may use (e.g. 8G), instead of the estimate of "
                   "free memory it is checked against before rendering")
    _add_cluster_option(r, "samples")
    sub.add_parser("devices", help="list OpenCL platforms and devices")
    _add_uq_parser(sub)
    _add_sample_parser(sub)
    v = sub.add_parser("convert-vdb", help="an OpenVDB grid to the .npz grid format",
                       description="Copy one float grid of a .vdb file to an .npz grid "
                       "(values, origin, voxel_size) usable as a grid mean. Needs OpenVDB's "
                       "Python binding.")
    v.add_argument("input", help=".vdb file")
    v.add_argument("output", help=".npz file to write")
    v.add_argument("--grid", help="grid name (default: the only grid, or 'density')")
    return ap


def _add_cluster_option(p, what):
    p.add_argument("--cluster", metavar="ADDRESS",
                   help=f"render the {what} on a Dask cluster: a running scheduler "
                   "(tcp://HOST:8786) or local:N (N worker processes for this run); the "
                   "same image bit for bit (needs: pip install 'gpiscl[distributed]')")


def _add_uq_parser(sub):
    u = sub.add_parser("uq", help="per-pixel mean and variance over GPIS realizations",
                       description="Render N weight-space realizations with K samples each; "
                       "write the mean, the unbiased between-realization variance (Monte "
                       "Carlo noise removed, not clamped), std and standard errors.")
    u.add_argument("scene", nargs="?", help="scene JSON file (default: the built-in scene)")
    u.add_argument("-o", "--output", default="uq.exr", help="output EXR (default uq.exr)")
    u.add_argument("--realizations", type=_positive_int, default=16, metavar="N",
                   help="number of realizations (default 16)")
    u.add_argument("--spp", type=_positive_int, default=16, metavar="K",
                   help="samples per pixel per realization, >= 2 (default 16)")
    u.add_argument("--seed", type=int, help="picks the realizations and their samples")
    u.add_argument("--first", type=int, default=0, metavar="I",
                   help="index of the first realization: batches [I, I+N) of one seed "
                   "merge with --merge (default 0)")
    u.add_argument("--merge", nargs="+", metavar="NPZ",
                   help="merge these .uq.npz partial sums (and render nothing)")
    u.add_argument("--resolution", type=_resolution, help="WIDTHxHEIGHT")
    u.add_argument("--device", help="OpenCL device: 'P:D' indices or a name fragment")
    u.add_argument("--batch-size", type=_batch_size, metavar="N",
                   help="the most paths in flight per batch")
    u.add_argument("--exposure", type=float, default=0.0, help="PNG preview exposure (stops)")
    _add_cluster_option(u, "realizations")


def _load(args):  # -> scene.loading.Scene (imported per command)
    from .host.scene.loading import load_scene
    if args.scene is None:
        from .scenes import default_scene
        return load_scene(default_scene())
    return load_scene(args.scene)


def cmd_render(args) -> int:
    from . import signals
    from .api import prepare_render
    from .host.render.device import Device
    from .host.scene import arguments
    from .host.scene.loading import Scene
    from .host.render.output import output_paths, write_outputs
    from .host.io.output_files import check_writable, scene_inputs
    from .host.render.progress import SppBar
    from .host.render.aov import parse as aov_names
    from .host.render.memory import return_freed_pages

    if args.cluster:
        importlib.import_module(f"{__package__}.host.commands.cluster")  # before any work: is Dask there?
    scene = _load(args)
    data = copy.deepcopy(scene.data)
    if args.resolution:
        data["camera"]["resolution"] = list(args.resolution)
    for key in ("spp", "seed", "realization", "tonemap"):
        if getattr(args, key) is not None:
            data["render"][key] = getattr(args, key)
    if args.realization == NO_REALIZATION:
        data["render"]["realization"] = None
    arguments.check(arguments.CLI_SOURCE, arguments.cli_name, spp=args.spp, seed=args.seed,
                    exposure=args.exposure, resolution=args.resolution, realization=None
                    if args.realization == NO_REALIZATION else args.realization)
    scene = Scene.resolved(data, scene.source, scene.base_dir)
    # before any work: a render must not end in 'cannot write' (output_files)
    check_writable(output_paths(args.output).values(), inputs=scene_inputs(scene))
    aovs = aov_names(args.aov) if args.aov is not None else ()
    if aovs and output_paths(args.output)["exr"] is None:
        raise SceneError("<command line>", "--aov", "AOVs are EXR layers: use -o NAME.exr")
    if aovs and args.cluster:
        # cluster units ship each path's radiance only (commands/cluster.py)
        raise SceneError("<command line>", "--aov", "not available with --cluster yet")
    device = Device(args.device)
    spp = data["render"]["spp"]
    w, h = data["camera"]["resolution"]
    integrator, _ = prepare_render(scene, device=device, batch_size=args.batch_size,
                             max_memory=args.max_memory, aov=bool(aovs))
    # after compiling, so that a scene refused there is still exactly one line
    where = f"the Dask cluster {args.cluster}" if args.cluster else device.name
    print(f"rendering {scene.source} at {w}x{h}, {spp} spp on {where}", file=sys.stderr)
    # from here on a stop signal ends the render and the samples so far are written
    with signals.noting():
        bar = SppBar(spp, w * h, file=sys.stderr) if sys.stderr.isatty() else None
        try:
            if args.cluster:
                from .host.commands.cluster import render_on_cluster
                result = render_on_cluster(args.cluster, integrator, scene, spp,
                                           args.time_limit, bar, signals.requested,
                                           arguments.CLI_SOURCE, "--cluster")
            else:
                result = integrator.render(spp, time_limit=args.time_limit, progress=bar,
                                           stop=signals.requested)
        finally:
            if bar:
                bar.close()
        # The film is on the host now: drop the integrator, so that its device buffers
        # (the film's sums, the scene's records: on a CPU device the process's own
        # memory, the film's in the malloc heap) are freed and handed back before the
        # output files' buffers are allocated. The peak RSS of csg_baked was there, 4 MB
        # above the render's (tools/bench_scenes.py).
        del integrator
        return_freed_pages()
        st = result.stats
        stopped_by = signals.received()
        reached = f"{st.spp_reached:.4g} of {spp} spp"
        if st.paths == 0:
            print(f"interrupted by {signals.name(stopped_by)} before the first samples: "
                  f"nothing written", file=sys.stderr)
            return signals.exit_code(stopped_by)
        with signals.writing():
            paths = write_outputs(result.image, scene, args.output, args.exposure, st, aovs)
        # still noting: a signal now only changes the exit code, the files are written
        stopped_by = signals.received()
        if stopped_by is not None:
            print(f"interrupted by {signals.name(stopped_by)} at {reached}", file=sys.stderr)
        elif st.time_limited:
            print(f"time limit: stopped at {reached}", file=sys.stderr)
        elif st.interrupted:
            print(f"interrupted at {reached}", file=sys.stderr)
        uncovered = int((result.image.count == 0).sum())
        if uncovered:
            print(f"{uncovered} of {w * h} pixels have no sample yet: 0 in the EXR's "
                  f"'samples' channel, magenta in the PNG preview", file=sys.stderr)
        print(st.summary(), file=sys.stderr)
        if args.stats:
            print(st.kernel_table, file=sys.stderr)
        print("wrote " + ", ".join(str(p) for p in paths.values() if p is not None),
              file=sys.stderr)
        if getattr(st, "lost", None):    # the cluster failed: the image is what it merged
            return 1
        return 0 if stopped_by is None else signals.exit_code(stopped_by)


def cmd_devices(_args) -> int:
    from .host.render.device import Device, list_devices
    default = None
    try:
        default = Device().device
    except DeviceError:
        pass
    found = list_devices()
    if not found:
        print("no OpenCL devices found; pip install 'pyopencl[pocl]' for the CPU runtime")
        return 1
    for pi, di, plat, dev in found:
        mark = "*" if default is not None and dev.int_ptr == default.int_ptr else " "
        kind = cl_type(dev)
        print(f"{mark} {pi}:{di}  {plat.name.strip()} / {dev.name.strip()}  [{kind}, "
              f"{dev.max_compute_units} compute units]")
    print("* default (override with --device P:D or PYOPENCL_CTX)")
    return 0


def cmd_uq(args) -> int:
    from . import signals
    from .host.render.device import Device
    from .host.scene import arguments
    from .host.io.output_files import check_writable, scene_inputs
    from .host.commands.uq import check_uq_scene, merge_partials, uq_output_paths, write_uq_outputs

    if args.cluster:
        importlib.import_module(f"{__package__}.host.commands.cluster")  # before any work: is Dask there?
    if args.merge:
        sums, meta = merge_partials(args.merge)
        if sums.n < 2:
            raise SceneError("<command line>", "--merge", "needs >= 2 realizations in all")
        check_writable(uq_output_paths(args.output).values(), inputs=args.merge)
        paths = write_uq_outputs(sums, None, args.output, args.exposure, meta)
        print(f"merged {sums.n} realizations; wrote {paths['exr']}", file=sys.stderr)
        return 0
    if args.spp < 2:
        raise SceneError("<command line>", "--spp", "must be >= 2: each realization needs a "
                         "sample variance to remove the Monte Carlo part")
    arguments.check(arguments.CLI_SOURCE, arguments.cli_name, spp=args.spp, seed=args.seed,
                    exposure=args.exposure, resolution=args.resolution)
    if args.first < 0:
        raise SceneError("<command line>", "--first", "must be >= 0")
    scene = _load(args)
    check_uq_scene(scene.data, scene.source)
    check_writable(uq_output_paths(args.output).values(), inputs=scene_inputs(scene))
    device = Device(args.device)
    n, k = args.realizations, args.spp
    where = f"the Dask cluster {args.cluster}" if args.cluster else device.name
    print(f"uq: {n} realizations x {k} spp of {scene.source} on {where}",
          file=sys.stderr)
    with signals.noting():
        return _uq_run(args, scene, device, n, k)


def _uq_run(args, scene, device, n, k) -> int:
    from .host.scene.loading import Scene
    from . import signals
    from .host.commands.uq import render_realizations, uq_output_paths, write_uq_outputs
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=n, unit="realization", file=sys.stderr, desc="realizations")
    try:
        if args.cluster:
            from .host.commands.cluster import uq_on_cluster
            run = uq_on_cluster(args.cluster, scene, n, k, seed=args.seed, first=args.first,
                                resolution=args.resolution, batch_size=args.batch_size,
                                progress=bar.update if bar else None,
                                stop=signals.requested, source="<command line>",
                                key="--cluster")
        else:
            run = render_realizations(scene, n, k, seed=args.seed, first=args.first,
                                      resolution=args.resolution, device=device,
                                      batch_size=args.batch_size,
                                      progress=bar.update if bar else None,
                                      stop=signals.requested)
    finally:
        if bar:
            bar.close()
    n = run.sums.n
    stopped_by = signals.received()
    code = 0 if stopped_by is None else signals.exit_code(stopped_by)
    if run.interrupted:
        print(f"interrupted: keeping the {n} completed realizations", file=sys.stderr)
    if n == 0:
        if stopped_by is not None:
            print("no realization completed: nothing written", file=sys.stderr)
        return code or 1
    print(f"{n} realizations in {run.seconds:.2f} s ({n / run.seconds:.3g} realizations/s, "
          f"{run.paths / run.seconds:.4g} paths/s)", file=sys.stderr)
    if args.cluster:
        print(run.cluster.table(), file=sys.stderr)
    if n < 2:   # a batch to merge later: no variance yet
        from .host.io.output_files import write_atomically
        path = uq_output_paths(args.output)["sums"]
        with signals.writing():
            write_atomically(path, lambda tmp: run.sums.save(tmp, run.meta))
        print(f"one realization has no variance; wrote its partial sums {path} "
              f"(combine with: uq --merge)", file=sys.stderr)
        return code
    data = copy.deepcopy(scene.data)
    if args.resolution:
        data["camera"]["resolution"] = list(args.resolution)
    with signals.writing():
        paths = write_uq_outputs(run.sums, Scene.resolved(data, scene.source, scene.base_dir),
                                 args.output, args.exposure, run.meta)
    print(f"wrote {paths['exr']}, {paths['png']}, {paths['std_png']}, {paths['sums']}",
          file=sys.stderr)
    return code


def _add_sample_parser(sub):
    s = sub.add_parser("sample", help="PNG figures of GPIS realizations (needs matplotlib)",
                       description="Figures of random geometry: realizations along a line "
                       "and on a slice, weight-space M features vs exact samples (Fig. 2), "
                       "prior occupancy P(f <= 0) for a scene's GPIS (Fig. 3). Needs the "
                       "optional extra: pip install -e '.[plots]'.")
    s.add_argument("target", metavar="KERNEL_OR_SCENE",
                   help="a kernel type (e.g. rational_quadratic), a kernel JSON object "
                   "(e.g. '{\"type\": \"rational_quadratic\", \"alpha\": 0.5}') or a scene file")
    s.add_argument("-o", "--output", default="figures", help="output folder (default figures)")
    s.add_argument("--object", type=int, default=0, help="which GPIS of a scene (default 0)")
    s.add_argument("--features", default="10,100,1000",
                   help="feature counts M compared in features.png (default 10,100,1000)")
    s.add_argument("--realizations", type=_positive_int, default=4,
                   help="realizations per plot (default 4)")
    s.add_argument("--resolution", type=_positive_int, default=128,
                   help="slice resolution in pixels (default 128)")
    s.add_argument("--seed", type=int, default=0, help="random seed")
    s.add_argument("--observations", metavar="FILE",
                   help="surface points (x y z [nx ny nz] per line, or .npy): also draw the "
                   "posterior GPIS given them (mean, sd, occupancy, realizations)")
    s.add_argument("--noise", type=float, default=1e-4,
                   help="variance of the observed values (default 1e-4)")


def cmd_sample(args) -> int:
    from .host.commands.sample_figures import resolve_target, write_figures

    try:
        features = tuple(int(v) for v in args.features.split(","))
        if not features or min(features) < 1:
            raise ValueError
    except ValueError:
        raise SceneError("<command line>", "--features",
                         f"expected positive integers separated by commas (got "
                         f"{args.features!r})") from None
    from .host.commands.sample_figures import load_observations

    if not args.noise > 0:
        raise SceneError("<command line>", "--noise", f"must be > 0 (got {args.noise})")
    target = resolve_target(args.target, args.object)
    obs = load_observations(args.observations, args.noise) if args.observations else None
    paths = write_figures(target, args.output, features, args.realizations, args.seed,
                          args.resolution, observations=obs)
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0


def cl_type(dev) -> str:
    import pyopencl as cl
    return cl.device_type.to_string(dev.type).lower()


def cmd_convert_vdb(args) -> int:
    from .host.io.vdb import convert_vdb
    info = convert_vdb(args.input, args.output, args.grid)
    print(f"wrote {args.output}: grid '{info['grid']}', {info['shape']} samples, voxel "
          f"{info['voxel_size']:g}, origin {info['origin']}", file=sys.stderr)
    return 0


def main(argv=None) -> int:
    from . import signals
    try:
        args = _parser().parse_args(argv)
        commands = {"render": cmd_render, "devices": cmd_devices, "uq": cmd_uq,
                    "sample": cmd_sample, "convert-vdb": cmd_convert_vdb}
        return commands[args.command](args)
    except (SceneError, DeviceError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BaseException:
        # a stop signal during start-up: Interrupted itself, or what it became on the way
        # out of a C extension (an ImportError, a pyopencl error)
        stopped_by = signals.received()
        if stopped_by is None:
            raise
        signals.acknowledge()
        print(signals.startup_message(stopped_by), file=sys.stderr)
        return signals.exit_code(stopped_by)


if __name__ == "__main__":
    sys.exit(main())
