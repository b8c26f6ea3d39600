"""Resolved GPIS scene objects -> host GP model objects -> device arrays."""
from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..layout import records as layouts
from ..gp import kernels as K
from ..gp import means as M
from ..scene.proxies import analyse, bounding_proxy
from ..scene.transforms import transform_matrix
from ..gp.spectral import pack_order_tables
from ..layout.gp_records import (GP_KERNEL, MEAN_NODE, pack_kernel, pack_kernel_grids, sigma_top,
                                 pack_mean_parts)
from ..scene.gpis import DEFAULT_OCCUPANCY, FIELD_KEYS, field_minimum
from .colour_fields import pack_field
from ..errors import SceneError
from .posterior import build_posterior, pack_posterior
from ..kinds.memory_models import MEMORY_MODELS
from .proxy_cut import cut_extent
from ..layout import function_space_records as FSL
from ..layout.constants import FS_MEAN_Z
from ..kinds.gp_kernels import GP_KERNELS
from ..kinds.means import MEAN_OPS, MEAN_PRIMITIVES

# Roots are refined to this fraction of the kernel's length scale: far below the scale
# on which the realization varies, far above float32 resolution of scene coordinates.
ROOT_TOLERANCE = 1e-4


def _build_field(f: dict):
    if f["type"] == "grid":
        from ..io.grids import load_field_grid
        return load_field_grid(f["file"])
    params = {key: (tuple(v) if isinstance(v, list) else v) for key, v in f.items()
              if key != "type"}
    return K.FIELDS[f["type"]](**params)


def build_kernel(k: dict, proxy: dict | None = None) -> K.Kernel:
    """proxy: where rays sample, for the step rule's smallest l(x) (required with a
    linear length_scale_field)."""
    params = {key: (tuple(v) if isinstance(v, list) else v) for key, v in k.items()
              if key not in ("type", *FIELD_KEYS)}
    base = GP_KERNELS[k["type"]].host.cls(**params)
    sf, lf = k.get("sigma_field"), k.get("length_scale_field")
    if sf is None and lf is None:
        return base
    step = None
    if lf is not None and proxy is not None:
        step = base.length_scale * field_minimum(lf, proxy)
    return K.NonStationary(base, sigma_field=sf and _build_field(sf),
                           length_scale_field=lf and _build_field(lf), step_length_scale=step)


def build_mean(m: dict, bakes=None) -> M.Mean:
    """The mean tree of a resolved mean; bakes: a device's bakes for procedural grids and
    grid slope bounds (render/device_bakes.py; numpy when None, the same numbers)."""
    kind = m["type"]
    if kind in MEAN_OPS:
        return MEAN_OPS[kind].host(build_mean(m["left"], bakes), build_mean(m["right"], bakes),
                                   k=m["k"])
    if kind == "transform":
        return M.Transform(build_mean(m["child"], bakes), transform_matrix(m))
    if kind in MEAN_PRIMITIVES and MEAN_PRIMITIVES[kind].schema is not None:
        return MEAN_PRIMITIVES[kind].host.build(m)
    from .sdf_bake import mesh_mean, prepare_slopes, procedural_mean
    if kind == "mesh":
        grid = mesh_mean(m["file"], m["resolution"], m["margin"], m["band"],
                         transform_matrix(m["transform"]))[0]
    elif kind == "grid":
        from ..io.grids import load_grid
        grid = load_grid(m["file"])
    elif kind == "procedural":
        grid = procedural_mean(m["function"], m["resolution"], bakes=bakes)[0]
    else:
        raise AssertionError(kind)
    grid = dataclasses.replace(grid, interpolation=m["interpolation"])
    # the slope bounds the device's grid records need (gp_records.pack_mean), cached
    prepare_slopes(grid, bakes=bakes)
    return grid


def _join(parts: list) -> np.ndarray:
    """np.concatenate(parts), emptying the list as it goes: each part is freed once copied,
    so a scene's grid records are not held twice."""
    nodes = MEAN_NODE.page_aligned_zeros(sum(len(p) for p in parts))   # used in place
    at = 0
    parts.reverse()
    while parts:
        part = parts.pop()
        assert part.dtype == nodes.dtype    # as np.concatenate would insist
        nodes[at:at + len(part)] = part
        at += len(part)
    return nodes


