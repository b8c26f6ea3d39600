"""Writes a render: EXR (RGB + per-channel standard error), PNG preview, resolved scene."""
from __future__ import annotations

from pathlib import Path

from .film import FilmImage
from ..io.images import tonemap_srgb8, write_exr, write_png
from ..scene.loading import Scene, write_resolved


def output_paths(exr_path) -> dict:
    exr = Path(exr_path)
    stem = exr.with_suffix("")
    return {"exr": exr, "png": stem.with_suffix(".png"),
            "scene": stem.with_name(stem.name + ".scene.json")}


def write_outputs(image: FilmImage, scene: Scene, exr_path, exposure: float = 0.0) -> dict:
    paths = output_paths(exr_path)
    paths["exr"].parent.mkdir(parents=True, exist_ok=True)
    extra = {f"stderr.{c}": image.stderr[..., i] for i, c in enumerate("RGB")}
    write_exr(paths["exr"], image.mean, extra)
    write_png(paths["png"], tonemap_srgb8(image.mean, exposure, scene.data["render"]["tonemap"]))
    write_resolved(scene, paths["scene"])
    return paths
