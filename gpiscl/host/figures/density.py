"""The GPIS density as data and pictures (docs/design/classical-limits.md): free flights
and first-hit normals of one GPIS object along one ray, drawn by the renderer's own
function-space sampler under each memory model and by its classical medium counterpart,
against the closed forms of its classical counterparts (the medium's transmittance
exp(-int sigma_t) along the ray, Rice's entry rate, the Beckmann slope law); and the two
limits as series (free flights vs l, normals vs alpha).

Data functions need numpy only; plot_* need matplotlib (the optional `plots` extra),
imported only when a figure is drawn."""
from __future__ import annotations

import csv
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CLI_SOURCE, SceneError
from ..gp import classical as C
from ..gp.kernels import Kernel, NonStationary
from ..gp.means import Constant, Mean, Plane
from ..layout.constants import FS_CL_FAR, FS_CL_STRETCH
from ..layout.function_space_records import STATUS
from ..layout.random_slots import FS_TRACK_CAP
from ..render.device import Device, shared_device
from ..render.flight_samples import PackedGpis, flights, pack_scene_object
from .plotting import pyplot
from .samples import resolve_target

# the memory models, then the classical medium counterpart (kernels_cl/lib/fs_classical.h)
MEMORIES = ("none", "renewal", "renewal_plus", "global", "classical_medium")


@dataclass
class Ray:
    origin: np.ndarray
    direction: np.ndarray      # unit
    length: float


def default_ray(mean: Mean, center, half_extent: float) -> Ray:
    """Through the proxy's centre, against the mean's gradient there (straight down -z
    where the mean is flat), from the proxy's edge to the opposite one."""
    _, g = mean.value_and_gradient(np.asarray(center, float)[None])
    g = g[0]
    d = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 0.0, -1.0])
    return Ray(np.asarray(center, float) - half_extent * d, d, 2.0 * half_extent)


def parse_ray(text: str) -> Ray:
    """'ox,oy,oz,dx,dy,dz,length' from the command line."""
    try:
        v = [float(x) for x in text.split(",")]
        if len(v) != 7 or not v[6] > 0 or not np.linalg.norm(v[3:6]) > 0:
            raise ValueError
    except ValueError:
        raise SceneError("<command line>", "--ray", "expected ox,oy,oz,dx,dy,dz,length with a "
                         f"non-zero direction and a positive length (got {text!r})") from None
    d = np.asarray(v[3:6])
    return Ray(np.asarray(v[:3]), d / np.linalg.norm(d), v[6])


# --- data ---------------------------------------------------------------------------------

def free_path_fit(t, length: float):
    """(mean free path, hits) of flights t (-1: none within length): the exponential's
    maximum-likelihood mean free path with the misses censored at `length`."""
    t = np.asarray(t, float)
    hit = t >= 0
    return float(np.where(hit, t, length).sum() / max(hit.sum(), 1)), int(hit.sum())


def counterpart_law(kernel: Kernel, mean: Mean, ray: Ray, nodes: int = 20001,
                    interval=None):
    """(t, sigma_t, optical depth) on `nodes` points of the ray within interval (t0, t1)
    (the part the proxy keeps, PackedGpis.interval; default the whole ray): the medium
    counterpart's first flight has P(T > t) = exp(-optical depth) (gp/classical.
    extinction_profile; np.interp holds the depth constant outside) and density sigma_t
    exp(-optical depth)."""
    t0, t1 = interval or (0.0, ray.length)
    if not t1 > t0:        # the ray misses the proxy: no medium on it
        return np.array([0.0, ray.length]), np.zeros(2), np.zeros(2)
    return C.extinction_profile(kernel, mean, ray.origin, ray.direction, t0, t1, nodes)


def ks_with_misses(t, law) -> float:
    """One-sample KS distance of first flights t (-1: no hit within the ray) to the
    counterpart_law: a miss is a flight beyond the ray's end, so the empirical CDF's last
    step, up to the end, counts against 1 - exp(-depth(end))."""
    grid, _, depth = law
    n, hits = len(t), np.sort(np.asarray(t, float)[np.asarray(t) >= 0])
    if n == 0:
        return float("nan")
    cdf = -np.expm1(-np.interp(hits, grid, depth))
    i = np.arange(1, len(hits) + 1)
    end = abs(len(hits) / n + np.expm1(-depth[-1]))
    if not len(hits):
        return float(end)
    return float(max(np.max(i / n - cdf), np.max(cdf - (i - 1) / n), end))


