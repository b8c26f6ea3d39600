"""Uncertainty quantification by double Monte Carlo (supplemental Section 4).

N weight-space realizations, K samples per pixel each. Per pixel and channel, with y_i the
mean of realization i and u_i = s_i^2 / K the within-realization variance of that mean
(s_i^2: the film's unbiased sample variance of i's K samples):

  mean            ybar = sum y_i / N
  Eq. 44 (plain)  sum (y_i - ybar)^2 / N: its expectation is
                  (N-1)/N (Var_Phi[M] + E[s^2] / K), biased by the Monte Carlo noise
  unbiased        V = sum (y_i - ybar)^2 / (N-1) - sum u_i / N. By the law of total variance
                  Var(y) = Var_Phi[M] + E[s^2 / K], and E[s_i^2 | Phi_i] = Var(sample | Phi_i),
                  so E[V] = Var_Phi[M] exactly, for any N >= 2 and K >= 2. V is NOT clamped:
                  clamping at 0 would bias it upwards where the true variance is small, so it
                  can be negative; only previews and the derived std clamp.
  standard error  of V: V is the mean of d_i = N/(N-1) (y_i - ybar)^2 - u_i, so its
                  variance is estimated by the sample variance of d / N (ybar treated as
                  known: the SE itself is off by O(1/N) relative, fine for N >~ 10).

Independence: realization i has its own geometry id and its own path-sampling seed.
Reusing one seed for every realization would share the Monte Carlo samples between
realizations and bias V low by Var_y[E_Phi(y | samples)].

UqSums holds the moments of a set of realizations as centred sums, merged with the
pairwise update of Chan et al. and Pebay (2008), so batches of realizations rendered
anywhere merge in any order to the same result (up to float64 rounding) and stay
accurate when the variance is tiny next to the mean.
"""
from __future__ import annotations

import copy
import hashlib
import json
import time
from dataclasses import dataclass, fields

import numpy as np

from ..render.film import FilmImage
from ..errors import SceneError

_MASK31 = (1 << 31) - 1
_MASK32 = (1 << 32) - 1


def _mix32(x: int) -> int:
    """A 32-bit integer hash (lowbias32, C. Wellons): a bijection of [0, 2^32)."""
    x &= _MASK32
    x ^= x >> 16
    x = (x * 0x7FEB352D) & _MASK32
    x ^= x >> 15
    x = (x * 0x846CA68B) & _MASK32
    x ^= x >> 16
    return x


def realization_ids(seed: int, first: int, count: int):
    """(geometry ids, path seeds) of realizations first .. first+count-1 of a run.

    id_i = (h(seed) + i * odd) mod 2^31 is a bijection of i mod 2^31, so ids within a run
    are distinct; path seeds are hashed again so that no two realizations of a run share
    Monte Carlo samples (the path seed is a bijection of i too).
    """
    pairs = list(iter_realizations(seed, first, count))
    return [p[0] for p in pairs], [p[1] for p in pairs]


def iter_realizations(seed: int, first: int, count: int):
    """(geometry id, path seed) of each realization, one at a time: a run of 10^9
    realizations is interrupted or time-limited long before its ids would fit in memory."""
    base, hashed = _mix32(seed ^ 0x5BD1E995), _mix32(seed)
    for i in range(first, first + count):
        yield (base + i * 0x2545F491) & _MASK31, _mix32((hashed + i * 0x9E3779B9) & _MASK32)


