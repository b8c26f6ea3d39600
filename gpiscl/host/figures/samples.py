"""Pictures of the random geometry (supplemental Figs. 2 and 3): numpy data, then plots.

Data functions need numpy only and are what the tests check; plot_* and write_figures
need matplotlib, an optional extra (pip install -e '.[plots]'), imported only when a
figure is drawn so the renderer never depends on it.

Weight-space curves here redraw the features for every realization, as the renderer
does (features are keyed by the realization), so their covariance over realizations is
k for any M; what a small M gets wrong is each single realization, i.e. the kernel that
one basis draw implies, k_M(r) = sigma^2 / M sum_i cos(theta_i . r), and the Gaussianity
of the values. Fig. 2's second row shows k_M for a few draws against k.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..gp.kernels import Kernel, covariance_matrix
from ..scene.proxies import bounding_proxy
from ..gp.means import Mean
from ..gp.spectral import RandomFeatures, sample_frequencies
from ..errors import API_SOURCE, CLI_SOURCE, SceneError
from .plotting import pyplot



@dataclass
class Target:
    """What to draw: a kernel, and a mean and proxy box when it comes from a scene."""

    name: str
    kernel: Kernel
    kernel_spec: dict
    mean: Mean | None = None
    center: np.ndarray | None = None      # slice centre (the proxy's)
    half_extent: float | None = None      # half the slice width
    source: str = API_SOURCE              # where the kernel was given, for errors
    key: str = "kernel"                   # and at which key


def resolve_target(spec: str, obj: int = 0) -> Target:
    """A kernel type name, a kernel JSON object, or a scene file (its GPIS number obj)."""
    from ..compile.gpis import build_kernel, build_mean
    from ..scene.gpis import KERNELS
    from ..scene.loading import load_scene
    from ..schema import Context

    if spec.lstrip().startswith("{"):
        try:
            raw = json.loads(spec)
        except json.JSONDecodeError as exc:
            raise SceneError(API_SOURCE, "kernel", f"invalid JSON ({exc})") from None
        kdict = KERNELS.resolve(raw, "kernel", Context(API_SOURCE, os.getcwd()))
        return Target(kdict["type"], _kernel(build_kernel, kdict), kdict)
    if spec in KERNELS.variants:
        kdict = KERNELS.resolve({"type": spec}, "kernel", Context(API_SOURCE, os.getcwd()))
        return Target(spec, _kernel(build_kernel, kdict), kdict)
    if not os.path.exists(spec):
        raise SceneError(CLI_SOURCE, "KERNEL_OR_SCENE",
                         f"not a kernel type ({', '.join(KERNELS.variants)}), a kernel JSON "
                         f"object or an existing scene file (got {spec!r})")
    scene = load_scene(spec)
    gpis = [s for s in scene.data["shapes"] if s["type"] == "gpis"]
    if not gpis:
        raise SceneError(spec, "shapes", "has no gpis object to draw")
    if not 0 <= obj < len(gpis):
        raise SceneError(CLI_SOURCE, "--object",
                         f"must be in [0, {len(gpis)}) for this scene (got {obj})")
    g = gpis[obj]
    key = f"shapes[{next(i for i, s in enumerate(scene.data['shapes']) if s is g)}].kernel"
    proxy = bounding_proxy(g["proxy"])
    if proxy["type"] == "scene":
        from ..compile.scene import scene_box
        lo, hi = scene_box(scene.data)
        proxy = {"type": "box", "min": lo, "max": hi}
    if proxy["type"] == "box":
        lo, hi = np.asarray(proxy["min"], float), np.asarray(proxy["max"], float)
        center, half = (lo + hi) / 2, float(np.max(hi - lo)) / 2
    else:
        center, half = np.asarray(proxy["center"], float), float(proxy["radius"])
    kdict = g["kernel"]
    name = f"{Path(spec).stem} gpis {obj} ({kdict['type']})"
    return Target(name, _kernel(build_kernel, kdict), kdict, build_mean(g["mean"]),
                  center, half, spec, key)


def _kernel(build, kdict) -> Kernel:
    try:
        return build(kdict)
    except ValueError as exc:
        raise SceneError(API_SOURCE, "kernel", str(exc)) from None


def length_scale(kernel_spec: dict) -> float:
    from ..compile.gpis import kernel_length_scale
    return kernel_length_scale(kernel_spec)


def spectral_ok(kernel: Kernel) -> bool:
    return kernel.kind != "thin_plate"


# --- data: realizations along a line and on a plane ---------------------------------------

def line_points(t, direction=(1.0, 0.0, 0.0), origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    d = np.asarray(direction, float)
    return np.asarray(origin, float) + np.asarray(t, float)[:, None] * (d / np.linalg.norm(d))


def weight_space_samples(kernel: Kernel, m: int, x, n: int, rng) -> np.ndarray:
    """n zero-mean realizations (n, ...) at points x (..., 3), each with its own M features."""
    x = np.asarray(x, float)
    pts = x.reshape(-1, 3)
    out = np.empty((n, len(pts)))
    scale = math.sqrt(kernel.variance) * math.sqrt(2.0 / m)
    chunk = max(1, (1 << 22) // (m * len(pts)))     # realizations per 2^22 float64 phases
    for lo in range(0, n, chunk):
        c = min(chunk, n - lo)
        omega = sample_frequencies(kernel, c * m, rng).reshape(c, m, 3)
        phase = rng.uniform(0.0, 2.0 * np.pi, (c, m))
        w = rng.standard_normal((c, m))
        arg = omega @ pts.T
        arg += phase[:, :, None]
        np.cos(arg, out=arg)
        out[lo:lo + c] = scale * (w[:, None, :] @ arg)[:, 0, :]
    return out.reshape((n,) + x.shape[:-1])


def exact_samples(kernel: Kernel, x, n: int, rng) -> np.ndarray:
    """n exact (function-space) zero-mean samples (n, len(x)) at points x (N, 3).

    A symmetric square root from eigh: smooth kernels make K numerically singular, where
    Cholesky fails; eigenvalues below 0 by rounding are clipped.
    """
    K = covariance_matrix(kernel, np.asarray(x, float))
    lam, vec = np.linalg.eigh((K + K.T) / 2)
    root = vec * np.sqrt(np.clip(lam, 0.0, None))
    return rng.standard_normal((n, len(lam))) @ root.T


def empirical_covariance(samples, ref: int = 0):
    """cov(f(x_ref), f(x_j)) over realizations of zero-mean samples (n, N), and its
    standard error (from the spread of the products)."""
    s = np.asarray(samples, float)
    prod = s[:, ref:ref + 1] * s
    return prod.mean(0), prod.std(0, ddof=1) / math.sqrt(len(s))


def kernel_covariance(kernel: Kernel, x, ref: int = 0) -> np.ndarray:
    x = np.asarray(x, float)
    return kernel.cov(x[ref], x)


def implied_kernel(kernel: Kernel, m: int, r, rng, direction=(1.0, 0.0, 0.0)) -> np.ndarray:
    """The covariance one draw of M features gives: sigma^2 / M sum cos(theta_i . r)."""
    feats = RandomFeatures.sample(kernel, m, rng)
    x = line_points(r, direction)
    return feats.sigma**2 * np.cos(x @ feats.omega.T).mean(-1)


def plane_points(center, half_extent: float, res: int, axes=(0, 1)) -> np.ndarray:
    """(res, res, 3) points of a square slice through center, spanning axes (u, v)."""
    c = np.asarray(center, float)
    s = np.linspace(-half_extent, half_extent, res)
    v, u = np.meshgrid(s, s, indexing="ij")
    p = np.broadcast_to(c, (res, res, 3)).copy()
    p[..., axes[0]] += u
    p[..., axes[1]] += v
    return p


def occupancy(kernel: Kernel, mean: Mean, x) -> np.ndarray:
    """Prior occupancy P(f(x) <= 0) = Phi(-mu(x) / sigma) with sigma^2 = k(0)."""
    mu = mean.value(np.asarray(x, float))
    z = -np.asarray(mu, float) / math.sqrt(kernel.variance)
    return 0.5 * np.vectorize(math.erfc)(-z / math.sqrt(2.0))


def fig2_data(kernel: Kernel, spec: dict, features=(10, 100, 1000), curves: int = 5,
              draws: int = 3, points: int = 200, seed: int = 0, cov_curves: int = 400) -> dict:
    """Curves along x for each M and exact samples; implied kernels k_M of a few draws;
    the covariance with x = 0 over cov_curves realizations of each."""
    rng = np.random.default_rng(seed)
    ell = length_scale(spec)
    t = np.linspace(0.0, 8.0 * ell, points)
    x = line_points(t)
    data = {"t": t, "kernel": kernel_covariance(kernel, x), "features": list(features),
            "weight_space": {}, "implied": {}}
    for m in features:
        data["weight_space"][m] = weight_space_samples(kernel, m, x, curves, rng)
        data["implied"][m] = np.stack([implied_kernel(kernel, m, t, rng) for _ in range(draws)])
    data["exact"] = exact_samples(kernel, x, curves, rng)
    # covariance over many realizations: k for every M (features redrawn per realization)
    data["empirical"] = {m: empirical_covariance(weight_space_samples(kernel, m, x, cov_curves,
                                                                      rng))[0]
                         for m in features}
    data["empirical"]["exact"] = empirical_covariance(exact_samples(kernel, x, cov_curves,
                                                                    rng))[0]
    return data


# --- plots (matplotlib) -------------------------------------------------------------------

def plot_fig2(data: dict, title: str, path) -> None:
    plt = pyplot()
    ms = data["features"]
    fig, ax = plt.subplots(2, len(ms) + 1, figsize=(3.2 * (len(ms) + 1), 5.6),
                           sharex=True, sharey="row")
    t = data["t"]
    for j, m in enumerate(ms):
        ax[0, j].plot(t, data["weight_space"][m].T, lw=1)
        ax[0, j].set_title(f"M = {m}")
        ax[1, j].plot(t, data["implied"][m].T, lw=1, alpha=0.8)
        ax[1, j].plot(t, data["kernel"], "k--", lw=1.5, label="k(r)")
    ax[0, -1].plot(t, data["exact"].T, lw=1)
    ax[0, -1].set_title("exact (function space)")
    for label, cov in data["empirical"].items():
        name = "exact" if label == "exact" else f"M = {label}"
        ax[1, -1].plot(t, cov, lw=1, label=name)
    ax[1, -1].plot(t, data["kernel"], "k--", lw=1.5, label="k(r)")
    ax[1, -1].set_title("covariance over realizations", fontsize=9)
    ax[1, -1].legend(loc="upper right", fontsize=7)
    ax[0, 0].set_ylabel("f(x)")
    ax[1, 0].set_ylabel("k_M(r) of one basis")
    for a in ax[1]:
        a.set_xlabel("r")
    fig.suptitle(f"{title}: weight-space realizations vs exact samples")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_lines(t, samples, title: str, path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    ax.plot(t, np.asarray(samples).T, lw=1)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("x")
    ax.set_ylabel("f(x)")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_maps(maps, extent, titles, suptitle: str, path, cmap="RdBu_r", vmin=None,
              vmax=None, zero_contour=True, half_contour=False) -> None:
    plt = pyplot()
    n = len(maps)
    fig, ax = plt.subplots(1, n, figsize=(max(3.2 * n, 5.0), 3.6), squeeze=False,
                           constrained_layout=True)
    # one colour scale for all panels, as they share one colour bar
    lim = vmax if vmax is not None else float(np.max(np.abs(maps))) or 1.0
    lo = vmin if vmin is not None else -lim
    for a, img, title in zip(ax[0], maps, titles):
        im = a.imshow(img, origin="lower", extent=extent, cmap=cmap, vmin=lo, vmax=lim)
        if zero_contour or half_contour:
            a.contour(img, levels=[0.5 if half_contour else 0.0], colors="k",
                      linewidths=0.8, origin="lower", extent=extent)
        a.set_title(title)
        a.set_xticks([])
        a.set_yticks([])
    fig.colorbar(im, ax=ax[0].tolist(), shrink=0.9)
    fig.suptitle(suptitle, fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def load_observations(path, noise: float = 1e-4):
    """Surface points (n, 3), or points and normals (n, 6), from .npy or a text file
    (x y z [nx ny nz] per line), as posterior Observations (f = 0, grad f = n)."""
    from ..gp.posterior import surface_observations
    from ..io.points import load_points   # the scene's reader: same checks, no echo
    try:
        a = load_points(str(path))
    except ValueError as exc:
        raise SceneError(str(path), "", str(exc)) from None
    except OSError as exc:
        raise SceneError(str(path), "", f"cannot read file ({exc.strerror or exc})") from None
    return surface_observations(a[:, :3], a[:, 3:] if a.shape[1] == 6 else None, noise=noise)


def posterior_maps(target: Target, obs, pts, realizations: int, m: int, rng) -> dict:
    """Posterior mean, sd, occupancy and pathwise realizations on the points pts.

    Without a scene the prior mean is sigma (outside, one standard deviation), so that
    space far from the data reads as empty.
    """
    from ..gp.means import Constant
    from ..gp.posterior import Posterior
    mean = target.mean if target.mean is not None else Constant(math.sqrt(target.kernel.variance))
    post = Posterior(target.kernel, mean, obs)
    flat = pts.reshape(-1, 3)
    mu = post.mean(flat)
    sd = np.sqrt(post.variance(flat))
    occ = 0.5 * np.vectorize(math.erfc)(mu / np.maximum(sd, 1e-300) / math.sqrt(2.0))
    samples = [post.pathwise(RandomFeatures.sample(target.kernel, m, rng),
                             rng.standard_normal(m), rng)(flat) for _ in range(realizations)]
    shape = pts.shape[:-1]
    return {"mean": mu.reshape(shape), "sd": sd.reshape(shape), "occupancy": occ.reshape(shape),
            "samples": [v.reshape(shape) for v in samples], "jitter": post.jitter}


def write_figures(target: Target, out_dir, features=(10, 100, 1000), realizations: int = 4,
                  seed: int = 0, resolution: int = 128, slice_features: int | None = None,
                  observations=None):
    """Every figure for target into out_dir; returns the paths written. With
    observations (posterior.Observations), also the posterior's maps and realizations."""
    if not spectral_ok(target.kernel):
        raise SceneError(target.source, target.key, "thin_plate has no spectral density, "
                         "so weight-space figures cannot be drawn")
    varying = [k for k in ("sigma_field", "length_scale_field") if target.kernel_spec.get(k)]
    if varying:
        raise SceneError(target.source, f"{target.key}.{varying[0]}", "a spatially varying "
                         "kernel has no spectral density, so weight-space figures cannot be "
                         "drawn; remove the field to see the stationary kernel")
    pyplot()   # fail before any work if matplotlib is missing
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    name = target.name
    ell = length_scale(target.kernel_spec)
    m_slice = slice_features or max(features)
    written = []

    # 1-D realizations along x
    t = np.linspace(0.0, 8.0 * ell, 300)
    path = out / "lines.png"
    plot_lines(t, weight_space_samples(target.kernel, m_slice, line_points(t),
                                       realizations, rng),
               f"{name}: {realizations} realizations along x (M = {m_slice})", path)
    written.append(path)

    # 2-D slices z = centre: zero-mean realizations, or mean + realization for a scene
    center = target.center if target.center is not None else np.zeros(3)
    half = target.half_extent if target.half_extent is not None else 4.0 * ell
    pts = plane_points(center, half, resolution)
    fields = weight_space_samples(target.kernel, m_slice, pts, realizations, rng)
    if target.mean is not None:
        fields = fields + target.mean.value(pts)[None]
    extent = (center[0] - half, center[0] + half, center[1] - half, center[1] + half)
    path = out / "slices.png"
    what = "mean + realization" if target.mean is not None else "realization"
    plot_maps(list(fields), extent, [f"#{i}" for i in range(realizations)],
              f"{name}: {what} on z = {center[2]:g}, zero level in black", path)
    written.append(path)

    # Fig. 2: M = 10, 100, 1000 against exact samples and k
    path = out / "features.png"
    plot_fig2(fig2_data(target.kernel, target.kernel_spec, features, seed=seed + 1),
              name, path)
    written.append(path)

    # Fig. 3: prior occupancy, when there is a mean
    if target.mean is not None:
        occ = occupancy(target.kernel, target.mean, pts)
        path = out / "occupancy.png"
        plot_maps([occ], extent, ["P(f(x) <= 0), mean surface in black"],
                  f"{name}:\nprior occupancy on z = {center[2]:g}", path, cmap="viridis",
                  vmin=0.0, vmax=1.0, zero_contour=False, half_contour=True)
        written.append(path)

    # posterior given observed surface points: mean, sd, occupancy; pathwise realizations
    if observations is not None:
        post = posterior_maps(target, observations, pts, realizations, m_slice, rng)
        path = out / "posterior.png"
        plot_maps([post["mean"]], extent, ["posterior mean"], f"{name}: posterior given "
                  f"{len(observations)} observations, z = {center[2]:g}", path)
        plot_maps([post["sd"]], extent, ["posterior sd"], "", out / "posterior_sd.png",
                  cmap="magma", vmin=0.0, zero_contour=False)
        plot_maps([post["occupancy"]], extent, ["P(f(x) <= 0 | data)"],
                  f"{name}:\nposterior occupancy", out / "posterior_occupancy.png",
                  cmap="viridis", vmin=0.0, vmax=1.0, zero_contour=False, half_contour=True)
        plot_maps(post["samples"], extent, [f"#{i}" for i in range(realizations)],
                  f"{name}: posterior realizations (pathwise, M = {m_slice})",
                  out / "posterior_slices.png")
        written += [path, out / "posterior_sd.png", out / "posterior_occupancy.png",
                    out / "posterior_slices.png"]
    return written
