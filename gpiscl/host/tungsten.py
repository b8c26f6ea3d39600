"""Import the GPIS subset of the authors' Tungsten scene format into a gpiscl scene dict.

Mapping (../shared/design/REFERENCE-ALGORITHMS.md section 8 describes their format):

  camera  pinhole {transform {position, look_at, up}, fov (horizontal degrees), resolution}
          -> camera (fov made vertical for the image's aspect)
  renderer.spp -> render.spp;  integrator.max_bounces -> render.max_depth;
  integrator.enable_light_sampling -> render.nee;  camera.tonemap filmic -> render.tonemap
  bsdfs   lambert -> diffuse, mirror -> mirror, rough_conductor {material, roughness,
          distribution beckmann} -> rough_conductor, forward/null -> null; a checker texture
          albedo becomes the mean of its two colours (listed in the notes)
  primitives
          quad (unit square in xz, normal +y, transform scale/rotation/position) -> rectangle,
            or a rectangle light when it has emission/power
          cube (unit cube [-0.5, 0.5]^3, unrotated) -> box, or the proxy box of its
            int_medium; sphere (radius, or position/scale) -> sphere, or a sphere proxy
          infinite_sphere {emission: colour | .exr file} -> environment / environment_map
          infinite_sphere_cap {cap_angle, power, transform} -> directional light towards
            the rotated +y axis with radiance power / (2 pi (1 - cos cap)) inside the cap
  media   function_space_gaussian_process / gaussian_process -> sampler function_space
            {memory: elephant -> global, goldfish -> renewal_plus, dori -> renewal,
             none -> none; sample_points and step_size_cov (segments, fixed step) have no
             counterpart: the step is adaptive}
          weight_space_gaussian_process -> weight_space {features: basis_functions};
            single_realization -> render.realization 0 (a fixed realization; the authors'
            seed is not reproducible)
          phase_function / additional_phase_functions {type: brdf, bsdf} -> micro-BSDF by id
          gaussian_process: standard {mean, covariance, id}; csg {left, right} -> one gpis
            object per leaf in the same proxy: first hits over independent objects are the
            union min(f_L, f_R), which is what the reference's csg computes
  means   homogeneous {offset} -> constant; spherical {center, radius} -> sphere;
          linear {reference_point, direction, scale} -> plane;
          mesh {file (.obj/.ply/.stl/.off, relative to the scene file), transform} -> mesh
            (the transform goes to the vertices before the bake, as the reference applies
            it at load time; its rotY rotX rotZ rotation becomes our x-then-y-then-z Euler
            angles of the same matrix; `signed` is ignored, as by the reference; the exact
            distance becomes a 128^3 baked grid, listed in the notes)
          tabulated {grid, offset, scale, volume} -> grid (values (g + offset) scale, with
            g <- -log(max(1e-4, g)) first when volume; interpolate "quadratic" -> cubic, as
            gpiscl has no quadratic spline; the grid's transform -> a transform mean)
  kernels squared_exponential, rational_quadratic (a -> alpha), thin_plate (R -> radius),
          with sigma, lengthScale and aniso; the reference's kernels and ours agree there;
          nonstationary {cov, grid | variance, offset, scale} -> cov with a sigma_field grid
            of (g + offset) scale (their grid holds a deviation multiplier, the name
            notwithstanding; a translation in the grid's transform moves the grid's origin)
  grids   {type: vdb, file, density_name} (a VDB grid): read with an OpenVDB binding when
          one imports (vdb.py), else from FILE_STEM.DENSITY_NAME.npz next to the .vdb if
          present (made elsewhere with `python -m gpiscl convert-vdb`); written .npz files
          go to `grid_dir` (default: next to the .vdb)

Everything else (procedural means, a mesh mean's `min` clamp, their radial periodic kernel,
GGX microfacets, .hdr environment maps, rotated cubes) is an error naming the key path and
the reason, never silently dropped. Pass `environment` to substitute a
missing environment map.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .scene_schema import SceneError

MEMORIES = {"elephant": "global", "goldfish": "renewal_plus", "dori": "renewal", "none": "none"}
FS_MEDIA = ("function_space_gaussian_process", "gaussian_process")
WS_MEDIA = ("weight_space_gaussian_process",)
KERNEL_KEYS = {
    "squared_exponential": {"sigma": "sigma", "lengthScale": "length_scale", "aniso": "aniso"},
    "rational_quadratic": {"sigma": "sigma", "lengthScale": "length_scale", "a": "alpha",
                           "aniso": "aniso"},
    "thin_plate": {"sigma": "sigma", "R": "radius", "aniso": "aniso"},
}


MESH_MEAN_KEYS = ("type", "file", "transform", "signed", "min")
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off")


def euler_xyz(rot) -> list:
    """Degrees (x, y, z) with Rz Ry Rx = rot: gpiscl's rotate order (x first) for any
    rotation matrix, such as the reference's Ry Rx Rz."""
    r = np.asarray(rot, float)
    sy = -float(np.clip(r[2, 0], -1.0, 1.0))
    ay = math.asin(sy)
    if abs(r[2, 0]) < 1.0 - 1e-9:
        ax, az = math.atan2(r[2, 1], r[2, 2]), math.atan2(r[1, 0], r[0, 0])
    else:                   # gimbal lock: only ax - az (or ax + az) is defined; take az = 0
        ax, az = math.atan2(-r[1, 2], r[1, 1]), 0.0
    return [math.degrees(a) for a in (ax, ay, az)]


