"""Loading a scene: JSON text or a dict -> a validated, resolved Scene, and back.

A resolved scene (`Scene.data`) is plain JSON: every default filled in, every colour
three floats, every direction unit length, every file path absolute. Resolving is
idempotent, so a written resolved scene loads back to the same data.
"""
from __future__ import annotations

import copy
import hashlib
import json
import os
from dataclasses import dataclass, field

from . import gpis  # noqa: F401  (registers the "gpis" shape with records.SHAPES)
from .arguments import NO_REALIZATION
from .records import SCENE
from .settings import apply as apply_settings
from ..schema import Context, kind_of
from .tungsten_keys import tungsten_hint, tungsten_hint_of_text


@dataclass
class Scene:
    """A validated, resolved scene (see load_scene).

    Parameters
    ----------
    data : dict
        The scene document; Scene(data) validates and resolves it exactly as a scene file
        is (SceneError on any mistake), so no Scene holds unchecked data.
    source : str
        Where it came from, for error messages.
    base_dir : str
        The folder relative file paths are resolved against.

    data may be edited: load_scene and every render validate it again when it changed.
    """
    data: dict
    source: str = "<dict>"
    base_dir: str = field(default_factory=os.getcwd)
    # the digest of data as it was validated: data is a plain dict a caller can edit
    # (scene.data["camera"]["resolution"] = [0, 0] crashed in the film), so checked()
    # validates it again when it differs
    validated: str = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        self.data = SCENE.resolve(self.data, "", Context(self.source, self.base_dir))
        self.validated = _digest(self.data)

    @classmethod
    def resolved(cls, data: dict, source: str, base_dir: str) -> "Scene":
        """A Scene of data that is already resolved (load_scene's result, edited only with
        values checked on their own): skips validating again, which would reread every
        mesh and image the scene names."""
        scene = object.__new__(cls)
        scene.data, scene.source, scene.base_dir = data, source, base_dir
        scene.validated = _digest(data)
        return scene

    def checked(self) -> "Scene":
        """This scene, validated and resolved again (in place) if its data were changed
        since: SceneError naming the key of a bad edit. What load_scene does with a Scene,
        so every render and uq call gets only checked data."""
        digest = _digest(self.data)
        if digest is None or digest != self.validated:
            ctx = Context(self.source, self.base_dir)
            _check_nesting(self.data, ctx)   # first: the resolver recurses
            self.data = SCENE.resolve(self.data, "", ctx)
            self.validated = _digest(self.data)
        return self

    def with_overrides(self, spp=None, seed=None, resolution=None, realization=None,
                       tonemap=None, settings=None) -> "Scene":
        """This scene with the settings given (None: the scene's own), as a new Scene;
        realization='none' averages over realizations whatever the scene says. The values
        are checked by the caller (scene/arguments.py), so the scene is not resolved again;
        settings ({key path: value}, scene/settings.py) are applied first and checked by
        the schema, an error naming the setting."""
        self.checked()
        render = {k: v for k, v in (("spp", spp), ("seed", seed), ("realization", realization),
                                    ("tonemap", tonemap)) if v is not None}
        if not render and resolution is None and not settings:
            return self
        data = (apply_settings(self.data, self.source, self.base_dir, settings) if settings
                else copy.deepcopy(self.data))
        data["render"].update(render)
        if realization == NO_REALIZATION:
            data["render"]["realization"] = None
        if resolution is not None:
            data["camera"]["resolution"] = [int(resolution[0]), int(resolution[1])]
        return Scene.resolved(data, self.source, self.base_dir)

    def __repr__(self):
        return (f"Scene(source={self.source!r}, {len(self.data.get('shapes', []))} shapes, "
                f"{len(self.data.get('lights', []))} lights)")


def _digest(data) -> str | None:
    """sha256 of data as JSON; None for data that is no longer JSON (surely edited)."""
    try:
        text = json.dumps(data, sort_keys=True)
    except (TypeError, ValueError, RecursionError):
        return None
    return hashlib.sha256(text.encode()).hexdigest()


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


MAX_SCENE_BYTES = 64 << 20   # a scene names its big data in files; more is a mistake


def _read_json(path: str, ctx: Context):
    try:
        # a FIFO would block forever and /dev/zero fill memory: regular files only, bounded
        if os.path.exists(path) and not os.path.isdir(path) and not os.path.isfile(path):
            ctx.fail("", "not a regular file")
        if os.path.isfile(path) and os.path.getsize(path) > MAX_SCENE_BYTES:
            ctx.fail("", f"larger than {MAX_SCENE_BYTES >> 20} MiB: not a scene file")
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
        ctx.fail("", tungsten_hint_of_text(text) or f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}")
    except RecursionError:
        ctx.fail("", "invalid JSON: nested too deeply")
    except ValueError as exc:  # e.g. an integer literal with too many digits
        ctx.fail("", f"invalid JSON: {exc}")


def load_scene(source) -> Scene:
    """Validate and resolve a scene.

    Parameters
    ----------
    source : str, os.PathLike, dict or Scene
        A scene file (relative asset paths resolve against its real folder, also through
        a link), a scene document (relative paths resolve against the working folder), or
        a Scene, returned as is.

    Returns
    -------
    Scene
        Every default filled in, every colour three floats, every file path absolute.

    Raises
    ------
    SceneError
        For any mistake in the scene, naming the file, the key path and the reason. A given
        dict is never changed.
    """
    if isinstance(source, Scene):
        return source.checked()
    if isinstance(source, dict):
        ctx = Context("<dict>", os.getcwd())
        doc = source
    elif isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        # relative asset paths are relative to the scene file itself, also through a link
        ctx = Context(path, os.path.dirname(os.path.realpath(path)))
        doc = _read_json(path, ctx)
        if not isinstance(doc, dict):
            ctx.fail("", f"top level must be a JSON object (got {kind_of(doc)})")
    else:
        raise TypeError(f"load_scene takes a path, a dict or a Scene, not {type(source).__name__}")
    if tungsten_hint(doc):
        ctx.fail("", tungsten_hint(doc))
    _check_nesting(doc, ctx)
    return Scene.resolved(SCENE.resolve(doc, "", ctx), ctx.file, ctx.base_dir)


MAX_NESTING = 100   # levels of objects and lists: the resolver recurses, and a CSG tree
                    # anywhere near this deep is far beyond the device's stack anyway


def _check_nesting(doc, ctx: Context):
    """A clear error for a document nested too deeply, before the recursive resolver
    meets it (a 600-deep union chain was a RecursionError). Iterative, so any depth."""
    stack = [(doc, 1, "")]
    while stack:
        value, depth, path = stack.pop()
        if depth > MAX_NESTING:
            shown = path if len(path) <= 80 else path[:60] + "..."
            ctx.fail(shown, f"nested more than {MAX_NESTING} levels deep")
        if isinstance(value, dict):
            stack.extend((v, depth + 1, f"{path}.{k}" if path else str(k))
                         for k, v in value.items())
        elif isinstance(value, (list, tuple)):
            stack.extend((v, depth + 1, f"{path}[{i}]") for i, v in enumerate(value))


def write_resolved(scene, path) -> None:
    """Write the resolved scene as indented JSON; loading it gives the same data."""
    scene = load_scene(scene)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(scene.data, f, indent=2, allow_nan=False)
        f.write("\n")
