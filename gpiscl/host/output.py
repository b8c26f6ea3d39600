"""Writes a render: EXR (RGB, per-channel standard error, per-pixel sample count), PNG
preview, resolved scene.

A render stopped early (a signal, a time limit) can leave pixels with no sample. They are
never silent black: the EXR's `samples` channel is 0 there and the PNG preview paints them
UNCOVERED (magenta).
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from .film import FilmImage
from .imageio import tonemap_srgb8, write_exr, write_png
from .scene import Scene, write_resolved

UNCOVERED = (255, 0, 255)


def output_paths(exr_path) -> dict:
    exr = Path(exr_path)
    stem = exr.with_suffix("")
    return {"exr": exr, "png": stem.with_suffix(".png"),
            "scene": stem.with_name(stem.name + ".scene.json")}


def write_outputs(image: FilmImage, scene: Scene, exr_path, exposure: float = 0.0,
                  stats=None) -> dict:
    """stats (RenderStats) of a render stopped early: the resolved scene then records the
    samples per pixel that every pixel has, not the spp asked for."""
    paths = output_paths(exr_path)
    paths["exr"].parent.mkdir(parents=True, exist_ok=True)
    extra = {f"stderr.{c}": image.stderr[..., i] for i, c in enumerate("RGB")}
    extra["samples"] = image.count
    write_exr(paths["exr"], image.mean, extra)
    write_png(paths["png"], preview(image, exposure, scene.data["render"]["tonemap"]))
    write_resolved(resolved_as_rendered(scene, stats), paths["scene"])
    return paths


def preview(image: FilmImage, exposure: float, curve: str) -> np.ndarray:
    """The 8-bit preview, pixels without a sample in UNCOVERED."""
    rgb = tonemap_srgb8(image.mean, exposure, curve)
    rgb[image.count == 0] = UNCOVERED
    return rgb


def resolved_as_rendered(scene: Scene, stats=None) -> Scene:
    """The scene with render.spp set to the complete passes actually rendered (paths run
    in pixel order: a stop mid-pass leaves the first pixels one sample ahead, recorded in
    the EXR's samples channel), so that rendering it again gives those passes."""
    if stats is None or stats.paths >= stats.pixels * stats.spp_requested:
        return scene
    data = copy.deepcopy(scene.data)
    data["render"]["spp"] = max(1, math.floor(stats.spp_reached))
    return Scene(data, scene.source, scene.base_dir)
