"""Convert the GPIS subset of an authors' Tungsten scene to a gpiscl scene file.

    python tools/convert_tungsten.py scene.json out.json [--environment 0.8 | sky.exr | sky.hdr]
                                     [--grid-dir DIR]

A thin wrapper of gpiscl.host.scene.tungsten_convert.convert_file, which documents the
guarantees (outputs checked first, written atomically, nothing written on an error); the
mapping is documented in gpiscl/host/scene/tungsten.py. Errors are one line naming the
file, the key path and the reason (exit code 2).
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # this checkout's gpiscl

from gpiscl.host.errors import SceneError  # noqa: E402
from gpiscl.host.scene.tungsten_convert import convert_file, environment_option  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", help="Tungsten scene JSON")
    ap.add_argument("output", help="gpiscl scene JSON to write")
    ap.add_argument("--environment", help="substitute environment: a radiance, or an .exr "
                    "or .hdr map")
    ap.add_argument("--grid-dir", help="where .npz grids converted from .vdb grids go "
                    "(default: the output's folder)")
    args = ap.parse_args(argv)
    try:
        notes = convert_file(args.scene, args.output, environment_option(args.environment),
                             args.grid_dir)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