@dataclass
class UqSums:
    """Centred per-pixel sums over realizations; arrays are (H, W, 3) float64.

    n      realizations                 m2..m4  sum (y - mean)^k
    mean   mean of the realization means c1, c2  sum (y - mean)^k u
    u, uu  sum u, sum u^2 (u: within-realization variance of a realization's mean)
    """

    n: int
    mean: np.ndarray
    m2: np.ndarray
    m3: np.ndarray
    m4: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    u: np.ndarray
    uu: np.ndarray

    @classmethod
    def empty(cls, shape) -> "UqSums":
        z = lambda: np.zeros(shape, np.float64)
        return cls(0, z(), z(), z(), z(), z(), z(), z(), z())

    @classmethod
    def from_realization(cls, y, u) -> "UqSums":
        """One realization: its per-pixel mean y and the variance u of that mean."""
        y = np.asarray(y, np.float64)
        u = np.asarray(u, np.float64)
        z = np.zeros_like(y)
        return cls(1, y.copy(), z, z.copy(), z.copy(), z.copy(), z.copy(), u.copy(), u * u)

    @classmethod
    def from_film(cls, image: FilmImage) -> "UqSums":
        """From a realization's film, in double (the film's float32 stderr is not used)."""
        k = image.count[..., None]
        if np.any(k < 2):
            raise ValueError("every pixel needs >= 2 samples for a within-realization variance")
        y = image.sum / k
        # rounding only can make this negative; the exact value is a sum of squares
        s2 = np.maximum(image.sum_sq - k * y * y, 0.0) / (k - 1)
        return cls.from_realization(y, s2 / k)

    def merge(self, other: "UqSums") -> "UqSums":
        """The sums of both sets of realizations (a new object; neither input changes)."""
        if other.n == 0:
            return copy.deepcopy(self)
        if self.n == 0:
            return copy.deepcopy(other)
        if self.mean.shape != other.mean.shape:
            raise ValueError(f"cannot merge images of shapes {self.mean.shape} and "
                             f"{other.mean.shape}")
        a, b = self, other
        na, nb = float(a.n), float(b.n)
        n = na + nb
        delta = b.mean - a.mean
        da, db = -nb * delta / n, na * delta / n        # old means minus the new mean
        m2 = a.m2 + b.m2 + delta**2 * na * nb / n
        m3 = (a.m3 + b.m3 + delta**3 * na * nb * (na - nb) / n**2
              + 3.0 * delta * (na * b.m2 - nb * a.m2) / n)
        m4 = (a.m4 + b.m4 + delta**4 * na * nb * (na * na - na * nb + nb * nb) / n**3
              + 6.0 * delta**2 * (na * na * b.m2 + nb * nb * a.m2) / n**2
              + 4.0 * delta * (na * b.m3 - nb * a.m3) / n)
        c1 = a.c1 + da * a.u + b.c1 + db * b.u
        c2 = (a.c2 + 2.0 * da * a.c1 + da**2 * a.u) + (b.c2 + 2.0 * db * b.c1 + db**2 * b.u)
        # the mean as a weighted sum of both, symmetric in a and b
        mean = (na * a.mean + nb * b.mean) / n
        return UqSums(a.n + b.n, mean, m2, m3, m4, c1, c2, a.u + b.u, a.uu + b.uu)

    __add__ = merge

    # --- estimates ------------------------------------------------------------------

    def _need(self, k: int):
        if self.n < k:
            raise ValueError(f"needs at least {k} realizations (have {self.n})")

    @property
    def mean_stderr(self) -> np.ndarray:
        """Standard error of the mean image (realization and Monte Carlo noise together)."""
        self._need(2)
        return np.sqrt(self.m2 / (self.n - 1) / self.n)

    @property
    def variance_eq44(self) -> np.ndarray:
        """Eq. 44: the plain variance of the realization means (biased for finite K)."""
        self._need(1)
        return self.m2 / self.n

    @property
    def variance(self) -> np.ndarray:
        """Unbiased between-realization variance (law of total variance); not clamped."""
        self._need(2)
        return self.m2 / (self.n - 1) - self.u / self.n

    @property
    def within_variance(self) -> np.ndarray:
        """Mean within-realization variance of a realization's mean, E[s^2] / K."""
        self._need(1)
        return self.u / self.n

    @property
    def variance_stderr(self) -> np.ndarray:
        """Standard error of `variance` (delta method over the terms d_i)."""
        self._need(2)
        n = float(self.n)
        c = n / (n - 1.0)
        sum_d = c * self.m2 - self.u
        sum_d2 = c * c * self.m4 - 2.0 * c * self.c2 + self.uu
        var_d = np.maximum(sum_d2 - sum_d**2 / n, 0.0) / (n - 1.0)
        return np.sqrt(var_d / n)

    @property
    def std(self) -> np.ndarray:
        """sqrt(max(variance, 0)): for viewing; clamping makes it biased."""
        return np.sqrt(np.maximum(self.variance, 0.0))

    # --- partial results on disk, for batches rendered elsewhere ---------------------

    def save(self, path, meta: dict | None = None) -> None:
        """meta: where the sums come from (render_realizations' UqRun.meta), kept as JSON
        so that --merge can check the batches belong together."""
        extra = {} if meta is None else {"meta": np.array(json.dumps(meta))}
        np.savez_compressed(path, **{f.name: np.asarray(getattr(self, f.name))
                                     for f in fields(self)}, **extra)

    @classmethod
    def load(cls, path) -> "UqSums":
        with np.load(path) as z:
            kw = {f.name: z[f.name] for f in fields(cls)}
        kw["n"] = int(kw["n"])
        return cls(**kw)


def check_uq_scene(data: dict, source: str = "<scene>") -> None:
    """A fixed realization is a weight-space notion: every GPIS must use that sampler."""
    for i, s in enumerate(data.get("shapes", [])):
        if s.get("type") == "gpis" and s["sampler"]["type"] != "weight_space":
            raise SceneError(source, f"shapes[{i}].sampler.type",
                             "uq renders fixed realizations, which needs weight_space "
                             f"(got {s['sampler']['type']})")