def flight_summary(kernel: Kernel, mean: Mean, ray: Ray, runs: dict, law=None) -> list:
    """One row per memory model and flight: hits, the fitted mean free path, its KS
    distance to that exponential (hits only, the law truncated at the ray's end), the
    medium counterpart's extinction where the ray enters the proxy (Rice's entry rate,
    Eq. 3 of the note, with the local mean, its slope and fields; 0 where that is far
    outside a shape mean); for the first flight the counterpart's transmittance
    exp(-int sigma_t) along the ray and the KS distance of the flights to its law
    (classical_medium: noise only; the memory models: how far the GPIS is from its
    counterpart), and for the first hit the Beckmann alpha and its fit. Flights that
    failed (a solver status: `failed`, the paths end there) are in no statistic; the
    flights after a hit that failed are not started. law: counterpart_law's, if computed."""
    law = law or counterpart_law(kernel, mean, ray)
    rate = float(law[1][0])
    rows = []
    for memory, out in runs.items():
        for b in range(out.shape[1]):
            t = out[:, b, 0]
            started = np.full(len(t), True) if b == 0 else out[:, b - 1, 0] >= 0
            failed = out[:, b, 4] != 0
            mfp, hits = free_path_fit(t[started & ~failed], ray.length)
            ks = C.ks_to_cdf(t[t >= 0], lambda x, m=mfp: -np.expm1(-x / m)
                             / -np.expm1(-ray.length / m)) if hits else float("nan")
            row = {"memory": memory, "flight": b + 1, "paths": int(started.sum()), "hits": hits,
                   "failed": int(np.count_nonzero(failed)), "mean_free_path": mfp,
                   "ks_exponential": ks,
                   "rice_entry_rate": rate,
                   "rice_mean_free_path": 1.0 / rate if rate > 0 else float("inf")}
            if b == 0:
                row.update({"counterpart_transmittance": math.exp(-law[2][-1]),
                            "ks_counterpart": ks_with_misses(t[~failed], law)})
                row.update(normal_summary(kernel, mean, ray, out[t >= 0, 0]))
            rows.append(row)
    return rows


def slopes_at_hits(grad, direction):
    """tan^2 of the angle between each hit's normal and -direction."""
    d = np.asarray(direction, float)
    along = grad @ d
    tangential = grad - along[:, None] * d
    return np.sum(tangential ** 2, axis=1) / along ** 2


def normal_summary(kernel: Kernel, mean: Mean, ray: Ray, hits) -> dict:
    """The first hits' slopes against Beckmann with the alpha of the mean's gradient and
    of the GP's gradient variance at the mean hit point (a tangent perpendicular to the
    ray for anisotropic kernels; sigma and l fields taken there)."""
    if len(hits) == 0:
        return {}
    x = ray.origin + np.mean(hits[:, 0]) * ray.direction
    _, g = mean.value_and_gradient(x[None])
    gn = float(np.linalg.norm(g[0]))
    if gn == 0.0:
        return {}
    tangent = np.cross(ray.direction, [1.0, 0.0, 0.0])
    if np.linalg.norm(tangent) < 1e-6:
        tangent = np.cross(ray.direction, [0.0, 1.0, 0.0])
    tangent = tangent / np.linalg.norm(tangent)
    # C.beckmann_alpha at x: a field's kernel is not the same at the origin
    alpha = math.sqrt(2.0 * float(kernel.cov_dd(x, tangent, x, tangent))) / gn
    tan2 = slopes_at_hits(hits[:, 1:4], ray.direction)
    return {"beckmann_alpha": alpha, "alpha_fit": float(math.sqrt(np.mean(tan2))),
            "ks_beckmann": C.ks_to_cdf(tan2 / alpha ** 2, lambda v: -np.expm1(-v))}


