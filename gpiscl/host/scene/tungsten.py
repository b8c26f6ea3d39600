"""Import the GPIS subset of the authors' Tungsten scene format into a gpiscl scene dict.

Mapping (docs/design/tungsten-import.md says what is read and why):

  files   read as Tungsten reads them (lenient_json.py): trailing commas, comments, NaN
  transforms {position, scale, rotation}: T R S with their Mat4f::rotYXZ rotation, whose Y
          turn is the opposite of a right-handed one (R = Ry(-y) Rx(x) Rz(z))
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
          infinite_sphere {emission: colour | .exr or .hdr file, transform rotation about y}
            -> environment / environment_map (their u = atan2(z, x) / 2 pi + 1/2: half a
            turn from ours, added to the rotation)
          infinite_sphere_cap {cap_angle, power, transform} -> directional light towards
            the rotated +y axis with radiance power / (2 pi (1 - cos cap)) inside the cap
            (1 - cos cap computed as 2 sin^2(cap / 2), which keeps its digits for a 0.1
            degree sun)
  media   function_space_gaussian_process / gaussian_process -> sampler function_space
            {memory: elephant -> global, goldfish -> renewal_plus, dori -> renewal,
             none -> none; sample_points and step_size_cov (segments, fixed step) have no
             counterpart: the step is adaptive}
          weight_space_gaussian_process -> weight_space {features: basis_functions};
            single_realization -> render.realization 0 (a fixed realization; the authors'
            seed is not reproducible)
          sigma_s / (sigma_s + sigma_a) (their only use of the coefficients: the chance an
            event scatters) multiplies the micro-BSDF's albedo; their other medium keys
            (normal_method, intersect_method, skip_space, step_size, max_bounces) and the
            integrator's and camera's unmapped keys are listed in tungsten_keys.py, with a
            note whenever the scene's value makes their renderer differ from ours
          phase_function / additional_phase_functions {type: brdf, bsdf} -> micro-BSDF by id
          gaussian_process: standard {mean, covariance, id}; csg {left, right} -> one gpis
            object per leaf in the same proxy: first hits over independent objects are the
            union min(f_L, f_R), which is what the reference's csg computes
  means   homogeneous {offset} -> constant; spherical {center, radius} -> sphere;
          procedural {func: knob | knob_inner | knob_outer | two_spheres, transform} ->
            procedural (the knobs) or a union of two spheres, inside a transform mean (their
            renderer ignores that transform, a bug: the knob sinks into the floor; noted);
            a mean's `color` and `emission` fields are dropped with a note;
          linear {reference_point, direction, scale} -> plane;
          mesh {file (.obj/.ply/.stl/.off, relative to the scene file), transform} -> mesh
            (the transform goes to the vertices before the bake, as the reference applies
            it at load time; its rotY rotX rotZ rotation becomes our x-then-y-then-z Euler
            angles of the same matrix; `signed` is ignored, as by the reference; the exact
            distance becomes a 128^3 baked grid, listed in the notes)
          tabulated {grid, offset, scale, volume} -> grid (values (g + offset) scale, with
            g <- -log(max(1e-4, g)) first when volume; interpolate "quadratic" -> linear:
            trilinear stays between neighbouring samples, so it makes no zero crossing the
            samples lack, like their quadratic B-spline and unlike an interpolating cubic,
            which overshoots the bunny's far-field 100 to -38.6 in cells whose samples are
            all positive, a box-shaped shell around the bunny; the grid's transform -> a
            transform mean)
  kernels squared_exponential, rational_quadratic (a -> alpha), thin_plate (R -> radius),
          matern with v = 1.5 / 2.5 -> matern32 / matern52 (other v: an error; their
          renderer normalises its Matern with lgamma(v), noted),
          with sigma, lengthScale and aniso; SE, RQ and thin plate agree with ours;
          their knob's `roughness` (which their renderer ignores, keeping l = 1) is read as
          intended, the Beckmann alpha = sqrt(2) sigma / l, so l = sqrt(2) sigma / roughness
          when no lengthScale is given (as scenes/knob.json does; noted);
          nonstationary {cov, grid | variance, offset, scale} -> cov with a sigma_field grid
            of (g + offset) scale (their grid holds a deviation multiplier, the name
            notwithstanding; a translation in the grid's transform moves the grid's origin)
  grids   {type: vdb, file, density_name} (a VDB grid, inline or named in the top-level
          "grids" list): read with an OpenVDB binding when
          one imports (vdb.py), else from FILE_STEM.DENSITY_NAME.npz next to the .vdb if
          present (made elsewhere with `python -m gpiscl convert-vdb`); written .npz files
          go to `grid_dir` (default: the scene file's folder; convert_file: the output's),
          under plain names (a density_name with a / or a leading . is an error)

Everything else (procedural scalar means `f`, a mean's `min` clamp, their radial periodic
kernel, GGX microfacets, rotated cubes) is an error naming the key path and the reason,
never silently dropped; so is a value of the wrong type or range. Pass `environment` to
substitute a missing environment map.
"""
from __future__ import annotations

