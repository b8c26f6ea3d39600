"""Paths per second of the classical counterparts against the GPIS they stand for
(docs/design/classical-limits.md): the medium counterpart of a constant-mean GPIS
(mu/sigma = 2, Rice mean free path 0.5, function space, renewal), the same counterpart
through the tracked (heterogeneous) flight (a sigma field of 1 everywhere), the
heterogeneous counterpart of a sphere-mean GPIS (sigma 0.1, l 0.02, a linear sigma
field), the surface counterpart of a sphere-mean GPIS (sigma/l = 0.1, weight space
and function space), and the zero-set mesh counterpart of a CSG-mean GPIS (a rotated
smooth union of a box and a sphere, sigma/l = 0.1; the time to build its mesh is printed
too). Each scene renders once to warm the build, then once timed.

Usage: python tools/bench_classical.py [--spp 64] [--resolution 64]
                                       [--only medium,het,surface,mesh]"""
import argparse
import time

from gpiscl import render_result
from gpiscl.host.gp import SquaredExponential
from gpiscl.host.compile.classical import with_counterparts
from gpiscl.host.gp import classical as C
from gpiscl.host.scene.loading import load_scene

CSG = {"type": "transform", "rotate": [20, 30, 0],
       "child": {"type": "union", "k": 0.1,
                 "left": {"type": "box", "half_extents": [0.6, 0.4, 0.5]},
                 "right": {"type": "sphere", "center": [0.4, 0.3, 0.2], "radius": 0.45}}}


def medium(classical, res, spp, tracked=False):
    l = float(C.entry_rate(SquaredExponential(1.0, 1.0), 2.0)) * 0.5
    g = {"type": "gpis", "clip": True,
         "proxy": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
         "mean": {"type": "constant", "value": 2.0},
         "kernel": {"type": "squared_exponential", "sigma": 1.0, "length_scale": l},
         "sampler": {"type": "function_space", "memory": "renewal"},
         "bsdf": {"type": "diffuse", "albedo": 0.8}}
    if tracked:   # a field makes the kernel non-stationary: the tracked flight runs
        g["kernel"]["sigma_field"] = {"type": "linear", "value": 1.0, "gradient": [0, 0, 0]}
    return scene(g, classical and "medium", res, spp)


def het_medium(classical, res, spp):
    g = {"type": "gpis", "clip": True,
         "proxy": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
         "mean": {"type": "sphere", "center": [0, 0, 0], "radius": 0.6},
         "kernel": {"type": "squared_exponential", "sigma": 0.1, "length_scale": 0.02,
                    "sigma_field": {"type": "linear", "value": 1.0, "gradient": [0, 0.5, 0]}},
         "sampler": {"type": "function_space", "memory": "renewal"},
         "bsdf": {"type": "diffuse", "albedo": 0.8}}
    return scene(g, classical and "medium", res, spp)


def surface(classical, sampler, res, spp):
    g = {"type": "gpis", "proxy": {"type": "sphere", "center": [0, 0, 0], "radius": 1.1},
         "mean": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
         "kernel": {"type": "squared_exponential", "sigma": 0.01, "length_scale": 0.1},
         "sampler": {"type": sampler},
         "bsdf": {"type": "rough_conductor", "material": "Au", "roughness": 0.1}}
    return scene(g, classical and "surface", res, spp)


def csg_surface(classical, sampler, res, spp):
    g = {"type": "gpis", "proxy": {"type": "sphere", "center": [0, 0, 0], "radius": 1.2},
         "mean": CSG,
         "kernel": {"type": "squared_exponential", "sigma": 0.01, "length_scale": 0.1},
         "sampler": {"type": sampler},
         "bsdf": {"type": "rough_conductor", "material": "Au", "roughness": 0.1}}
    return scene(g, classical and "surface", res, spp)


def mesh_build_seconds(doc) -> str:
    data = load_scene(doc).data
    t = time.perf_counter()
    shapes = with_counterparts(data)["shapes"]
    return f"{time.perf_counter() - t:.2f} s for {len(shapes)} mesh shape(s)"


def scene(g, classical, res, spp):
    if classical:
        g["classical"] = classical
    return {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "fov": 40,
                       "resolution": [res, res]},
            "render": {"spp": spp, "seed": 1, "max_depth": 64}, "shapes": [g],
            "lights": [{"type": "environment", "radiance": 0.2},
                       {"type": "rectangle", "center": [1.5, 2.5, 1.5], "u": [1, 0, 0],
                        "v": [0, 0, 1], "radiance": 8.0}]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--only", default="medium,het,surface,mesh",
                    help="comma-separated groups of cases: medium, het, surface, mesh")
    a = ap.parse_args()
    groups, cases = a.only.split(","), []
    if "medium" in groups:
        cases += [("medium: GPIS mu/sigma=2", medium(False, a.resolution, a.spp)),
                  ("medium: counterpart", medium(True, a.resolution, a.spp)),
                  ("medium: counterpart, tracked", medium(True, a.resolution, a.spp, True))]
    if "het" in groups:
        cases += [("het medium: GPIS sphere mean", het_medium(False, a.resolution, a.spp)),
                  ("het medium: counterpart", het_medium(True, a.resolution, a.spp))]
    for sampler in ("weight_space", "function_space") if "surface" in groups else ():
        cases += [(f"surface: GPIS {sampler}", surface(False, sampler, a.resolution, a.spp)),
                  (f"surface: counterpart ({sampler} scene)",
                   surface(True, sampler, a.resolution, a.spp))]
    for sampler in ("weight_space", "function_space") if "mesh" in groups else ():
        cases += [(f"csg: GPIS {sampler}", csg_surface(False, sampler, a.resolution, a.spp)),
                  (f"csg: mesh counterpart ({sampler} scene)",
                   csg_surface(True, sampler, a.resolution, a.spp))]
    if "mesh" in groups:
        print("csg: zero-set mesh built in",
              mesh_build_seconds(csg_surface(True, "weight_space", a.resolution, a.spp)))
    for name, doc in cases:
        render_result(doc, spp=1)
        r = render_result(doc)
        print(f"{name:40s} {r.stats.paths / r.stats.seconds:12.0f} paths/s "
              f"({r.stats.paths} paths, {r.stats.seconds:.2f} s, mean {r.image.mean.mean():.5f})")


if __name__ == "__main__":
    main()