def sampler_window(kernel: dict) -> int:
    """Samples of the ray a function-space flight conditions on besides its memory."""
    return GP_KERNELS[kernel["type"]].host.window or FSL.DEFAULT_WINDOW


def kernel_length_scale(k: dict) -> float:
    """The length on which a realization varies: root tolerances and steps scale with it."""
    return GP_KERNELS[k["type"]].host.length(k)


# The occupancy bound's marches stop at steps below this fraction of the length scale:
# finer clipping saves less sampling than the march costs (tools/bench_occupancy.py).
OCCUPANCY_MIN_STEP = 0.1


def occupancy_step(g: dict, level: float, kernel: K.Kernel | None = None) -> float:
    """The world length below which the occupancy bound's marches stop (gpis_proxy.h):
    OCCUPANCY_MIN_STEP l, and for a function-space object at most (FS_MEAN_Z - z)
    sigma_max, where level = z sigma_max. A flight sphere-traces the same mean on from
    there, with dearer evaluations, down to FS_MEAN_Z sd (fs_mean_step's far balls): where
    sigma << l (the knob: sigma / l = 0.007) the march stopped ~18 sd from the zero set
    and left the balls ~3.5 hops a flight (docs/design/grid-means.md, "Where the occupancy
    marches stop"). Any floor keeps the bound: a march stopped early only clips less."""
    step = OCCUPANCY_MIN_STEP * kernel_length_scale(g["kernel"])
    if g["sampler"]["type"] == "function_space" and level > 0.0:
        near = FS_MEAN_Z * sigma_max(g, kernel) - level
        if near > 0.0:
            step = min(step, near)
    return step


def occupancy_level(g: dict, kernel: K.Kernel | None = None) -> float:
    """z sigma_max for the object's occupancy bound epsilon (0: off): where the mean
    exceeds it, P(f <= 0) = Phi(-mu / sigma(x)) < Phi(-z) = epsilon, because sigma(x) <=
    sigma_max everywhere in the proxy. Rounded up to the next float32, as the device
    compares in float. kernel: build_kernel(g["kernel"], g["proxy"]) if already built."""
    eps = (g.get("bounds") or {}).get("occupancy")
    if eps is None:
        return 0.0
    level = NormalDist().inv_cdf(1.0 - eps) * sigma_max(g, kernel)
    return float(np.nextafter(np.float32(level), np.float32(np.inf)))


def sigma_max(g: dict, kernel: K.Kernel | None = None) -> float:
    """The largest sigma(x) over the object's proxy (sigma itself without a sigma field)."""
    if kernel is None:
        kernel = build_kernel(g["kernel"], g["proxy"])
    base = kernel.base if isinstance(kernel, K.NonStationary) else kernel
    return math.sqrt(base.variance) * sigma_field_max(g, kernel)


def sigma_field_max(g: dict, kernel: K.Kernel) -> float:
    """The sigma field's largest value over the object's proxy (1 without one)."""
    sf = g["kernel"].get("sigma_field")
    if sf is None:
        return 1.0
    if sf["type"] == "radial":
        return max(sf["inner"], sf["outer"])
    if sf["type"] == "grid":
        return kernel.sigma_field.maximum()
    # max of a linear field = -(min of its negation)
    neg = dict(sf, value=-sf["value"], gradient=[-c for c in sf["gradient"]])
    return -field_minimum(neg, g["proxy"])


def _warn_if_cut(g: dict, mean: M.Mean, kernel: K.Kernel, source: str, key: str) -> None:
    """One line on stderr when the object reaches its proxy's boundary (proxy_cut.py):
    the render is still what the scene says, but a cut nobody asked for is a wrong image
    nobody sees coming. With the occupancy bound off, its default epsilon."""
    eps = (g.get("bounds") or {}).get("occupancy") or DEFAULT_OCCUPANCY
    share, p = cut_extent(mean, kernel, g["proxy"], eps)
    if share > 0.0:
        print(f"gpiscl: warning: {source}: {key}.proxy: cuts the object: P(f < 0) >= {eps:g} "
              f"on {100.0 * share:.3g}% of the proxy's boundary (up to {p:.2g}), where the "
              f"render shows a flat cut face; enlarge the proxy, or set {key}.clip to true "
              f"if the cut is meant", file=sys.stderr)