def density_data(kernel: Kernel, mean: Mean, ray: Ray, paths: int = 20000, bounces: int = 2,
                 seed: int = 1, memories=MEMORIES, device: Device | None = None,
                 packed: PackedGpis | None = None) -> dict:
    """Flights per memory model ((paths, bounces, 5) arrays of flight_samples.flights),
    their summary rows, and the medium counterpart's first-flight density along the ray
    ("counterpart": t, sigma_t exp(-optical depth), its transmittance). packed: the
    object's device records as the renderer compiles them (flight_samples.
    pack_scene_object); None packs kernel and mean. Failed flights are counted, not
    raised: the summary's `failed`, failures(runs)."""
    device = device or shared_device()
    runs = {m: flights(device, kernel, mean, ray.origin, ray.direction, ray.length, paths,
                       memory=m, bounces=bounces, seed=seed, packed=packed)
            for m in memories}
    law = counterpart_law(kernel, mean, ray, interval=packed and packed.interval(
        ray.origin, ray.direction, ray.length))
    t, rate, depth = law
    with np.errstate(invalid="ignore"):      # inf rate x exp(-800) = 0
        density = np.where(np.isfinite(rate), rate * np.exp(-depth), 0.0)
    return {"ray": ray, "runs": runs, "summary": flight_summary(kernel, mean, ray, runs, law),
            "counterpart": {"t": t, "density": density,
                            "transmittance": math.exp(-depth[-1])},
            "homogeneous": is_homogeneous(kernel, mean)}


def failures(runs: dict) -> str:
    """'' if every flight ended well, else per model the paths whose flight failed and
    the statuses (layout/function_space_records.STATUS names)."""
    names = {v: k for k, v in STATUS.items()}
    return "; ".join(
        f"{m} {int(np.count_nonzero(o[:, :, 4]))} of {len(o)} paths "
        f"({', '.join(sorted({names.get(int(v), str(v)) for v in o[:, :, 4].ravel() if v}))})"
        for m, o in runs.items() if np.any(o[:, :, 4]))


def is_homogeneous(kernel: Kernel, mean: Mean) -> bool:
    """The medium counterpart is one exponential everywhere and in every direction (as
    fs_classical_flight's homogeneous branch): a constant mean, no fields, isotropic."""
    return (isinstance(mean, Constant) and not isinstance(kernel, NonStationary)
            and len(set(np.ravel(kernel.aniso))) == 1)


def medium_limit_series(kernel_of, lengths, level: float, paths: int, seed: int = 1,
                        device: Device | None = None, path_lengths: float = 10.0) -> list:
    """Constant mean `level`, first flights along +x for each length scale l of
    kernel_of(l): the fitted extinction against Rice's entry rate, and the KS distance to
    the exponential of the fitted mean free path. Rays are path_lengths mean free paths
    long (Rice's), so the fit barely needs the censoring."""
    device = device or shared_device()
    rows = []
    for l in lengths:
        kernel = kernel_of(l)
        rate = float(C.entry_rate(kernel, level))
        L = path_lengths / rate
        t = flights(device, kernel, Constant(offset=level), (0, 0, 0), (1, 0, 0), L, paths,
                    memory="renewal", bounces=1, seed=seed)[:, 0, 0]
        mfp, hits = free_path_fit(t, L)
        rows.append({"length_scale": l, "level": level, "rice_entry_rate": rate,
                     "fitted_rate": 1.0 / mfp, "hits": hits,
                     "ks_exponential": C.ks_to_exponential(np.where(t >= 0, t, np.inf),
                                                           1.0 / mfp)})
    return rows


def surface_limit_series(kernel_of, sigmas, paths: int, seed: int = 1,
                         device: Device | None = None) -> list:
    """Plane mean z (unit slope), rays straight down from 6 sigma above, for each sigma of
    kernel_of(sigma) (l fixed by the caller): alpha = sqrt(2 lambda_2), the fitted alpha,
    the KS distance of tan^2 theta / alpha^2 to Exp(1) (Beckmann), and the tangential
    gradient's variance over lambda_2 (exactly 1 at every sigma / l)."""
    device = device or shared_device()
    plane = Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0))
    rows = []
    for s in sigmas:
        kernel = kernel_of(s)
        out = flights(device, kernel, plane, (0, 0, 6 * s), (0, 0, -1), 12 * s, paths,
                      memory="renewal", bounces=1, seed=seed)[:, 0]
        g = out[out[:, 0] >= 0, 1:4]
        alpha = C.beckmann_alpha(kernel)
        tan2 = slopes_at_hits(g, (0.0, 0.0, -1.0))
        lam2 = C.slope_variance(kernel)
        rows.append({"sigma": s, "beckmann_alpha": alpha,
                     "alpha_fit": float(math.sqrt(np.mean(tan2))), "hits": len(g),
                     "ks_beckmann": C.ks_to_cdf(tan2 / alpha ** 2, lambda v: -np.expm1(-v)),
                     "tangential_variance_x": float(np.var(g[:, 0]) / lam2),
                     "tangential_variance_y": float(np.var(g[:, 1]) / lam2)})
    return rows


