"""Writes a render: EXR (RGB, per-channel standard error, per-pixel sample count, how it
was made in the header), PNG preview, resolved scene; output_files says which, from -o.

A render stopped early (a signal, a time limit) can leave pixels with no sample. They are
never silent black: the EXR's `samples` channel is 0 there and the PNG preview paints them
UNCOVERED (magenta).
"""
from __future__ import annotations

import math

import numpy as np

from . import aov
from ..io import output_files
from .film import FilmImage
from ..io.images import tonemap_srgb8, write_exr, write_png
from ..scene.loading import Scene, write_resolved
from ..errors import API_SOURCE, SceneError

UNCOVERED = (255, 0, 255)


def output_paths(path, option: str = "output") -> dict:
    """{"exr", "png", "scene"} paths for -o path (output_files.plan: the extension picks
    the format; "exr" is None for a .png)."""
    return output_files.plan(path, option)


def write_outputs(image: FilmImage, scene: Scene, path, exposure: float = 0.0,
                  stats=None, aovs=(), option: str = "output") -> dict:
    """Write the files the extension of path asks for (see output_files), each whole or
    not at all. stats (RenderStats), when given, go into the EXR header (gpiscl:* attributes:
    spp reached and requested, paths, seed, render seconds, version, scene file), and for a
    render stopped early the resolved scene records the spp every pixel has. aovs: names of
    aov.AOVS to add as EXR layers (the film must have collected them)."""
    paths = output_paths(path, option)
    if aovs and paths["exr"] is None:
        raise SceneError(API_SOURCE, "aov", "AOVs are EXR layers: write NAME.exr")
    if paths["exr"] is not None:
        extra = {f"stderr.{c}": image.stderr[..., i] for i, c in enumerate("RGB")}
        extra["samples"] = image.count
        if aovs:
            extra.update(aov.channels(image.aov, image.count, aovs))
        attributes = exr_attributes(scene, stats)
        output_files.write_atomically(
            paths["exr"], lambda tmp: write_exr(tmp, image.mean, extra, attributes))
    rgb8 = preview(image, exposure, scene.data["render"]["tonemap"])
    output_files.write_atomically(paths["png"], lambda tmp: write_png(tmp, rgb8))
    resolved = resolved_as_rendered(scene, stats)
    output_files.write_atomically(paths["scene"], lambda tmp: write_resolved(resolved, tmp))
    return paths


def exr_attributes(scene: Scene, stats=None) -> dict:
    """What an EXR says about how it was made. The seed is a string: EXR ints are 32-bit
    signed and seeds go to 2**32 - 1."""
    from ...version import __version__, source_commit
    attrs = {"gpiscl:version": __version__, "gpiscl:commit": source_commit(),
             "gpiscl:scene": str(scene.source),
             "gpiscl:seed": str(scene.data["render"]["seed"]),
             "gpiscl:spp_requested": int(scene.data["render"]["spp"])}
    if stats is not None:
        attrs.update({"gpiscl:spp": float(stats.spp_reached), "gpiscl:paths": str(stats.paths),
                      "gpiscl:render_seconds": float(stats.seconds),
                      "gpiscl:stopped": ("signal" if stats.interrupted else
                                         "time limit" if stats.time_limited else "no")})
    return attrs


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
    return scene.with_overrides(spp=max(1, math.floor(stats.spp_reached)))