def _posterior(g: dict, kernel: K.Kernel, mean: M.Mean, source: str, key: str) -> tuple:
    """(FsObs rows, doubles) of the object's posterior (compile/posterior.py), empty
    without observations."""
    if g.get("observations") is None:
        return FSL.FS_OBS.zeros(0), np.zeros(0)
    try:
        return pack_posterior(build_posterior(g["observations"], kernel, mean))
    except np.linalg.LinAlgError as exc:
        raise SceneError(source, f"{key}.observations", str(exc)) from None


@dataclass
class ObjectShare:
    """One object's share of the scene's tables; offsets within the share."""
    kernel: K.Kernel
    records: list           # MeanNode record arrays: its mean program, then the grid
                            # fields of its kernel
    mean_count: int         # records of the mean program
    fields: dict            # GpisObject colour slot -> its field's records
    planes: np.ndarray      # mesh proxy: face planes (p, 4) float32; else empty
    posterior: tuple        # (FsObs rows, doubles), empty without observations


def _object_fields(o, g: dict, material_of) -> None:
    """The GpisObject fields that are the object's alone (no offsets into shared tables)."""
    proxy = g["proxy"]
    o["proxy_kind"] = layouts.GPIS_PROXIES[proxy["type"]]
    box = bounding_proxy(proxy)
    if box["type"] == "box":
        o["proxy_p0"][:3], o["proxy_p1"][:3] = box["min"], box["max"]
    else:
        o["proxy_p0"][:] = (*box["center"], box["radius"])
    o["sampler"] = layouts.GPIS_SAMPLERS[g["sampler"]["type"]]
    o["features"] = g["sampler"].get("features") or 0
    if g["sampler"]["type"] == "function_space":
        fs = g["sampler"]
        o["memory"] = layouts.GPIS_MEMORIES[
            "classical_medium" if g.get("classical") == "medium" else fs["memory"]]
        for key in ("memory_cap", "refine", "miss_tolerance"):
            o[key] = fs[key]
        o["window"] = sampler_window(g["kernel"])
    o["material"] = material_of(g["bsdf"])
    o["tolerance"] = ROOT_TOLERANCE * kernel_length_scale(g["kernel"])


def compile_object(g: dict, o, kernel_record: np.ndarray, source: str, key: str,
                   bakes=None) -> ObjectShare:
    """Builds the object's kernel and mean once and packs its share of the tables; fills
    kernel_record (GpKernel, 1) and o's occupancy level."""
    kernel = build_kernel(g["kernel"], g["proxy"])
    kernel_record[:] = pack_kernel(kernel)
    if g["kernel"].get("sigma_field") is not None:   # over the proxy: linear fields too
        kernel_record["sigma_top"] = sigma_top(kernel, sigma_field_max(g, kernel))
    try:
        mean = build_mean(g["mean"], bakes)
        records = pack_mean_parts(mean)
    except ValueError as exc:
        raise SceneError(source, f"{key}.mean", str(exc)) from None
    if not g.get("clip"):
        _warn_if_cut(g, mean, kernel, source, key)
    posterior = _posterior(g, kernel, mean, source, key)
    mean = None                     # its grids live on in records alone
    # the bound follows the prior mean, not the posterior's
    o["occupancy_level"] = 0.0 if len(posterior[0]) else occupancy_level(g, kernel)
    o["occupancy_step"] = occupancy_step(g, float(o["occupancy_level"]), kernel)
    count = sum(len(part) for part in records)
    # grid fields of sigma(x) and l(x): the kernel holds their offsets from the object's
    # mean program (fs_sampling.h fs_fields)
    records += pack_kernel_grids(kernel, kernel_record, count)
    fields = {slot: pack_field(g[name])
              for name, slot in (("color", "color_field"), ("emission", "emission_field"))
              if g.get(name) is not None}
    planes = np.zeros((0, 4), np.float32)
    if g["proxy"]["type"] == "mesh":
        planes = np.asarray(analyse(g["proxy"])[0], np.float32).reshape(-1, 4)
    return ObjectShare(kernel, records, count, fields, planes, posterior)


