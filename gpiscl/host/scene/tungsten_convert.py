"""Convert an authors' Tungsten scene file to a gpiscl scene file, with the output
guarantees of a render: the outputs are checked before any work (a folder, a device, an
unwritable place, the input itself are refused), every file is written under a temporary
name and renamed (output_files.write_atomically), and a refusal leaves nothing behind.

Files derived from the scene (grids converted or remapped from VDB grids) go only into
the grid folder (default: the output's folder) under plain names (tungsten.py checks each
name). They are first written into a private staging folder there and renamed into place
only once the converted scene has validated, just before the scene file itself, so an
error at any key writes nothing and never replaces an older file. Paths to files inside
the output's folder are written relative to it, so the output folder can move.
"""
from __future__ import annotations

import json
import os
import secrets
import shutil
from pathlib import Path

from ..errors import SceneError, argument_source
from ..io.lenient_json import read_lenient_json
from ..io.output_files import check_writable, write_atomically
from .tungsten import convert_tungsten


def environment_option(text):
    """The light for a substitute environment given as text: a radiance, or an .exr or
    .hdr map (None: keep the scene's own)."""
    if text is None:
        return None
    try:
        return {"type": "environment", "radiance": float(text)}
    except ValueError:
        return {"type": "environment_map", "file": os.path.abspath(text)}


def convert_file(src, dst, environment: dict | None = None, grid_dir=None,
                 option: str = "output", grid_option: str = "grid_dir") -> list[str]:
    """Convert Tungsten scene file `src` into gpiscl scene file `dst`; the notes on lossy
    mappings. SceneError (one line: file, key path, reason) on any problem, and then
    nothing is written. `environment` substitutes the scene's environment (a light dict,
    see environment_option); `grid_dir` is where derived grids go (default: dst's folder).
    `option` and `grid_option` name dst and grid_dir in an error about them (as the API
    spells them; the command line renames them)."""
    src, dst = Path(src), Path(dst)
    grids = Path(grid_dir) if grid_dir is not None else dst.absolute().parent
    if dst.absolute() == src.absolute() or _same_file(src, dst):
        raise SceneError(argument_source(option), option, f"{dst} is the Tungsten scene being "
                         "converted; it would be overwritten")
    check_writable([dst], option, inputs=[src])
    check_writable([grids / "grid.npz"], grid_option)
    doc = read_lenient_json(src)
    # made by the first write into it (write_atomically), if any; removed in the end
    staging = grids / f".convert-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        # validated there (SceneError at the key of their file) before anything is written
        scene, notes = convert_tungsten(doc, str(src), environment, staging)
        staged = os.listdir(staging) if staging.is_dir() else []
        final = {str(staging / n): str((grids / n).absolute()) for n in staged}
        scene = _paths_moved(scene, final, dst.absolute().parent)
        text = json.dumps(scene, indent=1, allow_nan=False) + "\n"

        def write(tmp):
            Path(tmp).write_text(text, encoding="utf-8")
            for staged, path in final.items():   # last: after the scene's bytes are down
                os.replace(staged, path)
        write_atomically(dst, write)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return notes


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _paths_moved(value, moved: dict, base: Path):
    """The scene with each staged file's path replaced by its final one, and every path
    made relative to `base` (the converted scene's folder; a scene refers to files
    relative to its own folder), so a copied project folder still renders."""
    if isinstance(value, dict):
        return {k: _paths_moved(v, moved, base) for k, v in value.items()}
    if isinstance(value, list):
        return [_paths_moved(v, moved, base) for v in value]
    if isinstance(value, str) and os.path.isabs(value):
        value = moved.get(value, value)
        try:
            return os.path.relpath(value, base)
        except ValueError:      # another drive (Windows): no relative path exists
            return value
    return value