import copy
import math
import os
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..io.output_files import write_atomically
from .loading import load_scene
from ..schema import kind_of
from .tungsten_keys import CAMERA, INTEGRATOR, MEDIUM, notes_for

MEMORIES = {"elephant": "global", "goldfish": "renewal_plus", "dori": "renewal", "none": "none"}
FS_MEDIA = ("function_space_gaussian_process", "gaussian_process")
WS_MEDIA = ("weight_space_gaussian_process",)
KERNEL_KEYS = {
    "squared_exponential": {"sigma": "sigma", "lengthScale": "length_scale", "aniso": "aniso"},
    "rational_quadratic": {"sigma": "sigma", "lengthScale": "length_scale", "a": "alpha",
                           "aniso": "aniso"},
    "thin_plate": {"sigma": "sigma", "R": "radius", "aniso": "aniso"},
}
# their "matern" {sigma, v, lengthScale, aniso}: our Matern kernels, by v (nu); theirs
# scales with sqrt(2 v) r / l as ours do, so sigma and l carry over unchanged
MATERN_KEYS = {"sigma": "sigma", "lengthScale": "length_scale", "aniso": "aniso", "v": None}
MATERNS = {1.5: "matern32", 2.5: "matern52"}


MESH_MEAN_KEYS = ("type", "file", "transform", "signed", "min")
# their procedural SDFs (SdfFunctions.cpp); two_spheres is exact as a union of spheres
KNOBS = ("knob", "knob_inner", "knob_outer")
TWO_SPHERES = {"type": "union", "left": {"type": "sphere", "center": [0, 10, 0], "radius": 9.5},
               "right": {"type": "sphere", "center": [0, -10, 0], "radius": 9.5}}
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


def tungsten_rotation(degrees) -> np.ndarray:
    """Their Mat4f::rotYXZ(x, y, z) as a matrix: Ry(-y) Rx(x) Rz(z) in right-handed terms.
    Its Y turn goes the other way from Rx's and Rz's (their matrix has -sin y above the
    diagonal); reading it as Ry(+y) mirrored their sun and sky caps."""
    ax, ay, az = np.radians(np.asarray(degrees, float))
    c, s = math.cos, math.sin
    rx = np.array([[1, 0, 0], [0, c(ax), -s(ax)], [0, s(ax), c(ax)]])
    ry = np.array([[c(ay), 0, -s(ay)], [0, 1, 0], [s(ay), 0, c(ay)]])
    rz = np.array([[c(az), -s(az), 0], [s(az), c(az), 0], [0, 0, 1]])
    m = ry @ rx @ rz
    # cos(90 deg) is 6e-17, not 0: their [0, 90, 90] quad got a 7.5e-33 component that
    # float32 cannot hold (an error in a scene the user never wrote); round-off of that
    # size is zero
    return np.where(np.abs(m) < 1e-12, 0.0, m)


