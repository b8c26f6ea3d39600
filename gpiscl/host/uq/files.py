"""What a uq run reads and writes: partial sums (NAME.uq.npz), checked and merged, and
the EXR of means and variances with its previews."""
from __future__ import annotations

import hashlib
import json
from dataclasses import fields

import numpy as np

from ..errors import SceneError, argument_source
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


MAX_REALIZATIONS = 2**31   # ids are distinct only modulo 2^31 (sums.realization_ids)
# sums of non-negative terms in UqSums.merge, so exactly >= 0 in any valid file
NON_NEGATIVE = ("m2", "u", "uu")


def sums_digest(sums: UqSums, meta: dict) -> str:
    """What binds a file's provenance to its sums: a relabelled copy (the same sums under
    other ranges) or sums edited by hand no longer match the digest its writer recorded."""
    h = hashlib.sha256(json.dumps({k: v for k, v in meta.items() if k != "digest"},
                                  sort_keys=True).encode())
    h.update(str(int(sums.n)).encode())
    for f in fields(UqSums)[1:]:
        h.update(np.ascontiguousarray(getattr(sums, f.name), np.float64).tobytes())
    return h.hexdigest()[:32]


def with_digest(sums: UqSums, meta: dict | None) -> dict | None:
    """meta as a partial-sums file records it (UqSums.save's caller: write_uq)."""
    if meta is None:
        return None
    meta = {k: v for k, v in meta.items() if k != "digest"}
    return dict(meta, digest=sums_digest(sums, meta))