class _Converter:
    def __init__(self, doc: dict, source: str, environment=None, grid_dir=None):
        self.doc, self.source, self.environment = doc, source, environment
        self.base = Path(source).resolve().parent if source != "<dict>" else Path.cwd()
        self.grid_dir = Path(grid_dir) if grid_dir is not None else None
        self.notes: list[str] = []

    def fail(self, key: str, reason: str):
        raise SceneError(self.source, key, reason)

    # --- small pieces -----------------------------------------------------------------

    def colour(self, value, key):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return [float(value)] * 3
        if isinstance(value, list) and len(value) == 3:
            return [float(v) for v in value]
        if isinstance(value, dict) and value.get("type") == "checker":
            on = self.colour(value.get("on_color", 0.8), f"{key}.on_color")
            off = self.colour(value.get("off_color", 0.2), f"{key}.off_color")
            self.notes.append(f"{key}: checker texture replaced by its mean colour")
            return [(a + b) / 2 for a, b in zip(on, off)]
        self.fail(key, f"unsupported colour or texture {value!r}")

    def named(self, ref, table: str, key: str) -> tuple[dict, str]:
        """An inline object, or the entry of doc[table] with that name."""
        if isinstance(ref, dict):
            return ref, key
        for i, entry in enumerate(self.doc.get(table, [])):
            if entry.get("name") == ref:
                return entry, f"{table}[{i}]"
        self.fail(key, f'no entry named "{ref}" in "{table}"')

    def bsdf(self, ref, key, micro=False) -> dict:
        b, key = self.named(ref, "bsdfs", key)
        kind = b.get("type", "lambert")
        albedo = self.colour(b.get("albedo", 1.0 if kind == "mirror" else 0.5), f"{key}.albedo")
        if kind == "lambert":
            return {"type": "diffuse", "albedo": albedo}
        if kind == "mirror":
            return {"type": "mirror", "albedo": albedo}
        if kind == "rough_conductor":
            return self.rough_conductor(b, key)
        if kind in ("forward", "null") and not micro:
            return {"type": "null"}
        self.fail(f"{key}.type", f'BSDF "{kind}" is not supported'
                  + (" as a micro-BSDF (diffuse or mirror only)" if micro else ""))

    def rough_conductor(self, b: dict, key: str) -> dict:
        from .conductors import CONDUCTORS
        dist = b.get("distribution", "ggx")
        if dist != "beckmann":
            self.fail(f"{key}.distribution", f'"{dist}" microfacets are not supported '
                      '(beckmann only)')
        material = b.get("material", "Cu")
        if material not in CONDUCTORS:
            self.fail(f"{key}.material", f'conductor "{material}" has no preset (one of: '
                      f'{", ".join(CONDUCTORS)}); give eta and k in the converted scene')
        albedo = self.colour(b.get("albedo", 1.0), f"{key}.albedo")
        return {"type": "rough_conductor", "material": material,
                "roughness": float(b.get("roughness", 0.1)), "albedo": albedo}

    def transform(self, t: dict, key: str, allow_rotation=True):
        pos = np.asarray(t.get("position", [0, 0, 0]), float)
        scale = t.get("scale", 1.0)
        scale = np.full(3, float(scale)) if np.ndim(scale) == 0 else np.asarray(scale, float)
        rot = np.asarray(t.get("rotation", [0, 0, 0]), float)
        if np.any(rot != 0) and not allow_rotation:
            self.fail(f"{key}.rotation", "rotated boxes are not supported (axis-aligned only)")
        # Tungsten's Mat4f::rotYXZ: R = Ry Rx Rz (degrees)
        ax, ay, az = np.radians(rot)
        rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
        ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
        rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
        return pos, scale, ry @ rx @ rz

    # --- blocks -----------------------------------------------------------------------

    def camera(self) -> dict:
        cam = self.doc.get("camera", {})
        if cam.get("type", "pinhole") != "pinhole":
            self.fail("camera.type", f'camera "{cam.get("type")}" is not supported (pinhole only)')
        t = cam.get("transform", {})
        res = cam.get("resolution", 512)
        w, h = (res, res) if isinstance(res, int) else res
        hfov = math.radians(float(cam.get("fov", 60.0)))
        vfov = math.degrees(2 * math.atan(math.tan(hfov / 2) * h / w))
        return {"position": t.get("position", [0, 0, 0]), "look_at": t.get("look_at", [0, 0, 1]),
                "up": t.get("up", [0, 1, 0]), "fov": vfov, "resolution": [w, h]}

    def render(self) -> dict:
        out = {}
        if "spp" in self.doc.get("renderer", {}):
            out["spp"] = self.doc["renderer"]["spp"]
        integ = self.doc.get("integrator", {})
        if "max_bounces" in integ:
            out["max_depth"] = integ["max_bounces"]
        if "enable_light_sampling" in integ:
            out["nee"] = bool(integ["enable_light_sampling"])
        if self.doc.get("camera", {}).get("tonemap") == "filmic":
            out["tonemap"] = "filmic"
        return out

    def mean(self, m: dict, key: str) -> dict:
        kind = m.get("type")
        if kind == "homogeneous":
            return {"type": "constant", "value": m.get("offset", 0.0)}
        if kind == "spherical":
            return {"type": "sphere", "center": m.get("center", [0, 0, 0]),
                    "radius": m.get("radius", 1.0)}
        if kind == "linear":
            if "min" in m:
                self.fail(f"{key}.min", "a clamped linear mean is not supported")
            return {"type": "plane", "point": m.get("reference_point", [0, 0, 0]),
                    "normal": m.get("direction", [1, 0, 0]), "scale": m.get("scale", 1.0)}
        if kind == "mesh":
            return self.mesh_mean(m, key)
        if kind == "tabulated":
            return self.tabulated_mean(m, key)
        self.fail(f"{key}.type", f'mean "{kind}" is not supported (homogeneous, spherical, '
                  'linear, mesh, tabulated)')

    def vdb_grid(self, spec, key: str, offset=0.0, scale=1.0, volume=False,
                 kind="mean") -> tuple[str, dict]:
        """(.npz path, the grid's transform) of a VDB grid reference, its values mapped
        to (g + offset) scale (after g <- -log(max(1e-4, g)) when volume)."""
        from . import vdb
        from .sdf_bake import load_grid, save_grid
        if not isinstance(spec, dict) or spec.get("type") != "vdb":
            self.fail(f"{key}.type", "only VDB grids ({type: vdb, file, density_name}) are "
                      "supported")
        if not isinstance(spec.get("file"), str):
            self.fail(f"{key}.file", "expected the .vdb file name")
        src = (self.base / spec["file"]).resolve()
        name = spec.get("density_name", "density")
        out_dir = self.grid_dir or src.parent
        converted = src.parent / f"{src.stem}.{name}.npz"
        if not converted.is_file():
            if not src.is_file():
                self.fail(f"{key}.file", f"file not found: {src}")
            if vdb.import_openvdb() is None:
                self.fail(f"{key}.file", f"{vdb.HOW_TO_GET}; or convert it where one is "
                          f"available (python -m gpiscl convert-vdb {src.name} "
                          f"{converted.name} --grid {name}) and keep the .npz next to the .vdb")
            converted = out_dir / f"{src.stem}.{name}.npz"
            try:
                vdb.convert_vdb(str(src), str(converted), name)
            except SceneError as exc:
                self.fail(f"{key}.density_name", exc.reason)
        if offset == 0.0 and scale == 1.0 and not volume:
            return str(converted), spec.get("transform", {})
        try:
            g = load_grid(converted)
        except ValueError as exc:
            self.fail(f"{key}.file", f"{converted}: {exc}")
        values = np.asarray(g.values, np.float64)
        if volume:
            values = -np.log(np.maximum(values, 1e-4))
        out = out_dir / f"{src.stem}.{name}.{kind}.npz"
        save_grid(out, type(g)((values + offset) * scale, g.origin, g.voxel_size))
        return str(out), spec.get("transform", {})

    def tabulated_mean(self, m: dict, key: str) -> dict:
        path, t = self.vdb_grid(m.get("grid"), f"{key}.grid", float(m.get("offset", 0.0)),
                                float(m.get("scale", 1.0)), bool(m.get("volume", False)))
        interp = m["grid"].get("interpolate", "linear")
        if interp not in ("linear", "quadratic"):
            self.fail(f"{key}.grid.interpolate", f'"{interp}" is not supported (linear, '
                      'quadratic)')
        if interp == "quadratic":
            self.notes.append(f"{key}.grid.interpolate: quadratic becomes gpiscl's cubic "
                              "spline (also smooth, through the same samples)")
        grid = {"type": "grid", "file": path,
                "interpolation": "cubic" if interp == "quadratic" else "linear"}
        if not t:
            return grid
        pos, scale, rot = self.transform(t, f"{key}.grid.transform")
        return {"type": "transform", "child": grid, "scale": scale.tolist(),
                "rotate": euler_xyz(rot), "translate": pos.tolist()}

    def nonstationary_kernel(self, k: dict, key: str) -> dict:
        from .sdf_bake import load_grid, save_grid
        base = self.kernel(k.get("cov", {"type": "squared_exponential"}), f"{key}.cov")
        if base["type"] not in KERNEL_KEYS:
            self.fail(f"{key}.cov.type", "expected a stationary kernel")
        gkey = "grid" if "grid" in k else "variance"
        if gkey not in k:
            self.fail(key, "a nonstationary kernel needs a grid (or variance) VDB grid")
        path, t = self.vdb_grid(k[gkey], f"{key}.{gkey}", float(k.get("offset", 0.0)),
                                float(k.get("scale", 1.0)), kind="sigma")
        if t:
            pos, scale, rot = self.transform(t, f"{key}.{gkey}.transform")
            if np.any(scale != 1.0) or np.any(rot != np.eye(3)):
                self.fail(f"{key}.{gkey}.transform", "only a translation of a sigma grid is "
                          "supported")
            g = load_grid(path)
            path = str(Path(path).with_suffix("")) + ".moved.npz"
            save_grid(path, type(g)(g.values, tuple(np.asarray(g.origin) + pos), g.voxel_size))
        from .sdf_bake import load_field_grid, problem_of
        problem = problem_of(load_field_grid)(path)
        if problem:
            self.fail(f"{key}.{gkey}", f"{path}: {problem}")
        return {**base, "sigma_field": {"type": "grid", "file": path}}

    def mesh_mean(self, m: dict, key: str) -> dict:
        for name in m:
            if name not in MESH_MEAN_KEYS:
                self.fail(f"{key}.{name}", f"unknown or unsupported mesh mean key (expected "
                          f"one of: {', '.join(MESH_MEAN_KEYS)})")
        if "min" in m:
            self.fail(f"{key}.min", "a clamped mesh mean is not supported (the mesh mean's "
                      "band clamps both signs)")
        if not isinstance(m.get("file"), str):
            self.fail(f"{key}.file", "expected the mesh file name")
        path = (self.base / m["file"]).resolve()
        if path.suffix.lower() not in MESH_SUFFIXES:
            self.fail(f"{key}.file", f'mesh "{m["file"]}" is not one of '
                      f'{", ".join(MESH_SUFFIXES)}; convert it (e.g. Tungsten .wo3 to .obj)')
        if not path.is_file():
            self.fail(f"{key}.file", f"file not found: {path}")
        t = m.get("transform", {})
        if not isinstance(t, dict):
            self.fail(f"{key}.transform", "only {position, scale, rotation} transforms are "
                      "supported")
        pos, scale, rot = self.transform(t, f"{key}.transform")
        if "signed" in m:
            self.notes.append(f"{key}.signed: ignored, as by the reference (the sign is "
                              "always the winding number's)")
        self.notes.append(f"{key}: the mesh's distance is baked to a grid (resolution 128); "
                          "the reference queries the mesh exactly")
        return {"type": "mesh", "file": str(path),
                "transform": {"scale": scale.tolist(), "rotate": euler_xyz(rot),
                              "translate": pos.tolist()}}

    def kernel(self, k: dict, key: str) -> dict:
        kind = k.get("type")
        if kind == "nonstationary":
            return self.nonstationary_kernel(k, key)
        if kind not in KERNEL_KEYS:
            why = (" (the reference's periodic kernel is radial; gpiscl's is a product over "
                   "axes)" if kind == "periodic" else "")
            self.fail(f"{key}.type", f'covariance "{kind}" is not supported{why}')
        out = {"type": kind}
        for name, value in k.items():
            if name == "type":
                continue
            if name not in KERNEL_KEYS[kind]:
                self.fail(f"{key}.{name}", f'unknown {kind} key (the reference ignores it; '
                          f'expected one of: {", ".join(KERNEL_KEYS[kind])})')
            out[KERNEL_KEYS[kind][name]] = value
        return out

    def leaves(self, gp: dict, key: str):
        """(mean, kernel, id, key) of each standard GP under a csg tree."""
        kind = gp.get("type", "standard")
        if kind == "csg":
            return self.leaves(gp["left"], f"{key}.left") + self.leaves(gp["right"], f"{key}.right")
        if kind != "standard":
            self.fail(f"{key}.type", f'GP node "{kind}" is not supported (standard, csg)')
        if "conditioning_data" in gp:
            self.fail(f"{key}.conditioning_data", "conditioning on a mesh is not supported")
        return [(self.mean(gp.get("mean", {"type": "spherical"}), f"{key}.mean"),
                 self.kernel(gp.get("covariance", {"type": "squared_exponential"}),
                             f"{key}.covariance"), int(gp.get("id", 0)), key)]

    def sampler(self, med: dict, key: str) -> dict:
        kind = med.get("type")
        if kind in FS_MEDIA:
            # sample_points and step_size_cov set the reference's segments and fixed step;
            # gpiscl samples online with an adaptive step (fs_march.h), so they have no
            # counterpart and the default miss tolerance applies
            s = {"type": "function_space",
                 "memory": MEMORIES.get(med.get("correlation_context", "goldfish"))}
            if s["memory"] is None:
                self.fail(f"{key}.correlation_context",
                          f"unknown memory model (expected one of: {', '.join(MEMORIES)})")
            return s
        if kind in WS_MEDIA:
            return {"type": "weight_space", "features": med.get("basis_functions", 300)}
        self.fail(f"{key}.type", f'medium "{kind}" is not a Gaussian-process medium')

    def gpis(self, medium_ref, proxy: dict, key: str, render: dict) -> list:
        med, mkey = self.named(medium_ref, "media", key)
        phases = [med.get("phase_function", {"type": "brdf", "bsdf": {"type": "lambert"}})]
        phases += med.get("additional_phase_functions", [])
        sampler = self.sampler(med, mkey)
        if med.get("single_realization"):
            render["realization"] = 0
        shapes = []
        for mean, kernel, gp_id, gkey in self.leaves(med.get("gaussian_process", {}),
                                                    f"{mkey}.gaussian_process"):
            if gp_id >= len(phases):
                self.fail(f"{gkey}.id", f"no phase function for GP id {gp_id}")
            phase = phases[gp_id]
            pkey = (f"{mkey}.phase_function" if gp_id == 0
                    else f"{mkey}.additional_phase_functions[{gp_id - 1}]")
            if phase.get("type") != "brdf":
                self.fail(f"{pkey}.type", "only brdf phase functions (micro-BSDFs) are supported")
            shapes.append({"type": "gpis", "proxy": proxy, "mean": mean, "kernel": kernel,
                           "sampler": dict(sampler),
                           "bsdf": self.bsdf(phase.get("bsdf", {}), f"{pkey}.bsdf", micro=True)})
        return shapes

    def primitive(self, p: dict, key: str, render: dict, shapes: list, lights: list):
        kind = p.get("type")
        t = p.get("transform", {})
        if kind == "quad":
            pos, scale, rot = self.transform(t, f"{key}.transform")
            u, v = rot @ [scale[0], 0, 0], rot @ [0, 0, -scale[2]]
            if "emission" in p or "power" in p:
                area = float(np.linalg.norm(np.cross(u, v)))
                radiance = (self.colour(p["emission"], f"{key}.emission") if "emission" in p
                            else [c / (math.pi * area) for c in self.colour(p["power"], f"{key}.power")])
                lights.append({"type": "rectangle", "center": pos.tolist(), "u": u.tolist(),
                               "v": v.tolist(), "radiance": radiance})
            else:
                shapes.append({"type": "rectangle", "center": pos.tolist(), "u": u.tolist(),
                               "v": v.tolist(), "bsdf": self.bsdf(p.get("bsdf", {}), f"{key}.bsdf")})
        elif kind in ("cube", "sphere"):
            pos, scale, _ = self.transform(t, f"{key}.transform", allow_rotation=False)
            if kind == "cube":
                geo = {"min": (pos - scale / 2).tolist(), "max": (pos + scale / 2).tolist()}
            else:
                geo = {"center": pos.tolist(), "radius": float(p.get("radius", scale[0]))}
            if "int_medium" in p:
                shapes += self.gpis(p["int_medium"], {"type": ("box" if kind == "cube" else "sphere"),
                                                      **geo}, f"{key}.int_medium", render)
            else:
                shapes.append({"type": "box" if kind == "cube" else "sphere", **geo,
                               "bsdf": self.bsdf(p.get("bsdf", {}), f"{key}.bsdf")})
        elif kind == "infinite_sphere":
            lights.append(self.environment_light(p.get("emission", 1.0), f"{key}.emission"))
        elif kind == "infinite_sphere_cap":
            theta = math.radians(float(p.get("cap_angle", 10.0)))
            _, _, rot = self.transform(t, f"{key}.transform")
            power = self.colour(p.get("power", 1.0), f"{key}.power")
            radiance = [c / (2 * math.pi * (1 - math.cos(theta))) for c in power]
            lights.append({"type": "directional", "direction": (rot @ [0, 1, 0]).tolist(),
                           "angular_radius": math.degrees(theta),
                           "irradiance": [L * math.pi * math.sin(theta) ** 2 for L in radiance]})
        elif kind == "mesh" and "int_medium" in p:
            # a (convex, closed) mesh proxy: the file and transform map as for a mesh mean
            m = self.mesh_mean({k: v for k, v in p.items() if k in ("file", "transform")}, key)
            self.notes.pop()   # nothing is baked for a proxy
            shapes += self.gpis(p["int_medium"], {"type": "mesh", "file": m["file"],
                                                  "transform": m["transform"]},
                                f"{key}.int_medium", render)
        elif "int_medium" in p:
            self.fail(f"{key}.type", f'a "{kind}" proxy is not supported (cube, sphere, mesh)')
        else:
            self.fail(f"{key}.type", f'primitive "{kind}" is not supported')

    def environment_light(self, emission, key) -> dict:
        if self.environment is not None:
            self.notes.append(f"{key}: replaced by the given environment")
            return self.environment
        if isinstance(emission, str):
            path = (self.base / emission).resolve()
            if path.suffix.lower() != ".exr":
                self.fail(key, f'environment map "{emission}" is not an .exr; convert it or '
                          "pass a substitute environment")
            return {"type": "environment_map", "file": str(path)}
        return {"type": "environment", "radiance": self.colour(emission, key)}

    def convert(self) -> dict:
        render = self.render()
        shapes, lights = [], []
        for i, p in enumerate(self.doc.get("primitives", [])):
            self.primitive(p, f"primitives[{i}]", render, shapes, lights)
        return {"description": f"converted from {Path(self.source).name}",
                "camera": self.camera(), "render": render, "shapes": shapes, "lights": lights}


def convert_tungsten(doc: dict, source: str = "<dict>", environment: dict | None = None,
                     grid_dir=None):
    """gpiscl scene dict and a list of notes on lossy mappings; SceneError if unsupported.
    grid_dir: where .npz grids converted from VDB grids are written (default: beside
    their .vdb)."""
    c = _Converter(doc, source, environment, grid_dir)
    return c.convert(), c.notes
