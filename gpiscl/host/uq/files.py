"""What a uq run reads and writes: partial sums (NAME.uq.npz), checked and merged, and
the EXR of means and variances with its previews."""
from __future__ import annotations

import hashlib
import json
from dataclasses import fields

import numpy as np

from ..errors import SceneError
from .sums import UqSums

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


def run_meta(data: dict, seed: int, spp: int, first: int, count: int) -> dict:
    """The provenance of realizations first .. first+count-1 (see merge_partials)."""
    w, h = data["camera"]["resolution"]
    return {"scene": scene_digest(data), "seed": seed, "spp": int(spp), "resolution": [w, h],
            "ranges": [[first, first + count]] if count else []}


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


def uq_output_paths(exr_path, option: str = "output") -> dict:
    """uq's files for -o NAME.exr: the variances need the EXR, so only .exr is accepted."""
    from ..io.output_files import plan
    paths = plan(exr_path, option, formats={".exr": ("exr", "png", "scene")})
    base = paths["exr"].with_suffix("")
    paths["std_png"] = base.with_name(base.name + ".std.png")
    paths["sums"] = base.with_name(base.name + ".uq.npz")
    return paths
