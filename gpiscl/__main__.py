"""Command line: python -m gpiscl render|devices ..."""
from __future__ import annotations

import argparse
import copy
import sys

from .host.device import Device, DeviceError, list_devices
from .host.scene import Scene, SceneError, load_scene


def _resolution(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 512x512 (got {text!r})")


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer (got {text!r})")
    return v


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m gpiscl",
                                 description="Render Gaussian Process Implicit Surfaces.")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene to EXR + PNG")
    r.add_argument("scene", nargs="?", help="scene JSON file (default: the built-in scene)")
    r.add_argument("-o", "--output", default="out.exr", help="output EXR (default out.exr)")
    r.add_argument("--spp", type=_positive_int, help="samples per pixel")
    r.add_argument("--seed", type=int, help="random seed")
    r.add_argument("--realization", type=int, metavar="R",
                   help="render one fixed GPIS realization R for every pixel (weight space)")
    r.add_argument("--resolution", type=_resolution, help="WIDTHxHEIGHT")
    r.add_argument("--time-limit", type=float, help="stop after this many seconds")
    r.add_argument("--device", help="OpenCL device: 'P:D' indices or a name fragment")
    r.add_argument("--batch-size", type=_positive_int, help="paths in flight per batch")
    r.add_argument("--exposure", type=float, default=0.0, help="PNG preview exposure (stops)")
    r.add_argument("--stats", action="store_true", help="print per-kernel timings")
    sub.add_parser("devices", help="list OpenCL platforms and devices")
    return ap


def _load(args) -> Scene:
    if args.scene is None:
        from .scenes import default_scene
        return load_scene(default_scene())
    return load_scene(args.scene)


def cmd_render(args) -> int:
    from .api import render_result
    from .host.output import write_outputs

    scene = _load(args)
    data = copy.deepcopy(scene.data)
    if args.resolution:
        data["camera"]["resolution"] = list(args.resolution)
    for key in ("spp", "seed", "realization"):
        if getattr(args, key) is not None:
            data["render"][key] = getattr(args, key)
    if not 0 <= data["render"]["seed"] < 2**32:
        raise SceneError("<command line>", "--seed", "must be in [0, 2**32)")
    if args.realization is not None and not 0 <= args.realization < 2**31:
        raise SceneError("<command line>", "--realization", "must be in [0, 2**31)")
    scene = Scene(data, scene.source, scene.base_dir)
    device = Device(args.device)
    spp = data["render"]["spp"]
    w, h = data["camera"]["resolution"]
    print(f"rendering {scene.source} at {w}x{h}, {spp} spp on {device.name}", file=sys.stderr)
    bar = _progress_bar(w * h * spp)
    try:
        result = render_result(scene, device=device, batch_size=args.batch_size,
                               time_limit=args.time_limit,
                               progress=bar.update if bar else None)
    finally:
        if bar:
            bar.close()
    paths = write_outputs(result.image, scene, args.output, args.exposure)
    st = result.stats
    if st.interrupted:
        print("interrupted: wrote the samples rendered so far", file=sys.stderr)
    print(st.summary(), file=sys.stderr)
    if args.stats:
        print(st.kernel_table, file=sys.stderr)
    print(f"wrote {paths['exr']}, {paths['png']}, {paths['scene']}", file=sys.stderr)
    return 0


def _progress_bar(total):
    if not sys.stderr.isatty():
        return None
    from tqdm import tqdm
    return tqdm(total=total, unit="path", unit_scale=True, file=sys.stderr,
                desc="paths", smoothing=0.1)


def cmd_devices(_args) -> int:
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


def cl_type(dev) -> str:
    import pyopencl as cl
    return cl.device_type.to_string(dev.type).lower()


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        return {"render": cmd_render, "devices": cmd_devices}[args.command](args)
    except (SceneError, DeviceError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