def load_partial(path):
    """(UqSums, meta) of a .uq.npz, checked: SceneError naming the file, the field and the
    problem. Every array must be the (H, W, 3) of the recorded resolution, the ranges
    disjoint [a, b) with 0 <= a < b <= 2^31 that hold n realizations, the sums possible
    (no NaN, no negative sum of squares) and the digest the writer recorded must match."""
    path = str(path)
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
    meta = _check_meta(path, arrays["meta"])
    n = arrays["n"]
    if n.shape != () or n.dtype.kind not in "iu" or not 1 <= int(n) <= MAX_REALIZATIONS:
        raise SceneError(path, "n", f"must be one integer in [1, 2**31] (got "
                         f"{n.ravel()[:3].tolist()} of {n.dtype})")
    held = sum(b - a for a, b in meta["ranges"])
    if held != int(n):
        raise SceneError(path, "n", f"{int(n)} realizations, but its ranges hold {held}")
    w, h = meta["resolution"]
    for k in names[1:]:
        a = arrays[k]
        if a.shape != (h, w, 3) or a.dtype.kind != "f":
            raise SceneError(path, k, f"must be a float ({h}, {w}, 3) array, as its recorded "
                             f"resolution {w}x{h} says (got {a.shape} {a.dtype})")
        if not np.isfinite(a).all():
            raise SceneError(path, k, "has NaN or infinite values")
        if k in NON_NEGATIVE and (a < 0).any():
            raise SceneError(path, k, f"has negative values ({a.min():.3g}): it is a sum of "
                             "squares, so the file is damaged")
    sums = UqSums(int(n), *(arrays[k].astype(np.float64) for k in names[1:]))
    if meta.get("digest") != sums_digest(sums, meta):
        raise SceneError(path, "meta", "its sums do not match the digest recorded with them "
                         "(the file was edited or relabelled): render that batch again")
    return sums, dict(meta, ranges=[tuple(r) for r in meta["ranges"]])


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_meta(path: str, stored) -> dict:
    """The provenance, each field checked: SceneError naming meta.<field>."""
    try:
        meta = json.loads(str(stored))
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        raise SceneError(path, "meta", "unreadable provenance")
    for key in MATCH + ("ranges", "digest"):
        if key not in meta:
            raise SceneError(path, f"meta.{key}", "missing (not a partial-sums file of "
                             "this version: render that batch again)")
    checks = {
        "scene": (lambda v: isinstance(v, str), "a scene digest string"),
        "seed": (lambda v: _is_int(v) and 0 <= v < 2**32, "an integer in [0, 2**32)"),
        "spp": (lambda v: _is_int(v) and 2 <= v < 2**31, "an integer in [2, 2**31)"),
        "resolution": (lambda v: isinstance(v, list) and len(v) == 2
                       and all(_is_int(x) and 1 <= x <= 16384 for x in v),
                       "[width, height], each in [1, 16384]"),
        "digest": (lambda v: isinstance(v, str), "a digest string"),
    }
    for key, (ok, what) in checks.items():
        if not ok(meta[key]):
            raise SceneError(path, f"meta.{key}", f"must be {what} (got {meta[key]!r:.60})")
    ranges = meta["ranges"]
    if not isinstance(ranges, list) or not ranges:
        raise SceneError(path, "meta.ranges", f"must be a non-empty list of [first, end) "
                         f"pairs (got {ranges!r:.60})")
    for i, r in enumerate(ranges):
        if not (isinstance(r, list) and len(r) == 2 and all(_is_int(x) for x in r)
                and 0 <= r[0] < r[1] <= MAX_REALIZATIONS):
            raise SceneError(path, f"meta.ranges[{i}]", f"must be [a, b) with 0 <= a < b <= "
                             f"2**31 (got {r!r:.60})")
    ordered = sorted(ranges)
    for (a, b), (c, d) in zip(ordered, ordered[1:]):
        if c < b:
            raise SceneError(path, "meta.ranges", f"[{a}, {b}) and [{c}, {d}) overlap")
    return meta


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
    attributes = uq_attributes(sums, scene, meta)
    write_atomically(paths["exr"], lambda tmp: write_exr(tmp, sums.mean, extra, attributes))
    curve = scene.data["render"]["tonemap"] if scene is not None else "clamp"
    write_atomically(paths["png"],
                     lambda tmp: write_png(tmp, tonemap_srgb8(sums.mean, exposure, curve)))
    write_atomically(paths["std_png"],
                     lambda tmp: write_png(tmp, tonemap_srgb8(sums.std, exposure)))
    write_atomically(paths["sums"], lambda tmp: sums.save(tmp, with_digest(sums, meta)))
    if scene is not None:
        write_atomically(paths["scene"], lambda tmp: write_resolved(scene, tmp))
    else:
        del paths["scene"]
    return paths


def uq_attributes(sums: UqSums, scene, meta: dict | None) -> dict:
    """What a uq EXR says about how it was made, as a render's does (render/output.py):
    the seed and the realization ranges as strings, EXR ints being 32-bit."""
    from ...version import __version__, source_commit
    attrs = {"gpiscl:version": __version__, "gpiscl:commit": source_commit(),
             "gpiscl:realizations": int(sums.n)}
    if scene is not None:
        attrs["gpiscl:scene"] = str(scene.source)
    if meta is not None:
        attrs.update({"gpiscl:seed": str(meta["seed"]), "gpiscl:spp": int(meta["spp"]),
                      "gpiscl:ranges": json.dumps(meta["ranges"])})
    return attrs


def uq_output_paths(exr_path, option: str = "output") -> dict:
    """uq's files for -o NAME.exr: the variances need the EXR, so only .exr is accepted."""
    from ..io.output_files import plan
    if str(exr_path).lower().endswith(".png"):
        raise SceneError(argument_source(option), option, f"uq writes its means and "
                         f"variances to an EXR, with PNG previews beside it: use NAME.exr "
                         f"(got {str(exr_path)!r})")
    paths = plan(exr_path, option, formats={".exr": ("exr", "png", "scene")})
    base = paths["exr"].with_suffix("")
    paths["std_png"] = base.with_name(base.name + ".std.png")
    paths["sums"] = base.with_name(base.name + ".uq.npz")
    return paths