class _Converter:
    def __init__(self, doc: dict, source: str, environment=None, grid_dir=None):
        self.doc, self.source, self.environment = doc, source, environment
        self.base = Path(source).resolve().parent if source != "<dict>" else Path.cwd()
        # every derived file goes here, under a plain name (derived_path): a scene's
        # names never choose a folder
        self.grid_dir = Path(grid_dir) if grid_dir is not None else self.base
        self.notes: list[str] = []
        # "shapes[3]" -> "primitives[1]": where in their file a converted entry came from
        self.origin: dict[str, str] = {}

    def fail(self, key: str, reason: str):
        raise SceneError(self.source, key, reason)

    # Every value read from their file goes through one of these, so a wrong type or a
    # non-finite number is an error at its key path, not a traceback or a bad scene.

    def table(self, value, key: str) -> dict:
        if not isinstance(value, dict):
            self.fail(key, f"expected an object (got {kind_of(value)})")
        return value

    def check_number(self, value, key: str, *, integer=False, gt=None, ge=None, lt=None,
                     le=None) -> float:
        what = "an integer" if integer else "a number"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f"expected {what} (got {kind_of(value)})")
        if not math.isfinite(value):
            self.fail(key, f"must be finite (got {value})")
        if integer and not float(value).is_integer():
            self.fail(key, f"expected {what} (got {value!r})")
        for bound, sign, ok in ((gt, ">", float.__gt__), (ge, ">=", float.__ge__),
                                (lt, "<", float.__lt__), (le, "<=", float.__le__)):
            if bound is not None and not ok(float(value), float(bound)):
                self.fail(key, f"must be {sign} {bound:g} (got {value:g})")
        return int(value) if integer else float(value)

    def number(self, block: dict, name: str, key: str, default, **bounds) -> float:
        return self.check_number(block.get(name, default), f"{key}.{name}", **bounds)

    def vector(self, block: dict, name: str, key: str, default) -> list:
        value = block.get(name, default)
        if not isinstance(value, list) or len(value) != 3:
            self.fail(f"{key}.{name}", f"expected a list of 3 numbers (got {kind_of(value)})")
        return [self.check_number(v, f"{key}.{name}[{i}]") for i, v in enumerate(value)]

    # --- small pieces -----------------------------------------------------------------

    def colour(self, value, key):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return [self.check_number(value, key)] * 3
        if isinstance(value, list) and len(value) == 3:
            return [self.check_number(v, f"{key}[{i}]") for i, v in enumerate(value)]
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
        entries = self.doc.get(table, [])
        if not isinstance(entries, list):
            self.fail(table, f"expected a list (got {kind_of(entries)})")
        for i, entry in enumerate(entries):
            if self.table(entry, f"{table}[{i}]").get("name") == ref:
                return entry, f"{table}[{i}]"
        self.fail(key, f'no entry named "{ref}" in "{table}"')

    def bsdf(self, ref, key, micro=False) -> dict:
        b, key = self.named(ref, "bsdfs", key)
        kind = self.table(b, key).get("type", "lambert")
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
        from ..kinds.conductors import CONDUCTORS
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
                "roughness": self.number(b, "roughness", key, 0.1, gt=0), "albedo": albedo}

    def transform(self, t, key: str, allow_rotation=True):
        t = self.table(t, key)
        pos = np.asarray(self.vector(t, "position", key, [0, 0, 0]))
        if isinstance(t.get("scale", 1.0), list):
            scale = np.asarray(self.vector(t, "scale", key, None))
        else:
            scale = np.full(3, self.number(t, "scale", key, 1.0))
        rot = np.asarray(self.vector(t, "rotation", key, [0, 0, 0]))
        if np.any(rot != 0) and not allow_rotation:
            self.fail(f"{key}.rotation", "rotated boxes are not supported (axis-aligned only)")
        return pos, scale, tungsten_rotation(rot)

    # --- blocks -----------------------------------------------------------------------

    def camera(self) -> dict:
        cam = self.table(self.doc.get("camera", {}), "camera")
        if cam.get("type", "pinhole") != "pinhole":
            self.fail("camera.type", f'camera "{cam.get("type")}" is not supported (pinhole only)')
        t = self.table(cam.get("transform", {}), "camera.transform")
        res = cam.get("resolution", 512)
        if isinstance(res, list):
            if len(res) != 2:
                self.fail("camera.resolution", f"expected 2 numbers (got {len(res)})")
            w, h = (self.check_number(v, f"camera.resolution[{i}]", integer=True, ge=1)
                    for i, v in enumerate(res))
        else:
            w = h = self.check_number(res, "camera.resolution", integer=True, ge=1)
        hfov = math.radians(self.number(cam, "fov", "camera", 60.0, gt=0, lt=180))
        vfov = math.degrees(2 * math.atan(math.tan(hfov / 2) * h / w))
        self.notes += notes_for(CAMERA, cam, "camera")
        if cam.get("tonemap", "filmic") != "filmic":
            self.notes.append(f'camera.tonemap: "{cam["tonemap"]}" becomes gpiscl\'s default '
                              "clamp curve (filmic is the only curve mapped)")
        return {"position": self.vector(t, "position", "camera.transform", [0, 0, 0]),
                "look_at": self.vector(t, "look_at", "camera.transform", [0, 0, 1]),
                "up": self.vector(t, "up", "camera.transform", [0, 1, 0]),
                "fov": vfov, "resolution": [w, h]}

    def render(self) -> dict:
        out = {}
        renderer = self.table(self.doc.get("renderer", {}), "renderer")
        if "spp" in renderer:
            out["spp"] = self.number(renderer, "spp", "renderer", None, integer=True, ge=1)
        integ = self.table(self.doc.get("integrator", {}), "integrator")
        if integ.get("type", "path_tracer") not in ("path_tracer", "gp_path_tracer"):
            self.fail("integrator.type", f'integrator "{integ["type"]}" is not supported '
                      "(path_tracer, gp_path_tracer)")
        if "max_bounces" in integ:
            out["max_depth"] = self.number(integ, "max_bounces", "integrator", None,
                                           integer=True, ge=1)
        nee = bool(integ.get("enable_light_sampling", True))
        out["nee"] = nee
        if bool(integ.get("enable_volume_light_sampling", True)) != nee:
            self.notes.append("integrator.enable_volume_light_sampling: differs from "
                              "enable_light_sampling; gpiscl's render.nee switches both "
                              f"(set to {str(nee).lower()})")
        self.notes += notes_for(INTEGRATOR, integ, "integrator")
        if self.doc.get("camera", {}).get("tonemap") == "filmic":
            out["tonemap"] = "filmic"
        return out

    def mean(self, m, key: str) -> dict:
        m = self.table(m, key)
        kind = m.get("type")
        for name in ("color", "emission"):
            if name in m:
                self.notes.append(f"{key}.{name}: their procedural {name} field on the mean "
                                  f"is dropped; give the gpis shape a `{name}` field by hand")
        if kind == "homogeneous":
            return {"type": "constant", "value": self.number(m, "offset", key, 0.0)}
        if kind == "spherical":
            return {"type": "sphere", "center": self.vector(m, "center", key, [0, 0, 0]),
                    "radius": self.number(m, "radius", key, 1.0, gt=0)}
        if kind == "linear":
            if "min" in m:
                self.fail(f"{key}.min", "a clamped linear mean is not supported")
            return {"type": "plane", "point": self.vector(m, "reference_point", key, [0, 0, 0]),
                    "normal": self.vector(m, "direction", key, [1, 0, 0]),
                    "scale": self.number(m, "scale", key, 1.0, gt=0)}
        if kind == "procedural":
            return self.procedural_mean(m, key)
        if kind == "mesh":
            return self.mesh_mean(m, key)
        if kind == "tabulated":
            return self.tabulated_mean(m, key)
        self.fail(f"{key}.type", f'mean "{kind}" is not supported (homogeneous, spherical, '
                  'linear, procedural, mesh, tabulated)')

    def procedural_mean(self, m: dict, key: str) -> dict:
        """Their knob SDFs and two_spheres; the transform that their renderer drops (it
        evaluates F at the untransformed point) is applied, as their scenes intend."""
        func = m.get("func")
        if "f" in m and func is None:
            self.fail(f"{key}.f", "procedural scalar means are not supported (func: "
                      f"{', '.join(KNOBS)}, two_spheres)")
        if func not in KNOBS + ("two_spheres",):
            self.fail(f"{key}.func", f'procedural function "{func}" is not supported (one of: '
                      f'{", ".join(KNOBS)}, two_spheres)')
        for name, same in (("scale", 1.0), ("offset", 0.0)):
            if self.number(m, name, key, same) != same:
                self.fail(f"{key}.{name}", f"a procedural mean's {name} is not supported "
                          f"({same:g} only)")
        if "min" in m:
            self.fail(f"{key}.min", "a clamped procedural mean is not supported")
        child = ({"type": "procedural", "function": func} if func in KNOBS
                 else copy.deepcopy(TWO_SPHERES))
        if "transform" not in m:
            return child
        pos, scale, rot = self.transform(m["transform"], f"{key}.transform")
        if np.any(pos != 0) or np.any(scale != 1) or np.any(rot != np.eye(3)):
            self.notes.append(f"{key}.transform: applied; their renderer ignores it (the "
                              "mean is evaluated at the untransformed point), so their "
                              "images differ here")
        out = {"type": "transform", "child": child}
        if np.any(scale != 1):
            out["scale"] = scale.tolist()
        if np.any(rot != np.eye(3)):
            out["rotate"] = euler_xyz(rot)
        out["translate"] = pos.tolist()
        return out

    def vdb_grid(self, spec, key: str, offset=0.0, scale=1.0, volume=False,
                 kind="mean") -> tuple[str, dict]:
        """(.npz path, the grid's transform) of a VDB grid reference, its values mapped
        to (g + offset) scale (after g <- -log(max(1e-4, g)) when volume)."""
        from ..io import vdb
        from ..io.grids import load_grid, save_grid
        spec, key = self.grid_ref(spec, key)
        if not isinstance(spec, dict) or spec.get("type") != "vdb":
            self.fail(f"{key}.type", "only VDB grids ({type: vdb, file, density_name}) are "
                      "supported")
        if not isinstance(spec.get("file"), str):
            self.fail(f"{key}.file", "expected the .vdb file name")
        src = (self.base / spec["file"]).resolve()
        name = self.plain_name(spec.get("density_name", "density"), f"{key}.density_name")
        converted = src.parent / f"{src.stem}.{name}.npz"
        if not converted.is_file():
            if not src.is_file():
                self.fail(f"{key}.file", f"file not found: {src}")
            if vdb.import_openvdb() is None:
                self.fail(f"{key}.file", f"{vdb.HOW_TO_GET}; or convert it where one is "
                          f"available (python -m gpiscl convert-vdb {src.name} "
                          f"{converted.name} --grid {name}) and keep the .npz next to the .vdb")
            converted = self.derived_path(f"{src.stem}.{name}.npz")
            try:
                write_atomically(converted, lambda tmp: vdb.convert_vdb(str(src), str(tmp),
                                                                        name))
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
        out = self.derived_path(f"{src.stem}.{name}.{kind}.npz")
        mapped = type(g)((values + offset) * scale, g.origin, g.voxel_size)
        write_atomically(out, lambda tmp: save_grid(tmp, mapped))
        return str(out), spec.get("transform", {})

    def plain_name(self, value, key: str) -> str:
        """A name that becomes part of a file name: one path component, no traversal."""
        if not isinstance(value, str) or not value or value.startswith(".") \
                or any(c in value for c in "/\\\0"):
            self.fail(key, f"must be a plain name (no '/' or '..'; got {value!r})")
        return value

    def derived_path(self, name: str) -> Path:
        """Where a file the conversion writes goes: grid_dir / name (name is plain)."""
        return self.grid_dir / name

    def grid_ref(self, spec, key: str):
        """A grid object given inline or by name from the top-level "grids" list."""
        if isinstance(spec, str):
            return self.named(spec, "grids", key)
        return spec, key

    def tabulated_mean(self, m: dict, key: str) -> dict:
        spec, gkey = self.grid_ref(m.get("grid"), f"{key}.grid")
        path, t = self.vdb_grid(spec, gkey, self.number(m, "offset", key, 0.0),
                                self.number(m, "scale", key, 1.0), bool(m.get("volume", False)))
        interp = spec.get("interpolate", "linear")
        if interp not in ("linear", "quadratic"):
            self.fail(f"{gkey}.interpolate", f'"{interp}" is not supported (linear, quadratic)')
        if interp == "quadratic":
            # Their quadratic B-spline blends samples with non-negative weights, so it
            # cannot cross zero where the samples do not; gpiscl's interpolating cubic can
            # (it overshoots the bunny's far-field 100 to -38.6). Trilinear keeps that
            # property, at the cost of facets in a mirror's reflections.
            self.notes.append(f"{gkey}.interpolate: their quadratic B-spline becomes "
                              "trilinear (also never crosses zero where the samples do not; "
                              "gradients are piecewise constant instead of smooth)")
        grid = {"type": "grid", "file": path, "interpolation": "linear"}
        if not t:
            return grid
        pos, scale, rot = self.transform(t, f"{gkey}.transform")
        return {"type": "transform", "child": grid, "scale": scale.tolist(),
                "rotate": euler_xyz(rot), "translate": pos.tolist()}

    def nonstationary_kernel(self, k: dict, key: str) -> dict:
        from ..io.grids import load_grid, save_grid
        base = self.kernel(k.get("cov", {"type": "squared_exponential"}), f"{key}.cov")
        if base["type"] not in KERNEL_KEYS:
            self.fail(f"{key}.cov.type", "expected a stationary kernel")
        gkey = "grid" if "grid" in k else "variance"
        if gkey not in k:
            self.fail(key, "a nonstationary kernel needs a grid (or variance) VDB grid")
        path, t = self.vdb_grid(k[gkey], f"{key}.{gkey}", self.number(k, "offset", key, 0.0),
                                self.number(k, "scale", key, 1.0), kind="sigma")
        if t:
            pos, scale, rot = self.transform(t, f"{key}.{gkey}.transform")
            if np.any(scale != 1.0) or np.any(rot != np.eye(3)):
                self.fail(f"{key}.{gkey}.transform", "only a translation of a sigma grid is "
                          "supported")
            g = load_grid(path)
            moved = type(g)(g.values, tuple(np.asarray(g.origin) + pos), g.voxel_size)
            path = self.derived_path(Path(path).stem + ".moved.npz")
            write_atomically(path, lambda tmp: save_grid(tmp, moved))
            path = str(path)
        from ..io.grids import load_field_grid, problem_of
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
        # the name the scene gives is checked, and kept (a link stays a link): the
        # loader checks the same name
        path = Path(os.path.abspath(self.base / m["file"]))
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

    def kernel(self, k, key: str) -> dict:
        k = self.table(k, key)
        kind = k.get("type")
        if kind == "nonstationary":
            return self.nonstationary_kernel(k, key)
        if kind == "matern":
            return self.matern_kernel(k, key)
        if kind not in KERNEL_KEYS:
            why = (" (the reference's periodic kernel is radial; gpiscl's is a product over "
                   "axes)" if kind == "periodic" else "")
            self.fail(f"{key}.type", f'covariance "{kind}" is not supported{why}')
        out = {"type": kind}
        for name, value in k.items():
            if name in ("type", "roughness"):
                continue
            if name not in KERNEL_KEYS[kind]:
                self.fail(f"{key}.{name}", f'unknown {kind} key (the reference ignores it; '
                          f'expected one of: {", ".join(KERNEL_KEYS[kind])})')
            out[KERNEL_KEYS[kind][name]] = (self.vector(k, name, key, None) if name == "aniso"
                                            else self.number(k, name, key, None, gt=0))
        if "roughness" in k:
            out.update(self.roughness_length(k, key, out))
        return out

    def matern_kernel(self, k: dict, key: str) -> dict:
        """Their Matern {sigma, v, lengthScale, aniso} (v defaults to 1 there) for v = 3/2
        and 5/2, the smoothnesses gpiscl has in closed form."""
        v = self.number(k, "v", key, 1.0, gt=0)
        kind = next((name for nu, name in MATERNS.items() if abs(v - nu) < 1e-6), None)
        if kind is None:
            self.fail(f"{key}.v", f"Matern smoothness {v:g} is not supported (gpiscl has "
                      "v = 1.5 and 2.5: matern32, matern52)")
        out = {"type": kind}
        for name in k:
            if name not in ("type", *MATERN_KEYS):
                self.fail(f"{key}.{name}", "unknown matern key (the reference ignores it; "
                          f"expected one of: {', '.join(MATERN_KEYS)})")
            if MATERN_KEYS.get(name):
                out[MATERN_KEYS[name]] = (self.vector(k, name, key, None) if name == "aniso"
                                          else self.number(k, name, key, None, gt=0))
        # their double-precision covariance divides by lgamma(v), not Gamma(v) (negative
        # for v = 1.5: -0.12), and the float paths drop sigma^2, so their images of it are
        # not of a Matern GP; the parameters name one, which is what is rendered here
        self.notes.append(f"{key}: matern v = {v:g} -> {kind}; their renderer normalises "
                          "it with lgamma(v) instead of Gamma(v), so its images of this "
                          "covariance differ from a Matern GP's (gpiscl renders the Matern)")
        return out

    def roughness_length(self, k: dict, key: str, out: dict) -> dict:
        """Their knob scenes give `roughness` (a Beckmann alpha) instead of lengthScale.
        Their renderer ignores the key (l stays 1); what it meant is alpha = sqrt(2) sigma
        / l for an SE surface, so l = sqrt(2) sigma / roughness (scenes/knob.json)."""
        alpha = self.number(k, "roughness", key, None, gt=0)
        if k.get("type") != "squared_exponential" or "lengthScale" in k:
            self.notes.append(f"{key}.roughness: ignored, as by their renderer (it only "
                              "stands in for lengthScale on a squared_exponential kernel)")
            return {}
        length = math.sqrt(2) * out.get("sigma", 1.0) / alpha
        self.notes.append(f"{key}.roughness: read as the Beckmann alpha sqrt(2) sigma / l, "
                          f"so length_scale = {length:.6g}; their renderer ignores the key "
                          "and uses l = 1")
        return {"length_scale": length}

    def leaves(self, gp, key: str):
        """(mean, kernel, id, key) of each standard GP under a csg tree."""
        kind = self.table(gp, key).get("type", "standard")
        if kind == "csg":
            return self.leaves(gp["left"], f"{key}.left") + self.leaves(gp["right"], f"{key}.right")
        if kind != "standard":
            self.fail(f"{key}.type", f'GP node "{kind}" is not supported (standard, csg)')
        if "conditioning_data" in gp:
            self.fail(f"{key}.conditioning_data", "conditioning on a mesh is not supported")
        return [(self.mean(gp.get("mean", {"type": "spherical"}), f"{key}.mean"),
                 self.kernel(gp.get("covariance", {"type": "squared_exponential"}),
                             f"{key}.covariance"),
                 self.number(gp, "id", key, 0, integer=True, ge=0), key)]

    def sampler(self, med: dict, key: str) -> dict:
        kind = med.get("type")
        if kind in FS_MEDIA:
            # sample_points and step_size_cov set the reference's segments and fixed step;
            # gpiscl samples online with an adaptive step (fs_march.h), so they have no
            # counterpart and the default miss tolerance applies (still checked: a
            # malformed value is a mistake in their file, said at its key)
            self.number(med, "sample_points", key, 32, integer=True, ge=2)
            self.number(med, "step_size_cov", key, 0.0, ge=0, lt=1)
            s = {"type": "function_space",
                 "memory": MEMORIES.get(med.get("correlation_context", "goldfish"))}
            if s["memory"] is None:
                self.fail(f"{key}.correlation_context",
                          f"unknown memory model (expected one of: {', '.join(MEMORIES)})")
            return s
        if kind in WS_MEDIA:
            return {"type": "weight_space",
                    "features": self.number(med, "basis_functions", key, 300, integer=True,
                                            ge=1)}
        self.fail(f"{key}.type", f'medium "{kind}" is not a Gaussian-process medium')

    def gpis(self, medium_ref, proxy: dict, key: str, render: dict) -> list:
        med, mkey = self.named(medium_ref, "media", key)
        med = self.table(med, mkey)
        phases = [med.get("phase_function", {"type": "brdf", "bsdf": {"type": "lambert"}})]
        extra = med.get("additional_phase_functions", [])
        if not isinstance(extra, list):
            self.fail(f"{mkey}.additional_phase_functions",
                      f"expected a list (got {kind_of(extra)})")
        phases += extra
        sampler = self.sampler(med, mkey)
        self.notes += notes_for(MEDIUM, med, mkey)
        # their only use of the coefficients: an event scatters with sigma_s / sigma_t
        # (density cancels), else the path is absorbed: a factor on the micro-BSDF
        sigma_s = self.number(med, "sigma_s", mkey, 0.0, ge=0)
        sigma_a = self.number(med, "sigma_a", mkey, 0.0, ge=0)
        if sigma_s == 0:
            self.fail(f"{mkey}.sigma_s", "must be > 0: their renderer absorbs every event "
                      "of a medium without scattering")
        scatter = sigma_s / (sigma_s + sigma_a)
        if scatter < 1:
            self.notes.append(f"{mkey}.sigma_a: the scattering chance sigma_s / (sigma_s + "
                              f"sigma_a) = {scatter:.4g} multiplies the micro-BSDF albedo")
        if med.get("single_realization"):
            render["realization"] = 0
        shapes = []
        for mean, kernel, gp_id, gkey in self.leaves(med.get("gaussian_process", {}),
                                                    f"{mkey}.gaussian_process"):
            if gp_id >= len(phases):
                self.fail(f"{gkey}.id", f"no phase function for GP id {gp_id}")
            pkey = (f"{mkey}.phase_function" if gp_id == 0
                    else f"{mkey}.additional_phase_functions[{gp_id - 1}]")
            phase = self.table(phases[gp_id], pkey)
            if phase.get("type") != "brdf":
                self.fail(f"{pkey}.type", "only brdf phase functions (micro-BSDFs) are supported")
            bsdf = self.bsdf(phase.get("bsdf", {}), f"{pkey}.bsdf", micro=True)
            bsdf["albedo"] = [a * scatter for a in bsdf["albedo"]]
            # their medium exists only inside its container, so their renderer always cuts
            # the object at the container's boundary, which is the proxy here
            shapes.append({"type": "gpis", "proxy": proxy, "mean": mean, "kernel": kernel,
                           "sampler": dict(sampler), "bsdf": bsdf, "clip": True})
        return shapes

    def primitive(self, p: dict, key: str, render: dict, shapes: list, lights: list):
        kind = p.get("type")
        t = p.get("transform", {})
        if p.get("sample", True) is False:
            self.notes.append(f"{key}.sample: false keeps their light sampling away from this "
                              "emitter; gpiscl samples every light")
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
            lights.append(self.environment_light(p.get("emission", 1.0), t, key))
        elif kind == "infinite_sphere_cap":
            cap = self.number(p, "cap_angle", key, 10.0, gt=0, lt=90)
            theta = math.radians(cap)
            _, _, rot = self.transform(t, f"{key}.transform")
            power = self.colour(p.get("power", 1.0), f"{key}.power")
            # their radiance power / (2 pi (1 - cos cap)); 1 - cos as 2 sin^2(cap / 2),
            # which keeps its digits for their 0.1 degree sun
            one_minus_cos = 2 * math.sin(theta / 2) ** 2
            radiance = [c / (2 * math.pi * one_minus_cos) for c in power]
            lights.append({"type": "directional", "direction": (rot @ [0, 1, 0]).tolist(),
                           "angular_radius": cap,
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

    def environment_light(self, emission, t, key) -> dict:
        ekey = f"{key}.emission"
        if self.environment is not None:
            self.notes.append(f"{ekey}: replaced by the given environment")
            if self.environment["type"] == "environment_map" and isinstance(emission, str):
                # a map standing in for their map is turned as theirs is
                return {**self.environment, "rotation": self.map_rotation(t, key)}
            return self.environment
        if not isinstance(emission, str):
            return {"type": "environment", "radiance": self.colour(emission, ekey)}
        from ..io.radiance_hdr import read_environment_rgb
        path = Path(os.path.abspath(self.base / emission))
        if path.suffix.lower() not in (".exr", ".hdr"):
            self.fail(ekey, f'environment map "{emission}" is neither .exr nor .hdr; convert '
                      "it or pass a substitute environment")
        if not path.is_file():
            self.fail(ekey, f"file not found: {path}; pass a substitute environment")
        try:
            read_environment_rgb(path)
        except (OSError, ValueError) as exc:
            self.fail(ekey, f"{exc}; pass a substitute environment")
        return {"type": "environment_map", "file": str(path),
                "rotation": self.map_rotation(t, key)}

    def map_rotation(self, t, key: str) -> float:
        """Our environment map rotation (degrees about +y) for their transform: their
        u = atan2(z, x) / 2 pi + 1/2 in the map's frame, whose rotation (Ry(-y)) turns it
        by y; ours is phi = atan2(z, x) turned by `rotation`."""
        _, _, rot = self.transform(t, f"{key}.transform")
        spin = math.degrees(math.atan2(-rot[0, 2], rot[0, 0]))
        if not np.allclose(rot @ [0, 1, 0], [0, 1, 0], atol=1e-9):
            self.fail(f"{key}.transform.rotation", "an environment map turns about y only")
        return (spin + 180.0) % 360.0

    def guarded(self, key: str, convert, *args):
        """convert(*args), with a malformed part of the input (a number where an object
        belongs, a string for a resolution, a zero divisor) as one SceneError naming the
        input file and key instead of whatever the mapping code tripped on."""
        try:
            return convert(*args)
        except (TypeError, ValueError, AttributeError, KeyError, IndexError,
                ZeroDivisionError, OverflowError) as exc:
            if isinstance(exc, SceneError):
                raise
            self.fail(key, f"malformed Tungsten input ({type(exc).__name__}: "
                           f"{str(exc).splitlines()[0] if str(exc) else ''})")

    def convert(self) -> dict:
        self.table(self.doc, "")
        # every value is checked where it is read; guarded() is the net for any case
        # those checks missed, so no input ends in a traceback
        camera = self.guarded("camera", self.camera)  # first: render() reads its tonemap
        render = self.guarded("renderer", self.render)
        shapes, lights = [], []
        primitives = self.doc.get("primitives", [])
        if not isinstance(primitives, list):
            self.fail("primitives", f"expected a list (got {kind_of(primitives)})")
        for i, p in enumerate(primitives):
            key = f"primitives[{i}]"
            first = len(shapes), len(lights)
            self.guarded(key, self.primitive, self.table(p, key), key, render, shapes, lights)
            self.origin.update({f"shapes[{j}]": key for j in range(first[0], len(shapes))})
            self.origin.update({f"lights[{j}]": key for j in range(first[1], len(lights))})
        return {"description": f"converted from {Path(self.source).name}",
                "camera": camera, "render": render, "shapes": shapes, "lights": lights}


def convert_tungsten(doc: dict, source: str = "<dict>", environment: dict | None = None,
                     grid_dir=None):
    """gpiscl scene dict and a list of notes on lossy mappings; SceneError if unsupported.
    grid_dir: where the .npz grids it derives from VDB grids are written (default: the
    scene file's folder). tungsten_convert.convert_file is the whole conversion of a
    file: checked outputs, nothing written on an error."""
    c = _Converter(doc, source, environment, grid_dir)
    scene = c.convert()
    try:
        load_scene(scene)   # strict validation, and its problem said at their key
    except SceneError as exc:
        head = exc.key.split(".")[0]
        origin = c.origin.get(head)
        raise SceneError(source, origin or "", f"converts to an invalid scene at "
                         f"{exc.key or 'its top level'}: {exc.reason}") from None
    return scene, c.notes
