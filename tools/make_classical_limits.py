"""The README's "From microfacets to participating media" figures (docs/gallery/):

  classical_limits.png    KS distance of first flights to the exponential against l (at a
                          fixed mu/sigma, and at a fixed Rice mean free path), and of
                          first-hit slopes to Beckmann against alpha (plane mean)
  classical_limits.csv    the numbers of that figure
  density_volume_free_flight.png   `gpiscl density` of scenes/fs_volume_room_global.json
  density_plane_normals.png        `gpiscl density` of scenes/ws_rough_mirror_plane.json

Needs matplotlib (pip install -e '.[plots]'). About a minute on a CPU device.
Usage: python tools/make_classical_limits.py [-o docs/gallery] [--paths 20000]"""
import argparse
import shutil
import tempfile
from pathlib import Path

import numpy as np

from gpiscl.host.figures.density import (medium_limit_series, plot_limits,
                                          surface_limit_series, write_csv, write_density)
from gpiscl.host.gp import Matern32, SquaredExponential
from gpiscl.host.gp import classical as C


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", default="docs/gallery")
    ap.add_argument("--paths", type=int, default=20000)
    args = ap.parse_args()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    n = args.paths

    fixed_level = medium_limit_series(lambda l: SquaredExponential(1.0, l),
                                      (1.0, 0.3, 0.1, 0.03, 0.01), 1.0, n)
    fixed_path = []
    for mu in (0.0, 1.0, 2.0, 2.5, 3.0):
        l = float(C.entry_rate(SquaredExponential(1.0, 1.0), mu))   # Rice mean free path 1
        fixed_path += medium_limit_series(lambda _: SquaredExponential(1.0, l), (l,), mu, n)
    surface = {name: surface_limit_series(make, (0.5, 0.2, 0.1, 0.05, 0.02), n)
               for name, make in (("SE", lambda s: SquaredExponential(s, 1.0)),
                                  ("Matern 3/2", lambda s: Matern32(s, 1.0)))}
    plot_limits({"mu/sigma = 1, l -> 0": fixed_level,
                 "mean free path 1, mu/sigma 0..3": fixed_path}, surface,
                out / "classical_limits.png")
    rows = ([dict(r, series="medium, fixed level") for r in fixed_level]
            + [dict(r, series="medium, fixed mean free path") for r in fixed_path]
            + [dict(r, series=f"surface, {k}") for k, v in surface.items() for r in v])
    write_csv(rows, out / "classical_limits.csv")
    for r in rows:
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in r.items()})

    # the volume's free flights and the plane's normals (a plane's flights all end near
    # its mean's zero: nothing to see there)
    for name, scene, figure in (("volume", "scenes/fs_volume_room_global.json", "free_flight.png"),
                                ("plane", "scenes/ws_rough_mirror_plane.json", "normals.png")):
        with tempfile.TemporaryDirectory() as tmp:
            for p in write_density(scene, 0, tmp, paths=n):
                if p.name == figure:
                    shutil.copy(p, out / f"density_{name}_{p.name}")
    print("wrote", out)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
