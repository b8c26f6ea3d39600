"""Convert the GPIS subset of an authors' Tungsten scene to a gpiscl scene file.

    python tools/convert_tungsten.py scene.json out.json [--environment 0.8 | sky.exr | sky.hdr]
                                     [--grid-dir DIR]

The scene file is read as their renderer reads it (trailing commas, comments, NaN and
Infinity). The mapping and what is unsupported are documented in gpiscl/host/scene/tungsten.py.
The result is validated by the strict scene loader before it is written; errors are one
line naming the input file, the key path and the reason (exit code 2).
"""
import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # this checkout's gpiscl

from gpiscl.host.errors import SceneError  # noqa: E402
from gpiscl.host.io.lenient_json import read_lenient_json  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402
from gpiscl.host.scene.tungsten import convert_tungsten  # noqa: E402


def _environment(text):
    if text is None:
        return None
    try:
        return {"type": "environment", "radiance": float(text)}
    except ValueError:
        return {"type": "environment_map", "file": str(Path(text).resolve())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", help="Tungsten scene JSON")
    ap.add_argument("output", help="gpiscl scene JSON to write")
    ap.add_argument("--environment", help="substitute environment: a radiance, or an .exr "
                    "or .hdr map")
    ap.add_argument("--grid-dir", help="where .npz grids converted from .vdb grids go "
                    "(default: beside the .vdb)")
    args = ap.parse_args(argv)
    try:
        doc = read_lenient_json(args.scene)
        scene, notes = convert_tungsten(doc, args.scene, _environment(args.environment),
                                        args.grid_dir)
        try:
            load_scene(scene)  # strict validation before anything is written
        except SceneError as exc:
            # a value the importer passed on unchecked: name the input file, and the
            # converted scene's key (the input's key maps to it as tungsten.py describes)
            raise SceneError(args.scene, "", f"the converted scene is invalid at "
                             f"{exc.key or 'its top level'}: {exc.reason}") from None
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    Path(args.output).write_text(json.dumps(scene, indent=1) + "\n")
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