@dataclass
class UqRun:
    sums: UqSums
    ids: list          # geometry ids of the completed realizations, in render order
    seconds: float
    paths: int
    interrupted: bool = False
    meta: dict = None  # provenance of the sums (see merge_partials)


# ---- partial sums from elsewhere: --merge checks that they belong together -----------
#
# A partial-sums file carries meta: a digest of the scene (everything but the render
# settings uq overrides), the seed, the spp, the resolution and the realization index
# ranges it holds. Batches merge only with equal scene, seed, spp and resolution and
# disjoint ranges: the same file twice would count its realizations twice, and batches of
# different scenes or seeds mean nothing together.

MATCH = ("scene", "seed", "spp", "resolution")


def scene_digest(data: dict) -> str:
    render = {k: v for k, v in data["render"].items()
              if k not in ("spp", "seed", "realization", "batch_size", "tonemap")}
    body = dict(data, render=render)
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]


def load_partial(path):
    """(UqSums, meta) of a .uq.npz, checked: SceneError naming the file and the problem."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in z.files}
    except Exception as exc:   # zipfile, format and OS errors alike
        raise SceneError(path, "", f"cannot read as a uq partial-sums file "
                         f"({type(exc).__name__})") from None
    names = [f.name for f in fields(UqSums)]
    missing = [k for k in names + ["meta"] if k not in arrays]
    if missing:
        raise SceneError(path, "", f"not a uq partial-sums file of this version (lacks "
                         f"{', '.join(missing)})")
    n = arrays["n"]
    if n.shape != () or n.dtype.kind not in "iu" or int(n) < 1:
        raise SceneError(path, "n", f"must be one integer >= 1 (got {n.ravel()[:3].tolist()} "
                         f"of {n.dtype})")
    shape = arrays["mean"].shape
    for k in names[1:]:
        a = arrays[k]
        if a.shape != shape or len(shape) != 3 or shape[2] != 3 or a.dtype.kind != "f":
            raise SceneError(path, k, f"must be a float (H, W, 3) array like 'mean' "
                             f"(got {a.shape} {a.dtype})")
        if not np.isfinite(a).all():
            raise SceneError(path, k, "has NaN or infinite values")
    try:
        meta = json.loads(str(arrays["meta"]))
        ranges = [(int(a), int(b)) for a, b in meta["ranges"]]
        assert all(k in meta for k in MATCH)
    except Exception:
        raise SceneError(path, "meta", "unreadable provenance") from None
    if sum(b - a for a, b in ranges) != int(n):
        raise SceneError(path, "n", f"{int(n)} realizations, but its ranges hold "
                         f"{sum(b - a for a, b in ranges)}")
    sums = UqSums(int(n), *(arrays[k].astype(np.float64) for k in names[1:]))
    return sums, dict(meta, ranges=ranges)


def merge_partials(paths):
    """(UqSums, meta) of the partial-sums files, refusing batches that do not belong
    together or overlap (SceneError naming the file)."""
    sums, meta, owner = UqSums.empty(()), None, {}
    for path in paths:
        s, m = load_partial(path)
        if meta is None:
            meta = dict(m, ranges=[])
        for key in MATCH:
            if m[key] != meta[key]:
                raise SceneError(path, "", f"its {key} ({m[key]}) differs from "
                                 f"{paths[0]}'s ({meta[key]}): not batches of one uq run")
        for a, b in m["ranges"]:
            for (c, d), other in owner.items():
                if a < d and c < b:
                    raise SceneError(path, "", f"realizations [{max(a, c)}, {min(b, d)}) "
                                     f"are also in {other}: merging would count them twice")
            owner[(a, b)] = path
        sums = sums.merge(s)
        meta["ranges"] = sorted(meta["ranges"] + m["ranges"])
    return sums, meta


def prepare_realizations(scene, realizations: int, spp: int, seed: int | None = None,
                         first: int = 0, resolution=None):
    """(scene, data, seed): the arguments checked, the scene loaded, its data with the
    resolution applied and the seed resolved; what every realization of a run is rendered
    from, here or on a cluster (commands/cluster.py)."""
    from ..scene.loading import load_scene

    if spp < 2:
        raise SceneError("<command line>", "--spp", "must be >= 2: each realization needs a "
                         "sample variance to remove the Monte Carlo part")
    if realizations < 1:
        raise SceneError("<command line>", "--realizations", "must be >= 1")
    if first + realizations > 2**31:
        # ids are distinct only modulo 2^31
        raise SceneError("<command line>", "--realizations", "--first + --realizations must "
                         "be <= 2**31")
    scene = load_scene(scene)
    data = copy.deepcopy(scene.data)
    check_uq_scene(data, scene.source)
    if resolution is not None:
        data["camera"]["resolution"] = [int(resolution[0]), int(resolution[1])]
    seed = data["render"]["seed"] if seed is None else int(seed)
    return scene, data, seed


def render_realization(device, compiled, data: dict, spp: int, rid: int, rseed: int,
                       batch_size=None, stop=None):
    """The RenderResult of one realization: geometry id rid, path seed rseed."""
    from ..render.integrator import WavefrontIntegrator

    settings = dict(data["render"], spp=int(spp), seed=rseed, realization=rid)
    return WavefrontIntegrator(device, compiled, settings, batch_size).render(int(spp),
                                                                              stop=stop)


def run_meta(data: dict, seed: int, spp: int, first: int, count: int) -> dict:
    """The provenance of realizations first .. first+count-1 (see merge_partials)."""
    w, h = data["camera"]["resolution"]
    return {"scene": scene_digest(data), "seed": seed, "spp": int(spp), "resolution": [w, h],
            "ranges": [[first, first + count]] if count else []}


def render_realizations(scene, realizations: int, spp: int, seed: int | None = None,
                        first: int = 0, resolution=None, device=None, batch_size=None,
                        progress=None, stop=None) -> UqRun:
    """Render realizations first .. first+realizations-1 with spp samples each; stop()
    (asked between bounces) or Ctrl-C ends it, keeping the completed realizations."""
    from ..render.device import Device, shared_device
    from ..render.device_bakes import DeviceBakes
    from ..compile.scene import compile_scene

    scene, data, seed = prepare_realizations(scene, realizations, spp, seed, first,
                                             resolution)
    if not isinstance(device, Device):
        device = shared_device(device)
    # once: only the ids and seeds change
    compiled = compile_scene(data, scene.source, DeviceBakes(device))
    w, h = data["camera"]["resolution"]
    sums = UqSums.empty((h, w, 3))
    paths, done, interrupted = 0, [], False
    start = time.perf_counter()
    try:
        for rid, rseed in iter_realizations(seed, first, realizations):
            result = render_realization(device, compiled, data, spp, rid, rseed, batch_size,
                                        stop)
            if result.stats.interrupted:   # Ctrl-C: fewer than K samples, so not used
                interrupted = True
                break
            sums = sums.merge(UqSums.from_film(result.image))
            paths += result.stats.paths
            done.append(rid)
            if progress is not None:
                progress(1)
    except KeyboardInterrupt:
        interrupted = True
    meta = run_meta(data, seed, spp, first, len(done))
    return UqRun(sums, done, time.perf_counter() - start, paths, interrupted, meta)


def write_uq_outputs(sums: UqSums, scene, exr_path, exposure: float = 0.0,
                     meta: dict | None = None) -> dict:
    """EXR channels (float32):
      R, G, B             mean over realizations       stderr.R/G/B   its standard error
      var.R/G/B           unbiased variance, unclamped  var_stderr.R/G/B  its standard error
      std.R/G/B           sqrt(max(var, 0))             var_eq44.R/G/B    Eq. 44, for reference
    plus PNG previews of the mean (PATH.png) and std (PATH.std.png), the partial sums
    (PATH.uq.npz, to merge with other batches) and the resolved scene.
    """
    from ..io.images import tonemap_srgb8, write_exr, write_png
    from ..io.output_files import write_atomically
    from ..scene.loading import write_resolved

    paths = uq_output_paths(exr_path)
    extra = {}
    planes = {"stderr": sums.mean_stderr, "var": sums.variance,
              "var_stderr": sums.variance_stderr, "std": sums.std,
              "var_eq44": sums.variance_eq44}
    for name, img in planes.items():
        for i, c in enumerate("RGB"):
            extra[f"{name}.{c}"] = img[..., i]
    write_atomically(paths["exr"], lambda tmp: write_exr(tmp, sums.mean, extra))
    curve = scene.data["render"]["tonemap"] if scene is not None else "clamp"
    write_atomically(paths["png"],
                     lambda tmp: write_png(tmp, tonemap_srgb8(sums.mean, exposure, curve)))
    write_atomically(paths["std_png"],
                     lambda tmp: write_png(tmp, tonemap_srgb8(sums.std, exposure)))
    write_atomically(paths["sums"], lambda tmp: sums.save(tmp, meta))
    if scene is not None:
        write_atomically(paths["scene"], lambda tmp: write_resolved(scene, tmp))
    else:
        del paths["scene"]
    return paths


def uq_output_paths(exr_path) -> dict:
    """uq's files for -o NAME.exr: the variances need the EXR, so only .exr is accepted."""
    from ..io.output_files import plan
    paths = plan(exr_path, formats={".exr": ("exr", "png", "scene")})
    base = paths["exr"].with_suffix("")
    paths["std_png"] = base.with_name(base.name + ".std.png")
    paths["sums"] = base.with_name(base.name + ".uq.npz")
    return paths
