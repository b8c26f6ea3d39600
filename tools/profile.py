"""Kernel throughput: renders a fixed workload, prints items/s per stage and the ratio
to a vectorised numpy implementation of the same stage measured in the same run.

    python tools/profile.py [--resolution 256] [--spp 16] [--repeats 3] [--scene FILE]

Numbers are medians over --repeats runs; the machines are noisy, so compare ratios.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpiscl.host.layout import records as layouts  # noqa: E402
from gpiscl.host.compile.camera import compile_camera  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402
from gpiscl.host.compile.scene import compile_scene  # noqa: E402

PRIM = layouts.PRIM_KINDS


# --- numpy twins of three stages ------------------------------------------------------

def numpy_generate_camera_rays(cam, n, rng):
    w, h = int(cam["width"][0]), int(cam["height"][0])
    pix = np.arange(n) % (w * h)
    jx, jy = rng.random(n, np.float32), rng.random(n, np.float32)
    sx = 2 * ((pix % w) + jx) / w - 1
    sy = 1 - 2 * ((pix // w) + jy) / h
    d = (cam["forward"][0, :3] + sx[:, None] * cam["right"][0, :3]
         + sy[:, None] * cam["up"][0, :3])
    return np.broadcast_to(cam["position"][0, :3], d.shape), d / np.linalg.norm(d, axis=1)[:, None]


def numpy_intersect(prims, o, d):
    """Brute force closest hit over every primitive, vectorised over rays."""
    best_t = np.full(len(d), np.inf, np.float32)
    best = np.full(len(d), -1, np.int32)
    for i, p in enumerate(prims):
        k = p["kind"]
        p0, p1, p2 = p["p0"][:3], p["p1"][:3], p["p2"][:3]
        if k == PRIM["sphere"]:
            oc = o - p0
            b = (oc * d).sum(1)
            disc = b * b - ((oc * oc).sum(1) - p["p0"][3] ** 2)
            s = np.sqrt(np.maximum(disc, 0))
            t = np.where(-b - s > 1e-4, -b - s, -b + s)
            t = np.where(disc >= 0, t, np.inf)
        else:
            if k == PRIM["triangle"]:
                e1, e2 = p1 - p0, p2 - p0
            elif k == PRIM["rectangle"]:
                e1, e2 = p1, p2
            else:
                e1 = e2 = None
            n = np.cross(e1, e2) if e1 is not None else p1
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((p0 - o) @ n) / (d @ n)
                h = o + t[:, None] * d - p0
                if k == PRIM["disk"]:
                    ok = (h * h).sum(1) <= p["p0"][3] ** 2
                else:
                    # barycentric / parametric coordinates in the (e1, e2) basis
                    g = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
                    a, b = np.linalg.solve(g, np.stack([h @ e1, h @ e2]))
                    ok = (a >= 0) & (b >= 0) & ((a + b <= 1) if k == PRIM["triangle"]
                                                else (a <= 1) & (b <= 1))
            t = np.where(ok, t, np.inf)
        t = np.where(t > 1e-4, t, np.inf)
        closer = t < best_t
        best_t[closer], best[closer] = t[closer], i
    return best_t, best


def numpy_accumulate(film_sum, film_sq, film_n, pixels, L):
    np.add.at(film_sum, pixels, L.astype(np.float64))
    np.add.at(film_sq, pixels, L.astype(np.float64) ** 2)
    np.add.at(film_n, pixels, 1.0)


def time_numpy(compiled, n):
    rng = np.random.default_rng(0)
    cam = compiled.camera
    out = {}
    t0 = time.perf_counter()
    o, d = numpy_generate_camera_rays(cam, n, rng)
    out["generate_camera_rays"] = n / (time.perf_counter() - t0)
    m = min(n, 1 << 16)  # brute force is slow: time a slice, report per item
    t0 = time.perf_counter()
    numpy_intersect(compiled.primitives, o[:m], d[:m])
    out["intersect"] = m / (time.perf_counter() - t0)
    npix = int(cam["width"][0] * cam["height"][0])
    fs, fq, fn = np.zeros((npix, 3)), np.zeros((npix, 3)), np.zeros(npix)
    t0 = time.perf_counter()
    numpy_accumulate(fs, fq, fn, np.arange(n) % npix, rng.random((n, 3), np.float32))
    out["accumulate"] = n / (time.perf_counter() - t0)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", help="scene file (default: the built-in default scene)")
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--device")
    args = ap.parse_args()

    if args.scene:
        scene = load_scene(args.scene)
    else:
        from gpiscl.scenes import default_scene
        scene = load_scene(default_scene())
    data = scene.data
    data["camera"]["resolution"] = [args.resolution, args.resolution]
    compiled = compile_scene(data)
    device = Device(args.device)
    print(f"device: {device.name}\nscene: {scene.source}  {args.resolution}^2 x {args.spp} spp, "
          f"{len(compiled.primitives)} primitives")

    path_rates, device_rates, numpy_rates = [], {}, {}
    for rep in range(args.repeats):
        integ = WavefrontIntegrator(device, compiled, data["render"])
        res = integ.render(args.spp)
        path_rates.append(res.stats.paths / res.stats.seconds)
        t = integ.program.timings
        for name in t.seconds:
            device_rates.setdefault(name, []).append(t.items[name] / t.seconds[name])
        for name, rate in time_numpy(compiled, args.resolution**2 * min(args.spp, 4)).items():
            numpy_rates.setdefault(name, []).append(rate)

    med = statistics.median
    print(f"\nrender: {med(path_rates):.4g} paths/s (median of {args.repeats})")
    print(f"\n{'stage':<24}{'device items/s':>16}{'numpy items/s':>16}{'ratio':>10}")
    for name in sorted(device_rates, key=lambda k: -med(device_rates[k])):
        dev = med(device_rates[name])
        if name in numpy_rates:
            npr = med(numpy_rates[name])
            print(f"{name:<24}{dev:>16.4g}{npr:>16.4g}{dev / npr:>10.2f}")
        else:
            print(f"{name:<24}{dev:>16.4g}{'-':>16}{'-':>10}")


if __name__ == "__main__":
    main()
