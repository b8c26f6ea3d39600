"""gpiscl sample: PNG figures of GPIS realizations (api.sample_figures)."""
from __future__ import annotations

import sys

from .. import api
from .args import int_list


def add_parser(sub):
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
    s.add_argument("--features", type=int_list, default=[10, 100, 1000],
                   help="feature counts M compared in features.png (default 10,100,1000)")
    s.add_argument("--realizations", type=int, default=4,
                   help="realizations per plot (default 4)")
    s.add_argument("--resolution", type=int, default=128,
                   help="slice resolution in pixels (default 128)")
    s.add_argument("--seed", type=int, default=0, help="random seed")
    s.add_argument("--observations", metavar="FILE",
                   help="surface points (x y z [nx ny nz] per line, or .npy): also draw the "
                   "posterior GPIS given them (mean, sd, occupancy, realizations)")
    s.add_argument("--noise", type=float, default=1e-2,
                   help="standard deviation of the observed values f = 0, > 0, in world "
                   "units as a scene's observations.noise (default 1e-2)")
    return s


def run(a) -> int:
    paths = api.sample_figures(a.target, a.output, a.object, a.features, a.realizations,
                               a.resolution, a.seed, a.observations, a.noise)
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0