@dataclass
class CompiledGpis:
    objects: np.ndarray     # GpisObject records
    kernels: np.ndarray     # GpKernel records, one per object
    mean_nodes: np.ndarray  # MeanNode records: each object's mean program, then its
                            # kernel's grid fields, object after object
    field_nodes: np.ndarray  # colour and emission fields (MeanNode records); 0: none
    order_table: np.ndarray  # weight space: periodic-order CDFs of all objects (float32)
    proxy_planes: np.ndarray      # mesh proxies' face planes, (p, 4) float32
    posterior_obs: np.ndarray     # posteriors' observation rows (FsObs)
    posterior_doubles: np.ndarray  # posteriors' alpha, factor and noise deviations
    ring_stride: int        # function space: observations per path ring (>= 1)
    window_max: int         # function space: the largest window (0: no such object)

    @property
    def posterior_rows(self) -> np.ndarray:
        """Observation rows of each object's posterior (0: the prior)."""
        return self.objects["posterior_count"]

    def uses(self, sampler: str) -> bool:
        return bool(np.any(self.objects["sampler"] == layouts.GPIS_SAMPLERS[sampler]))


def ring_stride(objects: np.ndarray) -> int:
    """Observations per path ring: the largest cap of a function-space object whose memory
    model keeps a ring, else 1."""
    fs = objects["sampler"] == layouts.GPIS_SAMPLERS["function_space"]
    ids = [MEMORY_MODELS.id(name) for name in MEMORY_MODELS.with_trait("ring")]
    ring = objects[fs & np.isin(objects["memory"], ids)]
    return int(ring["memory_cap"].max()) if len(ring) else 1


def compile_gpis(shapes: list, material_of, source: str = "<scene>",
                 keys: list | None = None, bakes=None) -> CompiledGpis:
    """shapes: the resolved "gpis" shapes in scene order; material_of(bsdf) -> index;
    source and keys (each shape's key path) name what a compile-time error is about;
    bakes: see build_mean."""
    keys = keys or [f"gpis[{i}]" for i in range(len(shapes))]
    objects = layouts.GPIS_OBJECT.zeros(len(shapes))
    kernels = GP_KERNEL.zeros(len(shapes))
    records, planes, obs, doubles, built = [], [], [], [], []
    fields = [MEAN_NODE.zeros(1)]       # record 0: no field
    at_record, at_field, at_plane, at_obs, at_double = 0, 1, 0, 0, 0
    for i, g in enumerate(shapes):
        o = objects[i]
        _object_fields(o, g, material_of)
        share = compile_object(g, o, kernels[i:i + 1], source, keys[i], bakes)
        built.append(share.kernel)
        o["mean_first"], o["mean_count"] = at_record, share.mean_count
        for slot, field in share.fields.items():
            o[slot] = at_field
            at_field += len(field)
            fields.append(field)
        at_record += sum(len(part) for part in share.records)
        records += share.records
        share.records = None                    # the list holds them; _join frees them
        o["proxy_first"], o["proxy_count"] = at_plane, len(share.planes)
        at_plane += len(share.planes)
        planes.append(share.planes)
        rows, values = share.posterior
        o["posterior_first"], o["posterior_count"] = at_obs, len(rows)
        o["posterior_doubles"] = at_double
        at_obs, at_double = at_obs + len(rows), at_double + len(values)
        obs.append(rows)
        doubles.append(values)
    table, t_first, t_count = pack_order_tables(built)
    objects["order_first"], objects["order_count"] = t_first, t_count
    fs = objects[objects["sampler"] == layouts.GPIS_SAMPLERS["function_space"]]
    return CompiledGpis(objects, kernels, _join(records), _join(fields), table,
                        np.concatenate([np.zeros((0, 4), np.float32), *planes]),
                        np.concatenate([FSL.FS_OBS.zeros(0), *obs]),
                        np.concatenate([np.zeros(0), *doubles]),
                        ring_stride(objects), int(fs["window"].max(initial=0)))
