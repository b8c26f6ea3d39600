"""Convert the GPIS subset of an authors' Tungsten scene to a gpiscl scene file.

    python tools/convert_tungsten.py scene.json out.json [--environment 0.8 | sky.exr]
                                     [--grid-dir DIR]

The mapping and what is unsupported are documented in gpiscl/host/tungsten.py. The result
is validated by the strict scene loader before it is written; errors are one line naming
the input file, the key path and the reason (exit code 2).
"""
import argparse
import json
import sys
from pathlib import Path

from gpiscl.host.errors import SceneError
from gpiscl.host.scene.loading import load_scene
from gpiscl.host.scene.tungsten import convert_tungsten


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
    ap.add_argument("--environment", help="substitute environment: a radiance or an .exr map")
    ap.add_argument("--grid-dir", help="where .npz grids converted from .vdb grids go "
                    "(default: beside the .vdb)")
    args = ap.parse_args(argv)
    try:
        try:
            doc = json.loads(Path(args.scene).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise SceneError(args.scene, "", f"cannot read JSON: {exc}") from None
        scene, notes = convert_tungsten(doc, args.scene, _environment(args.environment),
                                        args.grid_dir)
        load_scene(scene)  # strict validation before anything is written
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
