"""Convert the GPIS subset of an authors' Tungsten scene to a gpiscl scene file: the same
as `gpiscl convert-tungsten` (gpiscl/cli/convert_tungsten.py), for a checkout without the
package installed.

    python tools/convert_tungsten.py scene.json out.json [--environment 0.8 | sky.exr | sky.hdr]
                                     [--grid-dir DIR]
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # this checkout's gpiscl

from gpiscl.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["convert-tungsten", *sys.argv[1:]]))