def masking_series(kernel_of, sigmas, paths: int, memories=MEMORIES[:4], seed: int = 1,
                   device: Device | None = None, smith_draws: int = 2_000_000) -> list:
    """Plane mean, a ray straight down, then a Lambertian bounce off the first hit's
    sampled facet: the fraction of paths whose second flight (8 sigma / sqrt(lambda_2), 8 l
    for SE) meets
    the surface again, per memory model, against Smith's masking for the same Beckmann
    alpha (gp/classical.smith_rehit_fraction)."""
    device = device or shared_device()
    plane = Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0))
    rng = np.random.default_rng(seed)
    rows = []
    for s in sigmas:
        kernel = kernel_of(s)
        alpha = C.beckmann_alpha(kernel)
        row = {"sigma": s, "beckmann_alpha": alpha,
               "smith": C.smith_rehit_fraction(alpha, smith_draws, rng)}
        for memory in memories:
            out = flights(device, kernel, plane, (0, 0, 6 * s), (0, 0, -1), 12 * s, paths,
                          memory=memory, bounces=2, seed=seed,
                          later_length=8.0 * s / math.sqrt(C.slope_variance(kernel)))
            first = out[:, 0, 0] >= 0
            row[memory] = float(np.mean(out[first, 1, 0] >= 0))
            row[f"{memory}_paths"] = int(first.sum())
        rows.append(row)
    return rows


def brdf_table(kernel: Kernel, theta_i_deg: float, paths: int, memory: str, bins: int = 18,
               bounces: int = 16, seed: int = 1, device: Device | None = None) -> dict:
    """Plane mean, a white mirror micro-BSDF, light from theta_i: where the energy leaves
    (theta_o bins of 90/bins degrees, all phi) after exactly one hit and after several,
    per path traced by the device sampler (rays reflected about each sampled normal),
    against rough_conductor's single-scattering Beckmann BRDF with the same alpha."""
    device = device or shared_device()
    ti = math.radians(theta_i_deg)
    d = np.array([-math.sin(ti), 0.0, -math.cos(ti)])
    s = math.sqrt(kernel.variance)
    start = -d * 6.0 * s / math.cos(ti)
    plane = Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0))
    out = flights(device, kernel, plane, start, d, 12.0 * s / math.cos(ti), paths,
                  memory=memory, bounces=bounces, seed=seed, mirror=True,
                  later_length=8.0 * s / math.sqrt(C.slope_variance(kernel)))
    hits = np.sum(out[:, :, 0] >= 0, axis=1)
    direction = np.tile(d, (paths, 1))
    for b in range(bounces):                      # replay the reflections on the host
        hit = out[:, b, 0] >= 0
        n = out[hit, b, 1:4] / np.linalg.norm(out[hit, b, 1:4], axis=1)[:, None]
        direction[hit] -= 2.0 * np.sum(direction[hit] * n, axis=1)[:, None] * n
    edges = np.linspace(0.0, math.pi / 2, bins + 1)
    theta_o = np.arccos(np.clip(direction[:, 2], -1.0, 1.0))
    up = direction[:, 2] > 0
    escaped = up & (hits >= 1) & (hits < bounces)
    single = np.histogram(theta_o[escaped & (hits == 1)], edges)[0] / paths
    multiple = np.histogram(theta_o[escaped & (hits > 1)], edges)[0] / paths
    alpha = C.beckmann_alpha(kernel)
    return {"theta_i_deg": theta_i_deg, "alpha": alpha, "memory": memory, "paths": paths,
            "edges_deg": np.degrees(edges), "single": single, "multiple": multiple,
            "stuck": float(np.mean(hits >= bounces)),
            "beckmann_single": C.beckmann_single_scatter_bins(ti, alpha, edges)}


# --- files --------------------------------------------------------------------------------

def write_csv(rows: list, path) -> None:
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def write_flights_csv(runs: dict, path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["memory", "path", "flight", "t", "grad_x", "grad_y", "grad_z"])
        for memory, out in runs.items():
            for i, b in zip(*np.nonzero(out[:, :, 0] >= 0)):
                w.writerow([memory, int(i), int(b) + 1, *(f"{v:.9g}" for v in out[i, b, :4])])


