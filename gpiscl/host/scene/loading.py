"""Loading a scene: JSON text or a dict -> a validated, resolved Scene, and back.

A resolved scene (`Scene.data`) is plain JSON: every default filled in, every colour
three floats, every direction unit length, every file path absolute. Resolving is
idempotent, so a written resolved scene loads back to the same data.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

from . import gpis  # noqa: F401  (registers the "gpis" shape with records.SHAPES)
from .records import SCENE
from .schema import Context, kind_of


@dataclass
class Scene:
    data: dict
    source: str = "<dict>"
    base_dir: str = field(default_factory=os.getcwd)

    def __repr__(self):
        return (f"Scene(source={self.source!r}, {len(self.data.get('shapes', []))} shapes, "
                f"{len(self.data.get('lights', []))} lights)")


class _JsonObject(dict):
    """A parsed JSON object that remembers keys it saw twice (json keeps the last)."""
    duplicate_keys = ()


def _object_pairs(pairs):
    obj, dups = _JsonObject(), []
    for key, value in pairs:
        if key in obj:
            dups.append(key)
        obj[key] = value
    if dups:
        obj.duplicate_keys = dups
    return obj


def _read_json(path: str, ctx: Context):
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        ctx.fail("", "file not found")
    except IsADirectoryError:
        ctx.fail("", "is a directory, not a scene file")
    except UnicodeDecodeError:
        ctx.fail("", "not UTF-8 text")
    except OSError as exc:
        ctx.fail("", f"cannot read file ({exc.strerror or exc})")
    try:
        return json.loads(text, object_pairs_hook=_object_pairs)
    except json.JSONDecodeError as exc:
        ctx.fail("", f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}")
    except RecursionError:
        ctx.fail("", "invalid JSON: nested too deeply")
    except ValueError as exc:  # e.g. an integer literal with too many digits
        ctx.fail("", f"invalid JSON: {exc}")


def load_scene(source) -> Scene:
    """Validate and resolve a scene given as a path, a dict or a Scene (returned as is).

    Raises SceneError for any mistake in the scene; never mutates a given dict.
    """
    if isinstance(source, Scene):
        return source
    if isinstance(source, dict):
        ctx = Context("<dict>", os.getcwd())
        doc = source
    elif isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        ctx = Context(path, os.path.dirname(os.path.abspath(path)))
        doc = _read_json(path, ctx)
        if not isinstance(doc, dict):
            ctx.fail("", f"top level must be a JSON object (got {kind_of(doc)})")
    else:
        raise TypeError(f"load_scene takes a path, a dict or a Scene, not {type(source).__name__}")
    return Scene(SCENE.resolve(doc, "", ctx), ctx.file, ctx.base_dir)


def write_resolved(scene, path) -> None:
    """Write the resolved scene as indented JSON; loading it gives the same data."""
    scene = load_scene(scene)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(scene.data, f, indent=2, allow_nan=False)
        f.write("\n")
