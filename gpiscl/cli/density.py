"""gpiscl density: the GPIS density of one object as CSV and PNG (api.density)."""
from __future__ import annotations

import sys

from .. import api


def add_parser(sub):
    s = sub.add_parser("density", help="free flights and first-hit normals of a GPIS "
                       "(CSV and PNG; the PNG needs matplotlib)",
                       description="Many free flights of one GPIS object along one ray, by "
                       "the renderer's function-space sampler under each memory model and "
                       "by the classical medium counterpart: the free-flight distance of "
                       "the first and later flights (with the exponential of the same mean "
                       "and of Rice's entry rate) and the normal at the first hit (with "
                       "Beckmann). docs/design/classical-limits.md derives the limits. "
                       "Needs the optional extra: pip install -e '.[plots]'.")
    s.add_argument("scene", metavar="SCENE", help="a scene file")
    s.add_argument("-o", "--output", default="density", help="output folder (default density)")
    s.add_argument("--object", type=int, default=0, help="which GPIS of the scene (default 0)")
    s.add_argument("--ray", metavar="OX,OY,OZ,DX,DY,DZ,LENGTH",
                   help="the ray (default: through the proxy's centre, against the mean's "
                   "gradient there, across the proxy)")
    s.add_argument("--paths", type=int, default=20000, help="flights per model (default 20000)")
    s.add_argument("--bounces", type=int, default=2,
                   help="flights per path, turning off a Lambertian facet at each hit "
                   "(default 2)")
    s.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    return s


def run(a) -> int:
    paths = api.density(a.scene, a.object, a.output, a.ray, a.paths, a.bounces, a.seed)
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0
