"""Which files a render writes, checked before it starts, and written whole or not at all.

The format follows the extension of -o:
  NAME.exr   NAME.exr (float32 channels) + NAME.png (preview) + NAME.scene.json
  NAME.png   NAME.png (preview only: the float data are not kept) + NAME.scene.json
Anything else is an error before any work: a name without an extension used to get an EXR
nobody could open by name, and `-o pic.png` used to write the EXR to pic.png and then
overwrite it with the PNG. Only the last extension counts (a.b.exr -> a.b.png).

A render can take hours, so the output folder is checked writable (and the outputs checked
not to be the scene file or a folder) before it starts, and each file is written to a
temporary name beside it and renamed into place: a full disk or a signal never leaves a
truncated image over an earlier one, and never leaves the temporary file.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import SceneError, argument_source

FORMATS = {".exr": ("exr", "png", "scene"), ".png": ("png", "scene")}


def plan(path, option: str = "--output", formats=FORMATS) -> dict:
    """{"exr": Path | None, "png": Path, "scene": Path} for the output path given."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in formats or not p.stem:
        known = " or ".join(formats)
        raise SceneError(argument_source(option), option,
                         f"cannot tell the image format of {str(p)!r} from its extension "
                         f"(use {known})")
    wanted = formats[ext]
    base = p.with_suffix("")
    return {"exr": p if "exr" in wanted else None,
            "png": (p if ext == ".png" else p.with_suffix(".png")) if "png" in wanted else None,
            "scene": base.with_name(base.name + ".scene.json") if "scene" in wanted else None}


def check_writable(paths, option: str = "--output", inputs=(), source=None) -> None:
    """SceneError (source, option, reason) unless every path can be written: its folder
    exists or can be made, and is writable; an existing file there is a plain file (a
    rename over /dev/full would replace the device); its name leaves room for the
    temporary name; no path is one of the inputs (also through a link). source defaults
    to the command line or the API, as the option is spelled."""
    source = source or argument_source(option)
    inputs = [Path(i) for i in inputs if i]
    for path in (Path(p) for p in paths if p is not None):
        where = path.absolute()
        if len(_temporary(path).name.encode()) > _NAME_MAX:
            raise SceneError(source, option, f"the file name {path.name[:40]}... is too "
                             f"long ({len(path.name.encode())} bytes)")
        if any(where.resolve() == i.resolve() or _same_file(where, i) for i in inputs):
            raise SceneError(source, option,
                             f"{path} is an input of this render; it would be overwritten")
        if where.is_dir():
            raise SceneError(source, option, f"{path} is a folder")
        if where.exists() and not where.is_file():
            raise SceneError(source, option, f"{path} is not a regular file")
        folder = where.parent
        while not folder.exists():
            folder = folder.parent
        if not folder.is_dir():
            raise SceneError(source, option,
                             f"cannot create {where.parent}: {folder} is a file")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise SceneError(source, option,
                             f"cannot write to {folder} (permission denied)")


_NAME_MAX = 255   # bytes in one file name on Linux file systems (ext4, tmpfs, xfs)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _temporary(path: Path) -> Path:
    # the extension kept last: numpy's savez appends .npz to a name without it
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


def scene_inputs(scene) -> list:
    """The scene file and every file it reads (a resolved scene's file paths are absolute
    strings), so that -o can refuse to overwrite any of them."""
    found = [scene.source]

    def walk(v):
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
        elif isinstance(v, str) and os.path.isabs(v) and os.path.isfile(v):
            found.append(v)
    walk(scene.data)
    return found


def write_atomically(path, write) -> None:
    """write(temporary path), then rename it to path; a failure leaves path as it was and
    no temporary file, and is a SceneError naming path and the reason."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    except (OSError, RuntimeError) as exc:   # OpenEXR reports a failed write as RuntimeError
        reason = getattr(exc, "strerror", None) or str(exc).splitlines()[0]
        raise SceneError(str(path), "", f"cannot write ({reason})") from None
    finally:
        tmp.unlink(missing_ok=True)