def plot_density(data: dict, title: str, out_dir) -> list:
    """free_flight.png (each flight's distance per memory model, the fitted exponential;
    on the first flight the medium counterpart's closed form along the ray, on later ones
    Rice's exponential where the counterpart is homogeneous) and normals.png (tan theta_m
    at the first hit against Beckmann)."""
    plt = pyplot()
    ray, runs, summary = data["ray"], data["runs"], data["summary"]
    bounces = next(iter(runs.values())).shape[1]
    rate = summary[0]["rice_entry_rate"]
    law = data["counterpart"]
    fig, axes = plt.subplots(1, bounces, figsize=(5 * bounces, 3.8), squeeze=False)
    for b, ax in enumerate(axes[0]):
        top = 0.0
        for memory, out in runs.items():
            t = out[out[:, b, 0] >= 0, b, 0]
            if len(t):
                top = max(top, np.quantile(t, 0.99))
        edges = np.linspace(0.0, top or ray.length, 60)
        for i, (memory, out) in enumerate(runs.items()):
            t = out[out[:, b, 0] >= 0, b, 0]
            if len(t):      # a model's colour is the same in every panel
                ax.hist(t, edges, density=True, histtype="step", color=f"C{i}", label=memory)
        row = next(r for r in summary if r["flight"] == b + 1 and r["memory"] == "renewal"
                   ) if "renewal" in runs else summary[b]
        x = np.linspace(0.0, edges[-1], 200)
        m = row["mean_free_path"]
        ax.plot(x, np.exp(-x / m) / m, "k-", lw=1, label=f"exp, same mean ({m:.3g})")
        if b == 0 and law["transmittance"] < 1.0:
            # the hits' law, as the histograms show hits only
            keep = law["t"] <= edges[-1]
            ax.plot(law["t"][keep], law["density"][keep] / (1.0 - law["transmittance"]),
                    "k--", lw=1, label="medium counterpart, exact")
        elif rate > 0 and data["homogeneous"]:
            ax.plot(x, rate * np.exp(-rate * x), "k--", lw=1,
                    label=f"exp, Rice ({1 / rate:.3g})")
        ax.set_xlabel("free-flight distance t")
        ax.set_title(f"flight {b + 1}" + (" (fresh ray)" if b == 0 else " (after a vertex)"))
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    paths = [Path(out_dir) / "free_flight.png"]
    fig.savefig(paths[0], dpi=110)
    plt.close(fig)
    alpha = summary[0].get("beckmann_alpha")
    if alpha:
        fig, ax = plt.subplots(figsize=(5, 3.8))
        tans = {m: np.sqrt(slopes_at_hits(o[o[:, 0, 0] >= 0, 0, 1:4], ray.direction))
                for m, o in runs.items() if np.any(o[:, 0, 0] >= 0)}
        top = max(np.quantile(v, 0.995) for v in tans.values())
        edges = np.linspace(0.0, top, 60)
        for memory, v in tans.items():
            ax.hist(v, edges, density=True, histtype="step", label=memory)
        x = np.linspace(0.0, top, 200)
        ax.plot(x, 2 * x / alpha ** 2 * np.exp(-x * x / alpha ** 2), "k--", lw=1,
                label=f"Beckmann alpha {alpha:.3g}")
        ax.set_xlabel("tan theta_m at the first hit")
        ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
        fig.tight_layout()
        paths.append(Path(out_dir) / "normals.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths


def plot_limits(medium: dict, surface: dict, path) -> None:
    """The two limits: against l, the fitted extinction over Rice's entry rate and the KS
    distance of first flights to the exponential of their own mean (medium: at a fixed
    mu/sigma, and at a fixed Rice mean free path); against alpha, the KS distance of
    first-hit slopes to Beckmann (surface). Dotted: 1/sqrt(n), the KS noise level."""
    plt = pyplot()
    fig, (a, r, b) = plt.subplots(1, 3, figsize=(14, 3.8))
    for label, rows in medium.items():
        ls = [row["length_scale"] for row in rows]
        r.semilogx(ls, [row["fitted_rate"] / row["rice_entry_rate"] for row in rows], "o-",
                   label=label)
        a.loglog(ls, [row["ks_exponential"] for row in rows], "o-", label=label)
        a.axhline(1 / math.sqrt(rows[0]["hits"]), color="gray", ls=":", lw=1)
    r.axhline(1.0, color="k", lw=0.8)
    r.set_xlabel("length scale l")
    r.set_ylabel("fitted extinction / Rice entry rate")
    r.set_title("medium limit: extinction (first flights, SE)", fontsize=9)
    r.legend(fontsize=7)
    a.set_xlabel("length scale l")
    a.set_ylabel("KS distance to the exponential")
    a.set_title("medium limit: shape of the free flight", fontsize=9)
    a.legend(fontsize=7)
    for label, rows in surface.items():
        b.loglog([row["beckmann_alpha"] for row in rows], [row["ks_beckmann"] for row in rows],
                 "o-", label=label)
        b.axhline(1 / math.sqrt(rows[0]["hits"]), color="gray", ls=":", lw=1)
    b.set_xlabel("Beckmann alpha = sqrt(2 lambda_2)")
    b.set_ylabel("KS distance to Beckmann")
    b.set_title("surface limit (plane mean, normal incidence)", fontsize=9)
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def scene_object(scene: str, obj: int) -> tuple:
    """(resolved shape, key path) of GPIS number obj of a scene file that resolve_target
    has accepted; a "scene" proxy bounded by the scene's box, as the renderer does."""
    from ..compile.scene import bound_scene_proxies
    from ..scene.loading import load_scene
    data = load_scene(scene).data
    i = [k for k, s in enumerate(data["shapes"]) if s["type"] == "gpis"][obj]
    return bound_scene_proxies(data)[obj], f"shapes[{i}]"


def require_scene_file(scene: str) -> None:
    if not Path(scene).is_file():
        raise SceneError(CLI_SOURCE, "SCENE", f"not an existing scene file (got {scene!r})")


def scene_density(scene: str, obj: int, ray: Ray | None = None, paths: int = 20000,
                  bounces: int = 2, seed: int = 1, device: Device | None = None,
                  memories=MEMORIES) -> tuple:
    """(density_data, title) of GPIS number obj of a scene file under each of `memories`
    (default: every memory model and the medium counterpart), with the object's device
    records as the renderer compiles them. SceneError (one line) for a missing file or
    object; failed flights (which the renderer would count as failed, RenderStats.
    gpis_failed) are one warning line on stderr and the summary's `failed` column."""
    require_scene_file(scene)
    target = resolve_target(scene, obj)
    if target.mean is None:
        raise SceneError(CLI_SOURCE, "SCENE", "density needs a scene file")
    shape, key = scene_object(scene, obj)
    packed = pack_scene_object(shape, scene, key)
    ray = ray or default_ray(target.mean, target.center, target.half_extent)
    data = density_data(target.kernel, target.mean, ray, paths, bounces, seed, memories,
                        device, packed)
    failed = failures(data["runs"])
    if failed:
        hint = (f"; the medium counterpart's tracker stops after {FS_TRACK_CAP} stretches "
                f"(each as long as the mean moves by {FS_CL_STRETCH} sigma, or outside by "
                f"{FS_CL_FAR} of itself) or tentative collisions"
                ) if "track_cap" in failed else ""
        print(f"gpiscl: warning: {scene}: {key}: density: flights failed, as the renderer "
              f"would count them (RenderStats.gpis_failed): {failed}{hint}; summary.csv's "
              f"`failed` column counts them, and no statistic includes them", file=sys.stderr)
    return data, target.name


def write_density_tables(data: dict, out_dir) -> list:
    """flights.csv (every hit) and summary.csv (flight_summary's rows) of density_data."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_flights_csv(data["runs"], out / "flights.csv")
    write_csv(data["summary"], out / "summary.csv")
    return [out / "flights.csv", out / "summary.csv"]


def write_density(scene: str, obj: int, out_dir, ray: Ray | None = None, paths: int = 20000,
                  bounces: int = 2, seed: int = 1, device: Device | None = None) -> list:
    """Everything `density` writes for GPIS number obj of a scene file: flights.csv,
    summary.csv, free_flight.png, normals.png (a mean with a gradient only), each with
    every memory model and the medium counterpart (classical_medium). Returns the paths."""
    require_scene_file(scene)
    pyplot()   # fail before any work if matplotlib is missing
    data, title = scene_density(scene, obj, ray, paths, bounces, seed, device)
    return [*write_density_tables(data, out_dir), *plot_density(data, title, out_dir)]
